//! Global resampling (paper §6, Driftworld §3.7): every sample of the fixed reference mesh takes
//! its data from the plate that covers it now, by barycentric interpolation in that plate's
//! rotated triangulation; samples that no plate covers are gaps, filled by the gap fillers
//! (new oceanic crust, see `oceanic_crust`); then the plates are rebuilt from the new
//! assignment and their frames reset to the identity.
//!
//! How a plate covers a point: the point is rotated into the plate frame and located in the
//! reference mesh; the plate covers it if that triangle has at least one vertex owned by the
//! plate. Triangles straddling two plates therefore belong to both, so plates that move together
//! leave no seam of "gap" between them (the trap that made other implementations turn every
//! plate boundary into new ocean at every resampling). A plate covers the point from its *core*
//! when the triangle's nearest vertex (largest weight) is its own, from its *fringe* otherwise.
//! Core beats fringe; among cores (two plates overlapping), the plate order decides which one
//! stays on top (Driftworld §3.5, by overlap score). With every plate at rest, each sample is the
//! nearest vertex of its own triangle, so resampling is exactly the identity.
#![allow(clippy::needless_range_loop)]

pub mod gaps;
pub mod interpolate;
pub mod locate;
pub mod rebuild;

pub use gaps::*;
pub use interpolate::*;
pub use locate::*;
pub use rebuild::*;

use std::time::Instant;

use bevy_ecs::prelude::*;

use crate::components::{Plate, PlateBounds, PlateFrame, PlateMotion, PlateStats};
use crate::geometry::SphereMesh;
pub use crate::gpu::resample_locate::{CellPlates, OverlapRules, SampleSource};
use crate::gpu::{GpuContext, run_or_record};
use crate::resources::params::Params;
use crate::resources::{Crust, NextPlateId, PlateTable, ResampleRequest, SimClock, StepTimings};
use crate::resources::{OverridePairs, Sutures, TerraneField};

/// Work area of a resampling in progress (a resource). Reused between resamplings so memory
/// stays flat.
#[derive(Resource, Default)]
pub struct ResampleWork {
    /// True between the interpolation and the rebuild of a step that resamples.
    pub active: bool,
    /// The crust being built; swapped in at the rebuild.
    pub next: Crust,
    /// Gap samples of this resampling.
    pub gaps: Vec<GapSample>,
    /// Time since the previous resampling, My.
    pub elapsed_my: f64,
    /// Per-sample sources of this resampling.
    pub sources: Vec<SampleSource>,
    /// Continental crust that went under another plate's continental crust in this
    /// resampling (forced subduction of small terranes), km².
    pub continental_subducted_km2: f64,
    /// The same, summed over the whole run, km².
    pub continental_subducted_total_km2: f64,
    /// Set when a resampling installed its crust this step; cleared once the
    /// [`AfterResample`](crate::plugins::AfterResample) schedule ran after it (its systems may
    /// ask, with [`just_resampled`], whether a resampling or a new planet brought them).
    pub rebuilt: bool,
    started: Option<Instant>,
}

impl ResampleWork {
    /// Frees the buffers of the last resampling (the next one allocates them again), unless
    /// one is in progress. Between resamplings they would only add to the relief passes' work
    /// areas in the run's peak memory.
    pub fn release_buffers(&mut self) {
        if !self.active {
            self.next = Crust::default();
            self.sources = Vec::new();
            self.gaps = Vec::new();
        }
    }
}

/// Run condition of [`AfterResample`](crate::plugins::AfterResample) systems: true when a
/// resampling installed its crust this step (false when the schedule runs for a new planet or
/// plates given by hand).
pub fn just_resampled(work: Option<Res<ResampleWork>>) -> bool {
    work.is_some_and(|w| w.rebuilt)
}

/// Run condition: a resampling is due this step (asked for, or the fastest plate has travelled
/// far enough, within the configured interval bounds).
pub fn resample_due(
    clock: Res<SimClock>,
    params: Res<Params>,
    request: Res<ResampleRequest>,
    frames: Query<&PlateFrame>,
) -> bool {
    resample_due_after(
        clock.steps_since_resample,
        &params,
        request.0,
        max_frame_angle(frames.iter()),
    )
}

/// The largest angle any plate has turned since the last resampling (radians; 0 with no plate).
pub fn max_frame_angle<'a>(frames: impl Iterator<Item = &'a PlateFrame>) -> f64 {
    frames.map(|f| f.angle_rad()).fold(0.0, f64::max)
}

/// Whether a resampling is due after `steps` steps since the last one, with a resampling asked
/// for (`requested`) or not, and the fastest plate turned by `max_angle_rad` since: the rule of
/// [`resample_due`], for what must know it before the clock advances (random rifts, which
/// happen only on the steps that end with a resampling).
pub fn resample_due_after(
    steps: u64,
    params: &Params,
    requested: bool,
    max_angle_rad: f64,
) -> bool {
    if requested {
        return true;
    }
    let (min_steps, max_steps) = (
        params.resample.min_interval_steps,
        params.resample.max_interval_steps,
    );
    if steps >= max_steps {
        return true;
    }
    if steps < min_steps {
        return false;
    }
    max_angle_rad * params.planet.radius_km >= params.resample.adaptive_displacement_km
}

/// First system of a resampling: locates every sample in the moved plates (on the GPU when a
/// [`GpuContext`] is installed, see `crate::gpu::resample_locate`), interpolates, finds
/// the gaps and their nearest plates, and fills gaps with the nearest plate's data (gap-filler
/// plugins overwrite that next).
#[allow(clippy::too_many_arguments)]
pub fn resample_interpolate(
    mesh: Res<SphereMesh>,
    crust: Res<Crust>,
    clock: Res<SimClock>,
    params: Res<Params>,
    plates: Query<(&Plate, &PlateMotion, &PlateFrame, &PlateBounds, &PlateStats)>,
    pairs: Option<Res<OverridePairs>>,
    terranes: Option<Res<TerraneField>>,
    mut sutures: Option<ResMut<Sutures>>,
    mut work: ResMut<ResampleWork>,
    mut gpu: Option<ResMut<GpuContext>>,
    mut timings: Option<ResMut<StepTimings>>,
) {
    let started = Instant::now();
    // On the GPU backend nothing is pulled (stage 3 of docs/gpu-residency.md): the kernels read
    // the old crust from the resident buffers, and the CPU reads of the old crust here (cell
    // plate lists, the samples the location kernel leaves to the CPU, the suture of each
    // sample) and before (`collide_before_resample`) use only plate and crust type, which no
    // kernel writes. The host copy of the other fields may be stale until `resample_rebuild`
    // replaces the crust.
    let tick = crust.last_changed();
    let crust: &Crust = &crust;
    let table = PlateTable::from_query(&plates);
    let work = &mut *work;
    // Pending sutures: which old samples move to which plate.
    let mut pending: Vec<crate::resources::Suture> = sutures
        .as_mut()
        .map(|s| std::mem::take(&mut s.pending))
        .unwrap_or_default();
    let mut suture_of_sample = Vec::new();
    if let Some(t) = terranes
        .as_ref()
        .filter(|t| t.terrane.len() == crust.len() && !pending.is_empty())
    {
        suture_of_sample = vec![u32::MAX; crust.len()];
        for (i, &ter) in t.terrane.iter().enumerate() {
            if let Some(k) = pending
                .iter()
                .position(|s| s.terrane == ter && crust.plate[i] == s.moving_plate())
            {
                suture_of_sample[i] = k as u32;
            }
        }
    }
    // A terrane that left its plate earlier has moved with the plate it joins since: its
    // centroid is where its own plate's frame puts it now.
    if let Some(t) = terranes.as_ref() {
        for s in pending.iter_mut() {
            if let (Some(d), Some(c)) = (
                s.detached_plate.and_then(|d| table.get(d)),
                t.centroid.get(s.terrane as usize),
            ) {
                s.centroid_world = d.world_from_plate * *c;
            }
        }
    }
    let suture_target: Vec<u32> = pending.iter().map(|s| s.to_plate).collect();
    let rules = OverlapRules {
        pairs: pairs.as_ref().map_or(&[][..], |p| &p.0[..]),
        suture_of_sample: &suture_of_sample,
        suture_target: &suture_target,
    };
    let lap = |name: &str, t: &mut Instant| {
        tracing::debug!(ms = t.elapsed().as_secs_f64() * 1e3, "resample: {name}");
        *t = Instant::now();
    };
    let mut t = Instant::now();
    let on_gpu = gpu.as_mut().is_some_and(|g| {
        run_or_record(g, |g| {
            g.sync_crust(crust, Some(tick))?;
            locate::resample_locate_gpu(g, &mesh, crust, &table, &rules, &mut work.sources)
                .map(|r| tracing::debug!(rechecked = r.rechecked, "resample: located on the GPU"))
        })
    });
    if !on_gpu {
        resample_locate_cpu(&mesh, crust, &table, &rules, &mut work.sources);
    }
    if let Some(timings) = timings.as_mut() {
        timings.record("resample_locate", t.elapsed());
    }
    lap("locate", &mut t);
    let lost: f64 = work
        .sources
        .iter()
        .zip(mesh.area_km2.iter())
        .filter(|(s, _)| s.continental_lost)
        .map(|(_, a)| *a)
        .sum();
    work.continental_subducted_km2 = lost;
    work.continental_subducted_total_km2 += lost;
    if lost > 0.0 {
        tracing::debug!(km2 = lost, "continental crust forced under another plate");
    }
    if let Some(s) = sutures.as_mut() {
        let mut moved: Vec<Vec<u32>> = vec![Vec::new(); pending.len()];
        for (j, src) in work.sources.iter().enumerate() {
            if src.suture != u32::MAX {
                moved[src.suture as usize].push(j as u32);
            }
        }
        s.total += pending.len() as u64;
        s.applied = pending.into_iter().zip(moved).collect();
    }
    let interpolated_on_gpu = gpu.as_mut().is_some_and(|g| {
        run_or_record(g, |g| {
            g.sync_crust(crust, Some(tick))?;
            // Located on the device: the sources are read there (only the rechecked ones went
            // up again); otherwise they go up.
            let interpolate = if on_gpu {
                crate::gpu::resample_interpolate::resample_interpolate_gpu_located
            } else {
                crate::gpu::resample_interpolate::resample_interpolate_gpu
            };
            interpolate(g, &mesh, crust, &table, &work.sources, &mut work.next)
        })
    });
    if !interpolated_on_gpu {
        interpolate(&mesh, crust, &table, &work.sources, &mut work.next);
    }
    if let Some(timings) = timings.as_mut() {
        timings.record("resample_interpolate", t.elapsed());
    }
    displace_overridden_continents(&mesh, &work.sources, &mut work.next);
    lap("interpolate", &mut t);
    work.gaps = gaps_from_nearest(&mesh, &work.sources, &mut work.next);
    lap("nearest plates of gaps", &mut t);
    work.elapsed_my = clock.steps_since_resample as f64 * params.time.time_step_my;
    work.active = true;
    work.started = Some(started);
    tracing::trace!(gaps = work.gaps.len(), "resample: interpolated");
}

/// Last system of a resampling: installs the new crust, makes plates connected, rebuilds the
/// plate entities (samples, triangles, caps, areas), despawns empty plates, spawns split-off
/// pieces and resets every frame to the identity.
pub fn resample_rebuild(world: &mut World) {
    let Some(mut work) = world.get_resource_mut::<ResampleWork>() else {
        return;
    };
    if !work.active {
        return;
    }
    work.active = false;
    let started = work.started.take();
    let mut next = std::mem::take(&mut work.next);
    let min_area = world.resource::<Params>().resample.fragment_min_area_km2;
    let mut next_id = world.resource::<NextPlateId>().0;
    let t = Instant::now();
    let splits = {
        let mesh = world.resource::<SphereMesh>();
        defragment_plates(mesh, &mut next.plate, min_area, true, &mut next_id)
    };
    tracing::debug!(ms = t.elapsed().as_secs_f64() * 1e3, "resample: defragment");
    let t = Instant::now();
    world.resource_mut::<NextPlateId>().0 = next_id;
    {
        let mut crust = world.resource_mut::<Crust>();
        std::mem::swap(&mut *crust, &mut next);
    }
    // The new crust is the host's: whatever the device held newer (the interpolation read it
    // on the device; the old host copy, kept below as a buffer, may be stale) is superseded.
    if let Some(mut g) = world.get_resource_mut::<GpuContext>() {
        g.supersede_device();
    }
    // Keep the old buffers for the next resampling.
    world.resource_mut::<ResampleWork>().next = next;
    rebuild_plate_entities(world, &splits);
    tracing::debug!(
        ms = t.elapsed().as_secs_f64() * 1e3,
        "resample: rebuild plates"
    );
    {
        let mut clock = world.resource_mut::<SimClock>();
        clock.steps_since_resample = 0;
        clock.resamplings += 1;
    }
    world.resource_mut::<ResampleRequest>().0 = false;
    if let Some(t0) = started {
        world
            .resource_mut::<StepTimings>()
            .record("resampling", t0.elapsed());
    }
    // Fronts, terranes and collision uplift are rebuilt on the new crust next, by the
    // schedule's `run_after_resample`.
    world.resource_mut::<ResampleWork>().rebuilt = true;
}

/// Hands the allocator's free pages back to the system. A resampling frees and reallocates many
/// buffers of changing sizes on several threads; with glibc's per-thread arenas the freed space
/// fragments and the resident size crept up by about 20% over 1000 steps while the live state
/// stayed flat (measured with `examples/long_run`). Trimming after each resampling (well under a
/// millisecond at 100,000 samples) keeps the resident size flat. Elsewhere a no-op.
pub fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        unsafe extern "C" {
            fn malloc_trim(pad: usize) -> i32;
        }
        // SAFETY: malloc_trim only returns free heap memory to the OS; it has no preconditions.
        unsafe {
            malloc_trim(0);
        }
    }
}
