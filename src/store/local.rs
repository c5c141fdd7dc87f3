//! [`StagingDir`]: a directory output's files on local disk, written into a staging directory
//! beside the destination and renamed into place only when complete
//! ([`crate::output::replace_dir`]), so an interrupted run never leaves a directory that looks
//! like a finished pyramid.

use std::collections::HashSet;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use super::Files;
use crate::error::{Result, ShowPath, TilerError};
use crate::output::staging;

/// The staging directory of one local directory output. Dropped unpublished, it is removed.
pub(crate) struct StagingDir {
    dest: PathBuf,
    staging: PathBuf,
    made_dirs: Mutex<HashSet<PathBuf>>,
    /// Set once the directory is in place: nothing to remove.
    published: bool,
    /// A resumable run's staging: left when dropped unpublished, for a later `--resume`.
    keep: bool,
}

impl StagingDir {
    /// An empty staging directory for the destination `dest` (claimed by the caller).
    pub(crate) fn create(dest: &Path) -> Result<StagingDir> {
        let staging = staging::partial_path(dest);
        if staging.exists() {
            fs::remove_dir_all(&staging).map_err(|e| TilerError::write(&staging, e))?;
        }
        fs::create_dir_all(&staging).map_err(|e| {
            TilerError::write(dest, std::io::Error::new(e.kind(), format!("cannot create {}: {e}", staging.shown())))
        })?;
        Ok(StagingDir {
            dest: dest.to_path_buf(),
            staging,
            made_dirs: Mutex::new(HashSet::new()),
            published: false,
            keep: false,
        })
    }

    /// The staging directory of a resumable run (`--resume`, [`crate::resume`]): what is
    /// there already (an interrupted run's tiles, taken over) stays, and so does the directory
    /// when dropped unpublished.
    pub(crate) fn resumable(dest: &Path) -> Result<StagingDir> {
        let staging = staging::partial_path(dest);
        fs::create_dir_all(&staging).map_err(|e| {
            TilerError::write(dest, std::io::Error::new(e.kind(), format!("cannot create {}: {e}", staging.shown())))
        })?;
        let made_dirs = Mutex::new(HashSet::new());
        Ok(StagingDir { dest: dest.to_path_buf(), staging, made_dirs, published: false, keep: true })
    }
}

impl Files for StagingDir {
    fn put_new(&self, name: &str, bytes: &[u8]) -> Result<bool> {
        let path = self.staging.join(name);
        if let Some(dir) = path.parent().filter(|d| *d != self.staging) {
            let mut made = self.made_dirs.lock().unwrap_or_else(|p| p.into_inner());
            if !made.contains(dir) {
                fs::create_dir_all(dir).map_err(|e| TilerError::write(dir, e))?;
                made.insert(dir.to_path_buf());
            }
        }
        let mut file = match fs::File::create_new(&path) {
            Ok(file) => file,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => return Ok(false),
            Err(e) => return Err(TilerError::write(&path, e)),
        };
        file.write_all(bytes).map_err(|e| TilerError::write(&path, e))?;
        Ok(true)
    }

    fn read(&self, name: &str) -> Result<Vec<u8>> {
        let path = self.staging.join(name);
        fs::read(&path).map_err(|e| TilerError::io(&path, e))
    }

    fn publish(&mut self, manifests: Vec<(String, Vec<u8>)>) -> Result<()> {
        for (name, bytes) in manifests {
            let path = self.staging.join(name);
            // IIIF's whole-image files go into folders of their own (`full/max/0/`).
            let folder = path.parent().map_or(Ok(()), fs::create_dir_all);
            folder.and_then(|()| fs::write(&path, bytes)).map_err(|e| TilerError::write(&path, e))?;
        }
        staging::replace_dir(&self.staging, &self.dest).map_err(|e| TilerError::write(&self.dest, e))?;
        self.published = true;
        Ok(())
    }
}

/// An unpublished directory's staging goes with it.
impl Drop for StagingDir {
    fn drop(&mut self) {
        if !self.published && !self.keep {
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}
