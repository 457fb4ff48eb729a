//! Bounded reads, atomic writes and output-path checks.
//!
//! Every file frcd reads goes through [`read_limited`]: it refuses anything but a regular file
//! (a FIFO would block forever, `/dev/zero` never ends, a directory is a mistake) and reads at
//! most a documented number of bytes ([`Limits`]), with a typed error beyond. Every file frcd
//! writes goes through [`write_atomic`]: a temporary file in the target's folder, flushed to
//! disk, then renamed over the target, so a full disk or a crash leaves the previous file intact
//! and never a truncated one.

use crate::{Error, Result};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Largest mesh file read by default: 2 GiB (a binary STL of 42 million triangles).
pub const MAX_MESH_BYTES: u64 = 2 << 30;
/// Largest scene file read by default: 256 MiB (its inline frames included).
pub const MAX_SCENE_BYTES: u64 = 256 << 20;
/// Largest trajectory CSV read by default: 4 GiB (about 120 million rows).
pub const MAX_TRAJECTORY_BYTES: u64 = 4 << 30;
/// Largest report or other small JSON file (cost model) read by default: 1 GiB.
pub const MAX_JSON_BYTES: u64 = 1 << 30;
/// Frame indices must be below this by default: 1e9 frames (11.6 days at 1 kHz). Frames are
/// stored sparsely, so the limit is about run time and index width, not memory.
pub const MAX_FRAMES: u64 = 1_000_000_000;

/// Input limits (every one documented above and in `docs/limits.md`); plain data with
/// [`Default`] so a caller can raise one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Bytes of one mesh file ([`MAX_MESH_BYTES`]).
    pub mesh_bytes: u64,
    /// Bytes of a scene file ([`MAX_SCENE_BYTES`]).
    pub scene_bytes: u64,
    /// Bytes of one trajectory CSV ([`MAX_TRAJECTORY_BYTES`]).
    pub trajectory_bytes: u64,
    /// Bytes of a report or cost-model JSON ([`MAX_JSON_BYTES`]).
    pub json_bytes: u64,
    /// Frame indices must be below this ([`MAX_FRAMES`]); at most `u32::MAX`.
    pub frames: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            mesh_bytes: MAX_MESH_BYTES,
            scene_bytes: MAX_SCENE_BYTES,
            trajectory_bytes: MAX_TRAJECTORY_BYTES,
            json_bytes: MAX_JSON_BYTES,
            frames: MAX_FRAMES,
        }
    }
}

/// What kind of thing a path is, in words, when it is not a regular file.
fn non_regular_kind(meta: &std::fs::Metadata) -> Option<&'static str> {
    let t = meta.file_type();
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a directory");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_char_device() {
            return Some("a character device");
        }
        if t.is_block_device() {
            return Some("a block device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("not a regular file")
}

/// Reads a whole regular file of at most `limit` bytes.
///
/// Errors: [`Error::NotAFile`] for a directory, FIFO, device or socket (checked before opening,
/// so a FIFO never blocks; symbolic links are followed), [`Error::TooLarge`] beyond `limit`
/// (checked on the size and again while reading, for files that grow), [`Error::Io`] otherwise.
///
/// ```
/// let e = frcd_io::read_limited("/dev/zero".as_ref(), 1 << 20).unwrap_err();
/// assert!(matches!(e, frcd_io::Error::NotAFile { .. }));
/// ```
pub fn read_limited(path: &Path, limit: u64) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if let Some(kind) = non_regular_kind(&meta) {
        return Err(Error::NotAFile {
            path: path.into(),
            kind,
        });
    }
    if meta.len() > limit {
        return Err(Error::TooLarge {
            path: path.into(),
            size: Some(meta.len()),
            limit,
        });
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    // The path may have been swapped between the check and the open: check the open file too.
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if let Some(kind) = non_regular_kind(&meta) {
        return Err(Error::NotAFile {
            path: path.into(),
            kind,
        });
    }
    let mut bytes = Vec::with_capacity(meta.len().min(limit) as usize);
    file.take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(Error::TooLarge {
            path: path.into(),
            size: None,
            limit,
        });
    }
    Ok(bytes)
}

/// [`read_limited`] as UTF-8 text (the error names the line of the first bad byte).
pub fn read_text_limited(path: &Path, limit: u64) -> Result<String> {
    let bytes = read_limited(path, limit)?;
    String::from_utf8(bytes).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        let bytes = e.into_bytes();
        let line = 1 + bytes[..valid].iter().filter(|&&b| b == b'\n').count();
        Error::parse(path, crate::Location::Line(line), "text is not valid UTF-8")
    })
}

/// The file a write to `path` really replaces: the target of a symbolic link (so the link
/// survives), else `path` itself.
fn write_target(path: &Path) -> PathBuf {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => {
            std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
        }
        _ => path.to_path_buf(),
    }
}

fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

fn temp_path(target: &Path) -> PathBuf {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "frcd-output".into());
    let n = TEMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    folder_of(target).join(format!(".{name}.{}.{n}.tmp", std::process::id()))
}

/// Checks that `path` can be written by [`write_atomic`] without running anything first: its
/// folder exists and takes a new file, and `path` is absent or a regular file (never a
/// directory, FIFO or device, which a rename would replace or a write would block on).
///
/// Call it for every output before a long run, so a typo costs nothing.
pub fn check_output_path(path: &Path) -> Result<()> {
    let target = write_target(path);
    match std::fs::metadata(&target) {
        Ok(meta) => {
            if let Some(kind) = non_regular_kind(&meta) {
                return Err(Error::NotAFile {
                    path: path.into(),
                    kind,
                });
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(Error::io(path, e)),
    }
    let folder = folder_of(&target);
    let meta = std::fs::metadata(folder).map_err(|e| Error::io(folder, e))?;
    if !meta.is_dir() {
        return Err(Error::NotAFile {
            path: folder.into(),
            kind: "not a directory",
        });
    }
    // Can a file be created there? (Permissions, read-only file systems.)
    let probe = temp_path(&target);
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .map_err(|e| Error::io(path, e))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, written, flushed
/// to disk, then renamed over `path`. On any error the temporary file is removed and `path` is
/// untouched (the previous report survives a full disk). A symbolic link at `path` is kept and
/// its target replaced. `path` must be absent or a regular file ([`Error::NotAFile`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let target = write_target(path);
    if let Ok(meta) = std::fs::metadata(&target)
        && let Some(kind) = non_regular_kind(&meta)
    {
        return Err(Error::NotAFile {
            path: path.into(),
            kind,
        });
    }
    let temp = temp_path(&target);
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&temp, &target)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&temp);
        return Err(Error::io(path, e));
    }
    Ok(())
}

/// True when `a` and `b` name the same file: the same canonical path, or (for existing files)
/// the same device and inode (hard links). A path that does not exist yet is compared by its
/// canonical folder and file name.
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b))
            && x.dev() == y.dev()
            && x.ino() == y.ino()
        {
            return true;
        }
    }
    match (canonical_target(a), canonical_target(b)) {
        (Some(x), Some(y)) => x == y,
        _ => false,
    }
}

/// The canonical path of `p`, or of its folder joined with its name when `p` does not exist.
fn canonical_target(p: &Path) -> Option<PathBuf> {
    if let Ok(c) = std::fs::canonicalize(p) {
        return Some(c);
    }
    let folder = std::fs::canonicalize(folder_of(p)).ok()?;
    Some(folder.join(p.file_name()?))
}

// The integration tests' temp-folder guard, shared with these unit tests rather than written
// out again.
#[cfg(test)]
#[path = "../tests/common/mod.rs"]
mod test_common;

#[cfg(test)]
mod tests {
    use super::*;

    use super::test_common::TempDir;

    /// A fresh folder `frcd-io-fs-<process>-<name>`, removed when the guard drops.
    fn dir(name: &str) -> TempDir {
        TempDir::new("fs", name)
    }

    #[test]
    fn non_regular_files_are_refused_without_blocking() {
        let d = dir("nonreg");
        for p in [Path::new("/dev/zero"), Path::new("/dev/urandom"), &d] {
            assert!(
                matches!(read_limited(p, 1 << 20), Err(Error::NotAFile { .. })),
                "{}",
                p.display()
            );
        }
        #[cfg(unix)]
        {
            let fifo = d.join("fifo");
            let _ = std::fs::remove_file(&fifo);
            let ok = std::process::Command::new("mkfifo")
                .arg(&fifo)
                .status()
                .is_ok_and(|s| s.success());
            if ok {
                assert!(matches!(
                    read_limited(&fifo, 1 << 20),
                    Err(Error::NotAFile { kind, .. }) if kind.contains("FIFO")
                ));
                assert!(check_output_path(&fifo).is_err());
                assert!(write_atomic(&fifo, b"x").is_err());
            }
            // A symbolic link to /dev/zero is followed and refused.
            let link = d.join("zero.stl");
            let _ = std::fs::remove_file(&link);
            std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
            assert!(matches!(
                read_limited(&link, 1 << 20),
                Err(Error::NotAFile { .. })
            ));
        }
    }

    #[test]
    fn reads_are_bounded() {
        let d = dir("bounded");
        let p = d.join("big.txt");
        std::fs::write(&p, vec![b'x'; 1000]).unwrap();
        assert_eq!(read_limited(&p, 1000).unwrap().len(), 1000);
        assert!(matches!(
            read_limited(&p, 999),
            Err(Error::TooLarge {
                size: Some(1000),
                limit: 999,
                ..
            })
        ));
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temporary() {
        let d = dir("atomic");
        let p = d.join("report.json");
        write_atomic(&p, b"first").unwrap();
        write_atomic(&p, b"second").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"second");
        let left: Vec<_> = std::fs::read_dir(&*d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .filter(|n| n.to_string_lossy().ends_with(".tmp"))
            .collect();
        assert!(left.is_empty(), "{left:?}");
        // A directory is never replaced.
        assert!(matches!(
            write_atomic(&d, b"x"),
            Err(Error::NotAFile { .. })
        ));
        // A folder that does not exist: an error, before and during the write.
        let missing = d.join("no/such/folder/r.json");
        assert!(check_output_path(&missing).is_err());
        assert!(write_atomic(&missing, b"x").is_err());
        assert!(check_output_path(&p).is_ok());
    }

    #[test]
    fn same_file_sees_through_spellings_and_hard_links() {
        let d = dir("same");
        let p = d.join("a.txt");
        std::fs::write(&p, b"a").unwrap();
        let spelled = d.join(".").join("a.txt");
        assert!(same_file(&p, &spelled));
        let hard = d.join("hard.txt");
        let _ = std::fs::remove_file(&hard);
        std::fs::hard_link(&p, &hard).unwrap();
        assert!(same_file(&p, &hard));
        assert!(!same_file(&p, &d.join("other.txt")));
        assert!(same_file(&d.join("new.txt"), &d.join("./new.txt")));
    }
}
