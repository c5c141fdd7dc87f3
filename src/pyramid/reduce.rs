//! Exact 2x2 reduction from one LOD to the next.
//!
//! A texel of LOD k+1 is the mean of the *real* source pixels under it. Instead of rounding a
//! mean per level (which drifts), each level passes down the exact sum of its footprint in a
//! `u64`, and only the copy that becomes a tile is rounded, once. The divisor is the number
//! of real source pixels under the texel, so texels along a right/bottom edge that is not a
//! multiple of 2^k average only real pixels and padding never tints the image.
//!
//! Rows are consumed one at a time: a level keeps one half-built output row (the horizontal
//! pair sums of an even row, waiting for the odd one), so the extra memory is one row per level.
//!
//! What is summed depends on the filter ([`crate::pyramid::filter`]): the stored samples for `box`,
//! fixed-point linear light or alpha-weighted colour for the others. Sums are `u64` unless the
//! filter's values could overflow one over the pyramid's depth; then they are `u128` ([`Acc`]).

pub use crate::pixel::{Acc, ExactRow};

/// Reduces the rows of LOD `lod` into rows of LOD `lod + levels` (one level, 2x2, but for
/// the stripes' coarse pass, which sums LOD 0 straight into a coarse level).
pub struct Reducer<A = u64> {
    channels: usize,
    /// Input texels per output texel along each axis, as a power of two.
    levels: u32,
    /// Width of the output level in texels.
    #[cfg_attr(not(feature = "testing"), allow(dead_code))] // read by the tests, through `testing`
    out_width: usize,
    /// Source pixels per output texel column, `min(footprint, width - x * footprint)` for the
    /// column's place `x` in the whole image.
    col_weight: Vec<u64>,
    /// Source image height and the output level's footprint side, to weigh rows.
    src_height: u64,
    footprint: u64,
    /// Horizontal pair sums of the rows received so far for the current output row.
    acc: Vec<A>,
    rows_in_acc: u32,
    /// Index of the output row being built.
    out_row: u64,
}

impl<A: Acc> Reducer<A> {
    /// `src_width`/`src_height` are the source image's size at LOD 0; `in_width` is the width of
    /// the input level (LOD `lod`).
    #[cfg_attr(not(feature = "testing"), allow(dead_code))] // the tests' one-level reducer
    pub fn new(src_width: u64, src_height: u64, lod: u32, in_width: usize, channels: usize) -> Reducer<A> {
        Reducer::window(src_width, src_height, lod, 1, 0, in_width, channels)
    }

    /// Reduces `levels` LODs at once, for a window of the image: `in_width` texels of LOD `lod`
    /// whose first output texel is column `out_x0` of LOD `lod + levels`. The window starts at
    /// a multiple of `2^levels` input texels and ends at one or at the image's edge, so every
    /// output texel's footprint lies in it whole.
    pub fn window(
        src_width: u64,
        src_height: u64,
        lod: u32,
        levels: u32,
        out_x0: u64,
        in_width: usize,
        channels: usize,
    ) -> Reducer<A> {
        let footprint = 1u64 << (lod + levels);
        let out_width = in_width.div_ceil(1 << levels);
        let col_weight =
            (out_x0..out_x0 + out_width as u64).map(|x| footprint.min(src_width - x * footprint)).collect();
        Reducer {
            channels,
            levels,
            out_width,
            col_weight,
            src_height,
            footprint,
            acc: vec![A::default(); out_width * channels],
            rows_in_acc: 0,
            out_row: 0,
        }
    }

    /// The same reducer for a window whose first output row is row `out_y0` of its level (a
    /// shard's region): rows are weighed by their place in the whole image.
    pub fn starting_at_row(mut self, out_y0: u64) -> Reducer<A> {
        self.out_row = out_y0;
        self
    }

    /// Texels per output row: the input width over `2^levels`, rounded up.
    #[cfg_attr(not(feature = "testing"), allow(dead_code))] // read by the tests, through `testing`
    pub fn out_width(&self) -> usize {
        self.out_width
    }

    /// Adds one input row (samples or exact sums); returns the output row once two rows are in.
    pub fn push<S: Copy + Into<A>>(&mut self, row: &[S]) -> Option<ExactRow<'_, A>> {
        self.push_mapped(row, S::into)
    }

    /// Adds one input row whose samples `value` turns into what is summed (e.g. linear light),
    /// without an intermediate row.
    pub fn push_mapped<S: Copy>(&mut self, row: &[S], value: impl Fn(S) -> A + Copy) -> Option<ExactRow<'_, A>> {
        let first = self.rows_in_acc == 0;
        match self.levels {
            1 => add_column_pairs(row, self.channels, &mut self.acc, first, value),
            _ => add_column_groups(row, self.channels, self.levels, &mut self.acc, first, value),
        }
        self.rows_in_acc += 1;
        if self.rows_in_acc == 1 << self.levels { Some(self.emit()) } else { None }
    }

    /// Emits the last output row if the input ended inside one (an odd number of rows).
    pub fn finish(&mut self) -> Option<ExactRow<'_, A>> {
        if self.rows_in_acc > 0 { Some(self.emit()) } else { None }
    }

    fn emit(&mut self) -> ExactRow<'_, A> {
        self.rows_in_acc = 0;
        let y = self.out_row;
        self.out_row += 1;
        let row_weight = self.footprint.min(self.src_height - y * self.footprint);
        let full_cols = if row_weight == self.footprint {
            self.col_weight.iter().take_while(|w| **w == self.footprint).count()
        } else {
            0
        };
        ExactRow {
            sums: &self.acc,
            y,
            row_weight,
            col_weight: &self.col_weight,
            full_cols,
            footprint: self.footprint,
            channels: self.channels,
        }
    }
}

/// `dst[x] (+)= f(src[2x]) + f(src[2x+1])` per channel; an odd last column is taken alone.
fn add_column_pairs<S: Copy, A: Acc, F: Fn(S) -> A + Copy>(src: &[S], c: usize, dst: &mut [A], assign: bool, f: F) {
    // A constant channel count lets the compiler unroll and vectorise the inner loop.
    match (c, assign) {
        (1, true) => pairs::<S, A, F, 1, true>(src, dst, f),
        (1, false) => pairs::<S, A, F, 1, false>(src, dst, f),
        (2, true) => pairs::<S, A, F, 2, true>(src, dst, f),
        (2, false) => pairs::<S, A, F, 2, false>(src, dst, f),
        (3, true) => pairs::<S, A, F, 3, true>(src, dst, f),
        (3, false) => pairs::<S, A, F, 3, false>(src, dst, f),
        (4, true) => pairs::<S, A, F, 4, true>(src, dst, f),
        (4, false) => pairs::<S, A, F, 4, false>(src, dst, f),
        _ => unreachable!("1 to 4 channels"),
    }
}

fn pairs<S: Copy, A: Acc, F: Fn(S) -> A, const C: usize, const ASSIGN: bool>(src: &[S], dst: &mut [A], f: F) {
    let pairs = src.len() / (2 * C);
    let (body, rest) = src.split_at(pairs * 2 * C);
    let (dst_body, dst_rest) = dst.split_at_mut(pairs * C);
    for (d, s) in dst_body.chunks_exact_mut(C).zip(body.chunks_exact(2 * C)) {
        for ch in 0..C {
            let v = f(s[ch]) + f(s[C + ch]);
            d[ch] = if ASSIGN { v } else { d[ch] + v };
        }
    }
    for (d, s) in dst_rest.iter_mut().zip(rest) {
        *d = if ASSIGN { f(*s) } else { *d + f(*s) };
    }
}

/// `dst[x] (+)= sum of f(src[x * 2^levels ..][.. 2^levels])` per channel; a short last group
/// is summed as far as it goes. The coarse pass's reduction, once per source row.
fn add_column_groups<S: Copy, A: Acc, F: Fn(S) -> A>(
    src: &[S],
    c: usize,
    levels: u32,
    dst: &mut [A],
    assign: bool,
    f: F,
) {
    if assign {
        dst.fill(A::default());
    }
    for (d, group) in dst.chunks_exact_mut(c).zip(src.chunks(c << levels)) {
        for px in group.chunks_exact(c) {
            for ch in 0..c {
                d[ch] = d[ch] + f(px[ch]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reduce_all(src: &[u8], w: usize, h: usize, levels: u32) -> Vec<Vec<u8>> {
        // Cascades `levels` reductions of a grey image; returns each level's rounded texels.
        let mut out = Vec::new();
        let mut rows: Vec<Vec<u64>> = src.chunks(w).map(|r| r.iter().map(|v| *v as u64).collect()).collect();
        let mut width = w;
        for lod in 0..levels {
            let mut red = Reducer::new(w as u64, h as u64, lod, width, 1);
            let mut next = Vec::new();
            let mut rounded = Vec::new();
            for r in &rows {
                if let Some(e) = red.push(r) {
                    let mut o = vec![0u8; e.sums.len()];
                    e.round_into(&mut o);
                    rounded.extend_from_slice(&o);
                    next.push(e.sums.to_vec());
                }
            }
            if let Some(e) = red.finish() {
                let mut o = vec![0u8; e.sums.len()];
                e.round_into(&mut o);
                rounded.extend_from_slice(&o);
                next.push(e.sums.to_vec());
            }
            width = red.out_width();
            out.push(rounded);
            rows = next;
        }
        out
    }

    #[test]
    fn checkerboard_becomes_mid_grey() {
        let (w, h) = (6, 4);
        let src: Vec<u8> = (0..w * h).map(|i| if (i % w + i / w) % 2 == 0 { 0 } else { 255 }).collect();
        let lods = reduce_all(&src, w, h, 1);
        assert!(lods[0].iter().all(|v| *v == 128), "{:?}", lods[0]);
    }

    #[test]
    fn edge_texels_average_only_real_pixels() {
        // 3x3 image of 200 with a 5 in the corner: the right column's LOD-1 texels cover one
        // real column and must not be darkened by padding.
        let mut src = vec![200u8; 9];
        src[8] = 5;
        let l1 = &reduce_all(&src, 3, 3, 1)[0];
        assert_eq!(l1, &vec![200, 200, 200, 5]);
        let l2 = &reduce_all(&src, 3, 3, 2)[1];
        // (8 * 200 + 5) / 9 = 178.3
        assert_eq!(l2, &vec![178]);
    }

    #[test]
    fn one_reduction_of_many_levels_equals_the_cascade() {
        // 13 x 11 texels: odd sizes, partial footprints at the right and bottom.
        let (w, h) = (13usize, 11usize);
        let src: Vec<u8> = (0..w * h).map(|i| (i * 37 % 251) as u8).collect();
        let cascade = reduce_all(&src, w, h, 3);
        let mut block = Reducer::<u64>::window(w as u64, h as u64, 0, 3, 0, w, 1);
        let mut rows = Vec::new();
        for row in src.chunks(w) {
            if let Some(e) = block.push(row) {
                let mut o = vec![0u8; e.sums.len()];
                e.round_into(&mut o);
                rows.extend(o);
            }
        }
        let e = block.finish().unwrap();
        let mut o = vec![0u8; e.sums.len()];
        e.round_into(&mut o);
        rows.extend(o);
        assert_eq!(rows, cascade[2]);
    }

    #[test]
    fn a_window_weighs_its_columns_by_their_place_in_the_image() {
        // The right half (from column 8) of a 13-texel row: LOD 1 columns 4..7, the last one
        // covering one real texel.
        let (w, h) = (13usize, 2usize);
        let src: Vec<u8> = (0..w * h).map(|i| (i * 53 % 256) as u8).collect();
        let whole = &reduce_all(&src, w, h, 1)[0];
        let mut half = Reducer::<u64>::window(w as u64, h as u64, 0, 1, 4, w - 8, 1);
        half.push(&src[8..w]);
        let e = half.push(&src[w + 8..]).unwrap();
        let mut o = vec![0u8; e.sums.len()];
        e.round_into(&mut o);
        assert_eq!(o, whole[4..]);
    }
}
