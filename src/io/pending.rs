//! Output files written under a temporary name beside their final one and renamed when
//! complete: an export that stops halfway (an error, a full disk, a kill) leaves no truncated
//! file under the final name, and the previous file of that name survives until the new one is
//! whole.

use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};

/// A file being written as `.NAME.PID.part` beside `path`; [`Self::commit`] renames it to
/// `path`, and dropping it uncommitted removes it.
#[derive(Debug)]
pub struct PendingFile {
    path: PathBuf,
    tmp: PathBuf,
    committed: bool,
}

impl PendingFile {
    /// Creates the temporary file for `path` (which must not be a folder, a FIFO or a device:
    /// such a path is refused with an error of kind `InvalidInput`).
    pub fn create(path: &Path) -> io::Result<(Self, File)> {
        if let Ok(m) = std::fs::metadata(path)
            && !m.is_file()
        {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "it is {}; an export only replaces a regular file",
                    crate::resources::input::kind_in_words(m.file_type())
                ),
            ));
        }
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "export".into());
        let tmp = dir.join(format!(".{name}.{}.part", std::process::id()));
        let file = File::create(&tmp)?;
        Ok((
            Self {
                path: path.to_path_buf(),
                tmp,
                committed: false,
            },
            file,
        ))
    }

    /// The final path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Renames the complete temporary file to the final path, and removes temporary files of
    /// the same path left by killed processes ([`remove_stale_temps`]).
    pub fn commit(mut self) -> io::Result<PathBuf> {
        std::fs::rename(&self.tmp, &self.path)?;
        self.committed = true;
        if let (Some(dir), Some(name)) = (self.tmp.parent(), self.path.file_name()) {
            remove_stale_temps(dir, &name.to_string_lossy(), "part");
        }
        Ok(self.path.clone())
    }
}

/// Removes `.NAME.PID.SUFFIX` files in `dir` whose process no longer runs (left by a process
/// killed while writing `NAME`). Only where running processes can be told (`/proc`); never the
/// file of a process that still runs, nor this process's own.
pub fn remove_stale_temps(dir: &Path, name: &str, suffix: &str) {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let prefix = format!(".{name}.");
    let suffix = format!(".{suffix}");
    for e in entries.flatten() {
        let file_name = e.file_name();
        let Some(pid) = file_name
            .to_str()
            .and_then(|f| f.strip_prefix(&prefix))
            .and_then(|r| r.strip_suffix(&suffix))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if pid == std::process::id() || proc.join(pid.to_string()).exists() {
            continue;
        }
        if e.file_type().is_ok_and(|t| t.is_file()) && std::fs::remove_file(e.path()).is_ok() {
            tracing::info!(file = %e.path().display(), "removed a stale temporary file");
        }
    }
}

impl Drop for PendingFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unfinished_file_leaves_nothing_and_the_previous_one_survives() {
        let dir = std::env::temp_dir().join(format!("planet-pending-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.tif");
        std::fs::write(&path, b"previous").unwrap();
        // A stale part of a process that is gone (PIDs never reach this value).
        let stale = dir.join(format!(".a.tif.{}.part", 4_194_304 + 9));
        std::fs::write(&stale, b"half").unwrap();
        {
            let (p, mut f) = PendingFile::create(&path).unwrap();
            std::io::Write::write_all(&mut f, b"half of the new one").unwrap();
            drop(p);
        }
        assert_eq!(std::fs::read(&path).unwrap(), b"previous");
        assert!(stale.exists());
        let (p, mut f) = PendingFile::create(&path).unwrap();
        std::io::Write::write_all(&mut f, b"new").unwrap();
        drop(f);
        p.commit().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"new");
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(left.len(), 1, "temporary files left: {left:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
