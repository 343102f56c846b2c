//! # hbn-fs — the one atomic writer of hbn
//!
//! Every file hbn writes (model files, estimates as CSV or MCAP, plots, experiment rows) goes
//! through [`write_atomic_with`]: the content is written to a temporary file in the target's
//! directory, flushed and fsynced, renamed over the target, and the directory is fsynced so the
//! rename survives a power cut. A failure at any point leaves the target untouched and no
//! temporary file behind. Outputs get ordinary permissions (0644 on Unix), not the owner-only
//! mode of temporary files.
//!
//! On Linux the temporary file has no name while it is written (`O_TMPFILE`): a process killed
//! then (SIGKILL, a power cut) leaves nothing in the directory. It is given a temporary name
//! only after its content is synced, just before the rename; only a kill between those two
//! system calls can leave a `.hbn-tmp-*` file. Where the file system has no `O_TMPFILE`, the
//! temporary file is named from the start.
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
    // An unnamed file where the platform has them, else a named temporary file.
    let (handle, named) = match unnamed_in(dir) {
        Some(handle) => (handle, None),
        None => {
            let tmp = builder
                .tempfile_in(dir)
                .map_err(|e| err("create a temporary file for", e))?;
            let (handle, tmp_path) = tmp.into_parts();
            (handle, Some(tmp_path))
        }
    };
    let mut w = BufWriter::new(handle);
    // On error the temporary file is dropped here: deleted if named, gone if unnamed.
    fill(&mut w)?;
    let mut handle = w.into_inner().map_err(|e| err("write", e.into_error()))?;
    handle.sync_all().map_err(|e| err("sync", e))?;
    let tmp_path = match named {
        Some(tmp_path) => tmp_path,
        None => name_unnamed(&builder, dir, &mut handle)
            .map_err(|e| err("create a temporary file for", e))?,
    };
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

/// A new unnamed regular file in `dir` (Linux `O_TMPFILE`), readable and writable, mode 0644;
/// `None` where the platform or file system has none (the caller names one instead).
#[cfg(target_os = "linux")]
fn unnamed_in(dir: &Path) -> Option<File> {
    use rustix::fs::{CWD, Mode, OFlags};
    let mode = Mode::from_raw_mode(0o644);
    let fd = rustix::fs::openat(
        CWD,
        dir,
        OFlags::TMPFILE | OFlags::RDWR | OFlags::CLOEXEC,
        mode,
    )
    .ok()?;
    // The umask applied to the open: outputs get 0644 like any file hbn writes.
    rustix::fs::fchmod(&fd, mode).ok()?;
    Some(File::from(fd))
}

#[cfg(not(target_os = "linux"))]
fn unnamed_in(_dir: &Path) -> Option<File> {
    None
}

/// Gives the unnamed file `handle` a temporary name in `dir` (a hard link), to be renamed onto
/// the target. If no link can be made (no `/proc`, no capability), copies the content into a
/// named temporary file instead.
fn name_unnamed(
    builder: &tempfile::Builder<'_, '_>,
    dir: &Path,
    handle: &mut File,
) -> std::io::Result<tempfile::TempPath> {
    #[cfg(target_os = "linux")]
    {
        use rustix::fs::{AtFlags, CWD};
        use std::os::fd::AsRawFd;
        let proc_path = format!("/proc/self/fd/{}", handle.as_raw_fd());
        let linked = builder.make_in(dir, |p| {
            // By descriptor (needs CAP_DAC_READ_SEARCH), else through /proc.
            rustix::fs::linkat(&*handle, "", CWD, p, AtFlags::EMPTY_PATH)
                .or_else(|_| {
                    rustix::fs::linkat(CWD, proc_path.as_str(), CWD, p, AtFlags::SYMLINK_FOLLOW)
                })
                .map_err(std::io::Error::from)
        });
        if let Ok(named) = linked {
            return Ok(named.into_temp_path());
        }
    }
    use std::io::{Seek, SeekFrom};
    let tmp = builder.tempfile_in(dir)?;
    let (mut copy, tmp_path) = tmp.into_parts();
    handle.seek(SeekFrom::Start(0))?;
    std::io::copy(handle, &mut copy)?;
    copy.sync_all()?;
    Ok(tmp_path)
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

    /// On Linux, while the content is written the directory holds no new name, so a kill at
    /// that moment leaves nothing behind (`O_TMPFILE`; this machine's /tmp has it).
    #[cfg(target_os = "linux")]
    #[test]
    fn nothing_is_named_while_the_content_is_written() {
        let d = tempfile::tempdir().unwrap();
        let f = d.path().join("out.bin");
        let names = |dir: &Path| -> Vec<String> {
            let mut v: Vec<String> = std::fs::read_dir(dir)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        };
        for round in 0..2 {
            write_atomic_with::<WriteError, _>(&f, |w| {
                w.write_all(&vec![round as u8; 1 << 20]).unwrap();
                w.flush().unwrap();
                let seen = names(d.path());
                let expect: &[&str] = if round == 0 { &[] } else { &["out.bin"] };
                assert_eq!(seen, expect, "a name exists while writing");
                Ok(())
            })
            .unwrap();
            assert_eq!(names(d.path()), ["out.bin"]);
            assert_eq!(std::fs::read(&f).unwrap(), vec![round as u8; 1 << 20]);
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&f).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, 0o644);
        }
    }

    /// Naming an unnamed file keeps its content; a directory that does not exist is an error
    /// (the link and the copy fallback both fail), not a panic.
    #[test]
    fn naming_an_unnamed_file_keeps_its_content() {
        use std::io::Seek;
        let d = tempfile::tempdir().unwrap();
        let mut handle = tempfile::tempfile_in(d.path()).unwrap();
        handle.write_all(b"content").unwrap();
        handle.seek(std::io::SeekFrom::End(0)).unwrap();
        let mut b = tempfile::Builder::new();
        b.prefix(".hbn-tmp-");
        assert!(name_unnamed(&b, &d.path().join("missing"), &mut handle).is_err());
        let named = name_unnamed(&b, d.path(), &mut handle).unwrap();
        assert_eq!(std::fs::read(&named).unwrap(), b"content");
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
