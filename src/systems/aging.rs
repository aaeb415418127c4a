//! Crust aging (Driftworld §3.15): every sample's crust age grows by δt, and so does the orogeny
//! age where an orogeny is recorded.

use bevy_ecs::prelude::*;
use rayon::prelude::*;

use crate::gpu::{FieldMask, GpuContext, run_or_record};
use crate::resources::params::Params;
use crate::resources::{Crust, Orogeny};

/// The CPU kernel (reference of `shaders/aging.wgsl`): ages every sample by `dt_my`, in place.
pub fn aging_cpu(age_my: &mut [f32], orogeny_age_my: &mut [f32], orogeny: &[Orogeny], dt_my: f32) {
    age_my
        .par_iter_mut()
        .with_min_len(4096)
        .for_each(|a| *a += dt_my);
    orogeny_age_my
        .par_iter_mut()
        .zip(orogeny.par_iter())
        .with_min_len(4096)
        .for_each(|(a, &o)| {
            if o != Orogeny::None {
                *a += dt_my;
            }
        });
}

/// Ages the crust by one time step, on the GPU when a [`GpuContext`] is installed, with
/// [`aging_cpu`] otherwise.
pub fn age_crust(params: Res<Params>, mut crust: ResMut<Crust>, gpu: Option<ResMut<GpuContext>>) {
    let dt = params.time.time_step_my as f32;
    if let Some(mut gpu) = gpu {
        let tick = crust.last_changed();
        let done = run_or_record(&mut gpu, |g| {
            g.sync_crust(&crust, Some(tick))?;
            crate::gpu::aging::aging_dispatch(g, dt)?;
            // The host copy is pulled lazily, by the next CPU reader (see gpu::FieldMask).
            g.note_device_write(
                FieldMask::AGE | FieldMask::OROGENY_AGE,
                crust.bypass_change_detection(),
            )
        });
        if done {
            return;
        }
    }
    let crust = &mut *crust;
    aging_cpu(
        &mut crust.age_my,
        &mut crust.orogeny_age_my,
        &crust.orogeny,
        dt,
    );
}
