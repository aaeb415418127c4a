//! The library entry point: a [`Simulation`] owns the ECS app (world + step schedule) and steps
//! it. Rust users build one from [`Params`], optionally with their own plugin group, and call
//! [`Simulation::step`] or [`Simulation::run_for`].
//!
//! ```no_run
//! use tectonic_planets::prelude::*;
//!
//! let mut params = Params::default();
//! params.planet.samples = 20_000;
//! let mut sim = Simulation::new(params)?;
//! sim.run_for(100.0)?; // 100 My = 50 steps of 2 My
//! println!("land fraction {:.2}", sim.stats().land_fraction);
//! # Ok::<(), tectonic_planets::SimError>(())
//! ```

pub mod core_sections;
mod persist;

use std::time::Instant;

use bevy_app::{App, PluginGroup};
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::{ScheduleLabel, Schedules};

use crate::components::{Plate, PlateBounds, PlateFrame, PlateMesh, PlateMotion, PlateStats};
use crate::geometry::{MeshError, SphereMesh};
use crate::plugins::isostasy::ISOSTASY;
use crate::plugins::oceanic_crust::OCEANIC_CRUST;
use crate::plugins::{
    AfterResample, Phenomena, PhenomenonInfo, TectonicPlugins, TectonicSchedulePlugin,
    TectonicStep, UnknownPhenomenon,
};
use crate::random::StableHasher;
use crate::resources::params::{ParamError, Params};
use crate::resources::plugin_params::{PluginConfig, PluginParams};
use crate::resources::{
    Crust, CrustStats, NextPlateId, NonFinite, PlateTable, ReliefMode, ResampleRequest, SimClock,
    StepTimings,
};
use crate::systems::diagnostics::{CrustHealth, crust_stats};
use crate::systems::{init, oceanic_crust, resample};

/// Why a simulation could not be built or stepped.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A parameter is invalid.
    #[error(transparent)]
    Params(#[from] ParamError),
    /// The mesh could not be built.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// A non-finite value entered the crust (a bug; the step that made it is named).
    #[error("step {step}: {source}")]
    NonFinite {
        /// Step at which it was found.
        step: u64,
        /// Where.
        source: NonFinite,
    },
    /// A phenomenon name that no plugin registered.
    #[error(transparent)]
    UnknownPhenomenon(#[from] UnknownPhenomenon),
    /// The plugins' systems cannot be scheduled: two systems that touch the same data are not
    /// ordered, or the ordering has a cycle (a plugin's bug; the message names the sets).
    #[error("the step schedule cannot be built: {0}")]
    Schedule(String),
    /// A time or count argument that makes no sense.
    #[error("{0}")]
    BadArgument(String),
    /// The GPU backend could not be set up, or a kernel failed.
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
}

/// Builds the step schedules now, so that plugins whose systems cannot be ordered (an ambiguity,
/// which the schedules refuse, or a cycle) are reported here as an error instead of a panic at
/// the first step.
fn build_schedules(app: &mut App) -> Result<(), String> {
    let world = app.world_mut();
    for label in [TectonicStep.intern(), AfterResample.intern()] {
        // Out of `Schedules` while it is built: building reads `Schedules` itself.
        let Some(mut schedule) = world.resource_mut::<Schedules>().remove(label) else {
            continue;
        };
        let built = schedule.initialize(world);
        world.resource_mut::<Schedules>().insert(schedule);
        built.map_err(|e| format!("{label:?}: {e}"))?;
    }
    Ok(())
}

/// Mirrors the `isostasy` switch into [`ReliefMode`], which the uplift kernels read (they live
/// below the plugins and cannot see the switches).
fn sync_relief_mode(world: &mut World) {
    let isostatic = world
        .get_resource::<Phenomena>()
        .is_some_and(|p| p.is_enabled(ISOSTASY.name()));
    if let Some(mut mode) = world.get_resource_mut::<ReliefMode>()
        && mode.isostatic != isostatic
    {
        mode.isostatic = isostatic;
    }
}

/// A running planet: the ECS world and its step schedule.
pub struct Simulation {
    app: App,
}

impl Simulation {
    /// A new planet from `params` with the built-in phenomena ([`TectonicPlugins`]).
    pub fn new(params: Params) -> Result<Self, SimError> {
        Self::with_plugins(params, TectonicPlugins)
    }

    /// A new planet from `params` with the given plugin group (for example
    /// `TectonicPlugins.build().disable::<ErosionPlugin>().add(MyErosion)`).
    pub fn with_plugins(params: Params, plugins: impl PluginGroup) -> Result<Self, SimError> {
        Self::build(params, plugins, |mesh, params| {
            Ok(init::initial_planet(mesh, params))
        })
    }

    /// A new planet whose initial crust and plates come from a map ([`init::planet_from_map`]:
    /// `generate --from-heightmap`, `--from-earth`), with the built-in phenomena. Such a run is
    /// not rebuilt by [`crate::commands::replay`], which starts from the parameters alone.
    pub fn from_map(params: Params, start: &init::MapStart) -> Result<Self, SimError> {
        Self::build(params, TectonicPlugins, |mesh, params| {
            init::planet_from_map(mesh, params, start)
                .map_err(|e| SimError::BadArgument(e.to_string()))
        })
    }

    fn build(
        params: Params,
        plugins: impl PluginGroup,
        initial: impl FnOnce(&SphereMesh, &Params) -> Result<(Crust, Vec<init::InitialPlate>), SimError>,
    ) -> Result<Self, SimError> {
        params.validate()?;
        let mut timings = StepTimings::default();
        let t0 = Instant::now();
        let mesh = init::reference_mesh(&params)?;
        timings.record("mesh", t0.elapsed());
        let t1 = Instant::now();
        let (crust, plates) = initial(&mesh, &params)?;
        let next_id = plates.iter().map(|p| p.id.0 + 1).max().unwrap_or(0);

        let mut app = App::empty();
        app.insert_resource(params)
            .insert_resource(mesh)
            .insert_resource(crust)
            .insert_resource(NextPlateId(next_id));
        app.add_plugins(TectonicSchedulePlugin);
        app.add_plugins(core_sections::CoreSavePlugin);
        app.add_plugins(plugins);
        app.finish();
        app.cleanup();
        build_schedules(&mut app).map_err(SimError::Schedule)?;
        app.init_resource::<PluginParams>();
        if let Some(e) = app.world().resource::<PluginParams>().invalid_declaration() {
            return Err(SimError::BadArgument(e.to_string()));
        }
        let world = app.world_mut();
        for p in &plates {
            world.spawn(Plate::bundle(p.id, p.motion));
        }
        resample::rebuild_plate_entities(world, &[]);
        sync_relief_mode(world);
        let _ = world.try_run_schedule(AfterResample);
        timings.record("initial_planet", t1.elapsed());
        *world.resource_mut::<StepTimings>() = timings;
        let mut sim = Self { app };
        sim.refresh_stats();
        Ok(sim)
    }

    /// A simulation with `params`, `mesh`, the schedule and `plugins` but no initial planet: an
    /// empty crust and no plates. Used by the save loader, which fills in the rest of the state
    /// through the registered save sections and then calls [`Self::finish_load`].
    pub(crate) fn from_parts(
        params: Params,
        mesh: SphereMesh,
        plugins: impl PluginGroup,
    ) -> Result<Self, String> {
        let n = mesh.len();
        let mut app = App::empty();
        app.insert_resource(params)
            .insert_resource(mesh)
            .insert_resource(Crust::with_len(n))
            .insert_resource(NextPlateId(0));
        app.add_plugins(TectonicSchedulePlugin);
        app.add_plugins(core_sections::CoreSavePlugin);
        app.add_plugins(plugins);
        app.finish();
        app.cleanup();
        build_schedules(&mut app)?;
        app.init_resource::<PluginParams>();
        Ok(Self { app })
    }

    /// Refreshes the derived resources after a load.
    pub(crate) fn finish_load(&mut self) {
        sync_relief_mode(self.app.world_mut());
        self.refresh_stats();
    }

    fn refresh_stats(&mut self) {
        let world = self.app.world_mut();
        let plates = world.query::<&Plate>().iter(world).count();
        let mut stats = crust_stats(world.resource::<SphereMesh>(), world.resource::<Crust>());
        stats.plates = plates;
        *world.resource_mut::<CrustStats>() = stats;
    }

    /// Runs one time step (one run of the [`TectonicStep`] schedule).
    pub fn step(&mut self) -> Result<(), SimError> {
        sync_relief_mode(self.app.world_mut());
        self.app.world_mut().run_schedule(TectonicStep);
        // A standalone bevy_ecs world keeps a removal message for every component of every
        // despawned entity until its trackers are cleared; without this a long run (fronts,
        // terranes and plates come and go) grows by megabytes (measured: +8.4 MB in 1000 steps at
        // 100,000 samples). Nothing reads `RemovedComponents`, so once a step is enough.
        self.app.world_mut().clear_trackers();
        if let Some(e) = self
            .app
            .world_mut()
            .get_resource_mut::<crate::gpu::GpuContext>()
            .and_then(|mut g| g.failure.take())
        {
            return Err(SimError::Gpu(e));
        }
        let world = self.app.world();
        if let Some(e) = world.resource::<CrustHealth>().0.clone() {
            return Err(SimError::NonFinite {
                step: world.resource::<SimClock>().step,
                source: e,
            });
        }
        Ok(())
    }

    /// Chooses the compute backend of the per-sample kernels (see [`crate::gpu`]); returns a
    /// line saying which one runs and, under [`BackendChoice::Auto`](crate::gpu::BackendChoice),
    /// why the CPU was chosen. Takes effect from the next step; results on the CPU backend do not
    /// change.
    pub fn set_backend(&mut self, choice: crate::gpu::BackendChoice) -> Result<String, SimError> {
        let selected = crate::gpu::select_backend(choice)?;
        // The old context may hold fields newer than the host: bring them over before it goes.
        self.sync_crust()?;
        let world = self.app.world_mut();
        world.insert_resource(selected.backend);
        match selected.context {
            Some(ctx) => {
                world.insert_resource(ctx);
            }
            None => {
                world.remove_resource::<crate::gpu::GpuContext>();
            }
        }
        Ok(selected.note)
    }

    /// The compute backend in use.
    pub fn backend(&self) -> crate::gpu::ComputeBackend {
        self.app
            .world()
            .get_resource::<crate::gpu::ComputeBackend>()
            .copied()
            .unwrap_or_default()
    }

    /// Runs `n` steps; on the GPU backend the host crust is then in sync with the device.
    pub fn run_steps(&mut self, n: u64) -> Result<(), SimError> {
        for _ in 0..n {
            self.step()?;
        }
        self.sync_crust()
    }

    /// On the GPU backend, pulls every crust field the device holds newer than the host (lazy
    /// host sync: kernels leave their results on the device until a CPU reader needs them), so
    /// that [`Self::crust`] and [`Self::world`] show the current crust. Does nothing on the CPU
    /// backend or when the host is already in sync. [`Self::run_steps`], [`Self::state_hash`],
    /// [`Self::resampled_crust`], [`Self::world_mut`] and saves call it themselves; call it after
    /// [`Self::step`] before reading the crust through `crust()` or `world()`.
    pub fn sync_crust(&mut self) -> Result<(), SimError> {
        crate::gpu::sync_crust_to_host(self.app.world_mut(), crate::gpu::FieldMask::ALL)?;
        Ok(())
    }

    /// [`Self::sync_crust`] for methods that cannot return an error: a failure is kept in the
    /// context, so the next step stops with it (and reports it).
    fn sync_crust_or_record(&mut self) {
        crate::gpu::sync_crust_to_host_or_record(self.app.world_mut(), crate::gpu::FieldMask::ALL);
    }

    /// Number of steps that `my` million years take (rounded to the nearest step).
    pub fn steps_for(&self, my: f64) -> Result<u64, SimError> {
        let dt = self.params().time.time_step_my;
        if !my.is_finite() || my < 0.0 {
            return Err(SimError::BadArgument(format!(
                "time {my} My is not a finite, non-negative number"
            )));
        }
        Ok((my / dt).round() as u64)
    }

    /// Runs for `my` million years (rounded to whole steps).
    pub fn run_for(&mut self, my: f64) -> Result<(), SimError> {
        let n = self.steps_for(my)?;
        self.run_steps(n)
    }

    /// Asks for a global resampling at the end of the next step.
    pub fn request_resample(&mut self) {
        self.app.world_mut().resource_mut::<ResampleRequest>().0 = true;
    }

    /// Switches a phenomenon on or off (takes effect from the next step).
    pub fn set_enabled(&mut self, name: &str, enabled: bool) -> Result<(), SimError> {
        self.app
            .world_mut()
            .resource_mut::<Phenomena>()
            .set_enabled(name, enabled)
            .map_err(SimError::UnknownPhenomenon)
    }

    /// The parameters declared by plugins, with their current values.
    pub fn plugin_params(&self) -> &PluginParams {
        self.app.world().resource::<PluginParams>()
    }

    /// The plugin parameters, to change (every change is checked; see [`PluginParams::set`]).
    pub fn plugin_params_mut(&mut self) -> Mut<'_, PluginParams> {
        self.app.world_mut().resource_mut::<PluginParams>()
    }

    /// Applies the `[plugins.<plugin>]` tables of a config; unknown keys, wrong kinds and
    /// out-of-range values are refused with the key, the value and the range.
    pub fn apply_plugin_config(&mut self, config: &PluginConfig) -> Result<(), SimError> {
        self.plugin_params_mut().apply(config)?;
        Ok(())
    }

    /// Every registered phenomenon and whether it is on.
    pub fn phenomena(&self) -> Vec<PhenomenonInfo> {
        self.app
            .world()
            .resource::<Phenomena>()
            .iter()
            .cloned()
            .collect()
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        self.app.world().resource::<Params>()
    }
    /// The reference mesh.
    pub fn mesh(&self) -> &SphereMesh {
        self.app.world().resource::<SphereMesh>()
    }
    /// The crust (in plate frames since the last resampling). On the GPU backend this is the
    /// host copy as of the last sync: after [`Self::run_steps`] or [`Self::sync_crust`] it is
    /// current, after a bare [`Self::step`] the fields the kernels wrote may be stale.
    pub fn crust(&self) -> &Crust {
        self.app.world().resource::<Crust>()
    }
    /// The clock.
    pub fn clock(&self) -> &SimClock {
        self.app.world().resource::<SimClock>()
    }
    /// Simulated time, My.
    pub fn time_my(&self) -> f64 {
        self.clock().time_my
    }
    /// Statistics of the last step.
    pub fn stats(&self) -> &CrustStats {
        self.app.world().resource::<CrustStats>()
    }
    /// Timings of recent steps.
    pub fn timings(&self) -> &StepTimings {
        self.app.world().resource::<StepTimings>()
    }
    /// Frees what the steps keep between them only to save allocations: the resampling's work
    /// area, the relief passes' and the climate's, the isostasy's coarse level, and the last
    /// step's drainage network. The next step builds them again, with the same results (a run
    /// that releases them halfway gives the bits of one that does not); `generate` calls it
    /// before writing its maps, to lower the peak of memory.
    pub fn release_scratch(&mut self) {
        let world = self.app.world_mut();
        if let Some(mut w) = world.get_resource_mut::<resample::ResampleWork>() {
            w.release_buffers();
        }
        if let Some(mut r) = world.get_resource_mut::<crate::systems::relief::ReliefState>() {
            r.release_scratch();
            r.release_isostasy_levels();
        }
        if let Some(mut c) = world.get_resource_mut::<crate::systems::relief::ClimateState>() {
            c.release_scratch();
        }
        // A network that serves later steps (`time.relief_interval_steps` above 1) keeps what a
        // save holds of it (its source), and the next step builds its buffers again from it, bit
        // for bit. Any other is forgotten.
        if let Some(mut n) = world.get_resource_mut::<crate::systems::relief::DrainageNetwork>() {
            n.release_buffers();
        }
        // What was freed goes back to the system, not only to the allocator (which would keep
        // most of it resident).
        crate::systems::resample::release_free_memory();
    }
    /// The pelagic rain's multiplier at each sample of the mesh (`sediment.pelagic_variability`,
    /// see [`ReliefState::pelagic_rate`](crate::systems::relief::ReliefState::pelagic_rate)):
    /// the field the run's rain uses (shared, not copied), built there if no rain has fallen
    /// yet (a save just loaded). Empty when the same rain falls everywhere; `None` when no
    /// pelagic rain settles at all (the phenomenon `sediment`, which lays it, is off, or the
    /// relief phenomena are not part of the run).
    pub fn pelagic_rate(&mut self) -> Option<std::sync::Arc<Vec<f32>>> {
        let world = self.app.world_mut();
        let rains = world
            .get_resource::<Phenomena>()
            .is_some_and(|p| p.is_enabled(crate::plugins::sediment::SEDIMENT.name()));
        if !rains || !world.contains_resource::<crate::systems::relief::ReliefState>() {
            return None;
        }
        Some(world.resource_scope(
            |world, mut state: Mut<crate::systems::relief::ReliefState>| {
                state.pelagic_rate(world.resource::<SphereMesh>(), world.resource::<Params>())
            },
        ))
    }
    /// The sample graph every relief pass works on (see
    /// [`relief_graph`](crate::systems::relief::network::relief_graph)): the one the relief
    /// phenomena built for this mesh, shared, or a new one when none is held (a save just
    /// loaded, the relief phenomena off).
    pub fn relief_graph(&self) -> std::sync::Arc<crate::systems::relief::graph::ReliefGraph> {
        let mesh = self.mesh();
        self.app
            .world()
            .get_resource::<crate::systems::relief::ReliefState>()
            .and_then(|s| s.graph.clone())
            .filter(|g| g.len() == mesh.len())
            .unwrap_or_else(|| {
                std::sync::Arc::new(crate::systems::relief::network::relief_graph(mesh))
            })
    }
    /// The ECS world (read). On the GPU backend its crust is as of the last sync (see
    /// [`Self::crust`]).
    pub fn world(&self) -> &World {
        self.app.world()
    }
    /// The ECS world (write): spawn entities, change plate motions, edit the crust. On the GPU
    /// backend the host crust is first brought in sync with the device (a pull failure is kept
    /// and stops the next step).
    pub fn world_mut(&mut self) -> &mut World {
        self.sync_crust_or_record();
        self.app.world_mut()
    }
    /// The app, for adding plugins after construction (the crust is synced as for
    /// [`Self::world_mut`]).
    pub fn app_mut(&mut self) -> &mut App {
        self.sync_crust_or_record();
        &mut self.app
    }

    /// Replaces the plates: `plate_of_sample` gives the new owner of every reference sample and
    /// `motions` the motion of every plate it names (ids are free to choose). Only allowed right
    /// after a resampling (every frame at identity), e.g. at the start or after
    /// [`Self::request_resample`] and a step; used to author scenarios.
    pub fn reassign_plates(
        &mut self,
        plate_of_sample: Vec<u32>,
        motions: &[(u32, PlateMotion)],
    ) -> Result<(), SimError> {
        if self.clock().steps_since_resample != 0 {
            return Err(SimError::BadArgument(
                "plates can only be reassigned right after a resampling".into(),
            ));
        }
        if plate_of_sample.len() != self.mesh().len() {
            return Err(SimError::BadArgument(format!(
                "{} plate ids given for {} samples",
                plate_of_sample.len(),
                self.mesh().len()
            )));
        }
        let mut ids: Vec<u32> = motions.iter().map(|m| m.0).collect();
        ids.sort_unstable();
        if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
            return Err(SimError::BadArgument(format!(
                "plate {} has two motions",
                w[0]
            )));
        }
        if let Some(&bad) = plate_of_sample
            .iter()
            .find(|p| ids.binary_search(p).is_err())
        {
            return Err(SimError::BadArgument(format!(
                "plate {bad} is used by a sample but has no motion"
            )));
        }
        self.sync_crust()?;
        let world = self.app.world_mut();
        Plate::despawn_all(world);
        world.resource_mut::<Crust>().plate = plate_of_sample;
        for &(id, motion) in motions {
            world.spawn(Plate::bundle(crate::components::PlateId(id), motion));
        }
        let next = ids
            .last()
            .map_or(0, |m| m + 1)
            .max(world.resource::<NextPlateId>().0);
        world.resource_mut::<NextPlateId>().0 = next;
        resample::rebuild_plate_entities(world, &[]);
        let _ = world.try_run_schedule(AfterResample);
        self.refresh_stats();
        Ok(())
    }

    /// Sets the motion of plate `id`.
    pub fn set_plate_motion(&mut self, id: u32, motion: PlateMotion) -> Result<(), SimError> {
        let world = self.app.world_mut();
        let mut q = world.query::<(&Plate, &mut PlateMotion)>();
        for (p, mut m) in q.iter_mut(world) {
            if p.id.0 == id {
                *m = motion;
                return Ok(());
            }
        }
        Err(SimError::BadArgument(format!("no plate with id {id}")))
    }

    /// A snapshot of every plate's frame and motion, sorted by id.
    pub fn plate_table(&mut self) -> PlateTable {
        let world = self.app.world_mut();
        let mut q = world.query::<(&Plate, &PlateMotion, &PlateFrame, &PlateBounds, &PlateStats)>();
        PlateTable::from_plates(q.iter(world).map(|(p, m, f, b, s)| (*p, *m, *f, *b, *s)))
    }

    /// What decides the sea, the lakes and the rain of the drainage network the maps draw, as
    /// in this run:
    /// [`NetworkOptions::of`](crate::systems::relief::network::NetworkOptions::of) its
    /// parameters, with uniform rain when its phenomenon `climate` is off.
    pub fn network_options(&self) -> crate::systems::relief::network::NetworkOptions {
        let climate_on = self
            .app
            .world()
            .resource::<Phenomena>()
            .is_enabled(crate::plugins::climate::CLIMATE.name());
        crate::systems::relief::network::NetworkOptions::of(self.params()).with_climate(climate_on)
    }

    /// The crust as it would be after a resampling now, without changing the simulation: every
    /// field on the reference mesh in the world frame, gaps filled with new ocean floor (when the
    /// `oceanic_crust` phenomenon is on). This is what maps and exports show. (Unlike a real
    /// resampling it applies no pending suture and does not displace continental crust overridden
    /// by another continent; both only move a few samples near active collisions.)
    pub fn resampled_crust(&mut self) -> Crust {
        self.sync_crust_or_record();
        let table = self.plate_table();
        let ocean_on = self
            .app
            .world()
            .resource::<Phenomena>()
            .is_enabled(OCEANIC_CRUST.name());
        let world = self.app.world();
        let mesh = world.resource::<SphereMesh>();
        let crust = world.resource::<Crust>();
        let params = world.resource::<Params>();
        let clock = world.resource::<SimClock>();
        if clock.steps_since_resample == 0 {
            return crust.clone();
        }
        let mut sources = Vec::new();
        let mut next = Crust::default();
        let pairs = world
            .get_resource::<crate::resources::OverridePairs>()
            .map(|p| p.0.clone())
            .unwrap_or_default();
        let rules = resample::OverlapRules {
            pairs: &pairs,
            ..Default::default()
        };
        resample::resample_locate_cpu(mesh, crust, &table, &rules, &mut sources);
        resample::interpolate(mesh, crust, &table, &sources, &mut next);
        let gaps = resample::gaps_from_nearest(mesh, &sources, &mut next);
        if ocean_on {
            let elapsed = clock.steps_since_resample as f64 * params.time.time_step_my;
            let isostatic = world
                .get_resource::<crate::resources::ReliefMode>()
                .is_some_and(|m| m.isostatic);
            oceanic_crust::fill_ridge_crust(mesh, params, isostatic, elapsed, &gaps, &mut next);
        }
        let mut next_id = world.resource::<NextPlateId>().0;
        resample::defragment_plates(
            mesh,
            &mut next.plate,
            params.resample.fragment_min_area_km2,
            true,
            &mut next_id,
        );
        next
    }

    /// A stable hash of the whole simulation state: crust, plates (ids, motions, frames) and
    /// clock. Equal hashes mean bit-identical planets.
    pub fn state_hash(&mut self) -> u64 {
        self.sync_crust_or_record();
        let table = self.plate_table();
        let world = self.app.world();
        let mut h = StableHasher::default();
        h.write_u64(world.resource::<Crust>().hash());
        for p in &table.plates {
            h.write_u64(p.id as u64);
            for v in [
                p.motion.euler_pole.x,
                p.motion.euler_pole.y,
                p.motion.euler_pole.z,
                p.motion.angular_speed_rad_per_my,
            ] {
                h.write_u64(v.to_bits());
            }
            for c in p.world_from_plate.to_cols_array() {
                h.write_u64(c.to_bits());
            }
        }
        let c = world.resource::<SimClock>();
        h.write_u64(c.step);
        h.write_u64(c.steps_since_resample);
        h.finish()
    }

    /// Bytes held on the heap by the mesh, the crust, the resampling work area and the plates.
    pub fn state_bytes(&mut self) -> usize {
        let world = self.app.world_mut();
        let plates: usize = world
            .query::<&PlateMesh>()
            .iter(world)
            .map(|m| (m.samples.capacity() + m.triangles.capacity()) * 4)
            .sum();
        let work = world.resource::<resample::ResampleWork>();
        let work_bytes = work.next.heap_bytes()
            + work.sources.capacity() * std::mem::size_of::<resample::SampleSource>()
            + work.gaps.capacity() * std::mem::size_of::<resample::GapSample>();
        world.resource::<SphereMesh>().heap_bytes()
            + world.resource::<Crust>().heap_bytes()
            + work_bytes
            + plates
    }
}
