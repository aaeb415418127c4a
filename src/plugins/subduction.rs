//! Subduction (phenomenon [`SUBDUCTION`], paper §4.1): fronts are found at each resampling; every
//! step the overriding plates rise (Andean orogeny, island arcs, fold directions) and the
//! subducting plates bend into trenches. Systems: [`crate::systems::convergence::fronts`] and
//! [`crate::systems::convergence::subduction`]; GPU kernels: [`crate::gpu::subduction_uplift`]
//! and [`crate::gpu::crust_gather`]. The front state is saved by [`convergence_section`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::convergence_state::convergence_section;
use super::schedule::{
    AfterResample, AfterResampleSystems, Phenomenon, PhenomenonAppExt, TectonicStep,
    TectonicSystems, phenomenon_enabled,
};
use crate::resources::SaveAppExt;
use crate::systems::convergence::{fronts, subduction};

/// The phenomenon key.
pub const SUBDUCTION: Phenomenon = Phenomenon::new("subduction");

/// Subduction (phenomenon `subduction`): fronts found at each resampling; every step, uplift
/// of the overriding plates (Andean orogeny, island arcs), fold directions and trenches.
#[derive(Default)]
pub struct SubductionPlugin;

impl Plugin for SubductionPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            SUBDUCTION,
            TectonicSystems::Subduction,
            "uplift and trenches at converging boundaries",
        );
        app.register_save_section(convergence_section());
        app.add_systems(
            AfterResample,
            fronts::build_fronts
                .in_set(AfterResampleSystems::Fronts)
                .run_if(phenomenon_enabled(SUBDUCTION)),
        );
        app.add_systems(
            TectonicStep,
            (fronts::track_fronts, subduction::subduction_uplift)
                .chain()
                .in_set(TectonicSystems::Subduction)
                .run_if(phenomenon_enabled(SUBDUCTION)),
        );
    }
}
