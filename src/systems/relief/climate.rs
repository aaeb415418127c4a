//! Rain over the land from the planet's winds (phenomenon `climate`): a zonal pattern (wet
//! tropics and mid-latitudes, dry subtropics and poles), moisture that the prevailing winds carry
//! inland from the sea and lose with distance and over mountains (rain shadows, dry continental
//! interiors), and more rain on slopes that face the wind.
//!
//! Per land sample `i`:
//!
//! ```text
//! P_i ∝ Z(φ_i) · exp(−C_i / L) · (1 + min(lift_i / S₀, 2))
//! ```
//!
//! - `Z(φ) = 0.3 + 1.8·exp(−(φ/14°)²) + 0.9·exp(−((|φ| − 48°)/14°)²)`: the zonal mean, highest
//!   under the intertropical convergence (2.1 at the equator), lowest in the subtropical highs
//!   (0.5 at 30°) and over the poles (0.3), with a second maximum in the storm tracks (1.2 at
//!   48°) — the shape of Earth's zonal-mean precipitation (Adler et al. 2003, GPCP).
//! - `C_i`: the least cost of carrying air from the sea to `i` over the land, along the sample
//!   graph: each edge costs its length times `1 − a·(d·w)` (`d` the edge's direction, `w` the
//!   wind at its start, `a` = `climate.wind_anisotropy`), so moisture travels downwind more
//!   easily than against it, plus `L / H` per km climbed (`H` =
//!   `climate.orographic_height_km`): air forced over a range rains out on the way up, and the
//!   land behind lies in its rain shadow. The sea is every sample at or below sea level.
//! - The wind `w = −sin(6|φ|)·east`: easterly trade winds peaking at 15°, westerlies at 45°,
//!   polar easterlies at 75°, calm at the equator, 30°, 60° and the poles (the three cells of
//!   the general circulation).
//! - `lift_i`: the rise of the ground along the wind into `i` (m/m), the windward slope, over
//!   `S₀` = `climate.windward_slope`: orographic rain, up to three times the rain of flat
//!   ground.
//!
//! The field is then scaled so its area-weighted mean over the land is 1 (the drainage reads it
//! as relative rain: `rivers.runoff_mm_per_yr` stays the planet's mean runoff), and floored at
//! `climate.min_rain`. Sea samples get `Z(φ)` over the same scale. Paths costing more than
//! 40·L (moisture e⁻⁴⁰ of the coast's) are not followed: that land gets the least rain.
//! Deterministic: one sequential least-cost search (a bucket queue, label-correcting), sums over
//! fixed chunks in order, whatever the thread count.

use glam::DVec3;
use rayon::prelude::*;

use super::graph::ReliefGraph;

/// The parameters of [`precipitation`] (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClimateParams {
    /// Distance L over which moisture carried inland falls by e, km.
    pub moisture_length_km: f64,
    /// a: how much easier moisture travels downwind than across the wind (0: isotropic;
    /// 0.6: downwind edges cost 0.4 of their length, upwind ones 1.6, a quarter).
    pub wind_anisotropy: f64,
    /// H: the climb over which the air loses as much moisture as over L of flat land, km.
    pub orographic_height_km: f64,
    /// S₀: the windward slope that doubles the rain, m/m (0: no orographic gain).
    pub windward_slope: f64,
    /// The least rain, as a fraction of the land's mean.
    pub min_rain: f64,
}

impl Default for ClimateParams {
    fn default() -> Self {
        Self {
            moisture_length_km: 1500.0,
            wind_anisotropy: 0.6,
            orographic_height_km: 1.0,
            windward_slope: 0.004,
            min_rain: 0.1,
        }
    }
}

/// Reusable buffers of [`precipitation`], and what depends on the mesh only (computed once per
/// graph size: the mesh of a run does not change): each sample's zonal factor and each edge's
/// cosine to the wind at its start.
#[derive(Clone, Debug, Default)]
pub struct ClimateScratch {
    cost: Vec<f64>,
    /// Bucket queue of the least-cost search.
    buckets: super::buckets::BucketQueue,
    land: Vec<u32>,
    /// Surface height above the sea, km (0 at sea).
    height: Vec<f32>,
    zonal: Vec<f32>,
    /// Per directed edge `i → j`: the cosine between the edge and the wind at `i`, in 1/127.
    along: Vec<i8>,
}

/// The zonal factor `Z(φ)` at the unit position `p` (pole on +z).
pub fn zonal_factor(p: DVec3) -> f64 {
    let lat = p.z.clamp(-1.0, 1.0).asin().to_degrees();
    let a = lat.abs();
    0.3 + 1.8 * (-(lat / 14.0).powi(2)).exp() + 0.9 * (-((a - 48.0) / 14.0).powi(2)).exp()
}

/// The prevailing wind at the unit position `p`: a tangent vector of length ≤ 1, east
/// (`ẑ × p`, unit) times `−sin(6|φ|)`; zero at the poles. (No trigonometric call: with
/// `s = |sin φ|`, `c = cos φ`, `sin 6|φ| = 2·(3s − 4s³)·(4c³ − 3c)`.)
#[inline]
pub fn wind(p: DVec3) -> DVec3 {
    let east = DVec3::new(-p.y, p.x, 0.0);
    let c = east.length();
    if c < 1e-12 {
        return DVec3::ZERO;
    }
    let s = p.z.abs().min(1.0);
    let sin6 = 2.0 * (3.0 * s - 4.0 * s * s * s) * (4.0 * c * c * c - 3.0 * c);
    east * (-sin6 / c)
}

impl ClimateScratch {
    /// Frees the search's work areas, keeping the mesh's tables (`zonal`, `along`, which
    /// depend on the graph and positions alone).
    pub fn release_search(&mut self) {
        let (zonal, along) = (
            std::mem::take(&mut self.zonal),
            std::mem::take(&mut self.along),
        );
        *self = Self::default();
        (self.zonal, self.along) = (zonal, along);
    }
    /// The per-mesh tables of `g` (see the fields).
    fn prepare_mesh(&mut self, g: &ReliefGraph, positions: &[DVec3], n: usize) {
        if self.zonal.len() == n && self.along.len() == g.neighbors.len() {
            return;
        }
        self.zonal = positions[..n]
            .par_iter()
            .map(|&q| zonal_factor(q) as f32)
            .collect();
        let radius = g.radius_km;
        self.along = (0..g.len())
            .into_par_iter()
            .with_min_len(4096)
            .flat_map_iter(|i| {
                let w = if i < n {
                    wind(positions[i])
                } else {
                    DVec3::ZERO
                };
                g.edges(i).map(move |e| {
                    let j = g.neighbors[e] as usize;
                    if i >= n || j >= n {
                        return 0;
                    }
                    // The chord over the arc's length: they differ by under 1e-4 here.
                    let d = positions[j] - positions[i];
                    let c = (d.dot(w) * radius * f64::from(g.inv_edge_km(e))).clamp(-1.0, 1.0);
                    (c * 127.0).round() as i8
                })
            })
            .collect();
    }
}

/// Relative rain per sample into `out` (see the module documentation): `positions` are the
/// graph's unit positions, `elevation_km` the surface (sea level 0; NaN and missing values read
/// as sea level).
pub fn precipitation(
    g: &ReliefGraph,
    positions: &[DVec3],
    elevation_km: &[f32],
    p: &ClimateParams,
    out: &mut Vec<f32>,
    s: &mut ClimateScratch,
) {
    prepare(g, positions, elevation_km, s);
    precipitation_prepared(g, p, out, s);
}

/// The first part of [`precipitation`]: what it reads of the mesh and of the surface, copied
/// into `s`. The rest, [`precipitation_prepared`], needs only the graph and `s`, so it can run
/// apart from the world (on another thread) while the surface changes.
pub fn prepare(g: &ReliefGraph, positions: &[DVec3], elevation_km: &[f32], s: &mut ClimateScratch) {
    let n = g.len().min(positions.len());
    s.height.clear();
    if n == 0 {
        return;
    }
    s.prepare_mesh(g, positions, n);
    s.height.extend((0..n).map(|i| match elevation_km.get(i) {
        Some(&z) if z.is_finite() && z > 0.0 => z,
        _ => 0.0,
    }));
}

/// The second part of [`precipitation`], on the surface and mesh tables [`prepare`] put in
/// `s`.
pub fn precipitation_prepared(
    g: &ReliefGraph,
    p: &ClimateParams,
    out: &mut Vec<f32>,
    s: &mut ClimateScratch,
) {
    let n = s.height.len();
    out.clear();
    out.resize(g.len(), 1.0);
    if n == 0 {
        return;
    }
    let l = p.moisture_length_km.max(1e-9);
    let climb_cost = if p.orographic_height_km > 0.0 {
        l / p.orographic_height_km
    } else {
        0.0
    };
    let a = p.wind_anisotropy.clamp(0.0, 0.95) / 127.0;
    let (height, along) = (&s.height, &s.along);
    // Moisture carried over edge e from a sample at height hi to one at hj: km of flat,
    // crosswind land.
    let step_cost = |e: usize, hi: f32, hj: f32| -> f64 {
        f64::from(g.edge_km[e]) * (1.0 - a * f64::from(along[e]))
            + climb_cost * f64::from((hj - hi).max(0.0))
    };
    // 1. Least cost from the sea over the land: the land next to the sea starts at the cost of
    //    the step from its cheapest sea neighbour, then a label-correcting search over a bucket
    //    queue (a sample improved after it was handled goes back into the queue, so the costs
    //    are the least ones whatever the order inside a bucket; one thread, so deterministic).
    s.land.clear();
    s.land
        .extend((0..n as u32).filter(|&i| height[i as usize] > 0.0));
    s.cost.clear();
    s.cost.resize(n, f64::INFINITY);
    // Buckets half as wide as a mean edge straight downwind costs, and no more than 2¹⁶ of
    // them up to the cut-off (a wider bucket only means more samples handled twice).
    let max_cost = 40.0 * l;
    let width = (0.5 * (1.0 - 127.0 * a) * g.mean_spacing_km)
        .max(max_cost / 65536.0)
        .max(1e-3);
    // (At most 2¹⁷ buckets: a cost past the cut-off is never filed.)
    s.buckets.reset(width, 1 << 17);
    for &i in &s.land {
        let i = i as usize;
        let mut best = f64::INFINITY;
        for e in g.edges(i) {
            let j = g.neighbors[e] as usize;
            if j >= n || g.edge_km[e] <= 0.0 || height[j] > 0.0 {
                continue;
            }
            // The step from j (its wind) to i, over j's edge to i.
            best = best.min(step_cost(edge_to(g, j, i).unwrap_or(e), 0.0, height[i]));
        }
        if best <= max_cost {
            s.cost[i] = best;
            s.buckets.push(best, i as u32);
        }
    }
    while let Some(i) = s.buckets.pop(|i| s.cost[i]) {
        let c = s.cost[i];
        let hi = height[i];
        for e in g.edges(i) {
            let j = g.neighbors[e] as usize;
            if j >= n || g.edge_km[e] <= 0.0 || height[j] <= 0.0 {
                continue;
            }
            let cj = c + step_cost(e, hi, height[j]);
            if cj < s.cost[j] && cj <= max_cost {
                s.cost[j] = cj;
                s.buckets.push(cj, j as u32);
            }
        }
    }
    // 2. Raw rain (the sea: its zonal factor), then the land's mean to 1.
    out[..n].copy_from_slice(&s.zonal);
    const CH: usize = 4096;
    let cost = &s.cost;
    let raw: Vec<(Vec<f32>, f64, f64)> = s
        .land
        .par_chunks(CH)
        .map(|chunk| {
            let (mut sum, mut area) = (0.0f64, 0.0f64);
            let vals = chunk
                .iter()
                .map(|&i| {
                    let i = i as usize;
                    let hi = height[i];
                    let mut gain = 0.0;
                    if p.windward_slope > 0.0 {
                        // Rise of the ground into i from its upwind neighbours, weighted by how
                        // squarely each lies upwind.
                        let (mut num, mut den) = (0.0f64, 0.0f64);
                        for e in g.edges(i) {
                            let j = g.neighbors[e] as usize;
                            let up = -f64::from(along[e]) / 127.0;
                            if j < n && up > 0.0 {
                                num += up * f64::from(hi - height[j]) * f64::from(g.inv_edge_km(e));
                                den += up;
                            }
                        }
                        if den > 0.0 {
                            gain = ((num / den).max(0.0) / p.windward_slope).min(2.0);
                        }
                    }
                    let v = f64::from(s.zonal[i]) * (-cost[i] / l).exp() * (1.0 + gain);
                    sum += v * g.area_km2[i];
                    area += g.area_km2[i];
                    v as f32
                })
                .collect();
            (vals, sum, area)
        })
        .collect();
    let (mut sum, mut area) = (0.0f64, 0.0f64);
    for ((vals, su, ar), chunk) in raw.iter().zip(s.land.chunks(CH)) {
        sum += su;
        area += ar;
        for (&v, &i) in vals.iter().zip(chunk) {
            out[i as usize] = v;
        }
    }
    let scale = if sum > 0.0 && area > 0.0 {
        area / sum
    } else {
        1.0
    };
    let min_rain = p.min_rain;
    out[..n].par_chunks_mut(16384).for_each(|o| {
        o.iter_mut()
            .for_each(|o| *o = (f64::from(*o) * scale).max(min_rain) as f32)
    });
}

/// The CSR index of the edge `j → i`, if the graph has it.
fn edge_to(g: &ReliefGraph, j: usize, i: usize) -> Option<usize> {
    g.edges(j).find(|&e| g.neighbors[e] as usize == i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::SphereMesh;

    use crate::systems::relief::network::relief_graph as graph;

    #[test]
    fn the_zonal_pattern_is_wet_at_the_equator_and_dry_in_the_subtropics() {
        let at = |deg: f64| {
            zonal_factor(DVec3::new(
                deg.to_radians().cos(),
                0.0,
                deg.to_radians().sin(),
            ))
        };
        assert!(at(0.0) > 2.0 && at(30.0) < 0.6 && at(48.0) > 1.1 && at(90.0) < 0.35);
        assert!((at(20.0) - at(-20.0)).abs() < 1e-12);
        // Trade winds blow west, westerlies east.
        let w15 = wind(DVec3::new(
            15f64.to_radians().cos(),
            0.0,
            15f64.to_radians().sin(),
        ));
        let w45 = wind(DVec3::new(
            45f64.to_radians().cos(),
            0.0,
            45f64.to_radians().sin(),
        ));
        assert!(w15.y < -0.99 && w45.y > 0.99, "{w15} {w45}");
    }

    /// A continent across the westerlies with a north–south range near its west coast: the land
    /// downwind of the range is drier than the land upwind of it, the windward slope is the
    /// wettest, and the interior far from the sea is drier than the coast.
    #[test]
    fn a_range_in_the_westerlies_casts_a_rain_shadow() {
        let mesh = SphereMesh::fibonacci(20_000, 0.5, 3, 6371.0).expect("mesh");
        let g = graph(&mesh);
        let lon = |p: DVec3| p.y.atan2(p.x).to_degrees();
        let lat = |p: DVec3| p.z.asin().to_degrees();
        // Land: 15°..75° N, −40°..40° E (the test band, 40°..50° N, lies far from the north and
        // south coasts); a 3 km range at −25°..−20° E.
        let z: Vec<f32> = mesh
            .positions
            .iter()
            .map(|&p| {
                let (la, lo) = (lat(p), lon(p));
                if (15.0..75.0).contains(&la) && (-40.0..40.0).contains(&lo) {
                    if (-25.0..-20.0).contains(&lo) {
                        3.0
                    } else {
                        0.3
                    }
                } else {
                    -4.0
                }
            })
            .collect();
        let rain = |params: &ClimateParams| {
            let mut out = Vec::new();
            precipitation(
                &g,
                &mesh.positions,
                &z,
                params,
                &mut out,
                &mut ClimateScratch::default(),
            );
            out
        };
        let params = ClimateParams::default();
        let out = rain(&params);
        let mean_in = |out: &[f32], lo0: f64, lo1: f64| {
            let v: Vec<f64> = mesh
                .positions
                .iter()
                .zip(out)
                .filter(|(p, _)| (40.0..50.0).contains(&lat(**p)) && (lo0..lo1).contains(&lon(**p)))
                .map(|(_, &r)| f64::from(r))
                .collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        let windward = mean_in(&out, -40.0, -25.0);
        let shadow = mean_in(&out, -15.0, 0.0);
        let lee_coast = mean_in(&out, 30.0, 40.0);
        assert!(
            shadow < 0.5 * windward,
            "shadow {shadow} windward {windward}"
        );
        assert!(lee_coast > shadow, "coast {lee_coast} shadow {shadow}");
        // The shadow is the range's: without the climb's cost the same land is far wetter.
        let flat = rain(&ClimateParams {
            orographic_height_km: 0.0,
            ..params
        });
        let (w0, s0) = (mean_in(&flat, -40.0, -25.0), mean_in(&flat, -15.0, 0.0));
        assert!(
            s0 > 1.5 * shadow,
            "no climb: shadow {s0} windward {w0}, with it {shadow}"
        );
        // Against the wind the interior dries out faster: the land just east of the west coast
        // (downwind of the sea) is wetter than as far inland from the east coast (upwind).
        let calm = rain(&ClimateParams {
            orographic_height_km: 0.0,
            windward_slope: 0.0,
            ..params
        });
        let (west, east) = (mean_in(&calm, -35.0, -28.0), mean_in(&calm, 28.0, 35.0));
        assert!(west > 1.2 * east, "downwind {west} upwind {east}");
        // The land's area-weighted mean is 1.
        let (mut s, mut a) = (0.0, 0.0);
        for i in 0..mesh.len() {
            if z[i] > 0.0 {
                s += f64::from(out[i]) * mesh.area_km2[i];
                a += mesh.area_km2[i];
            }
        }
        assert!((s / a - 1.0).abs() < 1e-3, "{}", s / a);
    }

    /// The same bits with one thread and with two (the sums run over fixed chunks, in order).
    #[test]
    fn the_rain_does_not_depend_on_the_thread_count() {
        let mesh = SphereMesh::fibonacci(30_000, 0.5, 5, 6371.0).expect("mesh");
        let g = graph(&mesh);
        let z: Vec<f32> = mesh
            .positions
            .iter()
            .map(|p| (3.0 * (4.0 * p.x).sin() * (3.0 * p.y).cos() + p.z) as f32)
            .collect();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut out = Vec::new();
                precipitation(
                    &g,
                    &mesh.positions,
                    &z,
                    &ClimateParams::default(),
                    &mut out,
                    &mut ClimateScratch::default(),
                );
                out.iter().map(|v| v.to_bits()).collect::<Vec<u32>>()
            })
        };
        let one = run(1);
        assert!(one.iter().any(|&b| f32::from_bits(b) != 1.0));
        assert_eq!(one, run(2));
        assert_eq!(one, run(3));
    }

    /// A scratch whose search was released (the mesh's tables kept, as through a resampling)
    /// gives a new surface the rain a fresh scratch gives it.
    #[test]
    fn the_rain_after_a_released_search_is_a_fresh_scratchs() {
        let mesh = SphereMesh::fibonacci(20_000, 0.5, 7, 6371.0).expect("mesh");
        let g = graph(&mesh);
        let surface = |k: f64| -> Vec<f32> {
            mesh.positions
                .iter()
                .map(|p| (2.0 * (k * p.x).sin() * (3.0 * p.y).cos() + 0.3 * p.z) as f32)
                .collect()
        };
        let rain = |z: &[f32], s: &mut ClimateScratch| {
            let mut out = Vec::new();
            precipitation(
                &g,
                &mesh.positions,
                z,
                &ClimateParams::default(),
                &mut out,
                s,
            );
            out.iter().map(|v| v.to_bits()).collect::<Vec<u32>>()
        };
        let mut kept = ClimateScratch::default();
        rain(&surface(4.0), &mut kept);
        kept.release_search();
        assert_eq!(kept.along.len(), g.neighbors.len(), "the tables went");
        let other = surface(7.0);
        let fresh = rain(&other, &mut ClimateScratch::default());
        assert!(fresh.iter().any(|&b| f32::from_bits(b) != 1.0));
        assert_eq!(rain(&other, &mut kept), fresh);
    }
}
