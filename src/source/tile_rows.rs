//! Rows from a grid of compressed tiles that a codec decodes whole (JPEG 2000 tiles of a TIFF,
//! JPEG XL frames of a DICOM instance): one row of tiles is decoded at a time, its tiles in
//! parallel on the rayon pool, each cropped to the part inside the image, and the image's rows
//! are cut from them. Memory holds one row of decoded tiles.

use std::path::Path;

use rayon::prelude::*;

use crate::error::{Result, TilerError};

/// The decoded row of tiles and where the reader is.
#[derive(Default)]
pub(crate) struct TileRows {
    size: (u32, u32),
    tile: (u32, u32),
    /// Bytes of one decoded texel.
    pixel: usize,
    /// What a tile is called in messages (`tile`, `frame`).
    what: &'static str,
    /// The decoded tiles of the current row, the texels inside the image only.
    band: Vec<Vec<u8>>,
    band_first: u64,
    band_rows: u64,
    next: u64,
}

impl TileRows {
    /// An image of `size` in tiles of `tile`, decoded to `pixel` bytes a texel.
    pub(crate) fn new(size: (u32, u32), tile: (u32, u32), pixel: usize, what: &'static str) -> TileRows {
        let across = size.0.div_ceil(tile.0) as usize;
        TileRows { size, tile, pixel, what, band: vec![Vec::new(); across], ..TileRows::default() }
    }

    /// Tiles across.
    pub(crate) fn across(&self) -> u32 {
        self.band.len() as u32
    }

    /// The next row of the image into `out`; `decode(index, w, h, texels)` decodes tile
    /// `index` (row-major) into `texels`: its `w x h` texels inside the image, rows packed.
    pub(crate) fn read_row<D>(&mut self, path: &Path, out: &mut [u8], decode: D) -> Result<()>
    where
        D: Fn(usize, u32, u32, &mut Vec<u8>) -> std::result::Result<(), String> + Sync,
    {
        let y = self.next;
        let fail = |message: String| TilerError::DecodeRow { path: path.to_path_buf(), row: y, message };
        if y >= u64::from(self.size.1) {
            return Err(fail(format!("read past the last row ({} rows)", self.size.1)));
        }
        if out.len() != self.size.0 as usize * self.pixel {
            return Err(fail(format!("internal: a row of {} bytes for {} texels", out.len(), self.size.0)));
        }
        if y < self.band_first || y >= self.band_first + self.band_rows {
            self.load_band(y, &decode).map_err(fail)?;
        }
        let (r, tw, pixel) = ((y - self.band_first) as usize, self.tile.0 as usize, self.pixel);
        for (col, texels) in self.band.iter().enumerate() {
            let x0 = col * tw;
            let w = tw.min(self.size.0 as usize - x0);
            out[x0 * pixel..(x0 + w) * pixel].copy_from_slice(&texels[r * w * pixel..(r + 1) * w * pixel]);
        }
        self.next += 1;
        Ok(())
    }

    /// Decodes the row of tiles holding row `y`, the tiles in parallel.
    fn load_band<D>(&mut self, y: u64, decode: &D) -> std::result::Result<(), String>
    where
        D: Fn(usize, u32, u32, &mut Vec<u8>) -> std::result::Result<(), String> + Sync,
    {
        let (tw, th) = self.tile;
        let row = (y / u64::from(th)) as u32;
        let first = u64::from(row) * u64::from(th);
        let rows = u64::from(th).min(u64::from(self.size.1) - first) as u32;
        let (across, width) = (self.across() as usize, self.size.0);
        let result = self.band.par_iter_mut().enumerate().try_for_each(|(col, texels)| {
            let index = row as usize * across + col;
            let w = tw.min(width - col as u32 * tw);
            decode(index, w, rows, texels).map_err(|m| (col, index, m))
        });
        if let Err((col, index, message)) = result {
            self.band_rows = 0;
            let what = self.what;
            return Err(format!(
                "{what} {index} ({what} row {row}, column {col}; rows {first}..{}): {message}",
                first + u64::from(rows)
            ));
        }
        (self.band_first, self.band_rows) = (first, u64::from(rows));
        Ok(())
    }

    /// Bytes the decoded tiles hold now.
    pub(crate) fn buffer_bytes(&self) -> u64 {
        self.band.iter().map(|t| t.capacity() as u64).sum()
    }

    /// Bytes a row of decoded tiles holds at most.
    pub(crate) fn most_buffer_bytes(&self) -> u64 {
        u64::from(self.tile.0) * u64::from(self.tile.1) * self.pixel as u64 * u64::from(self.across())
    }

    /// Skips `rows` rows.
    pub(crate) fn skip(&mut self, rows: u32) {
        self.next += u64::from(rows);
    }

    /// Back to the first row.
    pub(crate) fn rewind(&mut self) {
        self.next = 0;
    }
}
