//! Linear hillslope (and, at these sample spacings, "unresolved relief") diffusion on land:
//!
//! ```text
//!   ∂h/∂t = κ ∇²h          κ in km²/My (1 km²/My = 1e6 m²/My = 1 m²/yr)
//! ```
//!
//! (Culling 1960; the hillslope term of Braun & Willett 2013 and of FastScape.) Discretised by
//! finite volumes on the Voronoi cells of the samples: a_i dh_i/dt = κ Σ_j w_ij (h_j − h_i),
//! with w_ij the cotangent weight (dual-edge length / edge length, symmetric), so land–land
//! exchanges conserve volume exactly. The coast is a Dirichlet boundary at sea level: a land
//! sample of height h > 0 beside an ocean sample loses κ·w·h km³/My to it, reported per ocean
//! sample in `to_ocean_km3` so the sediment pass can deposit it. Explicit sub-steps sized for
//! monotonicity (Δt_sub·κ·Σw/a ≤ 0.5), computed in f64.
//!
//! Physical hillslope diffusivities (~0.001–0.01 m²/yr; Fernandes & Dietrich 1997) are
//! negligible at 35–80 km spacing (time scale d²/κ ~ 10⁵ My); the default here is a much
//! larger "landscape" diffusivity standing for sub-grid processes, and is a calibration knob
//! (NOTES.md).

use rayon::prelude::*;

use super::graph::ReliefGraph;
use crate::gpu::GpuContext;
use crate::gpu::GpuError;
use crate::gpu::diffusion::{
    DiffusionGraph, DiffusionSteps, diffusion_dispatch, diffusion_read_back,
};

/// Volumes moved by one call of [`diffuse_land`], km³.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DiffusionBudget {
    /// Σ a_i·max(0, −Δh_i) over land.
    pub lowered_km3: f64,
    /// Σ a_i·max(0, Δh_i) over land.
    pub raised_km3: f64,
    /// Volume that crossed the coast into ocean samples.
    pub to_ocean_km3: f64,
    /// Number of explicit sub-steps used.
    pub substeps: u32,
}

impl DiffusionBudget {
    /// Adds the volumes of another call (the sub-steps: the most either used).
    pub fn add(&mut self, other: &DiffusionBudget) {
        self.lowered_km3 += other.lowered_km3;
        self.raised_km3 += other.raised_km3;
        self.to_ocean_km3 += other.to_ocean_km3;
        self.substeps = self.substeps.max(other.substeps);
    }
}

/// Scratch for [`diffuse_land`].
#[derive(Clone, Debug, Default)]
pub struct DiffusionScratch {
    h: Vec<f64>,
    next: Vec<f64>,
    coast: Vec<u32>,
    receipts: Vec<f64>,
    max_weight_rate: Option<(usize, f64)>,
    /// The device's diffused elevation and coastal receipts ([`diffuse_land_gpu`]).
    device_h: Vec<f32>,
    device_receipts: Vec<f32>,
}

/// The name of [`diffuse_land`] as the CPU reference of the `diffusion` kernel
/// (`shaders/diffusion.wgsl`).
pub use self::diffuse_land as diffusion_cpu;

/// The set-up of one call of [`diffuse_land`] (and [`diffuse_land_gpu`]): checks the inputs,
/// and finds the explicit sub-steps (count and length, My) and the coast (ocean samples beside
/// land, ascending) into `scratch`. None when there is nothing to diffuse (`delta_km` is then
/// zeroed whole; otherwise only past the samples, the write-out zeroing the rest).
#[allow(clippy::too_many_arguments)]
fn prepare(
    g: &ReliefGraph,
    elevation_km: &[f32],
    ocean: &[bool],
    kappa_km2_per_my: f64,
    dt_my: f64,
    delta_km: &mut [f32],
    to_ocean_km3: &[f64],
    scratch: &mut DiffusionScratch,
) -> Option<(u32, f64)> {
    let n = g.len();
    if !(kappa_km2_per_my > 0.0 && dt_my > 0.0)
        || elevation_km.len() < n
        || ocean.len() < n
        || delta_km.len() < n
        || to_ocean_km3.len() < n
    {
        delta_km.iter_mut().for_each(|d| *d = 0.0);
        return None;
    }
    let kappa = kappa_km2_per_my;
    // Stability bound: max over all samples of Σw/a (1/km²), cached per graph size.
    let max_w = match scratch.max_weight_rate {
        Some((len, v)) if len == n => v,
        _ => {
            let v = (0..n)
                .into_par_iter()
                .with_min_len(8192)
                .filter(|&i| g.area_km2[i] > 0.0)
                .map(|i| g.edges(i).map(|e| g.edge_weight[e] as f64).sum::<f64>() / g.area_km2[i])
                .reduce(|| 0.0, f64::max);
            scratch.max_weight_rate = Some((n, v));
            v
        }
    };
    let max_rate = kappa * max_w;
    if max_rate <= 0.0 {
        delta_km.iter_mut().for_each(|d| *d = 0.0);
        return None;
    }
    // The land's entries are written at the end (`apply_land_change`), the sea's zeroed there.
    delta_km[n..].iter_mut().for_each(|d| *d = 0.0);
    let substeps = ((dt_my * max_rate / 0.5).ceil() as u32).clamp(1, 10_000);
    let dts = dt_my / substeps as f64;
    // The sea samples with a land neighbour, ascending, each once: gathered from the land
    // (about a third of the samples) rather than tested at every sea sample.
    scratch.coast.clear();
    scratch.coast.par_extend(
        (0..n)
            .into_par_iter()
            .with_min_len(8192)
            .filter(|&i| !ocean[i])
            .flat_map_iter(|i| {
                g.neighbors_of(i)
                    .iter()
                    .copied()
                    .filter(|&j| ocean[j as usize])
            }),
    );
    scratch.coast.par_sort_unstable();
    scratch.coast.dedup();
    Some((substeps, dts))
}

/// The end of one call: writes the new elevation `new_of(i)` of every land sample (not in
/// `ocean`) whose elevation was finite, its change to `delta_km` (0 elsewhere), and the volumes
/// lowered and raised to `budget` (summed by fixed chunks of samples, the chunks in order: the
/// same sums whatever the thread count).
fn apply_land_change(
    g: &ReliefGraph,
    elevation_km: &mut [f32],
    delta_km: &mut [f32],
    ocean: &[bool],
    new_of: impl Fn(usize) -> f32 + Sync,
    budget: &mut DiffusionBudget,
) {
    let n = g.len();
    const CH: usize = 8192;
    let sums: Vec<(f64, f64)> = elevation_km[..n]
        .par_chunks_mut(CH)
        .zip(delta_km[..n].par_chunks_mut(CH))
        .enumerate()
        .map(|(c, (zs, ds))| {
            let (mut lowered, mut raised) = (0.0, 0.0);
            for (k, (z, dz)) in zs.iter_mut().zip(ds.iter_mut()).enumerate() {
                let i = c * CH + k;
                *dz = 0.0;
                let old = *z;
                if ocean[i] || !old.is_finite() {
                    continue;
                }
                let new = new_of(i);
                *z = new;
                let d = new - old;
                *dz = d;
                let v = d as f64 * g.area_km2[i];
                if v < 0.0 {
                    lowered -= v;
                } else {
                    raised += v;
                }
            }
            (lowered, raised)
        })
        .collect();
    for (lowered, raised) in sums {
        budget.lowered_km3 += lowered;
        budget.raised_km3 += raised;
    }
}

/// One explicit sub-step of the land's diffusion from the heights `h_of(i)` (read at land
/// samples only): the new heights of the land into `next` (the sea's entries untouched), and
/// the coastal outflow of the sub-step (`kappa` km²/My over `dts` My) added to `receipts` (one
/// entry per `coast` sample).
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
fn diffusion_substep(
    g: &ReliefGraph,
    ocean: &[bool],
    h_of: impl Fn(usize) -> f64 + Sync,
    kappa: f64,
    dts: f64,
    next: &mut [f64],
    coast: &[u32],
    receipts: &mut [f64],
) {
    const CH: usize = 8192;
    next.par_chunks_mut(CH).enumerate().for_each(|(c, out)| {
        let base = c * CH;
        for k in 0..out.len() {
            let i = base + k;
            if ocean[i] {
                continue;
            }
            let hi = h_of(i);
            if g.area_km2[i] <= 0.0 {
                out[k] = hi;
                continue;
            }
            let mut flux = 0.0; // km³/My into i
            for e in g.edges(i) {
                let j = g.neighbors[e] as usize;
                let w = g.edge_weight[e] as f64;
                flux += if !ocean[j] {
                    w * (h_of(j) - hi)
                } else {
                    -w * hi.max(0.0)
                };
            }
            out[k] = hi + dts * kappa * flux / g.area_km2[i];
        }
    });
    // Coastal outflow received by each ocean sample (gather: deterministic).
    receipts
        .par_iter_mut()
        .zip(coast.par_iter())
        .with_min_len(1024)
        .for_each(|(acc, &j)| {
            let j = j as usize;
            let mut v = 0.0;
            for e in g.edges(j) {
                let i = g.neighbors[e] as usize;
                if !ocean[i] {
                    v += g.edge_weight[e] as f64 * h_of(i).max(0.0);
                }
            }
            *acc += kappa * v * dts;
        });
}

/// Diffuses land elevations over `dt_my` with diffusivity `kappa_km2_per_my`. Land samples are
/// those not in `ocean`; ocean samples are held at sea level and receive the coastal outflow,
/// accumulated (+=) into `to_ocean_km3` (km³ per ocean sample). Writes the change of every
/// sample (km; 0 in the ocean) to `delta_km` and applies it to `elevation_km`.
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
pub fn diffuse_land(
    g: &ReliefGraph,
    elevation_km: &mut [f32],
    ocean: &[bool],
    kappa_km2_per_my: f64,
    dt_my: f64,
    delta_km: &mut [f32],
    to_ocean_km3: &mut [f64],
    scratch: &mut DiffusionScratch,
) -> DiffusionBudget {
    let n = g.len();
    let Some((substeps, dts)) = prepare(
        g,
        elevation_km,
        ocean,
        kappa_km2_per_my,
        dt_my,
        delta_km,
        to_ocean_km3,
        scratch,
    ) else {
        return DiffusionBudget::default();
    };
    let kappa = kappa_km2_per_my;
    scratch.next.resize(n, 0.0);
    scratch.receipts.clear();
    scratch.receipts.resize(scratch.coast.len(), 0.0);
    // The land's heights, as read by the sub-steps: a non-finite elevation reads as 0.
    let z_of = |i: usize| {
        let z = elevation_km[i] as f64;
        if z.is_finite() { z } else { 0.0 }
    };
    if substeps == 1 {
        // One sub-step (the usual case): straight from the elevation, without a copy.
        diffusion_substep(
            g,
            ocean,
            z_of,
            kappa,
            dts,
            &mut scratch.next,
            &scratch.coast,
            &mut scratch.receipts,
        );
    } else {
        // Only the land's heights are read (the sea's entries keep whatever they held).
        const CH: usize = 8192;
        scratch.h.resize(n, 0.0);
        scratch.h.par_chunks_mut(CH).enumerate().for_each(|(c, h)| {
            for (k, h) in h.iter_mut().enumerate() {
                let i = c * CH + k;
                if !ocean[i] {
                    *h = z_of(i);
                }
            }
        });
        for s in 0..substeps {
            if s > 0 {
                // The last sub-step's heights are read by this one; the last one leaves its
                // heights in `next`, as the one-step path does.
                std::mem::swap(&mut scratch.h, &mut scratch.next);
            }
            let h = &scratch.h;
            diffusion_substep(
                g,
                ocean,
                |i| h[i],
                kappa,
                dts,
                &mut scratch.next,
                &scratch.coast,
                &mut scratch.receipts,
            );
        }
    }
    let mut budget = DiffusionBudget {
        substeps,
        ..Default::default()
    };
    for (k, &j) in scratch.coast.iter().enumerate() {
        to_ocean_km3[j as usize] += scratch.receipts[k];
        budget.to_ocean_km3 += scratch.receipts[k];
    }
    let new = &scratch.next;
    apply_land_change(
        g,
        elevation_km,
        delta_km,
        ocean,
        |i| new[i] as f32,
        &mut budget,
    );
    budget
}

/// [`diffuse_land`] with the sub-steps on the device (`shaders/diffusion.wgsl`, f32): the same
/// set-up (sub-steps, land, coast) and the same end on the host, from the elevation and the
/// coastal receipts the device computed. `elevation_km` goes up into the resident elevation
/// buffer and is diffused there, so after `Ok(Some(_))` the device's elevation equals the
/// host's (declare the write of the elevation as done). `Ok(None)`: nothing to diffuse, the
/// device and `elevation_km` untouched (call [`diffuse_land`], which returns at once). On an
/// error the host's `elevation_km` and `to_ocean_km3` are as they were (the resident elevation
/// may not be), so [`diffuse_land`] can run instead.
#[allow(clippy::too_many_arguments)]
pub fn diffuse_land_gpu(
    ctx: &mut GpuContext,
    g: &ReliefGraph,
    elevation_km: &mut [f32],
    ocean: &[bool],
    kappa_km2_per_my: f64,
    dt_my: f64,
    delta_km: &mut [f32],
    to_ocean_km3: &mut [f64],
    scratch: &mut DiffusionScratch,
) -> Result<Option<DiffusionBudget>, GpuError> {
    let n = g.len();
    let Some((substeps, dts)) = prepare(
        g,
        elevation_km,
        ocean,
        kappa_km2_per_my,
        dt_my,
        delta_km,
        to_ocean_km3,
        scratch,
    ) else {
        return Ok(None);
    };
    let Some(z) = ctx
        .crust_buffers()
        .filter(|b| b.len == n)
        .map(|b| b.elevation_km.clone())
    else {
        return Err(GpuError::Kernel {
            kernel: "diffusion",
            message: format!("no crust of {n} samples on the device"),
        });
    };
    ctx.upload(&z, bytemuck::cast_slice(&elevation_km[..n]));
    let graph = DiffusionGraph {
        neighbor_start: &g.neighbor_start,
        neighbors: &g.neighbors,
        edge_weight: &g.edge_weight,
        area_km2: &g.area_km2,
    };
    let steps = DiffusionSteps {
        rate_km2: kappa_km2_per_my * dts,
        substeps,
    };
    diffusion_dispatch(ctx, &graph, &ocean[..n], &scratch.coast, &steps)?;
    scratch.device_h.resize(n, 0.0);
    scratch.device_receipts.resize(scratch.coast.len(), 0.0);
    diffusion_read_back(ctx, &mut scratch.device_h, &mut scratch.device_receipts)?;
    let mut budget = DiffusionBudget {
        substeps,
        ..Default::default()
    };
    for (k, &j) in scratch.coast.iter().enumerate() {
        let r = scratch.device_receipts[k] as f64;
        to_ocean_km3[j as usize] += r;
        budget.to_ocean_km3 += r;
    }
    let h = &scratch.device_h;
    apply_land_change(g, elevation_km, delta_km, ocean, |i| h[i], &mut budget);
    Ok(Some(budget))
}
