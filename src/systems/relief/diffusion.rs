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

/// Scratch for [`diffuse_land`].
#[derive(Clone, Debug, Default)]
pub struct DiffusionScratch {
    h: Vec<f64>,
    next: Vec<f64>,
    land: Vec<u32>,
    coast: Vec<u32>,
    receipts: Vec<f64>,
    max_weight_rate: Option<(usize, f64)>,
}

/// Diffuses land elevations over `dt_my` with diffusivity `kappa_km2_per_my`. Land samples are
/// those not in `ocean`; ocean samples are held at sea level and receive the coastal outflow,
/// accumulated (+=) into `to_ocean_km3` (km³ per ocean sample). Writes the change of every
/// sample (km; 0 in the ocean) to `delta_km` and applies it to `elevation_km`.
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
    delta_km.iter_mut().for_each(|d| *d = 0.0);
    if !(kappa_km2_per_my > 0.0 && dt_my > 0.0)
        || elevation_km.len() < n
        || ocean.len() < n
        || delta_km.len() < n
        || to_ocean_km3.len() < n
    {
        return DiffusionBudget::default();
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
        return DiffusionBudget::default();
    }
    let substeps = ((dt_my * max_rate / 0.5).ceil() as u32).clamp(1, 10_000);
    let dts = dt_my / substeps as f64;
    scratch.land.clear();
    scratch
        .land
        .extend((0..n as u32).filter(|&i| !ocean[i as usize]));
    scratch.coast.clear();
    for &i in &scratch.land {
        for &j in g.neighbors_of(i as usize) {
            if ocean[j as usize] {
                scratch.coast.push(j);
            }
        }
    }
    scratch.coast.sort_unstable();
    scratch.coast.dedup();
    scratch.h.resize(n, 0.0);
    scratch.next.resize(n, 0.0);
    for &i in &scratch.land {
        let z = elevation_km[i as usize] as f64;
        scratch.h[i as usize] = if z.is_finite() { z } else { 0.0 };
    }
    scratch.receipts.clear();
    scratch.receipts.resize(scratch.coast.len(), 0.0);
    const CH: usize = 8192;
    for _ in 0..substeps {
        let h = &scratch.h;
        scratch
            .next
            .par_chunks_mut(CH)
            .enumerate()
            .for_each(|(c, out)| {
                let base = c * CH;
                for k in 0..out.len() {
                    let i = base + k;
                    if ocean[i] {
                        continue;
                    }
                    let hi = h[i];
                    if g.area_km2[i] <= 0.0 {
                        out[k] = hi;
                        continue;
                    }
                    let mut flux = 0.0; // km³/My into i
                    for e in g.edges(i) {
                        let j = g.neighbors[e] as usize;
                        let w = g.edge_weight[e] as f64;
                        flux += if !ocean[j] {
                            w * (h[j] - hi)
                        } else {
                            -w * hi.max(0.0)
                        };
                    }
                    out[k] = hi + dts * kappa * flux / g.area_km2[i];
                }
            });
        // Coastal outflow received by each ocean sample (gather: deterministic).
        scratch
            .receipts
            .par_iter_mut()
            .zip(scratch.coast.par_iter())
            .with_min_len(1024)
            .for_each(|(acc, &j)| {
                let j = j as usize;
                let mut v = 0.0;
                for e in g.edges(j) {
                    let i = g.neighbors[e] as usize;
                    if !ocean[i] {
                        v += g.edge_weight[e] as f64 * h[i].max(0.0);
                    }
                }
                *acc += kappa * v * dts;
            });
        std::mem::swap(&mut scratch.h, &mut scratch.next);
    }
    let mut budget = DiffusionBudget {
        substeps,
        ..Default::default()
    };
    for (k, &j) in scratch.coast.iter().enumerate() {
        to_ocean_km3[j as usize] += scratch.receipts[k];
        budget.to_ocean_km3 += scratch.receipts[k];
    }
    for &i in &scratch.land {
        let i = i as usize;
        let old = elevation_km[i];
        if !old.is_finite() {
            continue;
        }
        let new = scratch.h[i] as f32;
        elevation_km[i] = new;
        let d = new - old;
        delta_km[i] = d;
        let v = d as f64 * g.area_km2[i];
        if v < 0.0 {
            budget.lowered_km3 -= v;
        } else {
            budget.raised_km3 += v;
        }
    }
    budget
}
