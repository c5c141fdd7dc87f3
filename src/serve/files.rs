//! Opening the files of a served directory: only regular files whose canonical path lies under
//! the directory, opened without ever blocking, so a link out of the directory exposes
//! nothing and a FIFO or device in it wedges no thread.
//!
//! The check is made on the open handle, not on the name: the file is opened non-blocking (a
//! FIFO opens at once instead of waiting for a writer) and its type read from the handle, so a
//! name swapped for a FIFO between a look and the open is still refused.

use crate::error::ShowPath;
use std::fs::{File, Metadata};
use std::io::{self, Read};
use std::path::Path;

/// Why a file under a served directory is not served.
#[derive(Debug)]
pub enum Refused {
    /// No such file (or no such directory on the way): a 404.
    Missing,
    /// There is something, but not a file this server reads; the reason names the path.
    Refused(String),
}

/// `path` opened for reading, with its metadata, if its canonical path lies under `root`
/// (canonical) and it is a regular file.
pub fn open_under(root: &Path, path: &Path) -> Result<(File, Metadata), Refused> {
    let canonical = std::fs::canonicalize(path).map_err(|e| missing_or(path, e))?;
    if !canonical.starts_with(root) {
        return Err(Refused::Refused(format!("{} leads out of {}", path.shown(), root.shown())));
    }
    let file = open_nonblocking(&canonical).map_err(|e| missing_or(path, e))?;
    let meta = file.metadata().map_err(|e| Refused::Refused(format!("{}: {e}", path.shown())))?;
    if !meta.is_file() {
        return Err(Refused::Refused(format!("{} is not a regular file", path.shown())));
    }
    Ok((file, meta))
}

/// The whole of `path` (see [`open_under`]) if it is at most `max` bytes; the bytes read are
/// bounded too, so a file that grows after the check cannot make the read unbounded.
pub fn read_under(root: &Path, path: &Path, max: u64) -> Result<Vec<u8>, Refused> {
    let (file, meta) = open_under(root, path)?;
    let too_large = || Refused::Refused(format!("{} is over {max} bytes", path.shown()));
    if meta.len() > max {
        return Err(too_large());
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(max + 1).read_to_end(&mut bytes).map_err(|e| Refused::Refused(format!("{}: {e}", path.shown())))?;
    if bytes.len() as u64 > max {
        return Err(too_large());
    }
    Ok(bytes)
}

fn missing_or(path: &Path, e: io::Error) -> Refused {
    match e.kind() {
        io::ErrorKind::NotFound | io::ErrorKind::NotADirectory => Refused::Missing,
        _ => Refused::Refused(format!("{}: {e}", path.shown())),
    }
}

#[cfg(unix)]
fn open_nonblocking(path: &Path) -> io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    // O_NONBLOCK only matters to the open of a FIFO or device (refused right after); reads of
    // a regular file ignore it.
    std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NONBLOCK).open(path)
}

#[cfg(not(unix))]
fn open_nonblocking(path: &Path) -> io::Result<File> {
    File::open(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_out_fifos_and_large_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let outside = tempfile::tempdir().unwrap();
        let root = std::fs::canonicalize(dir.path()).unwrap();
        std::fs::write(root.join("a.png"), "tile").unwrap();
        std::fs::write(outside.path().join("secret"), "secret").unwrap();
        assert_eq!(read_under(&root, &root.join("a.png"), 4).unwrap(), b"tile");
        assert!(matches!(read_under(&root, &root.join("a.png"), 3), Err(Refused::Refused(m)) if m.contains("over 3")));
        assert!(matches!(open_under(&root, &root.join("none.png")), Err(Refused::Missing)));
        assert!(matches!(open_under(&root, &root.join("a.png/x")), Err(Refused::Missing)));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(outside.path().join("secret"), root.join("out.png")).unwrap();
            assert!(
                matches!(open_under(&root, &root.join("out.png")), Err(Refused::Refused(m)) if m.contains("leads out"))
            );
            let fifo = root.join("fifo.png");
            assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
            // Returns at once (a blocking open would wait for a writer for ever).
            assert!(matches!(open_under(&root, &fifo), Err(Refused::Refused(m)) if m.contains("not a regular file")));
        }
    }
}
