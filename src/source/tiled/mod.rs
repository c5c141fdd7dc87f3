//! Already-tiled inputs for `convert`: a grid of tiles whose payloads, laid side by side, form
//! one image. [`TiledSource`] turns any [`TileGrid`] into a [`RowSource`], so re-tiling runs
//! through the same pipeline, pyramid and sinks as `split`.
//!
//! Only one row of input tiles is decoded and held at a time (decoded in parallel), so memory
//! does not grow with the grid's height.

pub(crate) mod store;

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use rayon::prelude::*;

pub(crate) use store::TileStore;

use crate::decode::probe_tile;
use crate::error::{Result, TilerError};
use crate::limits::human_bytes;
use crate::pixel::PixelLayout;
use crate::source::stored::{self, Quality, StoredTiles};
use crate::source::{ImageHeader, RowSource, decode_tile_within};

/// Where a cell's texels come from.
pub enum CellData {
    /// An encoded image file's bytes (PNG, JPEG, ...), and a name for errors.
    File(PathBuf, Vec<u8>),
    /// Samples in the grid's layout, `width x height` of the whole stored tile.
    Samples {
        /// What errors call the tile (its file, or the pack and tile).
        name: PathBuf,
        /// Width of the whole stored tile in texels.
        width: u32,
        /// Height of the whole stored tile in texels.
        height: u32,
        /// The samples, rows top to bottom, channels interleaved, native byte order.
        bytes: Vec<u8>,
    },
}

/// A tiled image. Cell (c, r) covers image texels `[c * cell_w, min((c + 1) * cell_w, width))`
/// across and likewise down; its stored tile may carry extra texels (borders, overlap) that
/// `crop` says how to skip.
pub trait TileGrid: Send + Sync {
    /// One line about the input, for the summary.
    fn describe(&self) -> String;
    /// The image the grid holds: its size (the cells' union) and texels.
    fn header(&self) -> ImageHeader;
    /// Nominal cell size in image texels.
    fn cell(&self) -> (u32, u32);
    /// The ICC profile the texels are in, where the input says so (the `iccProfile` of a
    /// tile directory or pack a `--keep-icc` run wrote); `None`: sRGB.
    fn icc_profile(&self) -> Result<Option<Vec<u8>>> {
        Ok(None)
    }
    /// The stored tile of cell (c, r), or `None` if it is missing; a tile file over `cap` bytes
    /// (declared or read) is an error naming it, before more than `cap` bytes are held.
    fn read(&self, col: u32, row: u32, cap: u64) -> Result<Option<CellData>>;
    /// Texels to skip at the left and top of the stored tile of cell (c, r).
    fn crop(&self, col: u32, row: u32) -> (u32, u32);
    /// The exact size the stored tile of cell (c, r) must have, where the layout fixes it;
    /// `None` only requires it to hold the cell.
    fn stored_size(&self, _col: u32, _row: u32) -> Option<(u32, u32)> {
        None
    }
    /// How many of the grid's tiles are stored, counted from listings without reading them,
    /// where a descriptor declares the grid (`None` where the grid is what was found).
    fn tiles_found(&self) -> Result<Option<u64>> {
        Ok(None)
    }
}

/// Refuses a grid whose descriptor declares more tiles than half of which are missing (a
/// `.dzi` claiming 300000² over one tile would be converted as minutes of filled cells):
/// `allow` proceeds anyway.
pub fn check_tiles_found(grid: &dyn TileGrid, allow: bool) -> Result<()> {
    let Some(found) = grid.tiles_found()? else { return Ok(()) };
    let (h, (cw, ch)) = (grid.header(), grid.cell());
    let declared = h.width.div_ceil(cw) as u64 * h.height.div_ceil(ch) as u64;
    if allow || declared - found.min(declared) <= declared / 2 {
        return Ok(());
    }
    Err(TilerError::Options(format!(
        "{}: only {found} of its {declared} tiles are there; the missing ones would be filled (--background, else zeros). Pass --allow-missing-tiles to convert it anyway",
        grid.describe()
    )))
}

/// The most bytes a tile file of `width x height` texels of `layout` may have: twice its
/// texels (a PNG stored without compression, or a JPEG of noise at quality 100, stays under
/// that) and 4 MiB for metadata (ICC profiles, EXIF), within [`store::MAX_TILE_BYTES`].
/// Anything larger is refused unread: an entry of a zip bomb inflates no further.
pub(crate) fn tile_file_cap(width: u32, height: u32, layout: PixelLayout) -> u64 {
    let texels = width as u64 * height as u64 * layout.bytes_per_pixel() as u64;
    (2 * texels + (4 << 20)).min(store::MAX_TILE_BYTES)
}

/// [`tile_file_cap`] of a `width x height` tile of the widest layout (RGBA, 32-bit float): a
/// tile of a grid whose descriptor gives its size, before its layout is known.
pub(crate) fn any_tile_file_cap(width: u32, height: u32) -> u64 {
    use crate::pixel::{Channels, Depth};
    tile_file_cap(width, height, PixelLayout::new(Channels::Rgba, Depth::F32))
}

/// A cell's texels, cropped to the cell; `None` for a missing cell.
type CellTexels = Option<Vec<u8>>;

/// Rows of a [`TileGrid`], one row of cells decoded at a time.
pub struct TiledSource {
    /// Shared with the [`StoredTiles`] a run copies JPEG cells through.
    grid: Arc<dyn TileGrid>,
    header: ImageHeader,
    /// Samples used for missing cells (one texel).
    fill: Vec<u8>,
    strict: bool,
    missing: Arc<Mutex<Vec<String>>>,
    /// The decoded cell row: `cell_h` image rows (fewer at the bottom).
    band: Vec<u8>,
    band_row: Option<u32>,
    next: u32,
    /// Read again from the top (a striped run): missing cells are already logged.
    rewound: bool,
    /// Texel columns read, when a stripe or a shard asked for fewer than all: only the
    /// cells under them are decoded.
    columns: Option<Range<u32>>,
    /// Bytes the tiles being read and decoded at once may hold together (`--max-memory` less
    /// the band).
    in_flight: u64,
}

impl TiledSource {
    /// `fill` is one texel of the grid's layout (native-endian samples) for missing cells;
    /// with `strict`, a missing cell is an error instead.
    pub fn new(grid: Box<dyn TileGrid>, fill: Vec<u8>, strict: bool) -> TiledSource {
        let header = grid.header();
        TiledSource {
            grid: Arc::from(grid),
            header,
            fill,
            strict,
            missing: Arc::default(),
            band: Vec::new(),
            band_row: None,
            next: 0,
            rewound: false,
            columns: None,
            in_flight: u64::MAX,
        }
    }

    /// Holds the run within `budget`: the band, and as many tiles read and decoded at once
    /// as the rest holds (at least one; [`memory_needed`](Self::memory_needed) says whether
    /// one fits).
    pub fn with_budget(mut self, budget: crate::limits::Budget) -> TiledSource {
        self.in_flight = budget.bytes().saturating_sub(self.band_bytes());
        self
    }

    /// Bytes a run holds at least: the band and one tile in flight.
    pub fn memory_needed(&self) -> u64 {
        self.band_bytes().saturating_add(self.tile_charge())
    }

    /// The largest size a stored tile of cell (c, r) may have: what the layout fixes, else
    /// twice the cell and its crop each way (named tiles are all meant to be the first's size).
    fn stored_bound(&self, col: u32, row: u32) -> (u32, u32) {
        self.grid.stored_size(col, row).unwrap_or_else(|| {
            let ((cw, ch), (sx, sy)) = (self.grid.cell(), self.grid.crop(col, row));
            (cw.saturating_add(sx).saturating_mul(2), ch.saturating_add(sy).saturating_mul(2))
        })
    }

    /// Bytes one tile in flight holds at most: its file, its decoded texels and its cell's
    /// texels cropped out of them; the largest over the first two cells each way (the
    /// interior ones, which carry overlap on every side).
    fn tile_charge(&self) -> u64 {
        let (h, (cw, ch)) = (self.header, self.grid.cell());
        let (cols, rows) = (h.width.div_ceil(cw), h.height.div_ceil(ch));
        let bpp = h.layout.bytes_per_pixel() as u64;
        let cell = cw as u64 * ch as u64 * bpp;
        let charge = |(c, r): (u32, u32)| {
            let (w, sh) = self.stored_bound(c, r);
            tile_file_cap(w, sh, h.layout) + w as u64 * sh as u64 * bpp + cell
        };
        [(0, 0), (1, 0), (0, 1), (1, 1)]
            .into_iter()
            .filter(|&(c, r)| c < cols && r < rows)
            .map(charge)
            .max()
            .unwrap_or(0)
    }

    /// Bytes held while a row of cells is read: the decoded cells of the row and the band
    /// they are copied into, each a cell high and the image wide.
    pub(crate) fn band_bytes(&self) -> u64 {
        let (_, ch) = self.grid.cell();
        2 * ch as u64 * self.header.width as u64 * self.header.layout.bytes_per_pixel() as u64
    }

    /// The list of cells found missing (and filled), which fills as rows are read.
    pub fn missing_log(&self) -> Arc<Mutex<Vec<String>>> {
        self.missing.clone()
    }

    fn load_row(&mut self, row: u32) -> Result<()> {
        let h = self.header;
        let (cw, ch) = self.grid.cell();
        let bpp = h.layout.bytes_per_pixel();
        let rows = ch.min(h.height - row * ch) as usize;
        let span = self.columns.clone().unwrap_or(0..h.width);
        let cols = span.start / cw..span.end.div_ceil(cw);
        let row_bytes = span.len() * bpp;
        let width_of = |col: u32| cw.min(h.width - col * cw) as usize;
        // Tiles in flight are charged against --max-memory: at most as many at once as fit.
        let at_once = (self.in_flight / self.tile_charge().max(1)).clamp(1, cols.len().max(1) as u64) as usize;
        let all: Vec<u32> = cols.clone().collect();
        let mut cells: Vec<Result<CellTexels>> = Vec::with_capacity(all.len());
        for some in all.chunks(at_once) {
            cells.par_extend(some.par_iter().map(|&col| self.cell_texels(col, row, width_of(col), rows)));
        }
        self.band.resize(rows * row_bytes, 0);
        for (col, cell) in cols.zip(cells) {
            // The part of the cell under the columns read, and where it goes in the band.
            let (cell_x0, width) = (col * cw, width_of(col));
            let from = span.start.max(cell_x0);
            let to = span.end.min(cell_x0 + width as u32);
            let (skip, x0, len) =
                ((from - cell_x0) as usize * bpp, (from - span.start) as usize * bpp, (to - from) as usize * bpp);
            match cell? {
                Some(texels) => {
                    for (y, src) in texels.chunks_exact(width * bpp).enumerate() {
                        self.band[y * row_bytes + x0..][..len].copy_from_slice(&src[skip..skip + len]);
                    }
                }
                None => {
                    for y in 0..rows {
                        for px in self.band[y * row_bytes + x0..][..len].chunks_exact_mut(bpp) {
                            px.copy_from_slice(&self.fill);
                        }
                    }
                }
            }
        }
        self.band_row = Some(row);
        Ok(())
    }

    /// The `width x rows` texels of cell (col, row), cropped out of its stored tile.
    fn cell_texels(&self, col: u32, row: u32, width: usize, rows: usize) -> Result<CellTexels> {
        let h = self.header;
        let (max_w, max_h) = self.stored_bound(col, row);
        let cap = tile_file_cap(max_w, max_h, h.layout);
        let (name, tile_w, tile_h, layout, bytes) = match self.grid.read(col, row, cap)? {
            None => {
                let name = format!("cell (x {col}, y {row})");
                if self.strict {
                    return Err(TilerError::Options(format!(
                        "{name} of {} is missing (--strict)",
                        self.grid.describe()
                    )));
                }
                if !self.rewound {
                    self.missing.lock().map_err(|_| TilerError::panicked("a tile reader"))?.push(name);
                }
                return Ok(None);
            }
            Some(CellData::File(path, bytes)) => {
                let d = decode_tile_within(&path, &bytes, (max_w, max_h))?;
                (path, d.width, d.height, d.layout, d.bytes)
            }
            Some(CellData::Samples { name, width, height, bytes }) => (name, width, height, h.layout, bytes),
        };
        if layout != h.layout {
            return Err(TilerError::decode(&name, format!("is {layout} but the other tiles are {}", h.layout)));
        }
        if let Some((w, h)) = self.grid.stored_size(col, row).filter(|s| *s != (tile_w, tile_h)) {
            return Err(TilerError::decode(
                &name,
                format!("is {tile_w}x{tile_h}, but the tiles of this input are {w}x{h} there"),
            ));
        }
        let (skip_x, skip_y) = self.grid.crop(col, row);
        if (tile_w as usize) < skip_x as usize + width || (tile_h as usize) < skip_y as usize + rows {
            return Err(TilerError::decode(
                &name,
                format!(
                    "is {tile_w}x{tile_h}, but cell (x {col}, y {row}) needs {}x{} texels",
                    skip_x as usize + width,
                    skip_y as usize + rows
                ),
            ));
        }
        let bpp = layout.bytes_per_pixel();
        let stride = tile_w as usize * bpp;
        let mut out = Vec::with_capacity(width * rows * bpp);
        for y in 0..rows {
            let start = (skip_y as usize + y) * stride + skip_x as usize * bpp;
            out.extend_from_slice(&bytes[start..start + width * bpp]);
        }
        Ok(Some(out))
    }
}

impl RowSource for TiledSource {
    fn header(&self) -> ImageHeader {
        self.header
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let (_, ch) = self.grid.cell();
        let cell_row = self.next / ch;
        if self.band_row != Some(cell_row) {
            self.load_row(cell_row)?;
        }
        let y = (self.next - cell_row * ch) as usize;
        out.copy_from_slice(&self.band[y * out.len()..(y + 1) * out.len()]);
        self.next += 1;
        Ok(())
    }

    fn describe(&self) -> String {
        self.grid.describe()
    }

    /// The cells as their JPEG files, where cells are stored without overlap (a Deep Zoom or
    /// IIIF input with overlap 0, XYZ, a pack of JPEG tiles without border) and the first is
    /// a JPEG file.
    fn stored_tiles(&self) -> Option<Arc<dyn StoredTiles>> {
        let (h, (cw, ch)) = (self.header, self.grid.cell());
        let inner = (1.min(h.width.div_ceil(cw) - 1), 1.min(h.height.div_ceil(ch) - 1));
        if self.grid.crop(0, 0) != (0, 0) || self.grid.crop(inner.0, inner.1) != (0, 0) {
            return None;
        }
        let cap = tile_file_cap(cw, ch, h.layout);
        let Ok(Some(CellData::File(_, first))) = self.grid.read(0, 0, cap) else { return None };
        let header = stored::read_header(&first).filter(|h| h.frame != 0)?;
        let quality = header.luma_table.map(|t| stored::estimate_quality(&t));
        let channels = h.layout.channels.count() as u8;
        Some(Arc::new(JpegCells { grid: Arc::clone(&self.grid), cell: (cw, ch), cap, channels, quality }))
    }

    fn rewind(&mut self) -> Result<()> {
        (self.next, self.band_row, self.rewound, self.columns) = (0, None, true, None);
        Ok(())
    }

    /// Decodes only the cells under `columns` (a stripe of a wide grid, a shard's region).
    fn read_columns(&mut self, columns: Range<u32>) -> bool {
        let columns = Some(columns).filter(|c| *c != (0..self.header.width));
        if columns != self.columns {
            (self.columns, self.band_row) = (columns, None);
        }
        true
    }

    /// Rows of cells are loaded by row: the next read loads the one it needs.
    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        self.next += rows;
        Ok(())
    }
}

/// Reads a tile file of at most `cap` bytes, or `None` if it does not exist.
/// The cells of a grid stored as JPEG files, handed out as they are.
struct JpegCells {
    grid: Arc<dyn TileGrid>,
    cell: (u32, u32),
    cap: u64,
    channels: u8,
    quality: Option<Quality>,
}

impl StoredTiles for JpegCells {
    fn tile_size(&self) -> (u32, u32) {
        self.cell
    }

    fn quality(&self) -> Option<Quality> {
        self.quality
    }

    /// The cell's file where it is a JPEG file of exactly the cell, as decoders read it
    /// (8-bit, Huffman-coded, as many components as the image); a missing cell, a PNG, an
    /// overlapping one or any other is encoded.
    fn tile(&self, col: u32, row: u32) -> Result<Option<Vec<u8>>> {
        if self.grid.crop(col, row) != (0, 0) {
            return Ok(None);
        }
        let Some(CellData::File(_, bytes)) = self.grid.read(col, row, self.cap)? else { return Ok(None) };
        let fits = stored::read_header(&bytes).is_some_and(|h| {
            matches!(h.frame, 0xC0..=0xC2)
                && h.precision == 8
                && (h.width as u32, h.height as u32) == self.cell
                && h.components == self.channels
        });
        Ok(fits.then_some(bytes))
    }
}

pub(crate) fn read_file(path: &Path, cap: u64) -> Result<Option<CellData>> {
    Ok(store::read_capped(path, cap)?.map(|bytes| CellData::File(path.to_path_buf(), bytes)))
}

/// Bytes of a tile file read to learn its size and layout: a PNG's IHDR, a JPEG's frame header
/// (after its APP segments) and WebP's lie in the first KiB or so.
const PROBE_HEAD: u64 = 1 << 20;

/// The header of the tile at `path` (size and layout), from its first bytes; a file whose
/// header lies further in (a TIFF with its directory at the end) is read whole, up to `cap`.
pub(crate) fn probe(path: &Path, cap: u64) -> Result<(u32, u32, PixelLayout)> {
    let parent = path.parent().unwrap_or(Path::new("/"));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    probe_stored(&TileStore::dir(parent), &name, cap)
}

/// The header of tile `rel` of `store` (size and layout), read from its first bytes (see
/// [`probe`]). A tile is never read whole here unless its header needs it: its size is
/// checked, against the cap of a tile of the size its header gives, before any read of it
/// ([`TiledSource`] reads each tile under that cap and `--max-memory`).
pub(crate) fn probe_stored(store: &TileStore, rel: &str, cap: u64) -> Result<(u32, u32, PixelLayout)> {
    let name = store.name(rel);
    let not_found = || TilerError::io(&name, std::io::ErrorKind::NotFound.into());
    let (head, size) = store.read_head(rel, PROBE_HEAD)?.ok_or_else(not_found)?;
    match probe_tile(&name, &head) {
        Ok((w, h, layout)) => {
            let most = tile_file_cap(w, h, layout);
            if size > most {
                let message = format!(
                    "is {}, more than a {w}x{h} {layout} tile file can be ({}): not a tile; it is not read",
                    human_bytes(size),
                    human_bytes(most)
                );
                return Err(TilerError::unsupported(&name, message));
            }
            Ok((w, h, layout))
        }
        Err(e) if size <= head.len() as u64 => Err(e),
        Err(_) => {
            let bytes = store.read(rel, cap)?.ok_or_else(not_found)?;
            probe_tile(&name, &bytes)
        }
    }
}

/// Reproducible noise bytes for the tests of the tiled inputs.
#[cfg(test)]
pub(crate) fn noise(len: usize, seed: u32) -> Vec<u8> {
    let mut state = seed.wrapping_mul(2_654_435_761).max(1);
    (0..len)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state >> 24) as u8
        })
        .collect()
}

/// The `iccProfile` member (base64) of an info.json document, decoded; `path` names the
/// document in errors.
pub(crate) fn info_icc_profile(path: &std::path::Path, json: &[u8]) -> Result<Option<Vec<u8>>> {
    use base64::Engine;
    let doc: serde_json::Value =
        serde_json::from_slice(json).map_err(|e| TilerError::decode(path, format!("not JSON: {e}")))?;
    let Some(value) = doc.get("iccProfile") else { return Ok(None) };
    let text = value.as_str().ok_or_else(|| TilerError::decode(path, "iccProfile is not a string"))?;
    let icc = base64::engine::general_purpose::STANDARD
        .decode(text)
        .map_err(|e| TilerError::decode(path, format!("iccProfile is not base64: {e}")))?;
    Ok(Some(icc))
}
