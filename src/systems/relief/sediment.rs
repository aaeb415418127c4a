//! Sediment routing and deposition: everything eroded on land travels down the drainage
//! network, fills lakes on the way (they fill and overflow), and is laid down offshore as a
//! shelf–slope–rise wedge, filling trenches and basins. Volume is conserved exactly: every km³
//! that enters is deposited somewhere in the same call (see [`SedimentBudget`]).
//!
//! Land: fluxes Q_i (km³) accumulate in reverse stack order (upstream first), Q_i = e_i·a_i +
//! Σ Q_donors. A lake sample keeps up to (water level − surface)·a_i / f_i (f_i = surface rise
//! per unit of deposited thickness, 1 before isostasy, ≈ 0.35 on oceanic crust after it) and
//! passes the rest on. An endorheic sink (a dry pit, or a closed lake's low point) fills its
//! basin from the floor: a pond grown over land, lowest sample first; when the basin is full to
//! its rim, the rest overflows there and goes on down the network. Rivers hand their load to the
//! ocean sample they end in.
//!
//! Ocean: a rule-based, single-pass stand-in for marine transport (nonlinear marine diffusion
//! as in Rivenæs 1992 or goSPL is too slow and too grid-bound at 35–80 km). Ocean samples that
//! receive sediment are visited from the shallowest down (a max-heap on the surface before
//! deposition, so a sample is visited after everything that feeds it). Each keeps sediment up
//! to a ceiling and passes the rest to its lower ocean neighbours in proportion to the slope
//! (multiple flow direction), carrying the along-path distance D from the coast:
//!
//! ```text
//!   ceiling = min( shelf_top(D),                                   shelf top (0.1° to −130 m,
//!                                                                    then 1/4 of that)
//!                  min_lower_j ( z_j + g(z_j)·d_ij ) )            repose against the next sample
//!   g(z_j) = g_slope (3°) where z_j ≥ −z_slope_base, else g_rise (0.5°)
//! ```
//!
//! so the shelf builds out to a break near −130 m, a ~3° slope forms in front of it, a gentle
//! rise apron spreads below, and deep depressions (trenches, basins) fill first. Surfaces are
//! tracked as they fill (z + f·deposit/a). Sediment that reaches a local minimum of the sea
//! floor fills it as a pond: a small priority flood grows the pond from the minimum, raising
//! its level sample by sample, until the sediment runs out or the pond reaches a lower
//! outlet, where the rest carries on downhill (fill-and-spill, as lakes on land). Geometry after Kearey, Klepeis & Vine (2009) and Pratson et al. (2007) for
//! shelf/slope/rise gradients; shelf-break depth ~130 m (Harris et al. 2014, "Geomorphology of
//! the oceans", Mar. Geol. 352).
//!
//! Deterministic: the land pass is sequential in stack order; the ocean pass pops samples in a
//! fixed (elevation, index) order.

use std::collections::BinaryHeap;

use rayon::prelude::*;

use super::drainage::Drainage;
use super::graph::ReliefGraph;
use crate::geometry::order_bits;

/// Parameters of the marine deposition profile. Depths are positive km below sea level.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SedimentParams {
    /// Water depth of the shelf surface at the shoreline, km.
    pub coast_depth_km: f64,
    /// Shelf gradient, m/m (0.1° ≈ 0.0017).
    pub shelf_gradient: f64,
    /// Depth of the shelf break, km (≈ 0.13).
    pub shelf_break_depth_km: f64,
    /// Gradient of the shelf top beyond the break depth, m/m (keeps wide shelves from being
    /// dead flat so sediment keeps a seaward path; 0.0004 = 40 m per 100 km).
    pub outer_shelf_gradient: f64,
    /// Continental-slope gradient, m/m (3° ≈ 0.052).
    pub slope_gradient: f64,
    /// Depth of the foot of the continental slope, where the rise begins, km.
    pub slope_base_depth_km: f64,
    /// Continental-rise gradient, m/m (0.5° ≈ 0.0087).
    pub rise_gradient: f64,
    /// Split the flux leaving a sample that keeps some sediment among its lower neighbours at
    /// least half as steep as the steepest (fans); `false`: steepest neighbour only (cheaper:
    /// about half the visits).
    pub marine_mfd: bool,
    /// Graded slope of a river draining 1,000 km², m/m: a land sample flatter than its graded
    /// slope above its receiver keeps what its river carries until it stands at that slope
    /// (0: rivers lay nothing down outside lakes).
    pub graded_slope: f64,
    /// Exponent θ of the graded slope's fall with drainage area A:
    /// S = graded_slope·(A / 1,000 km²)^(−θ).
    pub graded_concavity: f64,
    /// A flux that would make a layer thinner than this over the sample it reaches (km) is
    /// deposited there instead of being passed on (5 m per step: pelagic rates are 1–10 m/My).
    pub min_pass_thickness_km: f64,
}

impl Default for SedimentParams {
    fn default() -> Self {
        Self {
            coast_depth_km: 0.01,
            shelf_gradient: 0.0017,
            shelf_break_depth_km: 0.13,
            outer_shelf_gradient: 0.0004,
            slope_gradient: 0.052,
            slope_base_depth_km: 2.5,
            rise_gradient: 0.0087,
            min_pass_thickness_km: 5e-3,
            marine_mfd: true,
            graded_slope: 0.0,
            graded_concavity: 0.45,
        }
    }
}

impl SedimentParams {
    /// Graded slope (m/m) of a river draining `area_km2` (see [`Self::graded_slope`]).
    pub fn graded_slope_at(&self, area_km2: f64) -> f64 {
        self.graded_slope * (area_km2.max(1.0) / 1000.0).powf(-self.graded_concavity)
    }

    /// Shelf-top elevation (km, negative) at along-path distance `d_km` from the coast:
    /// −(z_coast + g_shelf·D) down to the break depth, then deepening at the outer gradient.
    pub fn shelf_top_km(&self, d_km: f64) -> f64 {
        let brk = self.shelf_break_depth_km.max(self.coast_depth_km);
        let inner = self.coast_depth_km + self.shelf_gradient * d_km;
        if inner <= brk || self.shelf_gradient <= 0.0 {
            -inner.min(brk)
        } else {
            let d_break = (brk - self.coast_depth_km) / self.shelf_gradient;
            -(brk + self.outer_shelf_gradient * (d_km - d_break))
        }
    }
}

/// Volumes handled by one [`SedimentRouter::route`] call, km³.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SedimentBudget {
    /// Sediment that entered: Σ e_i·a_i + Σ marine input.
    pub input_km3: f64,
    /// Σ deposit_i·a_i as written (f32 thicknesses × areas).
    pub deposited_km3: f64,
    /// Part kept in lakes and endorheic sinks.
    pub lakes_km3: f64,
    /// Part laid on river plains graded to their slope ([`SedimentParams::graded_slope`]).
    pub plains_km3: f64,
    /// Part that reached the ocean.
    pub to_ocean_km3: f64,
    /// Part spread around local minima of the sea floor (excess after filling them).
    pub spread_at_minima_km3: f64,
    /// Ocean samples visited.
    pub ocean_samples_visited: usize,
}

impl SedimentBudget {
    /// |deposited − input| / input (0 when nothing moved).
    pub fn relative_error(&self) -> f64 {
        if self.input_km3 > 0.0 {
            (self.deposited_km3 - self.input_km3).abs() / self.input_km3
        } else {
            self.deposited_km3.abs()
        }
    }
}

/// Scratch and state for sediment routing; reuse across steps.
#[derive(Clone, Debug, Default)]
pub struct SedimentRouter {
    /// Full endorheic basins one overflow may pass through before the rest goes to the nearest
    /// sea (`None`: [`MAX_OVERFLOWS`]).
    pub max_overflows: Option<usize>,
    /// Milliseconds the last [`Self::route`] spent on each of [`SedimentRouter::STAGES`].
    pub timings_ms: [f64; 4],
    flux: Vec<f64>,
    dep: Vec<f64>,
    dist: Vec<f32>,
    /// 0 untouched, 1 queued, 2 processed.
    state: Vec<u8>,
    visits: Vec<u8>,
    touched: Vec<u32>,
    heap: BinaryHeap<u64>,
    lower: Vec<(u32, f64, f64)>,
    pond: Vec<u32>,
    pond_mark: Vec<u32>,
    pond_epoch: u32,
    pond_heap: BinaryHeap<std::cmp::Reverse<u64>>,
    shares: Vec<(usize, f64)>,
    /// Position of each land sample in the drainage stack (`u32::MAX` at sea).
    rank: Vec<u32>,
    /// The endorheic sink each land sample drains to (`u32::MAX`: the sea).
    sink_of: Vec<u32>,
    /// The sinks one overflow passed through (see [`SedimentRouter::overflow`]).
    chain: Vec<u32>,
    /// Passages through subducted floor (see [`SedimentRouter::passages_mut`]): per sample, the
    /// neighbour its sediment passes on to, or [`NO_PASSAGE`] where it may settle.
    through: Vec<u32>,
    /// Ocean samples sediment may settle on (the ocean less the subducted floor), per call.
    settles: Vec<bool>,
    /// Loads waiting to fill their lakes (see [`SedimentRouter::queue_lake`]).
    lakes: Vec<PendingLake>,
    /// Per sample: the pending load filling from this low point of a lake floor, or
    /// [`NO_LAKE`].
    lake_at_low: Vec<u32>,
    /// Per sample: the first pending load whose rest goes on from this sample (the sample past
    /// its lake), or [`NO_LAKE`]; the others follow by [`PendingLake::next`].
    lakes_into: Vec<u32>,
    /// The floors of the lakes met so far in this call, one after the other (see
    /// [`SedimentRouter::lake_floor`]); `lake_ranges` holds each one's range.
    lake_members: Vec<u32>,
    lake_ranges: Vec<(u32, u32)>,
    /// Room left under each of those lakes' water surface, km³, as last known: exact after a
    /// count over its floor, less what ponds laid since (other deposits only lessen it), 0 once
    /// a load filled it to the brim, NaN before the first count.
    lake_room: Vec<f64>,
    /// Per sample: the index of its lake's floor in `lake_ranges`, or `u32::MAX` where none
    /// was met.
    lake_of: Vec<u32>,
    /// The room under the water surface of each sample of the floor [`Self::fill_whole_lake`]
    /// is counting, km³ (the count's terms, laid as they are when the load fills the lake).
    floor_room: Vec<f64>,
}

/// The load of one lake, gathered from every river that reaches it in one call and laid on its
/// floor at once, before the sample past its lake is routed.
#[derive(Clone, Copy, Debug)]
struct PendingLake {
    /// Low point of the lake floor the load fills from.
    low: u32,
    /// Water level of the lake, km.
    water_level_km: f64,
    /// Load, km³.
    q: f64,
    /// The last lake sample on the way out (its distance to the sea counts from there), and the
    /// sample past the lake the rest goes on to.
    from: u32,
    to: u32,
    /// The next pending load going on to the same sample, or [`NO_LAKE`].
    next: u32,
}

/// No pending lake load.
const NO_LAKE: u32 = u32::MAX;

/// No passage: the sample is not subducted floor, and sediment may settle on it.
pub const NO_PASSAGE: u32 = u32::MAX;
/// Most hops through subducted floor one delivery takes (each hop moves towards the front; a
/// strip of subducted floor is as wide as the convergence since the last resampling).
const MAX_PASSAGE_HOPS: usize = 256;

/// How a pond grows over land from an endorheic sink (see [`SedimentRouter::pond_fill`]).
#[derive(Clone, Copy)]
struct LandPond<'a> {
    /// The endorheic sink each land sample drains to (`u32::MAX`: the sea): a lower sample
    /// that drains to one of the pond's sinks joins the pond.
    sink_of: &'a [u32],
    /// The sinks whose basins the pond fills: its own, or several basins that overflow into
    /// each other, filled as one.
    members: &'a [u32],
    /// Whether the pond may overflow at a lower sample that drains elsewhere (else what is
    /// left is laid on the pond as a blanket).
    overflow: bool,
}

/// Most samples one pond may grow to before the rest is laid on it regardless (a thin blanket
/// over a flat plain; bounds the cost of one pond).
const MAX_POND: usize = 256;
/// Most samples a basin with no outlet fills over from its sink before the rest is laid on it
/// as a blanket (a large closed lake's floor; bounds the cost of one basin).
const MAX_LAND_POND: usize = 4096;
/// Full endorheic basins one overflow may pass through (each filled in turn, basins met again
/// filled as one) before the rest goes to the nearest sea (or, on a planet without one, the
/// last keeps it).
pub const MAX_OVERFLOWS: usize = 64;
/// Times one ocean sample may be processed in one call before its flux is laid on it.
const MAX_VISITS: u8 = 8;
/// Layers thinner than this (km) that stay within this distance of the shelf top are laid
/// down without looking at the neighbours.
const FAST_PATH_KM: f64 = 0.01;
/// Level differences below this (km) count as flat.
const TOL_KM: f64 = 1e-6;
/// Lake samples whose water levels differ by at most this (km) are one lake (the flood that
/// makes lakes raises each sample's level a rounding step over the one that flooded it).
const LAKE_LEVEL_TOL_KM: f64 = 1e-3;

/// Where what lake sample `i` passes on leaves its lake: down the receivers from `i`, the last
/// sample of the lake (`.0`) and the first beyond it (`.1`: a land sample outside the lake, a
/// sample of the sea, or `.0` itself when the lake drains to no sea and `.0` is its sink).
fn lake_exit(drainage: &Drainage, i: usize) -> (usize, usize) {
    let wl = drainage.water_level_km[i] as f64;
    let mut j = i;
    for _ in 0..drainage.receiver.len() {
        let r = drainage.receiver[j] as usize;
        if r == j {
            return (j, j);
        }
        if !in_lake(drainage, r, wl) {
            return (j, r);
        }
        j = r;
    }
    (j, j)
}

/// Whether sample `k` lies in the lake whose water level is `wl_km` (within
/// [`LAKE_LEVEL_TOL_KM`]).
#[inline]
fn in_lake(drainage: &Drainage, k: usize, wl_km: f64) -> bool {
    drainage.is_lake(k) && (drainage.water_level_km[k] as f64 - wl_km).abs() <= LAKE_LEVEL_TOL_KM
}

/// Current surface of sample `j` with the deposit `dep` (km³ per sample) laid on it, km: its
/// elevation (sea level where not finite) raised by `ff(j)` of the deposit's thickness.
#[inline]
fn surface_km(
    g: &ReliefGraph,
    elevation_km: &[f32],
    ff: &impl Fn(usize) -> f64,
    dep: &[f64],
    j: usize,
) -> f64 {
    let z = elevation_km[j];
    let z = if z.is_finite() { z as f64 } else { 0.0 };
    z + ff(j) * dep[j] / g.area_km2[j].max(1e-12)
}

/// Raises a pond of `inv` km³ per km of rise from `level` towards `target` (km) with the volume
/// left `q` (km³). Returns true when `q` ran out on the way (the level stops short, `q` is 0);
/// otherwise the level reaches the target (unchanged when already above it).
fn rise_pond(target: f64, inv: f64, q: &mut f64, level: &mut f64) -> bool {
    if target <= *level {
        return false;
    }
    let need = (target - *level) * inv;
    if *q <= need {
        *level += *q / inv;
        *q = 0.0;
        return true;
    }
    *q -= need;
    *level = target;
    false
}

impl SedimentRouter {
    /// The names [`Self::timings_ms`] are recorded under in the step timings: the setup, the
    /// land (rivers and lakes), the sea, and the safety net with the write-out.
    pub const STAGES: [&'static str; 4] = [
        "sediment_setup",
        "sediment_land",
        "sediment_sea",
        "sediment_safety_net",
    ];

    /// New router; buffers grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    /// Lists sample `i` before a deposit lands on it. A land sample upstream may still hold
    /// flux, which `touch` reads as already listed, so land samples are listed by their deposit.
    #[inline]
    fn touch_deposit(&mut self, i: usize, on_land: bool) {
        if on_land {
            if self.dep[i] == 0.0 {
                self.touched.push(i as u32);
            }
        } else {
            self.touch(i);
        }
    }

    /// The per-sample passages through subducted floor that the next [`Self::route`] follows:
    /// ocean floor that has gone under the overriding plate since the last resampling (still a
    /// sample of the subducting plate until the next one removes it) takes no sediment, and
    /// what reaches it passes on, neighbour by neighbour towards its front, to the floor that
    /// still shows (the trench). Each passage must lead to a sample nearer the front, so a
    /// chain ends. Fill with [`NO_PASSAGE`] where sediment may settle; leave empty (the
    /// default) for none. [`Self::route`] drops passages that start or end on land (it changes
    /// them to [`NO_PASSAGE`]); they are kept between calls.
    pub fn passages(&self) -> &[u32] {
        &self.through
    }

    /// The passages to fill before [`Self::route`] (see [`Self::passages`]).
    pub fn passages_mut(&mut self) -> &mut Vec<u32> {
        &mut self.through
    }

    /// Where sediment sent to ocean sample `j` settles: `j`, or the end of its passage.
    #[inline]
    fn settling_sample(&self, mut j: usize) -> usize {
        if self.through.len() <= j {
            return j;
        }
        for _ in 0..MAX_PASSAGE_HOPS {
            let t = self.through[j];
            if t == NO_PASSAGE || t as usize >= self.through.len() {
                break;
            }
            j = t as usize;
        }
        j
    }

    #[inline]
    fn touch(&mut self, i: usize) {
        if self.state[i] == 0 && self.flux[i] == 0.0 && self.dep[i] == 0.0 {
            self.touched.push(i as u32);
        }
    }

    /// Routes the eroded material and writes deposited thickness (km, ≥ 0) to `deposit_km`.
    ///
    /// - `elevation_km`: surface after erosion (km, sea level 0); the network `drainage` was
    ///   computed before erosion on the same mask.
    /// - `eroded_km`: thickness removed per sample (km, ≥ 0; e.g. stream power plus the
    ///   lowering from diffusion).
    /// - `marine_input_km3`: extra volume delivered straight to ocean samples (e.g. the coastal
    ///   outflow of [`super::diffusion::diffuse_land`]).
    /// - `fill_factor`: surface rise per unit deposited thickness per sample (0 < f ≤ 1;
    ///   missing = 1). Passing the isostatic factor of a *local* compensation (oceanic crust:
    ///   (ρ_m − ρ_s)/(ρ_m − ρ_w)) makes one step fill to the equilibrium profile; under regional
    ///   isostasy a single sample is barely compensated, so use 1 there.
    #[allow(clippy::too_many_arguments)]
    pub fn route(
        &mut self,
        g: &ReliefGraph,
        drainage: &Drainage,
        elevation_km: &[f32],
        eroded_km: &[f32],
        marine_input_km3: Option<&[f64]>,
        fill_factor: Option<&[f32]>,
        p: &SedimentParams,
        deposit_km: &mut [f32],
    ) -> SedimentBudget {
        let n = g.len();
        let mut lap = super::lap_timer();
        deposit_km.iter_mut().for_each(|d| *d = 0.0);
        let mut b = SedimentBudget::default();
        if elevation_km.len() < n
            || eroded_km.len() < n
            || deposit_km.len() < n
            || drainage.receiver.len() < n
            || drainage.ocean.len() < n
        {
            return b;
        }
        self.flux.resize(n, 0.0);
        self.dep.resize(n, 0.0);
        self.dist.resize(n, f32::INFINITY);
        self.state.resize(n, 0);
        self.visits.resize(n, 0);
        self.pond_mark.resize(n, 0);
        self.touched.clear();
        self.heap.clear();
        self.rank.clear();
        self.rank.resize(n, u32::MAX);
        self.sink_of.clear();
        self.sink_of.resize(n, u32::MAX);
        self.lakes.clear();
        self.lake_at_low.clear();
        self.lake_at_low.resize(n, NO_LAKE);
        self.lakes_into.clear();
        self.lakes_into.resize(n, NO_LAKE);
        for (k, &j) in drainage.stack.iter().enumerate() {
            let j = j as usize;
            if j >= n {
                continue;
            }
            self.rank[j] = k as u32;
            // Receivers come first in the stack, so theirs is known.
            let r = drainage.receiver[j] as usize;
            self.sink_of[j] = if r == j {
                j as u32
            } else if r < n && !drainage.ocean[r] {
                self.sink_of[r]
            } else {
                u32::MAX
            };
        }
        if self.lake_of.len() != n {
            self.lake_of.clear();
            self.lake_of.resize(n, u32::MAX);
        }
        self.lake_members.clear();
        self.lake_ranges.clear();
        self.lake_room.clear();
        let ocean = &drainage.ocean;
        // Sediment settles on ocean samples outside the passages (see `passages_mut`).
        let mut settles = std::mem::take(&mut self.settles);
        settles.clear();
        if self.through.len() == n {
            // A passage joins two ocean samples; one that starts or ends on land (crust that
            // stands above the sea) is no passage, so sediment only ever settles at sea.
            const CH: usize = 8192;
            settles.resize(n, false);
            self.through
                .par_chunks_mut(CH)
                .zip(settles.par_chunks_mut(CH))
                .enumerate()
                .for_each(|(c, (ts, ss))| {
                    for (k, (t, s)) in ts.iter_mut().zip(ss.iter_mut()).enumerate() {
                        let i = c * CH + k;
                        let j = *t as usize;
                        if j != NO_PASSAGE as usize && (!ocean[i] || j >= n || !ocean[j]) {
                            *t = NO_PASSAGE;
                        }
                        *s = ocean[i] && *t == NO_PASSAGE;
                    }
                });
        } else {
            settles.extend_from_slice(&ocean[..n]);
        }
        let sea = &settles[..];
        let ff = |i: usize| -> f64 {
            fill_factor
                .and_then(|f| f.get(i).copied())
                .filter(|f| f.is_finite() && *f > 0.0)
                .map(|f| (f as f64).min(1.0))
                .unwrap_or(1.0)
        };
        let z_of = |i: usize| -> f64 {
            let z = elevation_km[i];
            if z.is_finite() { z as f64 } else { 0.0 }
        };

        self.timings_ms[0] = lap();
        // Land: accumulate and route down the network, filling lakes. Land fluxes are zeroed as
        // the samples are visited, so only samples that keep a deposit are listed in `touched`.
        for i in 0..n {
            let e = eroded_km[i];
            if e.is_finite() && e > 0.0 && !ocean[i] {
                let v = e as f64 * g.area_km2[i];
                b.input_km3 += v;
                self.flux[i] += v;
            }
        }
        for k in (0..drainage.stack.len()).rev() {
            let i = drainage.stack[k] as usize;
            // Lakes whose rest comes this way are filled first: every river reaching them has
            // been routed (they all lie upstream).
            if self.lakes_into[i] != NO_LAKE {
                self.fill_lakes_into(i, g, drainage, elevation_km, &ff, &mut b);
            }
            let mut q = self.flux[i];
            if q <= 0.0 {
                continue;
            }
            self.flux[i] = 0.0;
            let mut r = drainage.receiver[i] as usize;
            // Where what is left goes on from (its distance to the sea counts from there).
            let mut from = i;
            // Lake: fill up to the water level. Endorheic sink: keep everything.
            let depth = if drainage.is_lake(i) {
                drainage.water_level_km[i] as f64 - z_of(i)
            } else {
                0.0
            };
            if r == i {
                // An endorheic sink (a closed lake's, or a pit whose lake dried up): what the
                // basin upstream did not keep fills it from its floor, lowest samples first,
                // never a pile on one sample (which would stand as a hill once the lake is gone).
                let sink_of = std::mem::take(&mut self.sink_of);
                let land = LandPond {
                    sink_of: &sink_of,
                    members: &[i as u32],
                    overflow: true,
                };
                let (outlet, rest) =
                    self.pond_fill(g, ocean, i, q, p, elevation_km, &ff, Some(land));
                self.sink_of = sink_of;
                b.lakes_km3 += q - rest;
                if let Some(o) = outlet
                    && rest > 0.0
                {
                    // The basin is full: the rest goes on from its outlet, down the network.
                    self.overflow(g, drainage, i, o, k, rest, p, elevation_km, &ff, &mut b);
                }
                continue;
            }
            if depth > 0.0 {
                // A lake: the load settles on the lake's floor, lowest first (not on the
                // samples along the flood's straight paths to the outlet, which it would raise
                // to the water surface one after the other: causeways across the lake that
                // stand as straight ridges once it is gone). What the lake cannot hold goes on
                // from its outlet: past the lake, on from the first sample beyond it (land or
                // sea), or into the endorheic sink the lake drains to. The loads of all the
                // rivers reaching one lake fill it together, once they are all in.
                let (j, end) = lake_exit(drainage, i);
                if end != i {
                    (from, r) = (j, end);
                }
                let low = self.lake_low_point(g, drainage, i, elevation_km, &ff);
                let wl = drainage.water_level_km[i] as f64;
                self.queue_lake(low, wl, q, from, r);
                continue;
            }
            // A river on ground flatter than its graded slope lays down what raises the ground
            // to that slope above its receiver (or above the sea at its mouth): alluvial
            // plains and delta tops, built from the sea up as the ground subsides.
            if p.graded_slope > 0.0 {
                let d = drainage.receiver_km[i] as f64;
                let (base, run) = if ocean[r] {
                    (0.0, 0.5 * d)
                } else {
                    (surface_km(g, elevation_km, &ff, &self.dep, r), d)
                };
                let target = base + p.graded_slope_at(drainage.area_km2[i]) * run;
                let zi = surface_km(g, elevation_km, &ff, &self.dep, i);
                if target > zi {
                    let keep = q.min((target - zi) * g.area_km2[i] / ff(i));
                    self.touch_deposit(i, true);
                    self.dep[i] += keep;
                    b.plains_km3 += keep;
                    q -= keep;
                }
            }
            if q <= 0.0 {
                continue;
            }
            self.pass_on(drainage, from, r, q, elevation_km, &mut b);
        }
        // Lakes that drain to the sea (every land sample is in the stack, so the others are
        // filled by now).
        for l in 0..self.lakes.len() {
            let to = self.lakes[l].to as usize;
            if self.lakes_into[to] != NO_LAKE {
                self.fill_lakes_into(to, g, drainage, elevation_km, &ff, &mut b);
            }
        }
        self.timings_ms[1] = lap();
        // Direct marine input (coastal diffusion outflow).
        if let Some(mi) = marine_input_km3 {
            let half = 0.5 * g.mean_spacing_km as f32;
            for (j, &v) in mi.iter().enumerate().take(n) {
                if !(v.is_finite() && v > 0.0 && ocean[j]) {
                    continue;
                }
                let j = self.settling_sample(j);
                b.input_km3 += v;
                b.to_ocean_km3 += v;
                // Fast path: a thin layer that stays under the shelf top is laid down where it
                // arrives (the repose limit is checked when the sample is routed later).
                let a = g.area_km2[j].max(1e-12);
                let add = ff(j) * v / a;
                let zj = z_of(j) + ff(j) * self.dep[j] / a;
                if self.state[j] == 0
                    && add <= FAST_PATH_KM
                    && zj + add <= p.shelf_top_km(half as f64) + FAST_PATH_KM
                {
                    self.touch(j);
                    self.dep[j] += v;
                    continue;
                }
                self.send(j, v, half, elevation_km);
            }
        }

        // Ocean: shallowest (current surface) first.
        let mut budget_visits = 8 * n + 1000;
        while let Some(key) = self.heap.pop() {
            let i = (!(key as u32)) as usize;
            if self.state[i] != 1 {
                continue;
            }
            self.state[i] = 2;
            b.ocean_samples_visited += 1;
            budget_visits = budget_visits.saturating_sub(1);
            self.visits[i] = self.visits[i].saturating_add(1);
            let mut q = self.flux[i];
            self.flux[i] = 0.0;
            if q <= 0.0 {
                continue;
            }
            let cur = |s: &Self, j: usize| z_of(j) + ff(j) * s.dep[j] / g.area_km2[j].max(1e-12);
            let zi = cur(self, i);
            let di = self.dist[i] as f64;
            let shelf_top = p.shelf_top_km(di);
            let ai = g.area_km2[i].max(1e-12);
            if ff(i) * q / ai <= FAST_PATH_KM && zi + ff(i) * q / ai <= shelf_top + FAST_PATH_KM {
                // Thin layer at most 10 m over the shelf top: laid down here, no neighbour scan
                // (the shelf top is a soft ceiling; the next step routes past the excess).
                self.dep[i] += q;
                continue;
            }
            self.lower.clear();
            let mut repose = f64::INFINITY;
            for e in g.edges(i) {
                let d = g.edge_km[e] as f64;
                let j = g.neighbors[e] as usize;
                if d <= 0.0 || !ocean[j] {
                    continue;
                }
                // Over subducted floor, the neighbour is where its passage ends (the trench):
                // the stale edge stands for the margin's edge at the trench.
                let j = self.settling_sample(j);
                if j == i || !sea[j] {
                    continue;
                }
                let zj = cur(self, j);
                if zj < zi - TOL_KM {
                    let grad = if zj >= -p.slope_base_depth_km {
                        p.slope_gradient
                    } else {
                        p.rise_gradient
                    };
                    repose = repose.min(zj + grad * d);
                    self.lower.push((j as u32, (zi - zj) / d, d));
                }
            }
            let ceiling = shelf_top.min(repose);
            let keep = q.min((ceiling - zi).max(0.0) * g.area_km2[i] / ff(i));

            self.dep[i] += keep;
            q -= keep;
            if q <= 0.0 {
                continue;
            }
            if q < p.min_pass_thickness_km * g.area_km2[i] {
                self.dep[i] += q;
                continue;
            }
            if budget_visits == 0 || self.visits[i] > MAX_VISITS {
                // Visited often enough: no more fanning out. Everything goes down the steepest
                // lower neighbour (each hop goes strictly down, so it ends), or stays here at a
                // local minimum.
                let steepest = self
                    .lower
                    .iter()
                    .copied()
                    .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)));
                match steepest {
                    Some((j, _, d)) => self.send(j as usize, q, (di + d) as f32, elevation_km),
                    None => self.dep[i] += q,
                }
                continue;
            }
            if self.lower.is_empty() {
                // Local minimum: fill as a pond; the rest spills at the pond's outlet.
                let (outlet, rest) = self.pond_fill(g, sea, i, q, p, elevation_km, &ff, None);
                b.spread_at_minima_km3 += q - rest;
                if let Some(o) = outlet {
                    let d = di as f32 + g.mean_spacing_km as f32;
                    self.send(o, rest, d, elevation_km);
                }
                continue;
            }
            // Multiple flow direction, restricted to the lower neighbours at least half as
            // steep as the steepest (keeps fans from spreading sediment over every direction).
            // A full sample (nothing kept) passes everything down its steepest path: sediment
            // bypassing a full shelf or slope travels in channels rather than fanning out.
            let smax = self.lower.iter().map(|l| l.1).fold(0.0, f64::max);
            let mfd = keep > 0.0 && p.marine_mfd;
            let cut = if mfd { 0.5 * smax } else { smax };
            self.lower.retain(|l| l.1 >= cut);
            self.lower.truncate(if mfd { usize::MAX } else { 1 });
            let total: f64 = self.lower.iter().map(|l| l.1).sum();
            let count = self.lower.len();
            let mut given = 0.0;
            for k in 0..count {
                let (j, s, d) = self.lower[k];
                let v = if k + 1 == count {
                    q - given
                } else {
                    q * s / total
                };
                given += v;
                self.send(j as usize, v, (di + d) as f32, elevation_km);
            }
        }

        self.timings_ms[2] = lap();
        // Safety net: no ocean sample may be raised above the shelf surface at the coast
        // (−coast depth). The visit and pond limits above can leave more than that on one
        // sample (a trench or a basin fed by many rivers); the excess spreads to the nearest
        // ocean samples with room, breadth first, in a fixed order.
        self.spread_overfull(g, sea, p, elevation_km, &ff);
        self.settles = settles;

        // Write out and reset scratch (a sample listed twice is written once: dep is cleared).
        for k in 0..self.touched.len() {
            let i = self.touched[k] as usize;
            let a = g.area_km2[i];
            if a > 0.0 && self.dep[i] > 0.0 {
                let t = (self.dep[i] / a) as f32;
                deposit_km[i] += t;
                b.deposited_km3 += t as f64 * a;
            }
            self.flux[i] = 0.0;
            self.dep[i] = 0.0;
            self.dist[i] = f32::INFINITY;
            self.state[i] = 0;
            self.visits[i] = 0;
        }
        for &j in &self.lake_members {
            self.lake_of[j as usize] = u32::MAX;
        }
        self.timings_ms[3] = lap();
        b
    }

    /// A fresh epoch of `pond_mark` (two values: the epoch and the epoch + 1).
    fn fresh_epoch(&mut self) -> u32 {
        self.pond_epoch = self.pond_epoch.wrapping_add(2);
        if self.pond_epoch < 2 {
            self.pond_mark.iter_mut().for_each(|m| *m = 0);
            self.pond_epoch = 2;
        }
        self.pond_epoch
    }

    /// Moves whatever would raise an ocean sample above `−coast_depth` to the nearest ocean
    /// samples with room. Overfull samples are held at that level; each connected region of
    /// full sea (ocean samples without room) that holds some pools their excess, and spreads it
    /// breadth first from the region's edge outward (the edge's samples with room in the order
    /// the region's search found them, from its first overfull sample; neighbours in CSR
    /// order). One search per region, not per overfull sample: a wide sea filled to the brim
    /// was crossed again for every sample at its heart. The spread crosses land (and floor gone
    /// under a margin) to the sea beyond: a speck of sea walled in by land (a trench sample
    /// whose sea-side neighbours all went under the margin) has no room of its own, and kept
    /// its river's whole load, 20–30 km thick. Conserves the volume; what no ocean sample
    /// within reach can take is laid over the region and the sea the spread crossed, in
    /// proportion to area.
    fn spread_overfull(
        &mut self,
        g: &ReliefGraph,
        ocean: &[bool],
        p: &SedimentParams,
        elevation_km: &[f32],
        ff: &impl Fn(usize) -> f64,
    ) {
        let cap_level = -p.coast_depth_km;
        // Volume (km³) a sample holds up to −coast depth, and what is left of it.
        let cap = |j: usize| -> f64 {
            let z = elevation_km[j];
            let z = if z.is_finite() { z as f64 } else { 0.0 };
            ((cap_level - z) * g.area_km2[j] / ff(j)).max(0.0)
        };
        let room = |dep: &[f64], j: usize| -> f64 { (cap(j) - dep[j]).max(0.0) };
        // 1. The overfull samples, in the order they were touched, held at the cap.
        let mut excess_of: std::collections::HashMap<u32, f64> = std::collections::HashMap::new();
        let mut starts: Vec<u32> = Vec::new();
        for k in 0..self.touched.len() {
            let i = self.touched[k] as usize;
            if !ocean[i] || self.dep[i] <= 0.0 {
                continue;
            }
            let cap = cap(i);
            let excess = self.dep[i] - cap;
            if excess <= 1e-9 * g.area_km2[i] {
                continue;
            }
            self.dep[i] = cap;
            *excess_of.entry(i as u32).or_insert(0.0) += excess;
            starts.push(i as u32);
        }
        let mut region: Vec<u32> = Vec::new();
        let mut queue: Vec<u32> = Vec::new();
        for &start in &starts {
            // Pooled already with an earlier region.
            let Some(e0) = excess_of.get_mut(&start).map(std::mem::take) else {
                continue;
            };
            if e0 <= 0.0 {
                continue;
            }
            let mut excess = e0;
            // 2. The full region around `start` (breadth first) and its edge with room.
            let seen = self.fresh_epoch();
            region.clear();
            queue.clear();
            region.push(start);
            self.pond_mark[start as usize] = seen;
            let mut head = 0;
            while head < region.len() {
                let u = region[head] as usize;
                head += 1;
                for e in g.edges(u) {
                    let j = g.neighbors[e] as usize;
                    if j == u || self.pond_mark[j] == seen {
                        continue;
                    }
                    self.pond_mark[j] = seen;
                    if !ocean[j] || room(&self.dep, j) > 0.0 {
                        // Room, or land (or floor gone under a margin) the spread crosses to
                        // the sea beyond: a speck of sea walled in by land has no room of its
                        // own.
                        queue.push(j as u32);
                    } else {
                        region.push(j as u32);
                        if let Some(x) = excess_of.get_mut(&(j as u32)) {
                            excess += std::mem::take(x);
                        }
                    }
                }
            }
            // 3. Spread from the edge outward, filling what has room.
            let mut head = 0;
            while head < queue.len() && excess > 0.0 && head < 100_000 {
                let u = queue[head] as usize;
                head += 1;
                let r = if ocean[u] { room(&self.dep, u) } else { 0.0 };
                if r > 0.0 {
                    let v = r.min(excess);
                    self.touch(u);
                    self.dep[u] += v;
                    excess -= v;
                    if excess <= 0.0 {
                        break;
                    }
                }
                for e in g.edges(u) {
                    let j = g.neighbors[e] as usize;
                    if j == u || self.pond_mark[j] == seen {
                        continue;
                    }
                    self.pond_mark[j] = seen;
                    queue.push(j as u32);
                }
            }
            if excess > 0.0 {
                // Nowhere within reach has room: a blanket over the region and the sea the
                // spread crossed, in proportion to area.
                region.extend(queue.iter().copied().filter(|&j| ocean[j as usize]));
                let total: f64 = region.iter().map(|&j| g.area_km2[j as usize]).sum();
                if total > 0.0 {
                    let mut given = 0.0;
                    let last = region.len() - 1;
                    for (k, &j) in region.iter().enumerate() {
                        let j = j as usize;
                        let v = if k == last {
                            excess - given
                        } else {
                            excess * g.area_km2[j] / total
                        };
                        given += v;
                        self.touch(j);
                        self.dep[j] += v;
                    }
                } else {
                    self.dep[start as usize] += excess;
                }
            }
        }
    }

    /// Carries `q` km³ that overflowed the full endorheic basin of `sink` at land sample `o`,
    /// while the land pass is at stack position `at`: down `o`'s receivers to the first sample
    /// the pass has still to route (which takes it on), or to the sea. A sink already routed
    /// fills as a pond of its own and may overflow in turn, up to
    /// [`SedimentRouter::max_overflows`] basins; the rest then goes to the nearest sea (on a
    /// planet without one, the last basin keeps it as a blanket). That limit bounds the cost of
    /// a plain pocked with pits; when the last basin kept the rest, one sample of such a plain
    /// took up to 570 km of sediment in a step (the default planet, before this limit's
    /// fallback), and stood at the height cap for a hundred million years.
    ///
    /// The network was drawn on the surface before this step's erosion, so a full basin can
    /// overflow into one that overflows back into it (through a hollow the erosion closed
    /// off): a sink met again makes every basin since then one pond, filled together until it
    /// overflows elsewhere. Without it the walk went round the circle and the last basin took
    /// all that was left as a blanket, kilometres thick.
    #[allow(clippy::too_many_arguments)]
    fn overflow(
        &mut self,
        g: &ReliefGraph,
        drainage: &Drainage,
        sink: usize,
        o: usize,
        at: usize,
        mut q: f64,
        p: &SedimentParams,
        elevation_km: &[f32],
        ff: &impl Fn(usize) -> f64,
        b: &mut SedimentBudget,
    ) {
        let ocean = &drainage.ocean;
        let mut j = o;
        let mut basins = 0;
        // The sinks passed, in order; those from `union` on fill as one pond.
        let mut chain = std::mem::take(&mut self.chain);
        chain.clear();
        chain.push(sink as u32);
        let mut union = usize::MAX;
        let limit = self.max_overflows.unwrap_or(MAX_OVERFLOWS);
        // Receivers come earlier in the stack, so each walk ends within the stack's length.
        let mut steps = 0;
        while steps <= drainage.stack.len() {
            steps += 1;
            let r = drainage.receiver[j] as usize;
            if (self.rank[j] as usize) < at {
                self.flux[j] += q;
                q = 0.0;
                break;
            }
            if r == j {
                basins += 1;
                if basins > limit
                    && let Some((sea, d)) = self.nearest_sea(g, ocean, j)
                {
                    // A long chain of small full basins (a plain pocked with pits): what is
                    // left goes to the nearest sea, not on the last basin as a blanket.
                    b.to_ocean_km3 += q;
                    self.send(sea, q, d, elevation_km);
                    q = 0.0;
                    break;
                }
                let from = match chain.iter().position(|&s| s as usize == j) {
                    Some(m) => {
                        union = union.min(m);
                        union
                    }
                    None => {
                        chain.push(j as u32);
                        chain.len() - 1
                    }
                };
                let sink_of = std::mem::take(&mut self.sink_of);
                let land = LandPond {
                    sink_of: &sink_of,
                    members: &chain[from..],
                    overflow: basins <= limit,
                };
                let (outlet, rest) =
                    self.pond_fill(g, ocean, j, q, p, elevation_km, ff, Some(land));
                self.sink_of = sink_of;
                b.lakes_km3 += q - rest;
                match outlet {
                    Some(next) if rest > 0.0 => {
                        q = rest;
                        j = next;
                        steps = 0;
                        continue;
                    }
                    _ => {
                        q = 0.0;
                        break;
                    }
                }
            }
            if ocean[r] {
                b.to_ocean_km3 += q;
                let d0 = 0.5 * drainage.receiver_km[j];
                self.send(r, q, d0, elevation_km);
                q = 0.0;
                break;
            }
            j = r;
        }
        if q > 0.0 {
            // Not reached on a valid network; keep the volume where the walk stopped.
            self.touch_deposit(j, true);
            self.dep[j] += q;
            b.lakes_km3 += q;
        }
        self.chain = chain;
    }

    /// The ocean sample nearest to land sample `j` (breadth first over the graph, neighbours in
    /// CSR order) and its distance (km, one mean spacing a hop); `None` without an ocean.
    fn nearest_sea(&mut self, g: &ReliefGraph, ocean: &[bool], j: usize) -> Option<(usize, f32)> {
        let seen = self.fresh_epoch();
        let mut queue: Vec<(u32, u32)> = vec![(j as u32, 0)];
        self.pond_mark[j] = seen;
        let mut head = 0;
        while head < queue.len() {
            let (u, hops) = queue[head];
            head += 1;
            for e in g.edges(u as usize) {
                let k = g.neighbors[e] as usize;
                if k == u as usize || self.pond_mark[k] == seen {
                    continue;
                }
                if ocean[k] {
                    return Some((k, ((hops + 1) as f64 * g.mean_spacing_km) as f32));
                }
                self.pond_mark[k] = seen;
                queue.push((k as u32, hops + 1));
            }
        }
        None
    }

    /// Adds flux `q` to ocean sample `j`, or to the end of its passage (distance from the coast
    /// `d`), and queues it at its current surface.
    fn send(&mut self, j: usize, q: f64, d: f32, elevation_km: &[f32]) {
        let j = self.settling_sample(j);
        self.touch(j);
        self.flux[j] += q;
        if d < self.dist[j] {
            self.dist[j] = d;
        }
        if self.state[j] != 1 {
            self.state[j] = 1;
            let z = elevation_km[j];
            let z = if z.is_finite() { z } else { 0.0 };
            self.heap
                .push(((order_bits(z) as u64) << 32) | (!(j as u32)) as u64);
        }
    }

    /// The low point of the lake floor a load reaching lake sample `i` settles towards: down
    /// the floor (the lake's samples, those whose water level is the same as `i`'s within
    /// [`LAKE_LEVEL_TOL_KM`]), each move to the lowest lower neighbour.
    fn lake_low_point(
        &self,
        g: &ReliefGraph,
        drainage: &Drainage,
        i: usize,
        elevation_km: &[f32],
        ff: &impl Fn(usize) -> f64,
    ) -> usize {
        let wl = drainage.water_level_km[i] as f64;
        let cur = |j: usize| surface_km(g, elevation_km, ff, &self.dep, j);
        // Each move strictly lower, so it ends.
        let mut m = i;
        for _ in 0..MAX_LAND_POND {
            let mut best = (cur(m), m);
            for &k in g.neighbors_of(m) {
                let k = k as usize;
                if in_lake(drainage, k, wl) {
                    let c = cur(k);
                    if c < best.0 - TOL_KM {
                        best = (c, k);
                    }
                }
            }
            if best.1 == m {
                break;
            }
            m = best.1;
        }
        m
    }

    /// Adds `q` km³ to the load filling a lake from its floor's low point `low`, whose rest
    /// goes on from lake sample `from` to sample `to`. One river after another, each load grew
    /// its pond from the low point again over the floor the ones before had filled: on a
    /// mature 500,000-sample planet 13,000 loads a step, over 0.3 to 3 million pond samples.
    fn queue_lake(&mut self, low: usize, water_level_km: f64, q: f64, from: usize, to: usize) {
        let at = self.lake_at_low[low];
        if at != NO_LAKE && self.lakes[at as usize].to as usize == to {
            self.lakes[at as usize].q += q;
            return;
        }
        let id = self.lakes.len() as u32;
        self.lakes.push(PendingLake {
            low: low as u32,
            water_level_km,
            q,
            from: from as u32,
            to: to as u32,
            next: self.lakes_into[to],
        });
        self.lakes_into[to] = id;
        if at == NO_LAKE {
            self.lake_at_low[low] = id;
        }
    }

    /// Fills the lakes whose rest goes on to sample `to` with their loads, and passes what they
    /// cannot hold on to `to` ([`Self::pass_on`]).
    fn fill_lakes_into(
        &mut self,
        to: usize,
        g: &ReliefGraph,
        drainage: &Drainage,
        elevation_km: &[f32],
        ff: &impl Fn(usize) -> f64,
        b: &mut SedimentBudget,
    ) {
        let mut l = std::mem::replace(&mut self.lakes_into[to], NO_LAKE);
        while l != NO_LAKE {
            let lake = self.lakes[l as usize];
            if self.lake_at_low[lake.low as usize] == l {
                self.lake_at_low[lake.low as usize] = NO_LAKE;
            }
            l = lake.next;
            let q = lake.q;
            let rest = self.lake_fill(g, drainage, &lake, elevation_km, ff);
            b.lakes_km3 += q - rest;
            if rest > 0.0 {
                self.pass_on(drainage, lake.from as usize, to, rest, elevation_km, b);
            }
        }
    }

    /// Sends `q` km³ on from land sample `from` to `r`: into the sea at a river mouth (its
    /// distance to the sea counted from half the last reach), or onto `r`'s flux on land.
    fn pass_on(
        &mut self,
        drainage: &Drainage,
        from: usize,
        r: usize,
        q: f64,
        elevation_km: &[f32],
        b: &mut SedimentBudget,
    ) {
        if drainage.ocean[r] {
            b.to_ocean_km3 += q;
            let d0 = 0.5 * drainage.receiver_km[from];
            self.send(r, q, d0, elevation_km);
        } else {
            self.flux[r] += q;
        }
    }

    /// Lays the load of `lake` on its floor, filling from its low point (see
    /// [`Self::lake_low_point`]), lowest ground first, up to the water surface (at most
    /// [`MAX_LAND_POND`] samples). Returns what the lake could not hold there.
    fn lake_fill(
        &mut self,
        g: &ReliefGraph,
        drainage: &Drainage,
        lake: &PendingLake,
        elevation_km: &[f32],
        ff: &impl Fn(usize) -> f64,
    ) -> f64 {
        let low = lake.low as usize;
        let id = drainage
            .is_lake(low)
            .then(|| self.lake_floor(g, drainage, low))
            .filter(|&id| {
                let (a, b) = self.lake_ranges[id];
                (b - a) as usize <= MAX_LAND_POND
            });
        if let Some(id) = id
            && let Some(rest) = self.fill_whole_lake(id, g, drainage, lake, elevation_km, ff)
        {
            return rest;
        }
        let (m, wl, mut q) = (lake.low as usize, lake.water_level_km, lake.q);
        let same_lake = |k: usize| in_lake(drainage, k, wl);
        let cur = |dep: &[f64], j: usize| surface_km(g, elevation_km, ff, dep, j);
        let in_pond = self.fresh_epoch();
        self.pond.clear();
        self.pond_heap.clear();
        self.pond.push(m as u32);
        self.pond_mark[m] = in_pond;
        let mut level = cur(&self.dep, m);
        let mut inv = g.area_km2[m] / ff(m);
        let q0 = q;
        loop {
            if level >= wl {
                break;
            }
            let next = if self.pond.len() < MAX_LAND_POND {
                self.push_boundary(g, in_pond, &same_lake, elevation_km, ff);
                self.pond_heap.pop()
            } else {
                None
            };
            let Some(std::cmp::Reverse(key)) = next else {
                // The whole lake floor is in the pond, or the pond is at its size limit: it
                // rises as one towards the surface.
                let used = q.min((wl - level) * inv);
                level += used / inv;
                q -= used;
                break;
            };
            let bnd = (key & 0xffff_ffff) as usize;
            let cb = cur(&self.dep, bnd).min(wl);
            if rise_pond(cb, inv, &mut q, &mut level) {
                break;
            }
            // Lower ground of the floor (the pond rose past it) fills to the level; when that
            // takes more than was left, the level settles lower.
            if self.join_pond(g, bnd, cb, in_pond, ff, (&mut q, &mut inv, &mut level)) {
                break;
            }
        }
        self.lay_on_pond(g, q0 - q, level, m, true, elevation_km, ff);
        if let Some(id) = id {
            self.lake_room[id] -= q0 - q;
        }
        q
    }

    /// The floor of the lake lake sample `low` lies in (its connected samples whose water
    /// levels agree within [`LAKE_LEVEL_TOL_KM`] from one to the next, as [`in_lake`] reads
    /// them): its index in `lake_ranges` (a range of `lake_members`), found breadth first the
    /// first time one of its samples asks in a call.
    fn lake_floor(&mut self, g: &ReliefGraph, drainage: &Drainage, low: usize) -> usize {
        let id = self.lake_of[low];
        if (id as usize) < self.lake_ranges.len() {
            return id as usize;
        }
        let id = self.lake_ranges.len() as u32;
        let start = self.lake_members.len();
        self.lake_members.push(low as u32);
        self.lake_of[low] = id;
        let mut k = start;
        while k < self.lake_members.len() {
            let j = self.lake_members[k] as usize;
            k += 1;
            let wl = drainage.water_level_km[j] as f64;
            for &nb in g.neighbors_of(j) {
                let nb = nb as usize;
                if self.lake_of[nb] == u32::MAX && in_lake(drainage, nb, wl) {
                    self.lake_of[nb] = id;
                    self.lake_members.push(nb as u32);
                }
            }
        }
        let end = self.lake_members.len();
        self.lake_ranges.push((start as u32, end as u32));
        self.lake_room.push(f64::NAN);
        id as usize
    }

    /// A load that fills its lake (`id`, see [`Self::lake_floor`]) to the brim: every sample of
    /// the floor rises to the water surface, which is what [`Self::lake_fill`]'s pond would
    /// come to once it had grown over the whole floor (to within rounding), without growing
    /// it. Returns what is left over, or `None` when the load does not fill the lake (the pond
    /// fills it then). Most loads reaching a lake fill it (about five in six on a mature
    /// 500,000-sample planet); the room is counted over the floor only when the load may fill
    /// it, and a full lake passes every later load on.
    fn fill_whole_lake(
        &mut self,
        id: usize,
        g: &ReliefGraph,
        drainage: &Drainage,
        lake: &PendingLake,
        elevation_km: &[f32],
        ff: &impl Fn(usize) -> f64,
    ) -> Option<f64> {
        let known = self.lake_room[id];
        if known == 0.0 {
            return Some(lake.q);
        }
        if lake.q < known * (1.0 - 1e-6) {
            return None; // the room is at most what is known
        }
        let (start, end) = self.lake_ranges[id];
        let (start, end) = (start as usize, end as usize);
        let wl = lake.water_level_km;
        let room = |dep: &[f64], j: usize| {
            if in_lake(drainage, j, wl) {
                (wl - surface_km(g, elevation_km, ff, dep, j)).max(0.0) * g.area_km2[j] / ff(j)
            } else {
                0.0
            }
        };
        self.floor_room.clear();
        self.floor_room.extend(
            self.lake_members[start..end]
                .iter()
                .map(|&j| room(&self.dep, j as usize)),
        );
        let volume: f64 = self.floor_room.iter().sum();
        self.lake_room[id] = volume;
        if lake.q < volume {
            return None;
        }
        for k in start..end {
            let (j, v) = (self.lake_members[k] as usize, self.floor_room[k - start]);
            if v > 0.0 {
                self.touch_deposit(j, true);
                self.dep[j] += v;
            }
        }
        self.lake_room[id] = 0.0;
        Some(lake.q - volume)
    }

    /// Sample `bnd`, whose surface `cb` lies at or under the pond's level, joins the pond and
    /// fills up to the level from the volume left `q` (km³); `inv` (km³ per km of rise) grows
    /// by its area. Returns true when filling it took all of `q`: the level then settles lower
    /// by what was missing, and `q` is 0.
    fn join_pond(
        &mut self,
        g: &ReliefGraph,
        bnd: usize,
        cb: f64,
        in_pond: u32,
        ff: &impl Fn(usize) -> f64,
        (q, inv, level): (&mut f64, &mut f64, &mut f64),
    ) -> bool {
        *q -= (*level - cb) * g.area_km2[bnd] / ff(bnd);
        self.pond.push(bnd as u32);
        self.pond_mark[bnd] = in_pond;
        *inv += g.area_km2[bnd] / ff(bnd);
        if *q <= 0.0 {
            *level += *q / *inv;
            *q = 0.0;
            return true;
        }
        false
    }

    /// Puts the neighbours of the pond's newest sample that `admit` lets in, and that are not in
    /// the pond (`pond_mark` = `in_pond`) or its boundary (`in_pond + 1`) yet, on the boundary
    /// heap, keyed by their current surface.
    fn push_boundary(
        &mut self,
        g: &ReliefGraph,
        in_pond: u32,
        admit: &impl Fn(usize) -> bool,
        elevation_km: &[f32],
        ff: &impl Fn(usize) -> f64,
    ) {
        let in_heap = in_pond + 1;
        let Some(&newest) = self.pond.last() else {
            return;
        };
        let newest = newest as usize;
        for e in g.edges(newest) {
            let k = g.neighbors[e] as usize;
            if k == newest
                || self.pond_mark[k] == in_pond
                || self.pond_mark[k] == in_heap
                || !admit(k)
            {
                continue;
            }
            self.pond_mark[k] = in_heap;
            let c = surface_km(g, elevation_km, ff, &self.dep, k) as f32;
            self.pond_heap
                .push(std::cmp::Reverse(((order_bits(c) as u64) << 32) | k as u64));
        }
    }

    /// Grows a pond from local minimum `i` with `q` km³: returns the outlet (a sample lower than
    /// the pond level next to it) and the volume left for it, or `None` when all was stored.
    ///
    /// With `land`, the pond grows over land samples from an endorheic sink: it fills the basin
    /// from its floor (up to [`MAX_LAND_POND`] samples, a large closed lake's floor). A lower
    /// sample that drains to the same sink joins it; one that drains elsewhere is the outlet
    /// the full basin overflows at. Without `land.overflow`, or at the size limit, the rest is
    /// laid on the pond as a blanket.
    #[allow(clippy::too_many_arguments)]
    fn pond_fill(
        &mut self,
        g: &ReliefGraph,
        ocean: &[bool],
        i: usize,
        mut q: f64,
        p: &SedimentParams,
        elevation_km: &[f32],
        ff: &impl Fn(usize) -> f64,
        land: Option<LandPond>,
    ) -> (Option<usize>, f64) {
        let on_land = land.is_some();
        let (ocean_cap, max_pond) = if on_land {
            (f64::INFINITY, MAX_LAND_POND)
        } else {
            (-p.coast_depth_km, MAX_POND)
        };
        let in_pond = self.fresh_epoch();
        let cur = |dep: &[f64], j: usize| surface_km(g, elevation_km, ff, dep, j);
        self.pond.clear();
        self.pond_heap.clear();
        self.pond.push(i as u32);
        self.pond_mark[i] = in_pond;
        let mut level = cur(&self.dep, i);
        let mut inv = g.area_km2[i] / ff(i); // km³ per km of level rise
        let q0 = q;
        let mut outlet = None;
        let mut barrier: Option<(f64, usize)> = None;
        loop {
            if self.pond.len() >= max_pond {
                break;
            }
            // Neighbours of the newest pond sample enter the boundary.
            self.push_boundary(g, in_pond, &|k| ocean[k] != on_land, elevation_km, ff);
            let Some(std::cmp::Reverse(key)) = self.pond_heap.pop() else {
                break;
            };
            let bnd = (key & 0xffff_ffff) as usize;
            let cb = cur(&self.dep, bnd);
            let joins =
                land.is_some_and(|l| l.sink_of.get(bnd).is_some_and(|s| l.members.contains(s)));
            if cb < level - TOL_KM {
                if !joins {
                    outlet = Some(bnd);
                    break;
                }
                // A lower sample that drains to this sink (eroded below it this step, or a
                // slope the pond rose past before reaching it) joins the pond: the basin fills
                // its lowest ground first.
                if self.join_pond(g, bnd, cb, in_pond, ff, (&mut q, &mut inv, &mut level)) {
                    break;
                }
                continue;
            }
            if cb >= ocean_cap {
                // Already filled to (nearly) sea level: a barrier the pond cannot rise over.
                // Raise the pond to the cap and look for another outlet; remember the lowest
                // barrier, over which the rest spills if no outlet is found.
                if barrier.is_none_or(|(z, _)| cb < z) {
                    barrier = Some((cb, bnd));
                }
                continue;
            }
            if rise_pond(cb, inv, &mut q, &mut level) {
                break;
            }
            if on_land && !joins {
                // The basin's pass (full to here; the lowest ground of another basin, or of the
                // coast, which may only have the sea below it): the rest goes over it.
                outlet = Some(bnd);
                break;
            }
            self.pond.push(bnd as u32);
            self.pond_mark[bnd] = in_pond;
            inv += g.area_km2[bnd] / ff(bnd);
        }
        if let Some(l) = land
            && (outlet.is_none() || !l.overflow)
        {
            // No outlet (the size limit): a blanket over the pond.
            level += q / inv;
            q = 0.0;
            outlet = None;
        }
        if outlet.is_none() && q > 0.0 {
            // No outlet within reach (a wide flat plain, or a sea walled in by full shelves):
            // fill the pond up to the shelf surface at the coast and spill the rest over the
            // lowest barrier; with no barrier either, lay it on the pond as a blanket.
            let room = ((ocean_cap - level) * inv).max(0.0);
            match barrier {
                Some((_, b)) if q > room => {
                    level = level.max(ocean_cap);
                    q -= room;
                    outlet = Some(b);
                }
                _ => {
                    level += q / inv;
                    q = 0.0;
                }
            }
        }
        self.lay_on_pond(g, q0 - q, level, i, on_land, elevation_km, ff);
        (outlet, q)
    }

    /// Lays `used` km³ on the pond (`self.pond`) that rose to `level`, each sample's share in
    /// proportion to its room under the level (see [`surface_km`]); on `start` when no sample
    /// has room.
    #[allow(clippy::too_many_arguments)]
    fn lay_on_pond(
        &mut self,
        g: &ReliefGraph,
        used: f64,
        level: f64,
        start: usize,
        on_land: bool,
        elevation_km: &[f32],
        ff: &impl Fn(usize) -> f64,
    ) {
        let mut shares = std::mem::take(&mut self.shares);
        shares.clear();
        shares.extend(self.pond.iter().map(|&j| {
            let j = j as usize;
            (
                j,
                (level - surface_km(g, elevation_km, ff, &self.dep, j)).max(0.0) * g.area_km2[j]
                    / ff(j),
            )
        }));
        let wsum: f64 = shares.iter().map(|s| s.1).sum();
        if wsum > 0.0 && used > 0.0 {
            let mut given = 0.0;
            let last = shares.len() - 1;
            for (k, &(j, w)) in shares.iter().enumerate() {
                let v = if k == last {
                    used - given
                } else {
                    used * w / wsum
                };
                given += v;
                self.touch_deposit(j, on_land);
                self.dep[j] += v;
            }
        } else if used > 0.0 {
            self.touch_deposit(start, on_land);
            self.dep[start] += used;
        }
        self.shares = shares;
    }
}
