//! A horizontal band of one LOD: the few real rows that the next row of tiles needs.
//!
//! A tile row of LOD k needs `payload + 2 * border` rows; once it is cut, only the rows the next
//! tile row shares with it (its top border) are kept. The band therefore never holds more than
//! `tile_size` rows of its level's width, whatever the image height.

pub struct Band<T> {
    /// Samples per row (texels x channels).
    row_len: usize,
    /// Image row index of the first row held.
    first: u64,
    data: Vec<T>,
}

impl<T: Copy> Band<T> {
    #[cfg(test)]
    pub fn new(row_len: usize, capacity_rows: usize) -> Band<T> {
        Band::starting_at(0, row_len, capacity_rows)
    }

    /// A band whose first row will be image row `first` (a shard's region starts below the top).
    pub fn starting_at(first: u64, row_len: usize, capacity_rows: usize) -> Band<T> {
        Band { row_len, first, data: Vec::with_capacity(row_len * capacity_rows) }
    }

    /// One past the last row held (= rows received so far).
    pub fn end(&self) -> u64 {
        self.first + (self.data.len() / self.row_len.max(1)) as u64
    }

    pub fn push(&mut self, row: &[T]) {
        debug_assert_eq!(row.len(), self.row_len);
        self.data.extend_from_slice(row);
    }

    /// Row `y` of the image; it must be held.
    pub fn row(&self, y: u64) -> &[T] {
        assert!(y >= self.first && y < self.end(), "row {y} is not in the band [{}, {})", self.first, self.end());
        let start = (y - self.first) as usize * self.row_len;
        &self.data[start..start + self.row_len]
    }

    /// Forgets every row before `y`.
    pub fn drop_before(&mut self, y: u64) {
        let y = y.min(self.end());
        if y > self.first {
            let n = (y - self.first) as usize * self.row_len;
            self.data.drain(..n);
            self.first = y;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_rows_by_image_index() {
        let mut b = Band::new(2, 4);
        for y in 0..5u8 {
            b.push(&[y, y]);
        }
        b.drop_before(3);
        assert_eq!((b.end(), b.row(3), b.row(4)), (5, &[3u8, 3][..], &[4u8, 4][..]));
        b.drop_before(99);
        assert_eq!(b.end(), 5);
    }
}
