//! River valleys in the amplified relief (issue 19, item 2): the simulation's drainage network
//! carved into the detailed elevation, so that valley floors fall to the sea, and a measure of
//! the closed pits a heightmap has ([`pit_share`]). docs/amplification.md ("River valleys") has
//! the constants' reasons and the measurements.
//!
//! **The network.** Every land sample of the resampled crust drains to one neighbour (its
//! receiver; [`Network`], from the relief's drainage network). Each such edge is a reach of river:
//! a straight segment (a chord of the sphere) from the sample to its receiver, with the
//! sample's drainage area.
//!
//! **The bed.** Each land sample gets a bed elevation: its water level (the coarse elevation, or
//! a lake's surface) less an incision of 0.6 times the amplitude of the relief primitives around
//! it, raised where needed so that no bed lies below its receiver's (walked from the outlets
//! upstream): beds fall monotonically to the sea. An ocean receiver's bed is sea level. A sample
//! that drains to no sea keeps its water level as its bed (no incision): the valleys would
//! otherwise deepen and widen its closed basin. Along a reach the bed is linear.
//!
//! **The valleys.** At a point, each reach near it offers a surface: its bed at the point's
//! projection on the reach, plus a wall rising at a slope set by the relief around the reach
//! (steep in young ranges, gentle on plains) beyond a flat floor whose half-width grows with
//! the square root of the drainage area. Each reach carries tributaries on two or three levels
//! (junctions every few km, leaving at 45–80° upstream, beds climbing from the parent's, walls
//! steeper), each blended into its parent's wall towards the end of its reach. The point is
//! first moved by a smooth random field, so that the valleys wind.
//!
//! **The cap.** The detailed elevation is the lowest of all these surfaces and a cap: the crust
//! plus half an amplitude plus the primitives' crests on land (their relief beyond a floor of a
//! fraction of an amplitude above the crust), the primitives' elevation at sea.
//! A function without local minima stays without them under such a minimum, so the floors
//! drain: the closed pits left are hollows ringed by the primitives' crests on the divides, and
//! the coarse network's closed basins and lakes.
//!
//! **Locality.** A cubic grid over the unit sphere lists the reaches that can reach each cell;
//! a point reads its own cell. The value at a point depends only on the point and the network,
//! never on the tiling, the output size or the thread count.

use glam::DVec3;

use crate::geometry::SphereMesh;
use crate::random::mix64;

#[cfg(doc)]
use super::procedural::relief_amplitude_m;
use super::procedural::{AmplifyQuery, Cell3};

/// No bed (ocean samples, samples without a reach).
const NO_BED: f32 = f32::NAN;
/// Half-width of the flat floor per square root of drainage area, km per √km².
const FLOOR_KM_PER_SQRT_KM2: f64 = 0.008;
/// Widest floor (half-width), km.
const MAX_FLOOR_KM: f64 = 4.0;
/// Incision of the bed below the coarse water level, as a share of the primitives' amplitude,
/// and its least value, metres.
const INCISION_SHARE: f64 = 0.6;
const MIN_INCISION_M: f64 = 10.0;
/// Scale of the valleys' warp (the displacement per unit of its noise vector), as a share of the
/// first tributaries' spacing, and its wavelength, in the same unit.
const WARP_SHARE: f64 = 0.15;
const WARP_WAVELENGTH_SHARE: f64 = 1.5;
/// Bound on the length of the warp's noise vector (three noise3 values, each within ±1.5): the
/// warp moves a point by at most `WARP_MAX · WARP_SHARE` (about 0.4) of that spacing.
const WARP_MAX: f64 = 2.6;
/// How much the primitives' relief steepens or flattens the valleys' walls: the walls' slope
/// is multiplied by 1 + this × (relief / amplitude), within [`MOD_RANGE`]. A wall whose slope
/// varies from place to place has hollows along it where a band of gentle slope crosses it:
/// 0.6 left 1.2–1.4% of the land of high 100 m tiles in closed pits (docs/amplification.md).
const MOD_GAIN: f64 = 0.3;
const MOD_RANGE: (f64, f64) = (0.6, 1.6);
/// The primitives' elevation caps the valleys' surfaces this many amplitudes above itself.
const CAP_AMPS: f64 = 0.5;
/// A main valley's walls climb to the crust plus this many amplitudes at the end of their run.
const WALL_RISE_AMPS: f64 = 0.6;
/// ... over this share of the distance at which they start to be blended into the cap (so they
/// meet the cap well before: no trace of the blend shows).
const WALL_RUN_SHARE: f64 = 0.75;
/// Crust elevation over which the cap grows from nothing to its full height, metres.
const CAP_RAMP_M: f64 = 100.0;
/// The cap keeps only the primitives' crests standing more than this many amplitudes above the
/// crust (see [`Valleys::new`]; the amplifier's choice).
pub const CREST_FLOOR_AMPS: f32 = 0.15;
/// [`CREST_FLOOR_AMPS`] on a sample with an exemplar.
pub const EXEMPLAR_CREST_FLOOR_AMPS: f32 = 0.3;
/// Reach of a river's valley from its course, in mesh spacings.
const REACH_SPACINGS: f64 = 0.6;
/// Width of the reach grid's cells, in valley reaches (`REACH_SPACINGS` mesh spacings).
const GRID_CELL_REACHES: f64 = 3.0;
/// Outer share of the reach over which a valley's surface is blended up to the cap, so that it
/// ends without a step.
const REACH_FADE_SHARE: f64 = 0.3;
/// Gentlest and steepest wall of a main valley, m/m.
const MIN_WALL_SLOPE: f64 = 0.01;
const MAX_WALL_SLOPE: f64 = 0.8;

/// A drainage network, as the valleys read it: per sample, the same slices as the relief's
/// `Drainage` (see `crate::io::rivers::RiverNetwork::valley_network`).
#[derive(Clone, Copy, Debug)]
pub struct Network<'a> {
    /// Downstream sample of each land sample; ocean samples and endorheic sinks point to
    /// themselves.
    pub receiver: &'a [u32],
    /// Land samples, each after its receiver.
    pub stack: &'a [u32],
    /// Drainage area of each land sample, km².
    pub area_km2: &'a [f64],
    /// Water surface of each land sample (a lake's level, or its elevation), km.
    pub water_level_km: &'a [f32],
    /// True for ocean samples.
    pub ocean: &'a [bool],
}

/// Whether each land sample of `network` drains to the sea (false for samples that drain to a
/// closed basin's sink, and for ocean samples).
pub fn drains_to_sea(network: Network<'_>) -> Vec<bool> {
    let mut open = vec![false; network.receiver.len()];
    for &i in network.stack {
        let i = i as usize;
        let r = network.receiver[i] as usize;
        open[i] = r != i && (network.ocean[r] || open[r]);
    }
    open
}

/// The river valleys of a crust's drainage network, ready to carve amplified relief.
#[derive(Clone, Debug)]
pub struct Valleys {
    /// Receiver of each sample with a reach (`u32::MAX`: none).
    receiver: Vec<u32>,
    /// Bed elevation of each land sample, metres (NaN: none).
    bed_m: Vec<f32>,
    /// Floor half-width of each sample's reach, km.
    floor_km: Vec<f32>,
    /// Wall slope of each sample's reach, m/m.
    slope: Vec<f32>,
    /// Amplitude of each sample's relief primitive, metres.
    amp_m: Vec<f32>,
    /// How far above the crust each sample's crests must stand to show on the cap, metres (see
    /// [`Valleys::new`]).
    crest_floor_m: Vec<f32>,
    /// The plane of each sample's reach: unit vectors downstream and to its left (chords: a
    /// reach is a few tens of km on a planet of thousands), and its length, km (0: no reach).
    frame: Vec<(DVec3, DVec3, f64)>,
    /// Largest distance from a reach at which it can carve, km.
    reach_km: f64,
    /// The reaches that can carve each cell of a cubic grid over the unit sphere (cells
    /// `cell` wide): sorted cell keys, and the reaches (their upstream samples) of each, CSR.
    cell: f64,
    keys: Vec<u64>,
    starts: Vec<u32>,
    reaches: Vec<u32>,
    /// Planet radius, km.
    radius_km: f64,
    /// Tributary levels (see [`trib_levels`]).
    levels: Vec<TribLevel>,
    /// How many of them are carved (the coarsest first; see [`Valleys::set_pixel_km`]).
    detail: usize,
    /// Noise seed of the warp.
    seed: u32,
    /// How far the tributaries of all levels reach from their reach, km (their longest runs
    /// added up).
    trib_reach_km: f64,
}

impl Valleys {
    /// The valleys of `drainage` (a network of the crust on `mesh`); `amp_m` is the amplitude of
    /// each sample's relief primitive, metres (as the amplifier scales it: see
    /// [`relief_amplitude_m`]), which sets the incision and the walls; `crest_floor_m` how far
    /// above the crust each sample's crests must stand to show on the divides' cap, metres
    /// (crests a little above the crust ring closed hollows on the flat cap where no valley
    /// reaches; the amplifier gives [`CREST_FLOOR_AMPS`] of the amplitude, or
    /// [`EXEMPLAR_CREST_FLOOR_AMPS`] with an exemplar, whose blocks of crests ring more of them
    /// than the procedural ridges running along the range; of another length than the mesh: 0
    /// everywhere); `seed` seeds the winding.
    pub fn new(
        mesh: &SphereMesh,
        drainage: Network<'_>,
        amp_m: Vec<f32>,
        crest_floor_m: Vec<f32>,
        seed: u32,
    ) -> Self {
        use rayon::prelude::*;
        let n = mesh.len();
        let crest_floor_m = if crest_floor_m.len() == n {
            crest_floor_m
        } else {
            vec![0.0; n]
        };
        let spacing_km = mesh.mean_spacing_rad() * mesh.radius_km;
        let max_floor = MAX_FLOOR_KM.min(0.15 * spacing_km);
        let reach_km = REACH_SPACINGS * spacing_km;
        let mut receiver = vec![u32::MAX; n];
        let mut bed_m = vec![NO_BED; n];
        let mut floor_km = vec![0.0f32; n];
        let mut slope = vec![0.0f32; n];
        let ok = drainage.receiver.len() == n
            && drainage.area_km2.len() == n
            && drainage.water_level_km.len() == n
            && drainage.ocean.len() == n
            && amp_m.len() == n;
        if ok {
            let open = drains_to_sea(drainage);
            // Beds, from the outlets upstream (the stack lists every land sample after its
            // receiver).
            for &i in drainage.stack {
                let i = i as usize;
                let r = drainage.receiver[i] as usize;
                let amp = f64::from(amp_m[i]);
                let level = 1000.0 * f64::from(drainage.water_level_km[i]);
                // A sample draining to no sea (to a closed basin's sink) keeps its level: cut
                // below it, the valleys would deepen and widen the closed basin, all of it
                // draining into its sink.
                let raw = if !open[i] {
                    level
                } else {
                    level - (INCISION_SHARE * amp).max(MIN_INCISION_M)
                };
                let below = if r == i {
                    level
                } else if drainage.ocean[r] {
                    0.0
                } else {
                    f64::from(bed_m[r])
                };
                let bed = raw.max(below);
                bed_m[i] = bed as f32;
                if r != i {
                    receiver[i] = r as u32;
                }
                let area = drainage.area_km2[i].max(0.0);
                floor_km[i] = (FLOOR_KM_PER_SQRT_KM2 * area.sqrt()).min(max_floor) as f32;
                // The main valley's walls climb from the bed to the primitives' crests over the
                // reach: tributaries cut into them, the primitives' noise caps the divides.
                let rise_m = level - bed + WALL_RISE_AMPS * amp;
                let run_km = WALL_RUN_SHARE * (1.0 - REACH_FADE_SHARE) * reach_km;
                slope[i] =
                    (rise_m / (1000.0 * run_km)).clamp(MIN_WALL_SLOPE, MAX_WALL_SLOPE) as f32;
            }
        }
        let levels = trib_levels(spacing_km);
        // Cells three valley reaches wide: each reach is listed in a few cells (the grid holds
        // about two entries a sample), and a block of pixels reads one or two cells' lists.
        let cell = GRID_CELL_REACHES * reach_km / mesh.radius_km;
        let frame = (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .map(|i| {
                let r = receiver[i];
                if r == u32::MAX {
                    return (DVec3::ZERO, DVec3::ZERO, 0.0);
                }
                let (a, b) = (mesh.positions[i], mesh.positions[r as usize]);
                let ab = b - a;
                let len = ab.length() * mesh.radius_km;
                if len <= 0.0 {
                    return (DVec3::ZERO, DVec3::ZERO, 0.0);
                }
                let u = ab.normalize();
                (u, a.cross(u).normalize_or_zero(), len)
            })
            .collect();
        let t = std::time::Instant::now();
        let warp_km = levels
            .first()
            .map_or(0.0, |l| WARP_MAX * WARP_SHARE * l.spacing_km);
        let (keys, starts, reaches) =
            reach_grid(mesh, &receiver, cell, (reach_km + warp_km) / mesh.radius_km);
        tracing::debug!(
            cells = keys.len(),
            entries = reaches.len(),
            ms = t.elapsed().as_secs_f64() * 1e3,
            "valleys' reach grid"
        );
        Self {
            cell,
            keys,
            starts,
            reaches,
            receiver,
            bed_m,
            floor_km,
            slope,
            amp_m,
            crest_floor_m,
            frame,
            reach_km,
            trib_reach_km: levels.iter().map(|l| l.max_len_km).sum(),
            detail: levels.len(),
            seed,
            levels,
            radius_km: mesh.radius_km,
        }
    }

    /// Carves only the tributary levels that an output of `pixel_km` pixels resolves: those
    /// whose junctions lie at least [`LOD_PIXELS`] pixels apart (all of them at 100 m; only the
    /// main valleys on a global map of 5 km pixels, where the tributaries would alias into a
    /// maze). The value at a point then depends on the pixel size, never on the tiling.
    pub fn set_pixel_km(&mut self, pixel_km: f64) {
        self.detail = self
            .levels
            .iter()
            .take_while(|l| l.spacing_km >= LOD_PIXELS * pixel_km)
            .count();
        self.trib_reach_km = self.levels[..self.detail]
            .iter()
            .map(|l| l.max_len_km)
            .sum();
    }

    /// Tributary levels carved (see [`Self::set_pixel_km`]).
    pub fn detail_levels(&self) -> usize {
        self.detail
    }

    /// How far a carved value can stand above the primitives' own value, metres (the cap on land
    /// lies half an amplitude above the crust, with the primitives' crests on top).
    pub fn max_rise_m(&self) -> f32 {
        self.amp_m.iter().fold(0.0f32, |m, &a| m.max(a)) * CAP_AMPS as f32
    }

    /// `p` moved within the tangent plane by a smooth random field (at most about 0.4 of the
    /// first tributaries' spacing, see [`WARP_MAX`]), so that valleys wind instead of running
    /// straight; small enough against its wavelength that the warp folds nothing over.
    /// `memo` keeps the warp's noise cell from one point to the next (the same bits).
    fn warp(&self, p: DVec3, memo: &mut Cell3<3>) -> DVec3 {
        let Some(first) = self.levels.first() else {
            return p;
        };
        let wl = WARP_WAVELENGTH_SHARE * first.spacing_km;
        let f = (self.radius_km / wl) as f32;
        let (x, y, z) = (p.x as f32 * f, p.y as f32 * f, p.z as f32 * f);
        let s = self.seed ^ 0x7761_7270;
        // Noises of seeds s, s + 1 and s + 2 at the same point.
        let [wx, wy, wz] = memo.noise3(s, x, y, z);
        let w = DVec3::new(f64::from(wx), f64::from(wy), f64::from(wz));
        let w = w - p * p.dot(w);
        (p + w * (WARP_SHARE * first.spacing_km / self.radius_km)).normalize()
    }

    /// The carved elevation at query `q`, metres: `amplified` (the primitives' value there)
    /// with the valleys of the reaches near it; `base` is the crust elevation there (the
    /// barycentric one). [`Self::carve_points`] does many points at once, for less.
    pub fn carve(&self, mesh: &SphereMesh, q: &AmplifyQuery, base: f32, amplified: f32) -> f32 {
        thread_local! {
            // The plan's buffers, kept from one point to the next.
            static PLAN: std::cell::RefCell<Plan> = std::cell::RefCell::new(Plan::default());
        }
        let mut z = [amplified];
        PLAN.with(|plan| {
            self.carve_points(
                mesh,
                std::slice::from_ref(q),
                &[base],
                &mut z,
                &mut plan.borrow_mut(),
            );
        });
        z[0]
    }

    /// [`Self::carve`] for a set of points at once: `amplified[k]` (the primitives' value at
    /// query `qs[k]`, whose crust elevation is `bases[k]`) becomes the carved value there, the
    /// same bits as [`Self::carve`] gives it alone. Any set works; points close together (a
    /// block of pixels) share the search for the tributaries near them. `plan` is scratch space,
    /// kept between calls to save allocations.
    pub fn carve_points(
        &self,
        mesh: &SphereMesh,
        qs: &[AmplifyQuery],
        bases: &[f32],
        amplified: &mut [f32],
        plan: &mut Plan,
    ) {
        plan.points.clear();
        plan.candidates.clear();
        plan.cells.clear();
        // The previous point's cell (points in a row share most cells).
        let mut last_cell: Option<(u64, Result<usize, usize>)> = None;
        for (k, (q, (&base, z))) in qs
            .iter()
            .zip(bases.iter().zip(amplified.iter_mut()))
            .enumerate()
        {
            let corners = [q.c0 as usize, q.c1 as usize, q.c2 as usize];
            let p0 = DVec3::new(f64::from(q.dx), f64::from(q.dy), f64::from(q.dz));
            let amp_here = f64::from(
                q.w0 * self.amp_m[corners[0]]
                    + q.w1 * self.amp_m[corners[1]]
                    + q.w2 * self.amp_m[corners[2]],
            )
            .max(30.0);
            // On land the valleys' walls are capped by the crust raised a little, with the
            // primitives' crests (their relief above the crust, less the floor of
            // `crest_floor_m`) on top: the divides keep their
            // peaks, and their cols drain (the crust is flat or tilted within a triangle, so the
            // cap has no pit of its own). At sea the cap is the primitives' elevation.
            // Continuous: the land's cap takes over within the first CAP_RAMP_M of crust
            // elevation.
            let amplified = *z;
            let land = (f64::from(base) / CAP_RAMP_M).clamp(0.0, 1.0);
            let relief = f64::from(amplified - base);
            let floor = f64::from(
                q.w0 * self.crest_floor_m[corners[0]]
                    + q.w1 * self.crest_floor_m[corners[1]]
                    + q.w2 * self.crest_floor_m[corners[2]],
            );
            let crests = (relief - floor).max(0.0);
            let land_cap = f64::from(base) + CAP_AMPS * amp_here + crests;
            let cap = f64::from(amplified) + (land_cap - f64::from(amplified)) * land;
            // The grid lists the reaches within reach of any point of a cell moved by at most
            // the warp, so the cell of the point itself is the one to read.
            let key = cell_key(p0, self.cell);
            let cell = match last_cell {
                Some((k, c)) if k == key => c,
                _ => {
                    let c = self.keys.binary_search(&key);
                    if let Ok(c) = c
                        && !plan.cells.contains(&c)
                    {
                        // A new cell: its reaches join the candidates.
                        plan.cells.push(c);
                        plan.candidates.extend_from_slice(
                            &self.reaches[self.starts[c] as usize..self.starts[c + 1] as usize],
                        );
                    }
                    last_cell = Some((key, c));
                    c
                }
            };
            if cell.is_err() {
                // No reach comes this close.
                *z = cap as f32;
                continue;
            }
            // The warp moves the valleys by less than the tributaries' spacing: without them
            // (an output too coarse to show them), it would not show either.
            let p = if self.detail == 0 {
                p0
            } else {
                self.warp(p0, &mut plan.warp)
            };
            let m = (1.0 + MOD_GAIN * relief / amp_here).clamp(MOD_RANGE.0, MOD_RANGE.1);
            plan.points.push(PlanPoint { k, p, cap, m });
        }
        if plan.points.is_empty() {
            return;
        }
        // A reach listed for another point's cell lies beyond the reach of this one (it is
        // skipped point by point), so the union of the points' lists serves them all.
        plan.candidates.sort_unstable();
        plan.candidates.dedup();
        // The points lie within `rb` km of `c` (in every reach's plane too: the plane's
        // coordinates are an orthonormal projection of the scaled position).
        let c = plan
            .points
            .iter()
            .fold(DVec3::ZERO, |s, pt| s + pt.p)
            .normalize_or_zero();
        let rb = plan
            .points
            .iter()
            .fold(0.0f64, |r, pt| r.max((pt.p - c).length()))
            * self.radius_km;
        self.build_plan(mesh, c, rb, plan);
        let levels = &self.levels[..self.detail];
        // How far the tributaries below each level run, summed once here (the same sums
        // [`Tree::surface`] made per call).
        let mut below = [0.0f64; MAX_LEVELS + 1];
        for (l, b) in below.iter_mut().enumerate().take(levels.len()) {
            *b = levels[l + 1..].iter().map(|l| l.max_len_km).sum();
        }
        for pt in &plan.points {
            let (p, m, cap) = (pt.p, pt.m, pt.cap);
            // Nothing above the cap matters.
            let mut surface = cap;
            for pr in &plan.reaches {
                let i = pr.i as usize;
                let (u, nrm, len) = self.frame[i];
                let rel = (p - mesh.positions[i]) * self.radius_km;
                let (x, y) = (rel.dot(u), rel.dot(nrm));
                // Distance to the reach's course; beyond the reach it offers nothing, and over
                // its outer part its surface is blended up to the cap (continuous, so no seam
                // where a point stops seeing this reach).
                let xc = x.clamp(0.0, len);
                let d_main = ((x - xc) * (x - xc) + y * y).sqrt();
                if d_main >= self.reach_km {
                    continue;
                }
                let blend_from = (1.0 - REACH_FADE_SHARE) * self.reach_km;
                let t = ((d_main - blend_from) / (self.reach_km - blend_from)).clamp(0.0, 1.0);
                // No valley of this reach's comes below its lowest bed plus the wall climbed
                // from the nearest its tributaries reach: skip it if that is no lower than what
                // is there.
                let bound = pr.seg.bed_a.min(pr.seg.bed_b)
                    + pr.slope
                        * m
                        * (d_main - self.trib_reach_km - pr.floor.max(TRIB_FLOOR_KM)).max(0.0);
                if bound >= surface {
                    continue;
                }
                let tree = Tree {
                    levels,
                    below: &below,
                    nodes: &plan.nodes,
                    floor_km: pr.floor,
                    m,
                };
                let s = tree.surface(&pr.seg, &pr.geo, pr.children, (x, y), 0, pr.slope, surface);
                // Over the outer part of the reach, blended up to the cap: at the reach's edge
                // it is nowhere below the cap, so leaving it out there changes nothing.
                surface = surface.min(s + t * t * (cap - s).max(0.0));
            }
            amplified[pt.k] = surface as f32;
        }
    }

    /// The reaches of `plan.candidates` and their tributaries (to the last level carved) that
    /// can carve a point within `rb` km of `c`.
    fn build_plan(&self, mesh: &SphereMesh, c: DVec3, rb: f64, plan: &mut Plan) {
        plan.reaches.clear();
        plan.nodes.clear();
        let levels = &self.levels[..self.detail];
        for &i in &plan.candidates {
            let i = i as usize;
            let r = self.receiver[i];
            if r == u32::MAX {
                continue;
            }
            let (u, nrm, len) = self.frame[i];
            if len <= 0.0 {
                continue;
            }
            let rel = (c - mesh.positions[i]) * self.radius_km;
            let (x, y) = (rel.dot(u), rel.dot(nrm));
            let xc = x.clamp(0.0, len);
            let d_main = ((x - xc) * (x - xc) + y * y).sqrt();
            if d_main - rb >= self.reach_km {
                continue;
            }
            let bed_a = f64::from(self.bed_m[i]);
            // An ocean receiver (no bed) is at sea level; `bed_a` was raised to it.
            let bed_b = match self.bed_m[r as usize] {
                b if b.is_nan() => 0.0,
                b => f64::from(b),
            };
            let seg = Seg {
                a: (0.0, 0.0),
                b: (len, 0.0),
                bed_a,
                bed_b,
            };
            let slope = 1000.0 * f64::from(self.slope[i]);
            let geo = Geo::of(&seg);
            let children = plan_tributaries(
                levels,
                i as u64,
                &seg,
                &geo,
                0,
                slope,
                (x, y),
                rb,
                &mut plan.nodes,
            );
            plan.reaches.push(PlanReach {
                i: i as u32,
                seg,
                geo,
                slope,
                floor: f64::from(self.floor_km[i]),
                children,
            });
        }
    }
}

/// Scratch space of [`Valleys::carve_points`]: the points, the reaches near them, and the
/// tributaries that can carve them.
#[derive(Clone, Debug, Default)]
pub struct Plan {
    points: Vec<PlanPoint>,
    cells: Vec<usize>,
    candidates: Vec<u32>,
    reaches: Vec<PlanReach>,
    nodes: Vec<Node>,
    /// The warp's last noise cell (see [`Cell3`]).
    warp: Cell3<3>,
}

/// A point to carve: its index in the call, its (warped) position, cap and wall factor.
#[derive(Clone, Copy, Debug)]
struct PlanPoint {
    k: usize,
    p: DVec3,
    cap: f64,
    m: f64,
}

/// A reach in a plan: its upstream sample, its course in its own plane (km; beds in metres),
/// the main valley's wall slope (m/km) and floor (km), and its tributaries (`Plan::nodes`).
#[derive(Clone, Copy, Debug)]
struct PlanReach {
    i: u32,
    seg: Seg,
    geo: Geo,
    slope: f64,
    floor: f64,
    children: (u32, u32),
}

/// A tributary in a plan: its course in its reach's plane, its wall slope (m/km), the side of
/// its parent it lies on (±1), and its own tributaries (a range of `Plan::nodes`).
#[derive(Clone, Copy, Debug)]
struct Node {
    seg: Seg,
    geo: Geo,
    slope: f64,
    side: f64,
    children: (u32, u32),
}

/// The key of the grid cell (`cell` wide, unit-sphere units) holding `p`.
fn cell_key(p: DVec3, cell: f64) -> u64 {
    const OFF: i64 = 1 << 20;
    let c = |v: f64| ((v / cell).floor() as i64 + OFF) as u64 & 0x1f_ffff;
    c(p.x) << 42 | c(p.y) << 21 | c(p.z)
}

/// The reach grid of [`Valleys`]: every reach (sample → receiver) listed in each cell whose
/// centre lies within its reach (`reach` plus half a cell's diagonal, unit-sphere units) of the
/// reach's course, so that a point sees, in its own cell, every reach within `reach` of it.
fn reach_grid(
    mesh: &SphereMesh,
    receiver: &[u32],
    cell: f64,
    reach: f64,
) -> (Vec<u64>, Vec<u32>, Vec<u32>) {
    use rayon::prelude::*;
    let half_diag = 0.5 * cell * 3f64.sqrt();
    // Each reach's cells come from a lazy iterator (no vector per reach).
    let mut pairs: Vec<(u64, u32)> = (0..receiver.len())
        .into_par_iter()
        .with_min_len(4096)
        .flat_map_iter(|i| {
            let r = receiver[i];
            let (a, b) = if r == u32::MAX {
                (DVec3::ZERO, DVec3::ZERO)
            } else {
                (mesh.positions[i], mesh.positions[r as usize])
            };
            let lo = a.min(b) - DVec3::splat(reach);
            let hi = a.max(b) + DVec3::splat(reach);
            let idx = |v: f64| (v / cell).floor() as i64;
            // No cell for a sample without a receiver (an empty range).
            let (x0, x1) = if r == u32::MAX {
                (1, 0)
            } else {
                (idx(lo.x), idx(hi.x))
            };
            let (y0, y1, z0, z1) = (idx(lo.y), idx(hi.y), idx(lo.z), idx(hi.z));
            let ab = b - a;
            (x0..=x1).flat_map(move |x| {
                (y0..=y1).flat_map(move |y| {
                    (z0..=z1).filter_map(move |z| {
                        let c = DVec3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * cell;
                        if (c.length() - 1.0).abs() > half_diag {
                            return None; // the cell holds no point of the sphere
                        }
                        let t = ((c - a).dot(ab) / ab.length_squared().max(1e-30)).clamp(0.0, 1.0);
                        ((c - (a + ab * t)).length() <= reach + half_diag)
                            .then(|| (cell_key(c, cell), i as u32))
                    })
                })
            })
        })
        .collect();
    pairs.par_sort_unstable();
    let mut keys = Vec::new();
    let mut starts = Vec::new();
    let mut reaches = Vec::with_capacity(pairs.len());
    for (k, r) in pairs {
        if keys.last() != Some(&k) {
            keys.push(k);
            starts.push(reaches.len() as u32);
        }
        reaches.push(r);
    }
    starts.push(reaches.len() as u32);
    (keys, starts, reaches)
}

/// A valley segment in a reach's plane (km): from `a` (upstream) to `b` (downstream), its bed
/// linear from `bed_a` to `bed_b` (metres, `bed_a ≥ bed_b`).
#[derive(Clone, Copy, Debug)]
struct Seg {
    a: (f64, f64),
    b: (f64, f64),
    bed_a: f64,
    bed_b: f64,
}

/// What a point's distance to a segment needs of it, computed once per segment: its vector
/// (km), length, unit direction, and the reciprocals of its length and of its squared length
/// (at least 1e-30), so that points multiply instead of dividing.
#[derive(Clone, Copy, Debug)]
struct Geo {
    dx: f64,
    dy: f64,
    len: f64,
    ux: f64,
    uy: f64,
    inv_len: f64,
    inv_len2: f64,
}

impl Geo {
    fn of(s: &Seg) -> Self {
        let (dx, dy) = (s.b.0 - s.a.0, s.b.1 - s.a.1);
        let l2 = dx * dx + dy * dy;
        let len = l2.sqrt();
        Self {
            dx,
            dy,
            len,
            ux: dx / len,
            uy: dy / len,
            inv_len: 1.0 / len,
            inv_len2: 1.0 / l2.max(1e-30),
        }
    }
}

/// Where `p` lies against segment `s` (whose [`Geo`] is `g`): its position along the segment's
/// line (km), the clamped share of the segment at its projection, its distance to the segment,
/// and its signed distance out from the line (positive on the left), km. The segment must not
/// be degenerate (length over 1e-9 km).
fn project(s: &Seg, g: &Geo, p: (f64, f64)) -> (f64, f64, f64, f64) {
    let (rx, ry) = (p.0 - s.a.0, p.1 - s.a.1);
    let along = rx * g.ux + ry * g.uy;
    let t = (along * g.inv_len).clamp(0.0, 1.0);
    let (cx, cy) = (rx - g.dx * t, ry - g.dy * t);
    let d = (cx * cx + cy * cy).sqrt();
    let across = ry * g.ux - rx * g.uy;
    (along, t, d, across)
}

/// Squared distance from `p` to segment `s` (whose [`Geo`] is `g`), km².
fn seg_distance2(s: &Seg, g: &Geo, p: (f64, f64)) -> f64 {
    let (dx, dy) = (g.dx, g.dy);
    let (rx, ry) = (p.0 - s.a.0, p.1 - s.a.1);
    let t = ((rx * dx + ry * dy) * g.inv_len2).clamp(0.0, 1.0);
    (rx - dx * t).powi(2) + (ry - dy * t).powi(2)
}

/// One level of tributaries: junction spacing along the parent, longest tributary, and the
/// distance from its course within which a tributary carves (it is blended out of the way over
/// half as much again), km.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TribLevel {
    spacing_km: f64,
    max_len_km: f64,
    influence_km: f64,
}

/// A tributary level is carved only where its junctions lie this many output pixels apart.
pub const LOD_PIXELS: f64 = 2.0;

/// Most tributary levels below a reach.
const MAX_LEVELS: usize = 4;
/// The first level on a mesh of 500,000 samples (32 km spacing): junctions every 5 km,
/// tributaries up to 14 km long, carving within 4 km; it scales with the mesh spacing, so that
/// the tributaries fill the land between reaches at any resolution.
const FIRST_LEVEL: TribLevel = TribLevel {
    spacing_km: 5.0,
    max_len_km: 14.0,
    influence_km: 4.0,
};
/// Mesh spacing the first level is given for, km.
const FIRST_LEVEL_SPACING_KM: f64 = 32.0;
/// Each level below is this much smaller (spacing, length, influence).
const LEVEL_RATIO: (f64, f64, f64) = (0.3, 0.21, 0.375);
/// Levels stop once the junctions would come closer than this, km (a 100 m map shows valleys
/// about a kilometre apart).
const FINEST_SPACING_KM: f64 = 0.9;

/// The tributary levels of a mesh of mean spacing `spacing_km`.
fn trib_levels(spacing_km: f64) -> Vec<TribLevel> {
    let s = (spacing_km / FIRST_LEVEL_SPACING_KM).max(0.25);
    let mut l = TribLevel {
        spacing_km: FIRST_LEVEL.spacing_km * s,
        max_len_km: FIRST_LEVEL.max_len_km * s,
        influence_km: FIRST_LEVEL.influence_km * s,
    };
    let mut out = Vec::new();
    while out.len() < MAX_LEVELS && (out.is_empty() || l.spacing_km >= FINEST_SPACING_KM) {
        out.push(l);
        l = TribLevel {
            spacing_km: l.spacing_km * LEVEL_RATIO.0,
            max_len_km: l.max_len_km * LEVEL_RATIO.1,
            influence_km: l.influence_km * LEVEL_RATIO.2,
        };
    }
    out
}

/// Rise of a tributary's bed across its parent's wall, as a share of the wall's rise.
const TRIB_BED_SHARE: f64 = 0.3;
/// A tributary's walls are this much steeper than its parent's.
const TRIB_STEEPER: f64 = 1.3;
/// Steepest tributary wall, m/km.
const MAX_TRIB_SLOPE_M_PER_KM: f64 = 800.0;
/// Half-width of a tributary's floor, km.
const TRIB_FLOOR_KM: f64 = 0.08;
/// The stream constant of `crate::random::hash3` (the tributaries' bits are its values).
const GOLDEN: u64 = 0x9e37_79b9_7f4a_7c15;
/// Slack of the lower bounds that skip tributaries, metres: a bound this close to what a point
/// has is not trusted to the last rounding.
const BOUND_MARGIN_M: f64 = 1e-6;

/// The tributaries of `seg` (a reach's course, or a tributary's, in the reach's plane) at
/// `level` and below, appended to `nodes`, that can carve a point within `rb` km of `c` (the
/// same plane): the range of `nodes` holding the first level's. `key` is the reach's random key,
/// `slope` `seg`'s wall slope (m/km).
#[allow(clippy::too_many_arguments)]
fn plan_tributaries(
    levels: &[TribLevel],
    key: u64,
    seg: &Seg,
    geo: &Geo,
    level: usize,
    slope: f64,
    c: (f64, f64),
    rb: f64,
    nodes: &mut Vec<Node>,
) -> (u32, u32) {
    let start = nodes.len() as u32;
    let Some(lv) = levels.get(level) else {
        return (start, start);
    };
    let Geo { len, ux, uy, .. } = *geo;
    if len <= 1e-9 {
        return (start, start);
    }
    let (along, _, d, across) = project(seg, geo, c);
    let (spacing, max_len) = (lv.spacing_km, lv.max_len_km);
    let max_len = max_len.min(0.6 * len.max(spacing));
    // A tributary carves within `rho` of its course and is blended into its parent's wall over
    // the next `fade` (so that it ends without a step); every tributary lies within `max_len`
    // of its parent.
    let rho = lv.influence_km;
    let fade = 0.5 * rho;
    let reach = rho + fade;
    if d - rb > max_len + reach {
        return (start, start);
    }
    // What every tributary of this level shares: the hash of the reach and level, and the
    // tributaries' wall slope.
    let key_level = mix64(key ^ mix64((0x7661_6c6c + level as u64).wrapping_add(GOLDEN)));
    let steeper = (slope * TRIB_STEEPER)
        .min(MAX_TRIB_SLOPE_M_PER_KM)
        .max(slope);
    let last_k = (len / spacing) as i64;
    for side in [-1.0f64, 1.0] {
        // The points' distance out from the parent on this side (negative: on the other side).
        let out = side * across;
        let (out_lo, out_hi) = (out - rb, out + rb);
        if out_hi <= -reach {
            continue; // every tributary of this side lies beyond the parent
        }
        // A tributary runs upstream from its junction at 45–80° to its parent: within `reach`
        // of a point only if its junction is no more than `reach` upstream of the point's
        // position along the parent, nor more than its run (`max_len`·cos 45°) downstream; and
        // within `reach` of the line through it at its angle: the point's position plus
        // out·cot θ (cot θ within 0.18–1), give or take reach / sin θ (at most √2·reach).
        let slack = std::f64::consts::SQRT_2 * reach;
        let (along_lo, along_hi) = (along - rb, along + rb);
        let lo = (along_lo - reach).max(along_lo + (0.17 * out_lo).min(out_lo) - slack);
        let hi = (along_hi + reach + std::f64::consts::FRAC_1_SQRT_2 * max_len)
            .min(along_hi + out_hi.max(0.17 * out_hi) + slack);
        // Junction k lies within [k + 0.2, k + 0.8] spacings (a little slack either way).
        let k0 = ((lo / spacing - 0.8).floor() as i64).max(0);
        let k1 = ((hi / spacing - 0.2).ceil() as i64).min(last_k);
        for k in k0..=k1 {
            let kk = k as u64;
            // One hash, three 21-bit uniforms: the junction's jitter, the angle, the length.
            let bits = mix64(key_level.wrapping_add(kk << 1 | u64::from(side > 0.0)));
            let h = |n: u64| ((bits >> (21 * n)) & 0x1f_ffff) as f64 / (1u64 << 21) as f64;
            let xk = (kk as f64 + 0.5 + 0.6 * (h(0) - 0.5)) * spacing;
            if !(0.0..=len).contains(&xk) {
                continue;
            }
            let l = max_len * (0.5 + 0.5 * h(2));
            let (jx, jy) = (seg.a.0 + ux * xk, seg.a.1 + uy * xk);
            // The whole tributary lies within `l` of its junction.
            let (ex, ey) = (c.0 - jx, c.1 - jy);
            let far = l + reach + rb + 1e-6;
            if ex * ex + ey * ey > far * far {
                continue;
            }
            let bed_j = seg.bed_a + (seg.bed_b - seg.bed_a) * (xk / len);
            // The angle to the parent, 45–80° (its tangent 1–5.7), without trigonometry.
            let tan = 1.0 + 4.7 * h(1);
            let (cos, sin) = (
                1.0 / (1.0 + tan * tan).sqrt(),
                tan / (1.0 + tan * tan).sqrt(),
            );
            // The tributary's head, upstream of the junction on its side.
            let (tx, ty) = (-cos * l, side * sin * l);
            let head = (jx + ux * tx - uy * ty, jy + uy * tx + ux * ty);
            // The head lies l·sin θ out on the parent's wall: its bed climbs part of that rise.
            let trib = Seg {
                a: head,
                b: (jx, jy),
                bed_a: bed_j + TRIB_BED_SHARE * slope * l * sin,
                bed_b: bed_j,
            };
            nodes.push(Node {
                seg: trib,
                geo: Geo::of(&trib),
                slope: steeper,
                side,
                children: (0, 0),
            });
        }
    }
    let end = nodes.len() as u32;
    for n in start..end {
        let node = nodes[n as usize];
        let children = plan_tributaries(
            levels,
            key,
            &node.seg,
            &node.geo,
            level + 1,
            node.slope,
            c,
            rb,
            nodes,
        );
        nodes[n as usize].children = children;
    }
    (start, end)
}

/// A reach's tree of tributaries in a plan, as one point sees it: the levels carved (and how far
/// the tributaries below each run), the plan's tributaries, the main valley's floor (km), and the point's wall factor.
struct Tree<'a> {
    levels: &'a [TribLevel],
    /// Per level: how far the tributaries of the levels below it run, summed, km.
    below: &'a [f64],
    nodes: &'a [Node],
    floor_km: f64,
    m: f64,
}

impl Tree<'_> {
    /// The lowest valley surface at `p` of `seg` (at `level`: 0 for the reach's main valley)
    /// and of its tributaries `children` (a range of the plan's nodes), metres; `slope` is
    /// `seg`'s wall slope (m/km). Tributaries that cannot come below `ub` (what the point
    /// already has) are skipped: the answer is exact wherever it is below `ub`.
    #[allow(clippy::too_many_arguments)]
    fn surface(
        &self,
        seg: &Seg,
        geo: &Geo,
        children: (u32, u32),
        p: (f64, f64),
        level: usize,
        slope: f64,
        ub: f64,
    ) -> f64 {
        let m = self.m;
        let len = geo.len;
        if len <= 1e-9 {
            return f64::INFINITY;
        }
        let (_, t, d, across) = project(seg, geo, p);
        let floor = if level == 0 {
            self.floor_km
        } else {
            TRIB_FLOOR_KM
        };
        let out = (d - floor).max(0.0);
        let own = seg.bed_a + (seg.bed_b - seg.bed_a) * t + slope * m * out;
        let mut best = own;
        let Some(lv) = self.levels.get(level) else {
            return best;
        };
        let (spacing, max_len) = (lv.spacing_km, lv.max_len_km);
        let max_len = max_len.min(0.6 * len.max(spacing));
        let rho = lv.influence_km;
        let fade = 0.5 * rho;
        if d > max_len + rho + fade {
            return best;
        }
        let reach = rho + fade;
        // How far the tributaries' own tributaries run.
        let below = self.below[level];
        for node in &self.nodes[children.0 as usize..children.1 as usize] {
            let trib = &node.seg;
            let bed_j = trib.bed_b;
            // A tributary's bed climbs across its parent's wall at TRIB_BED_SHARE of its slope
            // (and its own tributaries' beds from there), and its walls are steeper than that:
            // nothing of it comes below its junction's bed plus that climb to `p`.
            let climb =
                TRIB_BED_SHARE * slope * (node.side * across - below - TRIB_FLOOR_KM).max(0.0);
            if bed_j + climb + BOUND_MARGIN_M >= best.min(ub) {
                continue;
            }
            let dt2 = seg_distance2(trib, &node.geo, p);
            if dt2 >= reach * reach {
                continue;
            }
            let dt = dt2.sqrt();
            // Over the outer part of its reach, blended up to its parent's own surface: at the
            // edge it is nowhere below its parent, so leaving it out there changes nothing.
            let x = ((dt - rho) / fade).clamp(0.0, 1.0);
            // Nothing in the tributary's tree comes below its junction's bed plus the wall
            // climbed from the nearest its own tributaries reach: skip it if that is no lower
            // than what is there (the same bits: the minimum would not change).
            let bound = best.min(ub);
            if bed_j + node.slope * m * (dt - below - TRIB_FLOOR_KM).max(0.0) >= bound {
                continue;
            }
            let sub = self.surface(
                trib,
                &node.geo,
                node.children,
                p,
                level + 1,
                node.slope,
                bound,
            );
            best = best.min(sub + x * x * (own - sub).max(0.0));
        }
        best
    }
}

/// Closed pits of a heightmap under D8 flow routing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PitShare {
    /// Cells above sea level (elevation > 0) counted.
    pub land_cells: usize,
    /// Of those, cells in closed pits deeper than the depth asked (their level once every
    /// depression is filled to its spill point, less their elevation).
    pub pit_cells: usize,
}

impl PitShare {
    /// Pit cells as a share of the land cells (0 without land).
    pub fn share(&self) -> f64 {
        if self.land_cells == 0 {
            0.0
        } else {
            self.pit_cells as f64 / self.land_cells as f64
        }
    }
}

/// The closed pits of a `width × height` heightmap `z` (row-major, metres) under D8 routing:
/// every depression is filled to its spill point (priority flood from the map's border and
/// from the sea, cells at or below 0 m), and a land cell counts as a pit when its filled level
/// is more than `min_depth_m` above it. Cells with `skip[i]` set (lakes the coarse network
/// records, say) are left out of the count but still drain. NaN counts as sea.
pub fn pit_share(
    z: &[f32],
    width: usize,
    height: usize,
    min_depth_m: f32,
    skip: Option<&[bool]>,
) -> PitShare {
    pit_depths(z, width, height, min_depth_m, skip, &mut Vec::new())
}

/// [`pit_share`], also giving every cell's depth below its filled level in `depth_m` (0 outside
/// depressions), metres.
pub fn pit_depths(
    z: &[f32],
    width: usize,
    height: usize,
    min_depth_m: f32,
    skip: Option<&[bool]>,
    depth_m: &mut Vec<f32>,
) -> PitShare {
    pit_depths_with_outlets(z, width, height, min_depth_m, skip, None, depth_m)
}

/// [`pit_depths`] with more outlets than the sea and the border: cells with `outlets[i]` set
/// drain wherever they are (the sinks of closed basins the coarse network records, say: water
/// that reaches them has reached its end, as at the sea).
pub fn pit_depths_with_outlets(
    z: &[f32],
    width: usize,
    height: usize,
    min_depth_m: f32,
    skip: Option<&[bool]>,
    outlets: Option<&[bool]>,
    depth_m: &mut Vec<f32>,
) -> PitShare {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let n = width * height;
    assert_eq!(z.len(), n, "heightmap size");
    let key = crate::geometry::order_bits;
    let mut level = vec![f32::NAN; n];
    let mut done = vec![false; n];
    let mut heap = BinaryHeap::new();
    for i in 0..n {
        let (x, y) = (i % width, i / width);
        let sea = !(z[i] > 0.0);
        let outlet = outlets.is_some_and(|o| o[i]);
        if sea || outlet || x == 0 || y == 0 || x + 1 == width || y + 1 == height {
            let v = if sea { 0.0f32.min(z[i]) } else { z[i] };
            let v = if v.is_nan() { 0.0 } else { v };
            level[i] = v;
            done[i] = true;
            heap.push(Reverse((key(v), i as u32)));
        }
    }
    while let Some(Reverse((_, i))) = heap.pop() {
        let i = i as usize;
        let (x, y) = ((i % width) as isize, (i / width) as isize);
        let li = level[i];
        for dy in -1..=1isize {
            for dx in -1..=1isize {
                let (nx, ny) = (x + dx, y + dy);
                if (dx == 0 && dy == 0)
                    || nx < 0
                    || ny < 0
                    || nx >= width as isize
                    || ny >= height as isize
                {
                    continue;
                }
                let j = ny as usize * width + nx as usize;
                if done[j] {
                    continue;
                }
                done[j] = true;
                let lj = z[j].max(li);
                level[j] = lj;
                heap.push(Reverse((key(lj), j as u32)));
            }
        }
    }
    let mut s = PitShare::default();
    depth_m.clear();
    depth_m.extend(level.iter().zip(z).map(|(l, z)| (l - z).max(0.0)));
    for i in 0..n {
        if !(z[i] > 0.0) || skip.is_some_and(|k| k[i]) {
            continue;
        }
        s.land_cells += 1;
        if level[i] - z[i] > min_depth_m {
            s.pit_cells += 1;
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bowl_is_a_pit_and_a_slope_is_not() {
        let (w, h) = (40, 30);
        let slope: Vec<f32> = (0..w * h).map(|i| 5.0 + (i % w) as f32 * 10.0).collect();
        assert_eq!(pit_share(&slope, w, h, 10.0, None).pit_cells, 0);
        let bowl: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 - 20.0, (i / w) as f32 - 15.0);
                100.0 + (x * x + y * y).sqrt() * 5.0 - 60.0 * (-(x * x + y * y) / 20.0).exp()
            })
            .collect();
        let s = pit_share(&bowl, w, h, 10.0, None);
        assert!(s.pit_cells > 5, "{s:?}");
        assert_eq!(s.land_cells, w * h);
        // Skipped cells are not counted.
        let skip = vec![true; w * h];
        assert_eq!(pit_share(&bowl, w, h, 10.0, Some(&skip)).land_cells, 0);
        // An outlet at the bottom of the bowl (a closed basin's sink) drains it.
        let mut outlet = vec![false; w * h];
        outlet[15 * w + 20] = true;
        let drained = pit_depths_with_outlets(&bowl, w, h, 10.0, None, Some(&outlet), &mut vec![]);
        assert_eq!(drained.pit_cells, 0, "{drained:?}");
    }
}
