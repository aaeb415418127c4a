//! Coastal erosion (phenomenon [`COASTS`]): a coast facing open water retreats at
//! v₀·exp(−W/W₀), W the width of shallow water in front of it, and leaves a platform at the
//! wave base; the rock removed is carried off with what the rivers eroded and laid down by the
//! sediment. Systems: [`crate::systems::relief::coast`] ([`erode_coasts`](coast::erode_coasts)).
//! Needs the `drainage` phenomenon (the sea mask).

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::drainage::DRAINAGE;
use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::relief;
use crate::systems::relief::coast;

/// The phenomenon key.
pub const COASTS: Phenomenon = Phenomenon::new("coasts");

/// Coastal erosion (phenomenon `coasts`).
#[derive(Default)]
pub struct CoastsPlugin;

impl Plugin for CoastsPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            COASTS,
            TectonicSystems::Coasts,
            "waves cut back coasts and leave a platform that sediment builds into a shelf",
        );
        app.init_resource::<relief::ReliefState>()
            .init_resource::<relief::DrainageNetwork>()
            .init_resource::<relief::SurfaceFlux>()
            .init_resource::<coast::CoastState>();
        app.add_systems(
            TectonicStep,
            coast::erode_coasts
                .in_set(TectonicSystems::Coasts)
                .run_if(phenomenon_enabled(COASTS))
                .run_if(phenomenon_enabled(DRAINAGE)),
        );
    }
}
