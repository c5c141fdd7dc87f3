//! A raw tile's samples as the file stores them: horizontally differenced (`Predictor` 2)
//! where the spec asks, then compressed. Runs on the encoder threads, before the writer's lock.

use std::io::Write;

use super::{Compression, Spec};
use crate::error::{Result, TilerError};
use crate::pixel::Depth;

/// `raw` (one whole tile of `spec.stored` samples, little-endian, row by row) compressed as
/// `spec` says; tile `(level, x, y)` names it in errors.
pub(super) fn tile(spec: &Spec, raw: &[u8], (level, x, y): (u32, u32, u32)) -> Result<Vec<u8>> {
    let err = |message: String| TilerError::Encode { lod: level, x, y, message };
    if raw.len() as u64 != spec.raw_tile_bytes() {
        return Err(err(format!(
            "{} bytes where a {}-pixel {} tile has {}",
            raw.len(),
            spec.tile_size,
            spec.stored,
            spec.raw_tile_bytes()
        )));
    }
    let mut samples = raw.to_vec();
    if spec.predictor() {
        let row = spec.tile_size as usize * spec.stored.bytes_per_pixel();
        let spp = spec.stored.channels.count();
        for line in samples.chunks_exact_mut(row) {
            difference(line, spp, spec.stored.depth);
        }
    }
    match spec.compression {
        Compression::None | Compression::Jpeg { .. } => Ok(samples),
        Compression::Deflate { level } => {
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(level));
            z.write_all(&samples).and_then(|()| z.finish()).map_err(|e| err(format!("deflate: {e}")))
        }
        Compression::Zstd { level } => zstd::bulk::compress(&samples, level).map_err(|e| err(format!("zstd: {e}"))),
    }
}

/// Horizontal differencing of one row of `spp` samples a pixel, in place: each sample less
/// the same sample of the pixel to its left, modulo the sample's width (TIFF 6.0, section 14).
fn difference(row: &mut [u8], spp: usize, depth: Depth) {
    match depth {
        Depth::U8 => {
            for i in (spp..row.len()).rev() {
                row[i] = row[i].wrapping_sub(row[i - spp]);
            }
        }
        Depth::U16 => difference_wide::<2>(row, spp),
        Depth::U32 => difference_wide::<4>(row, spp),
        // No predictor for floats (`Spec::predictor`).
        Depth::F32 | Depth::F16 => {}
    }
}

/// [`difference`] for little-endian samples of `N` bytes.
fn difference_wide<const N: usize>(row: &mut [u8], spp: usize) {
    let read = |row: &[u8], i: usize| {
        let mut b = [0u8; 8];
        b[..N].copy_from_slice(&row[i * N..i * N + N]);
        u64::from_le_bytes(b)
    };
    let mask = if N == 8 { u64::MAX } else { (1u64 << (8 * N)) - 1 };
    let samples = row.len() / N;
    for i in (spp..samples).rev() {
        let d = read(row, i).wrapping_sub(read(row, i - spp)) & mask;
        row[i * N..i * N + N].copy_from_slice(&d.to_le_bytes()[..N]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Undoes [`difference`] as a reader does: a running sum per sample.
    fn undo(row: &mut [u8], spp: usize, n: usize) {
        let samples = row.len() / n;
        for i in spp..samples {
            let get = |row: &[u8], i: usize| {
                let mut b = [0u8; 8];
                b[..n].copy_from_slice(&row[i * n..i * n + n]);
                u64::from_le_bytes(b)
            };
            let v = get(row, i).wrapping_add(get(row, i - spp));
            row[i * n..i * n + n].copy_from_slice(&v.to_le_bytes()[..n]);
        }
    }

    #[test]
    fn differencing_is_undone_by_a_running_sum() {
        for (depth, n) in [(Depth::U8, 1), (Depth::U16, 2), (Depth::U32, 4)] {
            for spp in 1..=4 {
                let row: Vec<u8> = (0..(7 * spp * n)).map(|i| (i * 37 % 251) as u8).collect();
                let mut d = row.clone();
                difference(&mut d, spp, depth);
                assert_ne!(d, row, "{depth:?} {spp}");
                // The first pixel stays as it is.
                assert_eq!(d[..spp * n], row[..spp * n]);
                undo(&mut d, spp, n);
                assert_eq!(d, row, "{depth:?} {spp}");
            }
        }
    }

    #[test]
    fn sixteen_bit_differences_wrap_within_the_sample() {
        let mut row = [0xff, 0xff, 0x01, 0x00];
        difference(&mut row, 1, Depth::U16);
        assert_eq!(row, [0xff, 0xff, 0x02, 0x00], "1 - 65535 = 2 mod 65536");
    }
}
