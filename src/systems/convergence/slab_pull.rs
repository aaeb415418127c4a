//! Slab pull (paper §4.1): a subducting plate's Euler pole turns toward its fronts, weighted by
//! front length. See [`super`] for the model.
#![allow(clippy::needless_range_loop)]

use bevy_ecs::prelude::*;
use glam::DVec3;

use crate::components::{Plate, PlateBounds, PlateFrame, PlateMotion};
use crate::geometry::SphereMesh;
use crate::resources::FrontPoints;
use crate::resources::params::Params;

/// Slab pull: each subducting plate's Euler pole turns toward its active fronts.
pub fn slab_pull(
    mesh: Res<SphereMesh>,
    params: Res<Params>,
    fp: Res<FrontPoints>,
    mut plates: Query<(&Plate, &mut PlateMotion, &PlateFrame, &PlateBounds)>,
) {
    if fp.is_empty() {
        return;
    }
    let r_km = params.planet.radius_km;
    let dt = params.time.time_step_my;
    let eps = 0.01 * params.subduction.slab_pull_perturbation;
    let frames: std::collections::BTreeMap<u32, (glam::DMat3, DVec3)> = plates
        .iter()
        .map(|(p, _, f, b)| {
            let m = f.world_from_plate_mat();
            (p.id.0, (m, m * b.centroid))
        })
        .collect();
    let mut pull: std::collections::BTreeMap<u32, DVec3> = std::collections::BTreeMap::new();
    for k in 0..fp.len() {
        if !fp.active[k] {
            continue;
        }
        let (Some(over), Some(sub)) =
            (frames.get(&fp.overriding[k]), frames.get(&fp.subducting[k]))
        else {
            continue;
        };
        let q = over.0 * mesh.positions[fp.sample[k] as usize];
        let c = sub.1;
        if let Some(dir) = c.cross(q).try_normalize() {
            *pull.entry(fp.subducting[k]).or_insert(DVec3::ZERO) +=
                dir * (fp.length_km[k] as f64 / r_km);
        }
    }
    for (p, mut m, _, _) in &mut plates {
        if let Some(sum) = pull.get(&p.id.0) {
            let w = m.euler_pole + *sum * (eps * dt);
            if let Some(w) = w.try_normalize() {
                m.euler_pole = w;
            }
        }
    }
}
