//! [`TiffSink`]: the pipeline's tiles into a [`TiffWriter`], under a temporary name beside
//! the destination, renamed into place when complete and removed if the run fails.
//!
//! JPEG tiles come encoded and are stored as they are; the others come as raw samples and
//! are compressed here, on the encoder thread that calls, before the writer's lock. Tiles
//! are stored in the order they arrive (`ordered` is false, so compression runs on every
//! encoder thread): the tile data's order in the file varies from run to run, what each
//! level holds does not.

use std::fs::{self, File};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use super::{Spec, TiffSummary, TiffWriter, compress};
use crate::error::{Result, TilerError};
use crate::output::staging;
use crate::sink::TileSink;

/// A pyramidal TIFF as a pipeline sink.
pub struct TiffSink {
    dest: PathBuf,
    tmp: PathBuf,
    spec: Spec,
    writer: Mutex<Option<TiffWriter>>,
    tile_bytes: AtomicU64,
    /// Whether the file is in place; `Drop` removes the temporary otherwise.
    done: bool,
}

impl TiffSink {
    /// Starts the TIFF `spec` describes, to be renamed to `dest` (claimed by the caller).
    pub fn create(dest: &Path, spec: Spec) -> Result<TiffSink> {
        spec.check()?;
        let tmp = staging::partial_path(dest);
        let file = File::create(&tmp).map_err(|e| TilerError::write(&tmp, e))?;
        let mut sink = TiffSink {
            dest: dest.to_path_buf(),
            tmp,
            spec: spec.clone(),
            writer: Mutex::new(None),
            tile_bytes: AtomicU64::new(0),
            done: false,
        };
        // On failure `sink` is dropped, which removes the temporary.
        let writer = TiffWriter::create(&sink.tmp, file, spec)?;
        sink.writer = Mutex::new(Some(writer));
        Ok(sink)
    }

    /// Writes the IFDs and renames the file into place.
    pub fn finish(mut self) -> Result<TiffSummary> {
        let writer = self.writer.get_mut().map_err(|_| TilerError::panicked("a TIFF writer"))?.take();
        let writer = writer.ok_or_else(|| TilerError::Internal("a TIFF sink finished twice".into()))?;
        let summary = writer.finish()?;
        fs::rename(&self.tmp, &self.dest).map_err(|e| TilerError::write(&self.dest, e))?;
        self.done = true;
        if let Some(dir) = self.dest.parent().filter(|d| !d.as_os_str().is_empty()) {
            // Make the rename durable; not every file system syncs a directory.
            let _ = File::open(dir).and_then(|d| d.sync_all());
        }
        Ok(summary)
    }
}

impl Drop for TiffSink {
    /// An unfinished TIFF leaves nothing behind.
    fn drop(&mut self) {
        if !self.done {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

impl TileSink for TiffSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let compressed;
        let stored = if self.spec.compression.takes_encoded() {
            bytes
        } else {
            compressed = compress::tile(&self.spec, bytes, (lod, x, y))?;
            &compressed[..]
        };
        let mut writer = self.writer.lock().map_err(|_| TilerError::panicked("a TIFF writer"))?;
        let writer =
            writer.as_mut().ok_or_else(|| TilerError::Internal("a tile after the TIFF was finished".into()))?;
        writer.add_tile(lod, x, y, stored)?;
        self.tile_bytes.fetch_add(stored.len() as u64, Ordering::Relaxed);
        Ok(())
    }

    fn bytes_written(&self) -> u64 {
        self.tile_bytes.load(Ordering::Relaxed)
    }
}
