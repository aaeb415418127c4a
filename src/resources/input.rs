//! Input from users, handled defensively: a file's kind in words (so that a FIFO or a device is
//! named, not read), text files read under a size cap (configs, scripts, sidecars), and echoes
//! of user input clipped to a readable length in messages.

use std::io::Read;
use std::path::Path;

/// Largest parameter file (`--config`), bytes. The full commented parameter list is about
/// 20 KB.
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;
/// Largest script file (`--script`), bytes: tens of thousands of events.
pub const MAX_SCRIPT_BYTES: u64 = 8 << 20;
/// Longest echo of user input in a message, characters (longer ones end in `…`).
pub const MAX_ECHO_CHARS: usize = 120;

/// What a file system entry is, in words: "a regular file", "a folder", "a FIFO (named pipe)",
/// "a character device", "a block device", "a socket", "a symbolic link".
pub fn kind_in_words(t: std::fs::FileType) -> &'static str {
    if t.is_file() {
        return "a regular file";
    }
    if t.is_dir() {
        return "a folder";
    }
    if t.is_symlink() {
        return "a symbolic link";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

/// Why a text file could not be read (the caller names the file).
#[derive(Debug, thiserror::Error)]
pub enum TextFileError {
    /// There is no such file.
    #[error("does not exist")]
    Missing,
    /// The path is a folder.
    #[error("is a folder, not a file")]
    Folder,
    /// The path is a FIFO, a device or a socket, where only a regular file is read.
    #[error("is {0}, not a regular file")]
    NotAFile(&'static str),
    /// The file holds more than the cap.
    #[error("is larger than {} (the most a file of this kind may hold)", bytes_in_words(*limit))]
    TooLarge {
        /// The cap, bytes.
        limit: u64,
    },
    /// The content is not UTF-8 text.
    #[error("is not UTF-8 text")]
    NotUtf8,
    /// The OS refused to read it.
    #[error("{0}")]
    Io(std::io::Error),
}

/// Reads the text file at `path` once, refusing more than `limit` bytes. Pipes and FIFOs are
/// read (`--config <(...)`, `/dev/stdin`); only `limit + 1` bytes are ever read, so an endless
/// source (`/dev/zero`) costs nothing.
pub fn read_text_capped(path: &Path, limit: u64) -> Result<String, TextFileError> {
    let bytes = read_capped(path, limit, true)?;
    String::from_utf8(bytes).map_err(|_| TextFileError::NotUtf8)
}

/// Reads the regular file at `path`, refusing more than `limit` bytes and anything that is not
/// a regular file (a FIFO or a device is never opened).
pub fn read_regular_capped(path: &Path, limit: u64) -> Result<Vec<u8>, TextFileError> {
    read_capped(path, limit, false)
}

fn read_capped(path: &Path, limit: u64, pipes: bool) -> Result<Vec<u8>, TextFileError> {
    let meta = std::fs::metadata(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => TextFileError::Missing,
        _ => TextFileError::Io(e),
    })?;
    if meta.is_dir() {
        return Err(TextFileError::Folder);
    }
    if !pipes && !meta.is_file() {
        return Err(TextFileError::NotAFile(kind_in_words(meta.file_type())));
    }
    if meta.is_file() && meta.len() > limit {
        return Err(TextFileError::TooLarge { limit });
    }
    let file = std::fs::File::open(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => TextFileError::Missing,
        std::io::ErrorKind::IsADirectory => TextFileError::Folder,
        _ => TextFileError::Io(e),
    })?;
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::IsADirectory => TextFileError::Folder,
            _ => TextFileError::Io(e),
        })?;
    if bytes.len() as u64 > limit {
        return Err(TextFileError::TooLarge { limit });
    }
    Ok(bytes)
}

/// A byte count in words: `1 MiB`, `640 KiB`, `12 bytes`, `3.2 GiB`.
pub fn bytes_in_words(n: u64) -> String {
    const UNITS: [(u64, &str); 4] = [
        (1 << 40, "TiB"),
        (1 << 30, "GiB"),
        (1 << 20, "MiB"),
        (1 << 10, "KiB"),
    ];
    for (size, unit) in UNITS {
        if n >= size {
            let v = n as f64 / size as f64;
            return if n.is_multiple_of(size) {
                format!("{} {unit}", n / size)
            } else {
                format!("{v:.1} {unit}")
            };
        }
    }
    format!("{n} bytes")
}

/// `s` as it may be echoed in a message: control characters escaped, and at most
/// [`MAX_ECHO_CHARS`] characters, the rest replaced by `…`.
pub fn clip(s: &str) -> String {
    clip_to(s, MAX_ECHO_CHARS)
}

/// [`clip`] to `max` characters.
pub fn clip_to(s: &str, max: usize) -> String {
    let mut out = String::new();
    for (shown, c) in s.chars().enumerate() {
        if shown >= max {
            out.push('…');
            return out;
        }
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// A multi-line message (a parser's, with its excerpt of the input) with every line clipped to
/// [`MAX_ECHO_CHARS`] characters and at most `max_lines` lines.
pub fn clip_lines(s: &str, max_lines: usize) -> String {
    let mut lines: Vec<String> = Vec::new();
    for (k, line) in s.lines().enumerate() {
        if k == max_lines {
            lines.push("…".into());
            break;
        }
        lines.push(clip(line));
    }
    lines.join("\n")
}

/// A float as it may be echoed in a message: shortest round-trip digits in scientific notation
/// for very large or small magnitudes (never 300 digits), `NaN` and `inf` as such.
pub fn num(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-4..1e15).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_bounds_echoes() {
        let long = "k".repeat(1_000_000);
        let c = clip(&long);
        assert_eq!(c.chars().count(), MAX_ECHO_CHARS + 1);
        assert!(c.ends_with("…"));
        assert_eq!(clip("a\0b\nc"), "a\\u{0}b\\nc");
        assert_eq!(clip("short"), "short");
        let many = "x\n".repeat(100);
        assert_eq!(clip_lines(&many, 3).lines().count(), 4);
    }

    #[test]
    fn numbers_never_print_hundreds_of_digits() {
        assert_eq!(num(1e-300), "1e-300");
        assert_eq!(num(1e300), "1e300");
        assert_eq!(num(2.5), "2.5");
        assert_eq!(num(0.0), "0");
        assert_eq!(num(f64::NAN), "NaN");
    }

    #[test]
    fn sizes_in_words() {
        assert_eq!(bytes_in_words(1 << 20), "1 MiB");
        assert_eq!(bytes_in_words(1536), "1.5 KiB");
        assert_eq!(bytes_in_words(12), "12 bytes");
    }

    #[test]
    fn endless_and_oversized_text_is_refused_cheaply() {
        #[cfg(unix)]
        {
            let e = read_text_capped(Path::new("/dev/zero"), 1024).unwrap_err();
            assert!(matches!(e, TextFileError::TooLarge { limit: 1024 }), "{e}");
        }
        let dir = std::env::temp_dir().join(format!("planet-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("big.toml");
        std::fs::write(&f, vec![b'a'; 2048]).unwrap();
        assert!(matches!(
            read_text_capped(&f, 1024),
            Err(TextFileError::TooLarge { .. })
        ));
        assert_eq!(read_text_capped(&f, 4096).unwrap().len(), 2048);
        assert!(matches!(
            read_text_capped(&dir, 1024),
            Err(TextFileError::Folder)
        ));
        assert!(matches!(
            read_text_capped(&dir.join("none"), 1024),
            Err(TextFileError::Missing)
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
