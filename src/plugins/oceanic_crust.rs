//! New oceanic crust with a ridge in the gaps between diverging plates (phenomenon
//! [`OCEANIC_CRUST`], paper §4.3), filled during a resampling. Systems:
//! [`crate::systems::oceanic_crust`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    Phenomenon, PhenomenonAppExt, ResampleSystems, TectonicStep, TectonicSystems,
    phenomenon_enabled,
};
use crate::systems::oceanic_crust;

/// The phenomenon key.
pub const OCEANIC_CRUST: Phenomenon = Phenomenon::new("oceanic_crust");

/// New ocean floor with a ridge in divergent gaps (phenomenon `oceanic_crust`); without it,
/// gaps are filled by stretching the nearest plate.
#[derive(Default)]
pub struct OceanicCrustPlugin;

impl Plugin for OceanicCrustPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            OCEANIC_CRUST,
            TectonicSystems::Resample,
            "new ocean floor and ridges in divergent gaps",
        );
        app.add_systems(
            TectonicStep,
            oceanic_crust::generate_oceanic_crust
                .in_set(ResampleSystems::FillGaps)
                .run_if(phenomenon_enabled(OCEANIC_CRUST)),
        );
    }
}
