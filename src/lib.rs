//! Procedural tectonic planets: plates drift on a sphere, rift, collide and subduct, and
//! continents, ranges, trenches and ridges come out of that history (after Cortial et al. 2019,
//! *Procedural Tectonic Planets*).
//!
//! The simulation is an ECS world (bevy_ecs): per-sample crust fields are structure-of-arrays
//! resources, plates are entities, and each phenomenon is a plugin whose systems sit in one set
//! of the [`TectonicStep`](plugins::TectonicStep) schedule. Start with [`Simulation`].

#![deny(missing_docs)]
// `!(x > 0.0)` is how the relief passes say "not positive, NaN included" on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod amplify;
pub mod commands;
pub mod components;
pub mod geometry;
pub mod gpu;
pub mod io;
pub mod plugins;
pub mod random;
pub mod resources;
pub mod simulation;
pub mod systems;
#[cfg(feature = "viewer")]
pub mod viewer;

pub use simulation::{SimError, Simulation};

/// What a user or plugin author imports.
pub mod prelude {
    pub use crate::commands::{Cap, Command, CrustKind, LatLon, PlateRef, Script};
    pub use crate::components::{
        FrontKind, Plate, PlateBounds, PlateFrame, PlateId, PlateMesh, PlateMotion, PlateStats,
        SubductionFront, Terrane,
    };
    pub use crate::geometry::SphereMesh;
    pub use crate::geometry::spherical::angle_between;
    pub use crate::gpu::{
        BackendChoice, ComputeBackend, FieldMask, GpuContext, pull_or_record, sync_crust_to_host,
        write_crust_fields,
    };
    pub use crate::plugins::{
        AfterResample, AfterResampleSystems, AgingPlugin, AgingSystems, CollisionPlugin,
        DiagnosticsPlugin, DriftPlugin, ErosionPlugin, OceanicCrustPlugin, Phenomena, Phenomenon,
        PhenomenonAppExt, PhenomenonInfo, ResamplePlugin, ResampleSystems, RiftingPlugin,
        SlabPullPlugin, SubductionPlugin, TectonicPlugins, TectonicStep, TectonicSystems,
        TerranePlugin, phenomenon_enabled,
    };
    pub use crate::random::{SimRng, hash3, mix64, unit_f64, unit_vector};
    pub use crate::resources::params::{dry_isostatic_gain, oceanic_load_gain};
    pub use crate::resources::{
        Crust, CrustType, Orogeny, ParamError, ParamKind, ParamSpec, ParamValue, Params,
        PluginConfig, PluginParam, PluginParams, PluginParamsAppExt, ReliefMode, ResampleRequest,
        SaveAppExt, SaveSection, SectionError, SectionReader, SectionWriter, SimClock,
    };
    pub use crate::simulation::{SimError, Simulation};
    pub use bevy_app::{App, Plugin, PluginGroup};
    pub use bevy_ecs::prelude::*;
    pub use glam::{DQuat, DVec3};
}
