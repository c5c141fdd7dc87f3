//! A shard's root sums as stored: the exact sums of a rectangle of the cut level, row by row,
//! each row's sums split into byte planes (every sum's lowest byte, then the next, ...) and
//! the rows compressed as one zstd stream. Sums of `4^K` samples are a few bits wider than a
//! sample and their high bytes are zero: the planes let zstd drop those bytes, so the sums
//! cost about what the texels of the cut level would. `merge` reads them back a row at a time.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::ops::Range;
use std::path::Path;

use super::manifest::shard_error;
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

/// The rows of exact sums of the level above the cut, each added up from the shards'
/// rectangles that hold part of it (two, where a rectangle's edge halves an odd number of
/// texels). A rectangle's decoder lives only while its rows are read, so memory is the
/// rectangles of one row of roots.
pub(crate) struct RootRows<'a> {
    bound: SumBound,
    /// Rectangles not started, by first row.
    waiting: VecDeque<(&'a Path, RowReader<'a>)>,
    /// Rectangles being read.
    reading: Vec<(&'a Path, RowReader<'a>)>,
}

impl<'a> RootRows<'a> {
    pub(crate) fn new(bound: SumBound) -> Self {
        RootRows { bound, waiting: VecDeque::new(), reading: Vec::new() }
    }

    pub(crate) fn add(&mut self, path: &'a Path, reader: RowReader<'a>) {
        let at = self.waiting.partition_point(|(_, r)| r.rows.start <= reader.rows.start);
        self.waiting.insert(at, (path, reader));
    }

    /// The level the rows are of.
    pub fn lod(&self) -> u32 {
        self.bound.lod
    }

    /// Row `y` (rows are read in order, each once) into `out`, the level's width of sums.
    pub fn read<A: Acc>(&mut self, y: u64, out: &mut [A]) -> Result<()> {
        while self.waiting.front().is_some_and(|(_, r)| r.rows.start <= y) {
            self.reading.extend(self.waiting.pop_front());
        }
        out.fill(A::default());
        let c = self.bound.channels;
        let lod = self.bound.lod;
        let mut part = Vec::new();
        for (path, reader) in &mut self.reading {
            let columns = reader.columns.start as usize * c..reader.columns.end as usize * c;
            if columns.end > out.len() {
                return Err(shard_error(path, format!("its root sums reach past the image at row {y} of LOD {lod}")));
            }
            let first = columns.start;
            part.resize(columns.len(), A::default());
            reader.read_into(&mut part).map_err(|m| shard_error(path, m))?;
            for (i, (o, &v)) in out[columns].iter_mut().zip(&part).enumerate() {
                // Checked before it is added: no sum the shards hold can overflow the total.
                let (x, channel) = ((first + i) / c, (first + i) % c);
                let (total, most) = (wide(*o) + wide(v), self.bound.most(x as u64, y));
                if total > most {
                    return Err(shard_error(
                        path,
                        format!(
                            "its root sums are out of range: channel {channel} of texel ({x}, {y}) of LOD {lod} sums to {total}, over {most} ({} for each of the {} source pixels under it): the shard is damaged or forged",
                            self.bound.summand,
                            most / self.bound.summand.max(1) as u128
                        ),
                    ));
                }
                *o = *o + v;
            }
        }
        let mut i = 0;
        while i < self.reading.len() {
            if self.reading[i].1.rows.end == y + 1 {
                let (path, mut reader) = self.reading.remove(i);
                if !reader.is_complete() {
                    return Err(shard_error(path, "its root sums hold more rows than it says".into()));
                }
            } else {
                i += 1;
            }
        }
        Ok(())
    }

    /// Checks that every rectangle was read to its end.
    pub fn finish(&self) -> Result<()> {
        match self.waiting.front().or(self.reading.first()) {
            Some((path, _)) => Err(shard_error(path, "holds root sums below the image".into())),
            None => Ok(()),
        }
    }
}

/// What the exact sums of the level above the cut can reach: no source pixel adds more than
/// `summand` to a sum, and a texel sums the pixels under it (`2^lod` on a side, fewer along
/// the right and bottom edges). A sum over that is none the source could give.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SumBound {
    pub(crate) lod: u32,
    pub(crate) channels: usize,
    /// The image at LOD 0.
    pub(crate) width: u64,
    pub(crate) height: u64,
    pub(crate) summand: u64,
}

impl SumBound {
    /// The largest sum texel (x, y) of the level can hold.
    fn most(&self, x: u64, y: u64) -> u128 {
        let side = 1u64 << self.lod;
        let pixels = |at: u64, extent: u64| side.min(extent.saturating_sub(at.saturating_mul(side)));
        self.summand as u128 * pixels(x, self.width) as u128 * pixels(y, self.height) as u128
    }
}

/// A sum as a `u128`, whichever width it is kept in.
fn wide<A: Acc>(sum: A) -> u128 {
    let mut le = [0u8; 16];
    sum.to_le(&mut le[..A::BYTES]);
    u128::from_le_bytes(le)
}
