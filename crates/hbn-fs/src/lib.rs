//! # hbn-fs — the one atomic writer of hbn
//!
//! Every file hbn writes (model files, estimates as CSV or MCAP, plots, experiment rows) goes
//! through [`write_atomic_with`]: the content is written to a temporary file in the target's
//! directory, flushed and fsynced, renamed over the target, and the directory is fsynced so the
//! rename survives a power cut. A failure at any point leaves the target untouched and no
//! temporary file behind. Outputs get ordinary permissions (0644 on Unix), not the owner-only
//! mode of temporary files.
//!
//! Two kinds of target are not renamed over: an existing target that is not a regular file
//! (`/dev/stdout`, `/dev/null`, a pipe) is written in place, since renaming would replace the
//! device node or pipe itself; and a symbolic link is followed, so the file it points to is
//! replaced atomically and the link stays.
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// A failed atomic write: which file, which operation, the OS error.
#[derive(Debug, thiserror::Error)]
#[error("cannot {op} `{}`: {source}", path.display())]
pub struct WriteError {
    /// The target file.
    pub path: PathBuf,
    /// What was being done: `create a temporary file for`, `write`, `sync`, `rename onto`.
    pub op: &'static str,
    /// The OS error (or the content writer's error).
    #[source]
    pub source: std::io::Error,
}

/// The directory a file is written in (`.` for a bare file name).
pub fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Writes `bytes` to `path` atomically (see the crate documentation).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_atomic_with(path, |w| {
        w.write_all(bytes).map_err(|source| WriteError {
            path: path.to_owned(),
            op: "write",
            source,
        })
    })
}

/// Writes the content `fill` produces to `path` atomically: `fill` writes into a buffered
/// temporary file next to `path` (seekable, for formats such as MCAP that patch their
/// header); on success the file is fsynced, renamed over `path` and the directory fsynced. If
/// `fill` fails, its error is returned and nothing changes. `E` is the caller's error type.
pub fn write_atomic_with<E, F>(path: &Path, fill: F) -> Result<(), E>
where
    E: From<WriteError>,
    F: FnOnce(&mut BufWriter<File>) -> Result<(), E>,
{
    let err = |op, source| WriteError {
        path: path.to_owned(),
        op,
        source,
    };
    // A symbolic link: replace the file it points to, keep the link.
    let resolved;
    let path = match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => match std::fs::canonicalize(path) {
            Ok(p) => {
                resolved = p;
                resolved.as_path()
            }
            Err(_) => path,
        },
        _ => path,
    };
    // A device or pipe: write in place (no temporary file, no rename).
    if let Ok(m) = std::fs::metadata(path)
        && !m.is_file()
        && !m.is_dir()
    {
        let handle = std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| err("open", e))?;
        let mut w = BufWriter::new(handle);
        fill(&mut w)?;
        w.flush().map_err(|e| err("write", e))?;
        return Ok(());
    }
    let err = |op, source| WriteError {
        path: path.to_owned(),
        op,
        source,
    };
    let dir = parent_dir(path);
    let mut builder = tempfile::Builder::new();
    builder.prefix(".hbn-tmp-");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let tmp = builder
        .tempfile_in(dir)
        .map_err(|e| err("create a temporary file for", e))?;
    let (handle, tmp_path) = tmp.into_parts();
    let mut w = BufWriter::new(handle);
    // On error `tmp_path` is dropped here, which deletes the temporary file.
    fill(&mut w)?;
    let handle = w.into_inner().map_err(|e| err("write", e.into_error()))?;
    handle.sync_all().map_err(|e| err("sync", e))?;
    drop(handle);
    tmp_path
        .persist(path)
        .map_err(|e| err("rename the temporary file onto", e.error))?;
    // Make the rename durable where the platform allows opening directories (not on Windows).
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(".hbn-tmp-"))
            .collect()
    }

    #[test]
    fn replaces_the_target_and_leaves_no_temporary_file() {
        let d = tempfile::tempdir().unwrap();
        let f = d.path().join("out.txt");
        write_atomic(&f, b"one").unwrap();
        write_atomic(&f, b"two").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"two");
        assert!(leftovers(d.path()).is_empty());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&f).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, 0o644);
        }
    }

    #[cfg(unix)]
    #[test]
    fn devices_are_written_in_place_not_replaced() {
        use std::os::unix::fs::FileTypeExt;
        // /dev/null takes anything and stays a device.
        write_atomic(Path::new("/dev/null"), b"gone").unwrap();
        assert!(
            std::fs::metadata("/dev/null")
                .unwrap()
                .file_type()
                .is_char_device()
        );
        // /dev/full fails with "no space" and stays a device.
        if Path::new("/dev/full").exists() {
            let e = write_atomic(Path::new("/dev/full"), &[0u8; 1 << 16]).unwrap_err();
            assert_eq!(e.path, Path::new("/dev/full"));
            assert_eq!(e.source.raw_os_error(), Some(28), "{e}"); // ENOSPC
            assert!(e.to_string().contains("/dev/full"), "{e}");
            assert!(
                std::fs::metadata("/dev/full")
                    .unwrap()
                    .file_type()
                    .is_char_device()
            );
        }
    }

    #[cfg(unix)]
    #[test]
    fn a_symbolic_link_keeps_pointing_at_the_replaced_file() {
        let d = tempfile::tempdir().unwrap();
        let target = d.path().join("real.txt");
        let link = d.path().join("link.txt");
        write_atomic(&target, b"old").unwrap();
        std::os::unix::fs::symlink(&target, &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        assert!(leftovers(d.path()).is_empty());
    }

    #[test]
    fn a_failing_writer_keeps_the_old_content() {
        let d = tempfile::tempdir().unwrap();
        let f = d.path().join("out.txt");
        write_atomic(&f, b"old").unwrap();
        let e = write_atomic_with(&f, |w| {
            w.write_all(b"partial").unwrap();
            Err(WriteError {
                path: f.clone(),
                op: "write",
                source: std::io::Error::other("renderer failed"),
            })
        })
        .unwrap_err();
        assert_eq!(e.op, "write");
        assert!(e.to_string().contains("out.txt"), "{e}");
        assert_eq!(std::fs::read(&f).unwrap(), b"old");
        assert!(leftovers(d.path()).is_empty());
    }

    #[test]
    fn a_missing_directory_is_an_error_naming_the_file() {
        let d = tempfile::tempdir().unwrap();
        let f = d.path().join("no/such/dir/out.txt");
        let e = write_atomic(&f, b"x").unwrap_err();
        assert_eq!(e.source.kind(), std::io::ErrorKind::NotFound);
        assert!(e.to_string().contains("out.txt"), "{e}");
    }
}
