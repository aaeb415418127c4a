//! Terranes (phenomenon [`TERRANES`], paper §4.2, §6): the connected continental regions of
//! each plate, as entities, rebuilt after every resampling (and trapped slivers of ocean closed).
//! Systems: [`crate::systems::convergence::terranes`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::convergence_state::convergence_section;
use super::schedule::{
    AfterResample, AfterResampleSystems, Phenomenon, PhenomenonAppExt, TectonicSystems,
    phenomenon_enabled,
};
use crate::resources::SaveAppExt;
use crate::systems::convergence::terranes;

/// The phenomenon key.
pub const TERRANES: Phenomenon = Phenomenon::new("terranes");

/// Terranes (phenomenon `terranes`): connected continental regions of each plate, as entities,
/// rebuilt at each resampling.
#[derive(Default)]
pub struct TerranePlugin;

impl Plugin for TerranePlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            TERRANES,
            TectonicSystems::Resample,
            "continental regions of each plate, as entities",
        );
        app.register_save_section(convergence_section());
        app.add_systems(
            AfterResample,
            (terranes::close_trapped_ocean, terranes::build_terranes)
                .chain()
                .in_set(AfterResampleSystems::Terranes)
                .run_if(phenomenon_enabled(TERRANES)),
        );
    }
}
