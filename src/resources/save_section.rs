//! The save-section API through which every plugin keeps its state in saves: a section is a
//! name, a version and the functions that write and read it ([`SaveSection`]), registered in the
//! [`SaveRegistry`] from a plugin's `build` ([`SaveAppExt::register_save_section`]); its bytes
//! are built with a [`SectionWriter`] and read back with a bounds-checked [`SectionReader`].
//! The file container around the sections (header, compression, checksum, atomic writes) is
//! `io::save`; turning sections into a simulation is `simulation::load`.

use std::io;
use std::path::PathBuf;

use bevy_app::App;
use bevy_ecs::prelude::*;

use crate::geometry::MeshError;
use crate::resources::params::ParamError;

/// Why a section could not be written or read. The message is shown to users inside the
/// loader's error, which names the file and the section.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SectionError {
    /// A read ran past the end of the section.
    #[error("ends early: {needed} bytes needed at offset {offset}, {left} left")]
    EndsEarly {
        /// Bytes the read needed.
        needed: usize,
        /// Where it started.
        offset: usize,
        /// Bytes that were left.
        left: usize,
    },
    /// Bytes were left over after the section was read.
    #[error("{0} unread bytes at the end")]
    TrailingBytes(usize),
    /// A string is not UTF-8.
    #[error("a string is not valid UTF-8")]
    NotUtf8,
    /// A value that must be finite is not.
    #[error("{what} is not finite ({value})")]
    NonFinite {
        /// What the value is.
        what: String,
        /// The value read.
        value: f64,
    },
    /// The content is inconsistent (the message says how).
    #[error("{0}")]
    Invalid(String),
}

impl From<String> for SectionError {
    fn from(message: String) -> Self {
        Self::Invalid(message)
    }
}

impl From<&str> for SectionError {
    fn from(message: &str) -> Self {
        Self::Invalid(message.to_string())
    }
}

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
    /// The target path is a FIFO, a device, a socket or a symbolic link to one (or to nothing):
    /// a save never replaces one.
    #[error(
        "cannot write save {}: it is {kind}; a save only replaces a regular file (give another path)",
        path.display()
    )]
    NotAFile {
        /// The path.
        path: PathBuf,
        /// What it is, in words ("a FIFO (named pipe)", "a character device", ...).
        kind: String,
    },
    /// The target is a file that is not a save (a typo must not cost a file).
    #[error(
        "cannot write save {}: it exists and is not a planet save (it does not start with \"PLANETSV\"); it is left as it is (remove it or give another path)",
        path.display()
    )]
    NotASave {
        /// The path.
        path: PathBuf,
    },
    /// Another program replaced or changed the file since this one last read or wrote it; it
    /// was left as it is.
    #[error(
        "save {} was replaced or changed by another program since this run last read or wrote it; it was left as it is",
        path.display()
    )]
    Replaced {
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
    /// The path is a FIFO, a device or a socket: never read (it could block or never end).
    #[error("is {0}, not a save file (only regular files are read)")]
    NotAFile(&'static str),
    /// The file is larger than any save can be.
    #[error("is {} long, more than any save can be (at most {})", crate::resources::input::bytes_in_words(*bytes), crate::resources::input::bytes_in_words(*limit))]
    TooLarge {
        /// Its length, bytes.
        bytes: u64,
        /// The most a save may hold, bytes.
        limit: u64,
    },
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
    /// The plugins' step schedule cannot be built (see `SimError::Schedule`).
    #[error("the step schedule cannot be built: {0}")]
    Schedule(String),
    /// The reference mesh could not be rebuilt.
    #[error("cannot rebuild the simulation: {0}")]
    Mesh(MeshError),
}

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

/// Writes one section's content.
pub type SaveFn = fn(&mut World, &mut SectionWriter) -> Result<(), SectionError>;
/// Reads one section's content into the world (the section version is given).
pub type LoadFn = fn(&mut World, &mut SectionReader, u32) -> Result<(), SectionError>;
/// Sets up the state of a section absent from an older save.
pub type DefaultFn = fn(&mut World) -> Result<(), SectionError>;

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
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], SectionError> {
        if n > self.remaining() {
            return Err(SectionError::EndsEarly {
                needed: n,
                offset: self.pos,
                left: self.remaining(),
            });
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], SectionError> {
        let s = self.take(N)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }
    /// One byte.
    pub fn u8(&mut self) -> Result<u8, SectionError> {
        Ok(self.array::<1>()?[0])
    }
    /// A u32.
    pub fn u32(&mut self) -> Result<u32, SectionError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    /// A u64.
    pub fn u64(&mut self) -> Result<u64, SectionError> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    /// An f64.
    pub fn f64(&mut self) -> Result<f64, SectionError> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    /// A finite f64 (`what` names it in the error).
    pub fn finite_f64(&mut self, what: &str) -> Result<f64, SectionError> {
        let v = self.f64()?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(SectionError::NonFinite {
                what: what.to_string(),
                value: v,
            })
        }
    }
    /// A string written by [`SectionWriter::str`].
    pub fn str(&mut self) -> Result<&'a str, SectionError> {
        let n = self.u32()? as usize;
        let b = self.take(n)?;
        std::str::from_utf8(b).map_err(|_| SectionError::NotUtf8)
    }
    /// A list written by [`SectionWriter::u32s`].
    pub fn u32s(&mut self) -> Result<Vec<u32>, SectionError> {
        let n = self.u32()? as usize;
        let b = self.take(n.checked_mul(4).ok_or("list length overflows")?)?;
        Ok(b.chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }
    /// Fails unless every byte was read.
    pub fn finish(&self) -> Result<(), SectionError> {
        if self.remaining() == 0 {
            Ok(())
        } else {
            Err(SectionError::TrailingBytes(self.remaining()))
        }
    }
}
