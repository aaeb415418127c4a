//! Convergent boundaries (paper §4.1, §4.2, §6; Driftworld §3.8, §3.9, §3.13): subduction
//! fronts, subduction uplift and trenches, slab pull, terranes and continental collisions.
//!
//! How the pieces fit, and the choices made where the paper is vague:
//! - **Fronts** are found at each resampling, when every plate is in the reference frame: a
//!   plate-boundary edge whose plates approach each other faster than
//!   `subduction.min_convergence_mm_per_yr` is converging; connected runs of such edges between
//!   the same two plates form one front. Who goes under is decided per front as the paper does:
//!   oceanic under continental, the older of two oceanic plates, and for continent against
//!   continent a forced subduction of the plate with the lower overlap score. The front's
//!   points are the overriding plate's boundary samples. The front is fixed in the overriding
//!   plate's frame until the next resampling (the subducting plate slides under it).
//! - **Distances** to the front are great-circle distances (never hop counts), propagated once
//!   per resampling through each plate's own samples: for the overriding plate, the distance of
//!   each sample to the nearest front point (uplift); for the subducting plate, the distance of
//!   each sample to the front at the resampling, from which the distance now is that minus the
//!   convergence accumulated at its front point since (trench, interpenetration).
//! - **Uplift** on the overriding plate: ũ = u0·f(d)·g(v)·h(z̃) with Driftworld's cubic f (peak 1
//!   at the control distance, 0 at r_s; its small negative part near the front is clipped to 0,
//!   since the trench is made on the subducting side), g = v/v0 and h = z̃², z̃ the normalised
//!   elevation of the subducting crust now at the front point (located in the subducting plate
//!   every step). Elevations are capped at z_c. Uplifted crust above sea level gets Andean
//!   orogeny with its age reset (island arcs stay oceanic crust: turning emerged arcs into
//!   continental crust grew the default planet's continents by 13% per 1000 My at 500,000
//!   samples); fold directions take β·(s_sub − s_over)·δt.
//! - **Trench**: oceanic crust of the subducting plate within `subduction.trench_width_km` of the
//!   front deepens toward a profile from z_t at the front to z_a at the trench edge.
//! - **Slab pull**: w ← normalise(w + 0.01·ε·Σ_k (c × q_k)/|c × q_k|·(ℓ_k/R)·δt) over the active
//!   front points q_k of the subducting plate, each weighted by the front length ℓ_k it stands
//!   for, so the effect depends on the length of the front, not on the sample count.
//! - **Collisions** fire when continental crust of a subducting plate is more than
//!   `collision.interpenetration_km` past a front where the overriding crust is continental too
//!   (and at any depth when a resampling is about to run, so that no continental crust is lost
//!   under another plate). The smaller of the two terranes in contact leaves its plate and
//!   sutures to the other at that resampling; then the crust around it rises by
//!   Δz = Δz₀·(1 − (d/r)²)², r = r_c·min(1, √(v/v0·A/A0)), Δz₀ = H·(1 − exp(−Δ_c·A/H)) (the
//!   paper's Δ_c·A for small terranes, saturating at H = `collision.max_uplift_km` for
//!   continents, since Δ_c·A alone gives tens of kilometres for a continent), with Himalayan
//!   orogeny and fold directions pointing away from the terrane centroid.
#![allow(clippy::needless_range_loop)]

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;

use crate::components::{
    FrontKind, Plate, PlateBounds, PlateFrame, PlateId, PlateMotion, PlateStats, SubductionFront,
    Terrane,
};
use crate::geometry::SphereMesh;
use crate::gpu::{FieldMask, GpuContext, run_or_record};
use crate::io::params::Params;
use crate::resources::convergence::NONE;
use crate::resources::{
    ConvergenceField, Crust, CrustType, FrontPoints, Orogeny, OverridePairs, PlateTable,
    ResampleRequest, Suture, Sutures, TerraneField,
};

/// Nearest-seed propagation through the mesh in order of true great-circle distance to the
/// seed point (a bucket queue, as for the gaps). `seeds` are (sample, label) pairs; the
/// distance is measured to `origin(label)`; a sample is reached only if `allowed(sample,
/// label)`; nothing farther than `max_rad`. Writes distances (radians) and labels of reached
/// samples; others keep their values.
#[allow(clippy::too_many_arguments)]
pub fn propagate_nearest(
    mesh: &SphereMesh,
    seeds: &[(u32, u32)],
    origin: impl Fn(u32) -> DVec3,
    allowed: impl Fn(usize, u32) -> bool,
    max_rad: f64,
    dist_rad: &mut [f32],
    label: &mut [u32],
    settled: &mut Vec<bool>,
) {
    settled.clear();
    settled.resize(mesh.len(), false);
    // Ordered by chord length (monotone in the great-circle angle, and much cheaper). While the
    // search runs, `dist_rad` holds the best chord offered so far (a worse offer is not queued)
    // and `label` its front point; chords become angles at the end.
    let chord = |a: DVec3, b: DVec3| (a - b).length();
    let max_chord = 2.0 * (0.5 * max_rad.min(std::f64::consts::PI)).sin();
    let width = 0.5 * mesh.mean_spacing_rad();
    let mut buckets: Vec<Vec<(u32, u32, f32)>> = Vec::new();
    let offer = |buckets: &mut Vec<Vec<(u32, u32, f32)>>,
                 dist: &mut [f32],
                 lab: &mut [u32],
                 cur: usize,
                 c: f64,
                 node: u32,
                 l: u32| {
        let n = node as usize;
        if c > max_chord || (c as f32) >= dist[n] {
            return;
        }
        dist[n] = c as f32;
        lab[n] = l;
        let b = ((c / width) as usize).max(cur);
        if b >= buckets.len() {
            buckets.resize_with(b + 1, Vec::new);
        }
        buckets[b].push((node, l, c as f32));
    };
    for &(s, l) in seeds {
        if allowed(s as usize, l) {
            let c = chord(mesh.positions[s as usize], origin(l));
            offer(&mut buckets, dist_rad, label, 0, c, s, l);
        }
    }
    let mut cur = 0;
    while cur < buckets.len() {
        let mut k = 0;
        while k < buckets[cur].len() {
            let (node, l, c) = buckets[cur][k];
            k += 1;
            let n = node as usize;
            if settled[n] || label[n] != l || c > dist_rad[n] {
                continue; // settled already, or a better offer came later
            }
            settled[n] = true;
            let o = origin(l);
            for &h in mesh.neighbors_of(n) {
                let h = h as usize;
                if settled[h] || !allowed(h, l) {
                    continue;
                }
                let c = chord(mesh.positions[h], o);
                offer(&mut buckets, dist_rad, label, cur, c, h as u32, l);
            }
        }
        buckets[cur] = Vec::new();
        cur += 1;
    }
    dist_rad.par_iter_mut().with_min_len(4096).for_each(|d| {
        if d.is_finite() {
            *d = (2.0 * (0.5 * *d as f64).min(1.0).asin()) as f32;
        }
    });
}

/// Driftworld's cubic distance transfer: 1 at the control distance `rc`, 0 at `rs` (and beyond),
/// clipped at 0 near the front.
pub fn distance_transfer(d: f64, rc: f64, rs: f64) -> f64 {
    if d >= rs {
        return 0.0;
    }
    let num = d.powi(3) / 3.0 - (rc + rs) * d * d / 2.0 + rc * rs * d + rs.powi(3) / 6.0
        - rs * rs * rc / 2.0;
    let den = (rs.powi(3) - rc.powi(3)) / 6.0 + (rc * rc * rs - rs * rs * rc) / 2.0;
    if den.abs() < 1e-12 {
        return 0.0;
    }
    (num / den).max(0.0)
}

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

    // 1. Converging boundary edges (each undirected edge once, from its lower index).
    let edges: Vec<ConvergingEdge> = (0..n)
        .into_par_iter()
        .with_min_len(4096)
        .flat_map_iter(|u| {
            let pu = crust.plate[u];
            let mut out = Vec::new();
            for &v in mesh.neighbors_of(u) {
                let v = v as usize;
                let pv = crust.plate[v];
                if v < u || pv == pu {
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
    let mut parent: Vec<usize> = (0..edges.len()).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    let mut by_vertex: std::collections::HashMap<(u32, u32, u32), usize> =
        std::collections::HashMap::new();
    for (i, e) in edges.iter().enumerate() {
        let pair = (e.plate_a.min(e.plate_b), e.plate_a.max(e.plate_b));
        for v in [e.a, e.b] {
            match by_vertex.get(&(pair.0, pair.1, v)) {
                Some(&j) => {
                    let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
                    if ri != rj {
                        parent[ri.max(rj)] = ri.min(rj);
                    }
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
        let r = find(&mut parent, i);
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
    fp.subducting_elevation_km = vec![0.0; m];
    fp.relative_velocity = vec![DVec3::ZERO; m];
    fp.converged_km = vec![0.0; m];
    fp.convergence_km_per_my = vec![0.0; m];
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
                propagate_nearest(
                    mesh,
                    &over_seeds,
                    origin,
                    |s, l| crust.plate[s] == fp.overriding[l as usize],
                    params.subduction.distance_km / r_km,
                    overriding_distance_km,
                    overriding_point,
                    &mut Vec::new(),
                )
            },
            || {
                propagate_nearest(
                    mesh,
                    &sub_seeds,
                    origin,
                    |s, l| crust.plate[s] == fp.subducting[l as usize],
                    sub_limit,
                    subducting_distance_km,
                    subducting_point,
                    &mut Vec::new(),
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

/// Welds into the continent every small patch of oceanic crust (smaller than
/// `collision.trapped_ocean_km2`) that the continental crust of a single plate encloses: the
/// remnants of an ocean closed by a collision. Its elevation is taken from the surrounding
/// continent, from the shore inward. Without this, such slivers stay as pits kilometres deep in
/// the middle of mountain belts.
pub fn close_trapped_ocean(world: &mut World) {
    let _timer = crate::systems::DebugTimer::new("close_trapped_ocean");
    let limit = world.resource::<Params>().collision.trapped_ocean_km2;
    if limit <= 0.0 {
        return;
    }
    // First the trapped components (crust type and plate only, which no GPU kernel writes);
    // filling one cannot change the test of another (components are not adjacent), so this
    // finds the same ones as testing and filling in turn.
    let trapped = {
        let crust = world.resource::<Crust>();
        let mesh = world.resource::<SphereMesh>();
        let n = mesh.len();
        let mut seen = vec![false; n];
        let mut trapped: Vec<Vec<usize>> = Vec::new();
        let mut comp = Vec::new();
        for s in 0..n {
            if seen[s] || crust.crust_type[s] != CrustType::Oceanic {
                continue;
            }
            comp.clear();
            comp.push(s);
            seen[s] = true;
            let (mut area, mut enclosed, mut k) = (0.0, true, 0);
            let plate = crust.plate[s];
            while k < comp.len() {
                let u = comp[k];
                k += 1;
                area += mesh.area_km2[u];
                for &v in mesh.neighbors_of(u) {
                    let v = v as usize;
                    if crust.crust_type[v] == CrustType::Oceanic {
                        if !seen[v] {
                            seen[v] = true;
                            comp.push(v);
                        }
                    } else if crust.plate[v] != plate {
                        enclosed = false;
                    }
                }
                if area >= limit {
                    enclosed = false;
                }
            }
            if !enclosed || area >= limit || comp.iter().any(|&u| crust.plate[u] != plate) {
                continue;
            }
            trapped.push(comp.clone());
        }
        trapped
    };
    // Nothing to weld: the crust is left untouched (its change tick does not move, so on the
    // GPU backend the device copy, surged by the collision kernel, stays current).
    if trapped.is_empty() {
        return;
    }
    // The fill reads elevations: on the GPU backend the elevation comes down first (the
    // collision kernel may have raised it). The fill runs on copies of the elevation and crust
    // type (later rings read the samples filled before them), then the written samples go into
    // the crust as a declared write of elevation, crust type and thickness (on the GPU backend
    // those three fields go up, 9 B/sample, instead of a pull of every field and a full upload).
    if !crate::gpu::sync_crust_to_host_or_record(world, crate::gpu::FieldMask::ELEVATION) {
        return;
    }
    let thickness = world.resource::<Params>().init.continental_thickness_km as f32;
    let mut writes: Vec<(usize, f32)> = Vec::new();
    {
        let crust = world.resource::<Crust>();
        let mesh = world.resource::<SphereMesh>();
        let mut elevation = crust.elevation_km.clone();
        let mut crust_type = crust.crust_type.clone();
        for comp in &trapped {
            // Fill from the shore inward with the mean elevation of continental neighbours.
            let mut remaining: Vec<usize> = comp.clone();
            while !remaining.is_empty() {
                let mut next = Vec::new();
                let mut filled = Vec::new();
                for &u in &remaining {
                    let (mut sum, mut cnt) = (0.0f64, 0u32);
                    for &v in mesh.neighbors_of(u) {
                        if crust_type[v as usize] == CrustType::Continental {
                            sum += elevation[v as usize] as f64;
                            cnt += 1;
                        }
                    }
                    if cnt > 0 {
                        filled.push((u, (sum / cnt as f64) as f32));
                    } else {
                        next.push(u);
                    }
                }
                if filled.is_empty() {
                    break;
                }
                for (u, z) in filled {
                    elevation[u] = z;
                    crust_type[u] = CrustType::Continental;
                    writes.push((u, z));
                }
                remaining = next;
            }
        }
    }
    use crate::gpu::FieldMask;
    crate::gpu::write_crust_fields_or_record(
        world,
        FieldMask::ELEVATION | FieldMask::CRUST_TYPE | FieldMask::THICKNESS,
        |crust| {
            for &(u, z) in &writes {
                crust.elevation_km[u] = z;
                crust.crust_type[u] = CrustType::Continental;
                crust.thickness_km[u] = thickness;
            }
        },
    );
}

/// Rebuilds the terranes: connected continental regions within each plate, as entities and as
/// the per-sample [`TerraneField`].
pub fn build_terranes(world: &mut World) {
    let _timer = crate::systems::DebugTimer::new("build_terranes");
    let mesh = world.resource::<SphereMesh>();
    let crust = world.resource::<Crust>();
    let n = mesh.len();
    let mut field = TerraneField {
        terrane: vec![NONE; n],
        ..Default::default()
    };
    let mut terranes = Vec::new();
    let mut stack = Vec::new();
    for s in 0..n {
        if field.terrane[s] != NONE || crust.crust_type[s] != CrustType::Continental {
            continue;
        }
        let t = field.area_km2.len() as u32;
        let plate = crust.plate[s];
        field.terrane[s] = t;
        stack.push(s as u32);
        let (mut area, mut centroid, mut count) = (0.0, DVec3::ZERO, 0u32);
        while let Some(u) = stack.pop() {
            let u = u as usize;
            area += mesh.area_km2[u];
            centroid += mesh.positions[u] * mesh.area_km2[u];
            count += 1;
            for &v in mesh.neighbors_of(u) {
                let v = v as usize;
                if field.terrane[v] == NONE
                    && crust.crust_type[v] == CrustType::Continental
                    && crust.plate[v] == plate
                {
                    field.terrane[v] = t;
                    stack.push(v as u32);
                }
            }
        }
        let centroid = centroid.try_normalize().unwrap_or(mesh.positions[s]);
        field.area_km2.push(area);
        field.plate.push(plate);
        field.centroid.push(centroid);
        terranes.push(Terrane {
            index: t,
            plate: PlateId(plate),
            area_km2: area,
            centroid,
            samples: count,
        });
    }
    world.insert_resource(field);
    let old: Vec<Entity> = world
        .query_filtered::<Entity, With<Terrane>>()
        .iter(world)
        .collect();
    for e in old {
        world.despawn(e);
    }
    world.spawn_batch(terranes);
}

/// Every step, first in the subduction set: for each front point, where the subducting plate is
/// now, the elevation of its crust under the point, the relative velocity, and the convergence
/// accumulated since the last resampling.
pub fn track_fronts(
    mesh: Res<SphereMesh>,
    crust: Res<Crust>,
    params: Res<Params>,
    plates: Query<(&Plate, &PlateMotion, &PlateFrame, &PlateBounds, &PlateStats)>,
    mut fp: ResMut<FrontPoints>,
    gpu: Option<ResMut<GpuContext>>,
) {
    let crust: &Crust = &crust;
    let table = PlateTable::from_query(&plates);
    let r_km = params.planet.radius_km;
    let dt = params.time.time_step_my as f32;
    let fp = &mut *fp;
    // Where each front point is: the triangle and weights under it in the subducting plate
    // (f64, on the CPU), whether subducting crust is there, the velocities.
    type Located = (bool, [u32; 3], [f64; 3], DVec3, f32);
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
            let active = t.iter().any(|&v| crust.plate[v as usize] == sub.id);
            let rel_world =
                sub.motion.velocity_km_per_my(w, r_km) - over.motion.velocity_km_per_my(w, r_km);
            let n_world = over.world_from_plate * fp.normal[k];
            let conv = (-rel_world.dot(n_world)) as f32;
            // A front acts only while subducting crust is under it and the plates still converge.
            let active = active && conv as f64 > params.subduction.min_convergence_mm_per_yr;
            Some((
                active,
                t,
                [loc.weights[0], loc.weights[1], loc.weights[2]],
                over.plate_from_world * rel_world,
                conv,
            ))
        })
        .collect();
    // The elevation at the three vertices of each located point. On the GPU backend, when the
    // device holds the elevation newer than the host (lazy host sync), the gather kernel reads
    // just these 3F values (raw f32, the same bits as the host array after a pull).
    let index: Vec<u32> = located
        .iter()
        .flatten()
        .flat_map(|&(_, t, _, _, _)| t)
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
    let results: Vec<(bool, f32, DVec3, f32)> = located
        .into_iter()
        .map(|l| {
            let Some((active, _, weights, rel, conv)) = l else {
                return (false, 0.0, DVec3::ZERO, 0.0);
            };
            let zv = &gathered[next..next + 3];
            next += 3;
            let z = (0..3).map(|i| weights[i] * zv[i] as f64).sum::<f64>() as f32;
            (active, z, rel, conv)
        })
        .collect();
    for (k, (active, z, rel, conv)) in results.into_iter().enumerate() {
        fp.active[k] = active;
        fp.subducting_elevation_km[k] = z;
        fp.relative_velocity[k] = rel;
        fp.converged_km[k] += conv * dt;
        fp.convergence_km_per_my[k] = conv;
    }
}

/// The constants of one subduction-uplift step (from the parameters).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpliftConstants {
    /// r_s: subduction distance, km.
    pub rs: f64,
    /// r_c: control distance, km.
    pub rc: f64,
    /// δt, My.
    pub dt: f64,
    /// u0, km/My.
    pub u0: f64,
    /// v0: maximum plate speed, km/My.
    pub v0: f64,
    /// z_t: trench elevation, km.
    pub z_t: f64,
    /// z_c: maximum continental elevation, km.
    pub z_c: f64,
    /// z_a: abyssal elevation, km.
    pub z_a: f64,
    /// β: fold weight.
    pub beta: f64,
    /// Trench width, km.
    pub wt: f64,
    /// Trench deepening rate per step.
    pub rate: f64,
    /// z_r: ridge elevation, km.
    pub z_r: f64,
}

impl UpliftConstants {
    /// The constants for `params`.
    pub fn new(params: &Params) -> Self {
        let s = &params.subduction;
        Self {
            rs: s.distance_km,
            rc: s.control_distance_km,
            dt: params.time.time_step_my,
            u0: s.uplift_mm_per_yr,
            v0: params.plates.max_speed_mm_per_yr,
            z_t: params.ocean.trench_elevation_km,
            z_c: params.continent.max_elevation_km,
            z_a: params.ocean.abyssal_elevation_km,
            beta: s.fold_weight,
            wt: s.trench_width_km,
            rate: s.trench_rate,
            z_r: params.ocean.ridge_elevation_km,
        }
    }
}

/// The CPU kernel (reference of `shaders/subduction_uplift.wgsl`): one step of subduction
/// uplift, fold directions, Andean orogeny and trenches on every sample, in place. `field` must
/// have one entry per sample of `crust`.
pub fn subduction_uplift_cpu(
    k: &UpliftConstants,
    fp: &FrontPoints,
    field: &ConvergenceField,
    crust: &mut Crust,
) {
    let UpliftConstants {
        rs,
        rc,
        dt,
        u0,
        v0,
        z_t,
        z_c,
        z_a,
        beta,
        wt,
        rate,
        z_r,
    } = *k;
    (
        crust.elevation_km.par_iter_mut(),
        crust.orogeny.par_iter_mut(),
        crust.orogeny_age_my.par_iter_mut(),
        crust.fold_dir.par_iter_mut(),
        crust.crust_type.par_iter(),
        field.overriding_distance_km.par_iter(),
        field.overriding_point.par_iter(),
        field.subducting_distance_km.par_iter(),
        field.subducting_point.par_iter(),
    )
        .into_par_iter()
        .with_min_len(4096)
        .for_each(|(z, og, oga, fold, ct, &od, &op, &sd, &sp)| {
            if op != NONE && (od as f64) < rs && fp.active[op as usize] {
                let k = op as usize;
                let rel = fp.relative_velocity[k];
                let zs = fp.subducting_elevation_km[k] as f64;
                let zn = ((zs - z_t) / (z_c - z_t)).clamp(0.0, 1.0);
                let u = u0
                    * distance_transfer(od as f64, rc, rs)
                    * (rel.length() / v0).min(1.0)
                    * zn
                    * zn;
                if u > 0.0 {
                    let znew = (*z as f64 + u * dt).min(z_c);
                    *z = znew as f32;
                    if znew > 0.0 && u * dt > 1e-4 {
                        *og = Orogeny::Andean;
                        *oga = 0.0;
                    }
                    let f = rel * (beta * dt);
                    fold[0] += f.x as f32;
                    fold[1] += f.y as f32;
                    fold[2] += f.z as f32;
                }
            }
            // Only ocean floor makes a trench (not oceanic specks stranded among continents).
            if sp != NONE
                && *ct == CrustType::Oceanic
                && (*z as f64) < z_r
                && fp.active[sp as usize]
            {
                let d = sd as f64 - fp.converged_km[sp as usize] as f64;
                if (0.0..wt).contains(&d) {
                    let target = z_t + (z_a - z_t) * (d / wt);
                    let zc = *z as f64;
                    if zc > target {
                        *z = (zc + (target - zc) * rate) as f32;
                    }
                }
            }
        });
}

/// Subduction uplift on overriding plates, fold directions, Andean orogeny, and trenches on
/// subducting plates (see the module documentation), on the GPU when a [`GpuContext`] is
/// installed, with [`subduction_uplift_cpu`] otherwise.
pub fn subduction_uplift(
    params: Res<Params>,
    fp: Res<FrontPoints>,
    field: Res<ConvergenceField>,
    mut crust: ResMut<Crust>,
    gpu: Option<ResMut<GpuContext>>,
) {
    if fp.is_empty() || field.overriding_point.len() != crust.len() {
        return;
    }
    let k = UpliftConstants::new(&params);
    if let Some(mut gpu) = gpu {
        let (tick, field_tick) = (crust.last_changed(), field.last_changed());
        let done = run_or_record(&mut gpu, |g| {
            g.sync_crust(&crust, Some(tick))?;
            crate::gpu::subduction_uplift::subduction_uplift_dispatch(
                g,
                &k,
                &fp,
                &field,
                Some(field_tick),
            )?;
            // The host copy is pulled lazily, by the next CPU reader (see gpu::FieldMask).
            g.note_device_write(
                FieldMask::ELEVATION
                    | FieldMask::OROGENY
                    | FieldMask::OROGENY_AGE
                    | FieldMask::FOLD_DIR,
                crust.bypass_change_detection(),
            )
        });
        if done {
            return;
        }
    }
    subduction_uplift_cpu(&k, &fp, &field, &mut crust);
}

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

/// Finds terranes colliding now: continental crust of a subducting plate more than
/// `threshold_km` past a front whose overriding crust is continental too. Queues a suture for
/// the smaller terrane of each pair in contact and asks for a resampling.
#[allow(clippy::too_many_arguments)]
pub fn find_collisions(
    threshold_km: f64,
    lookahead_my: f64,
    params: &Params,
    crust: &Crust,
    fp: &FrontPoints,
    field: &ConvergenceField,
    terranes: &TerraneField,
    table: &PlateTable,
    sutures: &mut Sutures,
) -> bool {
    if fp.is_empty()
        || field.subducting_point.len() != crust.len()
        || terranes.terrane.len() != crust.len()
    {
        return false;
    }
    let mut contacts: Vec<(u32, u32, u32, u32)> = (0..crust.len())
        .into_par_iter()
        .with_min_len(4096)
        .filter_map(|i| {
            let k = field.subducting_point[i];
            if k == NONE || crust.crust_type[i] != CrustType::Continental {
                return None;
            }
            let k = k as usize;
            // Where the crust will be after `lookahead_my` more of convergence (the collision
            // check at the start of a step looks one step ahead, as Driftworld does, so that the
            // overlap at the resampling that follows is about the threshold, not a step more).
            let d = field.subducting_distance_km[i] as f64
                - fp.converged_km[k] as f64
                - fp.convergence_km_per_my[k].max(0.0) as f64 * lookahead_my;
            if d >= -threshold_km || (threshold_km <= 0.0 && d >= 0.0) {
                return None;
            }
            let os = fp.sample[k] as usize;
            if crust.crust_type[os] != CrustType::Continental {
                return None;
            }
            let (tb, ta) = (terranes.terrane[i], terranes.terrane[os]);
            if tb == NONE || ta == NONE {
                return None;
            }
            let min_area = params.collision.min_terrane_km2;
            if terranes.area_km2[tb as usize] < min_area
                || terranes.area_km2[ta as usize] < min_area
            {
                return None;
            }
            Some((tb, ta, fp.subducting[k], fp.overriding[k]))
        })
        .collect();
    contacts.sort_unstable();
    contacts.dedup();
    let r_km = params.planet.radius_km;
    let mut any = false;
    for (tb, ta, plate_b, plate_a) in contacts {
        let (moving, from, to) = if terranes.area_km2[ta as usize] < terranes.area_km2[tb as usize]
        {
            (ta, plate_a, plate_b)
        } else {
            (tb, plate_b, plate_a)
        };
        if sutures.pending.iter().any(|s| s.terrane == moving) {
            continue;
        }
        let (Some(pf), Some(pt)) = (table.get(from), table.get(to)) else {
            continue;
        };
        let centroid = pf.world_from_plate * terranes.centroid[moving as usize];
        let v = (pf.motion.velocity_km_per_my(centroid, r_km)
            - pt.motion.velocity_km_per_my(centroid, r_km))
        .length();
        sutures.pending.push(Suture {
            terrane: moving,
            from_plate: from,
            to_plate: to,
            area_km2: terranes.area_km2[moving as usize],
            relative_speed_km_per_my: v,
            centroid_world: centroid,
        });
        any = true;
    }
    any
}

/// What the collision checks read.
#[derive(bevy_ecs::system::SystemParam)]
pub struct CollisionInputs<'w, 's> {
    params: Res<'w, Params>,
    crust: Res<'w, Crust>,
    fp: Res<'w, FrontPoints>,
    field: Res<'w, ConvergenceField>,
    terranes: Res<'w, TerraneField>,
    plates: Query<
        'w,
        's,
        (
            &'static Plate,
            &'static PlateMotion,
            &'static PlateFrame,
            &'static PlateBounds,
            &'static PlateStats,
        ),
    >,
}

impl CollisionInputs<'_, '_> {
    fn find(&self, threshold_km: f64, lookahead_my: f64, sutures: &mut Sutures) -> bool {
        let table = PlateTable::from_query(&self.plates);
        find_collisions(
            threshold_km,
            lookahead_my,
            &self.params,
            &self.crust,
            &self.fp,
            &self.field,
            &self.terranes,
            &table,
            sutures,
        )
    }
}

/// Collision detection at the start of a step (threshold `collision.interpenetration_km`,
/// looking one step ahead); asks for a resampling when a collision fires.
pub fn detect_collisions(
    inputs: CollisionInputs,
    mut sutures: ResMut<Sutures>,
    mut request: ResMut<ResampleRequest>,
) {
    let t = inputs.params.collision.interpenetration_km;
    let ahead = inputs.params.time.time_step_my;
    if inputs.find(t, ahead, &mut sutures) {
        request.0 = true;
    }
}

/// Just before a resampling: any continental crust already under another plate's continental
/// crust collides now, whatever its depth, so the resampling drops none of it.
pub fn collide_before_resample(inputs: CollisionInputs, mut sutures: ResMut<Sutures>) {
    inputs.find(0.0, 0.0, &mut sutures);
}

/// After a resampling that applied sutures: the collision surge around each sutured terrane.
pub fn collision_uplift(world: &mut World) {
    let applied = std::mem::take(&mut world.resource_mut::<Sutures>().applied);
    if !applied.is_empty() {
        world.resource_mut::<Sutures>().last_applied =
            applied.iter().map(|a| a.0.clone()).collect();
    }
    if applied.is_empty() {
        return;
    }
    let params = world.resource::<Params>().clone();
    let crust_tick = world.get_resource_ref::<Crust>().map(|c| c.last_changed());
    let mut crust = world.remove_resource::<Crust>().unwrap_or_default();
    // On the GPU backend the surges are applied on the device after every distance is known
    // (the distances depend only on the plates, which the surges do not change).
    let mut gpu = world.remove_resource::<GpuContext>();
    let mut surges = Vec::new();
    let mesh = world.resource::<SphereMesh>();
    let r_km = params.planet.radius_km;
    let c = &params.collision;
    let a0 = 4.0 * std::f64::consts::PI * r_km * r_km / params.init.plates as f64;
    let v0 = params.plates.max_speed_mm_per_yr;
    let z_c = params.continent.max_elevation_km;
    let mut dist = vec![f32::INFINITY; mesh.len()];
    let mut label = vec![NONE; mesh.len()];
    let mut settled = Vec::new();
    for (suture, samples) in &applied {
        if samples.is_empty() {
            continue;
        }
        let xi = (suture.relative_speed_km_per_my / v0 * suture.area_km2 / a0).sqrt();
        let r = c.distance_km * xi.min(1.0);
        let peak = if c.max_uplift_km > 0.0 {
            c.max_uplift_km
                * (1.0 - (-c.coefficient_per_km * suture.area_km2 / c.max_uplift_km).exp())
        } else {
            0.0
        };
        let seeds: Vec<(u32, u32)> = samples.iter().map(|&s| (s, s)).collect();
        dist.iter_mut().for_each(|d| *d = f32::INFINITY);
        let to = suture.to_plate;
        let plate = &crust.plate;
        propagate_nearest(
            mesh,
            &seeds,
            |l| mesh.positions[l as usize],
            |s, _| plate[s] == to,
            r / r_km,
            &mut dist,
            &mut label,
            &mut settled,
        );
        let surge = CollisionSurge {
            radius_km: r,
            peak_km: peak,
            planet_radius_km: r_km,
            max_elevation_km: z_c,
            centroid: suture.centroid_world,
        };
        match gpu {
            Some(_) => surges.push((surge, dist.clone())),
            None => collision_uplift_cpu(&surge, &mesh.positions, &dist, &mut crust),
        }
        tracing::debug!(
            terrane = suture.terrane,
            from = suture.from_plate,
            to = suture.to_plate,
            area_km2 = suture.area_km2,
            radius_km = r,
            uplift_km = peak,
            "collision"
        );
    }
    let mut synced = false;
    if let Some(g) = gpu.as_mut().filter(|_| !surges.is_empty()) {
        // The surged fields stay on the device (lazy host sync, stage 3 of
        // docs/gpu-residency.md): the CPU systems that follow pull what they read.
        let done = run_or_record(g, |g| {
            g.sync_crust(&crust, crust_tick)?;
            crate::gpu::collision_uplift::collision_uplift_gpu(g, &mesh.positions, &surges)?;
            g.note_device_write(crate::gpu::collision_uplift::WRITES, &mut crust)
        });
        synced = done;
        if !done {
            for (surge, dist) in &surges {
                collision_uplift_cpu(surge, &mesh.positions, dist, &mut crust);
            }
        }
    }
    world.insert_resource(crust);
    if let Some(mut g) = gpu {
        if synced {
            g.mark_crust_synced(world.resource_ref::<Crust>().last_changed());
        }
        world.insert_resource(g);
    }
}

/// One sutured terrane's collision surge (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollisionSurge {
    /// r: radius of the surge, km.
    pub radius_km: f64,
    /// Δz₀: uplift at the terrane, km.
    pub peak_km: f64,
    /// Planet radius, km.
    pub planet_radius_km: f64,
    /// z_c: elevations are capped here, km.
    pub max_elevation_km: f64,
    /// The terrane's centroid (world frame, unit vector); fold directions point away from it.
    pub centroid: DVec3,
}

/// The CPU kernel (reference of `shaders/collision_uplift.wgsl`): one collision surge on every
/// sample, in place. `dist` is each sample's great-circle distance (radians) to the sutured
/// terrane through its new plate, infinite where the surge does not reach; `positions` are the
/// reference positions. Continental samples rise by Δz₀·(1 − (d/r)²)² (capped at z_c); where
/// the rise exceeds 1 m they get Himalayan orogeny, orogeny age 0 and a fold direction pointing
/// away from the centroid. `positions` and `dist` must have one entry per sample of `crust`.
pub fn collision_uplift_cpu(
    s: &CollisionSurge,
    positions: &[DVec3],
    dist: &[f32],
    crust: &mut Crust,
) {
    let (r, peak, r_km, z_c, q) = (
        s.radius_km,
        s.peak_km,
        s.planet_radius_km,
        s.max_elevation_km,
        s.centroid,
    );
    for i in 0..positions.len().min(dist.len()).min(crust.len()) {
        if !dist[i].is_finite() {
            continue;
        }
        let d = if r > 0.0 {
            dist[i] as f64 * r_km / r
        } else {
            0.0
        };
        let dz = peak * (1.0 - d * d).max(0.0).powi(2);
        if dz <= 0.0 || crust.crust_type[i] != CrustType::Continental {
            continue;
        }
        crust.elevation_km[i] = (crust.elevation_km[i] as f64 + dz).min(z_c) as f32;
        if dz > 1e-3 && crust.crust_type[i] == CrustType::Continental {
            crust.orogeny[i] = Orogeny::Himalayan;
            crust.orogeny_age_my[i] = 0.0;
            let p = positions[i];
            let away = p - q;
            let f = (away - p * p.dot(away))
                .try_normalize()
                .unwrap_or(DVec3::ZERO);
            crust.fold_dir[i] = [f.x as f32, f.y as f32, f.z as f32];
        }
    }
}
