//! Sea level from a conserved ocean volume (eustasy).
//!
//! With a fixed sea level, nothing on the planet ties the height of the continents to the
//! capacity of the ocean basins: continental crust lifted by subduction and collisions stays
//! above the sea for ever, and the land grows with it. On Earth the water has a fixed volume
//! (1.335·10⁹ km³, a layer 2.62 km deep over the globe): when the basins get shallower (young
//! floor, arcs, sediment) or the continents higher, the sea rises and floods the lowest land
//! (the Cretaceous seas), and when they deepen it falls.
//!
//! After the isostatic surface is computed, [`solve_datum`] finds the shift `d` of the solid
//! surface against the sea that makes the water volume `V₀`, and [`shift_surface`] applies it.
//! The water loads what it covers: a column whose surface would stand at `y` without water
//! stands at `y` above sea level, or at `y·f` below it, f = ρ_m/(ρ_m − ρ_w). So every sample has
//! a "dry" level `y` (continental crust above the sea: its elevation; everything at sea and all
//! oceanic crust, whose age–depth law is already water-loaded: elevation / f); a datum shift
//! `d` moves `y` to `y + d`, and the water volume is f·Σ a·max(0, −(y + d)). Raising the sea by
//! s deepens the ocean floor by s·f (water load included), and lowers land by s.

use rayon::prelude::*;

use crate::resources::CrustType;

/// The level `y` of a sample free of its water load (see the module documentation).
#[inline]
fn dry_level(z: f32, t: CrustType, f: f64) -> f64 {
    let z = z as f64;
    if t == CrustType::Continental && z >= 0.0 {
        z
    } else {
        z / f
    }
}

/// Water volume (km³) over a surface: Σ a·max(0, −z) over every finite sample.
pub fn ocean_volume_km3(elevation_km: &[f32], area_km2: &[f64]) -> f64 {
    const CH: usize = 16384;
    elevation_km
        .par_chunks(CH)
        .enumerate()
        .map(|(c, zs)| {
            let mut v = 0.0f64;
            for (k, &z) in zs.iter().enumerate() {
                if z < 0.0 {
                    v -= z as f64 * area_km2.get(c * CH + k).copied().unwrap_or(0.0);
                }
            }
            v
        })
        .collect::<Vec<f64>>()
        .iter()
        .sum()
}

/// Histogram range of dry levels (km) searched for the water level; a datum shift beyond it is
/// clamped to it.
const RANGE_KM: f64 = 4.0;
/// Bin width (km) of the first, coarse search.
const BIN_KM: f64 = 0.01;

/// The datum shift `d` (km; > 0 lifts the surface against the sea, i.e. the sea falls) that
/// makes the water volume over `elevation_km` equal `volume_km3`, for submerge factor `f`
/// (ρ_m/(ρ_m − ρ_w)). Non-finite elevations are left out. Exact to rounding within ±4 km (the
/// answer is clamped to that range); the same inputs give the same bits whatever the thread
/// count.
pub fn solve_datum(
    elevation_km: &[f32],
    crust_type: &[CrustType],
    area_km2: &[f64],
    f: f64,
    volume_km3: f64,
) -> f64 {
    let n = elevation_km.len().min(crust_type.len()).min(area_km2.len());
    // The water level L in dry levels: Σ_{y<L} a·(L − y) = W; d = −L.
    let w = volume_km3 / f;
    let bins = (2.0 * RANGE_KM / BIN_KM).round() as usize;
    let bin_of = |y: f64| -> Option<usize> {
        if y < -RANGE_KM {
            None
        } else {
            Some((((y + RANGE_KM) / BIN_KM) as usize).min(bins))
        }
    };
    // Per fixed chunk: area and Σa·y below the range, and per bin (the last bin gathers
    // everything above the range); merged in chunk order.
    const CH: usize = 16384;
    // (area below the range, Σ a·y below it, the bins' (area, Σ a·y)) per chunk.
    type Part = (f64, f64, Vec<(f64, f64)>);
    let parts: Vec<Part> = (0..n.div_ceil(CH))
        .into_par_iter()
        .map(|c| {
            let (mut a_lo, mut s_lo) = (0.0f64, 0.0f64);
            let mut h = vec![(0.0f64, 0.0f64); bins + 1];
            for i in c * CH..((c + 1) * CH).min(n) {
                let z = elevation_km[i];
                if !z.is_finite() {
                    continue;
                }
                let (y, a) = (dry_level(z, crust_type[i], f), area_km2[i]);
                match bin_of(y) {
                    None => {
                        a_lo += a;
                        s_lo += a * y;
                    }
                    Some(b) => {
                        h[b].0 += a;
                        h[b].1 += a * y;
                    }
                }
            }
            (a_lo, s_lo, h)
        })
        .collect();
    let (mut a_cum, mut s_cum) = (0.0f64, 0.0f64);
    let mut hist = vec![(0.0f64, 0.0f64); bins + 1];
    for (a_lo, s_lo, h) in &parts {
        a_cum += a_lo;
        s_cum += s_lo;
        for (t, x) in hist.iter_mut().zip(h) {
            t.0 += x.0;
            t.1 += x.1;
        }
    }
    // G(L) = L·A(<L) − S(<L) at the bin edges: the first edge where it reaches W closes the bin
    // holding the water level.
    let g_at = |l: f64, a: f64, s: f64| l * a - s;
    if g_at(-RANGE_KM, a_cum, s_cum) >= w {
        return RANGE_KM;
    }
    let mut found = None;
    for (b, &(a, s)) in hist.iter().enumerate().take(bins) {
        let hi = -RANGE_KM + (b + 1) as f64 * BIN_KM;
        if g_at(hi, a_cum + a, s_cum + s) >= w {
            found = Some(b);
            break;
        }
        a_cum += a;
        s_cum += s;
    }
    let Some(b) = found else {
        return -RANGE_KM;
    };
    // Within the bin: its samples in order of level, adding each below the level found so far.
    let lo = -RANGE_KM + b as f64 * BIN_KM;
    let mut inside: Vec<(f64, f64)> = (0..n.div_ceil(CH))
        .into_par_iter()
        .flat_map_iter(|c| {
            (c * CH..((c + 1) * CH).min(n)).filter_map(|i| {
                let z = elevation_km[i];
                if !z.is_finite() {
                    return None;
                }
                let y = dry_level(z, crust_type[i], f);
                (bin_of(y) == Some(b)).then_some((y, area_km2[i]))
            })
        })
        .collect();
    inside.sort_by(|p, q| p.0.total_cmp(&q.0).then(p.1.total_cmp(&q.1)));
    let mut level = lo;
    for &(y, a) in &inside {
        if a_cum > 0.0 {
            level = ((w + s_cum) / a_cum).max(lo);
            if level <= y {
                return -level;
            }
        }
        a_cum += a;
        s_cum += a * y;
    }
    if a_cum > 0.0 {
        level = (w + s_cum) / a_cum;
    }
    -level
}

/// Moves the solid surface by datum shift `d` (km) against the sea (see the module
/// documentation): a level `y` becomes `y + d`, and what lies below the sea carries its water
/// load. Non-finite elevations are left as they are.
pub fn shift_surface(elevation_km: &mut [f32], crust_type: &[CrustType], f: f64, d: f64) {
    if d == 0.0 {
        return;
    }
    elevation_km
        .par_iter_mut()
        .zip(crust_type.par_iter())
        .with_min_len(8192)
        .for_each(|(z, &t)| {
            if !z.is_finite() {
                return;
            }
            let y = dry_level(*z, t, f) + d;
            *z = if t == CrustType::Continental && y >= 0.0 {
                y
            } else {
                y * f
            } as f32;
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A made-up planet: `n` samples of unit area, elevations spread from −6 to +3 km, every
    /// third one continental.
    fn planet(n: usize) -> (Vec<f32>, Vec<CrustType>, Vec<f64>) {
        let z = (0..n)
            .map(|i| (-6.0 + 9.0 * ((i * 7919) % n) as f64 / n as f64) as f32)
            .collect();
        let t = (0..n)
            .map(|i| {
                if i % 3 == 0 {
                    CrustType::Continental
                } else {
                    CrustType::Oceanic
                }
            })
            .collect();
        (z, t, vec![1.0; n])
    }

    #[test]
    fn the_shift_restores_the_water_volume() {
        let f = 3.3 / (3.3 - 1.03);
        let (z, t, a) = planet(100_000);
        let v = ocean_volume_km3(&z, &a);
        for target in [0.8 * v, v, 1.1 * v] {
            let d = solve_datum(&z, &t, &a, f, target);
            let mut z2 = z.clone();
            shift_surface(&mut z2, &t, f, d);
            let v2 = ocean_volume_km3(&z2, &a);
            assert!(
                (v2 - target).abs() <= 1e-5 * target,
                "volume {v2} against {target} (d = {d})"
            );
            // Less water lets the surface stand higher.
            assert_eq!(d > 1e-9, target < v - 1e-9 * v, "d = {d}");
        }
        // The volume it has already: no shift.
        assert!(solve_datum(&z, &t, &a, f, v).abs() < 1e-6);
    }

    #[test]
    fn the_same_bits_with_one_thread_or_two() {
        let f = 1.45;
        let (z, t, a) = planet(200_000);
        let v = 0.9 * ocean_volume_km3(&z, &a);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let d = solve_datum(&z, &t, &a, f, v);
                    let mut z2 = z.clone();
                    shift_surface(&mut z2, &t, f, d);
                    (
                        d.to_bits(),
                        z2.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                    )
                })
        };
        assert_eq!(run(1), run(2));
    }

    #[test]
    fn a_rising_sea_floods_land_by_its_rise_and_deepens_the_floor_under_its_load() {
        let f = 1.5;
        let t = [
            CrustType::Continental,
            CrustType::Continental,
            CrustType::Oceanic,
        ];
        let mut z = [1.0f32, 0.1, -3.0];
        shift_surface(&mut z, &t, f, -0.2);
        assert!(
            (z[0] - 0.8).abs() < 1e-6,
            "land lowered by the rise: {}",
            z[0]
        );
        assert!(
            (z[1] - (-0.1 * 1.5)).abs() < 1e-6,
            "flooded and loaded: {}",
            z[1]
        );
        assert!(
            (z[2] - (-3.0 - 0.3)).abs() < 1e-6,
            "floor deepened by rise × f: {}",
            z[2]
        );
    }
}
