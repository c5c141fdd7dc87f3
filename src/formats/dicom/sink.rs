//! [`DicomSink`]: the pipeline's tiles into a DICOM series, in a staging directory beside the
//! destination renamed into place when complete (and removed if the run fails).
//!
//! Each tile comes as its frame's JPEG, encoded on the encoder threads or copied from the
//! source, and is appended to its level's staging file at once (`frames::Staged`); the sink
//! is `ordered`, so the staging files, and the instances made from them, are the same on
//! every run. `finish` writes each level's instance: the data set (`dataset`), then its
//! frames copied from the staging file in row-major order. A slide's copied levels
//! (`Spec::copied`) come in row-major order: their instances are written in place as the
//! frames come (`frames::InOrder`), the same bytes without the second copy.
//!
//! JPEG XL frames (`--codec jxl`) are staged as JPEG frames are; a source's stored JPEG tile
//! that lines up with a level-0 frame comes recompressed losslessly (`write_recompressed`),
//! and `finish` states each instance's transfer syntax from what its frames are
//! ([`instance_coding`]): JPEG XL JPEG Recompression where every frame is such a JPEG (with
//! the JPEGs' photometric interpretation, which a transcoding back to JPEG baseline keeps),
//! else the series' JPEG XL or JPEG XL Lossless, JPEG XL where the two are mixed.
//!
//! Native frames (`--codec raw`) come as the tile's samples (`Codec::Raw`: interleaved,
//! little-endian) and are written at once at their place in their level's instance, whose
//! data set is written when the sink is made (`frames::Native`); `finish` checks that every
//! frame came.

use std::fs::{self, File};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};

use super::dataset::{Part, Series};
use super::frames::{InOrder, Native, Offsets, Staged};
use super::{AssociatedSummary, DicomSummary, LevelFrames, Photometric, Spec, Transfer};
use crate::codec::Subsampling;
use crate::error::{Result, TilerError};
use crate::output::{Claim, staging};
use crate::sink::TileSink;

/// What one instance's file holds.
struct Written {
    frames: u64,
    frame_bytes: u64,
    file_bytes: u64,
    /// Whether its frames are located by the Basic Offset Table.
    basic: bool,
}

/// One level's frames as they come.
enum Frames {
    /// JPEG frames, staged as items until the instance is written.
    Encapsulated(Staged),
    /// A copied level's frames, in row-major order, written in place as items.
    InOrder(InOrder),
    /// Native frames, written in place in the instance.
    Native(Native),
}

/// A DICOM series as a pipeline sink.
pub struct DicomSink {
    dest: PathBuf,
    staging: PathBuf,
    spec: Spec,
    levels: Mutex<Vec<Option<Frames>>>,
    /// Per level, the frames copied as the source stored them (`write_stored`), or
    /// recompressed losslessly into JPEG XL (`write_recompressed`).
    stored: Vec<AtomicU64>,
    /// In a JPEG XL series, the photometric interpretation the stored JPEG tiles taken for
    /// recompression are as JPEG frames (the first one taken says; the others must match).
    recompressed_form: OnceLock<Photometric>,
    /// A slide's copied JPEG levels recompressed into JPEG XL (`copy`): tiles, JPEG bytes,
    /// JPEG XL bytes.
    recompressed: [AtomicU64; 3],
    frame_bytes: AtomicU64,
    /// Whether the series is in place; `Drop` removes the staging directory otherwise.
    done: bool,
}

impl DicomSink {
    /// Starts the series `spec` describes, to be renamed to the claimed directory.
    pub fn create(claim: &Claim, spec: Spec) -> Result<DicomSink> {
        spec.check()?;
        let dest = claim.path.clone();
        let staging = staging::partial_path(&dest);
        let levels_count = spec.level_count();
        staging::fresh_dir(&staging).map_err(|e| TilerError::write(&staging, e))?;
        let mut sink = DicomSink {
            dest,
            staging,
            spec,
            levels: Mutex::new(Vec::new()),
            stored: (0..levels_count).map(|_| AtomicU64::new(0)).collect(),
            recompressed_form: OnceLock::new(),
            recompressed: [AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0)],
            frame_bytes: AtomicU64::new(0),
            done: false,
        };
        // On failure `sink` is dropped, which removes the staging directory.
        let mut levels = Vec::with_capacity(sink.spec.level_count() as usize);
        let series = Series::new(&sink.spec)?;
        for lod in 0..sink.spec.level_count() {
            let frames = sink.spec.level(lod).tiles() as usize;
            let copied = !sink.spec.copied.is_empty();
            let level = match sink.spec.transfer.encapsulated() {
                true if copied => {
                    let part = Part { coded_here: false, ..Part::level(&sink.spec, lod) };
                    let header = series.header(&part, &Offsets::none(), 0)?;
                    let path = sink.staging.join(Spec::file_name(lod));
                    Frames::InOrder(InOrder::create(&path, &header, frames).map_err(|e| TilerError::write(&path, e))?)
                }
                true => {
                    let path = sink.staging.join(format!(".level-{lod}.frames"));
                    Frames::Encapsulated(Staged::create(&path, frames).map_err(|e| TilerError::write(&path, e))?)
                }
                false => {
                    let part = Part::level(&sink.spec, lod);
                    let path = sink.staging.join(Spec::file_name(lod));
                    Frames::Native(sink.start_native(&series, &part, &path)?)
                }
            };
            levels.push(Some(level));
        }
        drop(series);
        sink.levels = Mutex::new(levels);
        Ok(sink)
    }

    /// Writes the data set of native instance `part` at `path`, ready for its frames.
    fn start_native(&self, series: &Series, part: &Part, path: &Path) -> Result<Native> {
        let header = series.header(part, &Offsets::none(), 0)?;
        let samples = u64::from(part.photometric.samples()) * u64::from(part.bits / 8);
        let frame_len = u64::from(part.level.tile.0) * u64::from(part.level.tile.1) * samples;
        let frames = part.level.tiles() as usize;
        Native::create(path, &header, frames, frame_len, part.bits > 8).map_err(|e| TilerError::write(path, e))
    }

    /// The effort a slide's copied JPEG levels are recompressed into JPEG XL at, where the
    /// series is of such levels (JPEG XL JPEG Recompression); `None` where they are copied as
    /// they are.
    pub(crate) fn recompressing(&self) -> Option<crate::codec::JxlEffort> {
        (self.spec.transfer == Transfer::JpegXlRecompression)
            .then(|| self.spec.jxl_effort.unwrap_or(crate::codec::DEFAULT_JXL_EFFORT))
    }

    /// Stores a copied level's stored tile recompressed into JPEG XL (`jxl`, from a JPEG of
    /// `jpeg` bytes) as frame (`x`, `y`) of level `lod`, counted.
    pub(crate) fn write_recompressed_copy(&self, lod: u32, (x, y): (u32, u32), jpeg: usize, jxl: &[u8]) -> Result<()> {
        self.write_recompressed(lod, x, y, jxl)?;
        let [tiles, jpeg_bytes, jxl_bytes] = &self.recompressed;
        tiles.fetch_add(1, Ordering::Relaxed);
        jpeg_bytes.fetch_add(jpeg as u64, Ordering::Relaxed);
        jxl_bytes.fetch_add(jxl.len() as u64, Ordering::Relaxed);
        Ok(())
    }

    /// A slide's copied JPEG levels recompressed so far (none refused: a tile libjxl cannot
    /// rebuild fails the run, since no texels of it were decoded).
    pub(crate) fn recompressed(&self) -> crate::job::Recompressed {
        let [tiles, jpeg_bytes, jxl_bytes] = &self.recompressed;
        crate::job::Recompressed {
            tiles: tiles.load(Ordering::Relaxed),
            jpeg_bytes: jpeg_bytes.load(Ordering::Relaxed),
            jxl_bytes: jxl_bytes.load(Ordering::Relaxed),
            refused: 0,
        }
    }

    /// Writes every level's instance, then each associated image's, and renames the series
    /// into place.
    pub fn finish(mut self) -> Result<DicomSummary> {
        let levels = std::mem::take(self.levels.get_mut().map_err(|_| TilerError::panicked("a DICOM sink"))?);
        let series = Series::new(&self.spec)?;
        let mut summary = DicomSummary {
            instances: 0,
            frames: 0,
            photometric: self.spec.photometric.name(),
            transfer_syntax: self.spec.transfer.uid(),
            frame_coding: self.spec.transfer.describe(self.spec.stored.depth),
            series_uid: series.series_uid(),
            extended_offsets: 0,
            frame_bytes: 0,
            file_bytes: 0,
            levels: super::Levels::Pow2,
            levels_copied: !self.spec.copied.is_empty(),
            levels_declined: None,
            associated: Vec::new(),
            associated_left_out: self.spec.associated_left_out,
            level_frames: Vec::new(),
        };
        for (lod, frames) in levels.into_iter().enumerate() {
            let lod = lod as u32;
            let frames = frames.ok_or_else(|| TilerError::Internal("a DICOM sink finished twice".into()))?;
            let name = Spec::file_name(lod);
            let copied = self.stored[lod as usize].load(Ordering::Relaxed);
            let mut part = Part::level(&self.spec, lod);
            let written = match frames {
                Frames::Encapsulated(staged) => {
                    let form = self.recompressed_form.get().copied();
                    let total = self.spec.level(lod).tiles();
                    (part.transfer, part.photometric, part.coded_here) =
                        instance_coding(&self.spec, copied, total, form);
                    self.write_instance(&series, &part, staged, &name)?
                }
                Frames::Native(native) => self.finish_native(native, &name)?,
                Frames::InOrder(in_order) => self.finish_in_order(&series, lod, in_order, &name)?,
            };
            summary.level_frames.push(LevelFrames {
                transfer_syntax: part.transfer.uid(),
                photometric: part.photometric.name(),
                stored: copied,
            });
            summary.file_bytes += written.file_bytes;
            summary.instances += 1;
            summary.frames += written.frames;
            summary.frame_bytes += written.frame_bytes;
            summary.extended_offsets += u32::from(!written.basic);
        }
        for k in 0..self.spec.associated.len() {
            summary.associated.push(self.write_associated(&series, k)?);
        }
        staging::replace_dir(&self.staging, &self.dest).map_err(|e| TilerError::write(&self.dest, e))?;
        self.done = true;
        Ok(summary)
    }

    /// Writes the instance `part` of `staged` frames into the staging directory as `name`.
    fn write_instance(&self, series: &Series, part: &Part, staged: Staged, name: &str) -> Result<Written> {
        let number = part.number;
        let offsets = staged.offsets().ok_or_else(|| {
            TilerError::Internal(format!("instance {number} of the DICOM series lacks frames at the end"))
        })?;
        let basic = offsets.fit_basic();
        let frame_bytes = staged.frame_bytes();
        let header = series.header(part, &offsets, frame_bytes)?;
        let path = self.staging.join(name);
        let frames = offsets.offsets.len() as u64;
        let write = |file: &mut File| -> std::io::Result<u64> {
            use std::io::Write;
            file.write_all(&header)?;
            let n = staged.write_pixel_data(file, &offsets, basic)?;
            file.sync_all()?;
            Ok(header.len() as u64 + n)
        };
        let mut file = File::create(&path).map_err(|e| TilerError::write(&path, e))?;
        let file_bytes = write(&mut file).map_err(|e| TilerError::write(&path, e))?;
        Ok(Written { frames, frame_bytes, file_bytes, basic })
    }

    /// Ends copied level `lod`'s instance `name`, written in place: every frame copied as
    /// stored (its data set says no coding of the series' own), the Extended Offset Table
    /// where the offsets pass 32 bits.
    fn finish_in_order(&self, series: &Series, lod: u32, in_order: InOrder, name: &str) -> Result<Written> {
        let copied = self.stored[lod as usize].load(Ordering::Relaxed);
        let missing = || TilerError::Internal(format!("{name} of the DICOM series lacks copied frames at the end"));
        let offsets = in_order.offsets().filter(|_| copied == self.spec.level(lod).tiles()).ok_or_else(missing)?;
        let (frames, basic, frame_bytes) = (offsets.offsets.len() as u64, offsets.fit_basic(), in_order.frame_bytes());
        let extended = match basic {
            true => None,
            false => {
                let part = Part { coded_here: false, ..Part::level(&self.spec, lod) };
                Some(series.header(&part, offsets, frame_bytes)?)
            }
        };
        let path = self.staging.join(name);
        let file_bytes = in_order.finish(extended.as_deref()).map_err(|e| TilerError::write(&path, e))?;
        Ok(Written { frames, frame_bytes, file_bytes, basic })
    }

    /// Ends native instance `name`, naming what is missing.
    fn finish_native(&self, native: Native, name: &str) -> Result<Written> {
        let path = self.staging.join(name);
        let (frames, frame_bytes) = (native.frames(), native.frame_bytes());
        let file_bytes = native.finish().map_err(|e| match e.kind() {
            std::io::ErrorKind::Other => TilerError::Internal(format!("{name} of the DICOM series: {e}")),
            _ => TilerError::write(&path, e),
        })?;
        Ok(Written { frames, frame_bytes, file_bytes, basic: true })
    }

    /// Decodes associated image `k` of the source, encodes it as one JPEG baseline frame
    /// (YCbCr 4:2:0, or grey, at the series' quality: also in a series of copied JPEG 2000
    /// levels), or one native frame of its 8-bit samples, and writes its instance.
    fn write_associated(&self, series: &Series, k: usize) -> Result<AssociatedSummary> {
        let image = &self.spec.associated[k];
        let mut pixels = image.decode(self.spec.associated_bytes)?;
        let lossy = std::mem::take(&mut pixels.lossy);
        let name = self.spec.associated_file_name(k);
        let summary = |file, photometric: Photometric, frame_bytes| AssociatedSummary {
            kind: image.kind.name(),
            width: image.width,
            height: image.height,
            origin: image.origin(),
            file,
            photometric: photometric.name(),
            frame_bytes,
        };
        if self.spec.transfer == Transfer::Native {
            let photometric = Photometric::native(pixels.channels);
            let part = Part::associated(&self.spec, k, photometric, lossy)
                .ok_or_else(|| TilerError::Internal(format!("no associated image {k}")))?;
            let path = self.staging.join(&name);
            let mut native = self.start_native(series, &part, &path)?;
            native.put(0, &pixels.samples).map_err(|e| TilerError::write(&path, e))?;
            drop(pixels);
            let written = self.finish_native(native, &name)?;
            return Ok(summary(name, photometric, written.frame_bytes));
        }
        let photometric = Photometric::of(pixels.channels, Subsampling::S420);
        let size = (pixels.width, pixels.height);
        let jpeg = crate::codec::encode_jpeg(
            &pixels.samples,
            size,
            pixels.channels,
            self.spec.quality,
            Subsampling::S420,
            Vec::new(),
        )
        .map_err(|message| {
            TilerError::Internal(format!(
                "the {} ({}) could not be encoded: {message}",
                image.kind.name(),
                image.origin()
            ))
        })?;
        drop(pixels);
        let path = self.staging.join(format!(".{name}.frames"));
        let mut staged = Staged::create(&path, 1).map_err(|e| TilerError::write(&path, e))?;
        staged.append(0, &jpeg).map_err(|e| TilerError::write(&path, e))?;
        let part = Part::associated(&self.spec, k, photometric, lossy)
            .ok_or_else(|| TilerError::Internal(format!("no associated image {k}")))?;
        let written = self.write_instance(series, &part, staged, &name)?;
        Ok(summary(name, photometric, written.frame_bytes))
    }

    fn path(&self) -> &Path {
        &self.dest
    }
}

/// The transfer syntax, photometric interpretation and whether the series' own coding lost
/// anything, of a level's instance in the series `spec` of whose `frames` frames `stored` are
/// the source's stored JPEG tiles (copied, or in a JPEG XL series recompressed, `form` their
/// photometric interpretation as JPEG frames). JPEG baseline: the series' own JPEG coding is
/// a lossy step where a frame was coded here. JPEG XL: an instance of only recompressed JPEGs
/// is JPEG XL JPEG Recompression, stating the JPEGs' photometric interpretation (PS3.5 8.2.15:
/// that which the JPEG baseline instance rebuilt from it states); one that mixes them with
/// frames coded here is JPEG XL (a recompressed JPEG is a JPEG XL codestream, but not a
/// lossless coding of the pyramid's samples, so not JPEG XL Lossless), decoded as RGB or
/// grey; the series' own coding loses where it is lossy (`--quality`) and coded a frame.
pub(super) fn instance_coding(
    spec: &Spec,
    stored: u64,
    frames: u64,
    form: Option<Photometric>,
) -> (Transfer, Photometric, bool) {
    let coded_here = stored < frames;
    match spec.transfer {
        Transfer::JpegXl | Transfer::JpegXlLossless => match form {
            Some(form) if !coded_here => (Transfer::JpegXlRecompression, form, false),
            _ if stored > 0 => (Transfer::JpegXl, spec.photometric, coded_here && spec.transfer == Transfer::JpegXl),
            _ => (spec.transfer, spec.photometric, coded_here && spec.transfer == Transfer::JpegXl),
        },
        transfer => (transfer, spec.photometric, coded_here),
    }
}

impl Drop for DicomSink {
    /// An unfinished series leaves nothing behind.
    fn drop(&mut self) {
        if !self.done {
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}

impl TileSink for DicomSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, stored: &[u8]) -> Result<()> {
        if lod >= self.spec.level_count() {
            return Err(TilerError::Internal(format!("a frame of level {lod}, past the series' levels")));
        }
        let (columns, rows) = self.spec.level(lod).grid();
        if x >= columns || y >= rows {
            let message = format!("outside level {lod}'s {columns} x {rows} frames");
            return Err(TilerError::Encode { lod, x, y, message });
        }
        let mut levels = self.levels.lock().map_err(|_| TilerError::panicked("a DICOM sink"))?;
        let frames = levels.get_mut(lod as usize).and_then(Option::as_mut);
        let frames = frames.ok_or_else(|| TilerError::Internal(format!("a frame of level {lod} after the end")))?;
        let index = y as usize * columns as usize + x as usize;
        let put = match frames {
            Frames::Encapsulated(staged) => staged.append(index, stored),
            Frames::InOrder(in_order) => in_order.append(index, stored),
            Frames::Native(native) => native.put(index, stored),
        };
        put.map_err(|e| TilerError::write(self.path(), e))?;
        self.frame_bytes.fetch_add(stored.len() as u64, Ordering::Relaxed);
        Ok(())
    }

    /// A stored JPEG tile copied as a frame, counted: an instance of only such frames adds
    /// no lossy step of its own to the source's.
    fn write_stored(&self, lod: u32, x: u32, y: u32, jpeg: &[u8]) -> Result<()> {
        self.write_tile(lod, x, y, jpeg)?;
        if let Some(count) = self.stored.get(lod as usize) {
            count.fetch_add(1, Ordering::Relaxed);
        }
        Ok(())
    }

    /// A stored JPEG tile recompressed losslessly into JPEG XL: stored as any frame,
    /// counted with the copied ones (it adds no lossy step either).
    fn write_recompressed(&self, lod: u32, x: u32, y: u32, jxl: &[u8]) -> Result<()> {
        self.write_stored(lod, x, y, jxl)
    }

    /// A stored JPEG tile only where it is what the instance says of every frame: JPEG
    /// frames (never native ones), baseline, 8-bit, of the frame's size, grey for
    /// MONOCHROME2, else coded as the photometric interpretation names (RGB, or YCbCr at its
    /// subsampling). In a JPEG XL series (to be recompressed), one a whole-slide image may
    /// state as a JPEG frame (not YCbCr 4:4:4), of the series' samples, and of the form of
    /// the first one taken, which an instance of only such frames states.
    fn takes_stored_jpeg(&self, jpeg: &[u8]) -> bool {
        let Some(h) = crate::source::stored::read_header(jpeg) else { return false };
        let side = self.spec.layout.tile_size;
        // Process 1 (SOF0) is what the transfer syntax names; extended sequential is not.
        let whole = h.frame == 0xC0 && h.precision == 8 && (u32::from(h.width), u32::from(h.height)) == (side, side);
        if matches!(self.spec.transfer, Transfer::JpegXl | Transfer::JpegXlLossless) {
            let Ok(form) = super::copy::form(&h) else { return false };
            let grey = self.spec.photometric == Photometric::Monochrome;
            let samples = self.spec.stored.depth == crate::pixel::Depth::U8;
            return whole
                && samples
                && grey == (form == Photometric::Monochrome)
                && *self.recompressed_form.get_or_init(|| form) == form;
        }
        if self.spec.transfer != Transfer::JpegBaseline {
            return false;
        }
        let form = match self.spec.photometric {
            Photometric::Monochrome => h.components == 1,
            Photometric::Rgb => h.subsampling() == Some(Subsampling::Rgb),
            Photometric::YbrFull422 => h.subsampling() == Some(Subsampling::S420),
            Photometric::YbrFull => h.subsampling() == Some(Subsampling::S444),
            Photometric::YbrRct | Photometric::YbrIct => false,
        };
        whole && form
    }

    /// Frames in the producer's order, so that the series is the same on every run.
    fn ordered(&self) -> bool {
        true
    }

    fn bytes_written(&self) -> u64 {
        self.frame_bytes.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each level's instance states what its frames are: in a JPEG XL series, JPEG XL JPEG
    /// Recompression (with the JPEGs' photometric interpretation) only where every frame is a
    /// recompressed stored JPEG; mixed with frames coded here, JPEG XL, whose own lossy step
    /// counts only where the series is lossy. A JPEG series is JPEG baseline whatever was
    /// copied, its own step where a frame was coded here.
    #[test]
    fn an_instance_of_only_recompressed_jpegs_is_jpeg_xl_jpeg_recompression() {
        let rgb = |transfer| Spec { transfer, photometric: Photometric::Rgb, ..super::super::test_spec(1000, 700, 1) };
        let form = Some(Photometric::YbrFull422);
        let (lossy, lossless) = (rgb(Transfer::JpegXl), rgb(Transfer::JpegXlLossless));
        let recompression = (Transfer::JpegXlRecompression, Photometric::YbrFull422, false);
        assert_eq!(instance_coding(&lossy, 12, 12, form), recompression);
        assert_eq!(instance_coding(&lossless, 12, 12, form), recompression);
        assert_eq!(instance_coding(&lossy, 6, 12, form), (Transfer::JpegXl, Photometric::Rgb, true));
        assert_eq!(instance_coding(&lossless, 6, 12, form), (Transfer::JpegXl, Photometric::Rgb, false));
        assert_eq!(instance_coding(&lossy, 0, 12, None), (Transfer::JpegXl, Photometric::Rgb, true));
        assert_eq!(instance_coding(&lossless, 0, 12, None), (Transfer::JpegXlLossless, Photometric::Rgb, false));
        let jpeg = super::super::test_spec(1000, 700, 1);
        assert_eq!(instance_coding(&jpeg, 12, 12, None), (Transfer::JpegBaseline, Photometric::YbrFull422, false));
        assert_eq!(instance_coding(&jpeg, 6, 12, None), (Transfer::JpegBaseline, Photometric::YbrFull422, true));
    }
}
