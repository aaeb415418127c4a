//! A flat, id-indexed snapshot of every plate's frame and motion, rebuilt from the plate entities
//! whenever a per-sample kernel needs it, so inner loops never touch the ECS.

use bevy_ecs::prelude::*;
use glam::{DMat3, DVec3};

use crate::components::{Plate, PlateBounds, PlateFrame, PlateMotion, PlateStats};

/// The plate components a [`PlateTable`] is built from, as a field of a `SystemParam` struct
/// (a system function may spell it `Query<(&Plate, &PlateMotion, ...)>`).
pub type PlateTableQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Plate,
        &'static PlateMotion,
        &'static PlateFrame,
        &'static PlateBounds,
        &'static PlateStats,
    ),
>;

/// One plate, as per-sample kernels need it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlateState {
    /// Plate id.
    pub id: u32,
    /// Rotation from the plate frame to the world.
    pub world_from_plate: DMat3,
    /// Rotation from the world to the plate frame (the transpose).
    pub plate_from_world: DMat3,
    /// Motion of the plate.
    pub motion: PlateMotion,
    /// Centroid of the plate's bounding cap, world frame.
    pub centroid_world: DVec3,
    /// Cosine of the cap radius (a point with a smaller dot product is outside the plate).
    pub cap_cos: f64,
    /// Overlap score (higher stays on top).
    pub overlap_score: f64,
}

/// All plates sorted by id, with an id → slot index.
#[derive(Clone, Debug, Default)]
pub struct PlateTable {
    /// Plates in ascending id order.
    pub plates: Vec<PlateState>,
    slot_of_id: Vec<u32>,
    /// Slots ordered from the plate that stays on top to the one that goes under
    /// (overlap score descending, then id ascending).
    pub by_rank: Vec<u32>,
}

impl PlateTable {
    /// Builds the table from plate entities.
    pub fn from_query(
        q: &Query<(&Plate, &PlateMotion, &PlateFrame, &PlateBounds, &PlateStats)>,
    ) -> Self {
        Self::from_plates(q.iter().map(|(p, m, f, b, s)| (*p, *m, *f, *b, *s)))
    }

    /// Builds the table from plate component tuples (any order).
    pub fn from_plates(
        items: impl Iterator<Item = (Plate, PlateMotion, PlateFrame, PlateBounds, PlateStats)>,
    ) -> Self {
        let mut plates: Vec<PlateState> = items
            .map(|(p, m, f, b, s)| {
                let world_from_plate = f.world_from_plate_mat();
                PlateState {
                    id: p.id.0,
                    world_from_plate,
                    plate_from_world: world_from_plate.transpose(),
                    motion: m,
                    centroid_world: world_from_plate * b.centroid,
                    cap_cos: b.cap_radius_rad.min(std::f64::consts::PI).cos(),
                    overlap_score: s.overlap_score(),
                }
            })
            .collect();
        plates.sort_by_key(|p| p.id);
        let max_id = plates.last().map(|p| p.id as usize + 1).unwrap_or(0);
        let mut slot_of_id = vec![u32::MAX; max_id];
        for (slot, p) in plates.iter().enumerate() {
            slot_of_id[p.id as usize] = slot as u32;
        }
        let mut by_rank: Vec<u32> = (0..plates.len() as u32).collect();
        by_rank.sort_by(|&a, &b| {
            let (pa, pb) = (&plates[a as usize], &plates[b as usize]);
            pb.overlap_score
                .total_cmp(&pa.overlap_score)
                .then(pa.id.cmp(&pb.id))
        });
        Self {
            plates,
            slot_of_id,
            by_rank,
        }
    }

    /// The slot of plate `id`, if it exists.
    #[inline]
    pub fn slot(&self, id: u32) -> Option<usize> {
        self.slot_of_id
            .get(id as usize)
            .copied()
            .filter(|&s| s != u32::MAX)
            .map(|s| s as usize)
    }

    /// The plate with id `id`.
    #[inline]
    pub fn get(&self, id: u32) -> Option<&PlateState> {
        self.slot(id).map(|s| &self.plates[s])
    }

    /// Number of plates.
    pub fn len(&self) -> usize {
        self.plates.len()
    }

    /// True when there are no plates.
    pub fn is_empty(&self) -> bool {
        self.plates.is_empty()
    }
}
