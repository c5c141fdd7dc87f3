//! [`DirSink`]: one file per tile plus `info.json`, written into a staging directory beside the
//! destination and renamed into place only when everything is written, so an interrupted run
//! never leaves a directory that looks like a finished pyramid.

use std::collections::HashSet;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use super::TileSink;
use crate::error::{Result, TilerError};
use crate::output::{Claim, Product, staging};
use crate::tile_dir::filename::FilenameFormat;
use crate::tile_dir::info::Info;

/// One image file per tile plus `info.json`.
pub struct DirSink {
    dest: PathBuf,
    staging: PathBuf,
    names: FilenameFormat,
    made_dirs: Mutex<HashSet<PathBuf>>,
    bytes: AtomicU64,
}

impl DirSink {
    /// Prepares to write into the destination `claim` checked (see [`crate::output::claim`]): absent,
    /// empty, or a previous output of ours, which `finish` replaces.
    pub fn create(claim: &Claim, names: FilenameFormat) -> Result<DirSink> {
        if claim.product != Product::TileDir {
            return Err(TilerError::Options(format!(
                "{} was claimed for {}",
                claim.path.display(),
                claim.product.noun()
            )));
        }
        let dest = claim.path.as_path();
        let staging = staging::partial_path(dest);
        if staging.exists() {
            fs::remove_dir_all(&staging).map_err(|e| TilerError::write(&staging, e))?;
        }
        fs::create_dir_all(&staging).map_err(|e| {
            TilerError::write(dest, std::io::Error::new(e.kind(), format!("cannot create {}: {e}", staging.display())))
        })?;
        Ok(DirSink {
            dest: dest.to_path_buf(),
            staging,
            names,
            made_dirs: Mutex::new(HashSet::new()),
            bytes: AtomicU64::new(0),
        })
    }

    /// Writes `info.json` last, then moves the staging directory into place. A previous output
    /// at the destination is moved aside first and deleted only after the new one is in place.
    pub fn finish(self, info: &Info) -> Result<()> {
        let json = self.staging.join("info.json");
        if let Err(e) = fs::write(&json, info.to_json_pretty()) {
            let _ = fs::remove_dir_all(&self.staging);
            return Err(TilerError::write(&json, e));
        }
        staging::replace_dir(&self.staging, &self.dest).map_err(|e| TilerError::write(&self.dest, e))
    }

    /// Removes the staging directory after a failure.
    pub fn abandon(self) {
        let _ = fs::remove_dir_all(&self.staging);
    }

    pub fn staging_dir(&self) -> &Path {
        &self.staging
    }
}

impl TileSink for DirSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let path = self.staging.join(self.names.format(&[lod, x, y]));
        if let Some(dir) = path.parent().filter(|d| *d != self.staging) {
            let mut made = self.made_dirs.lock().unwrap_or_else(|p| p.into_inner());
            if !made.contains(dir) {
                fs::create_dir_all(dir).map_err(|e| TilerError::write(dir, e))?;
                made.insert(dir.to_path_buf());
            }
        }
        let mut file = fs::File::create_new(&path).map_err(|e| match e.kind() {
            std::io::ErrorKind::AlreadyExists => TilerError::Options(format!(
                "tile (lod {lod}, x {x}, y {y}) would overwrite {}: the filename format '{}' gives two tiles one name; pad the numbers or separate them",
                self.names.format(&[lod, x, y]),
                self.names.as_str()
            )),
            _ => TilerError::write(&path, e),
        })?;
        file.write_all(bytes).map_err(|e| TilerError::write(&path, e))?;
        self.bytes.fetch_add(bytes.len() as u64, Ordering::Relaxed);
        Ok(())
    }

    fn bytes_written(&self) -> u64 {
        self.bytes.load(Ordering::Relaxed)
    }
}
