//! Coastal erosion (wave planation): the sea cuts back a coast that faces open water and leaves
//! a platform just below sea level, which the sediment then builds into a shelf.
//!
//! Model: a land sample next to the sea retreats at `v = v₀·exp(−W/W₀)` km/My, `W` the width of
//! shallow water (shallower than `open_depth`) in front of it: waves lose their energy crossing a
//! wide shelf, so a coast cuts back fast while its platform is narrow and ever more slowly as the
//! platform widens (Sunamura 1992; Trenhaile 2000). A retreat of `v·dt` across a sample of width
//! `Δx = √area` lowers the sample by the fraction `v·dt/Δx` of its height above the wave base
//! (the area-averaged cliff retreat), and what is removed is carried off like any eroded rock:
//! it enters the sediment routing at that sample.

use bevy_ecs::prelude::*;
use rayon::prelude::*;

use super::graph::ReliefGraph;
use super::{DrainageNetwork, ReliefState, SurfaceFlux};
use crate::geometry::SphereMesh;
use crate::gpu::{FieldMask, GpuContext};
use crate::resources::{Crust, Params, SimClock};

/// Constants of coastal erosion.
#[derive(Clone, Copy, Debug)]
pub struct CoastParams {
    /// Retreat rate of a coast facing open water, km/My (1 km/My = 1 mm/yr).
    pub retreat_km_per_my: f64,
    /// Width of shallow water over which the retreat rate falls by e, km.
    pub damping_width_km: f64,
    /// Depth (km, positive) the waves plane the platform down to.
    pub wave_base_km: f64,
    /// Water deeper than this (km, positive) is open sea: the shallow-water width is measured
    /// from it.
    pub open_depth_km: f64,
}

/// Scratch of [`coastal_erosion`], reused across steps: the widths of the last call (see
/// [`CoastScratch::width_km`]) and buffers.
#[derive(Default)]
pub struct CoastScratch {
    /// Width per sample; infinite except at the samples in `touched`.
    width: Vec<f32>,
    /// Samples whose width was set by the last call.
    touched: Vec<u32>,
    /// What each sample was in the last call: [`OPEN`] sea, [`SHALLOW`] sea, or neither (land).
    class: Vec<u8>,
    shallow: Vec<u32>,
    /// The shallow samples of each chunk of the samples (gathered in parallel, then in order).
    chunks: Vec<Vec<u32>>,
    /// The bucket queue of the width search.
    buckets: super::buckets::BucketQueue,
    lower: Vec<(u32, f32)>,
}

impl CoastScratch {
    /// Width of shallow sea (km) at sample `i` found by the last [`shallow_width_km`]: 0 on open
    /// sea, the distance to open sea through shallow sea, infinite on land, on shallow seas with
    /// no open water and out of range.
    pub fn width_km(&self, i: usize) -> f32 {
        if self.class.get(i) == Some(&OPEN) {
            0.0
        } else {
            self.width.get(i).copied().unwrap_or(f32::INFINITY)
        }
    }
}

/// A sea sample deeper than the open-water depth (see [`CoastScratch::class`]).
const OPEN: u8 = 1;
/// A sea sample shallower than the open-water depth.
const SHALLOW: u8 = 2;

/// Width (km) of shallow sea between each sea sample and open water: the shortest path along the
/// graph, through sea samples shallower than `open_depth_km`, to a sea sample deeper than it
/// (0 for those; infinite for shallow seas with no open water). Land samples get infinity.
/// Read them with [`CoastScratch::width_km`].
///
/// A least-cost search from the open-sea samples next to shallow sea (a bucket queue,
/// label-correcting: the widths are the least path sums, as a Dijkstra search gives them).
/// Cost: one parallel pass over the samples (each one's class in a byte, which the search reads
/// instead of the elevation), then work on the shallow sea only (the widths of
/// the last call are reset sample by sample, not as a whole).
pub fn shallow_width_km(
    g: &ReliefGraph,
    ocean: &[bool],
    elevation_km: &[f32],
    open_depth_km: f64,
    scratch: &mut CoastScratch,
) {
    let n = g.len();
    let open = -(open_depth_km as f32);
    let s = scratch;
    if s.width.len() != n {
        s.width.clear();
        s.width.resize(n, f32::INFINITY);
        s.touched.clear();
    }
    for &t in &s.touched {
        s.width[t as usize] = f32::INFINITY;
    }
    s.touched.clear();
    let (ocean, elevation_km) = (&ocean[..n], &elevation_km[..n]);
    // One pass: each sample's class, and the shallow samples of each chunk in order.
    const CH: usize = 8192;
    s.class.resize(n, 0);
    s.chunks.resize_with(n.div_ceil(CH), Vec::new);
    s.class
        .par_chunks_mut(CH)
        .zip(s.chunks.par_iter_mut())
        .enumerate()
        .for_each(|(c, (cl, list))| {
            list.clear();
            for (k, cl) in cl.iter_mut().enumerate() {
                let i = c * CH + k;
                let z = elevation_km[i];
                // (A NaN elevation is neither.)
                *cl = if !ocean[i] {
                    0
                } else if z <= open {
                    OPEN
                } else if z > open {
                    list.push(i as u32);
                    SHALLOW
                } else {
                    0
                };
            }
        });
    s.shallow.clear();
    for list in &s.chunks {
        s.shallow.extend_from_slice(list);
    }
    let class = &s.class;
    let shallow = |i: usize| class[i] == SHALLOW;
    // Open samples next to shallow sea start the search.
    let (width, touched, queue) = (&mut s.width, &mut s.touched, &mut s.buckets);
    // A bucket queue over the width (buckets half a mean edge wide, at most 2¹⁶ of them),
    // label-correcting (see [`super::buckets`]): the widths of a Dijkstra search.
    queue.reset((0.5 * g.mean_spacing_km).max(1e-3), 1 << 16);
    for &i in &s.shallow {
        for e in g.edges(i as usize) {
            let j = g.neighbors[e];
            if class[j as usize] == OPEN && width[j as usize] != 0.0 {
                width[j as usize] = 0.0;
                touched.push(j);
                queue.push(0.0, j);
            }
        }
    }
    while let Some(i) = queue.pop(|i| f64::from(width[i])) {
        let d = width[i];
        for e in g.edges(i) {
            let j = g.neighbors[e] as usize;
            if !shallow(j) {
                continue;
            }
            let dj = d + g.edge_km[e];
            if dj < width[j] {
                if width[j] == f32::INFINITY {
                    touched.push(j as u32);
                }
                width[j] = dj;
                queue.push(f64::from(dj), j as u32);
            }
        }
    }
}

/// Lowers every land sample next to the sea by its coastal retreat over `dt_my` (see the module
/// documentation): the surface and the crust's thickness go down alike, and what was removed is
/// added to `eroded_km`. `ocean` is the sea mask (lakes
/// are not sea: their waves are small). Returns the volume removed, km³.
#[allow(clippy::too_many_arguments, clippy::neg_cmp_op_on_partial_ord)]
pub fn coastal_erosion(
    g: &ReliefGraph,
    ocean: &[bool],
    elevation_km: &mut [f32],
    thickness_km: &mut [f32],
    eroded_km: &mut [f32],
    p: &CoastParams,
    dt_my: f64,
    scratch: &mut CoastScratch,
) -> f64 {
    let n = g.len();
    if p.retreat_km_per_my <= 0.0
        || dt_my <= 0.0
        || ocean.len() < n
        || elevation_km.len() < n
        || thickness_km.len() < n
        || eroded_km.len() < n
    {
        return 0.0;
    }
    let t = crate::systems::DebugTimer::new("coasts: shallow widths");
    shallow_width_km(g, ocean, elevation_km, p.open_depth_km, scratch);
    drop(t);
    let mut lower = std::mem::take(&mut scratch.lower);
    lower.clear();
    let sc = &*scratch;
    let base = -p.wave_base_km;
    let w0 = p.damping_width_km.max(1e-6);
    // Lowering of each coastal land sample, from the surface before any of them moved.
    lower.par_extend((0..n).into_par_iter().with_min_len(8192).filter_map(|i| {
        if ocean[i] {
            return None;
        }
        let z = elevation_km[i] as f64;
        if !(z > base) {
            return None;
        }
        let w = g
            .edges(i)
            .filter(|&e| ocean[g.neighbors[e] as usize])
            .map(|e| sc.width_km(g.neighbors[e] as usize))
            .fold(f32::INFINITY, f32::min);
        if !w.is_finite() {
            return None;
        }
        let dx = g.area_km2[i].max(1e-12).sqrt();
        let v = p.retreat_km_per_my * (-(w as f64) / w0).exp();
        let f = (v * dt_my / dx).min(1.0);
        let d = ((z - base) * f) as f32;
        (d > 0.0).then_some((i as u32, d))
    }));
    // The rock leaves the surface and the crust alike (in index order: the sum is the same
    // whatever the thread count).
    let mut volume = 0.0;
    for &(i, d) in &lower {
        let i = i as usize;
        elevation_km[i] -= d;
        thickness_km[i] -= d;
        eroded_km[i] += d;
        volume += d as f64 * g.area_km2[i];
    }
    scratch.lower = lower;
    volume
}

/// The sea mask of a step after its network's (with `time.relief_interval_steps` above 1), for
/// the rivers, the hillslopes and the coasts: the samples at or below sea level joined to the
/// network's sea through samples at or below sea level. A network built now would put those at
/// sea (the bodies of water too small to be sea aside); the samples of its sea that rose above
/// sea level since are land. So the coasts retreat past the samples they cut down on the step
/// before, and the rivers and slopes end at the sea where it now is, as with a network every
/// step. `frontier` is scratch.
pub fn refresh_sea(
    g: &ReliefGraph,
    ocean: &[bool],
    elevation_km: &[f32],
    sea: &mut Vec<bool>,
    frontier: &mut Vec<u32>,
) {
    let n = g.len();
    let wet = |i: usize| elevation_km[i] <= 0.0;
    sea.clear();
    sea.par_extend(
        (0..n)
            .into_par_iter()
            .with_min_len(8192)
            .map(|i| ocean[i] && wet(i)),
    );
    // Sunk land beside the sea, then what is joined to it (few samples: breadth first).
    frontier.clear();
    frontier.par_extend((0..n).into_par_iter().with_min_len(8192).filter_map(|i| {
        (!ocean[i] && wet(i) && g.neighbors_of(i).iter().any(|&j| sea[j as usize]))
            .then_some(i as u32)
    }));
    for &i in frontier.iter() {
        sea[i as usize] = true;
    }
    while let Some(i) = frontier.pop() {
        for &j in g.neighbors_of(i as usize) {
            if !sea[j as usize] && wet(j as usize) {
                sea[j as usize] = true;
                frontier.push(j);
            }
        }
    }
}

/// State of the coastal erosion system (scratch only).
#[derive(Resource, Default)]
pub struct CoastState {
    scratch: CoastScratch,
}

/// The coastal-erosion constants of `params`.
pub fn coast_params(params: &Params) -> CoastParams {
    let c = &params.coasts;
    CoastParams {
        retreat_km_per_my: c.retreat_km_per_my,
        damping_width_km: c.damping_width_km,
        wave_base_km: c.wave_base_m * 1e-3,
        open_depth_km: c.open_water_depth_m * 1e-3,
    }
}

/// Coastal erosion (phenomenon `coasts`): coasts facing open water retreat and leave a platform
/// at the wave base; the rock removed joins what the rivers carry (to the sediment routing).
/// Every step, on the last network's sea mask (refreshed by [`refresh_sea`] on a later step of
/// a network).
#[allow(clippy::too_many_arguments)]
pub fn erode_coasts(
    params: Res<Params>,
    mesh: Res<SphereMesh>,
    clock: Res<SimClock>,
    mut crust: ResMut<Crust>,
    mut relief: ResMut<ReliefState>,
    mut state: ResMut<CoastState>,
    network: Res<DrainageNetwork>,
    mut flux: ResMut<SurfaceFlux>,
    mut gpu: Option<ResMut<GpuContext>>,
) {
    let n = mesh.len();
    if !network.built || network.drainage.ocean.len() != n {
        return;
    }
    const WRITES: FieldMask = FieldMask(FieldMask::ELEVATION.0 | FieldMask::THICKNESS.0);
    let Some(declared) = super::before_write(&mut crust, &mut gpu, FieldMask::NONE, WRITES) else {
        return;
    };
    let relief = &mut *relief;
    let Some(g) = relief.graph.as_ref() else {
        return;
    };
    let flux = &mut *flux;
    let state = &mut *state;
    let mut crust_res = crust;
    let crust = &mut *crust_res;
    let mut lap = super::lap_timer();
    let fresh = network.fresh(clock.step);
    flux.open(n, fresh);
    // The relief state's buffers for the sea as it is now (the rivers' before this).
    let mut sea = std::mem::take(&mut relief.sea_now);
    let ocean = if fresh {
        &network.drainage.ocean
    } else {
        refresh_sea(
            g,
            &network.drainage.ocean,
            &crust.elevation_km,
            &mut sea,
            &mut relief.frontier,
        );
        &sea
    };
    let t_sea = lap();
    let volume = coastal_erosion(
        g,
        ocean,
        &mut crust.elevation_km,
        &mut crust.thickness_km,
        &mut flux.eroded_km,
        &coast_params(&params),
        params.time.time_step_my,
        &mut state.scratch,
    );
    tracing::debug!(sea = t_sea, erosion = lap(), "coasts by pass (ms)");
    relief.sea_now = sea;
    flux.coastal_km3 += volume;
    flux.total_eroded_km3 += volume;
    super::after_write(&crust_res, &mut gpu, WRITES, declared);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::SphereMesh;

    /// A 20k-sample sphere: land north of `lat0` (500 m), sea south of it, 4 km deep except a
    /// shallow band `shelf_km` wide along the coast (100 m deep).
    fn planet(shelf_km: f64) -> (ReliefGraph, Vec<bool>, Vec<f32>) {
        let mesh = SphereMesh::fibonacci(20_000, 0.0, 0, 6371.0).expect("mesh");
        let g = ReliefGraph::new(
            &mesh.positions,
            &mesh.neighbor_start,
            &mesh.neighbors,
            Some(&mesh.triangles),
            Some(&mesh.area_km2),
            mesh.radius_km,
        );
        let lat0 = 0.2f64;
        let mut z = Vec::new();
        let mut ocean = Vec::new();
        for p in &mesh.positions {
            let lat = p.z.clamp(-1.0, 1.0).asin();
            let below_km = (lat0 - lat) * 6371.0;
            if below_km <= 0.0 {
                z.push(0.5);
                ocean.push(false);
            } else if below_km < shelf_km {
                z.push(-0.1);
                ocean.push(true);
            } else {
                z.push(-4.0);
                ocean.push(true);
            }
        }
        (g, ocean, z)
    }

    fn params() -> CoastParams {
        CoastParams {
            retreat_km_per_my: 20.0,
            damping_width_km: 40.0,
            wave_base_km: 0.05,
            open_depth_km: 0.2,
        }
    }

    #[test]
    fn open_coast_retreats_to_the_wave_base_and_counts_its_volume() {
        let (g, ocean, mut z) = planet(0.0);
        let before = z.clone();
        let mut eroded = vec![0.0f32; z.len()];
        let mut t = vec![35.0f32; z.len()];
        let mut s = CoastScratch::default();
        let v = coastal_erosion(
            &g,
            &ocean,
            &mut z,
            &mut t,
            &mut eroded,
            &params(),
            2.0,
            &mut s,
        );
        let mut lowered = 0;
        let mut volume = 0.0;
        for i in 0..z.len() {
            // What left the surface is what was eroded, and nothing is cut below the wave base.
            assert!((before[i] - z[i] - eroded[i]).abs() < 1e-6, "sample {i}");
            assert!(
                (35.0 - t[i] - eroded[i]).abs() < 1e-5,
                "thickness of sample {i}"
            );
            assert!(eroded[i] >= 0.0);
            if eroded[i] > 0.0 {
                lowered += 1;
                assert!(!ocean[i], "a sea sample was cut");
                assert!(
                    g.edges(i).any(|e| ocean[g.neighbors[e] as usize]),
                    "inland sample cut"
                );
                assert!(z[i] >= -0.05 - 1e-6, "cut below the wave base: {}", z[i]);
            }
            volume += eroded[i] as f64 * g.area_km2[i];
        }
        assert!(lowered > 100, "only {lowered} coastal samples cut");
        assert!(
            (v - volume).abs() <= 1e-6 * volume.max(1.0),
            "{v} vs {volume}"
        );
        // Many steps plane the coast down to the wave base.
        for _ in 0..200 {
            coastal_erosion(
                &g,
                &ocean,
                &mut z,
                &mut t,
                &mut eroded,
                &params(),
                2.0,
                &mut s,
            );
        }
        for i in 0..z.len() {
            if eroded[i] > 0.0 {
                assert!((z[i] + 0.05).abs() < 0.01, "not planed: {}", z[i]);
            }
        }
    }

    /// On a step after its network's, the coasts see the samples they cut down to the sea on
    /// the step before as sea ([`refresh_sea`]), so a fast coast retreats a sample a step, as
    /// with a network every step; on the network's own mask the second step only cuts the first
    /// row again. Seen to fail with the refresh left out (no inland sample cut).
    #[test]
    fn the_coast_retreats_past_what_it_cut_on_the_step_before() {
        let fast = CoastParams {
            retreat_km_per_my: 1000.0,
            ..params()
        };
        let (g, ocean, z0) = planet(0.0);
        let beside_sea = |i: usize| g.edges(i).any(|e| ocean[g.neighbors[e] as usize]);
        let run = |refresh: bool| {
            let mut z = z0.clone();
            let mut t = vec![35.0f32; z.len()];
            let mut eroded = vec![0.0f32; z.len()];
            let mut s = CoastScratch::default();
            let mut sea = Vec::new();
            for step in 0..2 {
                let mask = if step > 0 && refresh {
                    refresh_sea(&g, &ocean, &z, &mut sea, &mut Vec::new());
                    &sea
                } else {
                    &ocean
                };
                coastal_erosion(&g, mask, &mut z, &mut t, &mut eroded, &fast, 1.0, &mut s);
            }
            for i in 0..z.len() {
                assert!((z0[i] - z[i] - eroded[i]).abs() < 1e-5, "sample {i}");
                assert!((35.0 - t[i] - eroded[i]).abs() < 1e-5, "thickness {i}");
            }
            (0..z.len())
                .filter(|&i| !ocean[i] && eroded[i] > 0.0 && !beside_sea(i))
                .count()
        };
        assert_eq!(
            run(false),
            0,
            "the network's own mask let the coast cut inland"
        );
        let inland = run(true);
        assert!(
            inland > 100,
            "the refreshed sea let only {inland} inland samples be cut"
        );
    }

    #[test]
    fn a_wide_platform_shelters_its_coast() {
        let mut cut = [0.0f64; 2];
        for (k, shelf) in [0.0, 400.0].into_iter().enumerate() {
            let (g, ocean, mut z) = planet(shelf);
            let mut eroded = vec![0.0f32; z.len()];
            let mut t = vec![35.0f32; z.len()];
            cut[k] = coastal_erosion(
                &g,
                &ocean,
                &mut z,
                &mut t,
                &mut eroded,
                &params(),
                2.0,
                &mut CoastScratch::default(),
            );
        }
        // 400 km of shallow water at W₀ = 40 km: e^-10 of the exposed coast's retreat.
        assert!(cut[0] > 0.0);
        assert!(
            cut[1] < 1e-3 * cut[0],
            "sheltered {} vs open {}",
            cut[1],
            cut[0]
        );
    }

    #[test]
    fn shallow_width_is_the_distance_to_open_water() {
        let (g, ocean, z) = planet(300.0);
        let mut s = CoastScratch::default();
        shallow_width_km(&g, &ocean, &z, 0.2, &mut s);
        let spacing = g.mean_spacing_km as f32;
        let mut seen = 0;
        for i in 0..g.len() {
            if !ocean[i] {
                assert!(s.width_km(i).is_infinite());
            } else if z[i] < -1.0 {
                assert_eq!(s.width_km(i), 0.0);
            } else {
                // A shallow sample: at most the band's width (plus one sample of slack), > 0.
                assert!(
                    s.width_km(i) > 0.0 && s.width_km(i) < 300.0 + 2.0 * spacing,
                    "{}",
                    s.width_km(i)
                );
                seen += 1;
            }
        }
        assert!(seen > 100);
    }

    /// The bucket search gives the widths of a plain Dijkstra search, bit for bit, on an
    /// irregular mesh with a ragged shelf, islands and lagoons; and a second call on another
    /// surface forgets the first one's widths.
    #[test]
    fn shallow_widths_match_a_dijkstra_search() {
        let mesh = SphereMesh::fibonacci(20_000, 0.5, 11, 6371.0).expect("mesh");
        let g = crate::systems::relief::network::relief_graph(&mesh);
        let surface = |phase: f64| -> Vec<f32> {
            mesh.positions
                .iter()
                .map(|p| {
                    let w = (5.0 * p.x + phase).sin() * (4.0 * p.y).cos() + 0.6 * (9.0 * p.z).sin();
                    (0.6 * w - 0.25) as f32
                })
                .collect()
        };
        let reference = |ocean: &[bool], z: &[f32], open: f32| -> Vec<f32> {
            let n = g.len();
            let shallow = |i: usize| ocean[i] && z[i] > open;
            let is_open = |i: usize| ocean[i] && z[i] <= open;
            let mut w = vec![f32::INFINITY; n];
            let mut heap = std::collections::BinaryHeap::new();
            for i in (0..n).filter(|&i| shallow(i)) {
                for &j in g.neighbors_of(i) {
                    if is_open(j as usize) && w[j as usize] != 0.0 {
                        w[j as usize] = 0.0;
                        heap.push(std::cmp::Reverse((0f32.to_bits(), j)));
                    }
                }
            }
            while let Some(std::cmp::Reverse((bits, i))) = heap.pop() {
                let (i, d) = (i as usize, f32::from_bits(bits));
                if d > w[i] {
                    continue;
                }
                for e in g.edges(i) {
                    let j = g.neighbors[e] as usize;
                    if shallow(j) && d + g.edge_km[e] < w[j] {
                        w[j] = d + g.edge_km[e];
                        heap.push(std::cmp::Reverse((w[j].to_bits(), j as u32)));
                    }
                }
            }
            (0..n)
                .map(|i| if is_open(i) { 0.0 } else { w[i] })
                .collect()
        };
        let mut s = CoastScratch::default();
        for phase in [0.0, 1.3] {
            let z = surface(phase);
            let ocean: Vec<bool> = z.iter().map(|&z| z <= 0.0).collect();
            let shallow = z.iter().filter(|&&z| z <= 0.0 && z > -0.2).count();
            assert!(shallow > 1000, "{shallow} shallow samples");
            shallow_width_km(&g, &ocean, &z, 0.2, &mut s);
            let want = reference(&ocean, &z, -0.2);
            let got: Vec<f32> = (0..g.len()).map(|i| s.width_km(i)).collect();
            assert!(want.iter().any(|w| w.is_finite() && *w > 1000.0));
            for i in 0..g.len() {
                assert_eq!(got[i].to_bits(), want[i].to_bits(), "sample {i}");
            }
        }
    }
}
