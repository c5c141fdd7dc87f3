//! EXIF orientation: the image is tiled as viewers show it, not as its rows are stored.
//!
//! Orientation 2 (a mirror) keeps the row order and streams. The others put a stored row where
//! another row, or a column, should be: 3 and 4 read the stored rows bottom up, 5 to 8 turn
//! stored columns into rows. Those are made a band of output rows at a time, the band as large
//! as `--max-memory` allows: one band (the whole image, decoded once) when it fits, otherwise
//! one pass over the source per band. A pass seeks where the source can (TIFF strips and tiles
//! skip to the rows it needs, tiled TIFFs decode only the tiles under the columns it needs);
//! more than `MAX_PASSES` passes is refused, naming `--no-autorotate`.

use std::path::Path;

use super::{ImageHeader, RowSource};
use crate::error::{Result, TilerError};
use crate::limits::human_bytes;

/// Passes over the source allowed for one image before a reorientation is refused: each pass
/// of a JPEG or PNG decodes the whole file again.
pub(crate) const MAX_PASSES: u64 = 8;

/// The EXIF/TIFF Orientation tag (274): where the stored first row and column belong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Orientation(u16);

impl Default for Orientation {
    fn default() -> Orientation {
        Orientation::NORMAL
    }
}

impl Orientation {
    /// Orientation 1: rows as stored, nothing to undo.
    pub(crate) const NORMAL: Orientation = Orientation(1);

    /// The tag's value; anything outside 1..=8 means nothing, as viewers read it.
    pub fn from_tag(value: u16) -> Orientation {
        if (1..=8).contains(&value) { Orientation(value) } else { Orientation::NORMAL }
    }

    /// The EXIF value, 1 to 8.
    pub(crate) fn value(self) -> u16 {
        self.0
    }

    /// Stored columns become rows (orientations 5 to 8).
    pub(crate) fn transposes(self) -> bool {
        self.0 >= 5
    }

    /// What is done to the stored image to show it, as the summary says it.
    pub fn describe(self) -> &'static str {
        match self.0 {
            2 => "mirrored left-right",
            3 => "rotated 180°",
            4 => "mirrored top-bottom",
            5 => "transposed",
            6 => "rotated 90° clockwise",
            7 => "transversed",
            8 => "rotated 90° anticlockwise",
            _ => "as stored",
        }
    }

    /// Where stored texel (`x`, `y`) of a `width` x `height` image goes: (column, row) shown.
    pub fn place(self, x: u32, y: u32, width: u32, height: u32) -> (u32, u32) {
        let (right, bottom) = (width - 1 - x, height - 1 - y);
        match self.0 {
            2 => (right, y),
            3 => (right, bottom),
            4 => (x, bottom),
            5 => (y, x),
            6 => (bottom, x),
            7 => (bottom, right),
            8 => (y, right),
            _ => (x, y),
        }
    }
}

/// The Orientation in an EXIF block: a TIFF structure (byte order, IFD0), as JPEG's APP1
/// (after "Exif\0\0") and PNG's eXIf chunk hold it. Anything malformed means no orientation:
/// viewers ignore what they cannot read, and so do we.
pub(crate) fn from_exif(exif: &[u8]) -> Orientation {
    let exif = exif.strip_prefix(b"Exif\0\0").unwrap_or(exif);
    let big = match exif.get(..4) {
        Some(b"II*\0") => false,
        Some(b"MM\0*") => true,
        _ => return Orientation::NORMAL,
    };
    let u16_at = |at: usize| {
        exif.get(at..at + 2)
            .map(|b| if big { u16::from_be_bytes([b[0], b[1]]) } else { u16::from_le_bytes([b[0], b[1]]) })
    };
    let u32_at = |at: usize| {
        exif.get(at..at + 4).map(|b| {
            let b = [b[0], b[1], b[2], b[3]];
            if big { u32::from_be_bytes(b) } else { u32::from_le_bytes(b) }
        })
    };
    let Some(ifd) = u32_at(4).map(|o| o as usize) else { return Orientation::NORMAL };
    let Some(count) = u16_at(ifd) else { return Orientation::NORMAL };
    for i in 0..count as usize {
        let entry = ifd + 2 + 12 * i;
        // Tag 274, type SHORT, one value, held in the entry itself.
        if u16_at(entry) == Some(274) && u16_at(entry + 2) == Some(3) && u32_at(entry + 4) == Some(1) {
            return u16_at(entry + 8).map_or(Orientation::NORMAL, Orientation::from_tag);
        }
    }
    Orientation::NORMAL
}

/// `inner` shown as `orientation` says, within `max_memory` for the reordering buffer.
pub fn apply(
    path: &Path,
    inner: Box<dyn RowSource>,
    orientation: Orientation,
    max_memory: u64,
) -> Result<Box<dyn RowSource>> {
    if orientation == Orientation::NORMAL {
        return Ok(inner);
    }
    let stored = inner.header();
    let (width, height) =
        if orientation.transposes() { (stored.height, stored.width) } else { (stored.width, stored.height) };
    let header = ImageHeader { width, height, layout: stored.layout };
    let row_bytes = width as u64 * stored.layout.bytes_per_pixel() as u64;
    // Orientation 2 needs only the row being read: one pass, no band.
    let band_rows = if orientation.value() == 2 { 0 } else { (max_memory / row_bytes.max(1)).min(height as u64) };
    let passes = match band_rows {
        _ if orientation.value() == 2 => 1,
        0 => u64::MAX,
        rows => (height as u64).div_ceil(rows),
    };
    if passes > MAX_PASSES {
        return Err(TilerError::unsupported(
            path,
            format!(
                "EXIF orientation {} ({}) puts the stored rows in another order; within --max-memory ({}) that takes {} passes over the {}x{} image (at most {MAX_PASSES} are made): raise --max-memory to {} or more, or keep the stored order with --no-autorotate",
                orientation.value(),
                orientation.describe(),
                human_bytes(max_memory),
                if passes == u64::MAX { "too many".to_string() } else { passes.to_string() },
                stored.width,
                stored.height,
                human_bytes(row_bytes.saturating_mul(height as u64).div_ceil(MAX_PASSES)),
            ),
        ));
    }
    Ok(Box::new(Oriented {
        inner,
        orientation,
        stored,
        header,
        band: Vec::new(),
        band_rows: band_rows as u32,
        band_first: 0,
        band_len: 0,
        next: 0,
        fresh: true,
        passes,
        scratch: Vec::new(),
    }))
}

struct Oriented {
    inner: Box<dyn RowSource>,
    orientation: Orientation,
    stored: ImageHeader,
    header: ImageHeader,
    /// Output rows `band_first..band_first + band_len`, whole.
    band: Vec<u8>,
    /// Most output rows a band holds.
    band_rows: u32,
    band_first: u32,
    band_len: u32,
    next: u32,
    /// The source is at its first row (nothing read since it was opened or rewound).
    fresh: bool,
    passes: u64,
    /// One stored row (or the part of it a pass reads).
    scratch: Vec<u8>,
}

impl Oriented {
    fn pixel(&self) -> usize {
        self.stored.layout.bytes_per_pixel()
    }

    fn restart(&mut self) -> Result<()> {
        if !self.fresh {
            self.inner.rewind()?;
        }
        self.fresh = false;
        Ok(())
    }

    /// Fills the band with output rows `first..`: one pass over the part of the source they
    /// come from.
    fn fill(&mut self, first: u32) -> Result<()> {
        let (w, h) = (self.stored.width, self.stored.height);
        let px = self.pixel();
        let len = self.band_rows.min(self.header.height - first);
        let out_row = self.header.width as usize * px;
        self.band.resize(out_row * len as usize, 0);
        self.band_len = 0;
        self.restart()?;
        let o = self.orientation;
        if !o.transposes() {
            // Output rows first..first+len are stored rows h-first-len..h-first (3 and 4).
            let top = h - first - len;
            self.inner.skip_rows(top)?;
            for y in top..top + len {
                let at = (h - 1 - y - first) as usize * out_row;
                let row = &mut self.band[at..at + out_row];
                self.inner.read_row(row)?;
                if o.value() == 3 {
                    mirror(row, px);
                }
            }
        } else {
            // Output row r is stored column r (5, 6) or w-1-r (7, 8).
            let columns = if o.value() <= 6 { first..first + len } else { w - first - len..w - first };
            let narrow = self.inner.read_columns(columns.clone());
            let (skip, read) = if narrow { (0, columns.len()) } else { (columns.start as usize, w as usize) };
            self.scratch.resize(read * px, 0);
            for y in 0..h {
                self.inner.read_row(&mut self.scratch)?;
                for x in columns.clone() {
                    let (col, row) = o.place(x, y, w, h);
                    let from = (x as usize - columns.start as usize + skip) * px;
                    let to = (row - first) as usize * out_row + col as usize * px;
                    self.band[to..to + px].copy_from_slice(&self.scratch[from..from + px]);
                }
            }
        }
        self.band_first = first;
        self.band_len = len;
        Ok(())
    }
}

/// Reverses the order of the `px`-byte texels of `row`.
fn mirror(row: &mut [u8], px: usize) {
    let n = row.len() / px;
    for i in 0..n / 2 {
        let (left, right) = row.split_at_mut((n - 1 - i) * px);
        left[i * px..(i + 1) * px].swap_with_slice(&mut right[..px]);
    }
}

impl RowSource for Oriented {
    fn header(&self) -> ImageHeader {
        self.header
    }

    fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
        let y = self.next;
        if y >= self.header.height {
            return Err(TilerError::Internal(format!("{}: read past the last row", self.describe())));
        }
        if self.orientation.value() == 2 {
            self.fresh = false;
            self.inner.read_row(row)?;
            mirror(row, self.pixel());
        } else {
            if !(self.band_first..self.band_first + self.band_len).contains(&y) {
                self.fill(y)?;
            }
            let out_row = row.len();
            let at = (y - self.band_first) as usize * out_row;
            row.copy_from_slice(&self.band[at..at + out_row]);
        }
        self.next += 1;
        Ok(())
    }

    fn describe(&self) -> String {
        let how = match (self.orientation.value(), self.passes) {
            (2, _) => "streamed".to_string(),
            (_, 1) => "whole image held".to_string(),
            (_, n) => format!("{n} passes"),
        };
        format!(
            "{}; {} (EXIF orientation {}, {how})",
            self.inner.describe(),
            self.orientation.describe(),
            self.orientation.value()
        )
    }

    fn decoding(&self) -> crate::source::Decoding {
        self.inner.decoding()
    }

    fn rewind(&mut self) -> Result<()> {
        self.next = 0;
        if self.orientation.value() == 2 {
            self.inner.rewind()?;
            self.fresh = true;
        }
        // A band already held (the whole image, when it fits) is used again as it is.
        Ok(())
    }
}
