//! Area statistics and the no-NaN check (phenomenon [`DIAGNOSTICS`]). Systems:
//! [`crate::systems::diagnostics`]; GPU kernel: [`crate::gpu::crust_reduce`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::diagnostics;

/// The phenomenon key.
pub const DIAGNOSTICS: Phenomenon = Phenomenon::new("diagnostics");

/// Statistics and the no-NaN check (phenomenon `diagnostics`).
#[derive(Default)]
pub struct DiagnosticsPlugin;

impl Plugin for DiagnosticsPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            DIAGNOSTICS,
            TectonicSystems::Diagnostics,
            "area statistics and finiteness checks",
        );
        app.add_systems(
            TectonicStep,
            diagnostics::update_diagnostics
                .in_set(TectonicSystems::Diagnostics)
                .run_if(phenomenon_enabled(DIAGNOSTICS)),
        );
    }
}
