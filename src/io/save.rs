//! Saves: the whole simulation state in one checksummed, compressed file of named sections, the
//! registry through which every plugin adds its own state, safe (atomic) writes, and a loader
//! that answers any bad file with a clear error. The layout is documented in
//! `docs/save-format.md`.
//!
//! A save is a 32-byte header followed by a sequence of named, length-prefixed sections. Each
//! section is written and read by functions registered in the [`SaveRegistry`] with
//! [`SaveAppExt::register_save_section`]; the core registers its own ([`CoreSavePlugin`]), and
//! any plugin registers more from its `build`. Loading refuses a save holding a section that no
//! registered plugin reads, and a save lacking a section that a registered plugin needs (unless
//! that plugin gives a default).

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use bevy_app::{App, Plugin, PluginGroup};
use bevy_ecs::prelude::*;
use glam::{DQuat, DVec3};
use rayon::prelude::*;

use crate::components::{
    Plate, PlateBounds, PlateFrame, PlateId, PlateMesh, PlateMotion, PlateStats,
};
use crate::geometry::SphereMesh;
use crate::io::params::{ParamError, Params};
use crate::plugins::TectonicPlugins;
use crate::random::StableHasher;
use crate::resources::{
    Crust, CrustType, NextPlateId, Orogeny, Phenomena, ResampleRequest, SimClock,
};
use crate::simulation::{SimError, Simulation};
use crate::systems::init;

/// The eight bytes every save starts with.
pub const MAGIC: [u8; 8] = *b"PLANETSV";
/// The container format version this build writes (and the newest it reads).
pub const FORMAT_VERSION: u32 = 1;
/// The usual file extension of saves (without the dot).
pub const EXTENSION: &str = "planet";
/// The folder saves go to when a bare file name is given.
pub const DEFAULT_DIR: &str = "saves";
/// Size of the fixed header, bytes.
pub const HEADER_LEN: usize = 32;
/// Most sections a save may hold.
pub const MAX_SECTIONS: u32 = 1024;
/// Longest section name, bytes.
pub const MAX_NAME_LEN: usize = 64;
/// Largest uncompressed section, bytes (4 GiB).
pub const MAX_SECTION_BYTES: u64 = 1 << 32;

/// Section codec: stored as is.
pub const CODEC_RAW: u8 = 0;
/// Section codec: one LZ4 block (no frame, no size prefix).
pub const CODEC_LZ4: u8 = 1;

/// Why a save could not be written.
#[derive(Debug, thiserror::Error)]
pub enum SaveError {
    /// A file system operation failed.
    #[error("cannot write save {}: {what}: {source}", path.display())]
    Io {
        /// The save being written.
        path: PathBuf,
        /// What was being done.
        what: &'static str,
        /// The OS error.
        source: io::Error,
    },
    /// The target path is a directory.
    #[error("cannot write save {}: it is a directory", path.display())]
    IsDirectory {
        /// The path.
        path: PathBuf,
    },
    /// A section could not be encoded.
    #[error("cannot encode save section `{section}`: {message}")]
    Encode {
        /// Section name.
        section: &'static str,
        /// The problem.
        message: String,
    },
}

/// Why a save could not be loaded: the file (or `<bytes>` for in-memory data) and the problem.
#[derive(Debug, thiserror::Error)]
#[error("save {}: {kind}", file.display())]
pub struct LoadError {
    /// The file being loaded.
    pub file: PathBuf,
    /// What is wrong with it.
    pub kind: LoadErrorKind,
}

/// What is wrong with a save.
#[derive(Debug, thiserror::Error)]
pub enum LoadErrorKind {
    /// There is no such file.
    #[error("no such file")]
    Missing,
    /// The path is a directory.
    #[error("is a directory, not a save file")]
    IsDirectory,
    /// The file could not be read.
    #[error("cannot read: {0}")]
    Read(io::Error),
    /// The file is empty.
    #[error("the file is empty (0 bytes)")]
    Empty,
    /// The file does not start with the save magic.
    #[error("not a planet save: it does not start with the magic \"PLANETSV\" (found {found:?})")]
    BadMagic {
        /// The first bytes, escaped.
        found: String,
    },
    /// The file ends before the length its header gives.
    #[error("truncated: {expected} bytes expected, the file has {actual}")]
    Truncated {
        /// Bytes the header promises (or the header size).
        expected: u64,
        /// Bytes present.
        actual: u64,
    },
    /// The file is longer than its header says.
    #[error("{extra} unexpected bytes after the end of the save")]
    TrailingBytes {
        /// How many.
        extra: u64,
    },
    /// Format version 0 is not a version.
    #[error("format version 0 is invalid")]
    InvalidVersion,
    /// Written by a newer program.
    #[error(
        "format version {found} is newer than this program reads (up to {supported}): update the program"
    )]
    NewerVersion {
        /// Version in the file.
        found: u32,
        /// Newest this build reads.
        supported: u32,
    },
    /// The checksum does not match: the file was damaged.
    #[error(
        "checksum mismatch (stored {stored:#010x}, computed {computed:#010x}): the file is corrupted"
    )]
    Checksum {
        /// CRC-32 in the header.
        stored: u32,
        /// CRC-32 of the content.
        computed: u32,
    },
    /// The section table is malformed.
    #[error("malformed section table: {0}")]
    Layout(String),
    /// A section's content is malformed.
    #[error("section `{section}` is corrupt: {message}")]
    Corrupt {
        /// Section name.
        section: String,
        /// The problem.
        message: String,
    },
    /// A section no registered plugin reads.
    #[error(
        "section `{0}` is not read by any plugin of this simulation (the save was made with a plugin this program lacks)"
    )]
    UnknownSection(String),
    /// A section a registered plugin needs is absent.
    #[error("section `{0}` is missing and its plugin has no default")]
    MissingSection(String),
    /// A section's own version is newer than its plugin reads.
    #[error("section `{section}` has version {found}, newer than this program reads ({supported})")]
    NewerSection {
        /// Section name.
        section: String,
        /// Version in the file.
        found: u32,
        /// Newest the plugin reads.
        supported: u32,
    },
    /// The saved parameters are invalid.
    #[error("saved parameters are invalid: {0}")]
    Params(ParamError),
    /// The rebuilt reference mesh differs from the one the save was made on.
    #[error("{0}")]
    MeshMismatch(String),
    /// The simulation could not be rebuilt.
    #[error("cannot rebuild the simulation: {0}")]
    Sim(SimError),
}

/// Writes one section's content.
pub type SaveFn = fn(&mut World, &mut SectionWriter) -> Result<(), String>;
/// Reads one section's content into the world (the section version is given).
pub type LoadFn = fn(&mut World, &mut SectionReader, u32) -> Result<(), String>;
/// Sets up the state of a section absent from an older save.
pub type DefaultFn = fn(&mut World) -> Result<(), String>;

/// One registered section: its name, its version and the functions that write and read it.
#[derive(Clone, Copy, Debug)]
pub struct SaveSection {
    /// Unique name, `[a-z0-9._-]`, at most 64 bytes; by convention `plugin.thing`.
    pub name: &'static str,
    /// Version of this section's layout; a save holding a newer one is refused.
    pub version: u32,
    /// Writes the section.
    pub save: SaveFn,
    /// Reads the section.
    pub load: LoadFn,
    /// What to do when an (older) save lacks the section; `None`: refuse the save.
    pub default: Option<DefaultFn>,
}

/// Every registered save section, in registration order (the order they are written and read).
#[derive(Resource, Clone, Debug, Default)]
pub struct SaveRegistry {
    sections: Vec<SaveSection>,
}

impl SaveRegistry {
    /// Adds a section; a name registered twice keeps the first registration.
    pub fn register(&mut self, section: SaveSection) {
        if !self.sections.iter().any(|s| s.name == section.name) {
            self.sections.push(section);
        }
    }
    /// Every registered section.
    pub fn sections(&self) -> &[SaveSection] {
        &self.sections
    }
}

/// Registers save sections from a plugin's `build`.
pub trait SaveAppExt {
    /// Adds `section` to the [`SaveRegistry`].
    fn register_save_section(&mut self, section: SaveSection) -> &mut Self;
}

impl SaveAppExt for App {
    fn register_save_section(&mut self, section: SaveSection) -> &mut Self {
        self.init_resource::<SaveRegistry>();
        self.world_mut()
            .resource_mut::<SaveRegistry>()
            .register(section);
        self
    }
}

/// What was done to a planet, in order: one line per command (generate, resume...), with the
/// step at which it took effect. Saved as the `core.history` section.
#[derive(Resource, Clone, Debug, Default, PartialEq, Eq)]
pub struct CommandHistory {
    /// `(step, command line)`, oldest first.
    pub entries: Vec<(u64, String)>,
}

impl CommandHistory {
    /// Appends a command taking effect at `step`.
    pub fn record(&mut self, step: u64, command: impl Into<String>) {
        self.entries.push((step, command.into()));
    }
}

/// Registers the core sections: parameters, mesh recipe, phenomena switches, clock, crust,
/// plates and command history. Added by every [`Simulation`].
pub struct CoreSavePlugin;

impl Plugin for CoreSavePlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<CommandHistory>();
        for s in core_sections() {
            app.register_save_section(s);
        }
        app.register_save_section(convergence_section());
        app.register_save_section(crate::io::plugin_params::plugin_params_section());
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
// Little-endian section encoding.

/// Builds a section's bytes (little-endian).
#[derive(Debug, Default)]
pub struct SectionWriter {
    buf: Vec<u8>,
}

impl SectionWriter {
    /// Appends one byte.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    /// Appends a u32.
    pub fn u32(&mut self, v: u32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// Appends a u64.
    pub fn u64(&mut self, v: u64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// Appends an f64 (its bits).
    pub fn f64(&mut self, v: f64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// Appends raw bytes.
    pub fn bytes(&mut self, v: &[u8]) {
        self.buf.extend_from_slice(v);
    }
    /// Appends a string: u32 byte length, then UTF-8.
    pub fn str(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.bytes(s.as_bytes());
    }
    /// Appends a u32 count then the values.
    pub fn u32s(&mut self, v: &[u32]) {
        self.u32(v.len() as u32);
        self.buf.reserve(v.len() * 4);
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }
    /// The bytes written so far.
    pub fn into_bytes(self) -> Vec<u8> {
        self.buf
    }
}

/// Reads a section's bytes; every read checks the remaining length first, so no count read
/// from the file can make it allocate more than the section holds.
#[derive(Debug)]
pub struct SectionReader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> SectionReader<'a> {
    /// A reader over `data`.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }
    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }
    /// The next `n` bytes.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        if n > self.remaining() {
            return Err(format!(
                "ends early: {n} bytes needed at offset {}, {} left",
                self.pos,
                self.remaining()
            ));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let s = self.take(N)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }
    /// One byte.
    pub fn u8(&mut self) -> Result<u8, String> {
        Ok(self.array::<1>()?[0])
    }
    /// A u32.
    pub fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    /// A u64.
    pub fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    /// An f64.
    pub fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    /// A finite f64 (`what` names it in the error).
    pub fn finite_f64(&mut self, what: &str) -> Result<f64, String> {
        let v = self.f64()?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(format!("{what} is not finite ({v})"))
        }
    }
    /// A string written by [`SectionWriter::str`].
    pub fn str(&mut self) -> Result<&'a str, String> {
        let n = self.u32()? as usize;
        let b = self.take(n)?;
        std::str::from_utf8(b).map_err(|_| "a string is not valid UTF-8".to_string())
    }
    /// A list written by [`SectionWriter::u32s`].
    pub fn u32s(&mut self) -> Result<Vec<u32>, String> {
        let n = self.u32()? as usize;
        let b = self.take(n.checked_mul(4).ok_or("list length overflows")?)?;
        Ok(b.chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }
    /// Fails unless every byte was read.
    pub fn finish(&self) -> Result<(), String> {
        if self.remaining() == 0 {
            Ok(())
        } else {
            Err(format!("{} unread bytes at the end", self.remaining()))
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Core sections.

fn save_params(world: &mut World, w: &mut SectionWriter) -> Result<(), String> {
    w.bytes(world.resource::<Params>().to_commented_toml().as_bytes());
    Ok(())
}

fn parse_params(data: &[u8]) -> Result<Params, LoadErrorKind> {
    let text = std::str::from_utf8(data).map_err(|_| LoadErrorKind::Corrupt {
        section: "core.params".into(),
        message: "not UTF-8 text".into(),
    })?;
    Params::from_toml_str(text).map_err(LoadErrorKind::Params)
}

fn load_params_check(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), String> {
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
struct MeshRecipe {
    samples: u64,
    jitter: f64,
    seed: u64,
    radius_km: f64,
    triangles: u64,
    fingerprint: u64,
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

fn recipe_of(params: &Params, mesh: &SphereMesh) -> MeshRecipe {
    MeshRecipe {
        samples: mesh.len() as u64,
        jitter: params.planet.sample_jitter,
        seed: params.planet.seed,
        radius_km: mesh.radius_km,
        triangles: mesh.triangles.len() as u64,
        fingerprint: mesh_fingerprint(mesh),
    }
}

fn save_mesh(world: &mut World, w: &mut SectionWriter) -> Result<(), String> {
    let r = recipe_of(world.resource::<Params>(), world.resource::<SphereMesh>());
    w.u64(r.samples);
    w.f64(r.jitter);
    w.u64(r.seed);
    w.f64(r.radius_km);
    w.u64(r.triangles);
    w.u64(r.fingerprint);
    Ok(())
}

fn read_recipe(r: &mut SectionReader) -> Result<MeshRecipe, String> {
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

fn load_mesh_check(_world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), String> {
    // Checked against the rebuilt mesh before the world was built.
    read_recipe(r).map(|_| ())
}

fn save_phenomena(world: &mut World, w: &mut SectionWriter) -> Result<(), String> {
    let ph = world.resource::<Phenomena>();
    let list: Vec<_> = ph.iter().collect();
    w.u32(list.len() as u32);
    for p in list {
        w.str(p.name);
        w.u8(p.enabled as u8);
    }
    Ok(())
}

fn load_phenomena(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), String> {
    let n = r.u32()?;
    let mut ph = world.resource_mut::<Phenomena>();
    for _ in 0..n {
        let name = r.str()?;
        let enabled = match r.u8()? {
            0 => false,
            1 => true,
            b => {
                return Err(format!(
                    "phenomenon `{name}`: switch byte {b} is neither 0 nor 1"
                ));
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

fn save_clock(world: &mut World, w: &mut SectionWriter) -> Result<(), String> {
    let c = world.resource::<SimClock>().clone();
    w.u64(c.step);
    w.f64(c.time_my);
    w.u64(c.steps_since_resample);
    w.u64(c.resamplings);
    w.u32(world.resource::<NextPlateId>().0);
    w.u8(world.resource::<ResampleRequest>().0 as u8);
    Ok(())
}

fn load_clock(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), String> {
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
        b => return Err(format!("resample request byte {b} is neither 0 nor 1")),
    };
    r.finish()?;
    if clock.steps_since_resample > clock.step || clock.time_my < 0.0 {
        return Err(format!("inconsistent clock {clock:?}"));
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

fn save_crust(world: &mut World, w: &mut SectionWriter) -> Result<(), String> {
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

fn load_crust(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), String> {
    let n = r.u64()?;
    let expected = world.resource::<SphereMesh>().len() as u64;
    if n != expected {
        return Err(format!("{n} samples, but the mesh has {expected}"));
    }
    let n = n as usize;
    let count = r.u32()?;
    if count as usize != CRUST_FIELDS.len() {
        return Err(format!("{count} fields, expected {}", CRUST_FIELDS.len()));
    }
    let mut crust = Crust::default();
    for (name, t) in CRUST_FIELDS {
        let got = r.str()?;
        if got != name {
            return Err(format!("field `{got}` where `{name}` was expected"));
        }
        let gt = r.u8()?;
        if gt != t {
            return Err(format!(
                "field `{name}` has element type {gt}, expected {t}"
            ));
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
                        _ => Err(format!("crust_type {x} at sample {i} is not 0 or 1")),
                    })
                    .collect::<Result<_, _>>()?
            }
            "orogeny" => {
                crust.orogeny = b
                    .iter()
                    .enumerate()
                    .map(|(i, &x)| match x {
                        0 => Ok(Orogeny::None),
                        1 => Ok(Orogeny::Andean),
                        2 => Ok(Orogeny::Himalayan),
                        _ => Err(format!("orogeny {x} at sample {i} is not 0, 1 or 2")),
                    })
                    .collect::<Result<_, _>>()?
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

fn save_plates(world: &mut World, w: &mut SectionWriter) -> Result<(), String> {
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

fn load_plates(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), String> {
    let n = r.u32()?;
    let (samples, triangles) = {
        let m = world.resource::<SphereMesh>();
        (m.len(), m.triangles.len())
    };
    if n == 0 {
        return Err("no plates".into());
    }
    let mut plates = Vec::new();
    for k in 0..n {
        // 17 f64 + 3 u32 at least per plate: refuse a count the section cannot hold.
        if r.remaining() < 4 + 16 * 8 + 8 {
            return Err(format!("{n} plates announced, the data ends at plate {k}"));
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
            return Err(format!("plate {id}: Euler pole is not a unit vector"));
        }
        let frame = PlateFrame {
            world_from_plate: DQuat::from_xyzw(f[4], f[5], f[6], f[7]),
        };
        if (frame.world_from_plate.length() - 1.0).abs() > 1e-6 {
            return Err(format!("plate {id}: frame is not a unit quaternion"));
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
            return Err(format!(
                "plate {id}: sample list is not ascending within 0..{samples}"
            ));
        }
        if !strictly_ascending_below(&mesh.triangles, triangles) {
            return Err(format!(
                "plate {id}: triangle list is not ascending within 0..{triangles}"
            ));
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
        ));
    }
    let ids: Vec<u32> = plates.iter().map(|p| p.0.id.0).collect();
    let next_id = world.resource::<NextPlateId>().0;
    if ids.last().is_some_and(|&m| m >= next_id) {
        return Err(format!(
            "plate id {} is not below the next plate id {next_id}",
            ids.last().copied().unwrap_or(0)
        ));
    }
    if let Some((i, &p)) = world
        .resource::<Crust>()
        .plate
        .iter()
        .enumerate()
        .find(|(_, p)| ids.binary_search(p).is_err())
    {
        return Err(format!(
            "sample {i} belongs to plate {p}, which does not exist"
        ));
    }
    Plate::despawn_all(world);
    for p in plates {
        world.spawn(p);
    }
    Ok(())
}

fn save_history(world: &mut World, w: &mut SectionWriter) -> Result<(), String> {
    let h = world.resource::<CommandHistory>();
    w.u32(h.entries.len() as u32);
    for (step, cmd) in &h.entries {
        w.u64(*step);
        w.str(cmd);
    }
    Ok(())
}

fn load_history(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), String> {
    let n = r.u32()?;
    let mut entries = Vec::new();
    for _ in 0..n {
        if r.remaining() < 12 {
            return Err(format!("{n} entries announced, the data ends early"));
        }
        entries.push((r.u64()?, r.str()?.to_string()));
    }
    r.finish()?;
    world.resource_mut::<CommandHistory>().entries = entries;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Writing.

/// How to write a save.
#[derive(Clone, Copy, Debug)]
pub struct SaveOptions {
    /// Compress sections with LZ4 (default); `false` stores them raw (for tests and tools).
    pub compress: bool,
}

impl Default for SaveOptions {
    fn default() -> Self {
        Self { compress: true }
    }
}

/// Sizes of a written save.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SaveInfo {
    /// Bytes in the file.
    pub file_bytes: u64,
    /// Bytes of all sections before compression.
    pub raw_bytes: u64,
}

/// The whole state of `sim` as save-file bytes.
pub fn save_to_bytes(sim: &mut Simulation) -> Result<Vec<u8>, SaveError> {
    save_to_bytes_with(sim, SaveOptions::default()).map(|(b, _)| b)
}

/// The whole state of `sim` as save-file bytes, with options; also gives the sizes.
pub fn save_to_bytes_with(
    sim: &mut Simulation,
    opts: SaveOptions,
) -> Result<(Vec<u8>, SaveInfo), SaveError> {
    let world = sim.world_mut();
    let sections: Vec<SaveSection> = world
        .get_resource::<SaveRegistry>()
        .map(|r| r.sections.clone())
        .unwrap_or_default();
    let mut raw = Vec::with_capacity(sections.len());
    for s in &sections {
        let mut w = SectionWriter::default();
        (s.save)(world, &mut w).map_err(|message| SaveError::Encode {
            section: s.name,
            message,
        })?;
        raw.push(w.into_bytes());
    }
    let raw_bytes = raw.iter().map(|r| r.len() as u64).sum();
    let stored: Vec<(u8, Vec<u8>)> = raw
        .par_iter()
        .map(|r| {
            if opts.compress {
                let z = lz4_flex::block::compress(r);
                // Incompressible content is stored as is.
                if z.len() < r.len() {
                    (CODEC_LZ4, z)
                } else {
                    (CODEC_RAW, Vec::new())
                }
            } else {
                (CODEC_RAW, Vec::new())
            }
        })
        .collect();
    let body_len: usize = sections
        .iter()
        .zip(&raw)
        .zip(&stored)
        .map(|((s, r), (c, z))| {
            2 + s.name.len() + 4 + 1 + 8 + 8 + if *c == CODEC_RAW { r.len() } else { z.len() }
        })
        .sum();
    let mut out = Vec::with_capacity(HEADER_LEN + body_len);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(sections.len() as u32).to_le_bytes());
    out.extend_from_slice(&(body_len as u64).to_le_bytes());
    out.extend_from_slice(&[0u8; 8]);
    for ((s, r), (codec, z)) in sections.iter().zip(&raw).zip(&stored) {
        let data = if *codec == CODEC_RAW { r } else { z };
        out.extend_from_slice(&(s.name.len() as u16).to_le_bytes());
        out.extend_from_slice(s.name.as_bytes());
        out.extend_from_slice(&s.version.to_le_bytes());
        out.push(*codec);
        out.extend_from_slice(&(r.len() as u64).to_le_bytes());
        out.extend_from_slice(&(data.len() as u64).to_le_bytes());
        out.extend_from_slice(data);
    }
    let crc = checksum(&out);
    out[24..28].copy_from_slice(&crc.to_le_bytes());
    let info = SaveInfo {
        file_bytes: out.len() as u64,
        raw_bytes,
    };
    Ok((out, info))
}

/// CRC-32 (IEEE, as zlib's `crc32`) of a whole save but its checksum field (bytes 24..28).
pub fn checksum(file: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(&file[..24.min(file.len())]);
    if file.len() > 28 {
        h.update(&file[28..]);
    }
    h.finalize()
}

/// Where a save named `name` goes: a bare file name goes into [`DEFAULT_DIR`]; a path with a
/// folder is kept as given.
pub fn resolve_save_path(name: &Path) -> PathBuf {
    let bare = name.parent().is_none_or(|p| p.as_os_str().is_empty());
    if bare {
        Path::new(DEFAULT_DIR).join(name)
    } else {
        name.to_path_buf()
    }
}

/// Writes `sim` to `path` safely: to a temporary file beside it, flushed and synced, then
/// renamed over `path`. However the write is interrupted, the previous save at `path` survives.
pub fn save_to_file(sim: &mut Simulation, path: &Path) -> Result<SaveInfo, SaveError> {
    let (bytes, info) = save_to_bytes_with(sim, SaveOptions::default())?;
    write_atomic(path, |f| f.write_all(&bytes))?;
    Ok(info)
}

/// Writes a file safely: `write` fills a temporary file in the same folder, which is flushed,
/// synced and renamed over `path`; on any error the temporary file is removed and `path` is left
/// as it was.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), SaveError> {
    let err = |what: &'static str| {
        let path = path.to_path_buf();
        move |source| SaveError::Io { path, what, source }
    };
    if path.is_dir() {
        return Err(SaveError::IsDirectory {
            path: path.to_path_buf(),
        });
    }
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(err("creating its folder"))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "save".into());
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| -> Result<(), SaveError> {
        let file = File::create(&tmp).map_err(err("creating the temporary file"))?;
        let mut w = io::BufWriter::with_capacity(1 << 20, file);
        write(&mut w).map_err(err("writing the temporary file"))?;
        let file = w
            .into_inner()
            .map_err(|e| e.into_error())
            .map_err(err("flushing the temporary file"))?;
        file.sync_all().map_err(err("syncing the temporary file"))?;
        drop(file);
        std::fs::rename(&tmp, path).map_err(err("renaming the temporary file over it"))?;
        // Make the rename durable (best effort: not every platform can sync a folder).
        if let Ok(d) = File::open(&dir) {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

// ---------------------------------------------------------------------------------------------
// Reading.

/// One section of a save as found in the file, decompressed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RawSection {
    /// Its name.
    pub name: String,
    /// Its layout version.
    pub version: u32,
    /// Its uncompressed content.
    pub data: Vec<u8>,
}

/// Checks the header and checksum and splits a save into its (decompressed) sections, without
/// interpreting them. Errors name the problem; `file` is only used in them.
pub fn read_sections(bytes: &[u8], file: &Path) -> Result<Vec<RawSection>, LoadError> {
    let fail = |kind| LoadError {
        file: file.to_path_buf(),
        kind,
    };
    if bytes.is_empty() {
        return Err(fail(LoadErrorKind::Empty));
    }
    let head = &bytes[..bytes.len().min(8)];
    if head != &MAGIC[..head.len()] {
        return Err(fail(LoadErrorKind::BadMagic {
            found: head.escape_ascii().to_string(),
        }));
    }
    if bytes.len() < HEADER_LEN {
        return Err(fail(LoadErrorKind::Truncated {
            expected: HEADER_LEN as u64,
            actual: bytes.len() as u64,
        }));
    }
    let u32_at =
        |o: usize| u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    let version = u32_at(8);
    if version == 0 {
        return Err(fail(LoadErrorKind::InvalidVersion));
    }
    if version > FORMAT_VERSION {
        return Err(fail(LoadErrorKind::NewerVersion {
            found: version,
            supported: FORMAT_VERSION,
        }));
    }
    let count = u32_at(12);
    let mut body_len_b = [0u8; 8];
    body_len_b.copy_from_slice(&bytes[16..24]);
    let body_len = u64::from_le_bytes(body_len_b);
    let actual = (bytes.len() - HEADER_LEN) as u64;
    if body_len > actual {
        return Err(fail(LoadErrorKind::Truncated {
            expected: body_len.saturating_add(HEADER_LEN as u64),
            actual: bytes.len() as u64,
        }));
    }
    if body_len < actual {
        return Err(fail(LoadErrorKind::TrailingBytes {
            extra: actual - body_len,
        }));
    }
    let stored = u32_at(24);
    let computed = checksum(bytes);
    if stored != computed {
        return Err(fail(LoadErrorKind::Checksum { stored, computed }));
    }
    if count > MAX_SECTIONS {
        return Err(fail(LoadErrorKind::Layout(format!(
            "{count} sections (at most {MAX_SECTIONS} allowed)"
        ))));
    }
    let layout = |m: String| fail(LoadErrorKind::Layout(m));
    let mut r = SectionReader::new(&bytes[HEADER_LEN..]);
    let mut out: Vec<RawSection> = Vec::new();
    for k in 0..count {
        let name_len = u16::from_le_bytes(
            r.take(2)
                .map_err(|e| layout(format!("section {k}: {e}")))?
                .try_into()
                .map_err(|_| layout("bad name length".into()))?,
        ) as usize;
        if name_len == 0 || name_len > MAX_NAME_LEN {
            return Err(layout(format!(
                "section {k}: name length {name_len} is not within 1..={MAX_NAME_LEN}"
            )));
        }
        let name_b = r
            .take(name_len)
            .map_err(|e| layout(format!("section {k}: {e}")))?;
        let name = std::str::from_utf8(name_b)
            .ok()
            .filter(|n| {
                n.bytes()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || b"._-".contains(&c))
            })
            .ok_or_else(|| {
                layout(format!(
                    "section {k}: name {:?} is not made of a-z 0-9 . _ -",
                    name_b.escape_ascii().to_string()
                ))
            })?
            .to_string();
        let ctx = |e: String| layout(format!("section `{name}`: {e}"));
        let sversion = r.u32().map_err(ctx)?;
        let codec = r.u8().map_err(ctx)?;
        let raw_len = r.u64().map_err(ctx)?;
        let stored_len = r.u64().map_err(ctx)?;
        if out.iter().any(|s| s.name == name) {
            return Err(layout(format!("section `{name}` appears twice")));
        }
        if stored_len > r.remaining() as u64 {
            return Err(ctx(format!(
                "{stored_len} bytes announced, {} left in the file",
                r.remaining()
            )));
        }
        let data = r.take(stored_len as usize).map_err(ctx)?;
        let content = match codec {
            CODEC_RAW => {
                if raw_len != stored_len {
                    return Err(ctx(format!(
                        "raw section of {stored_len} bytes claims {raw_len} uncompressed"
                    )));
                }
                data.to_vec()
            }
            CODEC_LZ4 => {
                // LZ4 cannot expand more than 255 times: refuse larger claims before allocating.
                if raw_len > MAX_SECTION_BYTES || raw_len > stored_len.saturating_mul(255) + 16 {
                    return Err(ctx(format!(
                        "claims {raw_len} uncompressed bytes from {stored_len} compressed"
                    )));
                }
                let v = lz4_flex::block::decompress(data, raw_len as usize)
                    .map_err(|e| ctx(format!("LZ4 data is damaged: {e}")))?;
                if v.len() as u64 != raw_len {
                    return Err(ctx(format!(
                        "decompressed to {} bytes, {raw_len} announced",
                        v.len()
                    )));
                }
                v
            }
            c => return Err(ctx(format!("unknown codec {c}"))),
        };
        out.push(RawSection {
            name,
            version: sversion,
            data: content,
        });
    }
    r.finish()
        .map_err(|e| layout(format!("after the last section: {e}")))?;
    Ok(out)
}

/// Reads a save file into bytes, with clear errors for a missing file, a directory, an
/// unreadable or empty file.
pub fn read_file(path: &Path) -> Result<Vec<u8>, LoadError> {
    let fail = |kind| LoadError {
        file: path.to_path_buf(),
        kind,
    };
    let meta = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Err(fail(LoadErrorKind::Missing)),
        Err(e) => return Err(fail(LoadErrorKind::Read(e))),
    };
    if meta.is_dir() {
        return Err(fail(LoadErrorKind::IsDirectory));
    }
    let bytes = std::fs::read(path).map_err(|e| fail(LoadErrorKind::Read(e)))?;
    if bytes.is_empty() {
        return Err(fail(LoadErrorKind::Empty));
    }
    Ok(bytes)
}

/// Loads a save with the built-in plugins ([`TectonicPlugins`]).
pub fn load_from_file(path: &Path) -> Result<Simulation, LoadError> {
    load_from_file_with(path, TectonicPlugins)
}

/// Loads a save with the given plugin group (it must be the one the save was made with).
pub fn load_from_file_with(
    path: &Path,
    plugins: impl PluginGroup,
) -> Result<Simulation, LoadError> {
    let bytes = read_file(path)?;
    load_from_bytes_with(&bytes, path, plugins)
}

/// Loads save bytes with the built-in plugins; `file` names the source in errors.
pub fn load_from_bytes(bytes: &[u8], file: &Path) -> Result<Simulation, LoadError> {
    load_from_bytes_with(bytes, file, TectonicPlugins)
}

/// Loads save bytes with the given plugin group; `file` names the source in errors.
pub fn load_from_bytes_with(
    bytes: &[u8],
    file: &Path,
    plugins: impl PluginGroup,
) -> Result<Simulation, LoadError> {
    let fail = |kind| LoadError {
        file: file.to_path_buf(),
        kind,
    };
    let corrupt = |section: &str, message: String| {
        fail(LoadErrorKind::Corrupt {
            section: section.to_string(),
            message,
        })
    };
    let sections = read_sections(bytes, file)?;
    let find = |name: &str| sections.iter().find(|s| s.name == name);
    // The bootstrap sections are read before the registry exists: check their versions here.
    for s in &sections {
        if (s.name == "core.params" || s.name == "core.mesh") && s.version > 1 {
            return Err(fail(LoadErrorKind::NewerSection {
                section: s.name.clone(),
                found: s.version,
                supported: 1,
            }));
        }
    }
    // Bootstrap: parameters and mesh recipe, needed to build the world.
    let params_s = find("core.params")
        .ok_or_else(|| fail(LoadErrorKind::MissingSection("core.params".into())))?;
    let params = parse_params(&params_s.data).map_err(fail)?;
    let mesh_s =
        find("core.mesh").ok_or_else(|| fail(LoadErrorKind::MissingSection("core.mesh".into())))?;
    let recipe =
        read_recipe(&mut SectionReader::new(&mesh_s.data)).map_err(|e| corrupt("core.mesh", e))?;
    let expected = MeshRecipe {
        samples: params.planet.samples,
        jitter: params.planet.sample_jitter,
        seed: params.planet.seed,
        radius_km: params.planet.radius_km,
        triangles: recipe.triangles,
        fingerprint: recipe.fingerprint,
    };
    if recipe != expected {
        return Err(corrupt(
            "core.mesh",
            format!("mesh recipe {recipe:?} does not match the saved parameters"),
        ));
    }
    let mesh = init::reference_mesh(&params).map_err(|e| fail(LoadErrorKind::Sim(e.into())))?;
    let rebuilt = recipe_of(&params, &mesh);
    if rebuilt.fingerprint != recipe.fingerprint || rebuilt.triangles != recipe.triangles {
        return Err(fail(LoadErrorKind::MeshMismatch(format!(
            "the reference mesh this program builds for these parameters ({} triangles, fingerprint {:#018x}) differs from the one the save was made on ({} triangles, fingerprint {:#018x}): the save comes from a program whose mesh construction differs",
            rebuilt.triangles, rebuilt.fingerprint, recipe.triangles, recipe.fingerprint
        ))));
    }
    let mut sim = Simulation::from_parts(params, mesh, plugins);
    let registry: Vec<SaveSection> = sim
        .world()
        .get_resource::<SaveRegistry>()
        .map(|r| r.sections.clone())
        .unwrap_or_default();
    if let Some(s) = sections
        .iter()
        .find(|s| !registry.iter().any(|r| r.name == s.name))
    {
        return Err(fail(LoadErrorKind::UnknownSection(s.name.clone())));
    }
    for reg in &registry {
        match find(reg.name) {
            Some(s) => {
                if s.version > reg.version {
                    return Err(fail(LoadErrorKind::NewerSection {
                        section: s.name.clone(),
                        found: s.version,
                        supported: reg.version,
                    }));
                }
                if s.version == 0 {
                    return Err(corrupt(reg.name, "section version 0 is invalid".into()));
                }
                let mut r = SectionReader::new(&s.data);
                (reg.load)(sim.world_mut(), &mut r, s.version).map_err(|e| corrupt(reg.name, e))?;
            }
            None => match reg.default {
                Some(d) => d(sim.world_mut()).map_err(|e| corrupt(reg.name, e))?,
                None => return Err(fail(LoadErrorKind::MissingSection(reg.name.into()))),
            },
        }
    }
    sim.finish_load();
    Ok(sim)
}

/// The convergent-boundary state (section `convergence.state`): subduction front points with
/// their per-step state, the per-sample distance fields, the override pairs, the terranes and
/// the collision count, plus the front and terrane entities. Saves made before this section
/// existed load with empty fronts and terranes, rebuilt at the next resampling.
pub fn convergence_section() -> SaveSection {
    SaveSection {
        name: "convergence.state",
        version: 1,
        save: save_convergence,
        load: load_convergence,
        default: Some(|_| Ok(())),
    }
}

fn f32s_as_bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn bits_as_f32s(v: Vec<u32>, what: &str) -> Result<Vec<f32>, String> {
    let out: Vec<f32> = v.into_iter().map(f32::from_bits).collect();
    if out.iter().any(|x| x.is_nan()) {
        return Err(format!("NaN in {what}"));
    }
    Ok(out)
}

fn save_convergence(world: &mut World, w: &mut SectionWriter) -> Result<(), String> {
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
        w.u8(fp.active[k] as u8);
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
    w.u64(world.resource::<Sutures>().total);
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
    Ok(())
}

fn load_convergence(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), String> {
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
    let (mut normal, mut rel, mut active) = (
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
        active.push(match r.u8()? {
            0 => false,
            1 => true,
            b => return Err(format!("front activity byte {b}")),
        });
    }
    let per_point = |v: Vec<u32>, what: &str| -> Result<Vec<f32>, String> {
        if v.len() != m {
            return Err(format!("{what}: {} values for {m} points", v.len()));
        }
        bits_as_f32s(v, what)
    };
    let length_km = per_point(r.u32s()?, "front lengths")?;
    let subducting_elevation_km = per_point(r.u32s()?, "front elevations")?;
    let converged_km = per_point(r.u32s()?, "front convergence")?;
    let convergence_km_per_my = per_point(r.u32s()?, "front convergence rate")?;
    let per_sample_f = |v: Vec<u32>, what: &str| -> Result<Vec<f32>, String> {
        if v.len() != n {
            return Err(format!("{what}: {} values for {n} samples", v.len()));
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
            b => return Err(format!("unknown front kind {b}")),
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
    r.finish()?;
    world.insert_resource(FrontPoints {
        sample,
        overriding,
        subducting,
        normal,
        length_km,
        active,
        subducting_elevation_km,
        relative_velocity: rel,
        converged_km,
        convergence_km_per_my,
    });
    world.insert_resource(field);
    world.insert_resource(OverridePairs(pairs));
    // Terrane centroids are kept once, on the entities; the field's copy is rebuilt from them.
    let mut centroid = vec![glam::DVec3::Z; area_km2.len()];
    for t in &terranes {
        match centroid.get_mut(t.index as usize) {
            Some(c) => *c = t.centroid,
            None => return Err(format!("terrane {} does not exist", t.index)),
        }
    }
    world.insert_resource(TerraneField {
        terrane,
        area_km2,
        plate,
        centroid,
    });
    world.resource_mut::<Sutures>().total = total;
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
