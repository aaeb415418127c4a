//! Global resampling (phenomenon [`RESAMPLE`], paper §6): every 10–60 steps (adaptive to the
//! fastest plate) or on request, every reference sample takes the data of the plate that covers
//! it now; gaps are filled (by [`super::oceanic_crust`]) and the plates rebuilt. Systems:
//! [`crate::systems::resample`]; GPU kernels: [`crate::gpu::resample_locate`],
//! [`crate::gpu::resample_interpolate`], [`crate::gpu::sources_patch`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    Phenomenon, PhenomenonAppExt, ResampleSystems, TectonicStep, TectonicSystems,
    phenomenon_enabled, run_after_resample,
};
use crate::systems::resample;

/// The phenomenon key.
pub const RESAMPLE: Phenomenon = Phenomenon::new("resample");

/// Global resampling every 10–60 steps (adaptive) or on request (phenomenon `resample`).
#[derive(Default)]
pub struct ResamplePlugin;

impl Plugin for ResamplePlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            RESAMPLE,
            TectonicSystems::Resample,
            "global resampling onto the reference mesh",
        );
        app.add_systems(
            TectonicStep,
            (
                resample::resample_interpolate
                    .in_set(ResampleSystems::Interpolate)
                    .run_if(phenomenon_enabled(RESAMPLE))
                    .run_if(resample::resample_due),
                (resample::resample_rebuild, run_after_resample)
                    .chain()
                    .in_set(ResampleSystems::Rebuild),
            ),
        );
    }
}
