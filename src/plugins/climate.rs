//! Rain over the land (phenomenon [`CLIMATE`]): a zonal pattern, moisture carried inland by the
//! prevailing winds, rain shadows behind ranges and more rain on windward slopes. Systems:
//! [`crate::systems::relief`] ([`update_climate`](relief::update_climate), on
//! [`relief::climate`]), which writes the [`Precipitation`](relief::Precipitation) field the
//! drainage weighs its areas with; switched off, the rain is uniform again
//! ([`clear_climate`](relief::clear_climate)). Recomputed every step from the surface, so it
//! needs no save section. Its search runs on the thread pool beside the drainage's routing, and
//! the drainage waits for it before it weighs its areas
//! ([`finish_climate`](relief::finish_climate)); the field is the same as computed in place.

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::drainage::DRAINAGE;
use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::relief;

/// The phenomenon key.
pub const CLIMATE: Phenomenon = Phenomenon::new("climate");

/// Rain over the land (phenomenon `climate`).
#[derive(Default)]
pub struct ClimatePlugin;

impl Plugin for ClimatePlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            CLIMATE,
            TectonicSystems::Climate,
            "rain: wet tropics and coasts, dry interiors and rain shadows behind ranges",
        );
        app.init_resource::<relief::ReliefState>()
            .init_resource::<relief::ClimateState>()
            .init_resource::<relief::Precipitation>();
        app.add_systems(
            TectonicStep,
            (
                relief::update_climate
                    .run_if(phenomenon_enabled(CLIMATE))
                    .run_if(phenomenon_enabled(DRAINAGE))
                    .run_if(relief::drainage_due),
                relief::clear_climate.run_if(not(phenomenon_enabled(CLIMATE))),
            )
                .chain()
                .in_set(TectonicSystems::Climate),
        );
    }
}
