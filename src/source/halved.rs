//! A source of stored JPEG tiles read at half its size (`--fast-shrink`): each tile decoded by
//! libjpeg at 1/2 scale, straight from its DCT coefficients, as libvips shrinks a JPEG on
//! load. A run that copies the finest level's pages from those tiles needs no texel of that
//! level: it makes its first reduced level from these rows instead of summing the decoded
//! finest level. That saves the inverse DCT, colour conversion and upsampling of three
//! quarters of the texels and the first level's sums, but not the entropy decoding, which is
//! most of a JPEG's decoding at high quality (a 16384² BigTIFF of Q90 tiles: 17.3 ms/Mpx of
//! decoding against 19.4 decoded whole, `bench/split-matrix.sh`). What it costs in accuracy
//! is measured in docs/accuracy.md: the scaled inverse DCT is a low-pass filter close to, but
//! not, the 2x2 box.
//!
//! Rows come a row of tiles at a time, its tiles decoded in parallel ([`TileRows`]): the run's
//! `decode` stage.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::error::TilerError;
use crate::source::stored::StoredTiles;
use crate::source::tile_rows::TileRows;
use crate::source::{Decoding, Embedded, ImageHeader, RowSource};
use crate::stages::TaskClock;

/// The rows of `tiles` at half size.
pub(crate) struct Halved {
    path: PathBuf,
    tiles: Arc<dyn StoredTiles>,
    header: ImageHeader,
    rows: TileRows,
    /// Tiles across.
    across: u32,
    embedded: Embedded,
    /// The decoding tasks' time: the run's `decode` stage.
    clock: TaskClock,
}

impl Halved {
    /// `tiles` of the image `full` (the source's header) in `path`, whose rows hold 8-bit grey
    /// or RGB, halved: `ceil(w / 2) x ceil(h / 2)` texels in tiles of half the stored size.
    pub(crate) fn new(path: &Path, tiles: Arc<dyn StoredTiles>, full: ImageHeader, embedded: Embedded) -> Halved {
        let (tw, th) = tiles.tile_size();
        let header = ImageHeader { width: full.width.div_ceil(2), height: full.height.div_ceil(2), ..full };
        let pixel = full.layout.bytes_per_pixel();
        let rows = TileRows::new((header.width, header.height), (tw / 2, th / 2), pixel, "tile");
        let across = rows.across();
        Halved { path: path.to_path_buf(), tiles, header, rows, across, embedded, clock: TaskClock::default() }
    }

    /// Tile `index`'s `w x h` texels at half size into `texels`.
    fn decode(&self, index: usize, w: u32, h: u32, texels: &mut Vec<u8>) -> std::result::Result<(), String> {
        let (col, row) = (index as u32 % self.across, index as u32 / self.across);
        let message = |e: TilerError| match e {
            TilerError::Decode { message, .. } => message,
            other => other.to_string(),
        };
        let Some(decoded) = self.clock.time(|| self.tiles.decode(col, row, 2)).map_err(message)? else {
            return Err("this source's tiles cannot be decoded at half size".into());
        };
        let want = w as usize * h as usize * self.header.layout.bytes_per_pixel();
        if decoded.len() != want {
            return Err(format!("internal: {} bytes decoded at half size for {w}x{h} texels", decoded.len()));
        }
        *texels = decoded;
        Ok(())
    }
}

impl RowSource for Halved {
    rows_of_tile_rows!(decode);

    fn header(&self) -> ImageHeader {
        self.header
    }

    fn describe(&self) -> String {
        let (tw, th) = self.tiles.tile_size();
        format!("{tw}x{th} JPEG tiles decoded at half size (--fast-shrink: DCT-scaled, a row of tiles in parallel)")
    }

    fn decoding(&self) -> Decoding {
        self.clock.total()
    }

    fn embedded(&self) -> Embedded {
        self.embedded.clone()
    }
}
