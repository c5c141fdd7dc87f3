//! Cutting stored tiles (payload plus borders) out of a band.
//!
//! A stored tile at `(x, y)` of LOD k covers virtual texels `[x*P - B, x*P + P + B)` in both
//! directions. Coordinates outside the virtual texture (its page grid) repeat its edge texels;
//! coordinates in the padding between the image and the virtual edge (inside the last page of
//! a row or column) repeat the image's last texel ("edge") or take the background colour.
//! Each direction is precomputed once per tile column or row as a few runs, so cutting is
//! mostly `memcpy` ([`band`](super::band) does it, a row at a time).

use crate::layout::Layout;

/// Where the texels of one direction of a tile come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Run {
    /// `len` real texels starting at `start`.
    Copy { start: u32, len: u32 },
    /// The real texel `at`, `len` times.
    Repeat { at: u32, len: u32 },
    /// The background colour, `len` times.
    Fill { len: u32 },
}

/// What fills the padding between the image and the virtual texture's edge.
#[derive(Clone, Debug, PartialEq)]
pub enum Padding<T> {
    /// Repeat the nearest image texel.
    Edge,
    /// One texel of this colour (`channels` samples).
    Colour(Vec<T>),
}

/// The runs for tile index `t` along a direction where the level's image has `extent` texels
/// and its virtual texture `virtual_len` (the pages' payloads side by side).
pub fn runs(layout: &Layout, t: u32, extent: u32, virtual_len: u64, edge_padding: bool) -> Vec<Run> {
    let p = layout.payload() as i64;
    let last_virtual = virtual_len as i64 - 1;
    let start = t as i64 * p - layout.border as i64;
    let mut out: Vec<Run> = Vec::new();
    for i in 0..layout.tile_size as i64 {
        let v = (start + i).clamp(0, last_virtual);
        let src = if v < extent as i64 {
            Some(v as u32)
        } else if edge_padding {
            Some(extent - 1)
        } else {
            None
        };
        match (out.last_mut(), src) {
            (Some(Run::Fill { len }), None) => *len += 1,
            (Some(Run::Repeat { at, len }), Some(s)) if *at == s => *len += 1,
            (Some(Run::Copy { start, len }), Some(s)) if *start + *len == s => *len += 1,
            (Some(Run::Copy { start, len }), Some(s)) if *start + *len - 1 == s => {
                // The texel just copied repeats: end the copy one early, start a repeat.
                *len -= 1;
                let drop_empty = *len == 0;
                if drop_empty {
                    out.pop();
                }
                out.push(Run::Repeat { at: s, len: 2 });
            }
            (_, Some(s)) => out.push(Run::Copy { start: s, len: 1 }),
            (_, None) => out.push(Run::Fill { len: 1 }),
        }
    }
    out
}

/// The first texel of page `t` along one direction that [`runs`] fills with the background
/// when it does not repeat the edge (the page's texels from there on lie past the image), or
/// the tile size where none does: what a page cut with edge padding needs filled to be the
/// page cut with a colour.
pub fn padding_from(layout: &Layout, t: u32, extent: u32, virtual_len: u64) -> u32 {
    let start = t as i64 * layout.payload() as i64 - layout.border as i64;
    let last_virtual = virtual_len as i64 - 1;
    (0..layout.tile_size)
        .find(|&i| (start + i as i64).clamp(0, last_virtual) >= extent as i64)
        .unwrap_or(layout.tile_size)
}

/// Fills the texels of a `side`-texel square tile (`channels` samples each) at or past
/// `from` (column, row) with `texel`: the tile cut with edge padding made the tile cut with
/// that colour ([`padding_from`]).
pub fn fill_padding<T: Copy>(tile: &mut [T], side: u32, channels: usize, from: (u32, u32), texel: &[T]) {
    let row_len = side as usize * channels;
    for (y, row) in tile.chunks_exact_mut(row_len).enumerate() {
        let first = if y as u32 >= from.1 { 0 } else { from.0 as usize };
        for t in row[first * channels..].chunks_exact_mut(channels) {
            t.copy_from_slice(texel);
        }
    }
}

/// `runs` for a band whose first column is image column `origin`.
pub fn shifted(runs: Vec<Run>, origin: u64) -> Vec<Run> {
    let by = origin as u32;
    runs.into_iter()
        .map(|run| match run {
            Run::Copy { start, len } => Run::Copy { start: start - by, len },
            Run::Repeat { at, len } => Run::Repeat { at: at - by, len },
            fill => fill,
        })
        .collect()
}

/// Appends one row of a tile to `out`: `x_runs` pick the columns of `row`, or of the background
/// `fill` (one texel) where `row` is `None`.
pub fn push_row<T: Copy>(out: &mut Vec<T>, x_runs: &[Run], row: Option<&[T]>, channels: usize, fill: &[T]) {
    for run in x_runs {
        match (*run, row) {
            (Run::Copy { start, len }, Some(r)) => {
                out.extend_from_slice(&r[start as usize * channels..(start + len) as usize * channels])
            }
            (Run::Repeat { at, len }, Some(r)) => {
                repeat_texel(out, &r[at as usize * channels..(at as usize + 1) * channels], len)
            }
            (Run::Copy { len, .. } | Run::Repeat { len, .. } | Run::Fill { len }, _) => repeat_texel(out, fill, len),
        }
    }
}

/// Whether every texel of one row of a tile, picked as [`push_row`] picks them, is `colour`
/// (one texel; where it is empty, it becomes the row's first texel). Stops at the first texel
/// that differs.
pub fn narrow_colour<T: Copy + PartialEq>(
    colour: &mut Vec<T>,
    x_runs: &[Run],
    row: Option<&[T]>,
    channels: usize,
    fill: &[T],
) -> bool {
    for run in x_runs {
        let texels = match (*run, row) {
            (Run::Copy { start, len }, Some(r)) => &r[start as usize * channels..(start + len) as usize * channels],
            (Run::Repeat { at, len }, Some(r)) if len > 0 => &r[at as usize * channels..(at as usize + 1) * channels],
            (Run::Copy { len, .. } | Run::Repeat { len, .. } | Run::Fill { len }, _) if len > 0 => fill,
            _ => &[],
        };
        if texels.is_empty() {
            continue;
        }
        if colour.is_empty() {
            colour.extend_from_slice(&texels[..channels]);
        }
        if !texels.chunks_exact(channels).all(|t| t == &colour[..]) {
            return false;
        }
    }
    true
}

/// Each texel of `runs` in turn: the real texel it holds, or `None` for the background.
pub fn expand(runs: &[Run]) -> Vec<Option<u32>> {
    let mut out = Vec::new();
    for run in runs {
        match *run {
            Run::Copy { start, len } => out.extend((start..start + len).map(Some)),
            Run::Repeat { at, len } => out.extend(std::iter::repeat_n(Some(at), len as usize)),
            Run::Fill { len } => out.extend(std::iter::repeat_n(None, len as usize)),
        }
    }
    out
}

/// Appends `len` copies of `texel`, doubling what is already written instead of copying
/// one texel at a time.
fn repeat_texel<T: Copy>(out: &mut Vec<T>, texel: &[T], len: u32) {
    let start = out.len();
    let total = texel.len() * len as usize;
    if total == 0 {
        return;
    }
    out.extend_from_slice(texel);
    while out.len() - start < total {
        let have = out.len() - start;
        out.extend_from_within(start..start + have.min(total - have));
    }
}

/// Last image row (inclusive) that tile row `t` of a level with `extent` rows reads.
pub fn last_row_needed(layout: &Layout, t: u32, extent: u32) -> u64 {
    let end = (t as u64 + 1) * layout.payload() as u64 + layout.border as u64;
    (end - 1).min(extent as u64 - 1)
}

/// First image row that tile row `t` reads (real texels start above the image's last row:
/// a row of tiles exists only where its payload does).
pub fn first_row_read(layout: &Layout, t: u32) -> u64 {
    (t as u64 * layout.payload() as u64).saturating_sub(layout.border as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn border_repeats_the_virtual_edge() {
        // 16-texel tiles, border 2: payload 12. A 20-texel image needs 2 pages.
        let l = Layout::new(20, 20, 16, 2).unwrap();
        let v = l.virtual_extent(0).0;
        let r0 = runs(&l, 0, 20, v, true);
        let want: Vec<Option<u32>> = [0, 0, 0].into_iter().chain(1..14).map(Some).collect();
        assert_eq!(expand(&r0), want);
        assert_eq!(r0[0], Run::Repeat { at: 0, len: 3 });
        // Second tile: texels 10..26, the image ends at 19, the virtual texture at 23.
        let edge = expand(&runs(&l, 1, 20, v, true));
        let want: Vec<Option<u32>> = (10..20).chain([19; 6]).map(Some).collect();
        assert_eq!(edge, want);
        let bg = expand(&runs(&l, 1, 20, v, false));
        let want: Vec<Option<u32>> = (10..20).map(Some).chain([None; 6]).collect();
        assert_eq!(bg, want);
    }

    /// `padding_from` is where `runs` without edge padding first fills, for grids with and
    /// without a border, at every page of every level.
    #[test]
    fn padding_starts_where_the_runs_fill() {
        for (w, tile, border) in [(20, 16, 2), (24, 16, 2), (1003, 256, 0), (1, 8, 0), (300, 254, 1), (17, 10, 3)] {
            let l = Layout::new(w, w, tile, border).unwrap();
            for lod in 0..l.lod_count {
                let (extent, _) = l.level_extent(lod);
                let virtual_len = l.virtual_extent(lod).0;
                for t in 0..l.grid(lod).0 {
                    let filled = expand(&runs(&l, t, extent, virtual_len, false)).iter().position(Option::is_none);
                    let want = filled.map_or(tile, |i| i as u32);
                    assert_eq!(
                        padding_from(&l, t, extent, virtual_len),
                        want,
                        "{w} {tile} {border} lod {lod} page {t}"
                    );
                }
            }
        }
    }

    #[test]
    fn full_image_repeats_last_texel_not_background() {
        // 24 texels fill the virtual texture exactly: the right border repeats texel 23.
        let l = Layout::new(24, 24, 16, 2).unwrap();
        let r = expand(&runs(&l, 1, 24, l.virtual_extent(0).0, false));
        let want: Vec<Option<u32>> = (10..24).chain([23, 23]).map(Some).collect();
        assert_eq!(r, want);
    }
}
