//! Plain-data components of the plate entities. Plates carry their motion, their rotation since
//! the last resampling and their share of the reference mesh; systems update them.

use bevy_ecs::prelude::*;
use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// Stable identifier of a plate. Ids are never reused within a run; the per-sample `plate`
/// field of the crust stores them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct PlateId(pub u32);

/// Marks a plate entity and gives its id.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plate {
    /// The plate's stable id.
    pub id: PlateId,
}

impl Plate {
    /// Every component of a new plate entity with this id and motion, at the identity frame,
    /// with empty geometry (filled by the next plate rebuild).
    pub fn bundle(id: PlateId, motion: PlateMotion) -> impl Bundle {
        (
            Plate { id },
            motion,
            PlateFrame::default(),
            PlateMesh::default(),
            PlateBounds {
                centroid: DVec3::Z,
                cap_radius_rad: std::f64::consts::PI,
            },
            PlateStats::default(),
        )
    }

    /// Despawns every plate entity.
    pub fn despawn_all(world: &mut World) {
        let old: Vec<Entity> = world
            .query_filtered::<Entity, With<Plate>>()
            .iter(world)
            .collect();
        for e in old {
            world.despawn(e);
        }
    }
}

/// Rigid geodetic movement of a plate: rotation about an Euler pole through the planet centre.
/// The surface velocity at unit position `p` is `ω w × p` (times the radius for km/My = mm/yr).
#[derive(Component, Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlateMotion {
    /// Unit rotation axis `w`, world frame.
    pub euler_pole: DVec3,
    /// Angular speed ω, radians per million years (positive: counter-clockwise about the pole).
    pub angular_speed_rad_per_my: f64,
}

impl PlateMotion {
    /// Surface velocity at world unit position `p`, km/My (= mm/yr), for a planet of `radius_km`.
    pub fn velocity_km_per_my(&self, p: DVec3, radius_km: f64) -> DVec3 {
        self.euler_pole.cross(p) * (self.angular_speed_rad_per_my * radius_km)
    }
    /// Highest surface speed anywhere on the sphere (at the pole's equator), mm/yr.
    pub fn max_speed_mm_per_yr(&self, radius_km: f64) -> f64 {
        self.angular_speed_rad_per_my.abs() * radius_km
    }
}

/// Where the plate is now: the rotation taking positions in the plate's frame (the reference
/// frame at the last resampling) to the world.
#[derive(Component, Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlateFrame {
    /// World-from-plate rotation since the last resampling (identity right after one).
    pub world_from_plate: DQuat,
}

impl Default for PlateFrame {
    fn default() -> Self {
        Self {
            world_from_plate: DQuat::IDENTITY,
        }
    }
}

impl PlateFrame {
    /// The rotation as a matrix.
    pub fn world_from_plate_mat(&self) -> DMat3 {
        DMat3::from_quat(self.world_from_plate)
    }
    /// Angle turned since the last resampling, radians.
    pub fn angle_rad(&self) -> f64 {
        2.0 * self.world_from_plate.w.abs().min(1.0).acos()
    }
}

/// The plate's share of the reference mesh, in the plate's own frame.
#[derive(Component, Clone, Debug, Default, PartialEq)]
pub struct PlateMesh {
    /// Samples owned by the plate (ascending).
    pub samples: Vec<u32>,
    /// Triangles with at least one vertex owned by the plate (ascending). Triangles shared with
    /// a neighbour belong to both, so co-moving plates leave no gap between them.
    pub triangles: Vec<u32>,
}

/// A spherical cap, in the plate frame, that contains every triangle of the plate.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct PlateBounds {
    /// Unit centre of the cap (the plate's area-weighted centroid), plate frame.
    pub centroid: DVec3,
    /// Angular radius of the cap, radians.
    pub cap_radius_rad: f64,
}

/// Plate statistics refreshed at each resampling.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq)]
pub struct PlateStats {
    /// Area of the plate, km².
    pub area_km2: f64,
    /// Area of its continental crust, km².
    pub continental_area_km2: f64,
}

impl PlateStats {
    /// Driftworld's overlap score (§3.5), by area: continental crust counts a hundred times
    /// more than oceanic crust. The higher score stays on top where two plates overlap.
    pub fn overlap_score(&self) -> f64 {
        100.0 * self.continental_area_km2 - (self.area_km2 - self.continental_area_km2)
    }
}

/// Which crust goes under at a subduction front (paper §4.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum FrontKind {
    /// Oceanic crust plunges beneath continental crust.
    OceanUnderContinent,
    /// The older of two oceanic plates plunges beneath the younger (island arcs).
    OceanUnderOcean,
    /// Continental against continental: a forced subduction that turns into a collision.
    Forced,
}

/// A converging boundary between two plates: one connected run of converging plate-boundary
/// edges between the same overriding and subducting plates, found at each resampling.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct SubductionFront {
    /// The plate that stays on top.
    pub overriding: PlateId,
    /// The plate that goes under.
    pub subducting: PlateId,
    /// What goes under what.
    pub kind: FrontKind,
    /// The front's points: indices into [`FrontPoints`](crate::resources::FrontPoints).
    pub points: Vec<u32>,
    /// Length of the front, km.
    pub length_km: f64,
}

/// A terrane (paper §3): a connected region of continental crust within one plate, from a small
/// island to a whole continent. Rebuilt at each resampling.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct Terrane {
    /// Index of the terrane in [`TerraneField`](crate::resources::TerraneField).
    pub index: u32,
    /// The plate that carries it.
    pub plate: PlateId,
    /// Its area, km².
    pub area_km2: f64,
    /// Its area-weighted centroid, plate frame.
    pub centroid: DVec3,
    /// Number of samples.
    pub samples: u32,
}
