//! Relief that balances (DESIGN §7): uplift builds relief by thickening the crust; rivers,
//! hillslopes, waves and isostasy take it back; sediment builds shelves and fills trenches. Five
//! phenomena, each a plugin, in this order within a step (after subduction):
//!
//! 1. **Drainage** ([`drainage`], system [`build_drainage`], set `Drainage`): every land sample
//!    drains to one neighbour by great-circle slope; closed depressions fill to lakes that
//!    overflow (priority flood); every river ends in the sea; drainage areas in km².
//! 2. **Rivers** ([`stream_power`], [`diffusion`], system [`erode_rivers`], set `Rivers`):
//!    stream-power incision E = K·A^m·S^n − E_c solved implicitly along the network (Braun &
//!    Willett 2013) and hillslope diffusion. The eroded rock leaves the crust: thickness goes down
//!    by what the surface lost.
//! 3. **Coasts** ([`coast`], system [`coast::erode_coasts`], set `Coasts`): a coast facing open
//!    water retreats, ever more slowly as the platform of shallow water in front of it widens,
//!    and leaves that platform at the wave base; the rock joins what the rivers carry.
//! 4. **Sediment** ([`sediment`], system [`deposit_sediment`], set `Sediment`): what was eroded
//!    travels down the network and is laid down in lakes, on shelves to a break near −130 m, on
//!    slopes and rises, and in trenches and basins; it thickens the crust it lies on. Deposited
//!    volume equals eroded volume every step ([`SurfaceFlux`]). Floor that went under another
//!    plate since the last resampling passes its share on to the trench.
//! 5. **Isostasy** ([`isostasy`], system [`apply_isostasy`], set `Isostasy`): the elevation
//!    follows from the crust. Continental crust floats (Airy) with a regional response standing
//!    in for flexure; ocean floor sinks with age (GDH1 or Parsons–Sclater), raised by what lies
//!    on it (sediment, arcs: the thickness above `init.oceanic_thickness_km`) and lowered by the
//!    flexure of neighbouring continents; a trench is cut in front of each active subduction
//!    front. It runs last (after the sediment), so the maps show the compensated surface.
//!    With `isostasy.ocean_volume_layer_km` set, the surface then moves against the sea until
//!    the water has that volume ([`sea_level`]): the sea rises over the land when the basins
//!    fill.
//!
//! With isostasy on, **every change of elevation goes through thickness**: subduction and
//! collision thicken the crust (the paper's uplift rates read as the surface rise before
//! compensation, so the crust thickens by Δz/(1 − ρ_c/ρ_m)), erosion thins it, deposition thickens
//! it, and the elevation is derived. Switched off, the crust keeps the paper's behaviour: the
//! kernels raise the elevation directly, and the paper's erosion law (phenomenon `erosion`, off
//! by default) is the one to use.
//!
//! For the outputs, [`network`] builds the network of a given crust (the resampled crust the maps
//! show), the basin of every sample and the rivers cut into reaches.
//!
//! The graph is the reference mesh: rivers ignore plate boundaries. Between two resamplings the
//! plates have moved, so an edge across a boundary joins samples that are no longer side by side;
//! few rivers cross a boundary, and the next resampling puts the samples back in place.

pub mod buckets;
pub mod climate;
pub mod coast;
pub mod diffusion;
pub mod drainage;
pub mod graph;
pub mod isostasy;
pub mod network;
pub mod sea_level;
pub mod sediment;
pub mod stream_power;

use std::sync::mpsc::{Receiver, TryRecvError};
use std::sync::{Arc, Mutex};

use bevy_ecs::prelude::*;
use rayon::prelude::*;

use self::diffusion::{DiffusionBudget, DiffusionScratch, diffuse_land, diffuse_land_gpu};
use self::drainage::{Drainage, SeaMaskScratch, sea_mask_with};
use self::graph::ReliefGraph;
use self::isostasy::{AgeDepthLaw, AgeDepthTable, IsostasyParams, RegionalIsostasy, isostasy_cpu};
use self::sediment::{SedimentBudget, SedimentParams, SedimentRouter};
use self::stream_power::{StreamPowerParams, StreamPowerScratch, stream_power_erode_to};
use crate::components::{Plate, PlateBounds, PlateFrame, PlateMotion, PlateStats};
use crate::geometry::SphereMesh;
use crate::gpu::isostasy::isostasy_dispatch;
use crate::gpu::{FieldMask, GpuContext, pull_or_record, run_or_record};
use crate::resources::convergence::NONE;
use crate::resources::params::Params;
use crate::resources::{
    ConvergenceField, Crust, CrustType, FrontPoints, PlateTable, SimClock, StepTimings,
};

/// Run condition of the climate and the drainage: when no network is there to follow (the first
/// step, the one after a resampling, the one after the drainage was switched on), and when the
/// last one was built `time.relief_interval_steps` steps ago (every step at 1, the default). The
/// rivers and coasts run every step, on the last network built; the sediment runs with each new
/// network ([`sediment_due`]). Counted from the last network, not from the start of the run: a
/// network built after a resampling serves its k steps too.
pub fn drainage_due(
    clock: Res<SimClock>,
    params: Res<Params>,
    network: Option<Res<DrainageNetwork>>,
) -> bool {
    let k = params.time.relief_interval_steps.max(1);
    let Some(net) = network.filter(|n| n.built) else {
        return true;
    };
    // A network built without its source (before `time.relief_interval_steps` was raised above
    // 1) cannot go into a save: it is built again.
    clock.step >= net.built_step.saturating_add(k) || (k > 1 && net.source.is_none())
}

/// Builds the network again from its source when its buffers were freed between steps
/// ([`crate::simulation::Simulation::release_scratch`] keeps only what a save holds of a network
/// that serves later steps): the same network, bit for bit ([`DrainageNetwork::rebuild`]), before
/// the rivers follow it. Runs on the steps that build no network of their own.
pub fn restore_network(
    params: Res<Params>,
    mesh: Res<SphereMesh>,
    mut state: ResMut<ReliefState>,
    mut network: ResMut<DrainageNetwork>,
) {
    if !network.built || network.drainage.receiver.len() == mesh.len() {
        return;
    }
    let Some(source) = network.source.take() else {
        return;
    };
    let step = network.built_step;
    network.rebuild(&params, &mesh, &mut state, source, step);
    // A source that no longer fits the mesh builds nothing: the network is forgotten, and the
    // drainage builds one of this step's surface.
    if network.drainage.receiver.len() != mesh.len() {
        network.forget();
    }
}

/// Run condition of the sediment's routing: the drainage built the network this step. It lays
/// down what the rivers and coasts eroded since the last routing.
pub fn sediment_due(clock: Res<SimClock>, network: Option<Res<DrainageNetwork>>) -> bool {
    network.is_some_and(|n| n.fresh(clock.step))
}

/// Run condition of the sediment's routing before a resampling: rock the rivers and coasts
/// eroded on steps since the last routing is still carried (with
/// `time.relief_interval_steps` above 1). It is laid down on the last network before the
/// resampling moves the samples it is recorded on.
pub fn sediment_carried(
    flux: Option<Res<SurfaceFlux>>,
    network: Option<Res<DrainageNetwork>>,
) -> bool {
    flux.is_some_and(|f| f.pending && f.carried) && network.is_some_and(|n| n.built)
}

/// The isostasy constants of `params`.
pub fn isostasy_params(params: &Params) -> IsostasyParams {
    let i = &params.isostasy;
    IsostasyParams {
        rho_crust: i.crust_density_g_per_cm3,
        rho_mantle: i.mantle_density_g_per_cm3,
        rho_water: 1.03,
        rho_sediment: i.sediment_density_g_per_cm3,
        ref_thickness_km: i.reference_thickness_km,
        ref_elevation_km: i.reference_elevation_km,
        elastic_thickness_km: i.elastic_thickness_km,
        young_modulus_gpa: 100.0,
        poisson: 0.25,
        gravity: 9.81,
        max_support_km: i.max_flexural_support_km,
    }
}

/// The stream-power constants of `params`.
pub fn stream_power_params(params: &Params) -> StreamPowerParams {
    let r = &params.rivers;
    StreamPowerParams {
        k: r.erodibility_per_my,
        m: r.area_exponent,
        n: r.slope_exponent,
        threshold_km_per_my: r.incision_threshold_mm_per_yr,
        reference_spacing_km: r.reference_spacing_km,
        spacing_exponent: 1.0,
    }
}

/// The marine deposition profile of `params`.
pub fn sediment_params(params: &Params) -> SedimentParams {
    let s = &params.sediment;
    SedimentParams {
        coast_depth_km: s.coast_depth_km,
        shelf_gradient: s.shelf_gradient,
        shelf_break_depth_km: s.shelf_break_depth_km,
        outer_shelf_gradient: s.outer_shelf_gradient,
        slope_gradient: s.slope_gradient,
        slope_base_depth_km: s.slope_base_depth_km,
        rise_gradient: s.rise_gradient,
        graded_slope: s.graded_slope,
        graded_concavity: s.graded_concavity,
        ..SedimentParams::default()
    }
}

/// The drainage network of the surface (a resource, built by [`build_drainage`] on the steps
/// of [`drainage_due`]): receivers, the stack, drainage areas, lakes, the sea mask.
#[derive(Resource, Default)]
pub struct DrainageNetwork {
    /// The network (see [`Drainage`]).
    pub drainage: Drainage,
    /// True while the network is there to follow: from its build until the next resampling
    /// moves the samples.
    pub built: bool,
    /// The step it was built on ([`SimClock::step`] as the relief sets see it).
    pub built_step: u64,
    /// What it was built from, kept while it serves later steps
    /// (`time.relief_interval_steps` above 1): a save holds it, and a load rebuilds the same
    /// network from it ([`DrainageNetwork::rebuild`]).
    pub source: Option<NetworkSource>,
}

/// The inputs a network was built from (see [`DrainageNetwork::source`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NetworkSource {
    /// The surface, km.
    pub elevation_km: Vec<f32>,
    /// Which samples were oceanic crust.
    pub oceanic: Vec<bool>,
    /// The rain it weighed its areas with (empty: uniform).
    pub rain: Vec<f32>,
}

impl DrainageNetwork {
    /// Built on `step` (the surface processes of that step run on a network of their own
    /// surface: the sediment routes only then).
    pub fn fresh(&self, step: u64) -> bool {
        self.built && self.built_step == step
    }

    /// Forgets the network (a resampling moved the samples): the next step builds one.
    pub fn forget(&mut self) {
        self.built = false;
        self.source = None;
    }

    /// Frees the network's buffers. A network with its source (one that serves later steps)
    /// stays built: the next step builds the buffers again from the source
    /// ([`restore_network`]); any other is forgotten.
    pub fn release_buffers(&mut self) {
        self.drainage = Drainage::default();
        if self.source.is_none() {
            self.built = false;
        }
    }

    /// Builds the network again from the `source` it was built from on `step` (a save's): the
    /// same network, bit for bit. `oceanic` of the relief state is set to the source's.
    pub fn rebuild(
        &mut self,
        params: &Params,
        mesh: &SphereMesh,
        state: &mut ReliefState,
        source: NetworkSource,
        step: u64,
    ) {
        let n = mesh.len();
        if ensure_graph(&mut state.graph, mesh) {
            state.iso_key = None;
        }
        let Some(g) = state.graph.as_ref() else {
            return;
        };
        if source.elevation_km.len() != n || source.oceanic.len() != n {
            return;
        }
        route_network(
            g,
            params,
            &source.elevation_km,
            &source.oceanic,
            &mut self.drainage,
            &mut state.sea,
        );
        let rain = Some(&source.rain[..]).filter(|r| r.len() == n);
        self.drainage.compute_areas(g, rain);
        state.oceanic.clone_from(&source.oceanic);
        self.built = true;
        self.built_step = step;
        self.source = Some(source);
    }
}

/// The sea mask and the routes of the surface `elevation_km` (oceanic crust `oceanic`) into
/// `drainage`; the areas come after ([`Drainage::compute_areas`]).
fn route_network(
    g: &ReliefGraph,
    params: &Params,
    elevation_km: &[f32],
    oceanic: &[bool],
    drainage: &mut Drainage,
    sea: &mut SeaMaskScratch,
) -> std::time::Duration {
    let mut ocean = std::mem::take(&mut drainage.ocean);
    let t_sea = std::time::Instant::now();
    sea_mask_with(
        g,
        elevation_km,
        oceanic,
        params.rivers.min_sea_area_km2,
        &mut ocean,
        sea,
    );
    drainage.lake_area_ratio = lake_area_ratio(params);
    let sea_ms = t_sea.elapsed();
    drainage.compute_routes(g, elevation_km, &ocean);
    sea_ms
}

/// Relative rain per sample (1 = the planet's mean; a resource a plugin may set). Drainage
/// areas are areas weighted by it. Absent or of the wrong length: uniform rain.
#[derive(Resource, Clone, Debug, Default)]
pub struct Precipitation(pub Vec<f32>);

/// What the surface processes moved this step (a resource): per sample, km of rock eroded by
/// rivers, the change by hillslope diffusion and the sediment laid down; and the volumes.
#[derive(Resource, Clone, Debug, Default)]
pub struct SurfaceFlux {
    /// Rock removed by stream power this step, km per sample.
    pub eroded_km: Vec<f32>,
    /// Surface change by hillslope diffusion, km per sample (land only).
    pub diffusion_km: Vec<f32>,
    /// Volume carried across the coast by diffusion into each ocean sample, km³.
    pub to_ocean_km3: Vec<f64>,
    /// Sediment laid down this step, km per sample.
    pub deposit_km: Vec<f32>,
    /// Stream-power volume, km³.
    pub incised_km3: f64,
    /// Diffusion volumes.
    pub diffusion: DiffusionBudget,
    /// Sediment volumes.
    pub sediment: SedimentBudget,
    /// Pelagic sediment laid on the sea floor this step, km³ (from the sea, not the land).
    pub pelagic_km3: f64,
    /// Volume the waves cut from the coasts this step, km³ (its thickness is in `eroded_km`).
    pub coastal_km3: f64,
    /// Summed over the run: eroded and deposited volumes, km³.
    pub total_eroded_km3: f64,
    /// See `total_eroded_km3`.
    pub total_deposited_km3: f64,
    /// Rock has been eroded into this flux and not laid down yet.
    pub pending: bool,
    /// The flux was opened on a step without a network of its own (with
    /// `time.relief_interval_steps` above 1): the next network's routing lays it down with its
    /// own step's ([`build_drainage`] keeps it), or the routing before a resampling
    /// ([`sediment_carried`]).
    pub carried: bool,
}

impl SurfaceFlux {
    /// Volume eroded this step (incision, diffusion lowering, coastal erosion), km³.
    pub fn eroded_km3(&self) -> f64 {
        self.incised_km3 + self.diffusion.lowered_km3 + self.coastal_km3
    }

    /// Starts a step on `n` samples: nothing eroded, carried or laid down yet (so that a
    /// phenomenon switched off leaves no stale flux for the sediment to lay down again). The
    /// run's totals are kept.
    pub fn begin_step(&mut self, n: usize) {
        for v in [
            &mut self.eroded_km,
            &mut self.diffusion_km,
            &mut self.deposit_km,
        ] {
            v.clear();
            v.resize(n, 0.0);
        }
        self.to_ocean_km3.clear();
        self.to_ocean_km3.resize(n, 0.0);
        self.incised_km3 = 0.0;
        self.diffusion = DiffusionBudget::default();
        self.sediment = SedimentBudget::default();
        self.pelagic_km3 = 0.0;
        self.coastal_km3 = 0.0;
        self.pending = false;
        self.carried = false;
    }

    /// Before the rivers or coasts add this step's erosion (`fresh`: on a network built this
    /// step). On a later step of a network, the flux of its routing is cleared first and what
    /// is eroded from then on is carried to the next routing. Returns whether the flux already
    /// holds rock not laid down (what is added now must add to it).
    pub fn open(&mut self, n: usize, fresh: bool) -> bool {
        if self.eroded_km.len() != n || (!fresh && !self.pending) {
            self.begin_step(n);
            self.carried = !fresh;
        }
        std::mem::replace(&mut self.pending, true)
    }
    /// Volume deposited this step (sediment plus diffusion raising), km³.
    pub fn deposited_km3(&self) -> f64 {
        self.sediment.deposited_km3 + self.diffusion.raised_km3
    }
}

/// One step's cut by the rivers and slopes, per sample (see [`SurfaceFlux`]).
#[derive(Default)]
struct StepFlux {
    eroded_km: Vec<f32>,
    diffusion_km: Vec<f32>,
    to_ocean_km3: Vec<f64>,
}

/// Scratch and cached state of the relief passes (a resource): the sample graph (built once per
/// mesh), the regional-isostasy levels, the age–depth table, the trench depth of this step.
#[derive(Resource, Default)]
pub struct ReliefState {
    /// The sample graph of the reference mesh (shared with the climate's search while it runs
    /// beside the drainage).
    pub graph: Option<Arc<ReliefGraph>>,
    iso: RegionalIsostasy,
    iso_key: Option<(usize, u64)>,
    table: Option<(bool, u64, AgeDepthTable)>,
    spl: StreamPowerScratch,
    /// This step's cut when the flux already holds rock of earlier steps (see [`erode_rivers`]).
    step_flux: StepFlux,
    /// The sea the rivers, slopes and coasts see on a later step of the network (see
    /// [`coast::refresh_sea`]), and its scratch.
    sea_now: Vec<bool>,
    frontier: Vec<u32>,
    diffusion: DiffusionScratch,
    router: SedimentRouter,
    sea: SeaMaskScratch,
    oceanic: Vec<bool>,
    continental: Vec<bool>,
    fill: Vec<f32>,
    trench_scratch: TrenchScratch,
    /// The trench running beside the sediment ([`begin_trench`]).
    trench_task: Option<TrenchTask>,
    /// The trench thread's copies of each sample's plate and crust type (kept for the next
    /// step's).
    trench_plate: Vec<u32>,
    trench_types: Vec<CrustType>,
    /// Trench depth below the sea floor beside it, km per sample (0 away from fronts), as cut
    /// by the last isostasy pass. The summary reads it to leave trenches out of the normal
    /// floor's age–depth statistics. The fronts do not: they read the elevation at the front,
    /// trench and its fill included (docs/relief.md, open problems).
    pub trench_km: Vec<f32>,
    /// Height of the sea above the isostatic datum from the last isostasy pass, km (0 unless
    /// `isostasy.ocean_volume_layer_km` sets the water's volume; see [`sea_level`]).
    pub sea_level_km: f64,
    /// The pelagic rain's rate field, built once per mesh and parameters.
    pelagic: PelagicField,
}

/// The multiplier of the pelagic rain at every sample ([`pelagic_rate_field`]) and what it was
/// built for (samples, seed, σ, wavelength, radius).
#[derive(Default)]
struct PelagicField {
    key: Option<(usize, u64, u64, u64, u64)>,
    /// Shared with the maps and the viewer, which take it as it is.
    rate: std::sync::Arc<Vec<f32>>,
}

impl PelagicField {
    /// Builds the field for `mesh` and `params` unless it is built already (the field of
    /// [`pelagic_rate_field`] for `sediment.pelagic_variability`, from the planet seed's own
    /// random stream); empty when σ is 0 (the same rain everywhere).
    fn ensure(&mut self, mesh: &SphereMesh, params: &Params) -> &[f32] {
        let s = &params.sediment;
        let r = params.planet.radius_km;
        let key = (
            mesh.len(),
            params.planet.seed,
            s.pelagic_variability.to_bits(),
            s.pelagic_variability_km.to_bits(),
            r.to_bits(),
        );
        if self.key != Some(key) {
            self.rate = std::sync::Arc::new(pelagic_rate_field(
                &mesh.positions,
                &mesh.area_km2,
                crate::random::hash3(params.planet.seed, crate::random::stream::PELAGIC, 0),
                s.pelagic_variability,
                s.pelagic_variability_km / r,
            ));
            self.key = Some(key);
        }
        &self.rate
    }
}

/// The multiplier of the pelagic rain at each of `positions` (unit vectors in the mantle frame)
/// for `sediment.pelagic_variability` σ: exp(σ·F) scaled to an area-weighted mean of 1 over
/// `area_km2`, where F is the fractal noise of `seed` (three octaves, the first `wavelength_rad`
/// long) less its area-weighted mean, over its area-weighted standard deviation. The noise is
/// computed per sample in parallel and the means summed in sample order, so the field is the
/// same whatever the thread count. Empty for σ ≤ 0 or no samples.
pub fn pelagic_rate_field(
    positions: &[glam::DVec3],
    area_km2: &[f64],
    seed: u64,
    sigma: f64,
    wavelength_rad: f64,
) -> Vec<f32> {
    let n = positions.len().min(area_km2.len());
    if !(sigma > 0.0) || n == 0 {
        return Vec::new();
    }
    let f: Vec<f64> = positions[..n]
        .par_iter()
        .with_min_len(4096)
        .map(|&p| crate::random::fbm(seed, p, wavelength_rad, 3))
        .collect();
    let area = &area_km2[..n];
    let total: f64 = area.iter().sum();
    if !(total > 0.0) {
        return Vec::new();
    }
    // Area-weighted mean of `g` over `xs`, summed in sample order.
    let mean_of = |xs: &[f64], g: &dyn Fn(f64) -> f64| {
        xs.iter().zip(area).map(|(&x, a)| g(x) * a).sum::<f64>() / total
    };
    let mean = mean_of(&f, &|x| x);
    let var = mean_of(&f, &|x| (x - mean) * (x - mean));
    let scale = if var > 0.0 { sigma / var.sqrt() } else { 0.0 };
    let e: Vec<f64> = f.iter().map(|x| ((x - mean) * scale).exp()).collect();
    let e_mean = mean_of(&e, &|x| x);
    e.iter().map(|x| (x / e_mean) as f32).collect()
}

impl ReliefState {
    /// The pelagic rain's multiplier at each sample of `mesh` under `params` (see
    /// [`pelagic_rate_field`]): the field the rain uses, built here if no rain has yet (a planet
    /// just loaded); empty with the same rain everywhere.
    pub fn pelagic_rate(&mut self, mesh: &SphereMesh, params: &Params) -> std::sync::Arc<Vec<f32>> {
        self.pelagic.ensure(mesh, params);
        self.pelagic.rate.clone()
    }

    /// Frees the relief passes' work areas (rebuilt at their next use): see
    /// [`crate::simulation::Simulation::release_scratch`]. Keeps the graph, the caches, the
    /// router's limit on overflows and what the summary reads (the trench depths, the sea level,
    /// the deflection).
    pub fn release_scratch(&mut self) {
        self.spl = StreamPowerScratch::default();
        self.step_flux = StepFlux::default();
        self.sea_now = Vec::new();
        self.frontier = Vec::new();
        self.diffusion = DiffusionScratch::default();
        // The router's setting stays; only its buffers go.
        let max_overflows = self.router.max_overflows;
        self.router = SedimentRouter::default();
        self.router.max_overflows = max_overflows;
        self.sea = SeaMaskScratch::default();
        self.fill = Vec::new();
        if self.trench_task.is_none() {
            self.trench_scratch = TrenchScratch::default();
            self.trench_plate = Vec::new();
            self.trench_types = Vec::new();
        }
    }

    /// Frees the regional isostasy's levels (its coarse mesh and restriction, about 60 bytes a
    /// sample); the next isostasy pass builds them again, the same. Not done before every
    /// resampling with the rest ([`Self::release_scratch`]): the build takes longer than a
    /// step's relief.
    pub fn release_isostasy_levels(&mut self) {
        self.iso = RegionalIsostasy::default();
        self.iso_key = None;
    }

    /// Whether the regional isostasy works on a coarse level (see
    /// [`Self::release_isostasy_levels`]).
    pub fn isostasy_has_coarse_level(&self) -> bool {
        self.iso.has_coarse_level()
    }

    /// Deflection w of the lithosphere under the continents' regional load (km, positive
    /// down) from the last isostasy pass: the flexural moat beside a continent at sea, before
    /// the `isostasy.max_flexural_support_km` clamp.
    pub fn deflection_km(&self) -> &[f32] {
        self.iso.deflection_km()
    }

    /// What the last sediment routing was given besides the network and the flux: the surface
    /// rise per unit of deposit of each sample, and the passages through subducted floor (see
    /// [`SedimentRouter::passages_mut`]); for timing the router apart on a real step's inputs.
    pub fn sediment_inputs(&self) -> (&[f32], &[u32]) {
        (&self.fill, self.router.passages())
    }
}

/// A lap timer for the passes that time their stages: each call gives the milliseconds since
/// the last call (the first since the timer was made).
pub(crate) fn lap_timer() -> impl FnMut() -> f64 {
    let clock = std::time::Instant::now();
    let mut last = 0.0;
    move || {
        let now = clock.elapsed().as_secs_f64() * 1e3;
        let d = now - last;
        last = now;
        d
    }
}

/// Builds the sample graph of `mesh` into `slot` unless it is there already (true when it was
/// rebuilt).
fn ensure_graph(slot: &mut Option<Arc<ReliefGraph>>, mesh: &SphereMesh) -> bool {
    if slot.as_ref().is_some_and(|g| g.len() == mesh.len()) {
        return false;
    }
    *slot = Some(Arc::new(network::relief_graph(mesh)));
    true
}

/// On the GPU backend, brings the fields of `mask` the device holds newer into the host crust
/// (without moving its change tick); false when that failed (the step then stops with it).
fn pull(crust: &mut ResMut<Crust>, gpu: &mut Option<ResMut<GpuContext>>, mask: FieldMask) -> bool {
    match gpu.as_mut() {
        Some(g) => pull_or_record(g, crust, mask),
        None => true,
    }
}

/// On the GPU backend, before a system that reads `reads` writes `writes` of the host crust:
/// pulls what it reads, and tells whether the write can be declared (the device is in sync
/// otherwise, so only `writes` go up afterwards, in [`after_write`]); when it cannot, every
/// field the device holds newer comes down first (and the next kernel uploads the whole crust).
/// `None` when a pull failed (the step stops with it).
fn before_write(
    crust: &mut ResMut<Crust>,
    gpu: &mut Option<ResMut<GpuContext>>,
    reads: FieldMask,
    writes: FieldMask,
) -> Option<bool> {
    let Some(g) = gpu.as_mut() else {
        return Some(false);
    };
    if !pull_or_record(g, crust, reads | writes) {
        return None;
    }
    let declared = g.can_declare_host_write(writes, crust.len(), crust.last_changed());
    if !declared && !pull_or_record(g, crust, FieldMask::ALL) {
        return None;
    }
    Some(declared)
}

/// After a declared host write of `writes` (see [`before_write`]): uploads those fields.
fn after_write(
    crust: &ResMut<Crust>,
    gpu: &mut Option<ResMut<GpuContext>>,
    writes: FieldMask,
    declared: bool,
) {
    if declared
        && let Some(g) = gpu.as_mut()
        && let Err(e) = g.note_host_write(crust, writes, crust.last_changed())
    {
        g.record_failure(e);
    }
}

/// The water balance of closed lakes from the parameters: runoff over net lake evaporation
/// (see [`Drainage::lake_area_ratio`]); `None` when the evaporation is 0 (lakes always fill).
pub fn lake_area_ratio(params: &Params) -> Option<f64> {
    let r = &params.rivers;
    (r.lake_net_evaporation_mm_per_yr > 0.0)
        .then(|| r.runoff_mm_per_yr / r.lake_net_evaporation_mm_per_yr)
}

/// With `isostasy.ocean_volume_layer_km` set: moves the isostatic surface of `crust` against
/// the sea until the water below sea level has that volume, and returns the sea's height above
/// the datum (km); None with the sea fixed at the datum (see [`sea_level`]).
fn settle_sea_level(
    ip: &crate::resources::params::Isostasy,
    c: &crate::gpu::isostasy::IsostasyConstants,
    g: &ReliefGraph,
    crust: &mut Crust,
) -> Option<f64> {
    if ip.ocean_volume_layer_km <= 0.0 || crust.len() != g.len() {
        return None;
    }
    let f = c.rho_mantle / (c.rho_mantle - c.rho_water);
    let volume = ip.ocean_volume_layer_km * g.total_area_km2();
    let d = sea_level::solve_datum(
        &crust.elevation_km,
        &crust.crust_type,
        &g.area_km2,
        f,
        volume,
    );
    sea_level::shift_surface(&mut crust.elevation_km, &crust.crust_type, f, d);
    Some(-d)
}

/// The climate's parameters from `params`.
pub fn climate_params(params: &Params) -> climate::ClimateParams {
    let c = &params.climate;
    climate::ClimateParams {
        moisture_length_km: c.moisture_length_km,
        wind_anisotropy: c.wind_anisotropy,
        orographic_height_km: c.orographic_height_km,
        windward_slope: c.windward_slope,
        min_rain: c.min_rain,
    }
}

/// Scratch of the climate, and whether [`Precipitation`] holds its field (a resource).
#[derive(Resource, Default)]
pub struct ClimateState {
    scratch: climate::ClimateScratch,
    /// True while [`Precipitation`] holds the field [`update_climate`] wrote.
    pub wrote: bool,
    /// The climate's search running beside the drainage: it hands back the field and the
    /// scratch ([`finish_climate`]).
    pending: Option<Mutex<Receiver<ClimateResult>>>,
    /// How long the last search took on its thread, taken by the drainage's timings (the
    /// climate set's own time does not hold it: the search runs inside the drainage's).
    pub last_search: Option<std::time::Duration>,
}

impl ClimateState {
    /// Frees the search's work area and the mesh's tables (rebuilt at the next run); none may
    /// be running (one runs only within a step).
    pub fn release_scratch(&mut self) {
        if self.pending.is_none() {
            self.scratch = climate::ClimateScratch::default();
        }
    }

    /// Frees the search's work area but keeps the mesh's tables (about 11 bytes a sample, which
    /// depend on the mesh alone and took 15–20 ms to build again at 500k samples after every
    /// resampling; keeping them through the resampling left the peak of memory where it was).
    pub fn release_search(&mut self) {
        if self.pending.is_none() {
            self.scratch.release_search();
        }
    }
}

/// What the climate's search hands back: the field, its scratch and the time it took, or its
/// panic.
type ClimateResult = std::thread::Result<(Vec<f32>, climate::ClimateScratch, std::time::Duration)>;

/// Rain over the land from the current surface into [`Precipitation`] (phenomenon `climate`;
/// see [`climate`]).
///
/// The surface is copied here, and the least-cost search, one thread's work, runs as a task of
/// the thread pool beside the drainage's routing (which does not read the rain):
/// [`build_drainage`] waits for it before it weighs its areas ([`finish_climate`]). The field
/// is the same as computed in place.
pub fn update_climate(
    params: Res<Params>,
    mesh: Res<SphereMesh>,
    mut crust: ResMut<Crust>,
    mut state: ResMut<ReliefState>,
    mut cs: ResMut<ClimateState>,
    mut rain: ResMut<Precipitation>,
    mut gpu: Option<ResMut<GpuContext>>,
) {
    finish_climate(&mut cs, &mut rain);
    if !pull(&mut crust, &mut gpu, FieldMask::ELEVATION) {
        return;
    }
    if ensure_graph(&mut state.graph, &mesh) {
        state.iso_key = None;
    }
    let Some(g) = state.graph.clone() else {
        return;
    };
    let cs = &mut *cs;
    climate::prepare(&g, &mesh.positions, &crust.elevation_km, &mut cs.scratch);
    let mut scratch = std::mem::take(&mut cs.scratch);
    let mut out = std::mem::take(&mut rain.0);
    let p = climate_params(&params);
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    rayon::spawn(move || {
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || {
            let t = std::time::Instant::now();
            climate::precipitation_prepared(&g, &p, &mut out, &mut scratch);
            (out, scratch, t.elapsed())
        }));
        let _ = tx.send(result);
    });
    cs.pending = Some(Mutex::new(rx));
    cs.wrote = true;
}

/// Waits for the climate [`update_climate`] started, if any, and puts its field into
/// [`Precipitation`] (a panic in it goes on here). On a thread of the pool (a simulation run
/// inside `ThreadPool::install`), it runs the pool's pending tasks while it waits, so a pool
/// of one thread does not wait on itself.
pub fn finish_climate(cs: &mut ClimateState, rain: &mut Precipitation) {
    let Some(rx) = cs.pending.take() else {
        return;
    };
    match wait_for(rx) {
        Some(Ok((out, scratch, took))) => {
            rain.0 = out;
            cs.scratch = scratch;
            cs.last_search = Some(took);
        }
        Some(Err(panic)) => std::panic::resume_unwind(panic),
        None => {
            rain.0.clear();
            cs.wrote = false;
        }
    }
}

/// With the climate switched off: the rain it wrote goes, so the drainage sees uniform rain
/// again (a field another plugin set stays).
pub fn clear_climate(mut cs: ResMut<ClimateState>, mut rain: ResMut<Precipitation>) {
    finish_climate(&mut cs, &mut rain);
    if cs.wrote {
        rain.0.clear();
        cs.wrote = false;
    }
}

/// Builds the drainage network of the current surface (phenomenon `drainage`), on the steps of
/// [`drainage_due`].
#[allow(clippy::too_many_arguments)]
pub fn build_drainage(
    params: Res<Params>,
    mesh: Res<SphereMesh>,
    clock: Res<SimClock>,
    mut crust: ResMut<Crust>,
    mut state: ResMut<ReliefState>,
    mut network: ResMut<DrainageNetwork>,
    mut flux: ResMut<SurfaceFlux>,
    mut rain: Option<ResMut<Precipitation>>,
    mut climate: Option<ResMut<ClimateState>>,
    mut gpu: Option<ResMut<GpuContext>>,
    mut timings: Option<ResMut<StepTimings>>,
) {
    // The climate's search, if it runs, is done when this system returns.
    let mut finish = |rain: &mut Option<ResMut<Precipitation>>| {
        if let (Some(cs), Some(rain)) = (climate.as_deref_mut(), rain.as_deref_mut()) {
            finish_climate(cs, rain);
        }
    };
    // The flux starts empty here for the relief systems after this one (they run only on a
    // built network), unless it carries what the rivers and coasts eroded on the steps since
    // the last network: the sediment lays that down with this step's.
    let n = mesh.len();
    if !(flux.carried && flux.pending && flux.eroded_km.len() == n) {
        flux.begin_step(n);
    }
    flux.carried = false;
    network.forget();
    if !pull(&mut crust, &mut gpu, FieldMask::ELEVATION) {
        finish(&mut rain);
        return;
    }
    let state = &mut *state;
    state.oceanic.clear();
    state
        .oceanic
        .extend(crust.crust_type.iter().map(|&t| t == CrustType::Oceanic));
    if ensure_graph(&mut state.graph, &mesh) {
        state.iso_key = None;
    }
    let Some(g) = state.graph.as_ref() else {
        finish(&mut rain);
        return;
    };
    let network = &mut *network;
    let sea_ms = route_network(
        g,
        &params,
        &crust.elevation_km,
        &state.oceanic,
        &mut network.drainage,
        &mut state.sea,
    );
    let t_wait = std::time::Instant::now();
    finish(&mut rain);
    let wait = t_wait.elapsed();
    let search = climate.as_deref_mut().and_then(|c| c.last_search.take());
    let rain = rain.as_ref().map(|r| &r.0[..]).filter(|r| r.len() == n);
    network.drainage.compute_areas(g, rain);
    network.built = true;
    network.built_step = clock.step;
    // Kept while the network serves later steps, for a save to rebuild it.
    if params.time.relief_interval_steps > 1 {
        network.source = Some(NetworkSource {
            elevation_km: crust.elevation_km.clone(),
            oceanic: state.oceanic.clone(),
            rain: rain.map(<[f32]>::to_vec).unwrap_or_default(),
        });
    }
    if let Some(t) = timings.as_mut() {
        t.record("drainage_sea_mask", sea_ms);
        t.record("drainage_climate_wait", wait);
        if let Some(search) = search {
            t.record("climate_search", search);
        }
        t.record_ms(&Drainage::STAGES, &network.drainage.timings_ms);
    }
}

/// After a resampling moved the samples: the network is forgotten (the next step builds one),
/// and rock still carried from earlier steps is dropped (it is laid down before the resampling
/// when the sediment is on: [`sediment_carried`]).
pub fn forget_network(mut network: ResMut<DrainageNetwork>, mut flux: ResMut<SurfaceFlux>) {
    network.forget();
    flux.carried = false;
}

/// Before a resampling, once the rock still carried is laid down: the network (which the
/// resampling makes stale: [`forget_network`]) and the relief passes' work areas are freed, and
/// built again on the next step. So the resampling's own buffers do not come on top of them, in
/// the step that holds the run's peak memory. What is freed never changes a result (a save holds
/// none of it, and resumes to the same bits). The climate keeps its mesh tables, which the
/// resampling does not change.
pub fn release_relief_before_resample(
    mut state: ResMut<ReliefState>,
    mut network: ResMut<DrainageNetwork>,
    climate: Option<ResMut<ClimateState>>,
) {
    state.release_scratch();
    if let Some(mut c) = climate {
        c.release_search();
    }
    network.forget();
    network.release_buffers();
}

/// Stream-power incision and hillslope diffusion along the network (phenomenon `rivers`): the
/// surface is lowered where rivers cut and slopes creep, and the crust thins by as much. Every
/// step, on the last network built (with `time.relief_interval_steps` above 1, one built on an
/// earlier step: see [`drainage_due`]); the rock joins the [`SurfaceFlux`] still to be laid
/// down.
#[allow(clippy::too_many_arguments)]
pub fn erode_rivers(
    params: Res<Params>,
    mesh: Res<SphereMesh>,
    clock: Res<SimClock>,
    mut crust: ResMut<Crust>,
    mut state: ResMut<ReliefState>,
    network: Res<DrainageNetwork>,
    mut flux: ResMut<SurfaceFlux>,
    mut gpu: Option<ResMut<GpuContext>>,
) {
    if !network.built || network.drainage.receiver.len() != mesh.len() {
        return;
    }
    const WRITES: FieldMask = FieldMask(FieldMask::ELEVATION.0 | FieldMask::THICKNESS.0);
    let Some(mut declared) = before_write(&mut crust, &mut gpu, FieldMask::NONE, WRITES) else {
        return;
    };
    // On the GPU backend the diffusion runs on the device, on the resident elevation: the
    // device must hold the rest of the crust as the host does (it does unless a CPU system
    // wrote the crust undeclared earlier in the step; then every stale field came down above,
    // and the whole crust goes up now rather than at the next kernel).
    if let Some(g) = gpu.as_mut()
        && !declared
        && g.failure.is_none()
    {
        let tick = crust.last_changed();
        if run_or_record(g, |g| g.sync_crust(&crust, Some(tick))) {
            declared = g.can_declare_host_write(WRITES, crust.len(), tick);
        }
    }
    let dt = params.time.time_step_my;
    let spl = stream_power_params(&params);
    let kappa = params.rivers.hillslope_diffusivity_km2_per_my;
    let state = &mut *state;
    let flux = &mut *flux;
    let Some(g) = state.graph.as_ref() else {
        return;
    };
    let n = g.len();
    let mut crust_res = crust;
    let crust = &mut *crust_res;
    // This step's cut goes straight into the flux when it holds nothing yet (every step with
    // `time.relief_interval_steps` = 1), else into the step's own buffers and then added: the
    // crust thins by this step's cut alone.
    let mut lap = lap_timer();
    let fresh = network.fresh(clock.step);
    let add = flux.open(n, fresh);
    // On a later step of the network, the slopes see the sea where it is now.
    let mut sea_now = std::mem::take(&mut state.sea_now);
    let ocean = if fresh {
        &network.drainage.ocean
    } else {
        coast::refresh_sea(
            g,
            &network.drainage.ocean,
            &crust.elevation_km,
            &mut sea_now,
            &mut state.frontier,
        );
        &sea_now
    };
    let mut own = add.then(|| {
        let mut o = std::mem::take(&mut state.step_flux);
        o.eroded_km.resize(n, 0.0);
        o.diffusion_km.resize(n, 0.0);
        o.to_ocean_km3.clear();
        o.to_ocean_km3.resize(n, 0.0);
        o
    });
    let (eroded_km, diffusion_km, to_ocean_km3) = match own.as_mut() {
        Some(o) => (&mut o.eroded_km, &mut o.diffusion_km, &mut o.to_ocean_km3),
        None => (
            &mut flux.eroded_km,
            &mut flux.diffusion_km,
            &mut flux.to_ocean_km3,
        ),
    };
    let t_sea = lap();
    let mut incised_km3 = stream_power_erode_to(
        g,
        &network.drainage,
        ocean,
        &mut crust.elevation_km,
        eroded_km,
        None,
        &spl,
        dt,
        &mut state.spl,
    );
    let t_spl = lap();
    // Background denudation: land loses k·min(z, cap) per My, added to the rock the rivers
    // carry.
    let k_den = params.rivers.denudation_per_my;
    if k_den > 0.0 {
        let factor = (1.0 - (-k_den * dt).exp()) as f32;
        let den_cap = params.rivers.denudation_cap_km as f32;
        let area = &g.area_km2;
        // Summed per fixed chunk, then the chunks in order: the same sum whatever the thread
        // count, without a per-sample buffer.
        const CH: usize = 8192;
        let extra: f64 = crust
            .elevation_km
            .par_chunks_mut(CH)
            .zip(eroded_km.par_chunks_mut(CH))
            .enumerate()
            .map(|(c, (zs, es))| {
                let mut sum = 0.0f64;
                for (k, (z, e)) in zs.iter_mut().zip(es.iter_mut()).enumerate() {
                    let i = c * CH + k;
                    if ocean.get(i).copied().unwrap_or(true) || *z <= 0.0 {
                        continue;
                    }
                    let d = z.min(den_cap) * factor;
                    *z -= d;
                    *e += d;
                    sum += d as f64 * area[i];
                }
                sum
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum();
        incised_km3 += extra;
    }
    let t_den = lap();
    // Hillslope diffusion: on the device when the write is declared (the device then holds the
    // diffused elevation, and only the thickness goes up at the end), else on the CPU.
    let mut on_device = None;
    if declared
        && let Some(ctx) = gpu.as_mut()
        && ctx.failure.is_none()
    {
        match diffuse_land_gpu(
            ctx,
            g,
            &mut crust.elevation_km,
            ocean,
            kappa,
            dt,
            diffusion_km,
            to_ocean_km3,
            &mut state.diffusion,
        ) {
            Ok(budget) => on_device = budget,
            Err(e) => {
                // The resident elevation is lost: the step stops with the error, and the next
                // kernel would upload the whole crust.
                ctx.invalidate_crust();
                ctx.record_failure(e);
                declared = false;
            }
        }
    }
    let uploaded = if on_device.is_some() {
        FieldMask::THICKNESS
    } else {
        WRITES
    };
    let budget = match on_device {
        Some(budget) => budget,
        None => diffuse_land(
            g,
            &mut crust.elevation_km,
            ocean,
            kappa,
            dt,
            diffusion_km,
            to_ocean_km3,
            &mut state.diffusion,
        ),
    };
    let t_dif = lap();
    crust
        .thickness_km
        .par_iter_mut()
        .zip(eroded_km.par_iter().zip(diffusion_km.par_iter()))
        .with_min_len(8192)
        .for_each(|(t, (&e, &d))| *t += d - e);
    if let Some(o) = own {
        add_into(&mut flux.eroded_km, &o.eroded_km);
        add_into(&mut flux.diffusion_km, &o.diffusion_km);
        add_into(&mut flux.to_ocean_km3, &o.to_ocean_km3);
        state.step_flux = o;
    }
    state.sea_now = sea_now;
    tracing::debug!(
        sea = t_sea,
        stream_power = t_spl,
        denudation = t_den,
        diffusion = t_dif,
        rest = lap(),
        "rivers by pass (ms)"
    );
    flux.total_eroded_km3 += incised_km3 + budget.lowered_km3;
    flux.total_deposited_km3 += budget.raised_km3;
    flux.incised_km3 += incised_km3;
    flux.diffusion.add(&budget);
    after_write(&crust_res, &mut gpu, uploaded, declared);
}

/// Adds `part` into `sum`, sample by sample.
fn add_into<T: Copy + std::ops::AddAssign + Send + Sync>(sum: &mut [T], part: &[T]) {
    sum.par_iter_mut()
        .zip(part.par_iter())
        .with_min_len(8192)
        .for_each(|(s, &p)| *s += p);
}

/// What the sediment's routing reads and writes.
#[derive(bevy_ecs::system::SystemParam)]
pub struct SedimentRouting<'w> {
    params: Res<'w, Params>,
    mesh: Res<'w, SphereMesh>,
    crust: ResMut<'w, Crust>,
    state: ResMut<'w, ReliefState>,
    network: Res<'w, DrainageNetwork>,
    flux: ResMut<'w, SurfaceFlux>,
    fp: Res<'w, FrontPoints>,
    field: Res<'w, ConvergenceField>,
    gpu: Option<ResMut<'w, GpuContext>>,
    timings: Option<ResMut<'w, StepTimings>>,
}

/// Lays down what the rivers and slopes carried (phenomenon `sediment`, with each new network:
/// [`sediment_due`]): in lakes, on the shelf, slope and rise, in trenches and basins; the crust
/// thickens by the deposit. Subducting floor that went under its overriding plate since the last
/// resampling takes none: it passes what reaches it on to the trench
/// ([`SedimentRouter::passages_mut`]). The step's pelagic rain follows ([`PelagicRain`]).
pub fn deposit_sediment(s: SedimentRouting) {
    route_sediment(s, true);
}

/// [`deposit_sediment`] of the rock still carried before a resampling ([`sediment_carried`]),
/// on the last network; the step's pelagic rain is laid already ([`lay_pelagic`]).
pub fn deposit_carried_sediment(s: SedimentRouting) {
    route_sediment(s, false);
}

fn route_sediment(s: SedimentRouting, with_pelagic: bool) {
    let SedimentRouting {
        params,
        mesh,
        mut crust,
        mut state,
        network,
        mut flux,
        fp,
        field,
        mut gpu,
        mut timings,
    } = s;
    let n = mesh.len();
    if !network.built || network.drainage.receiver.len() != n || flux.eroded_km.len() != n {
        return;
    }
    let reads = FieldMask(FieldMask::ELEVATION.0 | FieldMask::AGE.0);
    let Some(declared) = before_write(&mut crust, &mut gpu, reads, FieldMask::THICKNESS) else {
        return;
    };
    let iso = isostasy_params(&params);
    let sp = sediment_params(&params);
    let state = &mut *state;
    let flux = &mut *flux;
    let mut crust_res = crust;
    let crust = &mut *crust_res;
    // Surface rise per km deposited: oceanic crust is compensated locally (the sea floor follows
    // the age–depth law), continental crust regionally, so a single sample stands nearly
    // uncompensated in the step it receives its load (it sinks by the next steps' isostasy).
    state.fill.resize(n, 1.0);
    let gain = iso.sediment_gain() as f32;
    state
        .fill
        .par_iter_mut()
        .zip(crust.crust_type.par_iter())
        .with_min_len(8192)
        .for_each(|(f, &t)| {
            *f = if t == CrustType::Oceanic { gain } else { 1.0 };
        });
    flux.deposit_km.resize(n, 0.0);
    let Some(g) = state.graph.as_ref() else {
        return;
    };
    subducted_passages(
        &mesh,
        g,
        crust,
        &fp,
        &field,
        params.isostasy.trench_width_km,
        state.router.passages_mut(),
    );
    // Rock eroded on earlier steps' networks (carried) may lie on samples this network puts on
    // the other side of the coast: it enters the routing as this network sees them.
    match_coast(&network.drainage.ocean, &g.area_km2, flux);
    flux.sediment = state.router.route(
        g,
        &network.drainage,
        &crust.elevation_km,
        &flux.eroded_km,
        Some(&flux.to_ocean_km3),
        Some(&state.fill),
        &sp,
        &mut flux.deposit_km,
    );
    if let Some(t) = timings.as_mut() {
        t.record_ms(&SedimentRouter::STAGES, &state.router.timings_ms);
    }
    crust
        .thickness_km
        .par_iter_mut()
        .zip(flux.deposit_km.par_iter())
        .with_min_len(8192)
        .for_each(|(t, &d)| *t += d);
    flux.total_deposited_km3 += flux.sediment.deposited_km3;
    flux.pending = false;
    flux.carried = false;
    flux.pelagic_km3 = 0.0;
    if with_pelagic {
        flux.pelagic_km3 = pelagic_rain(&params, &mesh, crust, state, &network);
    }
    after_write(&crust_res, &mut gpu, FieldMask::THICKNESS, declared);
}

/// Moves the rock of `flux` recorded on the wrong side of the coast of `ocean` (eroded on a
/// sample now at sea, or carried across the coast into a sample now land) to the other input
/// of the router, at the same sample and with the same volume. Nothing moves when the flux was
/// made on this network (the rivers and coasts cut only its land, and the slopes carry only
/// into its sea).
fn match_coast(ocean: &[bool], area_km2: &[f64], flux: &mut SurfaceFlux) {
    let n = ocean.len();
    if flux.eroded_km.len() != n || flux.to_ocean_km3.len() != n || area_km2.len() != n {
        return;
    }
    flux.eroded_km
        .par_iter_mut()
        .zip(flux.to_ocean_km3.par_iter_mut())
        .enumerate()
        .with_min_len(8192)
        .for_each(|(i, (e, v))| {
            if ocean[i] {
                if *e > 0.0 {
                    *v += *e as f64 * area_km2[i];
                    *e = 0.0;
                }
            } else if *v > 0.0 {
                *e += (*v / area_km2[i].max(1e-12)) as f32;
                *v = 0.0;
            }
        });
}

/// Pelagic rain (phenomenon `sediment`) on the steps without a routing of their own (the
/// routing lays it on the others), on the last network's sea mask: see [`PelagicRain`]. It comes
/// from the sea, not the land, so it is counted apart from the eroded–deposited balance
/// ([`SurfaceFlux::pelagic_km3`]).
pub fn lay_pelagic(
    params: Res<Params>,
    mesh: Res<SphereMesh>,
    mut crust: ResMut<Crust>,
    mut state: ResMut<ReliefState>,
    network: Res<DrainageNetwork>,
    mut flux: ResMut<SurfaceFlux>,
    mut gpu: Option<ResMut<GpuContext>>,
) {
    flux.pelagic_km3 = 0.0;
    if !network.built || network.drainage.ocean.len() != crust.len() {
        return;
    }
    let reads = FieldMask(FieldMask::ELEVATION.0 | FieldMask::AGE.0);
    let Some(declared) = before_write(&mut crust, &mut gpu, reads, FieldMask::THICKNESS) else {
        return;
    };
    flux.pelagic_km3 = pelagic_rain(&params, &mesh, &mut crust, &mut state, &network);
    after_write(&crust, &mut gpu, FieldMask::THICKNESS, declared);
}

/// One step of pelagic rain on `crust` (see [`PelagicRain`]), km³.
fn pelagic_rain(
    params: &Params,
    mesh: &SphereMesh,
    crust: &mut Crust,
    state: &mut ReliefState,
    network: &DrainageNetwork,
) -> f64 {
    let n = crust.len();
    let Some(g) = state.graph.as_ref() else {
        return 0.0;
    };
    if network.drainage.ocean.len() != n
        || state.oceanic.len() != n
        || g.len() != n
        || mesh.len() != n
    {
        return 0.0;
    }
    let rain = PelagicRain::of(params);
    let rate = state.pelagic.ensure(mesh, params);
    let Crust {
        thickness_km,
        elevation_km,
        age_my,
        ..
    } = crust;
    rain.lay(
        thickness_km,
        elevation_km,
        age_my,
        &state.oceanic,
        &network.drainage.ocean,
        &g.area_km2,
        rate,
    )
}

/// Pelagic rain (plankton shells, dust) over one step: a layer `layer_km` thick on every
/// sample of oceanic crust at sea ([`Drainage::ocean`](drainage::Drainage::ocean)) younger than
/// `max_age_my` and deeper than `min_depth_km` (above the wave base the waves keep the fine rain
/// in suspension and carry it off: floor filled to sea level would otherwise be raised while at
/// sea and lowered by its age once dry, and flicker across sea level step after step). With a
/// carbonate compensation depth `ccd_km`, the shells dissolve in deep water: the layer falls
/// linearly over the [`PelagicRain::LYSOCLINE_KM`] above the CCD to `clay_km`, laid below it.
/// Floor that sinks past the CCD as it ages then keeps sinking, as on Earth, where the old
/// abyssal plains lie at 5–6 km, instead of being held near one depth by a rain that keeps
/// pace with its subsidence.
#[derive(Clone, Copy, Debug)]
pub struct PelagicRain {
    /// Thickness laid per step above the lysocline (or everywhere without a CCD), km.
    pub layer_km: f64,
    /// Oldest floor that gets it, My.
    pub max_age_my: f32,
    /// Shallowest water that gets it, km (positive).
    pub min_depth_km: f64,
    /// Carbonate compensation depth, km (positive; 0: none, the full layer at every depth).
    pub ccd_km: f64,
    /// Thickness laid per step below the CCD, km.
    pub clay_km: f64,
    /// Youngest floor the rate field of [`Self::lay`] applies to, My (younger floor gets the
    /// mean rain).
    pub varies_from_age_my: f32,
}

impl PelagicRain {
    /// Depth range over which the shells dissolve, from the lysocline down to the CCD, km.
    pub const LYSOCLINE_KM: f64 = 1.0;

    /// The rain of one step under `params` (`sediment.pelagic_*`).
    pub fn of(params: &Params) -> Self {
        let s = &params.sediment;
        let dt = params.time.time_step_my;
        Self {
            layer_km: s.pelagic_rate_m_per_my * 1e-3 * dt,
            max_age_my: s.pelagic_max_age_my as f32,
            min_depth_km: s.pelagic_min_depth_m * 1e-3,
            ccd_km: s.pelagic_ccd_m * 1e-3,
            clay_km: s.pelagic_clay_rate_m_per_my * 1e-3 * dt,
            varies_from_age_my: s.pelagic_variability_from_age_my as f32,
        }
    }

    /// The layer laid in one step on floor `depth_km` below sea level (positive), km.
    #[inline]
    pub fn layer_at(&self, depth_km: f64) -> f64 {
        if !(self.ccd_km > 0.0) {
            return self.layer_km;
        }
        let f = ((self.ccd_km - depth_km) / Self::LYSOCLINE_KM).clamp(0.0, 1.0);
        self.clay_km + (self.layer_km - self.clay_km) * f
    }

    /// Adds the layer to `thickness_km` where it settles (see [`PelagicRain`]), times `rate[i]`
    /// where `rate` is not empty and the floor is at least [`Self::varies_from_age_my`] old (a
    /// rain that varies from place to place, see [`pelagic_rate_field`]), and returns its
    /// volume, km³. One pass: each fixed chunk adds its rain and sums its volume, the chunks are
    /// summed in order (the same sum whatever the thread count).
    #[allow(clippy::too_many_arguments)]
    pub fn lay(
        &self,
        thickness_km: &mut [f32],
        elevation_km: &[f32],
        age_my: &[f32],
        oceanic: &[bool],
        ocean: &[bool],
        area_km2: &[f64],
        rate: &[f32],
    ) -> f64 {
        if !(self.layer_km > 0.0 || (self.ccd_km > 0.0 && self.clay_km > 0.0)) {
            return 0.0;
        }
        let top = -self.min_depth_km;
        let settles = |i: usize| {
            oceanic.get(i).copied().unwrap_or(false)
                && ocean.get(i).copied().unwrap_or(false)
                && age_my.get(i).is_some_and(|&a| a < self.max_age_my)
                && elevation_km.get(i).is_some_and(|&z| f64::from(z) < top)
        };
        const CH: usize = 8192;
        thickness_km
            .par_chunks_mut(CH)
            .enumerate()
            .map(|(c, ts)| {
                let mut sum = 0.0f64;
                for (k, t) in ts.iter_mut().enumerate() {
                    let i = c * CH + k;
                    if settles(i) {
                        let mut layer = self.layer_at(-f64::from(elevation_km[i]));
                        if let Some(&r) = rate.get(i)
                            && age_my[i] >= self.varies_from_age_my
                        {
                            layer *= f64::from(r);
                        }
                        *t += layer as f32;
                        sum += layer * area_km2.get(i).copied().unwrap_or(0.0);
                    }
                }
                sum
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum()
    }
}

/// Sample `i`'s distance to its subduction front at the last resampling less the convergence
/// since, km (negative once it went under the overriding plate); `None` for a sample that is not
/// oceanic crust coming to a front point with a trench ([`FrontPoints::trench`]).
fn to_front_km(field: &ConvergenceField, fp: &FrontPoints, oceanic: bool, i: usize) -> Option<f32> {
    let sp = *field.subducting_point.get(i)?;
    if sp == NONE || !oceanic || !fp.trench.get(sp as usize).copied().unwrap_or(false) {
        return None;
    }
    Some(field.subducting_distance_km[i] - fp.converged_km[sp as usize])
}

/// The passages of [`SedimentRouter::passages_mut`]: a sample of subducting ocean floor more
/// than the trench's width past its front has gone under the overriding plate since the last
/// resampling, which will remove it. It passes what reaches it to its neighbour nearest the
/// front, until the floor that still shows (the trench, or the floor in front of it). Without
/// this, the reference graph, whose edges still join the overriding margin to the floor it was
/// beside at the last resampling, sends a margin's sediment onto floor under the margin, and
/// the resampling then discards it: a sixth of the deposit on the default planet, a quarter
/// with collisions in place (a resampling every 10 steps or more).
///
/// A passage does not ask whether the sample lies beside the stretch of front its point stands
/// for: oblique convergence carries floor sideways by hundreds of km before it is removed, and
/// with that test three quarters of the loss remained.
fn subducted_passages(
    mesh: &SphereMesh,
    g: &ReliefGraph,
    crust: &Crust,
    fp: &FrontPoints,
    field: &ConvergenceField,
    width_km: f64,
    through: &mut Vec<u32>,
) {
    let n = mesh.len();
    if field.subducting_point.len() != n || fp.is_empty() || crust.plate.len() < n {
        through.clear();
        return;
    }
    through.resize(n, sediment::NO_PASSAGE);
    let oceanic = |i: usize| crust.crust_type[i] == CrustType::Oceanic;
    let d_of = |i: usize| to_front_km(field, fp, oceanic(i), i);
    through
        .par_iter_mut()
        .enumerate()
        .with_min_len(8192)
        .for_each(|(i, t)| {
            *t = sediment::NO_PASSAGE;
            let Some(di) = d_of(i) else { return };
            if (di as f64) >= -width_km {
                return;
            }
            let mut best = di;
            for &j in g.neighbors_of(i) {
                if let Some(dj) = d_of(j as usize)
                    && dj > best
                {
                    best = dj;
                    *t = j;
                }
            }
        });
}

/// Work areas of [`trench_candidates`], kept between steps.
#[derive(Default)]
struct TrenchScratch {
    /// Per sample: the front point whose neighbourhood it is in (`NONE` if none).
    point: Vec<u32>,
    /// The searches' marks and queues, one per worker thread (the first for a serial run).
    searches: Vec<Mutex<PlateSearch>>,
    /// The converging points: (subducting plate, sample, point), sorted.
    order: Vec<(u32, u32, u32)>,
    /// Per entry of `order`: the point in its subducting plate's frame and the vertex nearest
    /// it there (`None` when a plate is gone).
    seeds: Vec<Option<(glam::DVec3, u32)>>,
    /// The subducting plates' runs of `order`, and what each plate's search marked.
    plates: Vec<(usize, usize)>,
    marked: Vec<Vec<(u32, u32)>>,
}

/// The work area of one plate's search in [`trench_candidates`].
#[derive(Default)]
struct PlateSearch {
    /// Per mesh vertex: the search that last reached it.
    stamp: Vec<u32>,
    search: u32,
    /// (vertex, the index in `order` of the point whose search reached it).
    queue: Vec<(u32, u32)>,
}

impl PlateSearch {
    /// The breadth-first search of one subducting plate `sub` from its points
    /// `order[from..to]` (see [`trench_candidates`]): calls `mark(j, k)` for each sample `j` of
    /// the plate it reaches, in the order reached, with the point `k` whose search got there
    /// first. It reads and writes only its own marks, so plates can be searched side by side.
    #[allow(clippy::too_many_arguments)]
    fn run(
        &mut self,
        mesh: &SphereMesh,
        plate: &[u32],
        order: &[(u32, u32, u32)],
        seeds: &[Option<(glam::DVec3, u32)>],
        (from, to): (usize, usize),
        cos_r: f64,
        mut mark: impl FnMut(u32, u32),
    ) {
        let n = mesh.len();
        let sub = order[from].0;
        self.stamp.resize(n, 0);
        self.search = self.search.wrapping_add(1);
        if self.search == 0 {
            self.stamp.fill(0);
            self.search = 1;
        }
        let now = self.search;
        let pos = &mesh.positions;
        self.queue.clear();
        for (idx, seed) in seeds.iter().enumerate().take(to).skip(from) {
            if let Some((_, v)) = *seed
                && self.stamp[v as usize] != now
            {
                self.stamp[v as usize] = now;
                self.queue.push((v, idx as u32));
            }
        }
        let mut head = 0;
        while head < self.queue.len() {
            let (j, src) = self.queue[head];
            head += 1;
            // Only points with a seed are queued.
            let Some((c, _)) = seeds[src as usize] else {
                continue;
            };
            if plate[j as usize] == sub {
                mark(j, order[src as usize].2);
            }
            for &nb in mesh.neighbors_of(j as usize) {
                if self.stamp[nb as usize] != now && pos[nb as usize].dot(c) >= cos_r {
                    self.stamp[nb as usize] = now;
                    self.queue.push((nb, src));
                }
            }
        }
    }
}

/// Marks the samples that may lie in a trench: those of a subducting plate within `radius`
/// (radians) of a point of a front its plate goes under where the plates converge faster than
/// `min_speed` (km/My), all positions taken in the subducting plate's frame as it stands now.
/// Breadth first over the mesh from every such point of one plate at once (the points by plate,
/// then by sample); a sample keeps the point whose search reached it first (`scratch.point`).
/// The points are placed in parallel, and the plates searched side by side, each on marks of
/// its own thread (one after the other with `serial`): a plate's search marks only its own
/// samples, in its own fixed order, so the marks are the same whatever the thread count.
#[allow(clippy::too_many_arguments)]
fn trench_candidates(
    mesh: &SphereMesh,
    table: &PlateTable,
    fp: &FrontPoints,
    plate: &[u32],
    radius: f64,
    min_speed: f64,
    serial: bool,
    scratch: &mut TrenchScratch,
) {
    let n = mesh.len();
    let sc = scratch;
    sc.point.clear();
    sc.point.resize(n, NONE);
    sc.order.clear();
    sc.order.extend((0..fp.len()).filter_map(|k| {
        let fast = f64::from(fp.convergence_km_per_my.get(k).copied().unwrap_or(0.0)) > min_speed;
        fast.then_some((fp.subducting[k], fp.sample[k], k as u32))
    }));
    sc.order.sort_unstable();
    let pos = &mesh.positions;
    // Each point in its subducting plate's frame, and the vertex nearest it there (located on
    // their own: the walks' reads miss the cache, about 2 µs a point).
    sc.seeds.clear();
    let place = |&(sub, sample, k): &(u32, u32, u32)| {
        let (s, o) = (table.get(sub)?, table.get(fp.overriding[k as usize])?);
        let p = s.plate_from_world * (o.world_from_plate * pos[sample as usize]);
        // The tracking located the same point this step: walking from there is the locator's
        // search without the search (the same vertex; a stale hint only walks further).
        let v = match fp.near_vertex.get(k as usize) {
            Some(&h) if (h as usize) < n => mesh.nearest_vertex_from(h, p),
            _ => mesh.nearest_vertex(p),
        };
        Some((p, v))
    };
    // (Serial without rayon at all: off the pool, a parallel loop would run on another pool.)
    if serial {
        sc.seeds.extend(sc.order.iter().map(place));
    } else {
        sc.order
            .par_iter()
            .with_min_len(256)
            .map(place)
            .collect_into_vec(&mut sc.seeds);
    }
    let cos_r = radius.cos();
    sc.plates.clear();
    let mut from = 0;
    while from < sc.order.len() {
        let sub = sc.order[from].0;
        let to = from + sc.order[from..].partition_point(|&(p, _, _)| p == sub);
        sc.plates.push((from, to));
        from = to;
    }
    let threads = if serial {
        1
    } else {
        rayon::current_num_threads().max(1)
    };
    if sc.searches.len() < threads {
        sc.searches.resize_with(threads, Default::default);
    }
    let (order, seeds, point) = (&sc.order, &sc.seeds, &mut sc.point);
    if threads == 1 {
        let search = sc.searches[0].get_mut().unwrap_or_else(|e| e.into_inner());
        for &run in &sc.plates {
            search.run(mesh, plate, order, seeds, run, cos_r, |j, k| {
                point[j as usize] = k;
            });
        }
        return;
    }
    // The plates with the most points first, each a task of its own, on the marks of the
    // thread that takes it.
    sc.plates
        .sort_by_key(|&(a, b)| (std::cmp::Reverse(b - a), a));
    let searches = &sc.searches;
    sc.plates
        .par_iter()
        .with_max_len(1)
        .map(|&run| {
            let at = rayon::current_thread_index().unwrap_or(0) % searches.len();
            let mut search = searches[at].lock().unwrap_or_else(|e| e.into_inner());
            let mut marked = Vec::new();
            search.run(mesh, plate, order, seeds, run, cos_r, |j, k| {
                marked.push((j, k));
            });
            marked
        })
        .collect_into_vec(&mut sc.marked);
    for marked in &sc.marked {
        for &(j, k) in marked {
            point[j as usize] = k;
        }
    }
}

/// Where a subducting sample stands against the plate that overrides it, measured along its path
/// ([`TrenchPath::distance_rad`]).
struct TrenchPath<'a> {
    mesh: &'a SphereMesh,
    /// Plate of each sample.
    plate: &'a [u32],
    /// The overriding plate, and the rotation from the world into its frame.
    over: u32,
    over_from_world: glam::DMat3,
}

impl TrenchPath<'_> {
    /// The vertex nearest world point `p` in the overriding plate's frame (walking from `from`,
    /// [`SphereMesh::nearest_vertex_from`]), and whether the overriding plate covers `p` (that
    /// vertex is one of its samples).
    fn probe(&self, p: glam::DVec3, from: u32) -> (u32, bool) {
        let v = self
            .mesh
            .nearest_vertex_from(from, self.over_from_world * p);
        (v, self.plate.get(v as usize) == Some(&self.over))
    }

    /// Signed distance (radians) from world point `q` to the edge of the overriding plate along
    /// the great circle through `q` in the direction `dir` (unit, tangent at `q`: the floor's
    /// motion relative to the overriding plate): positive while the floor has yet to reach the
    /// edge, negative once it went under; `None` when the edge is not within `reach` either way
    /// (the floor slides past the plate, moves away from it, or is far from or deep under it).
    /// The edge is the plate's footprint: where the nearest sample, in its frame, turns its own
    /// (the boundary between its samples and the rest lies halfway between them).
    /// `start` is a mesh vertex near `q` in that frame, where the walks begin.
    fn distance_rad(
        &self,
        q: glam::DVec3,
        dir: glam::DVec3,
        start: u32,
        reach: f64,
        tol: f64,
    ) -> Option<f64> {
        let at = |s: f64| q * s.cos() + dir * s.sin();
        let (v0, in0) = self.probe(q, start);
        // Forward while outside, backward (along the way it came) once under the plate.
        let sign = if in0 { -1.0 } else { 1.0 };
        let (v1, in1) = self.probe(at(sign * reach), v0);
        if in1 == in0 {
            return None;
        }
        let (mut lo, mut hi, mut vlo, mut vhi) = (0.0f64, reach, v0, v1);
        while hi - lo > tol {
            let mid = 0.5 * (lo + hi);
            let (vm, im) = self.probe(at(sign * mid), vlo);
            if im == in0 {
                (lo, vlo) = (mid, vm);
            } else {
                (hi, vhi) = (mid, vm);
            }
        }
        // Where the path crosses the bisector of the last two vertices (in the overriding
        // plate's frame): p(s)·(a − b) = 0 for p(s) = q·cos s + d·sin s.
        let (a, b) = (
            self.mesh.positions[vlo as usize],
            self.mesh.positions[vhi as usize],
        );
        let ab = a - b;
        let (qq, dd) = (
            self.over_from_world * q,
            self.over_from_world * (dir * sign),
        );
        let (ca, cb) = (qq.dot(ab), dd.dot(ab));
        let s = if cb.abs() > 1e-15 {
            (-ca / cb).atan().clamp(lo, hi)
        } else {
            0.5 * (lo + hi)
        };
        Some(sign * s)
    }
}

/// The trench's constants (from [`Params`]).
#[derive(Clone, Copy, Debug, PartialEq)]
struct TrenchConsts {
    depth_km: f64,
    width_km: f64,
    min_speed: f64,
}

impl TrenchConsts {
    fn of(params: &Params) -> Self {
        Self {
            depth_km: params.isostasy.trench_depth_km,
            width_km: params.isostasy.trench_width_km,
            min_speed: params.subduction.min_convergence_mm_per_yr,
        }
    }
}

/// Trench depth per sample into `trench_km` (km below the floor beside it; 0 away from fronts),
/// from where the floor now stands against the plate that overrides it ([`TrenchPath`]): the
/// distance, along the floor's motion relative to that plate, to the edge of the plate's
/// footprint (ahead of floor yet to go under, behind floor gone under), for the floor near a
/// converging point of a front its plate goes under ([`trench_candidates`]). Cut where the
/// distance at the last resampling less the convergence since put the floor, the trench lagged
/// the floor as an interval aged and thinned into dashes (docs/relief.md). Floor that slides
/// past a plate, on a small plate's flanks or along a front, never reaches the edge along its
/// path and gets no trench, so a small plate is not ringed. With `serial`, one thread's work
/// (on the thread [`begin_trench`] starts), else in parallel loops; the depths are the same.
#[allow(clippy::too_many_arguments)]
fn trench_depths(
    mesh: &SphereMesh,
    table: &PlateTable,
    fp: &FrontPoints,
    plate: &[u32],
    crust_type: &[CrustType],
    c: TrenchConsts,
    serial: bool,
    scratch: &mut TrenchScratch,
    trench_km: &mut Vec<f32>,
) {
    let n = mesh.len();
    trench_km.clear();
    trench_km.resize(n, 0.0);
    if fp.is_empty() || plate.len() < n || crust_type.len() < n {
        return;
    }
    let (depth, width, min_speed) = (c.depth_km, c.width_km, c.min_speed);
    let r_km = mesh.radius_km;
    let spacing = mesh.mean_spacing_rad() * r_km;
    let positions = &mesh.positions;
    let (reach, tol) = ((width + spacing) / r_km, 0.5 * spacing / r_km);
    // The trench reaches a quarter spacing past its width along the path; the edge stands
    // within about half a spacing of the nearest front point (an overriding sample at the
    // boundary).
    let radius = (width + spacing) / r_km;
    trench_candidates(mesh, table, fp, plate, radius, min_speed, serial, scratch);
    let near = &scratch.point;
    let cut = |(i, t): (usize, &mut f32)| {
        let k = near[i];
        if k == NONE || crust_type[i] != CrustType::Oceanic {
            return;
        }
        let k = k as usize;
        let (Some(s), Some(o)) = (table.get(plate[i]), table.get(fp.overriding[k])) else {
            return;
        };
        let q = s.world_from_plate * positions[i];
        let v = s.motion.velocity_km_per_my(q, r_km) - o.motion.velocity_km_per_my(q, r_km);
        let speed = v.length();
        if !(speed > min_speed) {
            return;
        }
        let path = TrenchPath {
            mesh,
            plate,
            over: o.id,
            over_from_world: o.plate_from_world,
        };
        if let Some(d) = path.distance_rad(q, v / speed, fp.sample[k], reach, tol) {
            let depth_here = trench_depth_on_mesh_km(d * r_km, depth, width, spacing);
            if depth_here > 0.0 {
                *t = depth_here as f32;
            }
        }
    };
    if serial {
        trench_km.iter_mut().enumerate().for_each(cut);
    } else {
        trench_km
            .par_iter_mut()
            .enumerate()
            .with_min_len(4096)
            .for_each(cut);
    }
}

/// What the trench's thread hands back: the depths, its scratch, and the copies it read.
struct TrenchDone {
    trench_km: Vec<f32>,
    scratch: TrenchScratch,
    table: PlateTable,
    plate: Vec<u32>,
    crust_type: Vec<CrustType>,
}

/// The trench computed on a thread of its own beside the sediment ([`begin_trench`]), taken by
/// the isostasy ([`take_trench`]). While it runs, [`ReliefState::trench_km`] is empty (the
/// thread holds the buffer).
struct TrenchTask {
    rx: Mutex<Receiver<std::thread::Result<TrenchDone>>>,
    /// [`FrontPoints`]' last change when the task started.
    fronts_tick: bevy_ecs::change_detection::Tick,
    consts: TrenchConsts,
}

/// Waits for what `rx` will hand over. On a thread of the pool (a simulation run inside
/// `ThreadPool::install`) it runs the pool's pending tasks while it waits, so a pool of one
/// thread does not wait on itself. `None` if the sender went away.
fn wait_for<T>(rx: Mutex<Receiver<T>>) -> Option<T> {
    let rx = rx.into_inner().unwrap_or_else(|e| e.into_inner());
    if rayon::current_thread_index().is_some() {
        loop {
            match rx.try_recv() {
                Ok(r) => return Some(r),
                Err(TryRecvError::Disconnected) => return None,
                Err(TryRecvError::Empty) => {
                    if rayon::yield_now() != Some(rayon::Yield::Executed) {
                        std::thread::yield_now();
                    }
                }
            }
        }
    } else {
        rx.recv().ok()
    }
}

/// Starts the trench of this step (`trench_depths`) on a thread of its own, on copies of what
/// it reads (the plate and crust type of each sample, the plates, the front points; the mesh is
/// shared), so that it runs beside the sediment, which leaves those alone; [`apply_isostasy`]
/// takes it, or computes the trench itself when any of them changed since. The depths are the
/// same either way, whatever the thread count. With one worker thread asked for
/// (`--threads 1`), it starts nothing.
pub fn begin_trench(
    params: Res<Params>,
    mesh: Res<SphereMesh>,
    crust: Res<Crust>,
    mut state: ResMut<ReliefState>,
    fp: Res<FrontPoints>,
    plates: Query<(&Plate, &PlateMotion, &PlateFrame, &PlateBounds, &PlateStats)>,
) {
    let n = mesh.len();
    let state = &mut *state;
    // A thread left from a step whose isostasy did not run: its buffers come back first.
    if let Some(task) = state.trench_task.take()
        && let Some(done) = wait_for(task.rx)
    {
        keep_trench_buffers(state, done.unwrap_or_else(|p| std::panic::resume_unwind(p)));
    }
    // With one worker thread asked for, no second thread: the isostasy computes the trench.
    if fp.is_empty()
        || crust.plate.len() < n
        || crust.crust_type.len() < n
        || rayon::current_num_threads() < 2
    {
        return;
    }
    let mut plate = std::mem::take(&mut state.trench_plate);
    plate.clear();
    plate.extend_from_slice(&crust.plate[..n]);
    let mut crust_type = std::mem::take(&mut state.trench_types);
    crust_type.clear();
    crust_type.extend_from_slice(&crust.crust_type[..n]);
    let table = PlateTable::from_query(&plates);
    let fronts = fp.clone();
    let mesh = mesh.clone();
    let mut scratch = std::mem::take(&mut state.trench_scratch);
    let mut trench_km = std::mem::take(&mut state.trench_km);
    let consts = TrenchConsts::of(&params);
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    let job = move || {
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || {
            trench_depths(
                &mesh,
                &table,
                &fronts,
                &plate,
                &crust_type,
                consts,
                true,
                &mut scratch,
                &mut trench_km,
            );
            TrenchDone {
                trench_km,
                scratch,
                table,
                plate,
                crust_type,
            }
        }));
        let _ = tx.send(result);
    };
    // A thread of its own, not a task of the pool: a pool thread waiting in a parallel loop of
    // the sediment would take the task and run it there (measured: the sediment then took
    // about 10 ms more a step at 500k). If none starts, the isostasy computes the trench.
    if std::thread::Builder::new()
        .name("trench".into())
        .spawn(job)
        .is_err()
    {
        return;
    }
    state.trench_task = Some(TrenchTask {
        rx: Mutex::new(rx),
        fronts_tick: fp.last_changed(),
        consts,
    });
}

/// Puts a finished task's buffers back into `state` (its depths as the buffer for the next).
fn keep_trench_buffers(state: &mut ReliefState, done: TrenchDone) {
    state.trench_km = done.trench_km;
    state.trench_scratch = done.scratch;
    state.trench_plate = done.plate;
    state.trench_types = done.crust_type;
}

/// Takes the trench whose thread [`begin_trench`] started, if any: true, with its depths in
/// `state.trench_km`, when it read what the isostasy would read now (the same front points,
/// plates, plate and crust type of every sample, and constants); false otherwise (the caller
/// computes the trench). A panic in the task goes on here.
fn take_trench(
    state: &mut ReliefState,
    fp: &Res<FrontPoints>,
    table: &PlateTable,
    host: &Crust,
    consts: TrenchConsts,
    n: usize,
) -> bool {
    let Some(task) = state.trench_task.take() else {
        return false;
    };
    let Some(result) = wait_for(task.rx) else {
        return false;
    };
    let done = result.unwrap_or_else(|p| std::panic::resume_unwind(p));
    let current = task.fronts_tick == fp.last_changed()
        && task.consts == consts
        && done.table.plates == table.plates
        && done.trench_km.len() == n
        && host.plate.get(..n) == Some(&done.plate[..])
        && host.crust_type.get(..n) == Some(&done.crust_type[..]);
    keep_trench_buffers(state, done);
    current
}

/// Trench depth (km below the floor beside it) of a subducting ocean sample whose distance to
/// its front is `d_km` (negative once it passed under): `depth·(1 − |d|/w)²` within `w` of the
/// front, deepest at the front. Past the front the sample lies under the overriding plate; the
/// profile falls off the same way, so floor that went far under (and still shows where the
/// overriding plate does not cover it) is not kept at the trench's depth.
pub fn trench_profile_km(d_km: f64, depth_km: f64, width_km: f64) -> f64 {
    let x = 1.0 - d_km.abs() / width_km.max(1e-9);
    if x <= 0.0 { 0.0 } else { depth_km * x * x }
}

/// [`trench_profile_km`] on a mesh of mean spacing `spacing_km`: full depth within a quarter
/// spacing of the front, so that a trench narrower than a sample still shows at the samples next
/// to the front (at 100,000 samples the nearest one can lie 35 km from it).
pub fn trench_depth_on_mesh_km(d_km: f64, depth_km: f64, width_km: f64, spacing_km: f64) -> f64 {
    let d = (d_km.abs() - 0.25 * spacing_km).max(0.0);
    trench_profile_km(d, depth_km, width_km)
}

/// The elevation of every sample from the crust (phenomenon `isostasy`): continents by regional
/// Airy isostasy from their thickness, ocean floor by its age, its load and the flexure of
/// neighbouring continents, and a trench in front of each active subduction front.
///
/// The smoothed root (the regional response) and the trench depths are computed on the host; the
/// per-sample combine ([`isostasy_cpu`]) runs on the device on the GPU backend
/// (`shaders/isostasy.wgsl`), which then leaves the elevation there, marked newer, and reads
/// nothing back.
#[allow(clippy::too_many_arguments)]
pub fn apply_isostasy(
    params: Res<Params>,
    mesh: Res<SphereMesh>,
    mut crust: ResMut<Crust>,
    mut state: ResMut<ReliefState>,
    fp: Res<FrontPoints>,
    plates: Query<(&Plate, &PlateMotion, &PlateFrame, &PlateBounds, &PlateStats)>,
    mut gpu: Option<ResMut<GpuContext>>,
) {
    // On the GPU backend the host reads only the thickness (for the smoothed root) and crust
    // type (never written on the device); age stays on the device, and the host copy is not
    // written.
    let on_device = gpu.as_ref().is_some_and(|g| g.failure.is_none());
    let declared = if on_device {
        if !pull(&mut crust, &mut gpu, FieldMask::THICKNESS) {
            return;
        }
        false
    } else {
        let reads = FieldMask(FieldMask::THICKNESS.0 | FieldMask::AGE.0);
        match before_write(&mut crust, &mut gpu, reads, FieldMask::ELEVATION) {
            Some(declared) => declared,
            None => return,
        }
    };
    let n = mesh.len();
    let state = &mut *state;
    let iso = isostasy_params(&params);
    let ip = &params.isostasy;
    if ensure_graph(&mut state.graph, &mesh) {
        state.iso_key = None;
    }
    // (A handle of its own: the trench below takes `state` whole.)
    let Some(graph) = state.graph.clone() else {
        return;
    };
    let g = &*graph;
    // The regional levels depend on the mesh and on T_e (through σ).
    let key = (n, iso.regional_sigma_km().to_bits());
    if state.iso_key != Some(key) {
        state.iso = RegionalIsostasy::with_coarse_level(&mesh.positions, g, &iso);
        state.iso_key = Some(key);
    }
    let law = AgeDepthLaw::of(&params);
    let offset = ip.ridge_depth_offset_km;
    if state
        .table
        .as_ref()
        .is_none_or(|(ps, o, _)| *ps != ip.parsons_sclater || *o != offset.to_bits())
    {
        state.table = Some((
            ip.parsons_sclater,
            offset.to_bits(),
            AgeDepthTable::new(law, offset),
        ));
    }
    let host: &Crust = &crust;
    state.oceanic.clear();
    state
        .oceanic
        .extend(host.crust_type.iter().map(|&t| t == CrustType::Oceanic));
    state.continental.clear();
    state.continental.extend(state.oceanic.iter().map(|&o| !o));
    if host.thickness_km.len() >= n && host.elevation_km.len() >= n {
        state
            .iso
            .smooth_root(g, &host.thickness_km, &state.continental, &iso);
    }
    // The trench (see [`trench_depths`]): from the task [`begin_trench`] started beside the
    // surface processes when what it read still holds, computed here otherwise.
    let table = PlateTable::from_query(&plates);
    let tc = TrenchConsts::of(&params);
    if !take_trench(state, &fp, &table, host, tc, n) {
        trench_depths(
            &mesh,
            &table,
            &fp,
            &host.plate,
            &host.crust_type,
            tc,
            false,
            &mut state.trench_scratch,
            &mut state.trench_km,
        );
    }
    let Some((_, _, table)) = state.table.as_ref() else {
        return;
    };
    let mut c = iso.constants(params.init.oceanic_thickness_km);
    c.max_oceanic_load_km =
        params.isostasy.max_oceanic_thickness_km - params.init.oceanic_thickness_km;
    c.max_continental_km = params.isostasy.max_thickness_km;
    let w = state.iso.deflection_km();
    if on_device && let Some(ctx) = gpu.as_mut() {
        let tick = crust.last_changed();
        let done = run_or_record(ctx, |ctx| {
            let host = crust.bypass_change_detection();
            if !ctx.can_declare_host_write(FieldMask::NONE, host.len(), tick) {
                // A CPU system wrote the crust undeclared: the device takes the whole crust.
                ctx.pull(host, FieldMask::ALL)?;
            }
            ctx.sync_crust(host, Some(tick))?;
            isostasy_dispatch(ctx, &c, &table.samples(), w, &state.trench_km)?;
            // The host copy is pulled lazily, by the next CPU reader (the drainage).
            ctx.note_device_write(crate::gpu::isostasy::WRITES, host)
        });
        if done {
            // The sea level needs the whole surface: the elevation comes down, moves on the
            // host, and goes up again (4 bytes a sample each way; only with a water volume).
            if ip.ocean_volume_layer_km > 0.0
                && let Some(declared) = before_write(
                    &mut crust,
                    &mut gpu,
                    FieldMask::ELEVATION,
                    FieldMask::ELEVATION,
                )
            {
                if let Some(s) = settle_sea_level(ip, &c, g, &mut crust) {
                    state.sea_level_km = s;
                }
                after_write(&crust, &mut gpu, FieldMask::ELEVATION, declared);
            }
            return;
        }
        // The device failed (the step stops with the error): the host's combine instead, on
        // the age as of its last pull.
    }
    let host = &mut *crust;
    isostasy_cpu(
        &c,
        table,
        &host.crust_type,
        &host.thickness_km,
        &host.age_my,
        w,
        &state.trench_km,
        &mut host.elevation_km,
    );
    if let Some(s) = settle_sea_level(ip, &c, g, host) {
        state.sea_level_km = s;
    }
    after_write(&crust, &mut gpu, FieldMask::ELEVATION, declared);
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn mesh() -> SphereMesh {
        SphereMesh::fibonacci(20_000, 0.5, 3, 6370.0).expect("mesh")
    }

    /// 28 m a step on floor younger than 300 My and deeper than 50 m, no CCD, the same rate at
    /// every age: the pelagic rain of the tests below, each changing what it tests.
    const TEST_RAIN: PelagicRain = PelagicRain {
        layer_km: 0.028,
        max_age_my: 300.0,
        min_depth_km: 0.05,
        ccd_km: 0.0,
        clay_km: 0.0,
        varies_from_age_my: 0.0,
    };

    /// Pelagic rain settles on oceanic crust at sea, young enough, and below the wave base only:
    /// five samples, each failing one condition but the first and the last. Seen to fail with
    /// the depth condition left out (the shallow sample got its layer).
    #[test]
    fn pelagic_rain_settles_below_the_wave_base_only() {
        let rain = TEST_RAIN;
        // deep and young; shallow (20 m); old; continental crust; a lake (not the sea); deep again
        let elevation = [-4.0f32, -0.02, -5.0, -0.5, -0.3, -0.051];
        let age = [50.0f32, 50.0, 400.0, 50.0, 50.0, 10.0];
        let oceanic = [true, true, true, false, true, true];
        let ocean = [true, true, true, true, false, true];
        let area = [100.0; 6];
        let mut thickness = [7.0f32; 6];
        let v = rain.lay(
            &mut thickness,
            &elevation,
            &age,
            &oceanic,
            &ocean,
            &area,
            &[],
        );
        let got: Vec<bool> = thickness.iter().map(|&t| t > 7.0).collect();
        assert_eq!(got, [true, false, false, false, false, true]);
        assert!((v - 2.0 * 0.028 * 100.0).abs() < 1e-9, "volume {v}");
        assert!((thickness[0] - 7.028).abs() < 1e-6);
    }

    /// Below the carbonate compensation depth only clay settles; over the kilometre above it the
    /// rain falls linearly from the full layer to the clay's; above the lysocline it is the
    /// full layer; and its volume is what was laid. Seen to fail with the ramp's sign reversed
    /// (the deep floor got the full layer).
    #[test]
    fn pelagic_rain_dissolves_below_the_lysocline() {
        let rain = PelagicRain {
            ccd_km: 4.5,
            clay_km: 0.002,
            ..TEST_RAIN
        };
        // above the lysocline (3.5 km), halfway to the CCD, at the CCD, below it
        let elevation = [-3.0f32, -4.0, -4.5, -6.0];
        let n = elevation.len();
        let (age, oceanic, ocean, area) = (
            vec![50.0f32; n],
            vec![true; n],
            vec![true; n],
            vec![10.0; n],
        );
        let mut thickness = vec![7.0f32; n];
        let v = rain.lay(
            &mut thickness,
            &elevation,
            &age,
            &oceanic,
            &ocean,
            &area,
            &[],
        );
        let laid: Vec<f64> = thickness.iter().map(|&t| f64::from(t) - 7.0).collect();
        let want = [0.028, 0.015, 0.002, 0.002];
        for (k, (&got, &w)) in laid.iter().zip(&want).enumerate() {
            assert!(
                (got - w).abs() < 2e-6,
                "sample {k}: laid {got} km, want {w}"
            );
        }
        let total: f64 = want.iter().map(|w| w * 10.0).sum();
        assert!((v - total).abs() < 1e-9, "volume {v}, want {total}");
        // Without a CCD, the full layer everywhere.
        let flat = PelagicRain {
            ccd_km: 0.0,
            ..rain
        };
        assert_eq!(flat.layer_at(6.0), 0.028);
    }

    /// The rain's rate field has an area-weighted mean of 1 and a log-spread of σ, is smooth at
    /// its wavelength, is the same whatever the thread count, and differs from seed to seed.
    /// Seen to fail with the normalisation to a mean of 1 left out (mean 1.28 at σ 0.7).
    #[test]
    fn pelagic_rate_field_has_mean_one_and_the_spread_asked() {
        let m = mesh();
        let wl = 2000.0 / m.radius_km;
        let sigma = 0.7;
        let f = pelagic_rate_field(&m.positions, &m.area_km2, 9, sigma, wl);
        assert_eq!(f.len(), m.len());
        let total: f64 = m.area_km2.iter().sum();
        let mean = f
            .iter()
            .zip(m.area_km2.iter())
            .map(|(&r, a)| f64::from(r) * a)
            .sum::<f64>()
            / total;
        assert!((mean - 1.0).abs() < 1e-5, "mean {mean}");
        let logs: Vec<f64> = f.iter().map(|&r| f64::from(r).ln()).collect();
        let lm = logs
            .iter()
            .zip(m.area_km2.iter())
            .map(|(x, a)| x * a)
            .sum::<f64>()
            / total;
        let sd = (logs
            .iter()
            .zip(m.area_km2.iter())
            .map(|(x, a)| (x - lm) * (x - lm) * a)
            .sum::<f64>()
            / total)
            .sqrt();
        assert!((sd - sigma).abs() < 1e-4, "spread {sd}");
        // Smooth: next to each other (160 km apart) the log-rate differs by a small part of σ
        // (noise without correlation would differ by about 1.13σ on average).
        let mut diff = 0.0;
        let mut edges = 0usize;
        for i in 0..m.len() {
            for &j in m.neighbors_of(i) {
                diff += (logs[i] - logs[j as usize]).abs();
                edges += 1;
            }
        }
        let mean_diff = diff / edges as f64;
        assert!(mean_diff < 0.4 * sigma, "neighbours differ by {mean_diff}");
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| pelagic_rate_field(&m.positions, &m.area_km2, 9, sigma, wl));
        assert_eq!(f, one);
        let other = pelagic_rate_field(&m.positions, &m.area_km2, 10, sigma, wl);
        assert_ne!(f, other);
        assert!(pelagic_rate_field(&m.positions, &m.area_km2, 9, 0.0, wl).is_empty());
    }

    /// With a rate field the layer laid on each sample is the layer times its rate, and the
    /// volume returned is what was laid; an empty field lays the same rain everywhere; with
    /// `varies_from_age_my`, floor younger than that gets the mean layer. Seen to fail with the
    /// rate ignored, and with the age threshold ignored (sample 0 of 59 My then gets 0.056).
    #[test]
    fn pelagic_rain_follows_the_rate_field() {
        let oceanic = [true; 4];
        let ocean = [true; 4];
        let area = [100.0, 200.0, 50.0, 100.0];
        let rate = [2.0f32, 0.5, 1.0, 3.0];
        // Lays `rain` on four samples 7 km thick and checks the layer on each and the volume
        // returned (the layers times the areas).
        let check = |rain: &PelagicRain, elevation: [f32; 4], age: [f32; 4], want: [f64; 4]| {
            let mut t = [7.0f32; 4];
            let v = rain.lay(&mut t, &elevation, &age, &oceanic, &ocean, &area, &rate);
            for k in 0..4 {
                let laid = f64::from(t[k]) - 7.0;
                assert!(
                    (laid - want[k]).abs() < 1e-6,
                    "from {} My, sample {k} of {} My: {laid} against {}",
                    rain.varies_from_age_my,
                    age[k],
                    want[k]
                );
            }
            let want_v: f64 = (0..4).map(|k| want[k] * area[k]).sum();
            assert!((v - want_v).abs() < 1e-9, "volume {v} against {want_v}");
        };
        let rain = TEST_RAIN;
        let elevation = [-4.0f32, -4.0, -4.0, -0.02];
        check(&rain, elevation, [50.0; 4], [0.056, 0.014, 0.028, 0.0]);
        let mut u = [7.0f32; 4];
        rain.lay(&mut u, &elevation, &[50.0; 4], &oceanic, &ocean, &area, &[]);
        assert_eq!(u[..3], [7.028f32, 7.028, 7.028]);
        // From an age on: floor younger than that gets the mean layer, older floor its rate.
        let from_60 = PelagicRain {
            varies_from_age_my: 60.0,
            ..rain
        };
        check(
            &from_60,
            [-4.0; 4],
            [59.0, 60.0, 120.0, 30.0],
            [0.028, 0.014, 0.028, 0.028],
        );
    }

    /// The trench of a planet with several subducting plates is the same bits computed on one
    /// thread (as on the trench's own thread) and with the plates searched side by side on two
    /// or three. Seen to fail when a plate's search marked samples of another plate.
    #[test]
    fn the_trench_is_the_same_searched_plate_by_plate_in_parallel() {
        use crate::components::{Plate, PlateBounds, PlateFrame, PlateMotion, PlateStats};
        let mut p = Params::default();
        p.planet.samples = 20_000;
        p.planet.seed = 3;
        let mut sim = crate::simulation::Simulation::new(p.clone()).expect("simulation");
        for _ in 0..6 {
            sim.step().expect("step");
        }
        let world = sim.world_mut();
        let table = PlateTable::from_plates(
            world
                .query::<(&Plate, &PlateMotion, &PlateFrame, &PlateBounds, &PlateStats)>()
                .iter(world)
                .map(|(p, m, f, b, s)| (*p, *m, *f, *b, *s)),
        );
        let (mesh, fp, crust) = (
            world.resource::<SphereMesh>(),
            world.resource::<FrontPoints>(),
            world.resource::<Crust>(),
        );
        let c = TrenchConsts::of(&p);
        let subducting: std::collections::BTreeSet<u32> = (0..fp.len())
            .filter(|&k| f64::from(fp.convergence_km_per_my[k]) > c.min_speed)
            .map(|k| fp.subducting[k])
            .collect();
        assert!(subducting.len() >= 3, "subducting plates: {subducting:?}");
        let run = |threads: usize, serial: bool| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            pool.install(|| {
                let mut out = Vec::new();
                trench_depths(
                    mesh,
                    &table,
                    fp,
                    &crust.plate,
                    &crust.crust_type,
                    c,
                    serial,
                    &mut TrenchScratch::default(),
                    &mut out,
                );
                out.iter().map(|d| d.to_bits()).collect::<Vec<u32>>()
            })
        };
        let one = run(1, true);
        assert!(
            one.iter().filter(|&&b| f32::from_bits(b) > 0.0).count() > 50,
            "some trench"
        );
        assert_eq!(one, run(2, false));
        assert_eq!(one, run(3, false));
    }

    /// Plate 0 (the overriding plate) holds the northern hemisphere, plate 1 the rest: floor
    /// south of the equator moving north meets the edge at its latitude's distance (within a
    /// spacing, the footprint's jagged edge), obliquely at that over the cosine; floor under
    /// plate 0 measures back to the edge; floor moving along the edge or away has none.
    #[test]
    fn the_trench_distance_follows_the_floors_path_to_the_plates_edge() {
        let m = mesh();
        let plate: Vec<u32> = m.positions.iter().map(|p| u32::from(p.z <= 0.0)).collect();
        let path = TrenchPath {
            mesh: &m,
            plate: &plate,
            over: 0,
            over_from_world: glam::DMat3::IDENTITY,
        };
        let r = m.radius_km;
        let spacing = m.mean_spacing_rad() * r;
        let (reach, tol) = ((80.0 + spacing) / r, 0.5 * spacing / r);
        let at = |lon: f64, lat_km: f64| {
            let (lon, lat) = (lon.to_radians(), lat_km / r);
            DVec3::new(lat.cos() * lon.cos(), lat.cos() * lon.sin(), lat.sin())
        };
        let north = |q: DVec3| (DVec3::Z - q * q.z).normalize();
        let east = |q: DVec3| DVec3::Z.cross(q).normalize();
        let start = |q: DVec3| m.nearest_vertex(q);
        for lon in (0..360).step_by(15) {
            let lon = lon as f64;
            for lat_km in [-100.0, -60.0, -30.0, 30.0, 60.0] {
                let q = at(lon, lat_km);
                let d = path
                    .distance_rad(q, north(q), start(q), reach, tol)
                    .map(|d| d * r)
                    .unwrap_or_else(|| panic!("no edge from latitude {lat_km} km at {lon}°"));
                assert!(
                    (d + lat_km).abs() < spacing,
                    "at {lon}°, {lat_km} km: {d:.1} km to the edge"
                );
                // 40° off north, the path to the edge is longer by 1/cos 40°.
                let dir = (north(q) * 40f64.to_radians().cos()
                    + east(q) * 40f64.to_radians().sin())
                .normalize();
                if let Some(d2) = path.distance_rad(q, dir, start(q), reach, tol) {
                    let want = -lat_km / 40f64.to_radians().cos();
                    assert!(
                        (d2 * r - want).abs() < 1.5 * spacing,
                        "at {lon}°, {lat_km} km, oblique: {:.1} km, want {want:.1}",
                        d2 * r
                    );
                } else {
                    assert!(
                        lat_km.abs() > 60.0,
                        "no oblique edge from {lat_km} km at {lon}°"
                    );
                }
            }
            // Moving away from the plate, or along its edge three spacings off it: no trench.
            let q = at(lon, -30.0);
            assert_eq!(path.distance_rad(q, -north(q), start(q), reach, tol), None);
            let q = at(lon, -3.0 * spacing);
            assert_eq!(path.distance_rad(q, east(q), start(q), reach, tol), None);
        }
    }
}
