//! Stage 2 of a resampling: every field of the covering plate interpolated at each sample
//! ([`interpolate`](fn@interpolate), the CPU reference of `shaders/resample_interpolate.wgsl`), and continental
//! crust that went under another plate displaced rather than lost. See [`super`].
#![allow(clippy::needless_range_loop)]

use glam::DVec3;
use rayon::prelude::*;

use super::*;
use crate::geometry::SphereMesh;
use crate::resources::{Crust, CrustType, NO_PLATE, PlateTable};

/// Interpolates every field of `old` at the sources into `next` (gap samples get zeros and
/// `NO_PLATE`). Scalars are barycentric; the crust type is a weighted vote; other categories
/// come from the nearest vertex; direction
/// fields are interpolated in the plate frame, rotated to the world and projected onto the
/// tangent plane.
pub fn interpolate(
    mesh: &SphereMesh,
    old: &Crust,
    table: &PlateTable,
    sources: &[SampleSource],
    next: &mut Crust,
) {
    next.resize(mesh.len());
    let Crust {
        elevation_km,
        thickness_km,
        crust_type,
        age_my,
        ridge_dir,
        orogeny,
        orogeny_age_my,
        fold_dir,
        plate,
    } = next;
    (
        elevation_km.par_iter_mut(),
        thickness_km.par_iter_mut(),
        crust_type.par_iter_mut(),
        age_my.par_iter_mut(),
        ridge_dir.par_iter_mut(),
        orogeny.par_iter_mut(),
        orogeny_age_my.par_iter_mut(),
        fold_dir.par_iter_mut(),
        plate.par_iter_mut(),
        sources.par_iter(),
        mesh.positions.par_iter(),
    )
        .into_par_iter()
        .with_min_len(1024)
        .for_each(|(z, e, ct, age, rd, og, oga, fd, pl, src, &q)| {
            if src.is_gap() {
                *z = 0.0;
                *e = 0.0;
                *ct = CrustType::Oceanic;
                *age = 0.0;
                *rd = [0.0; 3];
                *og = Default::default();
                *oga = 0.0;
                *fd = [0.0; 3];
                *pl = NO_PLATE;
                return;
            }
            let t = mesh.triangles[src.triangle as usize];
            let v = [t[0] as usize, t[1] as usize, t[2] as usize];
            let plate_state = &table.plates[src.slot as usize];
            // A vertex of another plate carries valid data here only if that plate moved exactly
            // like the covering one (same frame); otherwise its crust would be copied to where it
            // is not (smearing continental margins across divergent boundaries at every
            // resampling), so only the covering plate's vertices and its co-moving neighbours'
            // count.
            let mut w_all = src.weights.map(|w| w as f64);
            let valid = |k: usize| {
                let p = old.plate[v[k]];
                p == plate_state.id
                    || table
                        .get(p)
                        .is_some_and(|o| o.world_from_plate == plate_state.world_from_plate)
            };
            let kept: f64 = (0..3).filter(|&k| valid(k)).map(|k| w_all[k]).sum();
            if kept > 0.0 && kept < 1.0 {
                for k in 0..3 {
                    w_all[k] = if valid(k) { w_all[k] / kept } else { 0.0 };
                }
            }
            // Crust type by weighted vote (the 0.5 level of the interpolated indicator): smoother
            // coastlines than the nearest vertex, which roughens them at every resampling.
            let cont: f64 = (0..3)
                .filter(|&k| old.crust_type[v[k]] == CrustType::Continental)
                .map(|k| w_all[k])
                .sum();
            let out_type = if cont > 0.5 {
                CrustType::Continental
            } else {
                CrustType::Oceanic
            };
            // Scalars are interpolated over the vertices of the sample's own crust type only, so
            // a coast never mixes trench depths into continents or mountains into the ocean.
            let same = if out_type == CrustType::Continental {
                cont
            } else {
                1.0 - cont
            };
            let w = if same > 0.0 {
                let mut m = [0.0; 3];
                for k in 0..3 {
                    if old.crust_type[v[k]] == out_type {
                        m[k] = w_all[k] / same;
                    }
                }
                m
            } else {
                w_all
            };
            let lerp = |f: &[f32]| {
                (w[0] * f[v[0]] as f64 + w[1] * f[v[1]] as f64 + w[2] * f[v[2]] as f64) as f32
            };
            let dir = |f: &[[f32; 3]]| -> [f32; 3] {
                let mut acc = DVec3::ZERO;
                for k in 0..3 {
                    let a = f[v[k]];
                    acc += DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64) * w[k];
                }
                if acc == DVec3::ZERO {
                    return [0.0; 3];
                }
                let world = plate_state.world_from_plate * acc;
                let t = world - q * q.dot(world);
                [t.x as f32, t.y as f32, t.z as f32]
            };
            let d = v[crate::geometry::locator::dominant_corner(&w)];
            *z = lerp(&old.elevation_km);
            *e = lerp(&old.thickness_km);
            *ct = out_type;
            *age = lerp(&old.age_my);
            *rd = dir(&old.ridge_dir);
            *og = old.orogeny[d];
            *oga = lerp(&old.orogeny_age_my);
            *fd = dir(&old.fold_dir);
            *pl = src.plate;
        });
}

/// Continental crust is never destroyed: where a plate's continental crust went under another
/// plate's continental crust (counted in [`SampleSource::continental_lost`]), the crust on top
/// takes the place, and as many oceanic samples of the same plate as were overridden, the ones
/// closest to the overlap (breadth-first through the plate), become continental with the
/// elevation and orogeny of the crust next to them: the thickened crust of the orogen spreads
/// outward instead of vanishing. Deterministic (plates by id, samples in index order).
pub fn displace_overridden_continents(
    mesh: &SphereMesh,
    sources: &[SampleSource],
    next: &mut Crust,
) {
    displace_with(mesh, sources, next, true);
}

/// [`displace_overridden_continents`]; `skip_futile_claims` false walks every claim, even one
/// that cannot turn anything (the same result, slower: for the test that says so). Returns the
/// number of claims skipped.
fn displace_with(
    mesh: &SphereMesh,
    sources: &[SampleSource],
    next: &mut Crust,
    skip_futile_claims: bool,
) -> usize {
    let mut skipped = 0;
    let mut by_plate: std::collections::BTreeMap<u32, Vec<u32>> = std::collections::BTreeMap::new();
    for (j, src) in sources.iter().enumerate() {
        if src.continental_lost && next.plate[j] != NO_PLATE {
            by_plate.entry(next.plate[j]).or_default().push(j as u32);
        }
    }
    if by_plate.is_empty() {
        return 0;
    }
    let mut visited = vec![false; mesh.len()];
    let (mut lost, mut moved, mut spilled) = (0usize, 0usize, 0usize);
    for (plate, starts) in by_plate {
        lost += starts.len();
        // First within the plate; what a plate without enough ocean of its own (a continental
        // fragment fresh from a rift, or a plate that is all continent) cannot take, it takes
        // from the neighbouring plates' ocean next to it, which joins the plate: the continent
        // grows outward over the adjacent ocean floor.
        let debt = spread_continent(
            mesh,
            next,
            &starts,
            starts.len(),
            Spread::Within(plate),
            &mut visited,
        );
        moved += starts.len() - debt;
        if debt > 0 {
            visited.iter_mut().for_each(|v| *v = false);
            // A claim turns ocean only next to continent it walks from: a start, this plate's
            // continent, or what it turned. With none (a plate without continent whose crust on
            // top at the starts is ocean) it would turn nothing and only walk all the ocean of
            // the globe (up to two thirds of the samples, 8–14 ms at 500k, most resamplings).
            let can_turn = !skip_futile_claims
                || starts
                    .iter()
                    .any(|&s| next.crust_type[s as usize] == CrustType::Continental)
                || next
                    .plate
                    .par_iter()
                    .zip(next.crust_type.par_iter())
                    .with_min_len(8192)
                    .any(|(&q, &t)| q == plate && t == CrustType::Continental);
            let left = if can_turn {
                spread_continent(
                    mesh,
                    next,
                    &starts,
                    debt,
                    Spread::Claim(plate),
                    &mut visited,
                )
            } else {
                tracing::trace!(plate, debt, "no continent to claim from: the claim skipped");
                skipped += 1;
                debt
            };
            spilled += debt - left;
            moved += debt - left;
            if left > 0 {
                // Landlocked (its continent borders no ocean at all): as a last resort the
                // nearest ocean bordering any continent turns continental, keeping its plate.
                visited.iter_mut().for_each(|v| *v = false);
                let rest =
                    spread_continent(mesh, next, &starts, left, Spread::Anywhere, &mut visited);
                spilled += left - rest;
                moved += left - rest;
            }
        }
        visited.iter_mut().for_each(|v| *v = false);
    }
    tracing::debug!(
        lost,
        moved,
        spilled,
        "overridden continental samples displaced"
    );
    skipped
}

/// Where [`spread_continent`] may turn ocean into continent.
#[derive(Clone, Copy)]
enum Spread {
    /// Only through and into this plate's samples.
    Within(u32),
    /// Through this plate's samples and the ocean of any plate; it turns ocean only next to
    /// continent it walks from (a start, this plate's continent, or what it turned), and the
    /// samples it turns join this plate (and carry the walk on), so the claim grows as a band
    /// along the coast nearest the overlap.
    Claim(u32),
    /// Through any plate, next to any continent; the samples keep their plate.
    Anywhere,
}

/// Breadth-first from `starts` (continental samples), turns up to `debt` oceanic samples next to
/// continental ones into continental crust with the elevation and orogeny of that neighbour.
/// Returns the debt left.
///
/// Every sample the walk leaves from is continental (a start, crust it walks through, or a sample
/// it turned), so while debt is left every ocean sample it reaches is turned, nearest the starts
/// first: the new crust grows as a band, never as a line running out across the ocean. (A claim
/// that walked through other plates' ocean once marked ocean reached from ocean as seen, so only
/// the tip of its front stayed turnable and it paid out as a crack two samples wide.)
fn spread_continent(
    mesh: &SphereMesh,
    next: &mut Crust,
    starts: &[u32],
    mut debt: usize,
    spread: Spread,
    visited: &mut [bool],
) -> usize {
    let mut queue: std::collections::VecDeque<u32> = starts.iter().copied().collect();
    for &s in starts {
        visited[s as usize] = true;
    }
    while let Some(u) = queue.pop_front() {
        if debt == 0 {
            break;
        }
        let u = u as usize;
        for &v in mesh.neighbors_of(u) {
            let v = v as usize;
            if visited[v] || next.plate[v] == NO_PLATE {
                continue;
            }
            let oceanic = next.crust_type[v] == CrustType::Oceanic;
            let walkable = match spread {
                Spread::Within(p) => next.plate[v] == p,
                Spread::Claim(p) => oceanic || next.plate[v] == p,
                Spread::Anywhere => true,
            };
            if !walkable {
                continue;
            }
            visited[v] = true;
            if oceanic && next.crust_type[u] == CrustType::Continental {
                if debt == 0 {
                    break;
                }
                next.crust_type[v] = CrustType::Continental;
                next.elevation_km[v] = next.elevation_km[u].max(0.0);
                // The crust it continues: no thin spot in a thickened orogen (with isostasy
                // on, that would stand kilometres low).
                next.thickness_km[v] = next.thickness_km[u];
                next.orogeny[v] = next.orogeny[u];
                next.orogeny_age_my[v] = next.orogeny_age_my[u];
                next.fold_dir[v] = next.fold_dir[u];
                if let Spread::Claim(p) = spread {
                    next.plate[v] = p;
                }
                debt -= 1;
            }
            queue.push_back(v as u32);
        }
    }
    debt
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hops from every sample to the nearest sample in `from` (through any sample).
    fn hops_from(mesh: &SphereMesh, from: impl Iterator<Item = usize>) -> Vec<u32> {
        let mut hops = vec![u32::MAX; mesh.len()];
        let mut queue = std::collections::VecDeque::new();
        for s in from {
            hops[s] = 0;
            queue.push_back(s);
        }
        while let Some(u) = queue.pop_front() {
            for &v in mesh.neighbors_of(u) {
                if hops[v as usize] == u32::MAX {
                    hops[v as usize] = hops[u] + 1;
                    queue.push_back(v as usize);
                }
            }
        }
        hops
    }

    /// An oceanic plate on top of lost continent, with no continent of its own, owes continent
    /// that its claim could not turn (it walks ocean only): skipping that claim changes nothing.
    /// With an island of its own across the ocean, the claim turns ocean beyond the island and
    /// must not be skipped.
    #[test]
    fn a_claim_is_skipped_only_when_it_cannot_turn_anything() {
        let mesh = SphereMesh::fibonacci(20_000, 0.5, 3, 6371.0).expect("mesh");
        let deg = |p: &DVec3, c: DVec3| p.dot(c).clamp(-1.0, 1.0).acos().to_degrees();
        let island_at = DVec3::new(1.0, 0.0, 0.0);
        for with_island in [false, true] {
            let mut next = Crust::with_len(mesh.len());
            let mut sources = vec![SampleSource::GAP; mesh.len()];
            for (s, p) in mesh.positions.iter().enumerate() {
                // Plate 1: an oceanic cap around the pole and, maybe, a continental island on
                // the equator, apart from it; plate 2: ocean everywhere else, and a continent
                // around the south pole (what the last resort turns ocean next to).
                let (plate, crust) = if deg(p, DVec3::Z) < 10.0 {
                    (1, CrustType::Oceanic)
                } else if with_island && deg(p, island_at) < 6.0 {
                    (1, CrustType::Continental)
                } else if deg(p, -DVec3::Z) < 20.0 {
                    (2, CrustType::Continental)
                } else {
                    (2, CrustType::Oceanic)
                };
                next.plate[s] = plate;
                next.crust_type[s] = crust;
                sources[s].plate = plate;
                sources[s].continental_lost = deg(p, DVec3::Z) < 3.0;
            }
            let mut walked = next.clone();
            let skipped = displace_with(&mesh, &sources, &mut next, true);
            assert_eq!(displace_with(&mesh, &sources, &mut walked, false), 0);
            assert_eq!(skipped, usize::from(!with_island), "island {with_island}");
            assert!(next == walked, "island {with_island}: another crust");
            if with_island {
                // The claim turned plate 2's ocean next to the island, which joined plate 1.
                let claimed = (0..mesh.len())
                    .filter(|&s| next.plate[s] == 1 && next.crust_type[s] == CrustType::Continental)
                    .filter(|&s| deg(&mesh.positions[s], island_at) >= 6.0)
                    .count();
                assert!(claimed > 0, "the claim turned nothing beyond the island");
            }
        }
    }

    /// A plate that is all continent owes continent where it lost its core, which the other
    /// plate's continent rings: the claim must come as a band on the nearest coast, not as a line
    /// running out across the ocean (seen on the default planet at 61° N before the claim walked
    /// through its own continent only). The plate's continent reaches the ocean only at a small
    /// cap, at the end of an isthmus through the other plate's continent.
    #[test]
    fn a_claim_grows_a_band_on_its_coast_not_a_crack() {
        let mesh = SphereMesh::fibonacci(20_000, 0.5, 3, 6371.0).expect("mesh");
        let mut next = Crust::with_len(mesh.len());
        let params = crate::resources::Params::default();
        let cap = DVec3::new(0.5, 0.0, 0.75_f64.sqrt());
        let deg = |p: &DVec3, c: DVec3| p.dot(c).clamp(-1.0, 1.0).acos().to_degrees();
        for (s, p) in mesh.positions.iter().enumerate() {
            let core = deg(p, DVec3::Z);
            let isthmus = p.x > 0.0 && p.y.abs() < 0.03 && core < 30.0;
            let (plate, crust) = if core < 8.0 || isthmus || deg(p, cap) < 3.0 {
                (1, CrustType::Continental)
            } else if core < 12.0 || (p.x > 0.0 && p.y.abs() < 0.12 && core < 25.0) {
                (2, CrustType::Continental)
            } else {
                (3, CrustType::Oceanic)
            };
            next.plate[s] = plate;
            next.crust_type[s] = crust;
            next.thickness_km[s] = params.nominal_thickness_km(crust) as f32;
        }
        // Plate 1 lost its core.
        let mut sources = vec![SampleSource::GAP; mesh.len()];
        let mut lost = 0;
        for s in 0..mesh.len() {
            sources[s].plate = next.plate[s];
            if deg(&mesh.positions[s], DVec3::Z) < 8.0 {
                sources[s].continental_lost = true;
                lost += 1;
            }
        }
        assert!(lost > 30, "{lost} samples lost");
        let before = next.clone();
        displace_overridden_continents(&mesh, &sources, &mut next);

        let turned: Vec<usize> = (0..mesh.len())
            .filter(|&s| {
                before.crust_type[s] == CrustType::Oceanic
                    && next.crust_type[s] == CrustType::Continental
            })
            .collect();
        assert_eq!(turned.len(), lost, "every lost sample paid back");
        assert!(turned.iter().all(|&s| next.plate[s] == 1));
        // A band as compact as it can be: no turned sample farther from plate 1's continent than
        // a disc of the debt's area would reach.
        let coast = hops_from(
            &mesh,
            (0..mesh.len()).filter(|&s| {
                before.plate[s] == 1 && before.crust_type[s] == CrustType::Continental
            }),
        );
        let reach = ((lost as f64 / std::f64::consts::PI).sqrt().ceil() as u32) + 1;
        let far = turned.iter().map(|&s| coast[s]).max().unwrap();
        assert!(
            far <= reach,
            "a turned sample {far} hops from the claiming continent (a disc of the debt reaches {reach})"
        );
    }
}
