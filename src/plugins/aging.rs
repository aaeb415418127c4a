//! Crust and orogeny aging (phenomenon [`AGING`]). Systems and CPU kernel:
//! [`crate::systems::aging`]; GPU kernel: [`crate::gpu::aging`] (`shaders/aging.wgsl`).

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    AgingSystems, Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::aging;

/// The phenomenon key.
pub const AGING: Phenomenon = Phenomenon::new("aging");

/// Crust and orogeny aging (phenomenon `aging`).
#[derive(Default)]
pub struct AgingPlugin;

impl Plugin for AgingPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            AGING,
            TectonicSystems::Aging,
            "crust and orogeny ages grow by the time step",
        );
        app.add_systems(
            TectonicStep,
            aging::age_crust
                .in_set(AgingSystems::Crust)
                .run_if(phenomenon_enabled(AGING)),
        );
    }
}
