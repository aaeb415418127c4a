//! Convergent boundaries (paper §4.1, §4.2, §6; Driftworld §3.8, §3.9, §3.13): subduction
//! fronts, subduction uplift and trenches, slab pull, terranes and continental collisions.
//!
//! How the pieces fit, and the choices made where the paper is vague:
//! - **Fronts** are found at each resampling, when every plate is in the reference frame: a
//!   plate-boundary edge whose plates approach each other faster than
//!   `subduction.min_convergence_mm_per_yr` is converging; connected runs of such edges between
//!   the same two plates form one front. Who goes under is decided per front as the paper does:
//!   oceanic under continental, the older of two oceanic plates, and for continent against
//!   continent a forced subduction of the plate with the lower overlap score. The front's
//!   points are the overriding plate's boundary samples. The front is fixed in the overriding
//!   plate's frame until the next resampling (the subducting plate slides under it).
//! - **Distances** to the front are great-circle distances (never hop counts), propagated once
//!   per resampling through each plate's own samples: for the overriding plate, the distance of
//!   each sample to the nearest front point (uplift); for the subducting plate, the distance of
//!   each sample to the front at the resampling, from which the distance now is that minus the
//!   convergence accumulated at its front point since (trench, interpenetration).
//! - **Uplift** on the overriding plate: ũ = u0·f(d)·g(v)·h(z̃) with Driftworld's cubic f (peak 1
//!   at the control distance, 0 at r_s; its small negative part near the front is clipped to 0,
//!   since the trench is made on the subducting side), g = v/v0 and h = z̃², z̃ the normalised
//!   elevation of the subducting crust now at the front point (located in the subducting plate
//!   every step). Elevations are capped at z_c. Uplifted crust above sea level gets Andean
//!   orogeny with its age reset (island arcs stay oceanic crust: turning emerged arcs into
//!   continental crust grew the default planet's continents by 13% per 1000 My at 500,000
//!   samples); fold directions take β·(s_sub − s_over)·δt.
//! - **Trench**: oceanic crust of the subducting plate within `subduction.trench_width_km` of the
//!   front deepens toward a profile from z_t at the front to z_a at the trench edge.
//! - **Slab pull**: w ← normalise(w + 0.01·ε·Σ_k (c × q_k)/|c × q_k|·(ℓ_k/R)·δt) over the active
//!   front points q_k of the subducting plate, each weighted by the front length ℓ_k it stands
//!   for, so the effect depends on the length of the front, not on the sample count.
//! - **Collisions** fire when continental crust of a subducting plate is more than
//!   `collision.interpenetration_km` past a front where the overriding crust is continental too
//!   (and at any depth when a resampling is about to run, so that no continental crust is lost
//!   under another plate). The smaller of the two terranes in contact leaves its plate at once
//!   as a plate of its own that keeps its old plate's frame and moves with the other plate, and
//!   sutures to that plate at the next regular resampling (the default); with
//!   `collision.resample_at_suture` on (the paper's way), the collision forces a resampling in
//!   its step and sutures there. Then the crust around the suture (d measured
//!   from the terrane's samples that touch the plate it joins) rises by Δz = Δz₀·(1 − (d/r)²)²
//!   and thickens by Δz/(1 − ρ_c/ρ_m), r = r_c·min(1, √(v/v0·A/A0)), Δz₀ = H·(1 − exp(−Δ_c·A/H)) (the
//!   paper's Δ_c·A for small terranes, saturating at H = `collision.max_uplift_km` for
//!   continents, since Δ_c·A alone gives tens of kilometres for a continent), with Himalayan
//!   orogeny and fold directions pointing away from the terrane centroid.
#![allow(clippy::needless_range_loop)]

pub mod collision;
pub mod fronts;
pub mod slab_pull;
pub mod subduction;
pub mod terranes;

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::SphereMesh;

/// Nearest-seed propagation through the mesh in order of true great-circle distance to the
/// seed point (a bucket queue, as for the gaps). `seeds` are (sample, label) pairs; the
/// distance is measured to `origin(label)`; a sample is reached only if `allowed(sample,
/// label)`; nothing farther than `max_rad`. Writes distances (radians) and labels of reached
/// samples; others keep their values.
#[allow(clippy::too_many_arguments)]
pub fn propagate_nearest(
    mesh: &SphereMesh,
    seeds: &[(u32, u32)],
    origin: impl Fn(u32) -> DVec3,
    allowed: impl Fn(usize, u32) -> bool,
    max_rad: f64,
    dist_rad: &mut [f32],
    label: &mut [u32],
    settled: &mut Vec<bool>,
) {
    settled.clear();
    settled.resize(mesh.len(), false);
    propagate_core(
        mesh,
        seeds,
        &origin,
        &allowed,
        |i| i,
        max_rad,
        dist_rad,
        label,
        settled,
    );
    chords_to_angles(dist_rad);
}

/// [`propagate_nearest`] for samples and labels that fall in groups (plates) that never reach
/// one another: label `l` reaches sample `s` only when `group_of_sample[s] ==
/// group_of_label(l)`. Each group with seeds runs on arrays of its own, the groups in parallel;
/// the distances and labels are the same bits as [`propagate_nearest`]'s with `allowed` that
/// test (a group's searches read and write only its own samples, in the same order).
#[allow(clippy::too_many_arguments)]
pub fn propagate_nearest_grouped(
    mesh: &SphereMesh,
    seeds: &[(u32, u32)],
    origin: impl Fn(u32) -> DVec3 + Sync,
    group_of_sample: &[u32],
    group_of_label: impl Fn(u32) -> u32 + Sync,
    max_rad: f64,
    dist_rad: &mut [f32],
    label: &mut [u32],
) {
    let n = mesh.len().min(group_of_sample.len());
    // Each group's seeds, in their order; groups numbered in order of first seed. Groups are
    // plate ids: their slots are a table by id (a hash lookup per sample cost 5–10 ms a field).
    const NO_SLOT: u32 = u32::MAX;
    let mut slot_by_group: Vec<u32> = Vec::new();
    let mut groups: Vec<(u32, Vec<(u32, u32)>)> = Vec::new();
    for &(s, l) in seeds {
        let g = group_of_label(l) as usize;
        if g >= slot_by_group.len() {
            slot_by_group.resize(g + 1, NO_SLOT);
        }
        if slot_by_group[g] == NO_SLOT {
            slot_by_group[g] = groups.len() as u32;
            groups.push((g as u32, Vec::new()));
        }
        groups[slot_by_group[g] as usize].1.push((s, l));
    }
    // The members of each group with seeds, in sample order, and each sample's place there.
    let slot: Vec<u32> = group_of_sample[..n]
        .par_iter()
        .with_min_len(8192)
        .map(|&g| slot_by_group.get(g as usize).copied().unwrap_or(NO_SLOT))
        .collect();
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); groups.len()];
    let mut local = vec![0u32; n];
    for (i, &k) in slot.iter().enumerate() {
        if k != NO_SLOT {
            let m = &mut members[k as usize];
            local[i] = m.len() as u32;
            m.push(i as u32);
        }
    }
    let (origin, group_of_sample, local_ref) = (&origin, &group_of_sample[..n], &local);
    let (dist_in, label_in) = (&*dist_rad, &*label);
    // Largest groups first, so that the last tasks are small.
    let mut order: Vec<usize> = (0..groups.len()).collect();
    order.sort_by_key(|&k| std::cmp::Reverse(members[k].len()));
    let mut results: Vec<(usize, Vec<f32>, Vec<u32>)> = order
        .par_iter()
        .map(|&k| {
            let (g, ref group_seeds) = groups[k];
            let mem = &members[k];
            let mut d: Vec<f32> = mem.iter().map(|&i| dist_in[i as usize]).collect();
            let mut lab: Vec<u32> = mem.iter().map(|&i| label_in[i as usize]).collect();
            let mut settled = vec![false; mem.len()];
            propagate_core(
                mesh,
                group_seeds,
                origin,
                &|s: usize, _l: u32| group_of_sample.get(s) == Some(&g),
                |i| local_ref[i] as usize,
                max_rad,
                &mut d,
                &mut lab,
                &mut settled,
            );
            (k, d, lab)
        })
        .collect();
    results.sort_unstable_by_key(|r| r.0);
    let results = &results;
    dist_rad[..n]
        .par_iter_mut()
        .zip(label[..n].par_iter_mut())
        .enumerate()
        .with_min_len(8192)
        .for_each(|(i, (d, l))| {
            let k = slot[i];
            if k != NO_SLOT {
                let (_, ref ds, ref ls) = results[k as usize];
                *d = ds[local_ref[i] as usize];
                *l = ls[local_ref[i] as usize];
            }
        });
    chords_to_angles(dist_rad);
}

/// The search of [`propagate_nearest`] with chords for distances: sample `i`'s distance, label
/// and settled flag at index `at(i)` of `dist`, `label` and `settled`.
#[allow(clippy::too_many_arguments)]
fn propagate_core(
    mesh: &SphereMesh,
    seeds: &[(u32, u32)],
    origin: &impl Fn(u32) -> DVec3,
    allowed: &impl Fn(usize, u32) -> bool,
    at: impl Fn(usize) -> usize,
    max_rad: f64,
    dist: &mut [f32],
    label: &mut [u32],
    settled: &mut [bool],
) {
    // Ordered by chord length (monotone in the great-circle angle, and much cheaper). While the
    // search runs, `dist` holds the best chord offered so far (a worse offer is not queued)
    // and `label` its front point; chords become angles at the end.
    let max_chord = 2.0 * (0.5 * max_rad.min(std::f64::consts::PI)).sin();
    // A squared chord above this is surely past `max_chord` once its root is taken (the bound
    // leaves room for the rounding of both), so the root is not taken.
    let far_sq = max_chord * max_chord * (1.0 + 1e-9);
    let width = 0.5 * mesh.mean_spacing_rad();
    let mut buckets: Vec<Vec<(u32, u32, f32)>> = Vec::new();
    // Emptied buckets, their room kept for the buckets further out.
    let mut spare: Vec<Vec<(u32, u32, f32)>> = Vec::new();
    // Offers chord `c` from label `l` to `node` (at index `a`).
    let offer = |buckets: &mut Vec<Vec<(u32, u32, f32)>>,
                 spare: &mut Vec<Vec<(u32, u32, f32)>>,
                 dist: &mut [f32],
                 lab: &mut [u32],
                 cur: usize,
                 c: f64,
                 node: u32,
                 a: usize,
                 l: u32| {
        if c > max_chord || (c as f32) >= dist[a] {
            return;
        }
        dist[a] = c as f32;
        lab[a] = l;
        let b = ((c / width) as usize).max(cur);
        while b >= buckets.len() {
            buckets.push(spare.pop().unwrap_or_default());
        }
        buckets[b].push((node, l, c as f32));
    };
    for &(s, l) in seeds {
        if allowed(s as usize, l) {
            let c = (mesh.positions[s as usize] - origin(l)).length();
            offer(
                &mut buckets,
                &mut spare,
                dist,
                label,
                0,
                c,
                s,
                at(s as usize),
                l,
            );
        }
    }
    let mut cur = 0;
    while cur < buckets.len() {
        let mut k = 0;
        while k < buckets[cur].len() {
            let (node, l, c) = buckets[cur][k];
            k += 1;
            let n = node as usize;
            let a = at(n);
            if settled[a] || label[a] != l || c > dist[a] {
                continue; // settled already, or a better offer came later
            }
            settled[a] = true;
            let o = origin(l);
            for &h in mesh.neighbors_of(n) {
                let h = h as usize;
                if !allowed(h, l) {
                    continue;
                }
                let ah = at(h);
                if settled[ah] {
                    continue;
                }
                let d = mesh.positions[h] - o;
                let sq = d.length_squared();
                if sq > far_sq {
                    continue;
                }
                offer(
                    &mut buckets,
                    &mut spare,
                    dist,
                    label,
                    cur,
                    sq.sqrt(),
                    h as u32,
                    ah,
                    l,
                );
            }
        }
        let mut done = std::mem::take(&mut buckets[cur]);
        done.clear();
        spare.push(done);
        cur += 1;
    }
}

/// Turns the finite chords of `dist` into great-circle angles (radians).
fn chords_to_angles(dist: &mut [f32]) {
    dist.par_iter_mut().with_min_len(4096).for_each(|d| {
        if d.is_finite() {
            *d = (2.0 * (0.5 * *d as f64).min(1.0).asin()) as f32;
        }
    });
}
