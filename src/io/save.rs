//! Save files: the whole simulation state in one checksummed, compressed file of named sections,
//! safe (atomic) writes, and a reader that answers any bad file with a clear error. The layout
//! is documented in `docs/save-format.md`.
//!
//! A save is a 32-byte header followed by a sequence of named, length-prefixed sections. What a
//! section holds is up to the plugin that registered it (the section API is
//! [`crate::resources::save_section`]); this module only packs the sections into a file
//! ([`save_to_bytes`]) and unpacks them ([`read_sections`]); the simulation encodes and decodes
//! its state ([`Simulation::to_sections`], [`Simulation::from_sections`]).

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use bevy_app::PluginGroup;
use rayon::prelude::*;

use crate::plugins::TectonicPlugins;
pub use crate::resources::save_section::{LoadError, LoadErrorKind, RawSection, SaveError};
pub use crate::resources::{
    CommandHistory, SaveAppExt, SaveRegistry, SaveSection, SectionError, SectionReader,
    SectionWriter,
};
use crate::simulation::Simulation;
pub use crate::simulation::core_sections::{CoreSavePlugin, mesh_fingerprint};

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
    let sections = sim.to_sections()?;
    Ok(pack_sections(&sections, opts))
}

/// Packs encoded sections into save-file bytes (header, optional LZ4 per section, checksum).
pub fn pack_sections(sections: &[RawSection], opts: SaveOptions) -> (Vec<u8>, SaveInfo) {
    let raw_bytes = sections.iter().map(|s| s.data.len() as u64).sum();
    let stored: Vec<(u8, Vec<u8>)> = sections
        .par_iter()
        .map(|s| {
            let r = &s.data;
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
        .zip(&stored)
        .map(|(s, (c, z))| {
            2 + s.name.len()
                + 4
                + 1
                + 8
                + 8
                + if *c == CODEC_RAW {
                    s.data.len()
                } else {
                    z.len()
                }
        })
        .sum();
    let mut out = Vec::with_capacity(HEADER_LEN + body_len);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(sections.len() as u32).to_le_bytes());
    out.extend_from_slice(&(body_len as u64).to_le_bytes());
    out.extend_from_slice(&[0u8; 8]);
    for (s, (codec, z)) in sections.iter().zip(&stored) {
        let data = if *codec == CODEC_RAW { &s.data } else { z };
        out.extend_from_slice(&(s.name.len() as u16).to_le_bytes());
        out.extend_from_slice(s.name.as_bytes());
        out.extend_from_slice(&s.version.to_le_bytes());
        out.push(*codec);
        out.extend_from_slice(&(s.data.len() as u64).to_le_bytes());
        out.extend_from_slice(&(data.len() as u64).to_le_bytes());
        out.extend_from_slice(data);
    }
    let crc = checksum(&out);
    out[24..28].copy_from_slice(&crc.to_le_bytes());
    let info = SaveInfo {
        file_bytes: out.len() as u64,
        raw_bytes,
    };
    (out, info)
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
        let ctx = |e: SectionError| layout(format!("section `{name}`: {e}"));
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
            )
            .into()));
        }
        let data = r.take(stored_len as usize).map_err(ctx)?;
        let content = match codec {
            CODEC_RAW => {
                if raw_len != stored_len {
                    return Err(ctx(format!(
                        "raw section of {stored_len} bytes claims {raw_len} uncompressed"
                    )
                    .into()));
                }
                data.to_vec()
            }
            CODEC_LZ4 => {
                // LZ4 cannot expand more than 255 times: refuse larger claims before allocating.
                if raw_len > MAX_SECTION_BYTES || raw_len > stored_len.saturating_mul(255) + 16 {
                    return Err(ctx(format!(
                        "claims {raw_len} uncompressed bytes from {stored_len} compressed"
                    )
                    .into()));
                }
                let v = lz4_flex::block::decompress(data, raw_len as usize)
                    .map_err(|e| ctx(format!("LZ4 data is damaged: {e}").into()))?;
                if v.len() as u64 != raw_len {
                    return Err(ctx(format!(
                        "decompressed to {} bytes, {raw_len} announced",
                        v.len()
                    )
                    .into()));
                }
                v
            }
            c => return Err(ctx(format!("unknown codec {c}").into())),
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
/// Loads save bytes with the given plugin group; `file` names the source in errors.
pub fn load_from_bytes_with(
    bytes: &[u8],
    file: &Path,
    plugins: impl PluginGroup,
) -> Result<Simulation, LoadError> {
    let sections = read_sections(bytes, file)?;
    Simulation::from_sections(&sections, plugins).map_err(|kind| LoadError {
        file: file.to_path_buf(),
        kind,
    })
}
