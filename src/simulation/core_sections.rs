//! The core save sections (parameters, mesh recipe, phenomena switches, clock, crust, plates,
//! command history) and the plugin-parameter section, registered by [`CoreSavePlugin`], which
//! every [`Simulation`](crate::Simulation) adds. The file container is `io::save`; the section
//! API is [`crate::resources::save_section`].

use bevy_app::{App, Plugin};
use bevy_ecs::prelude::*;
use glam::{DQuat, DVec3};

use crate::components::{
    Plate, PlateBounds, PlateFrame, PlateId, PlateMesh, PlateMotion, PlateStats,
};
use crate::geometry::SphereMesh;
use crate::plugins::schedule::Phenomena;
use crate::random::StableHasher;
use crate::resources::{
    CommandHistory, Crust, CrustType, LoadErrorKind, NextPlateId, Orogeny, Params, ResampleRequest,
    SaveAppExt, SaveSection, SectionError, SectionReader, SectionWriter, SimClock,
};

/// Registers the core sections: parameters, mesh recipe, phenomena switches, clock, crust,
/// plates, command history and plugin parameters. Added by every
/// [`Simulation`](crate::Simulation).
pub struct CoreSavePlugin;

impl Plugin for CoreSavePlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<CommandHistory>();
        for s in core_sections() {
            app.register_save_section(s);
        }
        app.register_save_section(crate::resources::plugin_params::plugin_params_section());
    }
}

fn core_sections() -> [SaveSection; 7] {
    [
        SaveSection {
            name: "core.params",
            version: 1,
            save: save_params,
            load: load_params_check,
            default: None,
        },
        SaveSection {
            name: "core.mesh",
            version: 1,
            save: save_mesh,
            load: load_mesh_check,
            default: None,
        },
        SaveSection {
            name: "core.phenomena",
            version: 1,
            save: save_phenomena,
            load: load_phenomena,
            default: None,
        },
        SaveSection {
            name: "core.clock",
            version: 1,
            save: save_clock,
            load: load_clock,
            default: None,
        },
        SaveSection {
            name: "core.crust",
            version: 1,
            save: save_crust,
            load: load_crust,
            default: None,
        },
        SaveSection {
            name: "core.plates",
            version: 1,
            save: save_plates,
            load: load_plates,
            default: None,
        },
        SaveSection {
            name: "core.history",
            version: 1,
            save: save_history,
            load: load_history,
            default: Some(|_| Ok(())),
        },
    ]
}

// ---------------------------------------------------------------------------------------------
// Core sections.

fn save_params(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    w.bytes(world.resource::<Params>().to_commented_toml().as_bytes());
    Ok(())
}

pub(crate) fn parse_params(data: &[u8]) -> Result<Params, LoadErrorKind> {
    let text = std::str::from_utf8(data).map_err(|_| LoadErrorKind::Corrupt {
        section: "core.params".into(),
        message: "not UTF-8 text".into(),
    })?;
    Params::from_toml_str(text).map_err(LoadErrorKind::Params)
}

fn load_params_check(
    world: &mut World,
    r: &mut SectionReader,
    _v: u32,
) -> Result<(), SectionError> {
    // Read before the world was built (it needs them); check they are the ones installed.
    let data = r.take(r.remaining())?;
    let p = parse_params(data).map_err(|e| e.to_string())?;
    if &p != world.resource::<Params>() {
        return Err("differs from the parameters the simulation was built with".into());
    }
    Ok(())
}

/// The recipe and fingerprint of a reference mesh (section `core.mesh`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MeshRecipe {
    pub(crate) samples: u64,
    pub(crate) jitter: f64,
    pub(crate) seed: u64,
    pub(crate) radius_km: f64,
    pub(crate) triangles: u64,
    pub(crate) fingerprint: u64,
}

/// A hash of the mesh's positions (f64 bits) and triangles.
pub fn mesh_fingerprint(mesh: &SphereMesh) -> u64 {
    let mut h = StableHasher::default();
    h.write_u64(mesh.positions.len() as u64);
    for p in &mesh.positions {
        h.write_u64(p.x.to_bits());
        h.write_u64(p.y.to_bits());
        h.write_u64(p.z.to_bits());
    }
    h.write_u64(mesh.triangles.len() as u64);
    h.write(bytemuck::cast_slice(&mesh.triangles));
    h.finish()
}

pub(crate) fn recipe_of(params: &Params, mesh: &SphereMesh) -> MeshRecipe {
    MeshRecipe {
        samples: mesh.len() as u64,
        jitter: params.planet.sample_jitter,
        seed: params.planet.seed,
        radius_km: mesh.radius_km,
        triangles: mesh.triangles.len() as u64,
        fingerprint: mesh_fingerprint(mesh),
    }
}

fn save_mesh(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    let r = recipe_of(world.resource::<Params>(), world.resource::<SphereMesh>());
    w.u64(r.samples);
    w.f64(r.jitter);
    w.u64(r.seed);
    w.f64(r.radius_km);
    w.u64(r.triangles);
    w.u64(r.fingerprint);
    Ok(())
}

pub(crate) fn read_recipe(r: &mut SectionReader) -> Result<MeshRecipe, SectionError> {
    let m = MeshRecipe {
        samples: r.u64()?,
        jitter: r.f64()?,
        seed: r.u64()?,
        radius_km: r.f64()?,
        triangles: r.u64()?,
        fingerprint: r.u64()?,
    };
    r.finish()?;
    Ok(m)
}

fn load_mesh_check(_world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    // Checked against the rebuilt mesh before the world was built.
    read_recipe(r).map(|_| ())
}

fn save_phenomena(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    let ph = world.resource::<Phenomena>();
    let list: Vec<_> = ph.iter().collect();
    w.u32(list.len() as u32);
    for p in list {
        w.str(p.name);
        w.u8(p.enabled as u8);
    }
    Ok(())
}

fn load_phenomena(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    let n = r.u32()?;
    let mut ph = world.resource_mut::<Phenomena>();
    for _ in 0..n {
        let name = r.str()?;
        let enabled = match r.u8()? {
            0 => false,
            1 => true,
            b => {
                return Err(
                    format!("phenomenon `{name}`: switch byte {b} is neither 0 nor 1").into(),
                );
            }
        };
        ph.set_enabled(name, enabled).map_err(|_| {
            format!(
                "the save uses phenomenon `{name}`, which no plugin of this simulation registers"
            )
        })?;
    }
    r.finish()
}

fn save_clock(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    let c = world.resource::<SimClock>().clone();
    w.u64(c.step);
    w.f64(c.time_my);
    w.u64(c.steps_since_resample);
    w.u64(c.resamplings);
    w.u32(world.resource::<NextPlateId>().0);
    w.u8(world.resource::<ResampleRequest>().0 as u8);
    Ok(())
}

fn load_clock(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    let clock = SimClock {
        step: r.u64()?,
        time_my: r.finite_f64("time")?,
        steps_since_resample: r.u64()?,
        resamplings: r.u64()?,
    };
    let next_id = r.u32()?;
    let request = match r.u8()? {
        0 => false,
        1 => true,
        b => return Err(format!("resample request byte {b} is neither 0 nor 1").into()),
    };
    r.finish()?;
    if clock.steps_since_resample > clock.step || clock.time_my < 0.0 {
        return Err(format!("inconsistent clock {clock:?}").into());
    }
    *world.resource_mut::<SimClock>() = clock;
    world.resource_mut::<NextPlateId>().0 = next_id;
    world.resource_mut::<ResampleRequest>().0 = request;
    Ok(())
}

/// Element types of crust fields in the `core.crust` section.
const ELEM_F32: u8 = 1;
const ELEM_U8: u8 = 2;
const ELEM_U32: u8 = 3;
const ELEM_F32X3: u8 = 4;

fn elem_size(t: u8) -> Option<usize> {
    match t {
        ELEM_F32 => Some(4),
        ELEM_U8 => Some(1),
        ELEM_U32 => Some(4),
        ELEM_F32X3 => Some(12),
        _ => None,
    }
}

/// The crust fields, in the order they are written.
const CRUST_FIELDS: [(&str, u8); 9] = [
    ("elevation_km", ELEM_F32),
    ("thickness_km", ELEM_F32),
    ("crust_type", ELEM_U8),
    ("age_my", ELEM_F32),
    ("ridge_dir", ELEM_F32X3),
    ("orogeny", ELEM_U8),
    ("orogeny_age_my", ELEM_F32),
    ("fold_dir", ELEM_F32X3),
    ("plate", ELEM_U32),
];

fn save_crust(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    // On the GPU backend, the fields the device holds newer come down first.
    crate::gpu::sync_crust_to_host(world, crate::gpu::FieldMask::ALL).map_err(|e| e.to_string())?;
    let c = world.resource::<Crust>();
    let n = c.len();
    let lens = [
        c.thickness_km.len(),
        c.crust_type.len(),
        c.age_my.len(),
        c.ridge_dir.len(),
        c.orogeny.len(),
        c.orogeny_age_my.len(),
        c.fold_dir.len(),
        c.plate.len(),
    ];
    if lens.iter().any(|&l| l != n) {
        return Err("crust fields have different lengths".into());
    }
    w.u64(n as u64);
    w.u32(CRUST_FIELDS.len() as u32);
    for (name, t) in CRUST_FIELDS {
        w.str(name);
        w.u8(t);
        let bytes: &[u8] = match name {
            "elevation_km" => bytemuck::cast_slice(&c.elevation_km),
            "thickness_km" => bytemuck::cast_slice(&c.thickness_km),
            "crust_type" => bytemuck::cast_slice(&c.crust_type),
            "age_my" => bytemuck::cast_slice(&c.age_my),
            "ridge_dir" => bytemuck::cast_slice(&c.ridge_dir),
            "orogeny" => bytemuck::cast_slice(&c.orogeny),
            "orogeny_age_my" => bytemuck::cast_slice(&c.orogeny_age_my),
            "fold_dir" => bytemuck::cast_slice(&c.fold_dir),
            _ => bytemuck::cast_slice(&c.plate),
        };
        if cfg!(target_endian = "little") {
            w.bytes(bytes);
        } else {
            // Every element is made of 4-byte words (or single bytes): swap per word.
            if elem_size(t) == Some(1) {
                w.bytes(bytes);
            } else {
                for word in bytes.chunks_exact(4) {
                    w.bytes(&[word[3], word[2], word[1], word[0]]);
                }
            }
        }
    }
    Ok(())
}

fn f32s(b: &[u8]) -> Vec<f32> {
    b.chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn f32x3s(b: &[u8]) -> Vec<[f32; 3]> {
    b.chunks_exact(12)
        .map(|c| {
            let f = |k: usize| f32::from_le_bytes([c[k], c[k + 1], c[k + 2], c[k + 3]]);
            [f(0), f(4), f(8)]
        })
        .collect()
}

fn load_crust(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    let n = r.u64()?;
    let expected = world.resource::<SphereMesh>().len() as u64;
    if n != expected {
        return Err(format!("{n} samples, but the mesh has {expected}").into());
    }
    let n = n as usize;
    let count = r.u32()?;
    if count as usize != CRUST_FIELDS.len() {
        return Err(format!("{count} fields, expected {}", CRUST_FIELDS.len()).into());
    }
    let mut crust = Crust::default();
    for (name, t) in CRUST_FIELDS {
        let got = r.str()?;
        if got != name {
            return Err(format!("field `{got}` where `{name}` was expected").into());
        }
        let gt = r.u8()?;
        if gt != t {
            return Err(format!("field `{name}` has element type {gt}, expected {t}").into());
        }
        let size = elem_size(t).unwrap_or(1);
        let b = r.take(n.checked_mul(size).ok_or("field size overflows")?)?;
        match name {
            "elevation_km" => crust.elevation_km = f32s(b),
            "thickness_km" => crust.thickness_km = f32s(b),
            "age_my" => crust.age_my = f32s(b),
            "orogeny_age_my" => crust.orogeny_age_my = f32s(b),
            "ridge_dir" => crust.ridge_dir = f32x3s(b),
            "fold_dir" => crust.fold_dir = f32x3s(b),
            "crust_type" => {
                crust.crust_type = b
                    .iter()
                    .enumerate()
                    .map(|(i, &x)| match x {
                        0 => Ok(CrustType::Oceanic),
                        1 => Ok(CrustType::Continental),
                        _ => Err(format!("crust_type {x} at sample {i} is not 0 or 1").into()),
                    })
                    .collect::<Result<_, SectionError>>()?
            }
            "orogeny" => {
                crust.orogeny = b
                    .iter()
                    .enumerate()
                    .map(|(i, &x)| match x {
                        0 => Ok(Orogeny::None),
                        1 => Ok(Orogeny::Andean),
                        2 => Ok(Orogeny::Himalayan),
                        _ => Err(format!("orogeny {x} at sample {i} is not 0, 1 or 2").into()),
                    })
                    .collect::<Result<_, SectionError>>()?
            }
            _ => {
                crust.plate = b
                    .chunks_exact(4)
                    .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                    .collect()
            }
        }
    }
    r.finish()?;
    crust.check_finite().map_err(|e| e.to_string())?;
    *world.resource_mut::<Crust>() = crust;
    Ok(())
}

fn save_plates(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    let mut q = world.query::<(
        &Plate,
        &PlateMotion,
        &PlateFrame,
        &PlateMesh,
        &PlateBounds,
        &PlateStats,
    )>();
    let mut plates: Vec<_> = q.iter(world).collect();
    plates.sort_by_key(|p| p.0.id);
    w.u32(plates.len() as u32);
    for (p, m, f, pm, b, s) in plates {
        w.u32(p.id.0);
        for v in [
            m.euler_pole.x,
            m.euler_pole.y,
            m.euler_pole.z,
            m.angular_speed_rad_per_my,
        ] {
            w.f64(v);
        }
        let q = f.world_from_plate;
        for v in [q.x, q.y, q.z, q.w] {
            w.f64(v);
        }
        for v in [
            b.centroid.x,
            b.centroid.y,
            b.centroid.z,
            b.cap_radius_rad,
            s.area_km2,
            s.continental_area_km2,
        ] {
            w.f64(v);
        }
        w.u32s(&pm.samples);
        w.u32s(&pm.triangles);
    }
    Ok(())
}

fn strictly_ascending_below(v: &[u32], limit: usize) -> bool {
    v.windows(2).all(|w| w[0] < w[1]) && v.last().is_none_or(|&x| (x as usize) < limit)
}

fn load_plates(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    let n = r.u32()?;
    let (samples, triangles) = {
        let m = world.resource::<SphereMesh>();
        (m.len(), m.triangles.len())
    };
    // No plate moves faster than ten times the fastest surface speed a parameter or a command
    // allows (1,000 mm/yr): a finite but absurd rate would overflow the fronts' velocities.
    let max_speed_rad_per_my = world
        .get_resource::<crate::resources::params::Params>()
        .map_or(f64::INFINITY, |p| 10.0 * 1000.0 / p.planet.radius_km);
    if n == 0 {
        return Err("no plates".into());
    }
    let mut plates = Vec::new();
    for k in 0..n {
        // 17 f64 + 3 u32 at least per plate: refuse a count the section cannot hold.
        if r.remaining() < 4 + 16 * 8 + 8 {
            return Err(format!("{n} plates announced, the data ends at plate {k}").into());
        }
        let id = r.u32()?;
        let mut f = [0.0f64; 14];
        for (i, v) in f.iter_mut().enumerate() {
            *v = r.finite_f64(&format!("plate {id} value {i}"))?;
        }
        let motion = PlateMotion {
            euler_pole: DVec3::new(f[0], f[1], f[2]),
            angular_speed_rad_per_my: f[3],
        };
        if (motion.euler_pole.length() - 1.0).abs() > 1e-6 {
            return Err(format!("plate {id}: Euler pole is not a unit vector").into());
        }
        if motion.angular_speed_rad_per_my.abs() > max_speed_rad_per_my {
            return Err(format!(
                "plate {id}: angular speed {} rad/My is more than {max_speed_rad_per_my:.3} (ten times the fastest plate the parameters allow)",
                motion.angular_speed_rad_per_my
            )
            .into());
        }
        let frame = PlateFrame {
            world_from_plate: DQuat::from_xyzw(f[4], f[5], f[6], f[7]),
        };
        if (frame.world_from_plate.length() - 1.0).abs() > 1e-6 {
            return Err(format!("plate {id}: frame is not a unit quaternion").into());
        }
        let bounds = PlateBounds {
            centroid: DVec3::new(f[8], f[9], f[10]),
            cap_radius_rad: f[11],
        };
        let stats = PlateStats {
            area_km2: f[12],
            continental_area_km2: f[13],
        };
        let mesh = PlateMesh {
            samples: r.u32s()?,
            triangles: r.u32s()?,
        };
        if !strictly_ascending_below(&mesh.samples, samples) {
            return Err(
                format!("plate {id}: sample list is not ascending within 0..{samples}").into(),
            );
        }
        if !strictly_ascending_below(&mesh.triangles, triangles) {
            return Err(format!(
                "plate {id}: triangle list is not ascending within 0..{triangles}"
            )
            .into());
        }
        plates.push((
            Plate { id: PlateId(id) },
            motion,
            frame,
            mesh,
            bounds,
            stats,
        ));
    }
    r.finish()?;
    if let Some(w) = plates.windows(2).find(|w| w[0].0.id >= w[1].0.id) {
        return Err(format!(
            "plate ids are not strictly ascending ({} then {})",
            w[0].0.id.0, w[1].0.id.0
        )
        .into());
    }
    let ids: Vec<u32> = plates.iter().map(|p| p.0.id.0).collect();
    let next_id = world.resource::<NextPlateId>().0;
    if ids.last().is_some_and(|&m| m >= next_id) {
        return Err(format!(
            "plate id {} is not below the next plate id {next_id}",
            ids.last().copied().unwrap_or(0)
        )
        .into());
    }
    if let Some((i, &p)) = world
        .resource::<Crust>()
        .plate
        .iter()
        .enumerate()
        .find(|(_, p)| ids.binary_search(p).is_err())
    {
        return Err(format!("sample {i} belongs to plate {p}, which does not exist").into());
    }
    Plate::despawn_all(world);
    for p in plates {
        world.spawn(p);
    }
    Ok(())
}

fn save_history(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    let h = world.resource::<CommandHistory>();
    w.u32(h.entries.len() as u32);
    for (step, cmd) in &h.entries {
        w.u64(*step);
        w.str(cmd);
    }
    Ok(())
}

fn load_history(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    let n = r.u32()?;
    let mut entries = Vec::new();
    for _ in 0..n {
        if r.remaining() < 12 {
            return Err(format!("{n} entries announced, the data ends early").into());
        }
        entries.push((r.u64()?, r.str()?.to_string()));
    }
    r.finish()?;
    world.resource_mut::<CommandHistory>().entries = entries;
    Ok(())
}
