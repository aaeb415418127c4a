//! Sediment (phenomenon [`SEDIMENT`]): what the rivers and slopes eroded travels down the
//! network and is laid down in lakes, on shelves to a break near −130 m, on slopes and rises,
//! and in trenches and basins; deposited volume equals eroded volume at each routing. Systems:
//! [`crate::systems::relief`] ([`deposit_sediment`](relief::deposit_sediment), on
//! [`relief::sediment`], with each new network and before a resampling that finds rock still
//! carried; [`lay_pelagic`](relief::lay_pelagic) every step). Needs the `drainage` phenomenon;
//! without `rivers` nothing is carried.

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;

use super::drainage::DRAINAGE;
use super::schedule::{
    Phenomenon, PhenomenonAppExt, ResampleSystems, TectonicStep, TectonicSystems,
    phenomenon_enabled,
};
use crate::systems::relief;

/// The phenomenon key.
pub const SEDIMENT: Phenomenon = Phenomenon::new("sediment");

/// Sediment deposition (phenomenon `sediment`).
#[derive(Default)]
pub struct SedimentPlugin;

impl Plugin for SedimentPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            SEDIMENT,
            TectonicSystems::Sediment,
            "eroded rock builds deltas, shelves and rises, and fills lakes and trenches",
        );
        app.init_resource::<relief::ReliefState>()
            .init_resource::<relief::DrainageNetwork>()
            .init_resource::<relief::SurfaceFlux>();
        app.add_systems(
            TectonicStep,
            (
                relief::deposit_sediment.run_if(relief::sediment_due),
                relief::lay_pelagic.run_if(not(relief::sediment_due)),
            )
                .chain()
                .in_set(TectonicSystems::Sediment)
                .run_if(phenomenon_enabled(SEDIMENT))
                .run_if(phenomenon_enabled(DRAINAGE)),
        );
        // Rock still carried from the steps since the last network is laid down on it before
        // a resampling moves the samples it is recorded on.
        app.add_systems(
            TectonicStep,
            relief::deposit_carried_sediment
                .in_set(TectonicSystems::Resample)
                .before(ResampleSystems::Interpolate)
                .run_if(phenomenon_enabled(SEDIMENT))
                .run_if(phenomenon_enabled(DRAINAGE))
                .run_if(relief::sediment_carried)
                .run_if(crate::systems::resample::resample_due),
        );
    }
}
