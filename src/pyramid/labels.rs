//! The label filters (`mode`, `nearest`), for segmentation images whose values name objects:
//! a mean invents labels that no object has, so each texel of the next level is instead one of
//! the texels of its 2x2 block in the level above it.
//!
//! * `nearest`: the block's top-left texel (the one at even coordinates).
//! * `mode`: the texel value the block holds most often; between values held equally often,
//!   the first in the order top-left, top-right, bottom-left, bottom-right. (So a block of four
//!   different labels gives its top-left one, as `nearest` does.)
//!
//! At a level's right and bottom edges a block has only the texels inside the level (two, or
//! one at the corner); nothing is padded in. Texels are compared whole (every channel), so any
//! channel layout works. Each level is made from the previous one, row pair by row pair, in
//! memory of one row.

use crate::pixel::Sample;
use crate::pyramid::filter::Filter;

/// Makes the rows of one level's next level from its rows.
pub struct LabelReducer<T> {
    mode: bool,
    channels: usize,
    in_width: usize,
    in_height: u64,
    received: u64,
    /// The even row of the block row being read.
    top: Vec<T>,
    out: Vec<T>,
}

impl<T: Sample> LabelReducer<T> {
    /// For a level of `in_width x in_height` texels of `channels` samples.
    pub fn new(filter: Filter, channels: usize, in_width: usize, in_height: u64) -> LabelReducer<T> {
        debug_assert!(filter.is_label(), "{filter} is not a label filter");
        LabelReducer {
            mode: filter == Filter::Mode,
            channels,
            in_width,
            in_height,
            received: 0,
            top: Vec::with_capacity(in_width * channels),
            out: vec![T::default(); in_width.div_ceil(2) * channels],
        }
    }

    /// Takes the level's next row; gives the next level's row once its block's rows are in (the
    /// last row alone where the height is odd).
    pub fn push(&mut self, row: &[T]) -> Option<&[T]> {
        let y = self.received;
        self.received += 1;
        if y.is_multiple_of(2) {
            self.top.clear();
            self.top.extend_from_slice(row);
            if self.received < self.in_height {
                return None;
            }
            let top = std::mem::take(&mut self.top);
            self.reduce(&top, None);
            self.top = top;
        } else {
            let top = std::mem::take(&mut self.top);
            self.reduce(&top, Some(row));
            self.top = top;
        }
        Some(&self.out)
    }

    fn reduce(&mut self, top: &[T], bottom: Option<&[T]>) {
        let (c, width) = (self.channels, self.in_width);
        fn texel<T>(row: &[T], x: usize, width: usize, c: usize) -> Option<&[T]> {
            (x < width).then(|| &row[x * c..x * c + c])
        }
        for ox in 0..width.div_ceil(2) {
            let (left, right) = (2 * ox, 2 * ox + 1);
            let mut block = [texel(top, left, width, c), texel(top, right, width, c), None, None];
            if let Some(b) = bottom {
                block[2] = texel(b, left, width, c);
                block[3] = texel(b, right, width, c);
            }
            let chosen = choose(self.mode, &block);
            self.out[ox * c..ox * c + c].copy_from_slice(chosen);
        }
    }
}

/// The texel a block gives: its first (top-left) for `nearest`, its most frequent for `mode`
/// (ties to the first in block order). `block` is top-left, top-right, bottom-left,
/// bottom-right, `None` where the level ends; the top-left is always there.
#[expect(clippy::expect_used, reason = "a block always has its top-left texel")]
pub fn choose<'a, T: PartialEq>(mode: bool, block: &[Option<&'a [T]>; 4]) -> &'a [T] {
    let first = block[0].expect("a block has its top-left texel");
    if !mode {
        return first;
    }
    let mut best = (first, 0);
    for candidate in block.iter().flatten() {
        let count = block.iter().flatten().filter(|t| *t == candidate).count();
        // Strictly more: an equal count keeps the earlier texel.
        if count > best.1 {
            best = (candidate, count);
        }
    }
    best.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn block(values: [Option<u16>; 4]) -> [Option<Vec<u16>>; 4] {
        values.map(|v| v.map(|v| vec![v]))
    }

    fn pick(mode: bool, values: [Option<u16>; 4]) -> u16 {
        let owned = block(values);
        let refs: [Option<&[u16]>; 4] = [0, 1, 2, 3].map(|i| owned[i].as_deref());
        choose(mode, &refs)[0]
    }

    #[test]
    fn mode_takes_the_most_frequent_and_ties_go_to_the_first() {
        assert_eq!(pick(true, [Some(1), Some(2), Some(2), Some(3)]), 2);
        assert_eq!(pick(true, [Some(1), Some(2), Some(3), Some(4)]), 1);
        assert_eq!(pick(true, [Some(5), Some(7), Some(7), Some(5)]), 5);
        assert_eq!(pick(true, [Some(9), Some(7), Some(8), Some(7)]), 7);
        assert_eq!(pick(true, [Some(9), None, Some(4), None]), 9);
        assert_eq!(pick(false, [Some(9), Some(7), Some(7), Some(7)]), 9);
    }

    #[test]
    fn odd_levels_use_only_their_own_texels() {
        // 3 x 3 level, one channel: the next level is 2 x 2.
        let rows: [[u8; 3]; 3] = [[1, 2, 3], [2, 2, 4], [5, 6, 6]];
        let mut r = LabelReducer::<u8>::new(Filter::Mode, 1, 3, 3);
        assert_eq!(r.push(&rows[0]), None);
        assert_eq!(r.push(&rows[1]), Some(&[2u8, 3][..]));
        assert_eq!(r.push(&rows[2]), Some(&[5u8, 6][..]));
    }
}
