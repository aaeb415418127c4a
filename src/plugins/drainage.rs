//! The drainage network (phenomenon [`DRAINAGE`]): each land sample drains to one neighbour by
//! great-circle slope, closed depressions become lakes that overflow, every river ends in the
//! sea. Systems: [`crate::systems::relief`] ([`build_drainage`](relief::build_drainage), on
//! [`relief::drainage`]). Rebuilt every step; the rivers and the sediment follow it, and the
//! maps draw it.

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::relief;

/// The phenomenon key.
pub const DRAINAGE: Phenomenon = Phenomenon::new("drainage");

/// The drainage network of the surface (phenomenon `drainage`).
#[derive(Default)]
pub struct DrainagePlugin;

impl Plugin for DrainagePlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            DRAINAGE,
            TectonicSystems::Drainage,
            "rivers: each land sample drains to the sea; depressions fill to lakes",
        );
        app.init_resource::<relief::ReliefState>()
            .init_resource::<relief::DrainageNetwork>()
            .init_resource::<relief::SurfaceFlux>();
        app.add_systems(
            TectonicStep,
            relief::build_drainage
                .in_set(TectonicSystems::Drainage)
                .run_if(phenomenon_enabled(DRAINAGE))
                .run_if(relief::relief_due),
        );
    }
}
