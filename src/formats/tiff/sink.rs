//! [`TiffSink`]: the pipeline's tiles into a [`TiffWriter`], under a temporary name beside
//! the destination, renamed into place when complete and removed if the run fails.
//!
//! Every tile comes as the file stores it, compressed on the encoder threads by the codec
//! [`Spec::codec`] names (or JPEG). The sink is `ordered`: tiles arrive from the encoders'
//! writer thread in the producer's order, the same on every run, so the file's bytes are
//! too; the writer appends them as they come and keeps only their offsets and lengths.

use std::fs::{self, File};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use super::{AssociatedSummary, Compression, Spec, TiffSummary, TiffWriter};
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

    /// Writes the source's associated images (decoded now, one at a time), the IFDs, and
    /// renames the file into place.
    pub fn finish(mut self) -> Result<TiffSummary> {
        let writer = self.writer.get_mut().map_err(|_| TilerError::panicked("a TIFF writer"))?.take();
        let mut writer = writer.ok_or_else(|| TilerError::Internal("a TIFF sink finished twice".into()))?;
        let mut associated = Vec::with_capacity(self.spec.associated.len());
        for (k, image) in self.spec.associated.iter().enumerate() {
            let pixels = image.decode(self.spec.associated_bytes)?;
            let (width, height) = (pixels.width, pixels.height);
            let bytes = writer.add_associated(image.kind, pixels)?;
            let page = self.spec.level_count() as usize + k;
            associated.push(AssociatedSummary {
                kind: image.kind.name(),
                width,
                height,
                origin: image.origin(),
                page,
                bytes,
            });
        }
        let mut summary = writer.finish()?;
        summary.associated = associated;
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

impl TiffSink {
    /// The sink of plane `c`'s pass, for an OME-TIFF of channels written one pass each
    /// (`Spec::planar`).
    pub fn plane(&self, c: u32) -> PlaneSink<'_> {
        PlaneSink { sink: self, c }
    }

    /// Stores tile `(x, y)` of level `lod` of plane `c`.
    fn write_plane(&self, c: u32, lod: u32, x: u32, y: u32, stored: &[u8]) -> Result<()> {
        if self.spec.compression == Compression::None && stored.len() as u64 != self.spec.raw_tile_bytes() {
            let s = &self.spec;
            let message = format!(
                "{} bytes where a {}-pixel {} tile has {}",
                stored.len(),
                s.layout.tile_size,
                s.stored,
                s.raw_tile_bytes()
            );
            return Err(TilerError::Encode { lod, x, y, message });
        }
        let mut writer = self.writer.lock().map_err(|_| TilerError::panicked("a TIFF writer"))?;
        let writer =
            writer.as_mut().ok_or_else(|| TilerError::Internal("a tile after the TIFF was finished".into()))?;
        writer.add_plane_tile(c, lod, x, y, stored)?;
        self.tile_bytes.fetch_add(stored.len() as u64, Ordering::Relaxed);
        Ok(())
    }
}

/// One channel's pass into a [`TiffSink`] of planes: its tiles are the plane's.
pub(crate) struct PlaneSink<'a> {
    sink: &'a TiffSink,
    c: u32,
}

impl TileSink for PlaneSink<'_> {
    fn write_tile(&self, lod: u32, x: u32, y: u32, stored: &[u8]) -> Result<()> {
        self.sink.write_plane(self.c, lod, x, y, stored)
    }

    /// A stored JPEG tile as the file's own sink takes it (a plane is grey, as a grey file).
    fn takes_stored_jpeg(&self, jpeg: &[u8]) -> bool {
        self.sink.takes_stored_jpeg(jpeg)
    }

    /// Tiles in the producer's order, so that the file is the same on every run.
    fn ordered(&self) -> bool {
        true
    }

    fn bytes_written(&self) -> u64 {
        self.sink.bytes_written()
    }
}

impl TileSink for TiffSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, stored: &[u8]) -> Result<()> {
        self.write_plane(0, lod, x, y, stored)
    }

    /// A stored JPEG tile only where it is what the level's tags say of every tile: of the
    /// tile's size, and of the form a copied level's tiles have (`copy::fits`: 8-bit
    /// sequential, grey for a grey file, else coded as `Photometric` and `YCbCrSubsampling`
    /// say; a TIFF of the source's RGB tiles is RGB).
    /// In a JPEG XL file, a stored tile of its size and of its grey or colour is taken, to be
    /// recompressed losslessly (it decodes to what `Photometric` says whatever its coding).
    fn takes_stored_jpeg(&self, jpeg: &[u8]) -> bool {
        let Some(h) = crate::source::stored::read_header(jpeg) else { return false };
        let side = self.spec.layout.tile_size;
        let grey = self.spec.photometric() == 1;
        let sized = (u32::from(h.width), u32::from(h.height)) == (side, side);
        match self.spec.compression {
            Compression::Jpeg { subsampling } => sized && super::fits(&h, (!grey).then_some(subsampling)),
            Compression::Jxl => sized && h.components == if grey { 1 } else { 3 },
            _ => false,
        }
    }

    /// Tiles in the producer's order, so that the file is the same on every run.
    fn ordered(&self) -> bool {
        true
    }

    fn bytes_written(&self) -> u64 {
        self.tile_bytes.load(Ordering::Relaxed)
    }
}
