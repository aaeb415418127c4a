//! Plate rifting (paper §4.4, Driftworld §3.14): a plate breaks into 2–4 fragments along warped
//! Voronoi borders (or along a line a user drew), and the fragments get diverging Euler poles so
//! that new ocean floor opens between them over the following steps.
//!
//! **When** (the paper's "Poisson law" made exact). Each plate `P` is a Poisson process of rate
//! `λ0·f(x_P)·A_P/A0` events per My, where
//! - `λ0` is `rifting.frequency_per_my`,
//! - `A0` is the reference plate area, the planet's area divided by `init.plates`,
//! - `x_P` is the plate's continental share and `f(x) = f0 + (1 − f0)·x` with
//!   `f0 = rifting.oceanic_factor`: supercontinents rift most, oceanic plates seldom,
//! - plates smaller than `rifting.min_plate_area_km2` do not rift on their own.
//!
//! Over one step of δt the plates together rift with probability `1 − exp(−Λ)`, where
//! `Λ = Σ λ0·δt·f(x_P)·A_P/A0`; when they do, the plate that rifts is drawn with probability
//! `λ_P/Λ`. (The paper writes `P = λ·e^{−λ}`, the probability of exactly one event, which
//! *falls* for large plates; `1 − e^{−λ}`, at least one event, is what a Poisson process gives and
//! grows with the plate.) At most one plate rifts per step, which the step length makes a
//! negligible restriction (Λ is a few hundredths per step at the defaults).
//!
//! **How.** `n` centroids (`n` uniform in 2..=`rifting.max_fragments`, fewer when the plate is
//! too small for `n` fragments of `resample.fragment_min_area_km2`) are drawn among the plate's
//! samples, kept apart; every sample of the plate goes to the nearest centroid after its position
//! is displaced by vector noise (`rifting.fracture_warp_km`), which makes the fracture lines
//! irregular. The fragment with the largest area keeps the plate's id and entity; the others
//! become new plates. Each fragment's angular velocity is the parent's plus a rotation that moves
//! its centroid straight away from the parent's centroid (direction jittered by up to ±20°), at a
//! speed in proportion to its distance from it, `rifting.divergence_speed_mm_per_yr` on average:
//! the plate stretches, so every fracture opens, and the fragments separate at once (the paper's
//! "direct divergence", §7.5); the gaps between them fill with ridge crust at the next
//! resamplings.
//!
//! **When.** Random rifts are drawn on the steps that end with a global resampling, over the steps
//! since the last one (their number Poisson with mean steps·Σλ, at most one per plate), and
//! carried out there: fragments share the parent's frame, so nothing moves at the moment of the
//! rift, and the resampling that follows in the same step (after the Rifting set) rebuilds fronts
//! and terranes for the new plates. (Drawn every step, each rift forced a resampling of its own:
//! three of the default run's fourteen.) With the resampling off they are drawn every step. A
//! rift asked for by a command happens at once and asks for a resampling.

use bevy_ecs::prelude::*;
use glam::{DQuat, DVec3};
use rayon::prelude::*;

use crate::components::{
    Plate, PlateBounds, PlateFrame, PlateId, PlateMesh, PlateMotion, PlateStats,
};
use crate::geometry::SphereMesh;
use crate::geometry::spherical::{angle_between, tangent_basis, triple};
use crate::random::{SimRng, hash3, stream, vector_fbm};
use crate::resources::params::Params;
use crate::resources::{Crust, CrustType, NextPlateId, ResampleRequest, SimClock};
use crate::systems::resample::plate_geometry_of;

/// Why a plate could not be rifted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RiftError {
    /// No plate has this id.
    #[error("no plate with id {0}")]
    NoPlate(u32),
    /// The fracture leaves fewer than two fragments.
    #[error("the fracture does not split plate {0}: every sample falls on one side")]
    NoSplit(u32),
    /// A fragment would be too small to live on as a plate.
    #[error(
        "the fracture leaves a fragment of {area_km2:.0} km² of plate {plate}, smaller than resample.fragment_min_area_km2 = {min_km2:.0} km²"
    )]
    FragmentTooSmall {
        /// The plate.
        plate: u32,
        /// The smallest fragment's area.
        area_km2: f64,
        /// The minimum.
        min_km2: f64,
    },
    /// The fracture line is unusable.
    #[error("bad fracture line: {0}")]
    BadLine(String),
}

/// How a plate is to be split. Points are in the plate's own frame.
#[derive(Clone, Debug, PartialEq)]
pub enum Fracture {
    /// Voronoi cells of these centroids, borders warped by noise with this seed.
    Voronoi {
        /// Unit centroids, plate frame.
        centroids: Vec<DVec3>,
        /// Seed of the warping noise.
        warp_seed: u64,
    },
    /// The two sides of a polyline of great-circle arcs (unit points, plate frame).
    Line(Vec<DVec3>),
}

/// What started a rift.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RiftCause {
    /// The Poisson process of the Rifting set.
    Random,
    /// An authoring command.
    Command,
}

/// One rift that happened.
#[derive(Clone, Debug, PartialEq)]
pub struct RiftEvent {
    /// Step at which it happened (the clock's step before that step's advance).
    pub step: u64,
    /// The plate that broke.
    pub parent: u32,
    /// Every fragment's plate id (the parent's id first).
    pub fragments: Vec<u32>,
    /// What started it.
    pub cause: RiftCause,
    /// Wall time of the rift itself (partition, motions, plate geometry), ms.
    pub elapsed_ms: f64,
}

/// Every rift so far (a resource; diagnostics, not saved).
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct RiftLog {
    /// Oldest first.
    pub events: Vec<RiftEvent>,
}

/// The transfer function f(x) of the rifting rate for a continental share `x`.
pub fn continental_factor(params: &Params, x: f64) -> f64 {
    let f0 = params.rifting.oceanic_factor;
    f0 + (1.0 - f0) * x.clamp(0.0, 1.0)
}

/// Expected number of rifts of one plate during one step (λ of the module docs).
pub fn rift_rate_per_step(params: &Params, stats: &PlateStats, planet_area_km2: f64) -> f64 {
    if stats.area_km2 < params.rifting.min_plate_area_km2 || stats.area_km2 <= 0.0 {
        return 0.0;
    }
    let a0 = planet_area_km2 / params.init.plates.max(1) as f64;
    let x = stats.continental_area_km2 / stats.area_km2;
    params.rifting.frequency_per_my
        * params.time.time_step_my
        * continental_factor(params, x)
        * stats.area_km2
        / a0
}

/// `n` centroids among `samples` (plate frame), drawn by `rng`, each at least a fraction of the
/// fragment size away from the others when that is possible.
pub fn random_centroids(
    mesh: &SphereMesh,
    samples: &[u32],
    area_km2: f64,
    n: usize,
    rng: &mut SimRng,
    radius_km: f64,
) -> Vec<DVec3> {
    let mut out: Vec<DVec3> = Vec::with_capacity(n);
    if samples.is_empty() {
        return out;
    }
    // Half the radius of a disc of the fragment's area.
    let min_sep_rad = 0.5 * (area_km2 / n.max(1) as f64 / std::f64::consts::PI).sqrt() / radius_km;
    while out.len() < n {
        let mut best = None;
        let mut best_sep = -1.0;
        for _ in 0..32 {
            let s = samples[(rng.next_u64() % samples.len() as u64) as usize];
            let p = mesh.positions[s as usize];
            let sep = out
                .iter()
                .map(|&c| angle_between(c, p))
                .fold(f64::INFINITY, f64::min);
            if sep >= min_sep_rad {
                best = Some(p);
                break;
            }
            if sep > best_sep {
                best_sep = sep;
                best = Some(p);
            }
        }
        match best {
            Some(p) => out.push(p),
            None => break,
        }
    }
    out
}

/// Which fragment each of `samples` falls in (indices into the fracture's centroids, or 0/1 for
/// the left/right side of a line).
pub fn partition(
    mesh: &SphereMesh,
    samples: &[u32],
    fracture: &Fracture,
    params: &Params,
) -> Vec<u8> {
    let r = params.planet.radius_km;
    match fracture {
        Fracture::Voronoi {
            centroids,
            warp_seed,
        } => {
            let amp = params.rifting.fracture_warp_km / r;
            let wl = params.rifting.fracture_wavelength_km / r;
            samples
                .par_iter()
                .map(|&s| {
                    let p = mesh.positions[s as usize];
                    let q = if amp > 0.0 {
                        (p + vector_fbm(*warp_seed, p, wl, 3) * amp).normalize_or(p)
                    } else {
                        p
                    };
                    let mut best = 0u8;
                    let mut best_dot = f64::NEG_INFINITY;
                    for (k, c) in centroids.iter().enumerate() {
                        let d = c.dot(q);
                        if d > best_dot {
                            best_dot = d;
                            best = k as u8;
                        }
                    }
                    best
                })
                .collect()
        }
        Fracture::Line(points) => samples
            .par_iter()
            .map(|&s| u8::from(side_of_line(points, mesh.positions[s as usize]) < 0.0))
            .collect(),
    }
}

/// Signed side of `p` relative to the polyline: positive on the left of the nearest arc.
fn side_of_line(points: &[DVec3], p: DVec3) -> f64 {
    let mut best_dist = f64::INFINITY;
    let mut side = 0.0;
    for w in points.windows(2) {
        let (a, b) = (w[0], w[1]);
        let n = a.cross(b).normalize_or_zero();
        if n == DVec3::ZERO {
            continue;
        }
        let s = n.dot(p);
        // Projection of p on the great circle; inside the arc when it lies between a and b.
        let proj = (p - n * s).normalize_or_zero();
        let inside = proj != DVec3::ZERO && triple(a, proj, n) >= 0.0 && triple(proj, b, n) >= 0.0;
        let dist = if inside {
            s.abs().min(1.0).asin()
        } else {
            angle_between(a, p).min(angle_between(b, p))
        };
        if dist < best_dist {
            best_dist = dist;
            side = s;
        }
    }
    side
}

/// Splits plate `parent` along `fracture`: reassigns its samples, spawns the new plates with the
/// parent's frame, gives every fragment a diverging motion, refreshes plate geometry and asks for
/// a resampling. Returns the fragments' ids (the parent's first). `jitter_seed` draws the
/// divergence directions' jitter.
pub fn rift_plate(
    world: &mut World,
    parent: u32,
    fracture: &Fracture,
    jitter_seed: u64,
    cause: RiftCause,
) -> Result<Vec<u32>, RiftError> {
    let started = std::time::Instant::now();
    let (entity, frame, motion, samples) = world
        .query::<(Entity, &Plate, &PlateFrame, &PlateMotion, &PlateMesh)>()
        .iter(world)
        .find(|(_, p, ..)| p.id.0 == parent)
        .map(|(e, _, f, m, pm)| (e, *f, *m, pm.samples.clone()))
        .ok_or(RiftError::NoPlate(parent))?;
    let params = world.resource::<Params>().clone();
    let mesh = world.resource::<SphereMesh>();
    let labels = partition(mesh, &samples, fracture, &params);
    let k = labels.iter().map(|&l| l as usize + 1).max().unwrap_or(0);
    let mut area = vec![0.0f64; k];
    let mut centroid = vec![DVec3::ZERO; k];
    for (&s, &l) in samples.iter().zip(&labels) {
        let a = mesh.area_km2[s as usize];
        area[l as usize] += a;
        centroid[l as usize] += mesh.positions[s as usize] * a;
    }
    // Non-empty fragments, largest first (ties: lower label).
    let mut order: Vec<usize> = (0..k).filter(|&l| area[l] > 0.0).collect();
    if order.len() < 2 {
        return Err(RiftError::NoSplit(parent));
    }
    order.sort_by(|&a, &b| area[b].total_cmp(&area[a]).then(a.cmp(&b)));
    let min_km2 = params.resample.fragment_min_area_km2;
    if let Some(&small) = order.last()
        && area[small] < min_km2
    {
        return Err(RiftError::FragmentTooSmall {
            plate: parent,
            area_km2: area[small],
            min_km2,
        });
    }
    let parent_centroid = centroid
        .iter()
        .copied()
        .sum::<DVec3>()
        .normalize_or(DVec3::Z);
    // Ids: the largest fragment keeps the parent's.
    let mut next_id = world.resource::<NextPlateId>().0;
    let mut id_of_label = vec![u32::MAX; k];
    let mut ids = Vec::with_capacity(order.len());
    for (rank, &l) in order.iter().enumerate() {
        let id = if rank == 0 {
            parent
        } else {
            let id = next_id;
            next_id += 1;
            id
        };
        id_of_label[l] = id;
        ids.push(id);
    }
    world.resource_mut::<NextPlateId>().0 = next_id;
    thin_rifted_margins(world, &samples, &labels, &params);
    // Only the plate ids change: on the GPU backend a declared write uploads them (4 B/sample)
    // instead of pulling every stale field and uploading the whole crust next.
    crate::gpu::write_crust_fields_or_record(world, crate::gpu::FieldMask::PLATE, |crust| {
        for (&s, &l) in samples.iter().zip(&labels) {
            crust.plate[s as usize] = id_of_label[l as usize];
        }
    });
    // Motions: the parent's angular velocity plus a stretch of the plate about its centroid.
    let world_from_plate = frame.world_from_plate;
    let omega_parent = motion.euler_pole * motion.angular_speed_rad_per_my;
    let div = params.rifting.divergence_speed_mm_per_yr / params.planet.radius_km;
    let stretch = stretch_factors(&centroid, &order, parent_centroid);
    let pc = world_from_plate * parent_centroid;
    let mut rng = SimRng::new(jitter_seed, stream::RIFT);
    let mut motions = Vec::with_capacity(order.len());
    for (&l, &f) in order.iter().zip(&stretch) {
        let c = world_from_plate * centroid[l].normalize_or(parent_centroid);
        let mut t = c * c.dot(pc) - pc;
        if t.length_squared() < 1e-18 {
            t = tangent_basis(c).0;
        }
        let t = t.normalize();
        let jitter = (rng.next_f64() * 2.0 - 1.0) * 20f64.to_radians();
        let t = DQuat::from_axis_angle(c, jitter) * t;
        let omega = omega_parent + c.cross(t) * (div * f);
        let speed = omega.length();
        motions.push(PlateMotion {
            euler_pole: if speed > 0.0 { omega / speed } else { DVec3::Z },
            angular_speed_rad_per_my: speed,
        });
    }
    if params.plates.momentum {
        // The fragments push apart without the plate as a whole gaining momentum.
        use crate::systems::momentum::{inertia, motion_of, omega, rift_correction, sample_mass};
        let mesh = world.resource::<SphereMesh>();
        let crust = world.resource::<Crust>();
        let inertias: Vec<glam::DMat3> = order
            .iter()
            .map(|&l| {
                inertia(
                    samples
                        .iter()
                        .zip(&labels)
                        .filter(|&(_, &ls)| ls as usize == l)
                        .map(|(&s, _)| {
                            let s = s as usize;
                            (
                                world_from_plate * mesh.positions[s],
                                sample_mass(crust.crust_type[s], mesh.area_km2[s], &params),
                            )
                        }),
                )
            })
            .collect();
        let mut omegas: Vec<DVec3> = motions.iter().map(omega).collect();
        rift_correction(&inertias, &mut omegas, omega_parent);
        for (m, w) in motions.iter_mut().zip(omegas) {
            *m = motion_of(w, m.euler_pole);
        }
    }
    world.entity_mut(entity).insert(motions[0]);
    for (rank, &id) in ids.iter().enumerate().skip(1) {
        world
            .spawn(Plate::bundle(PlateId(id), motions[rank]))
            .insert(frame);
    }
    refresh_plate_geometry(world, &ids);
    world.resource_mut::<ResampleRequest>().0 = true;
    let (step, now_my) = {
        let clock = world.resource::<SimClock>();
        (clock.step, clock.time_my)
    };
    // The fragments build no front between them for a while (see RiftSiblings).
    let grace = params.rifting.sibling_grace_my;
    if grace > 0.0 {
        world
            .get_resource_or_init::<crate::resources::RiftSiblings>()
            .add(&ids, now_my + grace, now_my);
    }
    let elapsed_ms = started.elapsed().as_secs_f64() * 1e3;
    tracing::debug!(parent, fragments = ?ids, ms = elapsed_ms, ?cause, "plate rifted");
    world
        .get_resource_or_init::<RiftLog>()
        .events
        .push(RiftEvent {
            step,
            parent,
            fragments: ids.clone(),
            cause,
            elapsed_ms,
        });
    Ok(ids)
}

/// Speed of each fragment of `order` away from the parent's centroid `parent_centroid` (unit), as
/// a multiple of `rifting.divergence_speed_mm_per_yr`: in proportion to the angular distance of
/// the fragment's centroid (`centroid[l]`, area-weighted sums) from it, scaled so that the
/// fragments' mean is 1. The plate stretches evenly, so every fracture between two fragments
/// opens. Two fragments separate at twice the divergence speed, as when each moved at that speed.
/// A rule of equal speeds away from the other fragments did not open every fracture: with three
/// or four fragments in a row, two neighbours at one end moved the same way at the same speed,
/// and their fracture stayed a narrow seaway that never widened (or closed into a front inside the
/// continent). When the centroids all coincide, every fragment gets 1.
fn stretch_factors(centroid: &[DVec3], order: &[usize], parent_centroid: DVec3) -> Vec<f64> {
    let d: Vec<f64> = order
        .iter()
        .map(|&l| angle_between(centroid[l].normalize_or(parent_centroid), parent_centroid))
        .collect();
    let mean = d.iter().sum::<f64>() / d.len().max(1) as f64;
    if mean <= 1e-12 {
        return vec![1.0; d.len()];
    }
    d.iter().map(|&x| x / mean).collect()
}

/// Thins the continental crust of a plate about to break along the new fracture lines:
/// `rifting.margin_thinning_km·(1 − d/w)²` within `w = rifting.margin_width_km` of the nearest
/// sample of another fragment (great-circle distance through the plate), never below 5 km. With
/// isostasy on, the margins then step down to the sea (a stretched, rifted margin) instead of
/// ending in a cliff. Off by default (`rifting.margin_thinning_km` = 0): where the fragments did
/// not part for good, the thinned strips stayed in the continent as narrow troughs.
fn thin_rifted_margins(world: &mut World, samples: &[u32], labels: &[u8], params: &Params) {
    let (amount, width) = (
        params.rifting.margin_thinning_km,
        params.rifting.margin_width_km,
    );
    if amount <= 0.0 || samples.is_empty() {
        return;
    }
    let mesh = world.resource::<SphereMesh>();
    let n = mesh.len();
    // Label of each sample of the plate (u32::MAX elsewhere).
    let mut label_of = vec![u32::MAX; n];
    for (&s, &l) in samples.iter().zip(labels) {
        label_of[s as usize] = u32::from(l);
    }
    // Seeds: samples with a neighbour of the same plate in another fragment.
    let seeds: Vec<(u32, u32)> = samples
        .iter()
        .filter(|&&s| {
            let l = label_of[s as usize];
            mesh.neighbors_of(s as usize).iter().any(|&h| {
                let lh = label_of[h as usize];
                lh != u32::MAX && lh != l
            })
        })
        .enumerate()
        .map(|(k, &s)| (s, k as u32))
        .collect();
    if seeds.is_empty() {
        return;
    }
    let origins: Vec<DVec3> = seeds
        .iter()
        .map(|&(s, _)| mesh.positions[s as usize])
        .collect();
    let mut dist = vec![f32::INFINITY; n];
    let mut nearest = vec![u32::MAX; n];
    let mut settled = Vec::new();
    crate::systems::convergence::propagate_nearest(
        mesh,
        &seeds,
        |k| origins[k as usize],
        |s, _| label_of[s] != u32::MAX,
        width / params.planet.radius_km,
        &mut dist,
        &mut nearest,
        &mut settled,
    );
    let radius_km = params.planet.radius_km;
    let thinned: Vec<(u32, f32)> = samples
        .iter()
        .filter_map(|&s| {
            let d = dist[s as usize] as f64 * radius_km;
            (d < width).then(|| {
                let x = 1.0 - d / width;
                (s, (amount * x * x) as f32)
            })
        })
        .collect();
    crate::gpu::write_crust_fields_or_record(world, crate::gpu::FieldMask::THICKNESS, |crust| {
        for &(s, dt) in &thinned {
            let s = s as usize;
            if crust.crust_type[s] == CrustType::Continental {
                let t = crust.thickness_km[s];
                crust.thickness_km[s] = (t - dt).max(5.0f32.min(t));
            }
        }
    });
}

/// Recomputes samples, triangles, bounding cap and areas of the plates `ids` from
/// `Crust::plate`, keeping their frames (unlike a resampling's rebuild).
pub fn refresh_plate_geometry(world: &mut World, ids: &[u32]) {
    let mut geometry = {
        let mesh = world.resource::<SphereMesh>();
        let crust = world.resource::<Crust>();
        plate_geometry_of(mesh, crust, Some(ids))
    };
    let targets: Vec<(Entity, u32)> = world
        .query::<(Entity, &Plate)>()
        .iter(world)
        .filter(|(_, p)| ids.contains(&p.id.0))
        .map(|(e, p)| (e, p.id.0))
        .collect();
    for (e, id) in targets {
        if let Some(g) = geometry.get_mut(id as usize).and_then(Option::take) {
            let bounds = g.bounds.unwrap_or(PlateBounds {
                centroid: DVec3::Z,
                cap_radius_rad: std::f64::consts::PI,
            });
            world.entity_mut(e).insert((g.mesh, bounds, g.stats));
        }
    }
}

/// Number of fragments for a random rift: uniform in 2..=max, fewer when the plate cannot hold
/// that many fragments of the minimum size.
fn fragment_count(params: &Params, area_km2: f64, u: f64) -> usize {
    let max = params.rifting.max_fragments.clamp(2, 4) as usize;
    let n = 2 + ((u * (max - 1) as f64) as usize).min(max - 2);
    let min = params.resample.fragment_min_area_km2.max(1.0);
    // Keep room for uneven cells: ask for three times the minimum per fragment.
    let fit = (area_km2 / (3.0 * min)).floor() as usize;
    n.min(fit.max(2))
}

/// A random rift of plate `id` into `n` fragments (or a random count when `None`), with
/// centroids and warping drawn from `seed_bits`.
pub fn random_rift(
    world: &mut World,
    id: u32,
    n: Option<usize>,
    seed_bits: u64,
    cause: RiftCause,
) -> Result<Vec<u32>, RiftError> {
    let params = world.resource::<Params>().clone();
    let (samples, stats) = world
        .query::<(&Plate, &PlateMesh, &PlateStats)>()
        .iter(world)
        .find(|(p, ..)| p.id.0 == id)
        .map(|(_, m, s)| (m.samples.clone(), *s))
        .ok_or(RiftError::NoPlate(id))?;
    let mut rng = SimRng::new(seed_bits, stream::RIFT);
    let u = rng.next_f64();
    let n = n.unwrap_or_else(|| fragment_count(&params, stats.area_km2, u));
    let centroids = {
        let mesh = world.resource::<SphereMesh>();
        random_centroids(
            mesh,
            &samples,
            stats.area_km2,
            n,
            &mut rng,
            params.planet.radius_km,
        )
    };
    let fracture = Fracture::Voronoi {
        centroids,
        warp_seed: rng.next_u64(),
    };
    rift_plate(world, id, &fracture, rng.next_u64(), cause)
}

/// The Rifting set's system (with the resampling on): on a step that ends with a global
/// resampling, draws the random rifts of the steps since the last one and carries them out, so
/// the resampling that was due anyway rebuilds fronts and terranes for the fragments. On the other
/// steps it does nothing. A rift drawn on any step would force a resampling of its own (the
/// fragments need their fronts and terranes), which put three resamplings more into the default
/// 250 My run; carried out at the next resampling instead, a rift waits at most
/// `resample.max_interval_steps` steps (about ten at the defaults), which a Poisson process of
/// tens of millions of years does not notice.
pub fn rift_plates(world: &mut World) {
    // The clock advances (in the Aging set) between this set and the resampling's.
    let steps = world.resource::<SimClock>().steps_since_resample + 1;
    let requested = world.resource::<ResampleRequest>().0;
    let max_angle =
        crate::systems::resample::max_frame_angle(world.query::<&PlateFrame>().iter(world));
    let due = crate::systems::resample::resample_due_after(
        steps,
        world.resource::<Params>(),
        requested,
        max_angle,
    );
    if due {
        draw_rifts(world, steps);
    }
}

/// The Rifting set's system with the resampling off: each step draws its own rifts (each one
/// asks for a resampling that will not come; the fragments keep the fronts of their parent).
pub fn rift_plates_every_step(world: &mut World) {
    draw_rifts(world, 1);
}

/// Draws the random rifts of the last `steps` steps from the plates' Poisson processes (their
/// rates now) and carries them out: their number is Poisson with mean `steps`·Σλ, at most one
/// per plate, each plate picked in proportion to its rate. Over one step with at most one rift,
/// the draws are those of a rift a step.
fn draw_rifts(world: &mut World, steps: u64) {
    let params = world.resource::<Params>();
    if params.rifting.frequency_per_my <= 0.0 {
        return;
    }
    let seed = params.planet.seed;
    let step = world.resource::<SimClock>().step;
    let planet_area = world.resource::<SphereMesh>().total_area_km2();
    // A terrane waiting for its suture on a plate of its own does not rift.
    let detached: Vec<u32> = world
        .get_resource::<crate::resources::Sutures>()
        .map(|s| s.pending.iter().filter_map(|s| s.detached_plate).collect())
        .unwrap_or_default();
    let mut rates: Vec<(u32, f64)> = {
        let params = world.resource::<Params>().clone();
        world
            .query::<(&Plate, &PlateStats)>()
            .iter(world)
            .filter(|(p, _)| !detached.contains(&p.id.0))
            .map(|(p, s)| (p.id.0, rift_rate_per_step(&params, s, planet_area)))
            .filter(|&(_, l)| l > 0.0)
            .collect()
    };
    rates.sort_by_key(|r| r.0);
    let mean = rates.iter().map(|r| r.1).sum::<f64>() * steps as f64;
    if mean <= 0.0 {
        return;
    }
    let mut rng = SimRng::new(hash3(seed, stream::RIFT, step), stream::RIFT);
    let count = poisson_count(rng.next_f64(), mean, rates.len());
    for _ in 0..count {
        let total: f64 = rates.iter().map(|r| r.1).sum();
        let mut pick = rng.next_f64() * total;
        let mut at = rates.len() - 1;
        for (k, &(_, l)) in rates.iter().enumerate() {
            if pick < l {
                at = k;
                break;
            }
            pick -= l;
        }
        let (chosen, _) = rates.remove(at);
        if let Err(e) = random_rift(world, chosen, None, rng.next_u64(), RiftCause::Random) {
            // A plate too small or too oddly shaped for its fragments: no rift this time.
            tracing::debug!(plate = chosen, "random rift skipped: {e}");
        }
    }
}

/// The number of events of a Poisson process of mean `mean` that the uniform draw `u` (in
/// [0, 1)) gives, at most `max`: at least k when `u` < P(K ≥ k), so a draw below
/// 1 − e^(−mean) gives at least one.
pub fn poisson_count(u: f64, mean: f64, max: usize) -> usize {
    if !(mean > 0.0) {
        return 0;
    }
    // P(K ≥ k) = 1 − P(K ≤ k − 1), with P(K = k) = e^(−mean)·mean^k / k!.
    let mut term = (-mean).exp();
    let mut at_most = term;
    let mut k = 0;
    while k < max && u < 1.0 - at_most {
        k += 1;
        term *= mean / k as f64;
        at_most += term;
    }
    k
}

/// The continental share of a set of samples, for diagnostics and tests.
pub fn continental_share(mesh: &SphereMesh, crust: &Crust, samples: &[u32]) -> f64 {
    let (mut c, mut t) = (0.0, 0.0);
    for &s in samples {
        let a = mesh.area_km2[s as usize];
        t += a;
        if crust.crust_type[s as usize] == CrustType::Continental {
            c += a;
        }
    }
    if t > 0.0 { c / t } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poisson_count_draws_the_poisson_distribution() {
        assert_eq!(poisson_count(0.0, 0.0, 5), 0);
        assert_eq!(poisson_count(0.5, f64::NAN, 5), 0);
        // At least one rift exactly below 1 − e^(−mean), as one draw a step did.
        let m: f64 = 0.3;
        let p1 = 1.0 - (-m).exp();
        assert_eq!(poisson_count(p1 - 1e-12, m, 5), 1);
        assert_eq!(poisson_count(p1 + 1e-12, m, 5), 0);
        // Over a uniform grid of draws: the law's mean and P(K = 2), and the cap.
        for mean in [0.05, 0.3, 2.0] {
            let n = 200_000;
            let counts: Vec<usize> = (0..n)
                .map(|k| poisson_count((k as f64 + 0.5) / n as f64, mean, 50))
                .collect();
            let avg = counts.iter().sum::<usize>() as f64 / n as f64;
            assert!((avg - mean).abs() < 1e-3 * mean.max(1.0), "{mean}: {avg}");
            let two = counts.iter().filter(|&&c| c == 2).count() as f64 / n as f64;
            let law = (-mean).exp() * mean * mean / 2.0;
            assert!((two - law).abs() < 1e-4, "{mean}: {two} against {law}");
        }
        assert_eq!(poisson_count(0.0, 50.0, 3), 3);
    }
}
