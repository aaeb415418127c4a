//! The step schedule and its plugins. One step is one run of the [`TectonicStep`] schedule, whose
//! shape is set once, here, as a chain of system sets:
//!
//! 1. [`TectonicSystems::Collision`]: continental collisions (discrete events).
//! 2. [`TectonicSystems::Drift`]: plates turn about their Euler poles.
//! 3. [`TectonicSystems::Subduction`]: uplift at converging boundaries.
//! 4. [`TectonicSystems::Erosion`]: continental erosion, oceanic damping, sediment accretion.
//! 5. [`TectonicSystems::SlabPull`]: subducting plates turn toward their fronts.
//! 6. [`TectonicSystems::Rifting`]: plates break apart.
//! 7. [`TectonicSystems::Aging`]: crust and orogenies age.
//! 8. [`TectonicSystems::Resample`]: global resampling when due, in three chained sub-sets
//!    ([`ResampleSystems::Interpolate`], [`ResampleSystems::FillGaps`],
//!    [`ResampleSystems::Rebuild`]).
//! 9. [`TectonicSystems::Diagnostics`]: statistics and checks.
//!
//! Each phenomenon is a plugin that puts its systems in its set, registers itself in
//! [`Phenomena`](crate::resources::Phenomena) and guards its systems with
//! [`phenomenon_enabled`](crate::resources::phenomenon_enabled), so it can be switched off at
//! run time. [`TectonicPlugins`] groups the built-in ones; a user can `disable` one and `add` a
//! replacement.

use std::time::Instant;

use bevy_app::{App, Plugin, PluginGroup, PluginGroupBuilder};
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::{ScheduleLabel, SingleThreadedExecutor};

use crate::resources::{Phenomena, ResampleRequest, SimClock, StepTimings, phenomenon_enabled};
use crate::systems::{
    aging, convergence, diagnostics, drift, erosion, oceanic_crust, resample, rifting,
};

/// The schedule that runs one tectonic time step.
#[derive(ScheduleLabel, Clone, Debug, PartialEq, Eq, Hash)]
pub struct TectonicStep;

/// A schedule run right after every global resampling (and once on the initial planet), when
/// every plate is in the reference frame: collision uplift, terranes and subduction fronts are
/// (re)built here, in the chained sets [`AfterResampleSystems`].
#[derive(ScheduleLabel, Clone, Debug, PartialEq, Eq, Hash)]
pub struct AfterResample;

/// The ordered phases of [`AfterResample`].
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AfterResampleSystems {
    /// Uplift around terranes sutured by the resampling.
    Collision,
    /// Terranes rebuilt.
    Terranes,
    /// Subduction fronts and distance fields rebuilt.
    Fronts,
}

/// The ordered phases of a step (see the module documentation).
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum TectonicSystems {
    /// Continental collisions.
    Collision,
    /// Plate drift.
    Drift,
    /// Subduction uplift.
    Subduction,
    /// Erosion, damping, sediment accretion.
    Erosion,
    /// Slab pull.
    SlabPull,
    /// Plate rifting.
    Rifting,
    /// Crust aging.
    Aging,
    /// Global resampling.
    Resample,
    /// Statistics and checks.
    Diagnostics,
}

impl TectonicSystems {
    /// Every set, in step order.
    pub const ALL: [TectonicSystems; 9] = [
        Self::Collision,
        Self::Drift,
        Self::Subduction,
        Self::Erosion,
        Self::SlabPull,
        Self::Rifting,
        Self::Aging,
        Self::Resample,
        Self::Diagnostics,
    ];
    /// Lower-case name used in timings and listings.
    pub fn name(self) -> &'static str {
        match self {
            Self::Collision => "collision",
            Self::Drift => "drift",
            Self::Subduction => "subduction",
            Self::Erosion => "erosion",
            Self::SlabPull => "slab_pull",
            Self::Rifting => "rifting",
            Self::Aging => "aging",
            Self::Resample => "resample",
            Self::Diagnostics => "diagnostics",
        }
    }
}

/// The phases of a resampling, chained inside [`TectonicSystems::Resample`].
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ResampleSystems {
    /// Locate samples in the moved plates and interpolate; find gaps.
    Interpolate,
    /// Gap fillers (new oceanic crust) write the gap samples.
    FillGaps,
    /// Install the new crust and rebuild the plates.
    Rebuild,
}

/// Timing marks around each set (internal).
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum TimingMark {
    Begin(TectonicSystems),
    End(TectonicSystems),
}

/// Registers a phenomenon from a plugin's `build`.
pub trait PhenomenonAppExt {
    /// Adds `name` to the [`Phenomena`] registry (enabled), in `set`.
    fn register_phenomenon(
        &mut self,
        name: &'static str,
        set: TectonicSystems,
        description: &'static str,
    ) -> &mut Self;
    /// Adds `name` to the [`Phenomena`] registry in `set`, on or off in a new simulation
    /// (`--enable NAME` or [`Simulation::set_enabled`](crate::Simulation::set_enabled) turns an
    /// off-by-default phenomenon on).
    fn register_phenomenon_with_default(
        &mut self,
        name: &'static str,
        set: TectonicSystems,
        description: &'static str,
        enabled_by_default: bool,
    ) -> &mut Self;
}

impl PhenomenonAppExt for App {
    fn register_phenomenon(
        &mut self,
        name: &'static str,
        set: TectonicSystems,
        description: &'static str,
    ) -> &mut Self {
        self.register_phenomenon_with_default(name, set, description, true)
    }

    fn register_phenomenon_with_default(
        &mut self,
        name: &'static str,
        set: TectonicSystems,
        description: &'static str,
        enabled_by_default: bool,
    ) -> &mut Self {
        self.init_resource::<Phenomena>();
        self.world_mut()
            .resource_mut::<Phenomena>()
            .register_with_default(name, set, description, enabled_by_default);
        self
    }
}

/// The schedule itself: the [`TectonicStep`] schedule, its chained sets, the timing marks and
/// the core resources. Always present; not a phenomenon.
pub struct TectonicSchedulePlugin;

impl Plugin for TectonicSchedulePlugin {
    fn build(&self, app: &mut App) {
        let mut schedule = Schedule::new(TectonicStep);
        schedule.set_executor(SingleThreadedExecutor::new());
        app.add_schedule(schedule);
        let mut after = Schedule::new(AfterResample);
        after.set_executor(SingleThreadedExecutor::new());
        app.add_schedule(after);
        app.configure_sets(
            AfterResample,
            (
                AfterResampleSystems::Collision,
                AfterResampleSystems::Terranes,
                AfterResampleSystems::Fronts,
            )
                .chain(),
        );
        app.init_resource::<Phenomena>()
            .init_resource::<StepTimings>()
            .init_resource::<SimClock>()
            .init_resource::<ResampleRequest>()
            .init_resource::<resample::ResampleWork>()
            .init_resource::<diagnostics::CrustHealth>()
            .init_resource::<crate::resources::CrustStats>()
            .init_resource::<crate::resources::FrontPoints>()
            .init_resource::<crate::resources::ConvergenceField>()
            .init_resource::<crate::resources::OverridePairs>()
            .init_resource::<crate::resources::TerraneField>()
            .init_resource::<crate::resources::Sutures>()
            .init_resource::<crate::gpu::ComputeBackend>();
        for set in TectonicSystems::ALL {
            app.configure_sets(
                TectonicStep,
                (TimingMark::Begin(set), set, TimingMark::End(set)).chain(),
            );
            app.add_systems(TectonicStep, begin_timing.in_set(TimingMark::Begin(set)));
            let name = set.name();
            app.add_systems(
                TectonicStep,
                (move |mut t: ResMut<StepTimings>| end_timing(&mut t, name))
                    .in_set(TimingMark::End(set)),
            );
        }
        for pair in TectonicSystems::ALL.windows(2) {
            app.configure_sets(
                TectonicStep,
                TimingMark::End(pair[0]).before(TimingMark::Begin(pair[1])),
            );
        }
        app.configure_sets(
            TectonicStep,
            (
                ResampleSystems::Interpolate,
                ResampleSystems::FillGaps,
                ResampleSystems::Rebuild,
            )
                .chain()
                .in_set(TectonicSystems::Resample),
        );
        app.add_systems(TectonicStep, advance_clock.in_set(TectonicSystems::Aging));
    }
}

fn begin_timing(mut t: ResMut<StepTimings>) {
    t.started = Some(Instant::now());
}

fn end_timing(t: &mut StepTimings, name: &'static str) {
    if let Some(s) = t.started.take() {
        t.record(name, s.elapsed());
    }
}

/// Advances the clock by one step (runs in every step, before resampling decides).
fn advance_clock(mut clock: ResMut<SimClock>, params: Res<crate::io::params::Params>) {
    clock.step += 1;
    clock.time_my += params.time.time_step_my;
    clock.steps_since_resample += 1;
}

macro_rules! phenomenon_plugin {
    ($(#[$doc:meta])* $plugin:ident, $name:literal, $set:expr, $desc:literal, $systems:expr) => {
        $(#[$doc])*
        #[derive(Default)]
        pub struct $plugin;
        impl Plugin for $plugin {
            fn build(&self, app: &mut App) {
                app.register_phenomenon($name, $set, $desc);
                app.add_systems(TectonicStep, $systems.run_if(phenomenon_enabled($name)));
            }
        }
    };
}

phenomenon_plugin!(
    /// Plate drift: each plate turns about its Euler pole (phenomenon `drift`).
    DriftPlugin, "drift", TectonicSystems::Drift, "plates turn about their Euler poles",
    drift::drift_plates.in_set(TectonicSystems::Drift)
);
phenomenon_plugin!(
    /// Continental erosion, oceanic damping and sediment accretion (phenomenon `erosion`).
    ErosionPlugin, "erosion", TectonicSystems::Erosion, "continental erosion, oceanic damping, sediment accretion",
    erosion::erode.in_set(TectonicSystems::Erosion)
);
/// Plate rifting (phenomenon `rifting`): plates break into 2–4 diverging fragments at random
/// (a Poisson process favouring large, continental plates; see [`rifting`]).
#[derive(Default)]
pub struct RiftingPlugin;

impl Plugin for RiftingPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            "rifting",
            TectonicSystems::Rifting,
            "large plates break into diverging fragments",
        );
        app.init_resource::<rifting::RiftLog>();
        app.add_systems(
            TectonicStep,
            rifting::rift_plates
                .in_set(TectonicSystems::Rifting)
                .run_if(phenomenon_enabled("rifting")),
        );
    }
}

phenomenon_plugin!(
    /// Crust and orogeny aging (phenomenon `aging`).
    AgingPlugin, "aging", TectonicSystems::Aging, "crust and orogeny ages grow by the time step",
    aging::age_crust.in_set(TectonicSystems::Aging)
);
phenomenon_plugin!(
    /// New oceanic crust with a ridge in the gaps between diverging plates (phenomenon
    /// `oceanic_crust`); without it, gaps are filled by stretching the nearest plate.
    OceanicCrustPlugin, "oceanic_crust", TectonicSystems::Resample, "new ocean floor and ridges in divergent gaps",
    oceanic_crust::generate_oceanic_crust.in_set(ResampleSystems::FillGaps)
);
phenomenon_plugin!(
    /// Statistics and the no-NaN check (phenomenon `diagnostics`).
    DiagnosticsPlugin, "diagnostics", TectonicSystems::Diagnostics, "area statistics and finiteness checks",
    diagnostics::update_diagnostics.in_set(TectonicSystems::Diagnostics)
);

/// Subduction (phenomenon `subduction`): fronts found at each resampling; every step, uplift
/// of the overriding plates (Andean orogeny, island arcs), fold directions and trenches.
#[derive(Default)]
pub struct SubductionPlugin;

impl Plugin for SubductionPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            "subduction",
            TectonicSystems::Subduction,
            "uplift and trenches at converging boundaries",
        );
        app.add_systems(
            AfterResample,
            convergence::build_fronts
                .in_set(AfterResampleSystems::Fronts)
                .run_if(phenomenon_enabled("subduction")),
        );
        app.add_systems(
            TectonicStep,
            (convergence::track_fronts, convergence::subduction_uplift)
                .chain()
                .in_set(TectonicSystems::Subduction)
                .run_if(phenomenon_enabled("subduction")),
        );
    }
}

phenomenon_plugin!(
    /// Slab pull (phenomenon `slab_pull`): subducting plates turn toward their fronts.
    SlabPullPlugin, "slab_pull", TectonicSystems::SlabPull, "subducting plates turn toward their fronts",
    convergence::slab_pull.in_set(TectonicSystems::SlabPull)
);

/// Terranes (phenomenon `terranes`): connected continental regions of each plate, as entities,
/// rebuilt at each resampling.
#[derive(Default)]
pub struct TerranePlugin;

impl Plugin for TerranePlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            "terranes",
            TectonicSystems::Resample,
            "continental regions of each plate, as entities",
        );
        app.add_systems(
            AfterResample,
            (
                convergence::close_trapped_ocean,
                convergence::build_terranes,
            )
                .chain()
                .in_set(AfterResampleSystems::Terranes)
                .run_if(phenomenon_enabled("terranes")),
        );
    }
}

/// Continental collisions (phenomenon `collision`): a terrane more than the interpenetration
/// threshold under another plate's continent sutures to it, with a Himalayan surge around it.
#[derive(Default)]
pub struct CollisionPlugin;

impl Plugin for CollisionPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            "collision",
            TectonicSystems::Collision,
            "continental collisions: terranes suture, Himalayan uplift",
        );
        app.add_systems(
            TectonicStep,
            (
                convergence::detect_collisions
                    .in_set(TectonicSystems::Collision)
                    .run_if(phenomenon_enabled("collision")),
                convergence::collide_before_resample
                    .in_set(ResampleSystems::Interpolate)
                    .before(resample::resample_interpolate)
                    .run_if(phenomenon_enabled("collision"))
                    .run_if(phenomenon_enabled("resample"))
                    .run_if(resample::resample_due),
            ),
        );
        app.add_systems(
            AfterResample,
            convergence::collision_uplift
                .in_set(AfterResampleSystems::Collision)
                .run_if(phenomenon_enabled("collision")),
        );
    }
}

/// Global resampling every 10–60 steps (adaptive) or on request (phenomenon `resample`).
#[derive(Default)]
pub struct ResamplePlugin;

impl Plugin for ResamplePlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon(
            "resample",
            TectonicSystems::Resample,
            "global resampling onto the reference mesh",
        );
        app.add_systems(
            TectonicStep,
            (
                resample::resample_interpolate
                    .in_set(ResampleSystems::Interpolate)
                    .run_if(phenomenon_enabled("resample"))
                    .run_if(resample::resample_due),
                resample::resample_rebuild.in_set(ResampleSystems::Rebuild),
            ),
        );
    }
}

/// The built-in phenomena, in schedule order, and the contributed ones (written against the
/// prelude only, in [`crate::contrib`]; hotspots start switched off). Disable one with
/// `TectonicPlugins.build().disable::<ErosionPlugin>()` and add your own in its place.
pub struct TectonicPlugins;

impl PluginGroup for TectonicPlugins {
    fn build(self) -> PluginGroupBuilder {
        PluginGroupBuilder::start::<Self>()
            .add(CollisionPlugin)
            .add(DriftPlugin)
            .add(SubductionPlugin)
            .add(ErosionPlugin)
            .add(SlabPullPlugin)
            .add(RiftingPlugin)
            .add(AgingPlugin)
            .add(ResamplePlugin)
            .add(TerranePlugin)
            .add(OceanicCrustPlugin)
            .add(DiagnosticsPlugin)
            .add(crate::contrib::HotspotPlugin)
    }
}
