//! Stage 4 of a resampling: disconnected pieces of plates joined to a neighbour or made plates
//! of their own, and the plate entities rebuilt from the new assignment. See [`super`].
#![allow(clippy::needless_range_loop)]

use bevy_ecs::prelude::*;
use glam::{DQuat, DVec3};
use rayon::prelude::*;

use crate::components::{
    Plate, PlateBounds, PlateFrame, PlateId, PlateMesh, PlateMotion, PlateStats,
};
use crate::geometry::union_find::union_lowest;
use crate::geometry::{SphereMesh, angle_between};
use crate::resources::{Crust, CrustType, NO_PLATE};

/// A plate created by splitting a disconnected piece off its parent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PlateSplit {
    /// The new plate.
    pub child: u32,
    /// The plate it came from (whose motion it inherits).
    pub parent: u32,
}

/// Makes every plate one connected region of the mesh: for each plate the largest connected
/// piece keeps the id; a smaller piece becomes a plate of its own when its area is at least
/// `min_area_km2` (if `allow_split`), otherwise it joins the neighbouring plate it shares most
/// edges with. Deterministic (pieces are found in sample order).
pub fn defragment_plates(
    mesh: &SphereMesh,
    plate: &mut [u32],
    min_area_km2: f64,
    allow_split: bool,
    next_id: &mut u32,
) -> Vec<PlateSplit> {
    let n = mesh.len();
    // Connected pieces by union–find over the edges to lower-numbered neighbours of the same
    // plate, every piece rooted at its lowest sample (a link always points to a lower sample),
    // so that pieces are numbered in the order of their first sample. Each thread joins the
    // edges within its own block of samples; the edges between blocks are joined after.
    let mut parent: Vec<u32> = (0..n as u32).collect();
    const BLOCK: usize = 1 << 16;
    let across: Vec<Vec<(u32, u32)>> = parent
        .par_chunks_mut(BLOCK)
        .enumerate()
        .map(|(b, par)| {
            let base = b * BLOCK;
            let mut across = Vec::new();
            for k in 0..par.len() {
                let s = base + k;
                let p = plate[s];
                for &v in mesh.neighbors_of(s) {
                    let v = v as usize;
                    if v >= s || plate[v] != p {
                        continue;
                    }
                    if v < base {
                        across.push((s as u32, v as u32));
                    } else {
                        union_lowest(par, base, k, v - base);
                    }
                }
            }
            across
        })
        .collect();
    for (s, v) in across.into_iter().flatten() {
        union_lowest(&mut parent, 0, s as usize, v as usize);
    }
    // Pieces and their areas, in sample order: a sample's parent is lower, so its piece is
    // known by then.
    let mut comp = vec![u32::MAX; n];
    let mut comps: Vec<(u32, f64)> = Vec::new();
    for s in 0..n {
        let r = parent[s] as usize;
        let c = if r == s {
            comps.push((plate[s], 0.0));
            comps.len() - 1
        } else {
            comp[r] as usize
        };
        comp[s] = c as u32;
        comps[c].1 += mesh.area_km2[s];
    }
    if comps.len() == 1 {
        return Vec::new();
    }
    // Largest piece of each plate.
    let mut largest: std::collections::BTreeMap<u32, u32> = std::collections::BTreeMap::new();
    for (c, &(p, area)) in comps.iter().enumerate() {
        let e = largest.entry(p).or_insert(c as u32);
        if area > comps[*e as usize].1 {
            *e = c as u32;
        }
    }
    let mut splits = Vec::new();
    let mut kept = vec![false; comps.len()];
    for &c in largest.values() {
        kept[c as usize] = true;
    }
    let mut new_plate_of_comp: Vec<u32> = comps.iter().map(|c| c.0).collect();
    for (c, &(p, area)) in comps.iter().enumerate() {
        if !kept[c] && allow_split && area >= min_area_km2 {
            let child = *next_id;
            *next_id += 1;
            new_plate_of_comp[c] = child;
            kept[c] = true;
            splits.push(PlateSplit { child, parent: p });
        }
    }
    // The samples of the pieces that join a neighbour, by piece (in sample order).
    let mut member_start = vec![0u32; comps.len() + 1];
    for s in 0..n {
        let c = comp[s] as usize;
        if !kept[c] {
            member_start[c + 1] += 1;
        }
    }
    for c in 0..comps.len() {
        member_start[c + 1] += member_start[c];
    }
    let mut members = vec![0u32; member_start[comps.len()] as usize];
    {
        let mut next = member_start.clone();
        for s in 0..n {
            let c = comp[s] as usize;
            if !kept[c] {
                members[next[c] as usize] = s as u32;
                next[c] += 1;
            }
        }
    }
    for c in 0..comps.len() {
        if kept[c] {
            continue;
        }
        // Count edges to neighbouring pieces; prefer pieces that are kept.
        let mut counts: Vec<(bool, u32, u32)> = Vec::new(); // (kept, plate, count)
        for &u in &members[member_start[c] as usize..member_start[c + 1] as usize] {
            for &v in mesh.neighbors_of(u as usize) {
                let cv = comp[v as usize] as usize;
                if cv == c {
                    continue;
                }
                let key = (kept[cv], new_plate_of_comp[cv]);
                match counts.iter_mut().find(|e| (e.0, e.1) == key) {
                    Some(e) => e.2 += 1,
                    None => counts.push((key.0, key.1, 1)),
                }
            }
        }
        counts.sort_by(|a, b| b.0.cmp(&a.0).then(b.2.cmp(&a.2)).then(a.1.cmp(&b.1)));
        if let Some(&(_, target, _)) = counts.first() {
            new_plate_of_comp[c] = target;
        }
    }
    for (s, p) in plate.iter_mut().enumerate() {
        *p = new_plate_of_comp[comp[s] as usize];
    }
    splits
}

/// Geometry and statistics of one plate on the reference mesh.
#[derive(Clone, Debug, Default)]
pub struct PlateGeometry {
    /// Samples and triangles.
    pub mesh: PlateMesh,
    /// Bounding cap.
    pub bounds: Option<PlateBounds>,
    /// Areas.
    pub stats: PlateStats,
}

/// Computes each plate's samples, triangles, bounding cap and areas from a crust on the
/// reference mesh. Indexed by plate id (plates without samples get `None`).
pub fn plate_geometry(mesh: &SphereMesh, crust: &Crust) -> Vec<Option<PlateGeometry>> {
    plate_geometry_of(mesh, crust, None)
}

/// [`plate_geometry`] of the plates in `ids` only (all with `None`; the others get `None`):
/// each plate's geometry is the same as among all, since it reads only its own samples and
/// triangles. A collision's detachment or a rift touches two or three plates.
pub fn plate_geometry_of(
    mesh: &SphereMesh,
    crust: &Crust,
    ids: Option<&[u32]>,
) -> Vec<Option<PlateGeometry>> {
    let max_id = crust
        .plate
        .iter()
        .copied()
        .filter(|&p| p != NO_PLATE)
        .max()
        .map_or(0, |m| m as usize + 1);
    let mut wanted = vec![ids.is_none(); max_id];
    for &id in ids.unwrap_or(&[]) {
        if let Some(w) = wanted.get_mut(id as usize) {
            *w = true;
        }
    }
    // Samples per plate first, so that each plate's lists are allocated once.
    let mut count = vec![0usize; max_id];
    for &p in &crust.plate {
        if p != NO_PLATE && wanted[p as usize] {
            count[p as usize] += 1;
        }
    }
    // Each block of triangles lists its plates' triangles (in order) on its own thread; a
    // plate's triangles are its blocks' lists in block order.
    const BLOCK: usize = 1 << 16;
    let blocks: Vec<Vec<Vec<u32>>> = mesh
        .triangles
        .par_chunks(BLOCK)
        .enumerate()
        .map(|(b, tris)| {
            let mut lists = vec![Vec::new(); max_id];
            for (k, tri) in tris.iter().enumerate() {
                let o = [
                    crust.plate[tri[0] as usize],
                    crust.plate[tri[1] as usize],
                    crust.plate[tri[2] as usize],
                ];
                for k2 in 0..3 {
                    if o[k2] == NO_PLATE || o[..k2].contains(&o[k2]) || !wanted[o[k2] as usize] {
                        continue;
                    }
                    lists[o[k2] as usize].push((b * BLOCK + k) as u32);
                }
            }
            lists
        })
        .collect();
    let mut out: Vec<Option<PlateGeometry>> = (0..max_id)
        .map(|id| {
            (count[id] > 0).then(|| {
                let tris = blocks.iter().map(|l| l[id].len()).sum();
                let mut triangles = Vec::with_capacity(tris);
                for l in &blocks {
                    triangles.extend_from_slice(&l[id]);
                }
                PlateGeometry {
                    mesh: PlateMesh {
                        samples: Vec::with_capacity(count[id]),
                        triangles,
                    },
                    ..Default::default()
                }
            })
        })
        .collect();
    drop(blocks);
    let mut centroid_sum = vec![DVec3::ZERO; max_id];
    for (s, &p) in crust.plate.iter().enumerate() {
        if p == NO_PLATE {
            continue;
        }
        let Some(g) = out[p as usize].as_mut() else {
            continue;
        };
        g.mesh.samples.push(s as u32);
        let a = mesh.area_km2[s];
        g.stats.area_km2 += a;
        if crust.crust_type[s] == CrustType::Continental {
            g.stats.continental_area_km2 += a;
        }
        centroid_sum[p as usize] += mesh.positions[s] * a;
    }
    out.par_iter_mut().enumerate().for_each(|(id, g)| {
        let Some(g) = g.as_mut() else { return };
        let centroid = centroid_sum[id]
            .try_normalize()
            .unwrap_or_else(|| mesh.positions[g.mesh.samples[0] as usize]);
        // The farthest sample has the least dot product with the centroid: the angle (the
        // costlier measure) is taken only of the samples within 1e-9 of that least dot, far
        // more than the rounding of either, so the maximum is the one over all samples.
        let least = g.mesh.samples.iter().fold(f64::INFINITY, |m, &s| {
            m.min(centroid.dot(mesh.positions[s as usize]))
        });
        let mut radius: f64 = 0.0;
        for &s in &g.mesh.samples {
            let p = mesh.positions[s as usize];
            if centroid.dot(p) <= least + 1e-9 {
                radius = radius.max(angle_between(centroid, p));
            }
        }
        g.bounds = Some(PlateBounds {
            centroid,
            cap_radius_rad: radius + 1.5 * mesh.max_edge_rad,
        });
    });
    out
}

/// Brings plate entities in line with `Crust::plate`: updates mesh, bounds and stats, despawns
/// plates left without samples, spawns split-off plates with their parent's motion, and resets
/// every frame to the identity.
pub fn rebuild_plate_entities(world: &mut World, splits: &[PlateSplit]) {
    let geometry = {
        let mesh = world.resource::<SphereMesh>();
        let crust = world.resource::<Crust>();
        plate_geometry(mesh, crust)
    };
    let mut existing: Vec<(Entity, u32, PlateMotion)> = world
        .query::<(Entity, &Plate, &PlateMotion)>()
        .iter(world)
        .map(|(e, p, m)| (e, p.id.0, *m))
        .collect();
    existing.sort_by_key(|e| e.1);
    let mut geometry = geometry;
    for (entity, id, _) in &existing {
        match geometry.get_mut(*id as usize).and_then(|g| g.take()) {
            Some(g) => {
                let bounds = g.bounds.unwrap_or(PlateBounds {
                    centroid: DVec3::Z,
                    cap_radius_rad: std::f64::consts::PI,
                });
                world
                    .entity_mut(*entity)
                    .insert((g.mesh, bounds, g.stats, PlateFrame::default()));
            }
            None => {
                tracing::debug!(plate = id, "plate has no samples left: despawned");
                world.despawn(*entity);
            }
        }
    }
    for split in splits {
        let Some(g) = geometry
            .get_mut(split.child as usize)
            .and_then(|g| g.take())
        else {
            continue;
        };
        let motion = existing
            .iter()
            .find(|e| e.1 == split.parent)
            .map(|e| e.2)
            .unwrap_or(PlateMotion {
                euler_pole: DVec3::Z,
                angular_speed_rad_per_my: 0.0,
            });
        let bounds = g.bounds.unwrap_or(PlateBounds {
            centroid: DVec3::Z,
            cap_radius_rad: std::f64::consts::PI,
        });
        tracing::debug!(
            child = split.child,
            parent = split.parent,
            "plate piece split off"
        );
        world.spawn((
            Plate {
                id: PlateId(split.child),
            },
            motion,
            PlateFrame {
                world_from_plate: DQuat::IDENTITY,
            },
            g.mesh,
            bounds,
            g.stats,
        ));
    }
}
