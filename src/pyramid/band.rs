//! A horizontal band of one LOD, held as the tiles it is cut into.
//!
//! A row of tiles of LOD k reads `payload + 2 * border` rows of its level. Each row, as it
//! arrives, is copied straight into every tile of every row of tiles that reads it (two where
//! borders overlap), so a texel is copied once between the pyramid and the encoders: a band of
//! rows cut into tiles once complete copied it twice, the larger part of the cutting thread's
//! time (issue 18). A row of tiles is handed on, complete, once its last row is in. The band
//! therefore holds one row of tiles of its level's width, and the border rows the next one
//! shares with it (more only where a border is over half the payload), whatever the image
//! height.

use std::collections::VecDeque;
use std::ops::Range;

use crate::layout::Layout;
use crate::pyramid::cut::{self, Padding, Run};

pub struct Band<T> {
    layout: Layout,
    lod: u32,
    channels: usize,
    /// The level's image height and its virtual texture's (the pages' payloads).
    height: u32,
    virtual_height: u64,
    edge_padding: bool,
    /// Per page column cut: its index, and which of a row's columns its texels come from.
    x_runs: Vec<(u32, Vec<Run>)>,
    /// Rows of tiles begun and not complete, top first.
    open: VecDeque<OpenRow<T>>,
    /// The next row of tiles to begin, and one past the last.
    next_tile_row: u32,
    end_tile_row: u32,
    /// Image row index of the next row to arrive.
    next_row: u64,
    /// Whether the tiles get their texels: not where the level's pages are the source's stored
    /// tiles, handed on with their one colour at most when their rows are in
    /// ([`Band::drop_texels`]).
    texels: bool,
}

/// A row of tiles being filled.
struct OpenRow<T> {
    index: u32,
    /// Per row of the tiles, top to bottom: the image row it holds (`None`: the background).
    sources: Vec<Option<u32>>,
    /// Rows of the tiles written so far.
    written: usize,
    /// One per entry of `x_runs`: its texels; without texels, the one colour of every texel
    /// so far (empty before the first, and once two differ).
    tiles: Vec<Vec<T>>,
    /// Without texels: per tile, whether two of its texels differ.
    varied: Vec<bool>,
}

/// A complete row of tiles: its index, and each tile's column and texels, left to right (without
/// texels, [`Band::drop_texels`]: the tile's one colour, or nothing where it has more than one).
pub struct TileRow<T> {
    pub index: u32,
    pub tiles: Vec<(u32, Vec<T>)>,
}

impl<T: Copy + PartialEq> Band<T> {
    /// The band of level `lod` that cuts the page columns of `x_runs` (whose
    /// runs index the rows it is given) in the rows of tiles `tile_rows`, given the level's
    /// rows from image row `first_row` on (a span's window may start above its first tile's).
    pub fn new(
        layout: Layout,
        lod: u32,
        channels: usize,
        x_runs: Vec<(u32, Vec<Run>)>,
        tile_rows: Range<u32>,
        first_row: u64,
        edge_padding: bool,
    ) -> Band<T> {
        Band {
            layout,
            lod,
            channels,
            height: layout.level_extent(lod).1,
            virtual_height: layout.virtual_extent(lod).1,
            edge_padding,
            x_runs,
            open: VecDeque::new(),
            next_row: first_row,
            next_tile_row: tile_rows.start,
            end_tile_row: tile_rows.end,
            texels: true,
        }
    }

    /// From now on, the band hands on its rows of tiles when their rows are in, as it would,
    /// but with no texels in them: only a tile all of whose texels are one colour holds it (one
    /// texel), which is all a pack needs of a page it copies (whether to store it as a colour).
    /// Each tile's texels are compared as they arrive, until two differ.
    pub fn drop_texels(&mut self) {
        self.texels = false;
    }

    pub fn lod(&self) -> u32 {
        self.lod
    }

    /// Bytes of the rows of tiles being filled (their capacity), for the memory gauge.
    pub fn held_bytes(&self) -> usize {
        let texels: usize = self.open.iter().flat_map(|open| &open.tiles).map(Vec::capacity).sum();
        texels * size_of::<T>()
    }

    /// Copies the next row into every tile that holds it; `done` gets each row of tiles this
    /// completes, top first.
    pub fn push<E>(
        &mut self,
        row: &[T],
        padding: &Padding<T>,
        mut done: impl FnMut(TileRow<T>) -> Result<(), E>,
    ) -> Result<(), E> {
        let y = self.next_row;
        self.next_row += 1;
        while self.next_tile_row < self.end_tile_row && cut::first_row_read(&self.layout, self.next_tile_row) <= y {
            let open = self.begin(self.next_tile_row);
            self.open.push_back(open);
            self.next_tile_row += 1;
        }
        let fill = match padding {
            Padding::Colour(c) => c.as_slice(),
            Padding::Edge => &[],
        };
        for open in &mut self.open {
            // Rows repeat where a border reaches past the virtual edge; the background rows
            // below an image that ends inside its last page come after its last row.
            while let Some(&source) = open.sources.get(open.written) {
                let texels = match source {
                    Some(s) if s as u64 == y => Some(row),
                    Some(_) => break,
                    None => None,
                };
                if self.texels {
                    for (tile, (_, runs)) in open.tiles.iter_mut().zip(&self.x_runs) {
                        cut::push_row(tile, runs, texels, self.channels, fill);
                    }
                } else {
                    let tiles = open.tiles.iter_mut().zip(&mut open.varied).zip(&self.x_runs);
                    for ((colour, varied), (_, runs)) in tiles.filter(|((_, varied), _)| !**varied) {
                        if !cut::narrow_colour(colour, runs, texels, self.channels, fill) {
                            *varied = true;
                            *colour = Vec::new();
                        }
                    }
                }
                open.written += 1;
            }
        }
        let complete = self.open.iter().take_while(|open| open.written == open.sources.len()).count();
        for open in self.open.drain(..complete) {
            let tiles = self.x_runs.iter().map(|(x, _)| *x).zip(open.tiles).collect();
            done(TileRow { index: open.index, tiles })?;
        }
        if complete > 0
            && self.texels
            && let Some(front) = self.open.front_mut()
        {
            let texels = self.layout.tile_texels() * self.channels;
            for tile in &mut front.tiles {
                tile.reserve_exact(texels - tile.len());
            }
        }
        Ok(())
    }

    /// A row of tiles whose first rows arrive: its tiles have room for all their texels if it
    /// is the only one open; below another (the rows their borders share), only once the one
    /// above is handed on, so that a band never holds two rows of tiles' worth of memory while
    /// the encoders' queue is full (12 MiB more at a 16384-texel width, issue 28).
    fn begin(&self, index: u32) -> OpenRow<T> {
        let sources = cut::expand(&cut::runs(&self.layout, index, self.height, self.virtual_height, self.edge_padding));
        let texels = if self.open.is_empty() && self.texels { self.layout.tile_texels() * self.channels } else { 0 };
        let tiles = self.x_runs.iter().map(|_| Vec::with_capacity(texels)).collect();
        OpenRow { index, sources, written: 0, tiles, varied: vec![false; self.x_runs.len()] }
    }
}

/// Bytes a band cutting `pages` page columns of `texel_bytes`-byte texels holds at most, for the
/// plan ([`crate::pyramid::stripes`]), from what [`Band::push`] and `begin` allocate: the front
/// row of tiles whole (reserved exactly), and each row of tiles below it that has begun (it
/// shares the rows its border reads) grown row by row: up to twice those rows, as a `Vec`
/// grows, plus its smallest allocation (8 samples of at most 4 bytes).
pub fn most_bytes(layout: &Layout, pages: u64, texel_bytes: u64) -> u64 {
    let (tile, payload) = (layout.tile_size as u64, layout.payload() as u64);
    // Rows of tiles `j` below the front one read `tile - j * payload` of its rows.
    let shared_rows: u64 = (1..).map(|j| tile.saturating_sub(j * payload)).take_while(|&rows| rows > 0).sum();
    let per_page = (tile * tile + 2 * shared_rows * tile) * texel_bytes + 32 * tile.div_ceil(payload);
    pages.saturating_mul(per_page)
}

/// Bytes (capacity) of one tile a band hands on, at most: its texels, reserved exactly, unless
/// the rows it shared with the row of tiles above had grown it past them already.
pub fn most_tile_bytes(layout: &Layout, texel_bytes: u64) -> u64 {
    let (tile, payload) = (layout.tile_size as u64, layout.payload() as u64);
    (tile * tile).max(2 * tile.saturating_sub(payload) * tile) * texel_bytes + 32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The image texel a tile's texel `i` along one direction holds, from the page geometry
    /// alone (not from `cut::runs`): virtual texel `t * payload - border + i`, clamped to the
    /// virtual texture, then the image's last texel (edge) or `None` (background) past it.
    fn naive(layout: &Layout, t: u32, i: u32, extent: u32, virtual_len: u64, edge: bool) -> Option<u32> {
        let v = (t as i64 * layout.payload() as i64 - layout.border as i64 + i as i64).clamp(0, virtual_len as i64 - 1);
        if v < extent as i64 { Some(v as u32) } else { edge.then_some(extent - 1) }
    }

    /// Every row of tiles of a `w x h` one-channel image whose texel (x, y) is `y * 100 + x`
    /// (9999 for the background), cut through a band, against [`naive`].
    fn check(w: u32, h: u32, tile: u32, border: u32, padding: Padding<u16>) {
        let layout = Layout::new(w as u64, h as u64, tile, border).unwrap();
        let edge = padding == Padding::Edge;
        let (virtual_w, virtual_h) = layout.virtual_extent(0);
        let x_runs: Vec<(u32, Vec<Run>)> =
            (0..layout.columns).map(|t| (t, cut::runs(&layout, t, w, virtual_w, edge))).collect();
        let mut band = Band::new(layout, 0, 1, x_runs, 0..layout.rows, 0, edge);
        let mut got = Vec::new();
        for y in 0..h {
            let row: Vec<u16> = (0..w).map(|x| (y * 100 + x) as u16).collect();
            band.push(&row, &padding, |r| -> Result<(), ()> {
                got.push(r);
                Ok(())
            })
            .unwrap();
        }
        assert_eq!(got.iter().map(|r| r.index).collect::<Vec<_>>(), (0..layout.rows).collect::<Vec<_>>());
        for r in &got {
            assert_eq!(r.tiles.iter().map(|(tx, _)| *tx).collect::<Vec<_>>(), (0..layout.columns).collect::<Vec<_>>());
            for (tx, texels) in &r.tiles {
                let want: Vec<u16> = (0..tile)
                    .flat_map(|j| (0..tile).map(move |i| (i, j)))
                    .map(|(i, j)| {
                        let x = naive(&layout, *tx, i, w, virtual_w, edge);
                        let y = naive(&layout, r.index, j, h, virtual_h, edge);
                        x.zip(y).map_or(9999, |(x, y)| (y * 100 + x) as u16)
                    })
                    .collect();
                assert_eq!(texels, &want, "{w}x{h} tile {tile} border {border}: tile ({tx}, {})", r.index);
            }
        }
    }

    #[test]
    fn every_tile_holds_what_its_geometry_says() {
        for (w, h) in [(1, 1), (20, 20), (24, 24), (13, 7), (7, 40), (29, 31)] {
            for (tile, border) in [(16, 2), (8, 0), (8, 1), (8, 2), (16, 5)] {
                check(w, h, tile, border, Padding::Edge);
                check(w, h, tile, border, Padding::Colour(vec![9999]));
            }
        }
    }
}
