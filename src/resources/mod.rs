//! Resources of the simulation world: the crust fields, the clock, the plate lookup table used
//! by per-sample kernels, the phenomenon registry (run-time switches) and step timings.

pub mod convergence;
pub mod crust;
pub mod phenomena;
pub mod plate_table;
pub mod timings;

pub use convergence::{
    ConvergenceField, FrontPoints, OverridePairs, Suture, Sutures, TerraneField,
};
pub use crust::{Crust, CrustType, NO_PLATE, NonFinite, Orogeny};
pub use phenomena::{Phenomena, PhenomenonInfo, phenomenon_enabled};
pub use plate_table::{PlateState, PlateTable};
pub use timings::StepTimings;

use bevy_ecs::prelude::*;
use serde::{Deserialize, Serialize};

/// Simulated time.
#[derive(Resource, Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SimClock {
    /// Steps taken since the start.
    pub step: u64,
    /// Simulated time since the start, My.
    pub time_my: f64,
    /// Steps taken since the last global resampling.
    pub steps_since_resample: u64,
    /// Number of global resamplings so far.
    pub resamplings: u64,
}

/// Set by any system or command to ask for a global resampling at the end of this step.
#[derive(Resource, Clone, Debug, Default, PartialEq, Eq)]
pub struct ResampleRequest(pub bool);

/// Area statistics of the crust, refreshed by the diagnostics system each step.
#[derive(Resource, Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CrustStats {
    /// Fraction of the surface above sea level.
    pub land_fraction: f64,
    /// Fraction of the surface with continental crust.
    pub continental_fraction: f64,
    /// Number of plates.
    pub plates: usize,
    /// Lowest and highest elevation, km.
    pub elevation_range_km: (f32, f32),
}

/// Id that the next new plate gets.
#[derive(Resource, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct NextPlateId(pub u32);
