//! Per-sample and per-front-point state of the convergent boundaries: where the subduction fronts
//! are, how far each sample is from the nearest one, which terrane each continental sample
//! belongs to, and the collisions waiting for the next resampling.

use bevy_ecs::prelude::*;
use glam::DVec3;

/// Sentinel for "none" in the per-sample index fields.
pub const NONE: u32 = u32::MAX;

/// The points of every subduction front, found at the last resampling (structure of arrays).
/// Static fields describe the front in the overriding plate's frame; dynamic fields are
/// refreshed every step by the subduction system.
#[derive(Resource, Clone, Debug, Default)]
pub struct FrontPoints {
    /// Overriding-side reference sample of each point (its position is the point, in the
    /// overriding plate's frame).
    pub sample: Vec<u32>,
    /// Overriding plate id.
    pub overriding: Vec<u32>,
    /// Subducting plate id.
    pub subducting: Vec<u32>,
    /// Unit tangent from the overriding toward the subducting plate, overriding frame.
    pub normal: Vec<DVec3>,
    /// Length of front each point stands for, km.
    pub length_km: Vec<f32>,
    /// Whether subducting crust is under the point now and the plates converge (dynamic): the
    /// point lifts the overriding plate and its slab pulls.
    pub active: Vec<bool>,
    /// Whether subducting crust is under the point or just ahead of it (one mean sample spacing
    /// towards the subducting plate) and the plates converge (dynamic): the point has a trench
    /// in front of it. Every active point has one.
    pub trench: Vec<bool>,
    /// Elevation of the subducting crust at the point now, km (dynamic).
    pub subducting_elevation_km: Vec<f32>,
    /// Subducting minus overriding surface velocity at the point, in the overriding plate's
    /// frame, km/My (dynamic).
    pub relative_velocity: Vec<DVec3>,
    /// Convergence accumulated since the last resampling, km (dynamic).
    pub converged_km: Vec<f32>,
    /// Convergence rate at the last step, km/My (dynamic).
    pub convergence_km_per_my: Vec<f32>,
    /// Where a walk to the mesh vertex nearest the point, in the subducting plate's frame,
    /// starts (dynamic; not saved): the dominant corner of the triangle the last tracking found
    /// under it there, so the walk from it ends at once while the plates have not moved since
    /// ([`crate::geometry::SphereMesh::nearest_vertex_from`]). A hint only: the walk finds the
    /// nearest vertex from any start; empty or [`NONE`] where there is none.
    pub near_vertex: Vec<u32>,
}

impl FrontPoints {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.sample.len()
    }
    /// True when there is no front.
    pub fn is_empty(&self) -> bool {
        self.sample.is_empty()
    }
    /// Removes every point.
    pub fn clear(&mut self) {
        *self = Self::default();
    }
}

/// Distance of every sample to the nearest subduction front, measured in its own plate at the
/// last resampling, on the overriding side and on the subducting side (a plate can be both, at
/// different fronts).
#[derive(Resource, Clone, Debug, Default)]
pub struct ConvergenceField {
    /// Distance to the nearest front this sample's plate overrides, km (infinite if none).
    pub overriding_distance_km: Vec<f32>,
    /// That front point ([`NONE`] if none).
    pub overriding_point: Vec<u32>,
    /// Distance to the nearest front this sample's plate subducts at, km (infinite if none).
    pub subducting_distance_km: Vec<f32>,
    /// That front point ([`NONE`] if none).
    pub subducting_point: Vec<u32>,
}

/// Which plate overrides which, per converging pair (from the fronts), for resolving overlaps.
#[derive(Resource, Clone, Debug, Default)]
pub struct OverridePairs(pub Vec<(u32, u32)>);

impl OverridePairs {
    /// True when plate `a` overrides plate `b` at some front.
    pub fn overrides(&self, a: u32, b: u32) -> bool {
        self.0.binary_search(&(a, b)).is_ok()
    }
}

/// The terrane of every sample ([`NONE`] for oceanic crust), rebuilt at each resampling, and the
/// terranes' areas.
#[derive(Resource, Clone, Debug, Default)]
pub struct TerraneField {
    /// Terrane index per sample.
    pub terrane: Vec<u32>,
    /// Area per terrane, km².
    pub area_km2: Vec<f64>,
    /// Plate id per terrane.
    pub plate: Vec<u32>,
    /// Area-weighted centroid per terrane, its plate's frame.
    pub centroid: Vec<DVec3>,
}

/// A collision decided this step: a terrane leaves its plate for another at the next resampling.
#[derive(Clone, Debug, PartialEq)]
pub struct Suture {
    /// The terrane that moves.
    pub terrane: u32,
    /// The plate it leaves.
    pub from_plate: u32,
    /// The plate it joins.
    pub to_plate: u32,
    /// Its area, km².
    pub area_km2: f64,
    /// Relative speed of the two plates at its centroid, km/My.
    pub relative_speed_km_per_my: f64,
    /// Its centroid, world frame.
    pub centroid_world: DVec3,
    /// The plate the terrane moves on until the suture is applied, when it left its plate at
    /// once (`collision.resample_at_suture` off): a plate of its own that kept the frame of
    /// `from_plate` and moves with `to_plate` (or `from_plate` itself, when the terrane was
    /// the whole plate). `None` while the terrane is still on `from_plate`.
    pub detached_plate: Option<u32>,
}

impl Suture {
    /// The plate whose samples of the terrane move at the suture.
    pub fn moving_plate(&self) -> u32 {
        self.detached_plate.unwrap_or(self.from_plate)
    }
}

/// Collisions waiting for the next resampling, and the ones it applied (for the
/// collision uplift that follows it).
#[derive(Resource, Clone, Debug, Default)]
pub struct Sutures {
    /// Decided, not yet applied.
    pub pending: Vec<Suture>,
    /// Applied by the last resampling: (suture, samples now in the joined plate).
    pub applied: Vec<(Suture, Vec<u32>)>,
    /// Every collision so far.
    pub total: u64,
    /// The sutures of the last resampling that applied any, kept after the collision uplift
    /// consumed `applied` (for reports and tests; not saved).
    pub last_applied: Vec<Suture>,
}

/// Pairs of plates born of one rift, which build no subduction front between them (so neither
/// goes under the other nor collides with it) until a time: a rift's fracture winds, and the
/// rigid rotations of its fragments, which open it on the whole, close a few of its stretches
/// (docs/relief.md). Without the exemption those stretches became fronts at once, a fragment's
/// continent was sutured back onto its sibling within the first resampling interval (undoing
/// the rift), and the suture's uplift drew a low ridge along the closed stretch. Where siblings
/// overlap meanwhile, the resampling keeps one plate's crust, as anywhere plates overlap.
/// Saved (section `rifting.siblings`).
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct RiftSiblings {
    /// ((lower id, higher id), simulated time at which the exemption ends, My), sorted by pair,
    /// one entry per pair.
    pub pairs: Vec<((u32, u32), f64)>,
}

impl RiftSiblings {
    /// Exempts every pair of `fragments` until `until_my` (a pair already there takes the new
    /// time), and forgets the pairs whose time is over at `now_my`.
    pub fn add(&mut self, fragments: &[u32], until_my: f64, now_my: f64) {
        self.forget_expired(now_my);
        for (i, &a) in fragments.iter().enumerate() {
            for &b in &fragments[i + 1..] {
                let key = (a.min(b), a.max(b));
                match self.pairs.binary_search_by(|(k, _)| k.cmp(&key)) {
                    Ok(j) => self.pairs[j].1 = until_my,
                    Err(j) => self.pairs.insert(j, (key, until_my)),
                }
            }
        }
    }

    /// Whether plates `a` and `b` are siblings still exempt at `now_my`.
    pub fn exempt(&self, a: u32, b: u32, now_my: f64) -> bool {
        let key = (a.min(b), a.max(b));
        self.pairs
            .binary_search_by(|(k, _)| k.cmp(&key))
            .is_ok_and(|j| self.pairs[j].1 > now_my)
    }

    /// Drops the pairs whose exemption is over at `now_my`.
    pub fn forget_expired(&mut self, now_my: f64) {
        self.pairs.retain(|&(_, until)| until > now_my);
    }
}
