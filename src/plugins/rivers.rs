//! River incision and hillslope diffusion (phenomenon [`RIVERS`]): stream power
//! E = K·A^m·S^n − E_c, solved implicitly along the drainage network (Braun & Willett 2013),
//! and diffusion of the land surface; the eroded rock leaves the crust. Systems:
//! [`crate::systems::relief`] ([`erode_rivers`](relief::erode_rivers), on
//! [`relief::stream_power`] and [`relief::diffusion`]). Needs the `drainage` phenomenon.

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::drainage::DRAINAGE;
use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::relief;

/// The phenomenon key.
pub const RIVERS: Phenomenon = Phenomenon::new("rivers");

/// River incision and hillslope diffusion (phenomenon `rivers`).
#[derive(Default)]
pub struct RiversPlugin;

impl Plugin for RiversPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            RIVERS,
            TectonicSystems::Rivers,
            "stream-power incision and hillslope diffusion wear the land down",
        );
        app.init_resource::<relief::ReliefState>()
            .init_resource::<relief::DrainageNetwork>()
            .init_resource::<relief::SurfaceFlux>();
        app.add_systems(
            TectonicStep,
            relief::erode_rivers
                .in_set(TectonicSystems::Rivers)
                .run_if(phenomenon_enabled(RIVERS))
                .run_if(phenomenon_enabled(DRAINAGE)),
        );
    }
}
