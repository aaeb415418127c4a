//! The step schedule, set once here: one step is one run of the [`TectonicStep`] schedule, a
//! chain of system sets:
//!
//! 1. [`TectonicSystems::Collision`]: continental collisions (discrete events).
//! 2. [`TectonicSystems::Drift`]: plates turn about their Euler poles.
//! 3. [`TectonicSystems::Subduction`]: uplift at converging boundaries.
//! 4. [`TectonicSystems::Erosion`]: the paper's continental erosion, oceanic damping and
//!    sediment accretion (off by default: the relief phenomena below replace it).
//! 5. [`TectonicSystems::Climate`]: rain over the land from the winds.
//! 6. [`TectonicSystems::Drainage`]: the drainage network of the surface.
//! 7. [`TectonicSystems::Rivers`]: stream-power incision and hillslope diffusion.
//! 8. [`TectonicSystems::Coasts`]: waves cut back the coasts.
//! 9. [`TectonicSystems::Sediment`]: what was eroded is laid down.
//! 10. [`TectonicSystems::Isostasy`]: the elevation follows from the crust (thickness, age).
//! 11. [`TectonicSystems::SlabPull`]: subducting plates turn toward their fronts.
//! 12. [`TectonicSystems::Rifting`]: plates break apart.
//! 13. [`TectonicSystems::Aging`]: crust and orogenies age (the clock first, then the crust,
//!     then plugins that build on this step's ages: [`AgingSystems`]).
//! 14. [`TectonicSystems::Resample`]: global resampling when due, in three chained sub-sets
//!     ([`ResampleSystems::Interpolate`], [`ResampleSystems::FillGaps`],
//!     [`ResampleSystems::Rebuild`]).
//! 15. [`TectonicSystems::Diagnostics`]: statistics and checks.
//!
//! After every global resampling the [`AfterResample`] schedule rebuilds what depends on the
//! plates ([`AfterResampleSystems`]: collision uplift, terranes, fronts, then plugin state
//! carried to the new plates).
//!
//! Both schedules run on one thread, and ambiguity detection is an error: two systems that touch
//! the same data must be ordered, so the order of a step never rests on registration order.
//!
//! Each phenomenon is a plugin that puts its systems in its set, registers itself in
//! [`Phenomena`] under a [`Phenomenon`] key and guards its systems with
//! [`phenomenon_enabled`], so it can be switched off at run time.

use std::time::Instant;

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::{LogLevel, ScheduleBuildSettings, ScheduleLabel, SingleThreadedExecutor};

use crate::resources::{Params, ResampleRequest, SimClock, StepTimings};
use crate::systems::{diagnostics, resample};

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
    /// Plugin state that rides on the plates carried to the new plates (hotspot edifices).
    Carry,
    /// The elevation derived again from the resampled crust (isostasy, with the rebuilt fronts'
    /// trenches), so the maps and the next step read it rather than the interpolated one.
    Relief,
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
    /// The paper's erosion, damping, sediment accretion.
    Erosion,
    /// Rain over the land.
    Climate,
    /// The drainage network.
    Drainage,
    /// River incision and hillslope diffusion.
    Rivers,
    /// Coastal erosion.
    Coasts,
    /// Sediment deposition.
    Sediment,
    /// Elevation from the crust.
    Isostasy,
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
    pub const ALL: [TectonicSystems; 15] = [
        Self::Collision,
        Self::Drift,
        Self::Subduction,
        Self::Erosion,
        Self::Climate,
        Self::Drainage,
        Self::Rivers,
        Self::Coasts,
        Self::Sediment,
        Self::Isostasy,
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
            Self::Climate => "climate",
            Self::Drainage => "drainage",
            Self::Rivers => "rivers",
            Self::Coasts => "coasts",
            Self::Sediment => "sediment",
            Self::SlabPull => "slab_pull",
            Self::Rifting => "rifting",
            Self::Aging => "aging",
            Self::Isostasy => "isostasy",
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

/// The phases of [`TectonicSystems::Aging`], chained: the clock advances, then the crust ages,
/// then whatever builds on this step's ages and positions (hotspots).
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AgingSystems {
    /// The clock advances by one step.
    Clock,
    /// Crust and orogeny ages grow.
    Crust,
    /// Plugins that act on the aged crust.
    After,
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
        name: impl Into<Phenomenon>,
        set: TectonicSystems,
        description: &'static str,
    ) -> &mut Self;
    /// Adds `name` to the [`Phenomena`] registry in `set`, on or off in a new simulation
    /// (`--enable NAME` or [`Simulation::set_enabled`](crate::Simulation::set_enabled) turns an
    /// off-by-default phenomenon on).
    fn register_phenomenon_with_default(
        &mut self,
        name: impl Into<Phenomenon>,
        set: TectonicSystems,
        description: &'static str,
        enabled_by_default: bool,
    ) -> &mut Self;
}

impl PhenomenonAppExt for App {
    fn register_phenomenon(
        &mut self,
        name: impl Into<Phenomenon>,
        set: TectonicSystems,
        description: &'static str,
    ) -> &mut Self {
        self.register_phenomenon_with_default(name, set, description, true)
    }

    fn register_phenomenon_with_default(
        &mut self,
        name: impl Into<Phenomenon>,
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
        app.add_schedule(step_schedule(TectonicStep));
        app.add_schedule(step_schedule(AfterResample));
        app.configure_sets(
            AfterResample,
            (
                AfterResampleSystems::Collision,
                AfterResampleSystems::Terranes,
                AfterResampleSystems::Fronts,
                AfterResampleSystems::Carry,
                AfterResampleSystems::Relief,
            )
                .chain(),
        );
        app.init_resource::<Phenomena>()
            .init_resource::<StepTimings>()
            .init_resource::<SimClock>()
            .init_resource::<crate::resources::ReliefMode>()
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
        app.configure_sets(
            TectonicStep,
            (
                AgingSystems::Clock,
                AgingSystems::Crust,
                AgingSystems::After,
            )
                .chain()
                .in_set(TectonicSystems::Aging),
        );
        app.add_systems(TectonicStep, advance_clock.in_set(AgingSystems::Clock));
    }
}

/// Runs the [`AfterResample`] schedule when a resampling installed its crust this step (fronts,
/// terranes and collision uplift rebuilt on the new crust; timed apart as `after_resample`),
/// then frees the resampling's buffers and hands the allocator's free pages back. The last system of
/// [`ResampleSystems::Rebuild`].
pub fn run_after_resample(world: &mut World) {
    let rebuilt = world
        .get_resource::<resample::ResampleWork>()
        .is_some_and(|w| w.rebuilt);
    if !rebuilt {
        return;
    }
    let t_after = Instant::now();
    let _ = world.try_run_schedule(AfterResample);
    if let Some(mut w) = world.get_resource_mut::<resample::ResampleWork>() {
        w.rebuilt = false;
        w.release_buffers();
    }
    world
        .resource_mut::<StepTimings>()
        .record("after_resample", t_after.elapsed());
    {
        let _t = crate::systems::DebugTimer::new("release_free_memory");
        resample::release_free_memory();
    }
}

/// A schedule of the step: one thread, and any ambiguity (two unordered systems touching the
/// same data) refused when it is built.
fn step_schedule(label: impl ScheduleLabel) -> Schedule {
    let mut schedule = Schedule::new(label);
    schedule.set_executor(SingleThreadedExecutor::new());
    schedule.set_build_settings(ScheduleBuildSettings {
        ambiguity_detection: LogLevel::Error,
        ..Default::default()
    });
    schedule
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
fn advance_clock(mut clock: ResMut<SimClock>, params: Res<Params>) {
    clock.step += 1;
    clock.time_my += params.time.time_step_my;
    clock.steps_since_resample += 1;
}

/// The key of a phenomenon: the name it is registered under, switched by (`--disable erosion`)
/// and saved with. Each plugin declares its key once as a constant (e.g.
/// [`EROSION`](crate::plugins::erosion::EROSION)) and uses it everywhere.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Phenomenon(&'static str);

impl Phenomenon {
    /// The key named `name` (short, lower case, unique: `[a-z_]+` by convention).
    pub const fn new(name: &'static str) -> Self {
        Self(name)
    }
    /// Its name.
    pub const fn name(self) -> &'static str {
        self.0
    }
}

impl From<&'static str> for Phenomenon {
    fn from(name: &'static str) -> Self {
        Self(name)
    }
}

impl std::fmt::Display for Phenomenon {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.0)
    }
}

/// A phenomenon name that no plugin registered.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown phenomenon \"{}\"; registered: {}",
    crate::resources::input::clip(name),
    registered.join(", ")
)]
pub struct UnknownPhenomenon {
    /// The name asked for.
    pub name: String,
    /// Every registered name, in registration order.
    pub registered: Vec<&'static str>,
}

/// Description of one registered phenomenon.
#[derive(Clone, Debug, PartialEq)]
pub struct PhenomenonInfo {
    /// Short unique name used on the command line (`--disable erosion`).
    pub name: &'static str,
    /// The system set its systems live in.
    pub set: TectonicSystems,
    /// One line for listings.
    pub description: &'static str,
    /// Whether its systems run.
    pub enabled: bool,
    /// Whether it is on in a new simulation (what `planet plugins` shows as the default).
    pub default_enabled: bool,
}

/// All registered phenomena in registration order (a resource).
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct Phenomena {
    entries: Vec<PhenomenonInfo>,
}

impl Phenomena {
    /// Adds a phenomenon (enabled). Registering a name twice keeps the first entry.
    pub fn register(
        &mut self,
        name: impl Into<Phenomenon>,
        set: TectonicSystems,
        description: &'static str,
    ) {
        self.register_with_default(name, set, description, true);
    }
    /// Adds a phenomenon that starts on (`enabled_by_default`) or off. Registering a name twice
    /// keeps the first entry.
    pub fn register_with_default(
        &mut self,
        name: impl Into<Phenomenon>,
        set: TectonicSystems,
        description: &'static str,
        enabled_by_default: bool,
    ) {
        let name = name.into().name();
        if !self.entries.iter().any(|e| e.name == name) {
            self.entries.push(PhenomenonInfo {
                name,
                set,
                description,
                enabled: enabled_by_default,
                default_enabled: enabled_by_default,
            });
        }
    }
    /// Whether `name` is registered and enabled.
    pub fn is_enabled(&self, name: &str) -> bool {
        self.entries.iter().any(|e| e.name == name && e.enabled)
    }
    /// Switches `name` on or off; `Err` lists the registered names when it is unknown.
    pub fn set_enabled(&mut self, name: &str, enabled: bool) -> Result<(), UnknownPhenomenon> {
        match self.entries.iter_mut().find(|e| e.name == name) {
            Some(e) => {
                e.enabled = enabled;
                Ok(())
            }
            None => Err(UnknownPhenomenon {
                name: name.to_string(),
                registered: self.entries.iter().map(|e| e.name).collect(),
            }),
        }
    }
    /// Every registered phenomenon.
    pub fn iter(&self) -> impl Iterator<Item = &PhenomenonInfo> {
        self.entries.iter()
    }
}

/// Run condition: true while the named phenomenon is enabled.
pub fn phenomenon_enabled(
    name: impl Into<Phenomenon>,
) -> impl FnMut(Option<Res<Phenomena>>) -> bool + Clone {
    let name = name.into().name();
    move |p: Option<Res<Phenomena>>| p.is_some_and(|p| p.is_enabled(name))
}
