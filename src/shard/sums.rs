//! A shard's root sums as stored: the exact sums of a rectangle of the cut level, row by row,
//! each row's sums split into byte planes (every sum's lowest byte, then the next, ...) and
//! the rows compressed as one zstd stream. Sums of `4^K` samples are a few bits wider than a
//! sample and their high bytes are zero: the planes let zstd drop those bytes, so the sums
//! cost about what the texels of the cut level would. `merge` reads them back a row at a time.

use std::io::{Read, Write};
use std::ops::Range;

use crate::error::{Result, TilerError};
use crate::pyramid::cascade::RootSums;
use crate::pyramid::reduce::Acc;

/// zstd level of the sums: fast, and the planes do most of the work.
const LEVEL: i32 = 3;

/// Compresses `roots` (`channels` sums per texel).
pub(crate) fn encode<A: Acc>(roots: &RootSums<A>, channels: usize) -> Result<Vec<u8>> {
    let samples = (roots.columns.end - roots.columns.start) as usize * channels;
    let failed = |e: std::io::Error| TilerError::Options(format!("compressing the root sums: {e}"));
    let mut z = zstd::stream::Encoder::new(Vec::new(), LEVEL).map_err(failed)?;
    let mut planes = vec![0u8; samples * A::BYTES];
    let mut le = [0u8; 16];
    for row in roots.sums.chunks_exact(samples.max(1)) {
        for (i, &sum) in row.iter().enumerate() {
            sum.to_le(&mut le[..A::BYTES]);
            for (b, &byte) in le[..A::BYTES].iter().enumerate() {
                planes[b * samples + i] = byte;
            }
        }
        z.write_all(&planes).map_err(failed)?;
    }
    z.finish().map_err(failed)
}

/// Reads the rows of one stored rectangle back, in order.
pub(crate) struct RowReader<'a> {
    decoder: zstd::stream::read::Decoder<'static, std::io::BufReader<&'a [u8]>>,
    planes: Vec<u8>,
    pub columns: Range<u64>,
    pub rows: Range<u64>,
    next: u64,
}

impl<'a> RowReader<'a> {
    pub fn new(
        bytes: &'a [u8],
        columns: Range<u64>,
        rows: Range<u64>,
        channels: usize,
        sum_bytes: usize,
    ) -> Result<Self> {
        let decoder = zstd::stream::read::Decoder::new(bytes)
            .map_err(|e| TilerError::Options(format!("reading the root sums: {e}")))?;
        let samples = (columns.end - columns.start) as usize * channels;
        let next = rows.start;
        Ok(RowReader { decoder, planes: vec![0; samples * sum_bytes], columns, rows, next })
    }

    /// The next row's sums into `out` (the rectangle's width x channels).
    pub fn read_into<A: Acc>(&mut self, out: &mut [A]) -> std::result::Result<(), String> {
        if self.next >= self.rows.end {
            return Err(format!("row {} is past the rectangle's last row {}", self.next, self.rows.end - 1));
        }
        self.decoder
            .read_exact(&mut self.planes)
            .map_err(|e| format!("the sums of row {} do not decompress: {e}", self.next))?;
        let samples = out.len();
        let mut le = [0u8; 16];
        for (i, o) in out.iter_mut().enumerate() {
            for (b, byte) in le[..A::BYTES].iter_mut().enumerate() {
                *byte = self.planes[b * samples + i];
            }
            *o = A::from_le(&le[..A::BYTES]);
        }
        self.next += 1;
        Ok(())
    }

    /// Whether every row has been read and nothing follows.
    pub fn is_complete(&mut self) -> bool {
        let mut byte = [0u8; 1];
        self.next == self.rows.end && matches!(self.decoder.read(&mut byte), Ok(0))
    }
}

/// One rectangle of a shard's roots, compressed: texel columns and rows of the cut level.
#[derive(Clone, Debug)]
pub struct EncodedRoots {
    pub columns: Range<u64>,
    pub rows: Range<u64>,
    pub bytes: Vec<u8>,
}
