//! Slab pull (phenomenon [`SLAB_PULL`], paper §4.1): subducting plates turn toward their fronts.
//! Systems: [`crate::systems::convergence::slab_pull`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::convergence_state::convergence_section;
use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::resources::SaveAppExt;
use crate::systems::convergence::slab_pull;

/// The phenomenon key.
pub const SLAB_PULL: Phenomenon = Phenomenon::new("slab_pull");

/// Slab pull (phenomenon `slab_pull`): subducting plates turn toward their fronts.
#[derive(Default)]
pub struct SlabPullPlugin;

impl Plugin for SlabPullPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            SLAB_PULL,
            TectonicSystems::SlabPull,
            "subducting plates turn toward their fronts",
        );
        app.register_save_section(convergence_section());
        app.add_systems(
            TectonicStep,
            slab_pull::slab_pull
                .in_set(TectonicSystems::SlabPull)
                .run_if(phenomenon_enabled(SLAB_PULL)),
        );
    }
}
