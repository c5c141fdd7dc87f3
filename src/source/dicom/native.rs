//! Uncompressed frames (native Pixel Data, 8-bit RGB or MONOCHROME2, interleaved), read straight
//! from the file: each row of the image is its part of each frame of its row of frames, one
//! positioned read a frame, so nothing is held beyond the row being filled.

use std::fs::File;
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::{ImageHeader, RowSource};

pub(super) struct NativeFrames {
    path: PathBuf,
    file: File,
    size: (u32, u32),
    tile: (u32, u32),
    across: u32,
    /// Each grid cell's frame offset in the file, row-major.
    offsets: Vec<u64>,
    pixel: usize,
    next: u64,
    columns: Option<Range<u32>>,
    label: String,
    embedded: crate::source::Embedded,
}

/// The row source of the frames at `offsets` (one per cell of the `tile` grid over `size`).
pub(super) fn open(
    path: &Path,
    size: (u32, u32),
    tile: (u32, u32),
    offsets: Vec<u64>,
    grey: bool,
    label: String,
    embedded: crate::source::Embedded,
) -> Result<Box<dyn RowSource>> {
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    Ok(Box::new(NativeFrames {
        path: path.to_path_buf(),
        file,
        size,
        tile,
        across: size.0.div_ceil(tile.0),
        offsets,
        pixel: if grey { 1 } else { 3 },
        next: 0,
        columns: None,
        label,
        embedded,
    }))
}

impl RowSource for NativeFrames {
    fn embedded(&self) -> crate::source::Embedded {
        self.embedded.clone()
    }

    fn header(&self) -> ImageHeader {
        let channels = if self.pixel == 1 { Channels::Grey } else { Channels::Rgb };
        ImageHeader { width: self.size.0, height: self.size.1, layout: PixelLayout::new(channels, Depth::U8) }
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let y = self.next;
        let columns = self.columns.clone().unwrap_or(0..self.size.0);
        let fail = |message: String| TilerError::DecodeRow { path: self.path.clone(), row: y, message };
        if y >= self.size.1 as u64 {
            return Err(fail(format!("past the image's {} rows", self.size.1)));
        }
        if out.len() != columns.len() * self.pixel {
            return Err(fail(format!("internal: a row of {} bytes for {} texels", out.len(), columns.len())));
        }
        let (tw, th) = (self.tile.0, self.tile.1 as u64);
        let (tile_row, within) = (y / th, y % th);
        for col in columns.start / tw..columns.end.div_ceil(tw) {
            let x0 = col * tw;
            let (from, to) = (columns.start.max(x0), columns.end.min(x0 + tw));
            let index = (tile_row * self.across as u64 + col as u64) as usize;
            let at = self.offsets[index] + (within * tw as u64 + (from - x0) as u64) * self.pixel as u64;
            let dest =
                &mut out[(from - columns.start) as usize * self.pixel..(to - columns.start) as usize * self.pixel];
            self.file
                .read_exact_at(dest, at)
                .map_err(|e| fail(format!("frame {index} (column {col}, row {tile_row}): cannot be read: {e}")))?;
        }
        self.next += 1;
        Ok(())
    }

    fn describe(&self) -> String {
        let (w, h) = self.tile;
        let kind = if self.pixel == 1 { "MONOCHROME2" } else { "RGB" };
        format!("{}, uncompressed {kind} frames of {w}x{h}, read in place", self.label)
    }

    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        self.next += rows as u64;
        Ok(())
    }

    fn rewind(&mut self) -> Result<()> {
        self.next = 0;
        Ok(())
    }

    fn read_columns(&mut self, columns: Range<u32>) -> bool {
        self.columns = (columns != (0..self.size.0)).then_some(columns);
        true
    }
}
