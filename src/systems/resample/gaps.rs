//! Stage 3 of a resampling: the samples no plate covers (gaps between diverging plates), each
//! with its two nearest plates, handed to the gap fillers (new oceanic crust). See [`super`].
#![allow(clippy::needless_range_loop)]

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
    for &g in gaps {
        for &nb in mesh.neighbors_of(g as usize) {
            if gap_index[nb as usize] == u32::MAX && plate[nb as usize] != NO_PLATE {
                let d = angle_between(pos[g as usize], pos[nb as usize]);
                push(&mut buckets, 0, d, g, nb);
            }
        }
    }
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
            let gs = &mut out[gap_index[node as usize] as usize];
            match (gs.nearest, gs.second) {
                (None, _) => gs.nearest = Some(label),
                (Some(a), None) if a.plate != p => gs.second = Some(label),
                _ => continue,
            }
            let seed_pos = pos[seed as usize];
            for &h in mesh.neighbors_of(node as usize) {
                let kh = gap_index[h as usize];
                if kh == u32::MAX {
                    continue;
                }
                let o = &out[kh as usize];
                if o.second.is_some() || o.nearest.is_some_and(|a| a.plate == p) {
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
