//! Stage 3 of a resampling: the samples no plate covers (gaps between diverging plates), each
//! with its two nearest plates, handed to the gap fillers (new oceanic crust). See [`super`].
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use super::*;
use crate::geometry::{SphereMesh, angle_between};
use crate::resources::{Crust, NO_PLATE};

/// The nearest covered sample of one plate, seen from a gap sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GapNeighbour {
    /// Plate id.
    pub plate: u32,
    /// The covered sample (reference index) nearest to the gap sample.
    pub seed: u32,
    /// Great-circle distance from the gap sample to the seed, radians.
    pub distance_rad: f64,
}

/// A sample no plate covered, with its nearest and second-nearest plates (different plates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GapSample {
    /// Reference sample index.
    pub sample: u32,
    /// Nearest plate (None only if no plate exists at all).
    pub nearest: Option<GapNeighbour>,
    /// Nearest other plate (None when the gap touches a single plate).
    pub second: Option<GapNeighbour>,
}

/// For every gap sample, the nearest covered sample of the nearest plate and of the nearest other
/// plate. Labels spread from the covered samples bordering the gaps through the gap samples in
/// order of true great-circle distance to their seed (never hop counts), two labels of distinct
/// plates per sample at most.
///
/// A label moves only from a gap sample to a neighbouring gap sample, so each connected run of
/// gaps (a strip along one divergent boundary) is searched on its own, the runs in parallel,
/// largest first: within a run the labels are taken in the same order as by one search over all
/// the gaps (the same buckets, the same order of insertion), so the result is the same.
pub fn nearest_two_plates(mesh: &SphereMesh, plate: &[u32], gaps: &[u32]) -> Vec<GapSample> {
    let mut out: Vec<GapSample> = gaps
        .iter()
        .map(|&g| GapSample {
            sample: g,
            nearest: None,
            second: None,
        })
        .collect();
    if gaps.is_empty() {
        return out;
    }
    let mut gap_index = vec![u32::MAX; mesh.len()];
    for (k, &g) in gaps.iter().enumerate() {
        gap_index[g as usize] = k as u32;
    }
    // The runs: each a list of gap indices, ascending; `local[k]` is gap k's place in its run.
    let mut local = vec![u32::MAX; gaps.len()];
    let mut runs: Vec<Vec<u32>> = Vec::new();
    let mut stack = Vec::new();
    for k0 in 0..gaps.len() {
        if local[k0] != u32::MAX {
            continue;
        }
        let mut run = vec![k0 as u32];
        local[k0] = 0;
        stack.push(k0 as u32);
        while let Some(k) = stack.pop() {
            for &h in mesh.neighbors_of(gaps[k as usize] as usize) {
                let kh = gap_index[h as usize];
                if kh != u32::MAX && local[kh as usize] == u32::MAX {
                    local[kh as usize] = 0;
                    run.push(kh);
                    stack.push(kh);
                }
            }
        }
        run.sort_unstable();
        for (i, &k) in run.iter().enumerate() {
            local[k as usize] = i as u32;
        }
        runs.push(run);
    }
    runs.sort_by_key(|r| std::cmp::Reverse(r.len()));
    let (gap_index, local) = (&gap_index, &local);
    // One run a task (`with_max_len(1)`): with rayon's default splitting the first quarter of
    // the list, the largest runs, would be searched one after the other on one thread.
    let labels: Vec<Vec<Labels>> = runs
        .par_iter()
        .with_max_len(1)
        .map(|run| search_run(mesh, plate, gaps, gap_index, local, run))
        .collect();
    for (run, labels) in runs.iter().zip(labels) {
        for (&k, (nearest, second)) in run.iter().zip(labels) {
            out[k as usize].nearest = nearest;
            out[k as usize].second = second;
        }
    }
    out
}

/// The nearest and second-nearest plate of one gap sample.
type Labels = (Option<GapNeighbour>, Option<GapNeighbour>);

/// The search of [`nearest_two_plates`] over one run of gaps (`run`: its gap indices, ascending;
/// `local`: each gap's place in its run). Returns the labels of the run's samples, in its order.
fn search_run(
    mesh: &SphereMesh,
    plate: &[u32],
    gaps: &[u32],
    gap_index: &[u32],
    local: &[u32],
    run: &[u32],
) -> Vec<Labels> {
    let mut out: Vec<Labels> = vec![(None, None); run.len()];
    let pos = &mesh.positions;
    // Bucket queue keyed by distance (Dial's algorithm): a quarter of the mean spacing per
    // bucket. Inside a bucket, entries are taken in insertion order, which is deterministic.
    let width = 0.25 * mesh.mean_spacing_rad();
    let mut buckets: Vec<Vec<(u32, u32, f64)>> = Vec::new();
    let push =
        |buckets: &mut Vec<Vec<(u32, u32, f64)>>, current: usize, d: f64, node: u32, seed: u32| {
            let b = ((d / width) as usize).max(current);
            if b >= buckets.len() {
                buckets.resize_with(b + 1, Vec::new);
            }
            buckets[b].push((node, seed, d));
        };
    for &k in run {
        let g = gaps[k as usize];
        for &nb in mesh.neighbors_of(g as usize) {
            if gap_index[nb as usize] == u32::MAX && plate[nb as usize] != NO_PLATE {
                let d = angle_between(pos[g as usize], pos[nb as usize]);
                push(&mut buckets, 0, d, g, nb);
            }
        }
    }
    let at = |node: u32| local[gap_index[node as usize] as usize] as usize;
    let mut current = 0;
    while current < buckets.len() {
        let mut k = 0;
        while k < buckets[current].len() {
            let (node, seed, d) = buckets[current][k];
            k += 1;
            let p = plate[seed as usize];
            let label = GapNeighbour {
                plate: p,
                seed,
                distance_rad: d,
            };
            let gs = &mut out[at(node)];
            match *gs {
                (None, _) => gs.0 = Some(label),
                (Some(a), None) if a.plate != p => gs.1 = Some(label),
                _ => continue,
            }
            let seed_pos = pos[seed as usize];
            for &h in mesh.neighbors_of(node as usize) {
                if gap_index[h as usize] == u32::MAX {
                    continue;
                }
                let o = &out[at(h)];
                if o.1.is_some() || o.0.is_some_and(|a| a.plate == p) {
                    continue;
                }
                let dh = angle_between(pos[h as usize], seed_pos);
                push(&mut buckets, current, dh, h, seed);
            }
        }
        buckets[current] = Vec::new();
        current += 1;
    }
    out
}

/// The gap samples of a resampling (sources no plate covers), with their two nearest plates,
/// each filled for now with a copy of its nearest covered sample ([`fill_gaps_from_nearest`]).
pub fn gaps_from_nearest(
    mesh: &SphereMesh,
    sources: &[SampleSource],
    next: &mut Crust,
) -> Vec<GapSample> {
    let gap_ids: Vec<u32> = sources
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_gap())
        .map(|(j, _)| j as u32)
        .collect();
    let gaps = nearest_two_plates(mesh, &next.plate, &gap_ids);
    fill_gaps_from_nearest(next, &gaps);
    gaps
}

/// Fills each gap sample with a copy of its nearest covered sample (the fallback when no gap
/// filler such as the oceanic-crust plugin runs): the nearest plate simply stretches.
pub fn fill_gaps_from_nearest(next: &mut Crust, gaps: &[GapSample]) {
    for g in gaps {
        let Some(a) = g.nearest else { continue };
        let (j, s) = (g.sample as usize, a.seed as usize);
        next.elevation_km[j] = next.elevation_km[s];
        next.thickness_km[j] = next.thickness_km[s];
        next.crust_type[j] = next.crust_type[s];
        next.age_my[j] = next.age_my[s];
        next.ridge_dir[j] = next.ridge_dir[s];
        next.orogeny[j] = next.orogeny[s];
        next.orogeny_age_my[j] = next.orogeny_age_my[s];
        next.fold_dir[j] = next.fold_dir[s];
        next.plate[j] = a.plate;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// One search over all the gaps at once (what [`nearest_two_plates`] did before it split
    /// them into runs): [`search_run`] with every gap in a single run.
    fn one_search(mesh: &SphereMesh, plate: &[u32], gaps: &[u32]) -> Vec<GapSample> {
        let mut index = vec![u32::MAX; mesh.len()];
        for (k, &g) in gaps.iter().enumerate() {
            index[g as usize] = k as u32;
        }
        let all: Vec<u32> = (0..gaps.len() as u32).collect();
        search_run(mesh, plate, gaps, &index, &all, &all)
            .into_iter()
            .zip(gaps)
            .map(|((nearest, second), &sample)| GapSample {
                sample,
                nearest,
                second,
            })
            .collect()
    }

    /// Gaps in many runs (strips along the boundaries of eight plates, and scattered holes),
    /// searched run by run in parallel, give the one search's labels bit for bit.
    #[test]
    fn runs_of_gaps_give_the_labels_of_one_search() {
        let mesh = SphereMesh::fibonacci(30_000, 0.3, 7, 6371.0).expect("mesh");
        let sector = |p: DVec3| {
            let lon = p.y.atan2(p.x) + std::f64::consts::PI;
            let k = (lon / (std::f64::consts::TAU / 4.0)) as u32;
            k.min(3) + 4 * u32::from(p.z > 0.1 * (3.0 * lon).sin())
        };
        let plate: Vec<u32> = mesh.positions.iter().map(|&p| sector(p)).collect();
        // Gaps: samples with a neighbour of another plate, thickened by one ring where the
        // longitude says so (runs of varied width), and every 97th sample (holes of one).
        let border = |i: usize| {
            mesh.neighbors_of(i)
                .iter()
                .any(|&j| plate[j as usize] != plate[i])
        };
        let is_gap: Vec<bool> = (0..mesh.len())
            .map(|i| {
                border(i)
                    || i % 97 == 0
                    || (mesh.positions[i].x > 0.3
                        && mesh.neighbors_of(i).iter().any(|&j| border(j as usize)))
            })
            .collect();
        let gaps: Vec<u32> = (0..mesh.len() as u32)
            .filter(|&i| is_gap[i as usize])
            .collect();
        let mut plate_now = plate.clone();
        for &g in &gaps {
            plate_now[g as usize] = NO_PLATE;
        }
        let got = nearest_two_plates(&mesh, &plate_now, &gaps);
        let want = one_search(&mesh, &plate_now, &gaps);
        assert_eq!(got.len(), want.len());
        let seconds = want.iter().filter(|g| g.second.is_some()).count();
        assert!(
            seconds > 100,
            "only {seconds} gap samples between two plates"
        );
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g, w, "gap sample {}", w.sample);
        }
    }
}
