//! The resampling LOD filters (`lanczos3`, `mitchell`), streamed band by band.
//!
//! A kernel wider than 2x2 cannot be cascaded as exact sums, and applying it over a texel's
//! whole source footprint would need `support x 2^k` source rows at LOD k. Instead each LOD is
//! resampled from the rounded previous one (as libvips and most mipmap tools do): output row
//! `y` of LOD k+1 is centred on input row `2y + 1` of LOD k and the kernel, scaled by 2, reads
//! `support x 2` input rows on each side. A [`Resampler`] keeps only the input rows its next
//! output rows need (at most `2 * CHUNK + 4 * support + 2`), so memory stays bounded by the
//! width, as for the exact filters.
//!
//! The input is extended to an even size by repeating its last column and row, so that every
//! output texel is centred on its 2x2 footprint. 8-bit images without alpha are resampled in
//! fast_image_resize's 8-bit fixed point; 16-bit and alpha images in `f32`, alpha images with
//! colour premultiplied by alpha and divided again afterwards (the ratio is taken before alpha
//! is clamped, so ringing in alpha does not tint colour; texels whose alpha rounds to 0 are
//! black, as with the exact `premultiplied` filter). `fast_image_resize` clamps the kernel to the
//! image it is given and renormalises its weights; because a band always holds every row the
//! kernel reaches (or starts or ends where the level does), each band gives exactly what
//! resizing the whole level at once would (checked by the tests below).

use fast_image_resize as fir;

use crate::error::{Result, TilerError};
use crate::pixel::{Depth, PixelLayout, Sample};
use crate::pyramid::filter::Filter;

/// Output rows computed per call to the resizer (fewer at the end of the level).
pub const CHUNK: u64 = 16;

/// Resamples the rows of one LOD into the rows of the next.
pub struct Resampler<T> {
    kernel: Kernel,
    in_width: usize,
    in_height: u64,
    out_height: u64,
    /// Input rows the kernel reads on each side of an output row's centre.
    reach: u64,
    /// Extended-input row index of the first row held.
    first: u64,
    /// Extended input rows (`2 * out_width` texels each) from `first` on, in the working
    /// representation: `native` for 8-bit without alpha, `float` otherwise.
    native: Vec<T>,
    float: Vec<f32>,
    received: u64,
    next_out: u64,
    out: Vec<T>,
    out_float: Vec<f32>,
    resizer: fir::Resizer,
}

/// One level's kernel and how samples are represented for it.
#[derive(Clone, Copy)]
struct Kernel {
    options: fir::ResizeOptions,
    pixel: fir::PixelType,
    channels: usize,
    /// Resample `f32` values (premultiplied when `alpha`), not the samples themselves.
    float: bool,
    alpha: bool,
}

impl Kernel {
    fn new<T: Sample>(filter: Filter, layout: PixelLayout) -> (Kernel, u64) {
        let (kernel, reach) = match filter {
            // Support 3 and 2 texels of the output: twice that in input rows.
            Filter::Lanczos3 => (fir::FilterType::Lanczos3, 6),
            Filter::Mitchell => (fir::FilterType::Mitchell, 4),
            other => unreachable!("{other} is not a resampling filter"),
        };
        let channels = layout.channels.count();
        let alpha = layout.channels.has_alpha();
        let float = alpha || T::DEPTH == Depth::U16;
        let pixel = match (float, channels) {
            (false, 1) => fir::PixelType::U8,
            (false, 2) => fir::PixelType::U8x2,
            (false, 3) => fir::PixelType::U8x3,
            (false, _) => fir::PixelType::U8x4,
            (true, 1) => fir::PixelType::F32,
            (true, 2) => fir::PixelType::F32x2,
            (true, 3) => fir::PixelType::F32x3,
            (true, _) => fir::PixelType::F32x4,
        };
        let options = fir::ResizeOptions::new().resize_alg(fir::ResizeAlg::Convolution(kernel)).use_alpha(false);
        (Kernel { options, pixel, channels, float, alpha }, reach)
    }

    /// Appends `row` (repeating its last texel if `odd`) in the working representation.
    fn append<T: Sample>(&self, row: &[T], odd: bool, native: &mut Vec<T>, float: &mut Vec<f32>) {
        let c = self.channels;
        if !self.float {
            native.extend_from_slice(row);
            if odd {
                native.extend_from_within(native.len() - c..);
            }
            return;
        }
        let max = T::MAX as f32;
        for px in row.chunks_exact(c) {
            let weight = if self.alpha { px[c - 1].to_u64() as f32 / max } else { 1.0 };
            for (ch, v) in px.iter().enumerate() {
                let v = v.to_u64() as f32;
                float.push(if self.alpha && ch < c - 1 { v * weight } else { v });
            }
        }
        if odd {
            float.extend_from_within(float.len() - c..);
        }
    }

    /// Rounds working values back to samples, dividing colour by alpha.
    fn samples<T: Sample>(&self, float: &[f32], out: &mut [T]) {
        let c = self.channels;
        let max = T::MAX as f32;
        let round = |v: f32| T::from_u64(v.clamp(0.0, max).round() as u64);
        for (px, o) in float.chunks_exact(c).zip(out.chunks_exact_mut(c)) {
            if !self.alpha {
                px.iter().zip(o.iter_mut()).for_each(|(v, o)| *o = round(*v));
                continue;
            }
            let a = px[c - 1];
            o[c - 1] = round(a);
            let visible = o[c - 1] != T::default();
            for ch in 0..c - 1 {
                o[ch] = if visible { round(px[ch] * max / a) } else { T::default() };
            }
        }
    }

    /// Resizes `rows` (`2 * out_w` texels wide) into `n` output rows, taking the output rows'
    /// centres from input row `top` (the crop box's top) on.
    fn resize(
        &self,
        resizer: &mut fir::Resizer,
        src: &[u8],
        out_w: usize,
        top: u64,
        n: u64,
        dst: &mut [u8],
    ) -> Result<()> {
        let err = |e: &dyn std::fmt::Display| TilerError::Options(format!("resampling a level: {e}"));
        let in_w = 2 * out_w as u32;
        let rows = (src.len() / (in_w as usize * self.pixel.size())) as u32;
        let src = fir::images::ImageRef::new(in_w, rows, src, self.pixel).map_err(|e| err(&e))?;
        let mut dst =
            fir::images::Image::from_slice_u8(out_w as u32, n as u32, dst, self.pixel).map_err(|e| err(&e))?;
        let options = self.options.crop(0.0, top as f64, in_w as f64, 2.0 * n as f64);
        resizer.resize(&src, &mut dst, &options).map_err(|e| err(&e))
    }
}

impl<T: Sample> Resampler<T> {
    /// `filter` must be a resampling filter; `in_width x in_height` is the input level's real size.
    pub fn new(filter: Filter, layout: PixelLayout, in_width: usize, in_height: u64) -> Resampler<T> {
        let (kernel, reach) = Kernel::new::<T>(filter, layout);
        Resampler {
            kernel,
            in_width,
            in_height,
            out_height: in_height.div_ceil(2),
            reach,
            first: 0,
            native: Vec::new(),
            float: Vec::new(),
            received: 0,
            next_out: 0,
            out: Vec::new(),
            out_float: Vec::new(),
            resizer: fir::Resizer::new(),
        }
    }

    /// Texels per output row: half the input level's width, rounded up.
    pub fn out_width(&self) -> usize {
        self.in_width.div_ceil(2)
    }

    /// Samples per extended input row.
    fn row_len(&self) -> usize {
        2 * self.out_width() * self.kernel.channels
    }

    fn held(&self) -> usize {
        (if self.kernel.float { self.float.len() } else { self.native.len() }) / self.row_len()
    }

    /// One past the last extended input row held.
    fn end(&self) -> u64 {
        self.first + self.held() as u64
    }

    /// Adds the next input row; returns the output rows it completes (row-major), if any.
    pub fn push(&mut self, row: &[T]) -> Result<Option<&[T]>> {
        debug_assert_eq!(row.len(), self.in_width * self.kernel.channels);
        self.kernel.append(row, self.in_width % 2 == 1, &mut self.native, &mut self.float);
        self.received += 1;
        if self.received == self.in_height && self.in_height % 2 == 1 {
            // Repeat the last row to make the height even.
            let len = self.row_len();
            if self.kernel.float {
                self.float.extend_from_within(self.float.len() - len..);
            } else {
                self.native.extend_from_within(self.native.len() - len..);
            }
        }
        let done = self.received == self.in_height;
        // Output row y needs extended input rows [2y + 1 - reach, 2y + 1 + reach).
        let ready = if done { self.out_height } else { (self.end() + 1).saturating_sub(self.reach) / 2 };
        if ready <= self.next_out || (!done && ready - self.next_out < CHUNK) {
            return Ok(None);
        }
        self.emit(ready)?;
        Ok(Some(&self.out))
    }

    /// Computes output rows `[next_out, to)` into `out` and forgets input rows no longer needed.
    fn emit(&mut self, to: u64) -> Result<()> {
        let n = to - self.next_out;
        let out_w = self.out_width();
        let samples = out_w * n as usize * self.kernel.channels;
        let top = 2 * self.next_out - self.first;
        self.out.resize(samples, T::default());
        if self.kernel.float {
            self.out_float.resize(samples, 0.0);
            let dst = bytemuck::cast_slice_mut(&mut self.out_float);
            self.kernel.resize(&mut self.resizer, bytemuck::cast_slice(&self.float), out_w, top, n, dst)?;
            self.kernel.samples(&self.out_float, &mut self.out);
        } else {
            let dst = bytemuck::cast_slice_mut(&mut self.out);
            self.kernel.resize(&mut self.resizer, bytemuck::cast_slice(&self.native), out_w, top, n, dst)?;
        }
        self.next_out = to;
        let keep_from = (2 * to + 1).saturating_sub(self.reach).min(self.end());
        if keep_from > self.first {
            let drop = (keep_from - self.first) as usize * self.row_len();
            if self.kernel.float {
                self.float.drain(..drop);
            } else {
                self.native.drain(..drop);
            }
            self.first = keep_from;
        }
        Ok(())
    }
}

/// A whole level resampled in one call: what the banded [`Resampler`] must give (tests and
/// oracles use it).
#[cfg_attr(not(feature = "testing"), allow(dead_code))] // read by the tests, through `testing`
pub fn resample_level<T: Sample>(filter: Filter, layout: PixelLayout, src: &[T], w: usize, h: usize) -> Result<Vec<T>> {
    let (kernel, _) = Kernel::new::<T>(filter, layout);
    let c = layout.channels.count();
    let (ow, oh) = (w.div_ceil(2), h.div_ceil(2));
    let (mut native, mut float) = (Vec::new(), Vec::new());
    for y in 0..2 * oh {
        kernel.append(&src[y.min(h - 1) * w * c..][..w * c], w % 2 == 1, &mut native, &mut float);
    }
    let mut out = vec![T::default(); ow * oh * c];
    let mut resizer = fir::Resizer::new();
    if kernel.float {
        let mut out_float = vec![0f32; out.len()];
        kernel.resize(
            &mut resizer,
            bytemuck::cast_slice(&float),
            ow,
            0,
            oh as u64,
            bytemuck::cast_slice_mut(&mut out_float),
        )?;
        kernel.samples(&out_float, &mut out);
    } else {
        kernel.resize(
            &mut resizer,
            bytemuck::cast_slice(&native),
            ow,
            0,
            oh as u64,
            bytemuck::cast_slice_mut(&mut out),
        )?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pixel::Channels;

    fn banded<T: Sample>(filter: Filter, layout: PixelLayout, src: &[T], w: usize, h: usize) -> Vec<T> {
        let c = layout.channels.count();
        let mut r = Resampler::<T>::new(filter, layout, w, h as u64);
        let mut out = Vec::new();
        for row in src.chunks_exact(w * c) {
            if let Some(rows) = r.push(row).unwrap() {
                out.extend_from_slice(rows);
            }
            // The band never holds more than its bound.
            assert!(r.held() as u64 <= 2 * CHUNK + 2 * r.reach + 2, "{} rows held", r.held());
        }
        out
    }

    fn noise(n: usize, seed: u64, max: u64) -> Vec<u64> {
        let mut s = seed | 1;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                s % (max + 1)
            })
            .collect()
    }

    #[test]
    fn bands_give_what_the_whole_level_gives() {
        for filter in [Filter::Lanczos3, Filter::Mitchell] {
            for (w, h) in [(1, 1), (1, 9), (9, 1), (2, 2), (37, 75), (64, 100), (5, 33)] {
                for channels in [Channels::Grey, Channels::GreyAlpha, Channels::Rgb, Channels::Rgba] {
                    let l8 = PixelLayout::new(channels, Depth::U8);
                    let c = channels.count();
                    let src: Vec<u8> = noise(w * h * c, (w * 131 + h) as u64, 255).iter().map(|v| *v as u8).collect();
                    let whole = resample_level(filter, l8, &src, w, h).unwrap();
                    assert_eq!(banded(filter, l8, &src, w, h), whole, "{filter} {w}x{h} {l8}");
                    let l16 = PixelLayout::new(channels, Depth::U16);
                    let src: Vec<u16> = noise(w * h * c, (w * 7 + h) as u64, 65535).iter().map(|v| *v as u16).collect();
                    let whole = resample_level(filter, l16, &src, w, h).unwrap();
                    assert_eq!(banded(filter, l16, &src, w, h), whole, "{filter} {w}x{h} {l16}");
                }
            }
        }
    }
}
