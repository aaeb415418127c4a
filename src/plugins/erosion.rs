//! Continental erosion, oceanic damping and sediment accretion (phenomenon [`EROSION`], paper
//! §4.5). Systems and CPU kernel: [`crate::systems::erosion`]; GPU kernel:
//! [`crate::gpu::erosion`] (`shaders/erosion.wgsl`).

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::erosion;

/// The phenomenon key.
pub const EROSION: Phenomenon = Phenomenon::new("erosion");

/// Continental erosion, oceanic damping and sediment accretion (phenomenon `erosion`).
#[derive(Default)]
pub struct ErosionPlugin;

impl Plugin for ErosionPlugin {
    fn build(&self, app: &mut App) {
        // Off by default: with isostasy on, the relief phenomena (drainage, rivers, sediment)
        // replace it; it is the paper's law, for paper parity with isostasy off.
        app.register_phenomenon_with_default(
            EROSION,
            TectonicSystems::Erosion,
            "the paper's erosion law: continental erosion, oceanic damping, trench accretion",
            false,
        );
        app.add_systems(
            TectonicStep,
            erosion::erode
                .in_set(TectonicSystems::Erosion)
                .run_if(phenomenon_enabled(EROSION)),
        );
    }
}
