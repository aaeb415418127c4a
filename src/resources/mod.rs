//! Resources of the simulation world: the crust fields, the clock, the plate lookup table used
//! by per-sample kernels, step timings, the parameters and their schema ([`params`], and the
//! plugins' [`plugin_params`]), the save-section API ([`save_section`]), and the defensive
//! reading of user files ([`input`]).

pub mod convergence;
pub mod crust;
pub mod input;
pub mod params;
pub mod plate_table;
pub mod plugin_params;
pub mod save_section;
pub mod timings;

pub use convergence::{
    ConvergenceField, FrontPoints, OverridePairs, RiftSiblings, Suture, Sutures, TerraneField,
};
pub use crust::{Crust, CrustType, NO_PLATE, NonFinite, Orogeny};
pub use params::{ParamError, ParamKind, ParamSpec, ParamValue, Params};
pub use plate_table::{PlateState, PlateTable, PlateTableQuery};
pub use plugin_params::{PluginConfig, PluginParam, PluginParams, PluginParamsAppExt};
pub use save_section::{
    LoadError, LoadErrorKind, RawSection, SaveAppExt, SaveError, SaveRegistry, SaveSection,
    SectionError, SectionReader, SectionWriter,
};
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

/// How the crust's relief is made (a resource, mirrored from the phenomenon switches at the start
/// of every step by the simulation): with `isostatic`, subduction and collisions thicken the
/// crust and the `isostasy` phenomenon derives the elevation; without, they raise the elevation
/// directly and cut trenches into it, as the paper does.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReliefMode {
    /// The `isostasy` phenomenon is on.
    pub isostatic: bool,
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

/// What was done to a planet, in order: one line per command (generate, resume...), with the
/// step at which it took effect. Saved as the `core.history` section.
#[derive(Resource, Clone, Debug, Default, PartialEq, Eq)]
pub struct CommandHistory {
    /// `(step, command line)`, oldest first.
    pub entries: Vec<(u64, String)>,
}

impl CommandHistory {
    /// Appends a command taking effect at `step`.
    pub fn record(&mut self, step: u64, command: impl Into<String>) {
        self.entries.push((step, command.into()));
    }
}
