//! Subduction fronts: found at each resampling from the converging plate-boundary edges (who goes
//! under, the front points, the distance fields), and tracked every step (the subducting crust
//! now under each front point, the convergence accumulated). See [`super`] for the model.
#![allow(clippy::needless_range_loop)]

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;

use super::propagate_nearest_grouped;
use crate::components::{
    FrontKind, Plate, PlateBounds, PlateFrame, PlateId, PlateMotion, PlateStats, SubductionFront,
};
use crate::geometry::SphereMesh;
use crate::geometry::union_find::{find_lowest, union_lowest};
use crate::gpu::{FieldMask, GpuContext};
use crate::resources::convergence::NONE;
use crate::resources::params::Params;
use crate::resources::{
    ConvergenceField, Crust, CrustType, FrontPoints, OverridePairs, PlateTable, RiftSiblings,
};

/// One converging boundary edge: overriding-side sample, subducting-side sample.
#[derive(Clone, Copy, Debug)]
struct ConvergingEdge {
    a: u32,
    b: u32,
    plate_a: u32,
    plate_b: u32,
    /// Unit tangent from a toward b at the edge midpoint.
    normal: DVec3,
}

/// Finds the fronts on a freshly resampled crust (every plate in the reference frame): fills
/// [`FrontPoints`], [`ConvergenceField`] and [`OverridePairs`] and respawns the
/// [`SubductionFront`] entities.
pub fn build_fronts(world: &mut World) {
    let _timer = crate::systems::DebugTimer::new("build_fronts");
    let table = {
        let mut q = world.query::<(&Plate, &PlateMotion, &PlateFrame, &PlateBounds, &PlateStats)>();
        PlateTable::from_plates(q.iter(world).map(|(p, m, f, b, s)| (*p, *m, *f, *b, *s)))
    };
    let params = world.resource::<Params>().clone();
    let mesh = world.resource::<SphereMesh>();
    let crust = world.resource::<Crust>();
    let r_km = params.planet.radius_km;
    let min_conv = params.subduction.min_convergence_mm_per_yr;
    let n = mesh.len();
    let now_my = world.resource::<crate::resources::SimClock>().time_my;
    let siblings = world
        .get_resource::<RiftSiblings>()
        .filter(|s| !s.pairs.is_empty());

    // 1. Converging boundary edges (each undirected edge once, from its lower index), but
    // between a rift's fragments still exempt from fronts ([`RiftSiblings`]).
    let edges: Vec<ConvergingEdge> = (0..n)
        .into_par_iter()
        .with_min_len(4096)
        .flat_map_iter(|u| {
            let pu = crust.plate[u];
            let mut out = Vec::new();
            for &v in mesh.neighbors_of(u) {
                let v = v as usize;
                let pv = crust.plate[v];
                if v < u || pv == pu || siblings.is_some_and(|s| s.exempt(pu, pv, now_my)) {
                    continue;
                }
                let (Some(a), Some(b)) = (table.get(pu), table.get(pv)) else {
                    continue;
                };
                let (xu, xv) = (mesh.positions[u], mesh.positions[v]);
                let m = (xu + xv).normalize();
                let Some(normal) = (xv - xu - m * m.dot(xv - xu)).try_normalize() else {
                    continue;
                };
                let rel =
                    a.motion.velocity_km_per_my(m, r_km) - b.motion.velocity_km_per_my(m, r_km);
                if rel.dot(normal) > min_conv {
                    out.push(ConvergingEdge {
                        a: u as u32,
                        b: v as u32,
                        plate_a: pu,
                        plate_b: pv,
                        normal,
                    });
                }
            }
            out.into_iter()
        })
        .collect();

    tracing::debug!(edges = edges.len(), "converging edges");
    let _t_runs = crate::systems::DebugTimer::new("front runs and points");
    // 2. Runs: edges of the same plate pair sharing a vertex.
    let mut parent: Vec<u32> = (0..edges.len() as u32).collect();
    let mut by_vertex: std::collections::HashMap<(u32, u32, u32), usize> =
        std::collections::HashMap::new();
    for (i, e) in edges.iter().enumerate() {
        let pair = (e.plate_a.min(e.plate_b), e.plate_a.max(e.plate_b));
        for v in [e.a, e.b] {
            match by_vertex.get(&(pair.0, pair.1, v)) {
                Some(&j) => {
                    union_lowest(&mut parent, 0, i, j);
                }
                None => {
                    by_vertex.insert((pair.0, pair.1, v), i);
                }
            }
        }
    }
    drop(by_vertex);
    let mut runs: std::collections::BTreeMap<usize, Vec<usize>> = std::collections::BTreeMap::new();
    for i in 0..edges.len() {
        let r = find_lowest(&mut parent, 0, i);
        runs.entry(r).or_default().push(i);
    }

    // 3. Decide who goes under, per run, and collect front points.
    let mut fp = FrontPoints::default();
    let mut fronts: Vec<SubductionFront> = Vec::new();
    let mut pairs: Vec<(u32, u32)> = Vec::new();
    let spacing_km = mesh.mean_spacing_rad() * r_km;
    let mut point_of_sample: std::collections::HashMap<u32, u32> = std::collections::HashMap::new();
    let mut sub_seeds: Vec<(u32, u32)> = Vec::new();
    for idx in runs.values() {
        let e0 = edges[idx[0]];
        let (p, q) = (e0.plate_a.min(e0.plate_b), e0.plate_a.max(e0.plate_b));
        let (mut cont, mut age, mut cnt) = ([0.0f64; 2], [0.0f64; 2], [0.0f64; 2]);
        for &i in idx {
            let e = edges[i];
            for (s, pl) in [(e.a, e.plate_a), (e.b, e.plate_b)] {
                let side = usize::from(pl != p);
                cnt[side] += 1.0;
                if crust.crust_type[s as usize] == CrustType::Continental {
                    cont[side] += 1.0;
                }
                age[side] += crust.age_my[s as usize] as f64;
            }
        }
        let cont_p = cont[0] > 0.5 * cnt[0];
        let cont_q = cont[1] > 0.5 * cnt[1];
        let score = |id: u32| table.get(id).map_or(0.0, |s| s.overlap_score);
        let (over, sub, kind) = match (cont_p, cont_q) {
            (true, false) => (p, q, FrontKind::OceanUnderContinent),
            (false, true) => (q, p, FrontKind::OceanUnderContinent),
            (false, false) => {
                // The older plate subducts.
                if age[0] / cnt[0].max(1.0) >= age[1] / cnt[1].max(1.0) {
                    (q, p, FrontKind::OceanUnderOcean)
                } else {
                    (p, q, FrontKind::OceanUnderOcean)
                }
            }
            (true, true) => {
                if score(p) >= score(q) {
                    (p, q, FrontKind::Forced)
                } else {
                    (q, p, FrontKind::Forced)
                }
            }
        };
        pairs.push((over, sub));
        let mut points = Vec::new();
        point_of_sample.clear();
        for &i in idx {
            let e = edges[i];
            let (os, ss, normal) = if e.plate_a == over {
                (e.a, e.b, e.normal)
            } else {
                (e.b, e.a, -e.normal)
            };
            let k = *point_of_sample.entry(os).or_insert_with(|| {
                let k = fp.sample.len() as u32;
                fp.sample.push(os);
                fp.overriding.push(over);
                fp.subducting.push(sub);
                fp.normal.push(DVec3::ZERO);
                fp.length_km.push(spacing_km as f32);
                points.push(k);
                k
            });
            fp.normal[k as usize] += normal;
            sub_seeds.push((ss, k));
        }
        fronts.push(SubductionFront {
            overriding: PlateId(over),
            subducting: PlateId(sub),
            kind,
            length_km: points.len() as f64 * spacing_km,
            points,
        });
    }
    for (k, nrm) in fp.normal.iter_mut().enumerate() {
        let p = mesh.positions[fp.sample[k] as usize];
        *nrm = (*nrm - p * p.dot(*nrm))
            .try_normalize()
            .unwrap_or(DVec3::ZERO);
    }
    let m = fp.len();
    fp.active = vec![false; m];
    fp.trench = vec![false; m];
    fp.subducting_elevation_km = vec![0.0; m];
    fp.relative_velocity = vec![DVec3::ZERO; m];
    fp.converged_km = vec![0.0; m];
    fp.convergence_km_per_my = vec![0.0; m];
    fp.near_vertex = vec![NONE; m];
    pairs.sort_unstable();
    pairs.dedup();

    drop(_t_runs);
    // 4. Distance fields.
    let mut field = world
        .remove_resource::<ConvergenceField>()
        .unwrap_or_default();
    let mesh = world.resource::<SphereMesh>();
    let crust = world.resource::<Crust>();
    field.overriding_distance_km.clear();
    field.overriding_distance_km.resize(n, f32::INFINITY);
    field.overriding_point.clear();
    field.overriding_point.resize(n, NONE);
    field.subducting_distance_km.clear();
    field.subducting_distance_km.resize(n, f32::INFINITY);
    field.subducting_point.clear();
    field.subducting_point.resize(n, NONE);
    let over_seeds: Vec<(u32, u32)> = fp
        .sample
        .iter()
        .enumerate()
        .map(|(k, &s)| (s, k as u32))
        .collect();
    let origin = |l: u32| mesh.positions[fp.sample[l as usize] as usize];
    // The subducting side is followed as far as the fastest plate can carry crust to the front
    // before the next resampling, plus the collision threshold and the trench.
    let sub_limit = (params.resample.adaptive_displacement_km
        + params.collision.interpenetration_km
        + params.subduction.trench_width_km)
        / r_km;
    {
        let _t = crate::systems::DebugTimer::new("front distance fields");
        let ConvergenceField {
            overriding_distance_km,
            overriding_point,
            subducting_distance_km,
            subducting_point,
        } = &mut field;
        let fp = &fp;
        rayon::join(
            || {
                propagate_nearest_grouped(
                    mesh,
                    &over_seeds,
                    origin,
                    &crust.plate,
                    |l| fp.overriding[l as usize],
                    params.subduction.distance_km / r_km,
                    overriding_distance_km,
                    overriding_point,
                )
            },
            || {
                propagate_nearest_grouped(
                    mesh,
                    &sub_seeds,
                    origin,
                    &crust.plate,
                    |l| fp.subducting[l as usize],
                    sub_limit,
                    subducting_distance_km,
                    subducting_point,
                )
            },
        );
    }
    for d in field
        .overriding_distance_km
        .iter_mut()
        .chain(field.subducting_distance_km.iter_mut())
    {
        if d.is_finite() {
            *d *= r_km as f32;
        }
    }
    world.insert_resource(field);
    world.insert_resource(fp);
    world.insert_resource(OverridePairs(pairs));
    let old: Vec<Entity> = world
        .query_filtered::<Entity, With<SubductionFront>>()
        .iter(world)
        .collect();
    for e in old {
        world.despawn(e);
    }
    for f in fronts {
        world.spawn(f);
    }
}

/// What the front tracking reads and writes.
#[derive(bevy_ecs::system::SystemParam)]
pub struct FrontTracking<'w, 's> {
    mesh: Res<'w, SphereMesh>,
    crust: Res<'w, Crust>,
    params: Res<'w, Params>,
    plates: crate::resources::PlateTableQuery<'w, 's>,
    fp: ResMut<'w, FrontPoints>,
    gpu: Option<ResMut<'w, GpuContext>>,
}

/// Every step, first in the subduction set: for each front point, where the subducting plate is
/// now, the elevation of its crust under the point, the relative velocity, and the convergence
/// accumulated since the last resampling.
pub fn track_fronts(t: FrontTracking) {
    let dt = t.params.time.time_step_my as f32;
    track_fronts_over(dt, t);
}

/// [`track_fronts`] without adding any convergence: after a resampling rebuilt the fronts (all
/// inactive until then), which are active and what lies under them, for what reads them before
/// the next step (the isostasy's trench, see `AfterResampleSystems::Relief`).
pub fn refresh_fronts(t: FrontTracking) {
    let _t = crate::systems::DebugTimer::new("refresh_fronts");
    track_fronts_over(0.0, t);
}

fn track_fronts_over(dt: f32, t: FrontTracking) {
    let FrontTracking {
        mesh,
        crust,
        params,
        plates,
        mut fp,
        gpu,
    } = t;
    let (mesh, crust, params): (&SphereMesh, &Crust, &Params) = (&mesh, &crust, &params);
    let table = PlateTable::from_query(&plates);
    let r_km = params.planet.radius_km;
    let fp = &mut *fp;
    // How far ahead of a point, towards the subducting plate, a second point looks for the slab
    // when the triangle under the point has none (for the trench): one mean sample spacing.
    let probe_rad = mesh.mean_spacing_rad();
    // Where each front point is: the triangle and weights under it in the subducting plate
    // (f64, on the CPU), whether subducting crust is there, the velocities.
    type Located = ((bool, bool), [u32; 3], [f64; 3], DVec3, f32, u32);
    let located: Vec<Option<Located>> = (0..fp.len())
        .into_par_iter()
        .with_min_len(256)
        .map(|k| {
            let (Some(over), Some(sub)) =
                (table.get(fp.overriding[k]), table.get(fp.subducting[k]))
            else {
                return None;
            };
            let w = over.world_from_plate * mesh.positions[fp.sample[k] as usize];
            let loc = mesh.locate(sub.plate_from_world * w);
            let t = mesh.triangles[loc.triangle as usize];
            let n_world = over.world_from_plate * fp.normal[k];
            let subducting_under =
                |t: [u32; 3]| t.iter().any(|&v| crust.plate[v as usize] == sub.id);
            let under = subducting_under(t);
            // A front point is a sample of the overriding plate, so right after a resampling it
            // sits on a vertex and the triangle found under it is a tie among the fan around
            // it: about a fifth of the points find no subducting vertex although the slab is
            // one sample away, and their stretch of trench went missing (the trenches came out
            // as dotted lines). A second point one spacing ahead, on the subducting side,
            // settles it for the trench. The uplift and the slab pull keep the test of the
            // point's own triangle: the uplift's rate was calibrated with those gaps, and with
            // them filled too the land rose over long runs (docs/relief.md, "Trenches without
            // gaps").
            let ahead = under || {
                let p = (w + n_world * probe_rad).normalize();
                subducting_under(
                    mesh.triangles[mesh.locate(sub.plate_from_world * p).triangle as usize],
                )
            };
            let rel_world =
                sub.motion.velocity_km_per_my(w, r_km) - over.motion.velocity_km_per_my(w, r_km);
            let conv = (-rel_world.dot(n_world)) as f32;
            // A front acts only while subducting crust is under it and the plates still converge.
            let converging = conv as f64 > params.subduction.min_convergence_mm_per_yr;
            Some((
                (under && converging, ahead && converging),
                t,
                [loc.weights[0], loc.weights[1], loc.weights[2]],
                over.plate_from_world * rel_world,
                conv,
                t[loc.dominant_corner()],
            ))
        })
        .collect();
    // The elevation at the three vertices of each located point. On the GPU backend, when the
    // device holds the elevation newer than the host (lazy host sync), the gather kernel reads
    // just these 3F values (raw f32, the same bits as the host array after a pull).
    let index: Vec<u32> = located
        .iter()
        .flatten()
        .flat_map(|&(_, t, _, _, _, _)| t)
        .collect();
    let mut gathered = None;
    if let Some(mut gpu) = gpu
        && gpu.device_newer().contains(FieldMask::ELEVATION)
    {
        let mut z = Vec::new();
        if crate::gpu::run_or_record(&mut gpu, |g| {
            z = crate::gpu::crust_gather::crust_gather_gpu(g, &index)?;
            Ok(())
        }) {
            gathered = Some(z);
        }
    }
    let gathered = gathered
        .unwrap_or_else(|| crate::gpu::crust_gather::crust_gather_cpu(&crust.elevation_km, &index));
    let mut next = 0;
    // (Active and trench, the elevation under the point, the relative velocity, the
    // convergence rate, the nearest-vertex hint.)
    type Tracked = ((bool, bool), f32, DVec3, f32, u32);
    let results: Vec<Tracked> = located
        .into_iter()
        .map(|l| {
            let Some((active, _, weights, rel, conv, near)) = l else {
                return ((false, false), 0.0, DVec3::ZERO, 0.0, NONE);
            };
            let zv = &gathered[next..next + 3];
            next += 3;
            let z = (0..3).map(|i| weights[i] * zv[i] as f64).sum::<f64>() as f32;
            (active, z, rel, conv, near)
        })
        .collect();
    fp.near_vertex.resize(fp.len(), NONE);
    for (k, ((active, trench), z, rel, conv, near)) in results.into_iter().enumerate() {
        fp.near_vertex[k] = near;
        fp.active[k] = active;
        fp.trench[k] = trench;
        fp.subducting_elevation_km[k] = z;
        fp.relative_velocity[k] = rel;
        fp.converged_km[k] += conv * dt;
        fp.convergence_km_per_my[k] = conv;
    }
}
