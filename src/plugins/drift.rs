//! Plate drift (phenomenon [`DRIFT`]): each plate turns about its Euler pole every step. Systems:
//! [`crate::systems::drift`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::drift;

/// The phenomenon key.
pub const DRIFT: Phenomenon = Phenomenon::new("drift");

/// Plate drift: each plate turns about its Euler pole (phenomenon `drift`).
#[derive(Default)]
pub struct DriftPlugin;

impl Plugin for DriftPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            DRIFT,
            TectonicSystems::Drift,
            "plates turn about their Euler poles",
        );
        app.add_systems(
            TectonicStep,
            drift::drift_plates
                .in_set(TectonicSystems::Drift)
                .run_if(phenomenon_enabled(DRIFT)),
        );
    }
}
