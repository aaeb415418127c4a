//! The plugins: one file per phenomenon, each putting its systems in one set of the step
//! schedule ([`schedule`]), registering its [`Phenomenon`] key, its parameters and its save
//! sections. [`TectonicPlugins`] lists the group.

pub mod aging;
pub mod climate;
pub mod coasts;
pub mod collision;
pub mod convergence_state;
pub mod diagnostics;
pub mod drainage;
pub mod drift;
pub mod erosion;
pub mod hotspots;
pub mod isostasy;
pub mod oceanic_crust;
pub mod resample;
pub mod rifting;
pub mod rivers;
pub mod schedule;
pub mod sediment;
pub mod slab_pull;
pub mod subduction;
pub mod terranes;

use bevy_app::{PluginGroup, PluginGroupBuilder};

pub use aging::AgingPlugin;
pub use climate::ClimatePlugin;
pub use coasts::CoastsPlugin;
pub use collision::CollisionPlugin;
pub use diagnostics::DiagnosticsPlugin;
pub use drainage::DrainagePlugin;
pub use drift::DriftPlugin;
pub use erosion::ErosionPlugin;
pub use hotspots::HotspotPlugin;
pub use isostasy::IsostasyPlugin;
pub use oceanic_crust::OceanicCrustPlugin;
pub use resample::ResamplePlugin;
pub use rifting::RiftingPlugin;
pub use rivers::RiversPlugin;
pub use schedule::{
    AfterResample, AfterResampleSystems, AgingSystems, Phenomena, Phenomenon, PhenomenonAppExt,
    PhenomenonInfo, ResampleSystems, TectonicSchedulePlugin, TectonicStep, TectonicSystems,
    UnknownPhenomenon, phenomenon_enabled,
};
pub use sediment::SedimentPlugin;
pub use slab_pull::SlabPullPlugin;
pub use subduction::SubductionPlugin;
pub use terranes::TerranePlugin;

/// The built-in phenomena, in schedule order, then the hotspots (written against the prelude
/// only, off by default). Disable one with `TectonicPlugins.build().disable::<ErosionPlugin>()`
/// and add your own in its place.
pub struct TectonicPlugins;

impl PluginGroup for TectonicPlugins {
    fn build(self) -> PluginGroupBuilder {
        PluginGroupBuilder::start::<Self>()
            .add(CollisionPlugin)
            .add(DriftPlugin)
            .add(SubductionPlugin)
            .add(ErosionPlugin)
            .add(ClimatePlugin)
            .add(DrainagePlugin)
            .add(RiversPlugin)
            .add(CoastsPlugin)
            .add(SedimentPlugin)
            .add(SlabPullPlugin)
            .add(RiftingPlugin)
            .add(AgingPlugin)
            .add(IsostasyPlugin)
            .add(ResamplePlugin)
            .add(TerranePlugin)
            .add(OceanicCrustPlugin)
            .add(DiagnosticsPlugin)
            .add(HotspotPlugin)
    }
}
