//! Stage 1 of a resampling: which plate covers each reference sample, and where in that plate's
//! rotated triangulation ([`resample_locate_cpu`], one [`locate_one`] per sample; on the GPU
//! [`locate_on_gpu`](resample_locate_gpu), with the doubtful samples rechecked here in f64). See [`super`].
#![allow(clippy::needless_range_loop)]

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;

use super::*;
use crate::geometry::SphereMesh;
use crate::gpu::GpuContext;
use crate::gpu::GpuError;
use crate::gpu::resample_locate::{self, LocateReport};
use crate::resources::{Crust, CrustType, PlateTable};

/// Finds, for every reference sample, the plate that covers it and where (see module docs).
/// This is the CPU backend's point location and the reference of the GPU kernel
/// `shaders/resample_locate.wgsl` (`crate::gpu::resample_locate`).
pub fn resample_locate_cpu(
    mesh: &SphereMesh,
    old: &Crust,
    table: &PlateTable,
    rules: &OverlapRules,
    sources: &mut Vec<SampleSource>,
) {
    let t = crate::systems::DebugTimer::new("cell plates");
    let cell_plates = CellPlates::build(mesh, old, table);
    drop(t);
    sources.clear();
    sources.resize(mesh.len(), SampleSource::GAP);
    // Samples lie along a space-filling curve, so a run of consecutive samples is a small patch:
    // the plates whose bounding cap reaches the patch are found once for the run, in rank order
    // (the order `locate_one` compares them in), and each sample tests only those.
    const RUN: usize = 512;
    sources
        .par_chunks_mut(RUN)
        .enumerate()
        .for_each(|(r, chunk)| {
            let q = &mesh.positions[r * RUN..r * RUN + chunk.len()];
            let slots = plates_near(table, q);
            for (src, &q) in chunk.iter_mut().zip(q) {
                *src = locate_among(mesh, old, table, &cell_plates, rules, q, &slots);
            }
        });
}

/// The slots of `table`, in rank order, whose bounding cap may hold one of the points `q`
/// (a superset of the plates passing the cap test of [`locate_one`] at any of them).
fn plates_near(table: &PlateTable, q: &[DVec3]) -> Vec<u32> {
    let centre = q.iter().sum::<DVec3>().normalize_or_zero();
    if centre == DVec3::ZERO {
        return table.by_rank.clone();
    }
    // The patch's angular radius around its centre, with a margin (6 m) far above the
    // rounding of these angles (`acos` near 1 loses up to about 1e-8 rad).
    let reach = q
        .iter()
        .map(|p| p.dot(centre).clamp(-1.0, 1.0).acos())
        .fold(0.0f64, f64::max)
        + 1e-6;
    table
        .by_rank
        .iter()
        .copied()
        .filter(|&slot| {
            let p = &table.plates[slot as usize];
            let cap = p.cap_cos.clamp(-1.0, 1.0).acos();
            centre.dot(p.centroid_world).clamp(-1.0, 1.0).acos() <= cap + reach
        })
        .collect()
}

/// A plate covering a point from its core.
#[derive(Clone, Copy)]
struct CoreHit {
    source: SampleSource,
    sutured: bool,
    continental: bool,
}

/// The covering plate of world point `q` (see module docs); `SampleSource::GAP` if none.
///
/// Between plates covering the point from their core, in this order: crust of a terrane that
/// sutures in this resampling stays on top (and joins its new plate); continental crust stays
/// on top of oceanic crust (it does not subduct); the overriding plate of a subduction front
/// stays on top of the subducting one; otherwise the plate order (overlap score) decides.
#[inline]
pub fn locate_one(
    mesh: &SphereMesh,
    old: &Crust,
    table: &PlateTable,
    cells: &CellPlates,
    rules: &OverlapRules,
    q: DVec3,
) -> SampleSource {
    locate_among(mesh, old, table, cells, rules, q, &table.by_rank)
}

/// [`locate_one`] over the plates `slots` only (in rank order; every plate whose cap holds `q`
/// must be among them).
#[inline]
fn locate_among(
    mesh: &SphereMesh,
    old: &Crust,
    table: &PlateTable,
    cells: &CellPlates,
    rules: &OverlapRules,
    q: DVec3,
    slots: &[u32],
) -> SampleSource {
    let mut best: Option<CoreHit> = None;
    let locator = mesh.locator();
    for &slot in slots {
        let p = &table.plates[slot as usize];
        if q.dot(p.centroid_world) < p.cap_cos {
            continue;
        }
        let ql = p.plate_from_world * q;
        let cell = locator.cell_of(ql);
        if !cells.may_cover(cell, slot) {
            continue;
        }
        let loc = locator.locate_in_cell(&mesh.positions, &mesh.triangles, ql, cell);
        let tri = mesh.triangles[loc.triangle as usize];
        let owners = [
            old.plate[tri[0] as usize],
            old.plate[tri[1] as usize],
            old.plate[tri[2] as usize],
        ];
        if !owners.contains(&p.id) {
            continue;
        }
        let mut found = SampleSource {
            slot,
            plate: p.id,
            suture: u32::MAX,
            continental_lost: false,
            triangle: loc.triangle,
            weights: loc.weights.map(|w| w as f32),
        };
        let corner = loc.dominant_corner();
        if owners[corner] != p.id {
            // Fringe only: the plate's half of a triangle it shares with a plate that moved
            // differently. Extending the plate there would stretch it by a strip at every
            // divergent margin (growing continents); the gap fillers make new crust instead.
            // (Plates that move together still cover every point from a core.)
            continue;
        }
        let d = tri[corner] as usize;
        let suture = rules.suture_of_sample.get(d).copied().unwrap_or(u32::MAX);
        let sutured = suture != u32::MAX;
        if sutured {
            found.suture = suture;
            found.plate = rules.suture_target[suture as usize];
        }
        let continental: f64 = (0..3)
            .filter(|&k| old.crust_type[tri[k] as usize] == CrustType::Continental)
            .map(|k| loc.weights[k])
            .sum();
        let hit = CoreHit {
            source: found,
            sutured,
            continental: continental >= 0.5,
        };
        best = Some(match best {
            None => hit,
            Some(b) => {
                let key = |h: &CoreHit| (h.sutured, h.continental);
                let beats = key(&hit) > key(&b)
                    || (key(&hit) == key(&b)
                        && rules
                            .pairs
                            .binary_search(&(hit.source.plate, b.source.plate))
                            .is_ok());
                let (mut win, lose) = if beats { (hit, b) } else { (b, hit) };
                win.source.continental_lost |= lose.continental && !lose.sutured;
                win
            }
        });
    }
    best.map_or(SampleSource::GAP, |b| b.source)
}
/// The GPU counterpart of [`resample_locate_cpu`]: locates every sample on the device, then the
/// samples the kernel left to the CPU with [`locate_one`] (on the host copy of `old`'s plates
/// and crust types, which no kernel writes). The resident crust must hold `old` (call
/// [`GpuContext::sync_crust`] first). Same outputs as the CPU except the
/// weights (f32 geometry, see the module documentation).
pub fn resample_locate_gpu(
    ctx: &mut GpuContext,
    mesh: &SphereMesh,
    old: &Crust,
    table: &PlateTable,
    rules: &OverlapRules,
    sources: &mut Vec<SampleSource>,
) -> Result<LocateReport, GpuError> {
    let cell_plates = CellPlates::build(mesh, old, table);
    let (located, doubtful) =
        resample_locate::resample_locate_raw(ctx, mesh, old, table, rules, &cell_plates)?;
    *sources = located;
    let redone: Vec<SampleSource> = doubtful
        .par_iter()
        .with_min_len(256)
        .map(|&j| {
            locate_one(
                mesh,
                old,
                table,
                &cell_plates,
                rules,
                mesh.positions[j as usize],
            )
        })
        .collect();
    // The rechecked sources go into the kernel's output on the device as well (36 bytes each),
    // so the interpolation reads every source there (stage 3b of docs/gpu-residency.md).
    let patches: Vec<(u32, [u32; 8])> = doubtful
        .iter()
        .zip(&redone)
        .map(|(&j, s)| (j, crate::gpu::sources_patch::source_words(s)))
        .collect();
    if let Some((buf, _)) = resample_locate::located_buffer(ctx) {
        crate::gpu::sources_patch::sources_patch_gpu(ctx, &buf, mesh.len(), &patches)?;
        resample_locate::mark_located_complete(ctx);
    }
    for (&j, s) in doubtful.iter().zip(redone) {
        sources[j as usize] = s;
    }
    ctx.traffic.locations += 1;
    ctx.traffic.rechecked_samples += doubtful.len() as u64;
    Ok(LocateReport {
        rechecked: doubtful.len(),
        gaps: sources.iter().filter(|s| s.is_gap()).count(),
    })
}
