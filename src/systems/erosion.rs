//! Continental erosion, oceanic damping and sediment accretion (paper §4.5), one pass over the
//! crust per step.
//!
//! - Continental erosion: emerged continental crust loses z/z_c·ε_c·δt.
//! - Oceanic damping: oceanic crust above the abyssal plain sinks by (1 − z/z_t)·ε_o·δt, applied
//!   as the exact solution of that law over δt, and stops at the abyssal depth z_a (the paper's
//!   law alone would drag all old floor toward the trench depth z_t).
//! - Sediment accretion: oceanic crust deeper than the abyssal plain is a trench; sediment raises
//!   it by ε_t·δt, up to z_a.
//!
//! Rates in mm/yr are km/My, so no unit conversion appears.

use bevy_ecs::prelude::*;
use rayon::prelude::*;

use crate::gpu::erosion::ErosionRates;
use crate::gpu::{FieldMask, GpuContext, run_or_record};
use crate::resources::params::Params;
use crate::resources::{Crust, CrustType};

/// New elevation of one sample after one step of erosion, damping and accretion.
#[inline]
pub fn erode_sample(z: f32, crust_type: CrustType, p: &ErosionRates) -> f32 {
    let z = z as f64;
    let out = match crust_type {
        CrustType::Continental => {
            if z > 0.0 {
                z - z / p.z_c * p.erosion_km
            } else {
                z
            }
        }
        CrustType::Oceanic => {
            if z > p.z_a {
                (p.z_t + (z - p.z_t) * p.damping_factor).max(p.z_a)
            } else {
                (z + p.sediment_km).min(p.z_a)
            }
        }
    };
    out as f32
}

/// The CPU kernel (reference of `shaders/erosion.wgsl`): one step of erosion, damping and
/// accretion on every sample, in place.
pub fn erosion_cpu(elevation_km: &mut [f32], crust_type: &[CrustType], rates: &ErosionRates) {
    elevation_km
        .par_iter_mut()
        .zip(crust_type.par_iter())
        .with_min_len(4096)
        .for_each(|(z, &t)| *z = erode_sample(*z, t, rates));
}

/// Applies one step of erosion, damping and accretion to every sample, on the GPU when a
/// [`GpuContext`] is installed, with [`erosion_cpu`] otherwise.
pub fn erode(params: Res<Params>, mut crust: ResMut<Crust>, gpu: Option<ResMut<GpuContext>>) {
    let rates = ErosionRates::new(&params);
    if let Some(mut gpu) = gpu {
        let tick = crust.last_changed();
        let done = run_or_record(&mut gpu, |g| {
            g.sync_crust(&crust, Some(tick))?;
            crate::gpu::erosion::erosion_dispatch(g, &rates)?;
            // The host copy is pulled lazily, by the next CPU reader (see gpu::FieldMask).
            g.note_device_write(FieldMask::ELEVATION, crust.bypass_change_detection())
        });
        if done {
            return;
        }
    }
    let crust = &mut *crust;
    erosion_cpu(&mut crust.elevation_km, &crust.crust_type, &rates);
}
