//! Writing a file so that an interrupted run never leaves a truncated file under a final
//! name: through a temporary file beside it, registered for removal on interruption.

use std::path::{Path, PathBuf};

/// Writes `path` through a temporary file beside it: `write` fills the temporary file,
/// whose name ends like `path`'s (image writers pick the format from the extension); it is
/// then synced and renamed over `path`. If anything fails the temporary file is removed
/// and `path` is untouched, so an interrupted run never leaves a truncated file under a
/// final name. Only a regular file (or nothing) is ever replaced ([`check_output`]).
/// `io_err` turns a refused path, a failed sync or a failed rename into the caller's error.
/// The one place every `vbim` output file is written.
pub fn write_atomic<T, E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<T, E>,
    io_err: impl FnOnce(std::io::Error) -> E,
) -> Result<T, E> {
    if let Err(e) = check_output(path) {
        return Err(io_err(e));
    }
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("out");
    let tmp = path.with_file_name(format!(".tmp-{}-{name}", std::process::id()));
    let _registered = Temporary::new(tmp.clone());
    let result = write(&tmp).and_then(|value| {
        std::fs::File::open(&tmp)
            .and_then(|f| f.sync_all())
            .and_then(|()| std::fs::rename(&tmp, path))
            .map_err(io_err)?;
        Ok(value)
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Temporary files being written, which [`remove_temporaries`] removes when the process
/// is interrupted (the `vbim` command's Ctrl-C and SIGTERM handler), so that an interrupted
/// run leaves nothing behind: no `.tmp-` file of [`write_atomic`], no pass file of
/// `--exact`.
static TEMPORARIES: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

fn temporaries() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner())
}

/// A temporary file registered for removal on interruption while this lives (dropping it
/// only forgets the registration: the owner removes or renames the file itself).
pub struct Temporary(PathBuf);

impl Temporary {
    /// Registers `path`.
    pub fn new(path: PathBuf) -> Temporary {
        temporaries().push(path.clone());
        Temporary(path)
    }

    /// The registered path.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for Temporary {
    fn drop(&mut self) {
        let mut list = temporaries();
        if let Some(i) = list.iter().position(|p| *p == self.0) {
            list.swap_remove(i);
        }
    }
}

/// Removes every registered temporary file. For an interrupt handler, which then exits:
/// the registrations are forgotten, whatever still holds them.
pub fn remove_temporaries() {
    for p in temporaries().drain(..) {
        let _ = std::fs::remove_file(p);
    }
}

/// Refuses an output path that exists and is not a regular file. Renaming over a device,
/// a FIFO, a socket, a directory or a symbolic link would replace what is not ours: as
/// root, `-o /dev/null` would have turned the machine's null device into a file.
pub fn check_output(path: &Path) -> std::io::Result<()> {
    let kind = match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
        Ok(m) => m.file_type(),
    };
    let what = if kind.is_file() {
        return Ok(());
    } else if kind.is_dir() {
        "a directory"
    } else if kind.is_symlink() {
        "a symbolic link (name the file it points to)"
    } else {
        special_kind(kind)
    };
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("is {what}: vbim only creates or replaces regular files"),
    ))
}

/// Writes `text` to `path` through [`write_atomic`].
pub fn write_text(path: &Path, text: &str) -> std::io::Result<()> {
    write_atomic(path, |tmp| std::fs::write(tmp, text), |e| e)
}

/// What a file that is neither a regular file, a directory nor a link is.
#[cfg(unix)]
fn special_kind(kind: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_char_device() || kind.is_block_device() {
        "a device"
    } else if kind.is_fifo() {
        "a FIFO"
    } else {
        "not a regular file"
    }
}

#[cfg(not(unix))]
fn special_kind(_: std::fs::FileType) -> &'static str {
    "not a regular file"
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`write_atomic`] with messages for errors, naming nothing.
    fn write_file(
        path: &Path,
        write: impl FnOnce(&Path) -> Result<(), String>,
    ) -> Result<(), String> {
        write_atomic(path, write, |e| e.to_string())
    }

    #[test]
    fn only_regular_files_are_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        assert!(std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let link = dir.path().join("link");
        let target = dir.path().join("target");
        std::fs::write(&target, b"keep").unwrap();
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        for (path, what) in [
            (&fifo, "a FIFO"),
            (&link, "a symbolic link"),
            (&sub, "a directory"),
        ] {
            let err = write_file(path, |tmp| {
                std::fs::write(tmp, b"x").map_err(|e| e.to_string())
            })
            .unwrap_err()
            .to_string();
            assert!(err.contains(what), "{err}");
        }
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo());
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"keep");
        // Nothing left behind, and a regular file is replaced as before.
        let names = std::fs::read_dir(dir.path()).unwrap().count();
        assert_eq!(names, 4);
        write_file(&target, |tmp| {
            std::fs::write(tmp, b"new").map_err(|e| e.to_string())
        })
        .unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
    }

    /// (Removal itself is the interrupt handler's: `an_interrupted_exact_encode_leaves_no_
    /// file_behind` in tests/cli.rs. Calling it here would remove the files other tests of
    /// this process are writing.)
    #[test]
    fn temporaries_are_registered_while_written_and_forgotten_when_done() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join(".tmp-a"), dir.path().join(".tmp-b"));
        let writing = Temporary::new(a.clone());
        drop(Temporary::new(b.clone()));
        let listed = temporaries().clone();
        assert!(listed.contains(&a) && !listed.contains(&b), "{listed:?}");
        drop(writing);
        assert!(!temporaries().contains(&a));
        // A file written through `write_atomic` is registered only while it is written.
        let target = dir.path().join("frame.bin");
        write_file(&target, |tmp| {
            assert!(temporaries().iter().any(|p| p == tmp));
            std::fs::write(tmp, b"x").map_err(|e| e.to_string())
        })
        .unwrap();
        assert!(!temporaries().iter().any(|p| p.starts_with(dir.path())));
    }
}
