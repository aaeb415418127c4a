//! The convergent-boundary state in saves (section `convergence.state`): subduction front points
//! with their per-step state, the per-sample distance fields, the override pairs, the terranes
//! and the collision count, plus the front and terrane entities. Registered by every plugin that
//! reads that state (subduction, slab pull, terranes, collisions); the registry keeps one copy.

use bevy_ecs::prelude::*;

use crate::resources::{SaveSection, SectionError, SectionReader, SectionWriter};

/// The convergent-boundary state (section `convergence.state`): subduction front points with
/// their per-step state, the per-sample distance fields, the override pairs, the terranes and
/// the collision count, the sutures waiting for the next resampling (version 2), which front
/// points have a trench without being active (version 3), plus the front and terrane entities.
/// Saves made before this section existed load with empty fronts and terranes, rebuilt at the
/// next resampling; version 1 saves load with no suture waiting; saves before version 3 load
/// with a trench at the active points only until the next step tracks the fronts again.
pub fn convergence_section() -> SaveSection {
    SaveSection {
        name: "convergence.state",
        version: 3,
        save: save_convergence,
        load: load_convergence,
        default: Some(|_| Ok(())),
    }
}

fn f32s_as_bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn bits_as_f32s(v: Vec<u32>, what: &str) -> Result<Vec<f32>, SectionError> {
    let out: Vec<f32> = v.into_iter().map(f32::from_bits).collect();
    if out.iter().any(|x| x.is_nan()) {
        return Err(format!("NaN in {what}").into());
    }
    Ok(out)
}

fn save_convergence(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    use crate::components::{FrontKind, SubductionFront, Terrane};
    use crate::resources::{ConvergenceField, FrontPoints, OverridePairs, Sutures, TerraneField};
    let fp = world.resource::<FrontPoints>().clone();
    w.u32(fp.len() as u32);
    w.u32s(&fp.sample);
    w.u32s(&fp.overriding);
    w.u32s(&fp.subducting);
    for k in 0..fp.len() {
        for v in fp.normal[k].to_array() {
            w.f64(v);
        }
        for v in fp.relative_velocity[k].to_array() {
            w.f64(v);
        }
        // Bit 0: active; bit 1 (version 3): a trench without being active.
        let trench_only = fp.trench[k] && !fp.active[k];
        w.u8(fp.active[k] as u8 | (trench_only as u8) << 1);
    }
    w.u32s(&f32s_as_bits(&fp.length_km));
    w.u32s(&f32s_as_bits(&fp.subducting_elevation_km));
    w.u32s(&f32s_as_bits(&fp.converged_km));
    w.u32s(&f32s_as_bits(&fp.convergence_km_per_my));
    let f = world.resource::<ConvergenceField>();
    w.u32s(&f32s_as_bits(&f.overriding_distance_km));
    w.u32s(&f.overriding_point);
    w.u32s(&f32s_as_bits(&f.subducting_distance_km));
    w.u32s(&f.subducting_point);
    let pairs = &world.resource::<OverridePairs>().0;
    w.u32(pairs.len() as u32);
    for &(a, b) in pairs {
        w.u32(a);
        w.u32(b);
    }
    let t = world.resource::<TerraneField>();
    w.u32s(&t.terrane);
    w.u32s(&t.plate);
    w.u32(t.area_km2.len() as u32);
    for &a in &t.area_km2 {
        w.f64(a);
    }
    let sutures = world.resource::<Sutures>();
    w.u64(sutures.total);
    // Version 2: the sutures waiting for the next resampling (terranes already detached).
    let pending = sutures.pending.clone();
    w.f64(
        world
            .resource::<crate::systems::resample::ResampleWork>()
            .continental_subducted_total_km2,
    );
    let mut terranes: Vec<Terrane> = world.query::<&Terrane>().iter(world).cloned().collect();
    terranes.sort_by_key(|t| t.index);
    w.u32(terranes.len() as u32);
    for t in &terranes {
        w.u32(t.index);
        w.u32(t.plate.0);
        w.f64(t.area_km2);
        for v in t.centroid.to_array() {
            w.f64(v);
        }
        w.u32(t.samples);
    }
    let mut fronts: Vec<SubductionFront> = world
        .query::<&SubductionFront>()
        .iter(world)
        .cloned()
        .collect();
    fronts.sort_by_key(|f| f.points.first().copied().unwrap_or(u32::MAX));
    w.u32(fronts.len() as u32);
    for f in &fronts {
        w.u32(f.overriding.0);
        w.u32(f.subducting.0);
        w.u8(match f.kind {
            FrontKind::OceanUnderContinent => 0,
            FrontKind::OceanUnderOcean => 1,
            FrontKind::Forced => 2,
        });
        w.u32s(&f.points);
        w.f64(f.length_km);
    }
    w.u32(pending.len() as u32);
    for s in &pending {
        w.u32(s.terrane);
        w.u32(s.from_plate);
        w.u32(s.to_plate);
        w.u32(s.detached_plate.unwrap_or(u32::MAX));
        w.f64(s.area_km2);
        w.f64(s.relative_speed_km_per_my);
        for v in s.centroid_world.to_array() {
            w.f64(v);
        }
    }
    Ok(())
}

fn load_convergence(world: &mut World, r: &mut SectionReader, v: u32) -> Result<(), SectionError> {
    use crate::components::{FrontKind, PlateId, SubductionFront, Terrane};
    use crate::resources::{ConvergenceField, FrontPoints, OverridePairs, Sutures, TerraneField};
    use glam::DVec3;
    let n = world.resource::<crate::resources::Crust>().len();
    let m = r.u32()? as usize;
    let sample = r.u32s()?;
    let overriding = r.u32s()?;
    let subducting = r.u32s()?;
    if sample.len() != m
        || overriding.len() != m
        || subducting.len() != m
        || sample.iter().any(|&s| s as usize >= n)
    {
        return Err("front point arrays are inconsistent".into());
    }
    // 7 f64 + 1 byte per point must be there before allocating.
    if r.remaining() < m.saturating_mul(57) {
        return Err("front points are truncated".into());
    }
    let (mut normal, mut rel, mut active, mut trench) = (
        Vec::with_capacity(m),
        Vec::with_capacity(m),
        Vec::with_capacity(m),
        Vec::with_capacity(m),
    );
    for _ in 0..m {
        normal.push(DVec3::new(
            r.finite_f64("front normal")?,
            r.finite_f64("front normal")?,
            r.finite_f64("front normal")?,
        ));
        rel.push(DVec3::new(
            r.finite_f64("front velocity")?,
            r.finite_f64("front velocity")?,
            r.finite_f64("front velocity")?,
        ));
        // Before version 3 a point had a trench exactly when it was active.
        let (a, t) = match (r.u8()?, v) {
            (0, _) => (false, false),
            (1, _) => (true, true),
            (2, 3..) => (false, true),
            (b, _) => return Err(format!("front activity byte {b}").into()),
        };
        active.push(a);
        trench.push(t);
    }
    let per_point = |v: Vec<u32>, what: &str| -> Result<Vec<f32>, SectionError> {
        if v.len() != m {
            return Err(format!("{what}: {} values for {m} points", v.len()).into());
        }
        bits_as_f32s(v, what)
    };
    let length_km = per_point(r.u32s()?, "front lengths")?;
    let subducting_elevation_km = per_point(r.u32s()?, "front elevations")?;
    let converged_km = per_point(r.u32s()?, "front convergence")?;
    let convergence_km_per_my = per_point(r.u32s()?, "front convergence rate")?;
    let per_sample_f = |v: Vec<u32>, what: &str| -> Result<Vec<f32>, SectionError> {
        if v.len() != n {
            return Err(format!("{what}: {} values for {n} samples", v.len()).into());
        }
        bits_as_f32s(v, what)
    };
    let per_sample_u = |v: Vec<u32>, what: &str| -> Result<Vec<u32>, String> {
        if v.len() != n || v.iter().any(|&p| p != u32::MAX && p as usize >= m) {
            return Err(format!("{what} is inconsistent"));
        }
        Ok(v)
    };
    let field = ConvergenceField {
        overriding_distance_km: per_sample_f(r.u32s()?, "overriding distances")?,
        overriding_point: per_sample_u(r.u32s()?, "overriding points")?,
        subducting_distance_km: per_sample_f(r.u32s()?, "subducting distances")?,
        subducting_point: per_sample_u(r.u32s()?, "subducting points")?,
    };
    let np = r.u32()? as usize;
    if r.remaining() < np.saturating_mul(8) {
        return Err("override pairs are truncated".into());
    }
    let mut pairs = Vec::with_capacity(np);
    for _ in 0..np {
        pairs.push((r.u32()?, r.u32()?));
    }
    let terrane = r.u32s()?;
    let plate = r.u32s()?;
    let nt = r.u32()? as usize;
    if r.remaining() < nt.saturating_mul(8) || plate.len() != nt {
        return Err("terrane areas are inconsistent".into());
    }
    let mut area_km2 = Vec::with_capacity(nt);
    for _ in 0..nt {
        area_km2.push(r.finite_f64("terrane area")?);
    }
    if !(terrane.is_empty() || terrane.len() == n)
        || terrane.iter().any(|&t| t != u32::MAX && t as usize >= nt)
    {
        return Err("terrane field is inconsistent".into());
    }
    let total = r.u64()?;
    let subducted = r.finite_f64("subducted continental area")?;
    let nter = r.u32()? as usize;
    if r.remaining() < nter.saturating_mul(44) {
        return Err("terranes are truncated".into());
    }
    let mut terranes = Vec::with_capacity(nter);
    for _ in 0..nter {
        terranes.push(Terrane {
            index: r.u32()?,
            plate: PlateId(r.u32()?),
            area_km2: r.finite_f64("terrane area")?,
            centroid: DVec3::new(
                r.finite_f64("terrane centroid")?,
                r.finite_f64("terrane centroid")?,
                r.finite_f64("terrane centroid")?,
            ),
            samples: r.u32()?,
        });
    }
    let nf = r.u32()? as usize;
    if r.remaining() < nf.saturating_mul(21) {
        return Err("subduction fronts are truncated".into());
    }
    let mut fronts = Vec::with_capacity(nf);
    for _ in 0..nf {
        let overriding = PlateId(r.u32()?);
        let subducting = PlateId(r.u32()?);
        let kind = match r.u8()? {
            0 => FrontKind::OceanUnderContinent,
            1 => FrontKind::OceanUnderOcean,
            2 => FrontKind::Forced,
            b => return Err(format!("unknown front kind {b}").into()),
        };
        let points = r.u32s()?;
        if points.iter().any(|&p| p as usize >= m) {
            return Err("front names a point that does not exist".into());
        }
        fronts.push(SubductionFront {
            overriding,
            subducting,
            kind,
            points,
            length_km: r.finite_f64("front length")?,
        });
    }
    // Version 1 saves were made between steps, when no suture waits.
    let mut pending = Vec::new();
    if v >= 2 {
        let np = r.u32()? as usize;
        if r.remaining() < np.saturating_mul(56) {
            return Err("pending sutures are truncated".into());
        }
        for _ in 0..np {
            let (terrane, from_plate, to_plate, detached) =
                (r.u32()?, r.u32()?, r.u32()?, r.u32()?);
            if terrane as usize >= area_km2.len() {
                return Err(format!(
                    "pending suture names terrane {terrane}, which does not exist"
                )
                .into());
            }
            pending.push(crate::resources::Suture {
                terrane,
                from_plate,
                to_plate,
                detached_plate: (detached != u32::MAX).then_some(detached),
                area_km2: r.finite_f64("suture area")?,
                relative_speed_km_per_my: r.finite_f64("suture speed")?,
                centroid_world: DVec3::new(
                    r.finite_f64("suture centroid")?,
                    r.finite_f64("suture centroid")?,
                    r.finite_f64("suture centroid")?,
                ),
            });
        }
    }
    r.finish()?;
    world.insert_resource(FrontPoints {
        sample,
        overriding,
        subducting,
        normal,
        length_km,
        active,
        trench,
        subducting_elevation_km,
        relative_velocity: rel,
        converged_km,
        convergence_km_per_my,
        near_vertex: Vec::new(),
    });
    world.insert_resource(field);
    world.insert_resource(OverridePairs(pairs));
    // Terrane centroids are kept once, on the entities; the field's copy is rebuilt from them.
    let mut centroid = vec![glam::DVec3::Z; area_km2.len()];
    for t in &terranes {
        match centroid.get_mut(t.index as usize) {
            Some(c) => *c = t.centroid,
            None => return Err(format!("terrane {} does not exist", t.index).into()),
        }
    }
    world.insert_resource(TerraneField {
        terrane,
        area_km2,
        plate,
        centroid,
    });
    {
        let mut s = world.resource_mut::<Sutures>();
        s.total = total;
        s.pending = pending;
    }
    world
        .resource_mut::<crate::systems::resample::ResampleWork>()
        .continental_subducted_total_km2 = subducted;
    let old: Vec<Entity> = world
        .query_filtered::<Entity, Or<(With<Terrane>, With<SubductionFront>)>>()
        .iter(world)
        .collect();
    for e in old {
        world.despawn(e);
    }
    world.spawn_batch(terranes);
    world.spawn_batch(fronts);
    Ok(())
}
