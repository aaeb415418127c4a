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
/// A symbolic link at `path` is written through (the file it points to is replaced, the link
/// stays); a FIFO, a device or a socket is refused ([`resolve_write_target`]).
pub fn save_to_file(sim: &mut Simulation, path: &Path) -> Result<SaveInfo, SaveError> {
    check_save_target(path)?;
    let (bytes, info) = save_to_bytes_with(sim, SaveOptions::default())?;
    write_atomic(path, |f| f.write_all(&bytes))?;
    Ok(info)
}

/// [`save_to_file`] for a program that saves the same file more than once: `last_seen` is the
/// file as this program last read or wrote it ([`FileStamp::of`], `None` when it did not
/// exist). If the file is no longer that one, another program replaced or changed it: it is
/// left alone and [`SaveError::Replaced`] returned. On success `last_seen` becomes the new file.
pub fn save_to_file_checked(
    sim: &mut Simulation,
    path: &Path,
    last_seen: &mut Option<FileStamp>,
) -> Result<SaveInfo, SaveError> {
    check_save_target(path)?;
    let (bytes, info) = save_to_bytes_with(sim, SaveOptions::default())?;
    write_atomic_inner(path, Some(last_seen), |f| f.write_all(&bytes))?;
    Ok(info)
}

/// Checks that a save may be written at `path`: [`resolve_write_target`] (no folder, FIFO,
/// device or socket, nor a link to one), and a file already there must be empty or a save
/// (start with [`MAGIC`]), so that a mistyped path never replaces another file. Returns where
/// the save will go.
pub fn check_save_target(path: &Path) -> Result<PathBuf, SaveError> {
    use std::io::Read;
    let target = resolve_write_target(path)?;
    if let Ok(f) = File::open(&target) {
        let mut head = Vec::with_capacity(MAGIC.len());
        let _ = f.take(MAGIC.len() as u64).read_to_end(&mut head);
        if !head.is_empty() && head != MAGIC[..head.len()] {
            return Err(SaveError::NotASave {
                path: path.to_path_buf(),
            });
        }
    }
    Ok(target)
}

/// What a file is at one moment (device, inode, length, modification time), to notice that
/// another program replaced or rewrote it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FileStamp {
    len: u64,
    modified: Option<std::time::SystemTime>,
    dev: u64,
    ino: u64,
}

impl FileStamp {
    /// The stamp of the file at `path` (through symbolic links); `None` when there is none.
    pub fn of(path: &Path) -> Option<FileStamp> {
        let m = std::fs::metadata(path).ok()?;
        #[cfg(unix)]
        let (dev, ino) = {
            use std::os::unix::fs::MetadataExt;
            (m.dev(), m.ino())
        };
        #[cfg(not(unix))]
        let (dev, ino) = (0, 0);
        Some(FileStamp {
            len: m.len(),
            modified: m.modified().ok(),
            dev,
            ino,
        })
    }
}

/// Where a write to `path` really goes: `path` itself when it is a regular file or does not
/// exist, or the file that a symbolic link at `path` leads to (so that the link stays a link).
/// Refuses a folder, a link to nothing, and anything that is not a regular file (a FIFO, a
/// character or block device, a socket): a save never replaces one.
pub fn resolve_write_target(path: &Path) -> Result<PathBuf, SaveError> {
    let not_a_file = |kind: String| SaveError::NotAFile {
        path: path.to_path_buf(),
        kind,
    };
    let mut p = path.to_path_buf();
    for hop in 0..40 {
        let meta = match std::fs::symlink_metadata(&p) {
            Ok(m) => m,
            Err(e) if e.kind() == io::ErrorKind::NotFound && hop == 0 => return Ok(p),
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                return Err(not_a_file(format!(
                    "a symbolic link to {}, which does not exist",
                    p.display()
                )));
            }
            Err(source) => {
                return Err(SaveError::Io {
                    path: path.to_path_buf(),
                    what: "looking at what it is",
                    source,
                });
            }
        };
        let t = meta.file_type();
        if t.is_symlink() {
            let to = std::fs::read_link(&p).map_err(|source| SaveError::Io {
                path: path.to_path_buf(),
                what: "reading the symbolic link",
                source,
            })?;
            p = match p.parent() {
                Some(dir) if to.is_relative() => dir.join(to),
                _ => to,
            };
        } else if t.is_dir() {
            return Err(SaveError::IsDirectory {
                path: path.to_path_buf(),
            });
        } else if t.is_file() {
            return Ok(p);
        } else {
            let kind = crate::resources::input::kind_in_words(t);
            return Err(not_a_file(if hop == 0 {
                kind.to_string()
            } else {
                format!("a symbolic link to {} ({kind})", p.display())
            }));
        }
    }
    Err(not_a_file("a chain of more than 40 symbolic links".into()))
}

/// Writes a file safely: `write` fills a temporary file in the same folder, which is flushed,
/// synced and renamed over `path`; on any error the temporary file is removed and `path` is left
/// as it was. A symbolic link at `path` is written through; anything but a regular file is
/// refused ([`resolve_write_target`]). After a successful write, temporary files of the same
/// target left by killed processes (`.NAME.PID.tmp` whose process is gone) are removed.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), SaveError> {
    write_atomic_inner(path, None, write)
}

fn write_atomic_inner(
    path: &Path,
    last_seen: Option<&mut Option<FileStamp>>,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), SaveError> {
    let err = |what: &'static str| {
        let path = path.to_path_buf();
        move |source| SaveError::Io { path, what, source }
    };
    let target = resolve_write_target(path)?;
    let dir = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(err("creating its folder"))?;
    let name = target
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
        if let Some(seen) = &last_seen
            && FileStamp::of(&target) != **seen
        {
            return Err(SaveError::Replaced {
                path: path.to_path_buf(),
            });
        }
        std::fs::rename(&tmp, &target).map_err(err("renaming the temporary file over it"))?;
        // Make the rename durable (best effort: not every platform can sync a folder).
        if let Ok(d) = File::open(&dir) {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    match &result {
        Err(_) => {
            let _ = std::fs::remove_file(&tmp);
        }
        Ok(()) => {
            if let Some(seen) = last_seen {
                *seen = FileStamp::of(&target);
            }
            crate::io::pending::remove_stale_temps(&dir, &name, "tmp");
        }
    }
    result
}

// ---------------------------------------------------------------------------------------------
// Reading.

/// The header fields a reader needs once [`check_header`] accepted them.
struct Header {
    /// Number of sections.
    count: u32,
}

/// Checks the start of a save (`head`, its first bytes, up to [`HEADER_LEN`]) against the
/// length of the whole file: magic, version, and the body length the header gives. Run before
/// the rest of a file is read, so a file that is not a save costs a 32-byte read.
fn check_header(head: &[u8], file_len: u64) -> Result<Header, LoadErrorKind> {
    if file_len == 0 {
        return Err(LoadErrorKind::Empty);
    }
    let magic = &head[..head.len().min(8)];
    if magic != &MAGIC[..magic.len()] {
        return Err(LoadErrorKind::BadMagic {
            found: magic.escape_ascii().to_string(),
        });
    }
    if file_len < HEADER_LEN as u64 || head.len() < HEADER_LEN {
        return Err(LoadErrorKind::Truncated {
            expected: HEADER_LEN as u64,
            actual: file_len.min(head.len() as u64),
        });
    }
    let u32_at = |o: usize| u32::from_le_bytes([head[o], head[o + 1], head[o + 2], head[o + 3]]);
    let version = u32_at(8);
    if version == 0 {
        return Err(LoadErrorKind::InvalidVersion);
    }
    if version > FORMAT_VERSION {
        return Err(LoadErrorKind::NewerVersion {
            found: version,
            supported: FORMAT_VERSION,
        });
    }
    let mut body_len_b = [0u8; 8];
    body_len_b.copy_from_slice(&head[16..24]);
    let body_len = u64::from_le_bytes(body_len_b);
    let actual = file_len - HEADER_LEN as u64;
    if body_len > actual {
        return Err(LoadErrorKind::Truncated {
            expected: body_len.saturating_add(HEADER_LEN as u64),
            actual: file_len,
        });
    }
    if body_len < actual {
        return Err(LoadErrorKind::TrailingBytes {
            extra: actual - body_len,
        });
    }
    Ok(Header { count: u32_at(12) })
}

/// One entry of the section table, its content still as stored.
struct StoredSection<'a> {
    name: String,
    version: u32,
    codec: u8,
    raw_len: u64,
    data: &'a [u8],
}

/// Most bytes a save file may have. A 4,000,000-sample planet saves to a few hundred MB.
pub const MAX_FILE_BYTES: u64 = 4 << 30;
/// Largest `core.params` section (the parameters as commented TOML, about 20 KB).
pub const MAX_PARAMS_BYTES: u64 = crate::resources::input::MAX_CONFIG_BYTES;
/// Largest `core.history` section (a line per command line and per authoring command).
pub const MAX_HISTORY_BYTES: u64 = 64 << 20;

/// The most uncompressed bytes a section named `name` may hold in a save of `samples` samples,
/// and what bounds it (for messages). Sections whose size follows the sample count get a budget
/// per sample (`core.crust` holds 46 bytes a sample, `core.plates` and `convergence.state`
/// less than 128); the others a fixed cap. Checked before anything is decompressed, so a
/// section claiming more (an LZ4 bomb) costs nothing.
pub fn section_limit(name: &str, samples: u64) -> (u64, &'static str) {
    match name {
        "core.params" => (MAX_PARAMS_BYTES, "the parameters"),
        "core.mesh" | "core.clock" => (1 << 10, "a fixed record"),
        "core.phenomena" | "core.plugin_params" => (1 << 20, "a list of names and values"),
        "core.history" => (MAX_HISTORY_BYTES, "the command history"),
        "core.crust" => (
            samples.saturating_mul(64).saturating_add(1 << 12),
            "64 bytes a sample",
        ),
        _ => (
            samples.saturating_mul(256).saturating_add(16 << 20),
            "256 bytes a sample and 16 MiB",
        ),
    }
}

/// Checks the header and checksum and splits a save into its (decompressed) sections, without
/// interpreting them beyond the parameters: their sample count bounds the size of every other
/// section ([`section_limit`]), checked before anything is decompressed. Errors name the
/// problem; `file` is only used in them.
pub fn read_sections(bytes: &[u8], file: &Path) -> Result<Vec<RawSection>, LoadError> {
    let fail = |kind| LoadError {
        file: file.to_path_buf(),
        kind,
    };
    let header =
        check_header(&bytes[..bytes.len().min(HEADER_LEN)], bytes.len() as u64).map_err(fail)?;
    let stored = u32::from_le_bytes([bytes[24], bytes[25], bytes[26], bytes[27]]);
    let computed = checksum(bytes);
    if stored != computed {
        return Err(fail(LoadErrorKind::Checksum { stored, computed }));
    }
    let count = header.count;
    if count > MAX_SECTIONS {
        return Err(fail(LoadErrorKind::Layout(format!(
            "{count} sections (at most {MAX_SECTIONS} allowed)"
        ))));
    }
    let layout = |m: String| fail(LoadErrorKind::Layout(m));
    let mut r = SectionReader::new(&bytes[HEADER_LEN..]);
    let mut table: Vec<StoredSection> = Vec::new();
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
        if table.iter().any(|s| s.name == name) {
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
        match codec {
            CODEC_RAW if raw_len != stored_len => {
                return Err(ctx(format!(
                    "raw section of {stored_len} bytes claims {raw_len} uncompressed"
                )
                .into()));
            }
            CODEC_RAW => {}
            // LZ4 cannot expand more than 255 times: refuse larger claims before allocating.
            CODEC_LZ4
                if raw_len > MAX_SECTION_BYTES || raw_len > stored_len.saturating_mul(255) + 16 =>
            {
                return Err(ctx(format!(
                    "claims {raw_len} uncompressed bytes from {stored_len} compressed"
                )
                .into()));
            }
            CODEC_LZ4 => {}
            c => return Err(ctx(format!("unknown codec {c}").into())),
        }
        table.push(StoredSection {
            name,
            version: sversion,
            codec,
            raw_len,
            data,
        });
    }
    r.finish()
        .map_err(|e| layout(format!("after the last section: {e}")))?;
    // The parameters first (under their own cap): their sample count bounds the rest.
    let params = table
        .iter()
        .find(|s| s.name == "core.params")
        .ok_or_else(|| fail(LoadErrorKind::MissingSection("core.params".into())))?;
    let params_text = unpack(params, MAX_PARAMS_BYTES, "the parameters").map_err(layout)?;
    let samples = crate::simulation::core_sections::parse_params(&params_text)
        .map_err(fail)?
        .planet
        .samples;
    let mut out: Vec<RawSection> = Vec::with_capacity(table.len());
    for s in &table {
        let data = if s.name == "core.params" {
            params_text.clone()
        } else {
            let (limit, why) = section_limit(&s.name, samples);
            unpack(s, limit, why).map_err(layout)?
        };
        out.push(RawSection {
            name: s.name.clone(),
            version: s.version,
            data,
        });
    }
    Ok(out)
}

/// The content of a stored section, refused unbounded: more than `limit` bytes claimed
/// (`why` says what sets the limit) is an error before anything is allocated.
fn unpack(s: &StoredSection, limit: u64, why: &str) -> Result<Vec<u8>, String> {
    let name = &s.name;
    if s.raw_len > limit {
        return Err(format!(
            "section `{name}` claims {} uncompressed bytes, more than it can hold ({}: {why})",
            s.raw_len,
            crate::resources::input::bytes_in_words(limit)
        ));
    }
    match s.codec {
        CODEC_LZ4 => {
            let v = lz4_flex::block::decompress(s.data, s.raw_len as usize)
                .map_err(|e| format!("section `{name}`: LZ4 data is damaged: {e}"))?;
            if v.len() as u64 != s.raw_len {
                return Err(format!(
                    "section `{name}`: decompressed to {} bytes, {} announced",
                    v.len(),
                    s.raw_len
                ));
            }
            Ok(v)
        }
        _ => Ok(s.data.to_vec()),
    }
}

/// Reads a save file into bytes, with clear errors for a missing file, a directory, anything
/// that is not a regular file (a FIFO or a device is never opened for reading), an unreadable
/// or empty file. The header is read and checked (magic, version, length against the file's)
/// before the rest, so a file that is not a save costs 32 bytes of reading.
pub fn read_file(path: &Path) -> Result<Vec<u8>, LoadError> {
    use std::io::Read;
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
    let kind = |m: &std::fs::Metadata| crate::resources::input::kind_in_words(m.file_type());
    if !meta.is_file() {
        return Err(fail(LoadErrorKind::NotAFile(kind(&meta))));
    }
    let mut f = File::open(path).map_err(|e| fail(LoadErrorKind::Read(e)))?;
    // What was opened is what is read (the path may have changed since it was looked at).
    let meta = f.metadata().map_err(|e| fail(LoadErrorKind::Read(e)))?;
    if !meta.is_file() {
        return Err(fail(LoadErrorKind::NotAFile(kind(&meta))));
    }
    let len = meta.len();
    if len > MAX_FILE_BYTES {
        return Err(fail(LoadErrorKind::TooLarge {
            bytes: len,
            limit: MAX_FILE_BYTES,
        }));
    }
    let mut head = Vec::with_capacity(HEADER_LEN);
    (&mut f)
        .take(HEADER_LEN as u64)
        .read_to_end(&mut head)
        .map_err(|e| fail(LoadErrorKind::Read(e)))?;
    check_header(&head, len).map_err(fail)?;
    let mut bytes = Vec::with_capacity(len as usize);
    bytes.extend_from_slice(&head);
    f.take(len - head.len() as u64)
        .read_to_end(&mut bytes)
        .map_err(|e| fail(LoadErrorKind::Read(e)))?;
    if bytes.len() as u64 != len {
        return Err(fail(LoadErrorKind::Truncated {
            expected: len,
            actual: bytes.len() as u64,
        }));
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
    let sections = read_sections(bytes, file)?;
    Simulation::from_sections(&sections, plugins).map_err(|kind| LoadError {
        file: file.to_path_buf(),
        kind,
    })
}
