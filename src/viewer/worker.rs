//! The simulation thread of the viewer: a worker owns the [`Simulation`], takes [`Request`]s
//! from the UI over a channel, steps while running, and publishes cheap [`Snapshot`]s (the
//! resampled crust, the plate table, fronts, terranes, timings, switches) that the UI draws.
//! The UI never waits for a step.

use std::path::PathBuf;
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::sync::{Arc, Condvar, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use glam::DVec3;

use crate::Simulation;
use crate::commands::{Command, LatLon, Outcome};
use crate::components::{Plate, PlateFrame, SubductionFront, Terrane};
use crate::geometry::SphereMesh;
use crate::geometry::spherical::to_lat_lon_deg;
use crate::gpu::{BackendChoice, ComputeBackend};
use crate::io::maps::{Raster, write_all_maps};
use crate::io::rivers::{NetworkOptions, RiverNetwork, write_rivers};
use crate::io::save::{self, CommandHistory};
use crate::io::summary::CrustSampler;
use crate::plugins::PhenomenonInfo;
use crate::plugins::TectonicSystems;
use crate::resources::params::{ParamValue, Params};
use crate::resources::plugin_params::PluginParam;
use crate::resources::{Crust, CrustStats, FrontPoints};
use crate::systems::relief::graph::ReliefGraph;
use crate::systems::relief::network::drainage_graph;

/// Width of the map lookup grid (pixels); the height is half.
pub const MAP_WIDTH: u32 = 1024;
/// Height of the map lookup grid (pixels).
pub const MAP_HEIGHT: u32 = MAP_WIDTH / 2;

/// Least time between two snapshots while running (a snapshot resamples the crust).
const SNAPSHOT_INTERVAL: Duration = Duration::from_millis(120);

/// How many `nice` levels the viewer's simulation threads drop (5: about a quarter of the CPU
/// when the window wants all of it, which keeps a big planet stepping).
const PRIORITY_DROP: i32 = 5;

/// Lowers the calling thread's scheduling priority (by `PRIORITY_DROP` `nice` levels; on
/// Linux a thread's own). The viewer's simulation threads call it, so that drawing frames
/// comes first.
pub fn lower_thread_priority() {
    #[cfg(target_os = "linux")]
    {
        unsafe extern "C" {
            fn nice(inc: std::ffi::c_int) -> std::ffi::c_int;
        }
        // SAFETY: nice(2) takes an integer and only changes the scheduling priority of the
        // calling thread (Linux threads are scheduled on their own); it has no other effect.
        let _ = unsafe { nice(PRIORITY_DROP) };
    }
}

/// A function run on the simulation thread with the simulation (see [`SimHandle::with_sim`]).
pub type SimFn = Box<dyn FnOnce(&mut Simulation) + Send>;

/// Builds the simulation on its thread (a bevy app is not `Send`, so it is made where it runs).
pub type SimFactory = Box<dyn FnOnce() -> Result<Simulation, String> + Send>;

/// Where the UI leaves the function that asks it for a new frame (see
/// [`SimHandle::set_repaint`]).
type RepaintSlot = Arc<Mutex<Option<Box<dyn Fn() + Send>>>>;

/// Makes the plugin group the viewer's planets are built with: "New planet" and "Load" rebuild
/// with it, so third-party plugins the viewer was started with stay.
pub type PluginsFn = Arc<dyn Fn() -> bevy_app::PluginGroupBuilder + Send + Sync>;

/// The built-in plugins ([`crate::plugins::TectonicPlugins`]).
pub fn builtin_plugins() -> PluginsFn {
    use bevy_app::PluginGroup;
    Arc::new(|| crate::plugins::TectonicPlugins.build())
}

/// What the UI asks of the simulation thread.
pub enum Request {
    /// Take this many steps now (stops a run).
    Step(u64),
    /// Step continuously until paused.
    Run,
    /// Stop stepping.
    Pause,
    /// Step continuously for this many steps, then pause.
    RunSteps(u64),
    /// Step until the planet's time reaches this many My.
    RunUntil(f64),
    /// Steps per second while running (0: as fast as possible).
    SetSpeed(f64),
    /// Apply an authoring command (recorded in the history).
    Apply(Command),
    /// Replace the live parameters (the `planet` and `init` sections must not change: they only
    /// make sense when a planet is built; use [`Request::NewPlanet`]).
    SetParams(Box<Params>),
    /// Set one plugin parameter.
    SetPluginParam(String, ParamValue),
    /// Build a new planet from these parameters (with the viewer's plugins).
    NewPlanet(Box<Params>),
    /// Save the planet to this file.
    Save(PathBuf),
    /// Load a planet from this file (with the viewer's plugins).
    Load(PathBuf),
    /// Write the maps (PNG) into this folder, at this width.
    ExportMaps(PathBuf, u32),
    /// Run a function with the simulation (for tests and tools).
    With(SimFn),
    /// Stop the thread.
    Shutdown,
}

/// One plate, as the UI shows it.
#[derive(Clone, Debug, PartialEq)]
pub struct PlateRow {
    /// Plate id.
    pub id: u32,
    /// Euler pole, degrees.
    pub pole: LatLon,
    /// Surface speed 90° from the pole, mm/yr (negative: clockwise about the pole).
    pub speed_mm_per_yr: f64,
    /// Unit Euler pole, world frame.
    pub pole_unit: DVec3,
    /// Angular speed, rad/My.
    pub angular_speed_rad_per_my: f64,
    /// Area, km².
    pub area_km2: f64,
    /// Continental area, km².
    pub continental_area_km2: f64,
    /// Centroid, world frame.
    pub centroid_world: DVec3,
}

/// A subduction front (from its entity), world positions.
#[derive(Clone, Debug, PartialEq)]
pub struct FrontRow {
    /// Overriding plate.
    pub overriding: u32,
    /// Subducting plate.
    pub subducting: u32,
    /// Points along the front, world frame.
    pub points_world: Vec<DVec3>,
}

/// A terrane (from its entity).
#[derive(Clone, Debug, PartialEq)]
pub struct TerraneRow {
    /// Carrying plate.
    pub plate: u32,
    /// Area, km².
    pub area_km2: f64,
    /// Centroid, world frame.
    pub centroid_world: DVec3,
}

/// For every pixel of the `MAP_WIDTH × MAP_HEIGHT` equirectangular grid, the reference-mesh
/// triangle under its centre and the barycentric weights (fixed while the mesh is).
#[derive(Debug)]
pub struct PixelLookup {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Triangle corners (sample indices) per pixel.
    pub corners: Vec<[u32; 3]>,
    /// Weights per pixel.
    pub weights: Vec<[f32; 3]>,
    /// The corner with the largest weight, per pixel (0..3).
    pub dominant: Vec<u8>,
}

impl PixelLookup {
    /// Builds the lookup for `mesh`.
    pub fn build(mesh: &SphereMesh, width: u32, height: u32) -> Self {
        use rayon::prelude::*;
        let n = (width * height) as usize;
        let located: Vec<([u32; 3], [f32; 3], u8)> = (0..n)
            .into_par_iter()
            .map(|i| {
                let (col, row) = (i as u32 % width, i as u32 / width);
                let d = DVec3::from_array(Raster::pixel_direction(width, height, col, row));
                let loc = mesh.locate(d);
                let t = mesh.triangles[loc.triangle as usize];
                let w = loc.weights;
                (
                    t,
                    [w[0] as f32, w[1] as f32, w[2] as f32],
                    loc.dominant_corner() as u8,
                )
            })
            .collect();
        let mut out = Self {
            width,
            height,
            corners: Vec::with_capacity(n),
            weights: Vec::with_capacity(n),
            dominant: Vec::with_capacity(n),
        };
        for (t, w, d) in located {
            out.corners.push(t);
            out.weights.push(w);
            out.dominant.push(d);
        }
        out
    }

    /// The sample nearest to pixel `i` (its dominant corner).
    pub fn sample_of(&self, i: usize) -> usize {
        self.corners[i][self.dominant[i] as usize] as usize
    }

    /// A scalar field interpolated at pixel `i`.
    pub fn lerp(&self, field: &[f32], i: usize) -> f32 {
        let t = self.corners[i];
        let w = self.weights[i];
        w[0] * field[t[0] as usize] + w[1] * field[t[1] as usize] + w[2] * field[t[2] as usize]
    }
}

/// What the UI draws: a consistent picture of the planet after some step.
#[derive(Clone, Debug)]
pub struct Snapshot {
    /// The last request handled when this snapshot was taken.
    pub seq: u64,
    /// Steps since the start of the planet.
    pub step: u64,
    /// Steps this thread has taken since it started (all planets).
    pub steps_taken: u64,
    /// Planet time, My.
    pub time_my: f64,
    /// Whether the thread is stepping continuously.
    pub running: bool,
    /// The target time of a run-until, if any.
    pub run_until_my: Option<f64>,
    /// Identifies the mesh (changes on load / new planet).
    pub mesh_generation: u64,
    /// Number of samples.
    pub samples: usize,
    /// Where the kernels run.
    pub backend: ComputeBackend,
    /// Planet radius, km.
    pub radius_km: f64,
    /// The crust as after a resampling now (world frame, reference mesh).
    pub crust: Arc<Crust>,
    /// Pixel → mesh lookup for the map.
    pub lookup: Arc<PixelLookup>,
    /// Unit positions of the reference samples.
    pub positions: Arc<Vec<DVec3>>,
    /// The sample graph of the reference mesh, without cotangent weights (for the drainage
    /// network: see [`drainage_graph`]).
    pub graph: Arc<ReliefGraph>,
    /// The drainage network of `crust`, made on first use ([`Snapshot::rivers`]).
    pub rivers: Arc<OnceLock<RiverNetwork>>,
    /// The pelagic rain's multiplier at each sample (`sediment.pelagic_variability`: the field
    /// the run's rain uses, fixed in the mantle frame, so it lines up with `crust`; see
    /// [`Simulation::pelagic_rate`]); empty when the same rain falls everywhere, `None` when
    /// none settles (the sediment off).
    pub pelagic_rate: Option<Arc<Vec<f32>>>,
    /// Every plate, by id.
    pub plates: Vec<PlateRow>,
    /// Subduction fronts.
    pub fronts: Vec<FrontRow>,
    /// Terranes.
    pub terranes: Vec<TerraneRow>,
    /// Duration of each system set in the last step, ms, in schedule order.
    pub set_timings_ms: Vec<(TectonicSystems, Option<f64>)>,
    /// Wall time of the last whole step, ms.
    pub step_ms: Option<f64>,
    /// Every registered phenomenon.
    pub phenomena: Vec<PhenomenonInfo>,
    /// Area statistics.
    pub stats: CrustStats,
    /// Parameters.
    pub params: Params,
    /// Plugin parameters.
    pub plugin_params: Vec<PluginParam>,
    /// The command history (step, line), most recent last.
    pub history: Vec<(u64, String)>,
    /// Messages (results and errors of requests), most recent last.
    pub log: Vec<String>,
}

impl Snapshot {
    /// The plate with id `id`.
    pub fn plate(&self, id: u32) -> Option<&PlateRow> {
        self.plates.iter().find(|p| p.id == id)
    }

    /// The drainage network of the crust shown (rivers, lakes, basins, rain), computed the
    /// first time it is asked for (by whoever draws a layer that needs it), with the climate's
    /// rain when the phenomenon `climate` is on in the run, uniform rain otherwise.
    pub fn rivers(&self) -> &RiverNetwork {
        self.rivers.get_or_init(|| {
            let climate_on = self
                .phenomena
                .iter()
                .any(|p| p.name == crate::plugins::climate::CLIMATE.name() && p.enabled);
            let opts = NetworkOptions::of(&self.params).with_climate(climate_on);
            RiverNetwork::on_graph(&self.graph, &self.positions, &self.crust, opts)
        })
    }
}

#[derive(Default)]
struct Shared {
    latest: Option<Arc<Snapshot>>,
    done_seq: u64,
    /// Why the simulation could not be built.
    failed: Option<String>,
}

/// The UI's end of the simulation thread.
pub struct SimHandle {
    tx: Sender<(u64, Request)>,
    shared: Arc<(Mutex<Shared>, Condvar)>,
    next_seq: u64,
    thread: Option<JoinHandle<()>>,
    repaint: RepaintSlot,
}

impl SimHandle {
    /// Starts the thread; it builds the simulation with `factory` and publishes a first
    /// snapshot (see [`Self::wait_ready`]). New and loaded planets get the built-in plugins.
    pub fn spawn(factory: impl FnOnce() -> Result<Simulation, String> + Send + 'static) -> Self {
        Self::spawn_with_plugins(builtin_plugins(), factory)
    }

    /// As [`Self::spawn`], with new and loaded planets built with `plugins` (give the group
    /// `factory` builds its planet with).
    pub fn spawn_with_plugins(
        plugins: PluginsFn,
        factory: impl FnOnce() -> Result<Simulation, String> + Send + 'static,
    ) -> Self {
        let (tx, rx) = channel();
        let shared: Arc<(Mutex<Shared>, Condvar)> = Arc::default();
        let repaint: RepaintSlot = Arc::default();
        let (shared2, repaint2) = (shared.clone(), repaint.clone());
        let thread = std::thread::Builder::new()
            .name("planet-sim".into())
            .spawn(move || match factory() {
                Ok(sim) => Worker::new(sim, plugins, rx, shared2, repaint2).run(),
                Err(e) => {
                    let (lock, cvar) = &*shared2;
                    if let Ok(mut s) = lock.lock() {
                        s.failed = Some(e);
                    }
                    cvar.notify_all();
                }
            });
        let thread = match thread {
            Ok(t) => Some(t),
            Err(e) => {
                if let Ok(mut s) = shared.0.lock() {
                    s.failed = Some(format!("could not start the simulation thread: {e}"));
                }
                None
            }
        };
        Self {
            tx,
            shared,
            next_seq: 0,
            thread,
            repaint,
        }
    }

    /// Waits for the first snapshot; `Err` says why the simulation could not be built.
    pub fn wait_ready(&self, timeout: Duration) -> Result<Arc<Snapshot>, String> {
        let deadline = Instant::now() + timeout;
        let (lock, cvar) = &*self.shared;
        let mut s = lock
            .lock()
            .map_err(|_| "the simulation thread died".to_string())?;
        loop {
            if let Some(e) = &s.failed {
                return Err(e.clone());
            }
            if let Some(l) = &s.latest {
                return Ok(l.clone());
            }
            let left = deadline
                .checked_duration_since(Instant::now())
                .ok_or_else(|| format!("the planet was not ready within {timeout:?}"))?;
            s = cvar
                .wait_timeout(s, left)
                .map_err(|_| "the simulation thread died".to_string())?
                .0;
        }
    }

    /// Runs `f` with the simulation on its thread and returns its result (`None` if the thread
    /// is gone or does not answer within `timeout`).
    pub fn with_sim<R: Send + 'static>(
        &mut self,
        timeout: Duration,
        f: impl FnOnce(&mut Simulation) -> R + Send + 'static,
    ) -> Option<R> {
        let (tx, rx) = channel();
        self.send(Request::With(Box::new(move |sim| {
            let _ = tx.send(f(sim));
        })));
        rx.recv_timeout(timeout).ok()
    }

    /// Calls `f` (e.g. `ctx.request_repaint()`) whenever a new snapshot is published.
    pub fn set_repaint(&self, f: impl Fn() + Send + 'static) {
        if let Ok(mut r) = self.repaint.lock() {
            *r = Some(Box::new(f));
        }
    }

    /// Sends a request; returns its sequence number (see [`Self::wait_for`]).
    pub fn send(&mut self, req: Request) -> u64 {
        self.next_seq += 1;
        let _ = self.tx.send((self.next_seq, req));
        self.next_seq
    }

    /// Sequence number of the last request sent.
    pub fn last_sent(&self) -> u64 {
        self.next_seq
    }

    /// The latest snapshot, if any.
    pub fn latest(&self) -> Option<Arc<Snapshot>> {
        self.shared.0.lock().ok().and_then(|s| s.latest.clone())
    }

    /// Waits until request `seq` has been handled and its snapshot published; `None` on timeout.
    pub fn wait_for(&self, seq: u64, timeout: Duration) -> Option<Arc<Snapshot>> {
        let deadline = Instant::now() + timeout;
        let (lock, cvar) = &*self.shared;
        let mut s = lock.lock().ok()?;
        while s.done_seq < seq || s.latest.as_ref().is_none_or(|l| l.seq < seq) {
            let left = deadline.checked_duration_since(Instant::now())?;
            s = cvar.wait_timeout(s, left).ok()?.0;
        }
        s.latest.clone()
    }

    /// Stops the thread and waits for it; false if it had died (panicked).
    pub fn shutdown(mut self) -> bool {
        let _ = self.tx.send((u64::MAX, Request::Shutdown));
        self.thread.take().is_some_and(|t| t.join().is_ok())
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        if let Some(t) = self.thread.take() {
            let _ = self.tx.send((u64::MAX, Request::Shutdown));
            let _ = t.join();
        }
    }
}

struct Worker {
    sim: Simulation,
    plugins: PluginsFn,
    rx: Receiver<(u64, Request)>,
    shared: Arc<(Mutex<Shared>, Condvar)>,
    repaint: RepaintSlot,
    running: bool,
    run_until_my: Option<f64>,
    steps_left: Option<u64>,
    steps_per_second: f64,
    seq: u64,
    steps_taken: u64,
    last_step_ms: Option<f64>,
    mesh_generation: u64,
    lookup: Arc<PixelLookup>,
    positions: Arc<Vec<DVec3>>,
    graph: Arc<ReliefGraph>,
    log: Vec<String>,
    last_publish: Instant,
}

impl Worker {
    fn new(
        sim: Simulation,
        plugins: PluginsFn,
        rx: Receiver<(u64, Request)>,
        shared: Arc<(Mutex<Shared>, Condvar)>,
        repaint: RepaintSlot,
    ) -> Self {
        let lookup = Arc::new(PixelLookup::build(sim.mesh(), MAP_WIDTH, MAP_HEIGHT));
        let positions = Arc::new(sim.mesh().positions.clone());
        let graph = Arc::new(drainage_graph(sim.mesh()));
        Self {
            sim,
            plugins,
            rx,
            shared,
            repaint,
            running: false,
            run_until_my: None,
            steps_left: None,
            steps_per_second: 0.0,
            seq: 0,
            steps_taken: 0,
            last_step_ms: None,
            mesh_generation: 1,
            lookup,
            positions,
            graph,
            log: Vec::new(),
            last_publish: Instant::now(),
        }
    }

    fn say(&mut self, msg: String) {
        tracing::info!("{msg}");
        self.log.push(msg);
        if self.log.len() > 200 {
            self.log.remove(0);
        }
    }

    /// Puts `sim` in place of the planet, on the compute backend the old one ran on (the GPU
    /// when it had a device; a message says so when the new one cannot get one).
    fn replace_sim(&mut self, mut sim: Simulation) {
        if self.sim.backend() == ComputeBackend::Gpu
            && let Err(e) = sim.set_backend(BackendChoice::Gpu)
        {
            self.say(format!("the new planet runs on the CPU: {e}"));
        }
        self.sim = sim;
        self.lookup = Arc::new(PixelLookup::build(self.sim.mesh(), MAP_WIDTH, MAP_HEIGHT));
        self.positions = Arc::new(self.sim.mesh().positions.clone());
        self.graph = Arc::new(drainage_graph(self.sim.mesh()));
        self.mesh_generation += 1;
        self.running = false;
        self.run_until_my = None;
    }

    fn run(mut self) {
        self.publish();
        loop {
            // Wait for a request: forever when paused, up to the next step when running.
            let wait = if self.running {
                if self.steps_per_second > 0.0 {
                    Duration::from_secs_f64(1.0 / self.steps_per_second).saturating_sub(
                        Duration::from_secs_f64(self.last_step_ms.unwrap_or(0.0) / 1e3),
                    )
                } else {
                    Duration::ZERO
                }
            } else {
                Duration::from_secs(3600)
            };
            match self.rx.recv_timeout(wait) {
                Ok((_, Request::Shutdown)) => return,
                Ok((seq, req)) => {
                    self.handle(req);
                    // Handle everything queued before stepping again.
                    self.seq = seq;
                    while let Ok((seq, req)) = self.rx.try_recv() {
                        if let Request::Shutdown = req {
                            return;
                        }
                        self.handle(req);
                        self.seq = seq;
                    }
                    self.publish();
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
            if self.running {
                if let Some(t) = self.run_until_my
                    && self.sim.time_my() + 0.5 * self.sim.params().time.time_step_my >= t
                {
                    self.running = false;
                    self.run_until_my = None;
                    self.say(format!("reached {:.0} My", self.sim.time_my()));
                    self.publish();
                    continue;
                }
                self.step_once();
                if let Some(n) = self.steps_left.as_mut() {
                    *n = n.saturating_sub(1);
                    if *n == 0 {
                        self.running = false;
                        self.steps_left = None;
                    }
                }
                if !self.running || self.last_publish.elapsed() >= SNAPSHOT_INTERVAL {
                    self.publish();
                }
            }
        }
    }

    fn step_once(&mut self) {
        let t = Instant::now();
        match self.sim.step() {
            Ok(()) => {
                self.steps_taken += 1;
                self.last_step_ms = Some(t.elapsed().as_secs_f64() * 1e3);
            }
            Err(e) => {
                self.running = false;
                self.say(format!("step failed: {e}"));
            }
        }
    }

    fn handle(&mut self, req: Request) {
        match req {
            Request::Step(n) => {
                self.running = false;
                for _ in 0..n {
                    self.step_once();
                    if !self.log.is_empty()
                        && self.log[self.log.len() - 1].starts_with("step failed")
                    {
                        break;
                    }
                }
            }
            Request::Run => {
                self.running = true;
                self.run_until_my = None;
                self.steps_left = None;
            }
            Request::RunSteps(n) => {
                self.running = n > 0;
                self.run_until_my = None;
                self.steps_left = Some(n);
            }
            Request::Pause => {
                self.running = false;
                self.run_until_my = None;
                self.steps_left = None;
            }
            Request::RunUntil(my) => {
                self.steps_left = None;
                if my.is_finite() && my > self.sim.time_my() {
                    self.running = true;
                    self.run_until_my = Some(my);
                } else {
                    self.say(format!(
                        "run until {my} My: the planet is already at {:.0} My",
                        self.sim.time_my()
                    ));
                }
            }
            Request::SetSpeed(s) => {
                self.steps_per_second = if s.is_finite() && s > 0.0 { s } else { 0.0 };
            }
            Request::Apply(cmd) => match self.sim.apply(&cmd) {
                Ok(o) => {
                    let msg = describe_outcome(&o);
                    self.say(msg);
                }
                Err(e) => self.say(format!("command refused: {e}")),
            },
            Request::SetParams(p) => {
                let cur = self.sim.params().clone();
                if let Err(e) = p.validate() {
                    self.say(format!("parameters refused: {e}"));
                } else if cur.planet != p.planet || cur.init != p.init {
                    self.say(
                        "parameters refused: [planet] and [init] only apply to a new planet".into(),
                    );
                } else {
                    *self.sim.world_mut().resource_mut::<Params>() = *p;
                    self.say("parameters applied to the running planet".into());
                }
            }
            Request::SetPluginParam(key, v) => match self.sim.plugin_params_mut().set(&key, v) {
                Ok(()) => self.say(format!("{key} = {v}")),
                Err(e) => self.say(format!("plugin parameter refused: {e}")),
            },
            Request::NewPlanet(p) => match Simulation::with_plugins(*p, (self.plugins)()) {
                Ok(sim) => {
                    self.replace_sim(sim);
                    self.say(format!(
                        "new planet: {} samples ({})",
                        self.sim.mesh().len(),
                        backend_name(self.sim.backend())
                    ));
                }
                Err(e) => self.say(format!("could not build the planet: {e}")),
            },
            Request::Save(path) => {
                let path = save::resolve_save_path(&path);
                if let Some(dir) = path.parent()
                    && !dir.as_os_str().is_empty()
                    && let Err(e) = std::fs::create_dir_all(dir)
                {
                    self.say(format!("could not create {}: {e}", dir.display()));
                    return;
                }
                match save::save_to_file(&mut self.sim, &path) {
                    Ok(info) => self.say(format!(
                        "saved {} ({:.1} MB)",
                        path.display(),
                        info.file_bytes as f64 / 1e6
                    )),
                    Err(e) => self.say(format!("save failed: {e}")),
                }
            }
            Request::Load(path) => match save::load_from_file_with(&path, (self.plugins)()) {
                Ok(sim) => {
                    self.replace_sim(sim);
                    self.say(format!(
                        "loaded {} ({})",
                        path.display(),
                        backend_name(self.sim.backend())
                    ));
                }
                Err(e) => self.say(format!("load failed: {e}")),
            },
            Request::ExportMaps(dir, width) => {
                let result = (|| -> Result<Vec<PathBuf>, String> {
                    let view = self.sim.resampled_crust();
                    let raster = Raster::sample(
                        &CrustSampler {
                            mesh: self.sim.mesh(),
                            crust: &view,
                        },
                        width,
                        width / 2,
                    )
                    .map_err(|e| e.to_string())?;
                    let radius_km = self.sim.params().planet.radius_km;
                    let mut files =
                        write_all_maps(&raster, &dir, radius_km).map_err(|e| e.to_string())?;
                    let opts = self.sim.network_options();
                    let rivers = RiverNetwork::on_graph(
                        &self.graph,
                        &self.sim.mesh().positions,
                        &view,
                        opts,
                    );
                    files.extend(
                        write_rivers(&raster, self.sim.mesh(), &rivers, &dir, radius_km)
                            .map_err(|e| e.to_string())?,
                    );
                    Ok(files)
                })();
                match result {
                    Ok(files) => {
                        self.say(format!("wrote {} maps into {}", files.len(), dir.display()))
                    }
                    Err(e) => self.say(format!("export failed: {e}")),
                }
            }
            Request::With(f) => f(&mut self.sim),
            Request::Shutdown => {}
        }
    }

    fn publish(&mut self) {
        let snap = self.snapshot();
        self.last_publish = Instant::now();
        let (lock, cvar) = &*self.shared;
        if let Ok(mut s) = lock.lock() {
            s.done_seq = self.seq;
            s.latest = Some(Arc::new(snap));
        }
        cvar.notify_all();
        if let Ok(r) = self.repaint.lock()
            && let Some(f) = r.as_ref()
        {
            f();
        }
    }

    fn snapshot(&mut self) -> Snapshot {
        let pelagic_rate = self.sim.pelagic_rate();
        let crust = Arc::new(self.sim.resampled_crust());
        let radius_km = self.sim.params().planet.radius_km;
        let table = self.sim.plate_table();
        let world = self.sim.world_mut();
        let mut plates: Vec<PlateRow> = Vec::new();
        for (p, stats) in world
            .query::<(&Plate, &crate::components::PlateStats)>()
            .iter(world)
        {
            let Some(state) = table.get(p.id.0) else {
                continue;
            };
            let m = state.motion;
            let (lat, lon) = to_lat_lon_deg(m.euler_pole.normalize_or(DVec3::Z));
            plates.push(PlateRow {
                id: p.id.0,
                pole: LatLon { lat, lon },
                speed_mm_per_yr: m.angular_speed_rad_per_my * radius_km,
                pole_unit: m.euler_pole,
                angular_speed_rad_per_my: m.angular_speed_rad_per_my,
                area_km2: stats.area_km2,
                continental_area_km2: stats.continental_area_km2,
                centroid_world: state.centroid_world,
            });
        }
        plates.sort_by_key(|p| p.id);
        let frames: std::collections::HashMap<u32, glam::DMat3> = world
            .query::<(&Plate, &PlateFrame)>()
            .iter(world)
            .map(|(p, f)| (p.id.0, f.world_from_plate_mat()))
            .collect();
        let mut fronts = Vec::new();
        {
            let raw: Vec<SubductionFront> = world
                .query::<&SubductionFront>()
                .iter(world)
                .cloned()
                .collect();
            let fp = world.resource::<FrontPoints>();
            let mesh = world.resource::<SphereMesh>();
            for f in &raw {
                let rot = frames
                    .get(&f.overriding.0)
                    .copied()
                    .unwrap_or(glam::DMat3::IDENTITY);
                let points_world = f
                    .points
                    .iter()
                    .filter_map(|&i| fp.sample.get(i as usize))
                    .filter_map(|&s| mesh.positions.get(s as usize))
                    .map(|&p| rot * p)
                    .collect();
                fronts.push(FrontRow {
                    overriding: f.overriding.0,
                    subducting: f.subducting.0,
                    points_world,
                });
            }
        }
        let mut terranes = Vec::new();
        for t in world.query::<&Terrane>().iter(world) {
            let rot = frames
                .get(&t.plate.0)
                .copied()
                .unwrap_or(glam::DMat3::IDENTITY);
            terranes.push(TerraneRow {
                plate: t.plate.0,
                area_km2: t.area_km2,
                centroid_world: rot * t.centroid,
            });
        }
        let history = world
            .get_resource::<CommandHistory>()
            .map(|h| h.entries.clone())
            .unwrap_or_default();
        let timings = self.sim.timings();
        let set_timings_ms = TectonicSystems::ALL
            .iter()
            .map(|s| (*s, timings.last(s.name()).map(|d| d.as_secs_f64() * 1e3)))
            .collect();
        Snapshot {
            seq: self.seq,
            step: self.sim.clock().step,
            steps_taken: self.steps_taken,
            time_my: self.sim.time_my(),
            running: self.running,
            run_until_my: self.run_until_my,
            mesh_generation: self.mesh_generation,
            samples: self.sim.mesh().len(),
            backend: self.sim.backend(),
            radius_km,
            crust,
            lookup: self.lookup.clone(),
            positions: self.positions.clone(),
            graph: self.graph.clone(),
            rivers: Arc::default(),
            pelagic_rate,
            plates,
            fronts,
            terranes,
            set_timings_ms,
            step_ms: self.last_step_ms,
            phenomena: self.sim.phenomena(),
            stats: self.sim.stats().clone(),
            params: self.sim.params().clone(),
            plugin_params: self.sim.plugin_params().iter().copied().collect(),
            history,
            log: self.log.clone(),
        }
    }
}

/// One line saying what a command did.
pub fn describe_outcome(o: &Outcome) -> String {
    match o {
        Outcome::Motion { plate } => format!("plate {plate} has a new motion"),
        Outcome::CrustType { samples } => format!("{samples} samples changed crust type"),
        Outcome::Rift { fragments } => format!("rift into plates {fragments:?}"),
        Outcome::Uplift { samples } => format!("{samples} samples raised or lowered"),
        Outcome::Phenomenon => "phenomenon switched".into(),
        Outcome::Param { key } => format!("{key} set"),
    }
}

/// How the viewer names a compute backend in its messages.
pub(crate) fn backend_name(b: ComputeBackend) -> &'static str {
    match b {
        ComputeBackend::Cpu => "CPU",
        ComputeBackend::Gpu => "GPU",
    }
}
