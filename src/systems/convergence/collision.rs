//! Continental collisions (paper §4.2): detection of terranes pushed past the interpenetration
//! threshold, sutures at the next resampling, and the Himalayan surge around each sutured
//! terrane (CPU kernel [`collision_uplift_cpu`], GPU kernel [`crate::gpu::collision_uplift`]).
//! See [`super`] for the model.
#![allow(clippy::needless_range_loop)]

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;

use super::propagate_nearest;
use crate::components::{Plate, PlateFrame, PlateMotion};
use crate::geometry::SphereMesh;
use crate::gpu::collision_uplift::CollisionSurge;
use crate::gpu::{GpuContext, run_or_record};
use crate::resources::convergence::NONE;
use crate::resources::params::Params;
use crate::resources::{
    ConvergenceField, Crust, CrustType, FrontPoints, NextPlateId, Orogeny, PlateTable,
    ResampleRequest, Suture, Sutures, TerraneField,
};

/// Finds terranes colliding now: continental crust of a subducting plate more than
/// `threshold_km` past a front whose overriding crust is continental too. Queues a suture for
/// the smaller terrane of each pair in contact and asks for a resampling.
///
/// Docking (`collision.docking`): an island arc (an arc terrane, oceanic) or a microcontinent
/// (smaller than `collision.min_terrane_km2`) in contact with a continent at least that large
/// docks onto it: its suture is queued only by the check just before a resampling
/// (`threshold_km` = 0), so docking never forces a resampling of its own.
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
    let mut contacts: Vec<(bool, u32, u32, u32, u32)> = (0..crust.len())
        .into_par_iter()
        .with_min_len(4096)
        .filter_map(|i| {
            let k = field.subducting_point[i];
            let tb = terranes.terrane[i];
            if k == NONE || tb == NONE {
                return None;
            }
            // An arc terrane's samples are oceanic (continental terranes' are continental).
            let arc = crust.crust_type[i] != CrustType::Continental;
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
            let ta = terranes.terrane[os];
            if ta == NONE {
                return None;
            }
            let min_area = params.collision.min_terrane_km2;
            let (small_b, small_a) = (
                terranes.area_km2[tb as usize] < min_area,
                terranes.area_km2[ta as usize] < min_area,
            );
            if arc || small_b || small_a {
                // Docking: onto a continent at least `min_area` large, at the resampling only.
                let receiver_small = if arc { small_a } else { small_a && small_b };
                if !params.collision.docking || receiver_small || threshold_km > 0.0 {
                    return None;
                }
            }
            Some((arc, tb, ta, fp.subducting[k], fp.overriding[k]))
        })
        .collect();
    contacts.sort_unstable();
    contacts.dedup();
    let r_km = params.planet.radius_km;
    let mut any = false;
    for (arc, tb, ta, plate_b, plate_a) in contacts {
        // An arc always moves; otherwise the smaller terrane does.
        let (moving, from, to) =
            if !arc && terranes.area_km2[ta as usize] < terranes.area_km2[tb as usize] {
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
            detached_plate: None,
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
    plates: crate::resources::PlateTableQuery<'w, 's>,
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

/// Whether a collision forces a global resampling in its step: `collision.resample_at_suture`,
/// and always with plate momentum (its exchange at the suture reads every plate in the
/// reference frame).
pub fn resample_at_suture(params: &Params) -> bool {
    params.collision.resample_at_suture || params.plates.momentum
}

/// Collision detection at the start of a step (threshold `collision.interpenetration_km`,
/// looking one step ahead). With [`resample_at_suture`] a collision asks for a resampling;
/// otherwise [`detach_sutured_terranes`] moves its terrane next.
pub fn detect_collisions(
    inputs: CollisionInputs,
    mut sutures: ResMut<Sutures>,
    mut request: ResMut<ResampleRequest>,
) {
    let t = inputs.params.collision.interpenetration_km;
    let ahead = inputs.params.time.time_step_my;
    if inputs.find(t, ahead, &mut sutures) && resample_at_suture(&inputs.params) {
        request.0 = true;
    }
}

/// Right after detection, when collisions do not resample at once ([`resample_at_suture`]): the
/// terrane of each new suture leaves its plate now, without a global resampling. Its samples
/// become a plate of their own that keeps the frame of the plate they leave (so nothing jumps)
/// and moves with the plate they join (so the convergence stops); the next regular resampling
/// applies the suture as before (the terrane stays on top where it overlaps, joins its new
/// plate, and the collision surge follows). A terrane that was its whole plate keeps it, and the
/// plate takes the motion of the one it joins. A terrane meeting a detached terrane joins the
/// plate that one joins.
pub fn detach_sutured_terranes(world: &mut World) {
    if resample_at_suture(world.resource::<Params>()) {
        return;
    }
    let todo: Vec<usize> = world
        .resource::<Sutures>()
        .pending
        .iter()
        .enumerate()
        .filter(|(_, s)| s.detached_plate.is_none())
        .map(|(k, _)| k)
        .collect();
    if todo.is_empty() {
        return;
    }
    let plates: Vec<(Entity, u32, PlateFrame, PlateMotion)> = world
        .query::<(Entity, &Plate, &PlateFrame, &PlateMotion)>()
        .iter(world)
        .map(|(e, p, f, m)| (e, p.id.0, *f, *m))
        .collect();
    let find = |id: u32| plates.iter().find(|p| p.1 == id);
    let mut touched = Vec::new();
    let mut dropped = Vec::new();
    // New plate ids, written at the end in one declared write (one upload on the GPU backend),
    // and how many samples each plate gave away so far.
    let mut relabel: Vec<(Vec<u32>, u32)> = Vec::new();
    let mut given: Vec<(u32, usize)> = Vec::new();
    for k in todo {
        let mut suture = world.resource::<Sutures>().pending[k].clone();
        // Follow detached plates to the plate they join (a chain is at most as long as the
        // pending list).
        for _ in 0..world.resource::<Sutures>().pending.len() {
            let pending = &world.resource::<Sutures>().pending;
            match pending
                .iter()
                .find(|p| p.detached_plate == Some(suture.to_plate))
            {
                Some(p) => suture.to_plate = p.to_plate,
                None => break,
            }
        }
        let (Some(from), Some(to)) = (find(suture.from_plate), find(suture.to_plate)) else {
            dropped.push(k);
            continue;
        };
        if suture.from_plate == suture.to_plate {
            dropped.push(k);
            continue;
        }
        // The terrane's samples on the plate it leaves, and how many samples that plate holds.
        let (samples, on_plate) = {
            let crust = world.resource::<Crust>();
            let terranes = world.resource::<TerraneField>();
            let mut samples = Vec::new();
            let mut on_plate = 0usize;
            for i in 0..crust.len().min(terranes.terrane.len()) {
                if crust.plate[i] == suture.from_plate {
                    on_plate += 1;
                    if terranes.terrane[i] == suture.terrane {
                        samples.push(i as u32);
                    }
                }
            }
            let gone: usize = given
                .iter()
                .filter(|g| g.0 == suture.from_plate)
                .map(|g| g.1)
                .sum();
            (samples, on_plate - gone)
        };
        if samples.is_empty() {
            dropped.push(k);
            continue;
        }
        let motion = to.3;
        let count = samples.len();
        let detached = if count >= on_plate {
            world.entity_mut(from.0).insert(motion);
            suture.from_plate
        } else {
            let id = {
                let mut next = world.resource_mut::<NextPlateId>();
                next.0 += 1;
                next.0 - 1
            };
            world
                .spawn(Plate::bundle(crate::components::PlateId(id), motion))
                .insert(from.2);
            given.push((suture.from_plate, count));
            relabel.push((samples, id));
            touched.extend([suture.from_plate, id]);
            id
        };
        if let Some(p) = world
            .resource_mut::<TerraneField>()
            .plate
            .get_mut(suture.terrane as usize)
        {
            *p = detached;
        }
        let mut q = world.query::<&mut crate::components::Terrane>();
        for mut t in q.iter_mut(world) {
            if t.index == suture.terrane {
                t.plate = crate::components::PlateId(detached);
            }
        }
        suture.detached_plate = Some(detached);
        tracing::debug!(
            terrane = suture.terrane,
            from = suture.from_plate,
            to = suture.to_plate,
            plate = detached,
            samples = count,
            "collision: terrane detached"
        );
        world.resource_mut::<Sutures>().pending[k] = suture;
    }
    for &k in dropped.iter().rev() {
        world.resource_mut::<Sutures>().pending.remove(k);
    }
    if !relabel.is_empty() {
        crate::gpu::write_crust_fields_or_record(world, crate::gpu::FieldMask::PLATE, |crust| {
            for (samples, id) in &relabel {
                for &s in samples {
                    crust.plate[s as usize] = *id;
                }
            }
        });
    }
    if !touched.is_empty() {
        crate::systems::rifting::refresh_plate_geometry(world, &touched);
    }
}

/// Just before a resampling: any continental crust already under another plate's continental
/// crust collides now, whatever its depth, so the resampling drops none of it.
pub fn collide_before_resample(inputs: CollisionInputs, mut sutures: ResMut<Sutures>) {
    inputs.find(0.0, 0.0, &mut sutures);
}

/// Docked island arcs become continental crust of the plate they joined, at their elevation
/// (the thickness that stands there under Airy isostasy, at least the arc's own).
fn dock_arcs(world: &mut World, applied: &[(Suture, Vec<u32>)], params: &Params) {
    use crate::gpu::FieldMask;
    if !params.collision.docking {
        return;
    }
    let arcs: Vec<u32> = {
        let crust = world.resource::<Crust>();
        applied
            .iter()
            .flat_map(|(_, s)| s.iter().copied())
            .filter(|&j| crust.crust_type.get(j as usize) == Some(&CrustType::Oceanic))
            .collect()
    };
    if arcs.is_empty() {
        return;
    }
    if !crate::gpu::sync_crust_to_host_or_record(world, FieldMask::ELEVATION | FieldMask::THICKNESS)
    {
        return;
    }
    let iso = crate::systems::relief::isostasy_params(params);
    crate::gpu::write_crust_fields_or_record(
        world,
        FieldMask::CRUST_TYPE | FieldMask::THICKNESS,
        |crust| {
            for &j in &arcs {
                let j = j as usize;
                let t = crate::systems::relief::isostasy::airy_thickness(
                    crust.elevation_km[j] as f64,
                    &iso,
                );
                crust.crust_type[j] = CrustType::Continental;
                crust.thickness_km[j] = (t as f32).max(crust.thickness_km[j]);
            }
        },
    );
    tracing::debug!(samples = arcs.len(), "island arcs docked");
}

/// Plate momentum at the sutures just applied (see [`crate::systems::momentum`]): each terrane
/// takes its momentum to the plate it joined, and the two plates exchange the collision's
/// impulse. Runs right after the resampling, when every frame is the identity.
fn exchange_momentum(world: &mut World, applied: &[(Suture, Vec<u32>)], params: &Params) {
    use crate::systems::momentum::{inertia, motion_of, omega, sample_mass, suture_exchange};
    // Inertia of the listed samples, and of the samples of `plate` not listed.
    let inertia_of = |world: &World, plate: Option<u32>, list: &[u32]| {
        let (mesh, crust) = (world.resource::<SphereMesh>(), world.resource::<Crust>());
        let n = mesh.len().min(crust.len());
        let point = |i: usize| {
            (
                mesh.positions[i],
                sample_mass(crust.crust_type[i], mesh.area_km2[i], params),
            )
        };
        match plate {
            Some(p) => {
                let mut listed = vec![false; n];
                list.iter()
                    .filter(|&&j| (j as usize) < n)
                    .for_each(|&j| listed[j as usize] = true);
                inertia(
                    (0..n)
                        .filter(|&i| crust.plate[i] == p && !listed[i])
                        .map(point),
                )
            }
            None => inertia(
                list.iter()
                    .map(|&j| j as usize)
                    .filter(|&j| j < n)
                    .map(point),
            ),
        }
    };
    for (suture, samples) in applied {
        if samples.is_empty() || suture.from_plate == suture.to_plate {
            continue;
        }
        let (a, b) = (suture.from_plate, suture.to_plate);
        let motion = |world: &mut World, id: u32| {
            let mut q = world.query::<(&Plate, &PlateMotion)>();
            q.iter(world).find(|(p, _)| p.id.0 == id).map(|(_, m)| *m)
        };
        let (Some(ma), Some(mb)) = (motion(world, a), motion(world, b)) else {
            continue;
        };
        let i_t = inertia_of(world, None, samples);
        // A without the terrane, B with it (counted whole even where the resampling's clean-up
        // gave a few of its samples to another plate, so that I_B ≥ I_T).
        let i_a = inertia_of(world, Some(a), samples);
        let i_b = inertia_of(world, Some(b), samples) + i_t;
        let (wa, wb) = suture_exchange(
            i_a,
            i_b,
            i_t,
            omega(&ma),
            omega(&mb),
            params.plates.collision_coupling,
        );
        let mut q = world.query::<(&Plate, &mut PlateMotion)>();
        for (p, mut m) in q.iter_mut(world) {
            if p.id.0 == a {
                *m = motion_of(wa, ma.euler_pole);
            } else if p.id.0 == b {
                *m = motion_of(wb, mb.euler_pole);
            }
        }
        tracing::debug!(from = a, to = b, "suture: plate momentum exchanged");
    }
}

/// After a resampling that applied sutures: the collision surge around each sutured terrane.
pub fn collision_uplift(world: &mut World) {
    let _t = crate::systems::DebugTimer::new("collision_uplift");
    let applied = std::mem::take(&mut world.resource_mut::<Sutures>().applied);
    if !applied.is_empty() {
        world.resource_mut::<Sutures>().last_applied =
            applied.iter().map(|a| a.0.clone()).collect();
    }
    if applied.is_empty() {
        return;
    }
    let params = world.resource::<Params>().clone();
    dock_arcs(world, &applied, &params);
    if params.plates.momentum {
        exchange_momentum(world, &applied, &params);
    }
    let isostatic = world
        .get_resource::<crate::resources::ReliefMode>()
        .is_some_and(|m| m.isostatic);
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
    let mut in_terrane = vec![false; mesh.len()];
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
        // The surge spreads from the suture, the terrane's samples that touch the plate it
        // joins (falling back to the whole terrane when none does), through the joined plate: a
        // belt of thickened crust astride the suture, not a terrane raised whole.
        let to = suture.to_plate;
        let plate = &crust.plate;
        in_terrane.iter_mut().for_each(|f| *f = false);
        for &s in samples {
            in_terrane[s as usize] = true;
        }
        let mut seeds: Vec<(u32, u32)> = samples
            .iter()
            .filter(|&&s| {
                mesh.neighbors_of(s as usize)
                    .iter()
                    .any(|&h| plate[h as usize] == to && !in_terrane[h as usize])
            })
            .map(|&s| (s, s))
            .collect();
        if seeds.is_empty() {
            seeds = samples.iter().map(|&s| (s, s)).collect();
        }
        dist.iter_mut().for_each(|d| *d = f32::INFINITY);
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
            thickening: 1.0 / crate::resources::params::dry_isostatic_gain(&params),
            max_thickness_km: params.isostasy.max_thickness_km,
            isostatic,
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
            g.note_device_write(crate::gpu::collision_uplift::writes(isostatic), &mut crust)
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
        if s.isostatic {
            let t = crust.thickness_km[i];
            crust.thickness_km[i] =
                ((t as f64 + dz * s.thickening) as f32).min((s.max_thickness_km as f32).max(t));
        } else {
            crust.elevation_km[i] = (crust.elevation_km[i] as f64 + dz).min(z_c) as f32;
        }
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
