//! Isostasy (phenomenon [`ISOSTASY`]): the elevation follows from the crust. Continents float
//! on the mantle (Airy, with a regional response standing in for flexure); ocean floor sinks
//! with age (plate cooling), raised by its load; a trench is cut in front of each active
//! subduction front. With it on, subduction, collisions, erosion and deposition change the
//! crust's thickness and the elevation is derived; off, the kernels raise the elevation as the
//! paper does. Systems: [`crate::systems::relief`] ([`apply_isostasy`](relief::apply_isostasy),
//! on [`relief::isostasy`]).

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::schedule::{
    Phenomenon, PhenomenonAppExt, TectonicStep, TectonicSystems, phenomenon_enabled,
};
use crate::systems::relief;

/// The phenomenon key.
pub const ISOSTASY: Phenomenon = Phenomenon::new("isostasy");

/// Elevation from the crust (phenomenon `isostasy`).
#[derive(Default)]
pub struct IsostasyPlugin;

impl Plugin for IsostasyPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            ISOSTASY,
            TectonicSystems::Isostasy,
            "elevation from crust thickness (continents) and sea-floor age (ocean)",
        );
        app.init_resource::<relief::ReliefState>();
        app.add_systems(
            TectonicStep,
            relief::apply_isostasy
                .in_set(TectonicSystems::Isostasy)
                .run_if(phenomenon_enabled(ISOSTASY)),
        );
    }
}
