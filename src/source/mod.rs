//! Image sources that deliver an image top to bottom, one row at a time.
//!
//! Streaming sources (PNG, TIFF, baseline JPEG, PPM/PGM) hold only what their decoder needs for
//! the current row, strip or tile row, so memory does not grow with the image height. Formats
//! that cannot be streamed are decoded whole through the `image` crate, but only under
//! `--max-memory`.
//!
//! [`tiled`] holds the other kind of input, for `convert`: grids of tiles (named files, a
//! tile directory this tool wrote, a pack, Deep Zoom, IIIF, z/y/x or z/x/y, in a directory or
//! a zip archive) read a row of tiles at a time.

/// The row-order methods of a [`RowSource`] that wraps another in its field `inner` and changes
/// what its rows hold but not which rows come (ICC conversion, widened or mapped samples, picked
/// channels): rewinding, skipping and narrowing go straight to the wrapped source, and the
/// decoder's buffers and decoding time are the wrapped source's (`forward_row_order_to_inner!(field)`: plus the
/// bytes the wrapper's `u64` field says it holds).
macro_rules! forward_row_order_to_inner {
    (@order) => {
        fn rewind(&mut self) -> $crate::error::Result<()> {
            self.inner.rewind()
        }

        fn skip_rows(&mut self, rows: u32) -> $crate::error::Result<()> {
            self.inner.skip_rows(rows)
        }

        fn read_columns(&mut self, columns: std::ops::Range<u32>) -> bool {
            self.inner.read_columns(columns)
        }
    };
    () => {
        forward_row_order_to_inner!(@order);

        fn buffer_bytes(&self) -> u64 {
            self.inner.buffer_bytes()
        }

        fn most_buffer_bytes(&self) -> u64 {
            self.inner.most_buffer_bytes()
        }

        fn decoding(&self) -> $crate::source::Decoding {
            self.inner.decoding()
        }
    };
    ($held:ident) => {
        forward_row_order_to_inner!(@order);

        fn buffer_bytes(&self) -> u64 {
            self.inner.buffer_bytes() + self.$held
        }

        fn most_buffer_bytes(&self) -> u64 {
            self.inner.most_buffer_bytes() + self.$held
        }

        fn decoding(&self) -> $crate::source::Decoding {
            self.inner.decoding()
        }
    };
}

/// The row methods of a [`RowSource`] whose rows come from a grid of whole-decoded tiles
/// (`tile_rows::TileRows`) in its field `rows`, the file named by its field `path`:
/// `rows_of_tile_rows!(decode)` reads each row through `self.decode(index, w, h, texels)`,
/// which decodes tile `index` (row-major) into `texels`, its `w x h` texels inside the image.
macro_rules! rows_of_tile_rows {
    ($decode:ident) => {
        fn read_row(&mut self, out: &mut [u8]) -> $crate::error::Result<()> {
            // Taken out while it reads, so that the decoding may borrow `self`.
            let mut rows = std::mem::take(&mut self.rows);
            let read = rows.read_row(&self.path, out, |index, w, h, texels| self.$decode(index, w, h, texels));
            self.rows = rows;
            read
        }

        fn buffer_bytes(&self) -> u64 {
            self.rows.buffer_bytes()
        }

        fn most_buffer_bytes(&self) -> u64 {
            self.rows.most_buffer_bytes()
        }

        fn skip_rows(&mut self, rows: u32) -> $crate::error::Result<()> {
            self.rows.skip(rows);
            Ok(())
        }

        fn rewind(&mut self) -> $crate::error::Result<()> {
            self.rows.rewind();
            Ok(())
        }
    };
}

pub mod associated;
pub mod channels;
pub(crate) mod dicom;
pub(crate) mod halved;
pub mod icc;
mod jpeg;
mod libjpeg;
pub mod orient;
mod png;
mod pnm;
pub mod range;
pub(crate) mod read_ahead;
pub(crate) mod stored;
pub(crate) mod tee;
pub(crate) mod tiff;
mod tile_rows;
pub use tiff::geo::{GeoTags, GeoValue};
pub mod tiled;
mod whole;
pub(crate) mod xml;

pub(crate) use crate::decode::{decode_tile, decode_tile_within, probe_tile};
pub use crate::stages::Decoding;

use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::error::{Result, TilerError};
use crate::limits::{Budget, human_bytes};
use crate::pixel::PixelLayout;

/// What a decoder knows before the first row: size and pixel layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageHeader {
    /// Width in texels, as the rows are delivered (after any EXIF rotation).
    pub width: u32,
    /// Height in texels: the number of rows the source delivers.
    pub height: u32,
    /// Channels and sample depth of every delivered row.
    pub layout: PixelLayout,
}

/// A decoder positioned at the next row of an image.
pub trait RowSource: Send {
    /// Size and pixel layout, known before the first row and the same until the end.
    fn header(&self) -> ImageHeader;
    /// [`ImageHeader::width`]: texels per row.
    fn width(&self) -> u32 {
        self.header().width
    }
    /// [`ImageHeader::height`]: rows in all.
    fn height(&self) -> u32 {
        self.header().height
    }
    /// [`ImageHeader::layout`]: what a row's samples are.
    fn layout(&self) -> PixelLayout {
        self.header().layout
    }
    /// Fills `row` (width x bytes per pixel, 16-bit samples in native byte order) with the next row.
    fn read_row(&mut self, row: &mut [u8]) -> Result<()>;
    /// Short name of the decoder path taken, for the summary line.
    fn describe(&self) -> String;
    /// Bytes the decoder holds now beyond the row it fills (a TIFF's decoded row of tiles),
    /// for `split --json`'s memory (`limits::Part::Decoder`); 0 where it keeps no more than a
    /// row's worth of its own.
    fn buffer_bytes(&self) -> u64 {
        0
    }
    /// The most [`buffer_bytes`](Self::buffer_bytes) can say during a run, known once the
    /// source is open (from its header, by the same arithmetic that sizes the buffers): the
    /// plan counts it before the pipeline allocates anything (`pyramid::stripes`). By default
    /// what it holds once open: sources whose buffers are all allocated at open say no more.
    fn most_buffer_bytes(&self) -> u64 {
        self.buffer_bytes()
    }
    /// The time the source has spent decoding in tasks on the rayon pool since it was opened
    /// (a JPEG TIFF's next band, decoded while this one's rows are read), summed over the
    /// tasks: what `split --json` reports as the `decode` stage. Zero where all the decoding is
    /// done inside [`read_row`](Self::read_row), on the reading thread, and counted there.
    fn decoding(&self) -> Decoding {
        Decoding::default()
    }
    /// Starts again from the first row: an image too wide for one band is read once per
    /// vertical stripe. Sources that cannot say so.
    fn rewind(&mut self) -> Result<()> {
        Err(TilerError::Options(format!("{} cannot be read twice, as a striped run needs", self.describe())))
    }
    /// Passes over the next `rows` rows: a shard's region starts below the top. Sources that can
    /// seek (TIFF strips and tiles, PPM, tiled inputs) go straight there; the others (PNG,
    /// JPEG) decode the rows and drop them. A source that reads columns
    /// ([`read_columns`](Self::read_columns)) must seek, since its rows may be narrower.
    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        let mut scratch = vec![0u8; self.width() as usize * self.layout().bytes_per_pixel()];
        for _ in 0..rows {
            self.read_row(&mut scratch)?;
        }
        Ok(())
    }
    /// From the next row on, fills `row` with the texels of `columns` only, if this source can
    /// read part of a row for less than the whole (a stripe of a wide PPM, a shard's region of
    /// a tiled input); returns whether it will. All the columns mean whole rows again. Sources
    /// that cannot keep giving whole rows.
    fn read_columns(&mut self, _columns: std::ops::Range<u32>) -> bool {
        false
    }
    /// The EXIF orientation and ICC profile the file carries (applied by [`open_with`], not by
    /// the decoder: its rows are the stored ones).
    fn embedded(&self) -> Embedded {
        Embedded::default()
    }
    /// The compressed tiles the rows are decoded from, where a run may copy them as they are
    /// (`StoredTiles`); `None` for sources whose rows are not a stored tile's texels (decoded
    /// from strips or whole, or changed on the way: rotated, converted to sRGB).
    fn stored_tiles(&self) -> Option<std::sync::Arc<dyn stored::StoredTiles>> {
        None
    }
    /// These rows at half their size, each stored JPEG tile decoded from its DCT coefficients at
    /// 1/2 scale (`--fast-shrink`, `source/halved.rs`), for a run that copies those tiles into its
    /// finest level; `None` for sources that cannot (the default), whose rows are not their
    /// stored tiles' texels as libjpeg decodes them.
    fn halved(&self) -> Option<Box<dyn RowSource>> {
        None
    }
    /// Every level of the slide the rows are the full resolution of, as stored, where all
    /// are grids of JPEG tiles an output may copy (`StoredLevels`); `None` for sources that
    /// are no such pyramid. Read when asked (the reduced levels' directories): an error names
    /// the file and the level.
    fn stored_levels(&self) -> Result<Option<stored::StoredLevels>> {
        Ok(None)
    }
    /// What the source has to add to the summary once its rows are read (the samples
    /// `--range` clamped), asked after the run.
    fn after_run(&self) -> Option<Box<dyn Fn() -> String + Send>> {
        None
    }
}

/// What a file says about how its stored texels are to be shown, and where.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Embedded {
    /// The EXIF orientation, or the identity where the file has none.
    pub orientation: orient::Orientation,
    /// The ICC profile, whole (JPEG's APP2 chunks joined).
    pub icc: Option<Vec<u8>>,
    /// A GeoTIFF's georeferencing, as its tags store it.
    pub geo: Option<GeoTags>,
    /// The physical size of a stored pixel, where the file states it.
    pub pitch: Option<PixelPitch>,
    /// The lossy compressions the stored texels went through, oldest first: a JPEG's or a
    /// JPEG-tiled slide's, or what a DICOM instance states. Empty where the file says none
    /// (its texels may still have been lossy once, before it was written).
    pub lossy: Vec<LossyStep>,
    /// The one channel the file names for the image (an OME-TIFF series of one `Channel`).
    pub channel: Option<ChannelLabel>,
}

/// What a file says of the one channel of its image, as OME-XML's `Channel` does: an
/// OME-TIFF output names its one channel so again.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ChannelLabel {
    /// Its `Name`.
    pub name: Option<String>,
    /// Its `Color`, RGBA.
    pub colour: Option<u32>,
}

/// One lossy compression of an image's texels, as DICOM's Lossy Image Compression Method
/// and Ratio record it: an output that states the image's history (a DICOM series) lists
/// the source's steps before its own.
#[derive(Clone, Debug, PartialEq)]
pub struct LossyStep {
    /// The method, as DICOM's defined terms name it: `ISO_10918_1` (JPEG), `ISO_15444_1`
    /// (JPEG 2000), `ISO_18181_1` (JPEG XL), or what a DICOM source states.
    pub method: String,
    /// Bytes of the texels uncompressed over bytes compressed (a DICOM source's as stated).
    pub ratio: f64,
}

impl LossyStep {
    /// JPEG's method (ISO/IEC 10918-1).
    pub const JPEG: &'static str = "ISO_10918_1";
    /// JPEG 2000's method (ISO/IEC 15444-1).
    pub const JPEG_2000: &'static str = "ISO_15444_1";
    /// JPEG XL's method (ISO/IEC 18181-1; PS3.3 C.7.6.1.1.5.1's defined term since
    /// Supplement 232).
    pub const JPEG_XL: &'static str = "ISO_18181_1";

    /// `method` compressing `width x height` texels of `samples` 8-bit samples into
    /// `compressed` bytes; no step where nothing was compressed.
    pub(crate) fn of(method: &str, (width, height): (u32, u32), samples: usize, compressed: u64) -> Vec<LossyStep> {
        let raw = u64::from(width) * u64::from(height) * samples as u64;
        match compressed {
            0 => Vec::new(),
            _ => vec![LossyStep { method: method.to_string(), ratio: raw as f64 / compressed as f64 }],
        }
    }
}

/// The physical size of one pixel, where a file states it (a slide's MPP, OME-XML's
/// `PhysicalSizeX`/`Y`, resolution tags in pixels per centimetre): what an OME-TIFF, an
/// OME-Zarr or a DICOM series records when `--pixel-size` is not given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelPitch {
    /// Micrometres across one pixel.
    pub x_um: f64,
    /// Micrometres down one pixel.
    pub y_um: f64,
    /// Where the file says it, for the summary ("the Aperio description's MPP").
    pub from: &'static str,
}

impl PixelPitch {
    /// The side of a square pixel, or `None` where the sides differ by more than rounding
    /// (a part in 10^4: resolution tags are rationals, MPP values a few digits).
    pub fn square(&self) -> Option<f64> {
        agree(self.x_um, self.y_um).then_some(self.x_um)
    }

    /// Whether `other` is the same size to rounding (as [`PixelPitch::square`] takes it),
    /// wherever each was stated.
    pub fn same_as(&self, other: &PixelPitch) -> bool {
        agree(self.x_um, other.x_um) && agree(self.y_um, other.y_um)
    }
}

/// Two lengths equal to a part in 10^4.
fn agree(u: f64, v: f64) -> bool {
    (u - v).abs() <= 1e-4 * u.max(v)
}

/// How [`open_with`] presents an image file.
#[derive(Clone, Copy, Debug)]
pub struct OpenOptions {
    /// What the source may hold (`--max-memory`): a format that cannot be streamed is decoded
    /// whole only within it, and the read-ahead is sized from it.
    pub budget: Budget,
    /// Apply the EXIF orientation (`--no-autorotate` turns it off).
    pub autorotate: bool,
    /// Keep the pixels as stored instead of converting an ICC profile to sRGB (`--keep-icc`).
    pub keep_icc: bool,
    /// Which image of a file holding several (`--page`, `--series`).
    pub pick: Pick,
}

impl OpenOptions {
    /// Orientation applied and colours converted to sRGB, as viewers show the image.
    pub fn shown(budget: Budget) -> OpenOptions {
        OpenOptions { budget, autorotate: true, keep_icc: false, pick: Pick::default() }
    }
}

/// A source and the ICC profile its texels are in, when kept ([`with_profile`]).
pub(crate) type Profiled = (Box<dyn RowSource>, Option<Vec<u8>>);

/// A source as [`open_with`] presents it, and what its file says that an output may carry.
pub struct Opened {
    /// The rows, oriented and converted as the options say.
    pub source: Box<dyn RowSource>,
    /// The ICC profile the texels are in, when `keep_icc` keeps it.
    pub icc: Option<Vec<u8>>,
    /// A GeoTIFF's georeferencing, where the rows are the file's own grid (not turned by an
    /// orientation): a TIFF output writes it again (docs/tiff.md).
    pub geo: Option<GeoTags>,
    /// The physical size of a pixel of the rows, where the file states it (its sides swapped
    /// where an orientation turns the image).
    pub pitch: Option<PixelPitch>,
    /// The lossy compressions the file's texels went through ([`Embedded::lossy`]).
    pub lossy: Vec<LossyStep>,
    /// The one channel the file names ([`Embedded::channel`]).
    pub channel: Option<ChannelLabel>,
}

/// Opens `path` as viewers show it (or as `opts` says): its orientation applied and its ICC
/// profile converted to sRGB. Returns the profile when `keep_icc` keeps it, for the output to
/// carry, and the georeferencing where the file has it and the rows keep its grid.
pub fn open_with(path: &Path, opts: OpenOptions) -> Result<Opened> {
    let source = open_picked(path, opts.budget, opts.pick)?;
    let Embedded { orientation, icc, geo, pitch, lossy, channel } = source.embedded();
    let (mut source, kept) = with_profile(path, source, icc, opts.keep_icc)?;
    let turned = opts.autorotate && orientation != orient::Orientation::NORMAL;
    if opts.autorotate {
        source = orient::apply(path, source, orientation, opts.budget.bytes())?;
    } else if orientation != orient::Orientation::NORMAL {
        let note = format!("EXIF orientation {} not applied (--no-autorotate)", orientation.value());
        source = Box::new(icc::Described { inner: source, note, transform: None, held: 0 });
    }
    // A turned image's pixels are no longer where the model transform puts them.
    let geo = geo.filter(|_| !turned);
    let pitch = match pitch {
        Some(p) if opts.autorotate && orientation.transposes() => Some(PixelPitch { x_um: p.y_um, y_um: p.x_um, ..p }),
        other => other,
    };
    Ok(Opened { source, icc: kept, geo, pitch, lossy, channel })
}

/// `source`, whose texels are in the colours of `icc`, converted to sRGB, or kept as they are
/// with `keep` (`--keep-icc`, which returns the profile for the output to carry); `split` and
/// `convert` share it.
pub fn with_profile(path: &Path, source: Box<dyn RowSource>, icc: Option<Vec<u8>>, keep: bool) -> Result<Profiled> {
    match icc {
        None => Ok((source, None)),
        // Each reader checks the size before it reads a profile; this holds for every one.
        Some(icc) if icc.len() as u64 > icc::MAX_PROFILE_BYTES => {
            Err(icc::too_large(path, Some(icc.len() as u64), "as read"))
        }
        Some(icc) if keep => {
            let note = format!("ICC profile kept ({} bytes, --keep-icc): pixels as stored", icc.len());
            let held = icc.len() as u64;
            Ok((Box::new(icc::Described { inner: source, note, transform: None, held }), Some(icc)))
        }
        Some(icc) => Ok((icc::to_srgb(path, source, &icc)?, None)),
    }
}

/// A file source that rewinds by opening its file again (a decoder from the top: PNG and
/// JPEG decode once more per stripe, as documented in docs/architecture.md).
struct Reopening {
    path: std::path::PathBuf,
    max_memory: u64,
    pick: Pick,
    inner: Box<dyn RowSource>,
}

/// Which image of a file holding several is read (`--page`, `--series`): only TIFF has more
/// than one; by default the first full-resolution image (docs/sources.md).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Pick {
    /// The Nth directory of a TIFF, counted from 0 as `tiffinfo` and libvips count them.
    pub page: Option<u32>,
    /// The Nth series: an OME-TIFF's Nth `Image`, else the Nth full-resolution page.
    pub series: Option<u32>,
}

impl RowSource for Reopening {
    fn header(&self) -> ImageHeader {
        self.inner.header()
    }
    fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
        self.inner.read_row(row)
    }
    fn describe(&self) -> String {
        self.inner.describe()
    }
    fn buffer_bytes(&self) -> u64 {
        self.inner.buffer_bytes()
    }
    fn most_buffer_bytes(&self) -> u64 {
        self.inner.most_buffer_bytes()
    }
    /// The file opened last's: a stripe's pass (`source::read_ahead`) counts what its reading
    /// added, and a rewind comes between passes.
    fn decoding(&self) -> Decoding {
        self.inner.decoding()
    }
    fn read_columns(&mut self, columns: std::ops::Range<u32>) -> bool {
        self.inner.read_columns(columns)
    }
    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        self.inner.skip_rows(rows)
    }
    fn embedded(&self) -> Embedded {
        self.inner.embedded()
    }
    fn stored_tiles(&self) -> Option<std::sync::Arc<dyn stored::StoredTiles>> {
        self.inner.stored_tiles()
    }
    fn halved(&self) -> Option<Box<dyn RowSource>> {
        self.inner.halved()
    }
    fn stored_levels(&self) -> Result<Option<stored::StoredLevels>> {
        self.inner.stored_levels()
    }
    fn rewind(&mut self) -> Result<()> {
        let again = open_once(&self.path, self.max_memory, self.pick)?;
        if again.header() != self.inner.header() {
            return Err(TilerError::decode(&self.path, "changed while it was being read"));
        }
        self.inner = again;
        Ok(())
    }
}

/// Opens `path`, choosing the decoder from the file's first bytes (not its extension); its
/// reader holds no more than `budget` (a file that cannot be streamed is decoded whole only
/// within it, and read-ahead is sized from it).
pub fn open(path: &Path, budget: Budget) -> Result<Box<dyn RowSource>> {
    open_picked(path, budget, Pick::default())
}

/// [`open`], reading the page or series `pick` names of a file holding several.
pub fn open_picked(path: &Path, budget: Budget, pick: Pick) -> Result<Box<dyn RowSource>> {
    let max_memory = budget.bytes();
    let inner = open_once(path, max_memory, pick)?;
    Ok(Box::new(Reopening { path: path.to_path_buf(), max_memory, pick, inner }))
}

fn open_once(path: &Path, max_memory: u64, pick: Pick) -> Result<Box<dyn RowSource>> {
    // Checked before opening: opening a FIFO blocks until a writer comes.
    let meta = std::fs::metadata(path).map_err(|e| TilerError::io(path, e))?;
    if meta.is_dir() {
        if pick == Pick::default() && dicom::holds_dicom(path) {
            return dicom::open(path, max_memory);
        }
        return Err(TilerError::decode(path, "is a directory, not an image"));
    }
    if !meta.is_file() {
        return Err(TilerError::unsupported(
            path,
            "is not a regular file (a FIFO, socket or device): an image is opened more than once (its first bytes, then its rows), so save it to a file first",
        ));
    }
    // A DICOM file's signature follows its 128-byte preamble; the others start the file.
    let mut magic = [0u8; dicom::MAGIC_AT + 4];
    let mut file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let n = read_up_to(&mut file, &mut magic).map_err(|e| TilerError::io(path, e))?;
    let magic = &magic[..n];
    if n == 0 {
        return Err(TilerError::decode(path, "the file is empty"));
    }
    let format = Streamed::sniff(magic);
    if pick != Pick::default() && format != Some(Streamed::Tiff) {
        let name = format.map_or("this", Streamed::name);
        return Err(TilerError::unsupported(
            path,
            match format {
                Some(Streamed::Dicom) => {
                    "--page and --series choose among a TIFF's images; of a DICOM series the full-resolution instance is read".to_string()
                }
                _ => format!("--page and --series choose among a TIFF's images; a {name} file holds one"),
            },
        ));
    }
    match format {
        Some(Streamed::Png) => png::open(path, max_memory),
        Some(Streamed::Tiff) => tiff::open(path, max_memory, pick),
        Some(Streamed::Jpeg) => jpeg::open(path, max_memory),
        Some(Streamed::Pnm) => pnm::open(path),
        Some(Streamed::Dicom) => dicom::open(path, max_memory),
        None => whole::open(path, max_memory),
    }
}

/// Whether `path` is a DICOM file or a directory holding one: a whole-slide series, which
/// [`open_with`] reads (`convert` takes it as `split` does).
pub fn is_dicom_input(path: &Path) -> bool {
    match path.is_dir() {
        true => dicom::holds_dicom(path),
        false => {
            let mut head = Vec::with_capacity(Streamed::SNIFF_BYTES);
            File::open(path)
                .and_then(|f| f.take(Streamed::SNIFF_BYTES as u64).read_to_end(&mut head))
                .is_ok_and(|_| dicom::is_dicom(&head))
        }
    }
}

/// The image formats read row by row, told apart by their first bytes (not the extension).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Streamed {
    /// PNG (`\x89PNG\r\n\x1a\n`).
    Png,
    /// TIFF and BigTIFF, either byte order (`II*\0`, `MM\0*`, `II+\0`, `MM\0+`).
    Tiff,
    /// JPEG (`\xff\xd8\xff`).
    Jpeg,
    /// Binary PGM or PPM (`P5`, `P6`).
    Pnm,
    /// A DICOM Part-10 file (`DICM` after a 128-byte preamble): a whole-slide image's series.
    Dicom,
}

impl Streamed {
    /// The bytes [`sniff`](Self::sniff) looks at: a DICOM file's signature is at 128.
    pub const SNIFF_BYTES: usize = dicom::MAGIC_AT + 4;

    /// The format whose signature `magic` (a file's first [`SNIFF_BYTES`](Self::SNIFF_BYTES)
    /// bytes, or fewer) starts with.
    pub fn sniff(magic: &[u8]) -> Option<Streamed> {
        if dicom::is_dicom(magic) {
            Some(Streamed::Dicom)
        } else if magic.starts_with(b"\x89PNG\r\n\x1a\n") {
            Some(Streamed::Png)
        } else if [b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"].iter().any(|m| magic.starts_with(*m)) {
            Some(Streamed::Tiff)
        } else if magic.starts_with(b"\xff\xd8\xff") {
            Some(Streamed::Jpeg)
        } else if magic.len() >= 2 && magic[0] == b'P' && matches!(magic[1], b'5' | b'6') {
            Some(Streamed::Pnm)
        } else {
            None
        }
    }

    /// The format's name as messages print it: `PNG`, `TIFF`, `JPEG`, `PNM`, `DICOM`.
    pub fn name(self) -> &'static str {
        match self {
            Streamed::Png => "PNG",
            Streamed::Tiff => "TIFF",
            Streamed::Jpeg => "JPEG",
            Streamed::Pnm => "PNM",
            Streamed::Dicom => "DICOM",
        }
    }
}

fn read_up_to(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

/// Bytes of a fully decoded image, checked for overflow.
pub(crate) fn image_bytes(width: u64, height: u64, layout: PixelLayout) -> Option<u64> {
    width.checked_mul(height)?.checked_mul(layout.bytes_per_pixel() as u64)
}

/// Refuses to hold a whole decoded image above `max_memory`, saying why and what to do.
pub(crate) fn check_whole_fits(
    path: &Path,
    width: u64,
    height: u64,
    layout: PixelLayout,
    max_memory: u64,
    why: &str,
) -> Result<()> {
    let need = image_bytes(width, height, layout).unwrap_or(u64::MAX);
    if need > max_memory {
        return Err(TilerError::unsupported(
            path,
            format!(
                "{why}, so the whole {width}x{height} {layout} image ({}) would have to be held in memory, more than --max-memory ({}); raise --max-memory or re-save it in a streamable form (non-interlaced PNG, baseline JPEG, striped or tiled TIFF)",
                human_bytes(need),
                human_bytes(max_memory)
            ),
        ));
    }
    Ok(())
}

/// Reads every row of `source` into one buffer (for tests of the decoders).
#[cfg(test)]
pub(crate) fn read_all(source: &mut dyn RowSource) -> Result<Vec<u8>> {
    let row = source.width() as usize * source.layout().bytes_per_pixel();
    let mut all = vec![0u8; row * source.height() as usize];
    for chunk in all.chunks_exact_mut(row) {
        source.read_row(chunk)?;
    }
    Ok(all)
}
