//! The initial planet (paper §3 "Workflow", Driftworld §3.4): plates as spherical Voronoi cells
//! of random centroids with borders warped by low-frequency noise, continents where a noise field
//! biased per plate is highest (exactly the target continental area), random Euler poles and
//! speeds, and initial elevation, thickness and age by crust type.
//!
//! With `init.flood_fill` the plates are grown instead from their seed points over the sample
//! graph (seed 003's flood fill): the sample nearest each plate's centroid starts it, and the
//! plates grow in order of arrival, a sample joining the first plate to reach it, where crossing
//! a km costs exp(roughness × noise) (a noise field on positions: the "shuffled frontier" drawn
//! from positions, not from sample indices). Each plate is continental or oceanic as a whole:
//! plates in a random order (per plate) are continental until `continental_fraction` of the area
//! is. Relief near the coasts tapers over 500 km, measured along the graph.
//!
//! Every random draw is made per plate (from the seed and the plate number) or per position
//! (noise evaluated at the sample's position), never per sample index, so the same seed gives
//! the same plates, motions and continents at any resolution.

use glam::DVec3;
use rayon::prelude::*;

use crate::components::{PlateId, PlateMotion};
use crate::geometry::{MeshError, SphereMesh, angle_between};
use crate::random::{fbm, hash3, stream, unit_f64, unit_vector, vector_fbm};
use crate::resources::params::Params;
use crate::resources::{Crust, CrustType, NO_PLATE, Orogeny};
use crate::systems::oceanic_crust::ocean_floor_age_my;
use crate::systems::resample::defragment_plates;

/// A plate of the initial planet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialPlate {
    /// Its id.
    pub id: PlateId,
    /// Its motion.
    pub motion: PlateMotion,
}

/// Seeds of the noise fields, derived from the run seed.
fn noise_seed(seed: u64, field: u64) -> u64 {
    hash3(seed, stream::NOISE + field, 0)
}

#[inline]
fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The centroid of initial plate `i` (per plate, from the seed).
pub fn plate_centroid(seed: u64, i: u64) -> DVec3 {
    unit_vector(
        hash3(seed, stream::PLATE_CENTROID, 2 * i),
        hash3(seed, stream::PLATE_CENTROID, 2 * i + 1),
    )
}

/// The motion of initial plate `i` (per plate, from the seed): a uniform random Euler pole and an
/// angular speed giving surface speeds up to between `min_speed_fraction`·v0 and v0.
pub fn plate_motion(params: &Params, i: u64) -> PlateMotion {
    let seed = params.planet.seed;
    let pole = unit_vector(
        hash3(seed, stream::PLATE_MOTION, 3 * i),
        hash3(seed, stream::PLATE_MOTION, 3 * i + 1),
    );
    let f = params.plates.min_speed_fraction;
    let u = f + (1.0 - f) * unit_f64(hash3(seed, stream::PLATE_MOTION, 3 * i + 2));
    // v0 in mm/yr = km/My; ω = v / R.
    let omega = u * params.plates.max_speed_mm_per_yr / params.planet.radius_km;
    PlateMotion {
        euler_pole: pole,
        angular_speed_rad_per_my: omega,
    }
}

/// Plate of each sample by warped Voronoi, plus the two-nearest distance gap used to soften the
/// per-plate continental bias near borders.
fn warped_voronoi(
    mesh: &SphereMesh,
    params: &Params,
    centroids: &[DVec3],
) -> (Vec<u32>, Vec<(u32, u32, f64)>) {
    let r = params.planet.radius_km;
    let amp = params.init.border_warp_km / r;
    let wl = params.init.border_warp_wavelength_km / r;
    let wseed = noise_seed(params.planet.seed, 1);
    let nearest: Vec<(u32, u32, f64)> = mesh
        .positions
        .par_iter()
        .with_min_len(1024)
        .map(|&p| {
            let pw = if amp > 0.0 {
                (p + vector_fbm(wseed, p, wl, 4) * amp).normalize()
            } else {
                p
            };
            let (mut i1, mut i2) = (0u32, 0u32);
            let (mut best1, mut best2) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
            for (i, c) in centroids.iter().enumerate() {
                let d = pw.dot(*c);
                if d > best1 {
                    best2 = best1;
                    i2 = i1;
                    best1 = d;
                    i1 = i as u32;
                } else if d > best2 {
                    best2 = d;
                    i2 = i as u32;
                }
            }
            let gap = angle_between(pw, centroids[i2 as usize])
                - angle_between(pw, centroids[i1 as usize]);
            (i1, i2, gap)
        })
        .collect();
    (nearest.iter().map(|n| n.0).collect(), nearest)
}

/// Distance over which the flood-fill start tapers its relief from the coast, km.
const FLOOD_COAST_KM: f64 = 500.0;

/// The sample nearest `p` (ties to the lower index).
fn nearest_sample(mesh: &SphereMesh, p: DVec3) -> usize {
    mesh.positions
        .par_iter()
        .enumerate()
        .with_min_len(4096)
        .map(|(i, q)| (q.dot(p), i))
        .reduce(
            || (f64::NEG_INFINITY, usize::MAX),
            |a, b| {
                if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }
            },
        )
        .1
}

/// Multi-source Dijkstra over the sample graph: the cost of each edge is `cost(i, j)`; `dist`
/// holds the sources' starting values (and `f64::INFINITY` elsewhere) and gets the distances;
/// `label` (when given) takes, at each sample, the label of the source that reached it first.
/// Ties break by sample index: deterministic.
fn dijkstra(
    mesh: &SphereMesh,
    dist: &mut [f64],
    mut label: Option<&mut [u32]>,
    cost: impl Fn(usize, usize) -> f64,
) {
    use std::cmp::Reverse;
    let mut heap: std::collections::BinaryHeap<Reverse<(u64, u32)>> = dist
        .iter()
        .enumerate()
        .filter(|(_, d)| d.is_finite())
        .map(|(i, d)| Reverse((d.to_bits(), i as u32)))
        .collect();
    while let Some(Reverse((bits, i))) = heap.pop() {
        let (i, d) = (i as usize, f64::from_bits(bits));
        if d > dist[i] {
            continue;
        }
        for &j in mesh.neighbors_of(i) {
            let j = j as usize;
            let dj = d + cost(i, j);
            if dj < dist[j] {
                dist[j] = dj;
                if let Some(l) = label.as_deref_mut() {
                    l[j] = l[i];
                }
                heap.push(Reverse((dj.to_bits(), j as u32)));
            }
        }
    }
}

/// Plates grown from the samples nearest `centroids` (see the module documentation); a plate
/// whose seed sample another plate took first gets no samples.
fn flood_fill_plates(mesh: &SphereMesh, params: &Params, centroids: &[DVec3]) -> Vec<u32> {
    let n = mesh.len();
    let r = params.planet.radius_km;
    let rough = params.init.flood_fill_roughness;
    let wl = params.init.border_warp_wavelength_km / r;
    let nseed = noise_seed(params.planet.seed, 6);
    // Cost of a km at each sample.
    let per_km: Vec<f64> = mesh
        .positions
        .par_iter()
        .with_min_len(1024)
        .map(|&p| (rough * fbm(nseed, p, wl, 5)).exp())
        .collect();
    let mut dist = vec![f64::INFINITY; n];
    let mut plate = vec![NO_PLATE; n];
    for (k, &c) in centroids.iter().enumerate() {
        let s = nearest_sample(mesh, c);
        if plate[s] == NO_PLATE {
            plate[s] = k as u32;
            dist[s] = 0.0;
        }
    }
    let pos = &mesh.positions;
    dijkstra(mesh, &mut dist, Some(&mut plate), |i, j| {
        angle_between(pos[i], pos[j]) * r * 0.5 * (per_km[i] + per_km[j])
    });
    plate
}

/// The Voronoi start: plates by warped Voronoi (defragmented), continents where fBm noise plus
/// a per-plate bias (softened across borders) is highest, exactly `target` km² of them.
/// Returns the plates, the continental mask and each sample's score above the threshold.
fn voronoi_start(
    mesh: &SphereMesh,
    params: &Params,
    centroids: &[DVec3],
    target: f64,
) -> (Vec<u32>, Vec<bool>, Vec<f64>) {
    let n = mesh.len();
    let seed = params.planet.seed;
    let r = params.planet.radius_km;
    let n_plates = centroids.len();
    let (mut plate, nearest) = warped_voronoi(mesh, params, centroids);
    let mut unused = n_plates as u32;
    defragment_plates(mesh, &mut plate, f64::INFINITY, false, &mut unused);
    let bias: Vec<f64> = (0..n_plates as u64)
        .map(|i| 2.0 * unit_f64(hash3(seed, stream::PLATE_CONTINENT, i)) - 1.0)
        .collect();
    let cont_wl = params.init.continent_wavelength_km / r;
    let border_soft = (params.init.border_warp_km.max(300.0) / r).max(1e-6);
    let cseed = noise_seed(seed, 2);
    let score: Vec<f64> = mesh
        .positions
        .par_iter()
        .zip(nearest.par_iter())
        .with_min_len(1024)
        .map(|(&p, &(i1, i2, gap))| {
            let t = smoothstep(0.0, border_soft, gap);
            let b1 = bias[i1 as usize];
            let b = 0.5 * (b1 + bias[i2 as usize]) * (1.0 - t) + b1 * t;
            0.6 * fbm(cseed, p, cont_wl, 6) + 0.5 * b
        })
        .collect();
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.par_sort_unstable_by(|&a, &b| {
        score[b as usize]
            .total_cmp(&score[a as usize])
            .then(a.cmp(&b))
    });
    let mut acc = 0.0;
    let mut threshold = f64::INFINITY;
    for &s in &order {
        if acc >= target {
            break;
        }
        acc += mesh.area_km2[s as usize];
        threshold = score[s as usize];
    }
    drop(order);
    let continental = score
        .iter()
        .map(|&s| s >= threshold && target > 0.0)
        .collect();
    let h = score.iter().map(|&s| s - threshold).collect();
    (plate, continental, h)
}

/// The flood-fill start (see the module documentation). Returns the plates, the continental
/// mask, and the distance to the coast in the units of the Voronoi start's score (0.12 at
/// [`FLOOD_COAST_KM`] inland, −0.1 as far out at sea).
fn flood_fill_start(
    mesh: &SphereMesh,
    params: &Params,
    centroids: &[DVec3],
    target: f64,
) -> (Vec<u32>, Vec<bool>, Vec<f64>) {
    let n = mesh.len();
    let seed = params.planet.seed;
    let r = params.planet.radius_km;
    let plate = flood_fill_plates(mesh, params, centroids);
    let mut area = vec![0.0f64; centroids.len()];
    for (i, &p) in plate.iter().enumerate() {
        if p != NO_PLATE {
            area[p as usize] += mesh.area_km2[i];
        }
    }
    // Plates in a random order (per plate) are continental until the target area is.
    let mut order: Vec<u64> = (0..centroids.len() as u64)
        .filter(|&k| area[k as usize] > 0.0)
        .collect();
    order.sort_by_key(|&k| (hash3(seed, stream::PLATE_CONTINENT, k), k));
    let mut is_cont = vec![false; centroids.len()];
    let mut acc = 0.0;
    for &k in &order {
        if acc >= target {
            break;
        }
        is_cont[k as usize] = true;
        acc += area[k as usize];
    }
    let continental: Vec<bool> = plate
        .iter()
        .map(|&p| p != NO_PLATE && is_cont[p as usize])
        .collect();
    // Distance to the coast: from the samples next to crust of the other type.
    let mut dist: Vec<f64> = (0..n)
        .map(|i| {
            let coastal = mesh
                .neighbors_of(i)
                .iter()
                .any(|&j| continental[j as usize] != continental[i]);
            if coastal { 0.0 } else { f64::INFINITY }
        })
        .collect();
    let pos = &mesh.positions;
    dijkstra(mesh, &mut dist, None, |i, j| {
        angle_between(pos[i], pos[j]) * r
    });
    let h = (0..n)
        .map(|i| {
            let d = dist[i] / FLOOD_COAST_KM;
            if continental[i] { 0.12 * d } else { -0.1 * d }
        })
        .collect();
    (plate, continental, h)
}

/// Builds the reference mesh for the parameters.
pub fn reference_mesh(params: &Params) -> Result<SphereMesh, MeshError> {
    SphereMesh::fibonacci(
        params.planet.samples as usize,
        params.planet.sample_jitter,
        params.planet.seed,
        params.planet.radius_km,
    )
}

/// Builds the initial crust and plates on `mesh`.
pub fn initial_planet(mesh: &SphereMesh, params: &Params) -> (Crust, Vec<InitialPlate>) {
    let n = mesh.len();
    let seed = params.planet.seed;
    let r = params.planet.radius_km;
    let n_plates = params.init.plates as usize;
    let centroids: Vec<DVec3> = (0..n_plates as u64)
        .map(|i| plate_centroid(seed, i))
        .collect();
    let total_area: f64 = mesh.area_km2.iter().sum();
    let target = params.init.continental_fraction * total_area;
    // Per sample: continental or not, and how far from the coast in the units of the Voronoi
    // start's score (`h` ≥ 0 on land, < 0 at sea).
    let (plate, continental, h) = if params.init.flood_fill {
        flood_fill_start(mesh, params, &centroids, target)
    } else {
        voronoi_start(mesh, params, &centroids, target)
    };

    let cont_wl = params.init.continent_wavelength_km / r;
    let eseed = noise_seed(seed, 3);
    let oseed = noise_seed(seed, 4);
    let aseed = noise_seed(seed, 5);
    let i = &params.init;
    let iso = &params.isostasy;
    let gain = crate::resources::params::dry_isostatic_gain(params);
    let mut crust = Crust::with_len(n);
    crust
        .elevation_km
        .par_iter_mut()
        .zip(crust.crust_type.par_iter_mut())
        .zip(crust.thickness_km.par_iter_mut())
        .zip(crust.age_my.par_iter_mut())
        .zip(mesh.positions.par_iter())
        .zip(continental.par_iter().zip(h.par_iter()))
        .with_min_len(1024)
        .for_each(|(((((z, ct), e), age), &p), (&cont, &h))| {
            if cont {
                let zc = i.continental_elevation_km * (0.3 + 0.7 * smoothstep(0.0, 0.12, h))
                    + i.elevation_noise_km * fbm(eseed, p, cont_wl / 3.0, 5);
                *z = zc as f32;
                *ct = CrustType::Continental;
                // The crust that stands at this elevation under Airy isostasy (so that isostasy,
                // when on, keeps the initial relief), thinned toward the coast like a rifted
                // margin (init.margin_thinning_km at the coastline).
                let taper = 1.0 - smoothstep(0.0, 0.1, h);
                *e = (iso.reference_thickness_km + (zc - iso.reference_elevation_km) / gain
                    - params.init.margin_thinning_km * taper * taper)
                    .max(5.0) as f32;
                *age = (1500.0 + 500.0 * fbm(aseed, p, cont_wl, 3)) as f32;
            } else {
                let o = &params.ocean;
                let zo = (i.oceanic_elevation_km
                    + 2.0 * i.elevation_noise_km * fbm(oseed, p, cont_wl / 2.0, 4))
                .clamp(o.abyssal_elevation_km, o.ridge_elevation_km);
                // Shallower floor close to the continents (continental rise).
                let margin = if target > 0.0 {
                    smoothstep(0.0, 0.1, -h)
                } else {
                    1.0
                };
                let zo = -1.5 * (1.0 - margin) + zo * margin;
                *z = zo as f32;
                *ct = CrustType::Oceanic;
                *e = i.oceanic_thickness_km as f32;
                *age = ocean_floor_age_my(zo, params) as f32;
            }
        });
    crust.orogeny.iter_mut().for_each(|o| *o = Orogeny::None);
    crust.plate.copy_from_slice(&plate);
    if params.init.craters > 0 {
        let b = crate::systems::craters::bombard(mesh, &mut crust, params);
        tracing::debug!(
            craters = b.craters,
            removed_km3 = b.removed_km3,
            deposited_km3 = b.deposited_km3,
            "impact craters struck"
        );
    }

    let plates = present_plates(&plate, n_plates, |k| plate_motion(params, k as u64));
    if plates.len() < n_plates {
        tracing::warn!(
            asked = n_plates,
            made = plates.len(),
            "some initial plates got no samples and were dropped"
        );
    }
    (crust, plates)
}

/// What a start from a map gives: the elevation everywhere, and optionally the plates and some
/// of their motions (see [`planet_from_map`]).
pub struct MapStart<'a> {
    /// Elevation (m) at a world unit direction.
    pub elevation_m: &'a (dyn Fn(DVec3) -> f64 + Sync),
    /// Plate index at a world unit direction; None draws the plates as a new planet does
    /// (Voronoi or flood fill, `init.flood_fill`).
    pub plates: Option<&'a (dyn Fn(DVec3) -> u32 + Sync)>,
    /// Motions of some plates by index; the others get a random motion (as a new planet's).
    pub motions: &'a [(u32, PlateMotion)],
    /// Plates of the map smaller than this (km²) join the neighbouring plate they share most
    /// edges with (0 keeps every plate that covers a sample).
    pub min_plate_area_km2: f64,
}

/// Why a map cannot start a planet.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MapStartError {
    /// No sample of the map lies above sea level.
    #[error(
        "the map has no land: every sample lies at or below sea level (lowest {min_m:.0} m, highest {max_m:.0} m)"
    )]
    AllOcean {
        /// Lowest elevation sampled, m.
        min_m: f64,
        /// Highest elevation sampled, m.
        max_m: f64,
    },
    /// An elevation is not a finite number.
    #[error(
        "the map holds an elevation that is not a number at latitude {lat:.2}°, longitude {lon:.2}°"
    )]
    NotFinite {
        /// Latitude, degrees.
        lat: f64,
        /// Longitude, degrees.
        lon: f64,
    },
    /// More plates than the parameters allow.
    #[error("the plates map has {plates} plates; at most {max} fit {samples} samples")]
    TooManyPlates {
        /// Plates in the map.
        plates: usize,
        /// The most allowed.
        max: usize,
        /// Samples.
        samples: u64,
    },
    /// A motion names a plate the map does not have.
    #[error("a motion is given for plate {plate}, but the plates are numbered 0 to {last}")]
    UnknownPlate {
        /// The plate asked for.
        plate: u32,
        /// The last plate.
        last: u32,
    },
}

/// Oldest age (My) a start from a map gives ocean floor (floor deeper than the age–depth law
/// reaches at this age is this old and thinner than normal).
pub const MAP_OLDEST_FLOOR_MY: f64 = 180.0;

/// The age (My) at which bare ocean floor reaches `z_km` under the parameters' age–depth law
/// (0 above the ridge, [`MAP_OLDEST_FLOOR_MY`] below the law's depth at that age): bisection on
/// the monotone law.
pub fn age_of_floor_my(z_km: f64, params: &Params) -> f64 {
    use crate::systems::relief::isostasy::ocean_floor_km;
    if z_km >= ocean_floor_km(0.0, params) {
        return 0.0;
    }
    if z_km <= ocean_floor_km(MAP_OLDEST_FLOOR_MY, params) {
        return MAP_OLDEST_FLOOR_MY;
    }
    let (mut lo, mut hi) = (0.0, MAP_OLDEST_FLOOR_MY);
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if ocean_floor_km(mid, params) > z_km {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Gives the samples of every plate smaller than `min_area_km2` to the larger plate most of
/// their neighbours belong to (in passes over the samples in order, until none is left; a
/// small plate with no larger neighbour keeps its samples).
fn merge_small_plates(mesh: &SphereMesh, plate: &mut [u32], n_plates: usize, min_area_km2: f64) {
    let mut area = vec![0.0f64; n_plates];
    for (i, &p) in plate.iter().enumerate() {
        if (p as usize) < n_plates {
            area[p as usize] += mesh.area_km2[i];
        }
    }
    let small = |p: u32| (p as usize) < n_plates && area[p as usize] < min_area_km2;
    let mut counts: Vec<(u32, u32)> = Vec::new();
    loop {
        let mut changed = false;
        for i in 0..plate.len() {
            if !small(plate[i]) {
                continue;
            }
            counts.clear();
            for &j in mesh.neighbors_of(i) {
                let q = plate[j as usize];
                if q == NO_PLATE || small(q) {
                    continue;
                }
                match counts.iter_mut().find(|c| c.0 == q) {
                    Some(c) => c.1 += 1,
                    None => counts.push((q, 1)),
                }
            }
            if let Some(&(q, _)) = counts
                .iter()
                .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
            {
                plate[i] = q;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
}

/// A planet started from a map (paper §7.1): each sample takes the map's elevation; crust above
/// `init.map_continental_above_m` is continental, with the thickness that stands at that
/// elevation under Airy isostasy; the rest is ocean floor of the age whose depth the age–depth
/// law gives (shallower floor is young floor under a load, deeper floor old floor thinned), with
/// the thickness that keeps its elevation. Plates come from `start.plates` (then made whole:
/// pieces cut off from their plate join a neighbour) or are drawn as for a new planet; motions
/// from `start.motions`, random for the plates it does not name. `init.craters` are struck into
/// it as into a generated planet.
pub fn planet_from_map(
    mesh: &SphereMesh,
    params: &Params,
    start: &MapStart,
) -> Result<(Crust, Vec<InitialPlate>), MapStartError> {
    use crate::geometry::to_lat_lon_deg;
    use crate::systems::relief::isostasy::{airy_thickness, ocean_floor_km};
    let n = mesh.len();
    let elevation: Vec<f64> = mesh
        .positions
        .par_iter()
        .with_min_len(1024)
        .map(|&p| (start.elevation_m)(p))
        .collect();
    if let Some(i) = elevation.iter().position(|z| !z.is_finite()) {
        let (lat, lon) = to_lat_lon_deg(mesh.positions[i]);
        return Err(MapStartError::NotFinite { lat, lon });
    }
    let (min_m, max_m) = elevation
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &z| {
            (a.min(z), b.max(z))
        });
    if max_m <= 0.0 {
        return Err(MapStartError::AllOcean { min_m, max_m });
    }
    // Plates.
    let n_plates;
    let mut plate: Vec<u32> = match start.plates {
        Some(f) => {
            let plate: Vec<u32> = mesh.positions.par_iter().map(|&p| f(p)).collect();
            n_plates = plate.iter().map(|&p| p as usize + 1).max().unwrap_or(0);
            let max = (params.planet.samples / 20).max(1) as usize;
            if n_plates > max {
                return Err(MapStartError::TooManyPlates {
                    plates: n_plates,
                    max,
                    samples: params.planet.samples,
                });
            }
            plate
        }
        None => {
            n_plates = params.init.plates as usize;
            let seed = params.planet.seed;
            let centroids: Vec<DVec3> = (0..n_plates as u64)
                .map(|i| plate_centroid(seed, i))
                .collect();
            if params.init.flood_fill {
                flood_fill_start(mesh, params, &centroids, 0.0).0
            } else {
                voronoi_start(mesh, params, &centroids, 0.0).0
            }
        }
    };
    let mut unused = n_plates as u32;
    defragment_plates(mesh, &mut plate, f64::INFINITY, false, &mut unused);
    if start.min_plate_area_km2 > 0.0 {
        merge_small_plates(mesh, &mut plate, n_plates, start.min_plate_area_km2);
    }
    if let Some(&(p, _)) = start.motions.iter().find(|(p, _)| *p as usize >= n_plates) {
        return Err(MapStartError::UnknownPlate {
            plate: p,
            last: n_plates.saturating_sub(1) as u32,
        });
    }
    // Crust.
    let iso = crate::systems::relief::isostasy_params(params);
    let threshold_km = params.init.map_continental_above_m * 1e-3;
    let t_oc = params.init.oceanic_thickness_km;
    let load_gain = crate::resources::params::oceanic_load_gain(params);
    let mut crust = Crust::with_len(n);
    crust
        .elevation_km
        .par_iter_mut()
        .zip(crust.crust_type.par_iter_mut())
        .zip(crust.thickness_km.par_iter_mut())
        .zip(crust.age_my.par_iter_mut())
        .zip(elevation.par_iter())
        .with_min_len(1024)
        .for_each(|((((z, ct), t), age), &zm)| {
            let zk = zm * 1e-3;
            *z = zk as f32;
            if zk > threshold_km {
                *ct = CrustType::Continental;
                *t = airy_thickness(zk, &iso).max(5.0) as f32;
                *age = 1000.0;
            } else {
                *ct = CrustType::Oceanic;
                let a = age_of_floor_my(zk, params);
                // What the law does not explain is a load (above it) or a thinner crust (below).
                let off = zk - ocean_floor_km(a, params);
                *age = a as f32;
                *t = (t_oc + off / load_gain).max(1.0) as f32;
            }
        });
    crust.orogeny.iter_mut().for_each(|o| *o = Orogeny::None);
    crust.plate.copy_from_slice(&plate);
    if params.init.craters > 0 {
        crate::systems::craters::bombard(mesh, &mut crust, params);
    }
    let plates = present_plates(&plate, n_plates, |k| {
        start
            .motions
            .iter()
            .find(|(p, _)| *p as usize == k)
            .map(|&(_, m)| m)
            .unwrap_or_else(|| plate_motion(params, k as u64))
    });
    Ok((crust, plates))
}

/// The plates among `0..n_plates` that cover at least one sample of `plate`, with their motions.
fn present_plates(
    plate: &[u32],
    n_plates: usize,
    motion: impl Fn(usize) -> PlateMotion,
) -> Vec<InitialPlate> {
    let mut present = vec![false; n_plates];
    for &p in plate {
        if (p as usize) < n_plates {
            present[p as usize] = true;
        }
    }
    (0..n_plates)
        .filter(|&k| present[k])
        .map(|k| InitialPlate {
            id: PlateId(k as u32),
            motion: motion(k),
        })
        .collect()
}
