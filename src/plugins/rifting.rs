//! Plate rifting (phenomenon [`RIFTING`], paper §4.4): plates break into 2–4 diverging fragments
//! at random (a Poisson process favouring large, continental plates). Systems:
//! [`crate::systems::rifting`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::resample::RESAMPLE;
use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::rifting;

/// The phenomenon key.
pub const RIFTING: Phenomenon = Phenomenon::new("rifting");

/// Plate rifting (phenomenon `rifting`): plates break into 2–4 diverging fragments at random
/// (a Poisson process favouring large, continental plates; see [`rifting`]).
#[derive(Default)]
pub struct RiftingPlugin;

impl Plugin for RiftingPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            RIFTING,
            TectonicSystems::Rifting,
            "large plates break into diverging fragments",
        );
        app.init_resource::<rifting::RiftLog>();
        // Random rifts happen on the steps that end with a resampling (which rebuilds the
        // fragments' fronts and terranes), or every step when the resampling is off.
        app.add_systems(
            TectonicStep,
            (
                rifting::rift_plates.run_if(phenomenon_enabled(RESAMPLE)),
                rifting::rift_plates_every_step.run_if(not(phenomenon_enabled(RESAMPLE))),
            )
                .chain()
                .in_set(TectonicSystems::Rifting)
                .run_if(phenomenon_enabled(RIFTING)),
        );
    }
}
