//! Tile codecs: turning a tile's texels into the bytes of one image file.
//!
//! The codec also decides the stored texel format: JPEG holds 8-bit grey or RGB only, so 16-bit
//! tiles are rounded to 8 bits and alpha is either composited away (`--flatten`) or refused.

use std::borrow::Cow;

use crate::error::TilerError;
use crate::pixel::{Channels, Depth, PixelLayout, Sample, u16_to_u8};

/// JPEG chroma subsampling.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Subsampling {
    /// 4:2:0: chroma at half resolution both ways (smaller files, what libjpeg does below q90).
    #[value(name = "420")]
    S420,
    /// 4:4:4: full-resolution chroma.
    #[value(name = "444")]
    S444,
}

/// PNG effort.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PngLevel {
    /// fdeflate: very fast, files a little larger.
    Fast,
    /// zlib-like default.
    Default,
    /// Slowest, smallest.
    Best,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    Jpeg { quality: u8, subsampling: Subsampling },
    Png { level: PngLevel },
}

impl Codec {
    /// The `codec` member of `info.json` and the usual file extension.
    pub fn name(&self) -> &'static str {
        match self {
            Codec::Jpeg { .. } => "jpeg",
            Codec::Png { .. } => "png",
        }
    }

    pub fn extension(&self) -> &'static str {
        match self {
            Codec::Jpeg { .. } => "jpg",
            Codec::Png { .. } => "png",
        }
    }

    /// The texel layout tiles are stored in for a source of `source` layout; `depth` asks for
    /// a sample depth other than the source's.
    pub fn stored_layout(
        &self,
        source: PixelLayout,
        flatten: bool,
        depth: Option<Depth>,
    ) -> Result<PixelLayout, TilerError> {
        let channels = if flatten { source.channels.without_alpha() } else { source.channels };
        match self {
            Codec::Png { .. } => Ok(PixelLayout::new(channels, depth.unwrap_or(source.depth))),
            Codec::Jpeg { .. } => {
                if channels.has_alpha() {
                    return Err(TilerError::Options(format!(
                        "the source is {source} but JPEG has no alpha channel: use --codec png to keep alpha, or --flatten to composite it over --background"
                    )));
                }
                if depth == Some(Depth::U16) {
                    return Err(TilerError::Options(
                        "JPEG stores 8-bit samples only: use --codec png for 16-bit tiles".into(),
                    ));
                }
                Ok(PixelLayout::new(channels, Depth::U8))
            }
        }
    }
}

/// Encodes tiles of one layout with one codec; shared by all worker threads.
pub struct TileEncoder<T> {
    codec: Codec,
    source: PixelLayout,
    stored: PixelLayout,
    side: u32,
    /// Colour alpha is composited over, in source samples (`--flatten`).
    matte: Vec<T>,
}

impl<T: Sample> TileEncoder<T> {
    pub fn new(
        codec: Codec,
        source: PixelLayout,
        flatten: bool,
        depth: Option<Depth>,
        side: u32,
        matte: Vec<T>,
    ) -> Result<Self, TilerError> {
        let stored = codec.stored_layout(source, flatten, depth)?;
        Ok(TileEncoder { codec, source, stored, side, matte })
    }

    pub fn stored_layout(&self) -> PixelLayout {
        self.stored
    }

    pub fn source_layout(&self) -> PixelLayout {
        self.source
    }

    /// Texels with alpha composited away if the stored layout has none.
    fn flattened<'a>(&self, texels: &'a [T]) -> Cow<'a, [T]> {
        if self.stored.channels != self.source.channels {
            Cow::Owned(flatten(texels, self.source.channels.count(), &self.matte))
        } else {
            Cow::Borrowed(texels)
        }
    }

    /// One source texel as stored (flattened, depth converted), little-endian samples.
    pub fn stored_texel(&self, texel: &[T]) -> Vec<u8> {
        let texel = self.flattened(texel);
        match self.stored.depth {
            Depth::U8 => to_u8(&texel).into_owned(),
            Depth::U16 => {
                let widen = if T::DEPTH == Depth::U8 { 257 } else { 1 };
                texel.iter().flat_map(|s| (s.to_u16() * widen).to_le_bytes()).collect()
            }
        }
    }

    /// Encodes a `side x side` tile given in the source layout.
    pub fn encode(&self, texels: &[T], out: &mut Vec<u8>) -> Result<(), String> {
        out.clear();
        let texels = self.flattened(texels);
        let texels = &texels[..];
        match self.codec {
            Codec::Jpeg { quality, subsampling } => self.encode_jpeg(texels, quality, subsampling, out),
            Codec::Png { level } => self.encode_png(texels, level, out),
        }
    }

    /// libjpeg-turbo's encoder (MozJPEG in its libjpeg-turbo-compatible "fastest" profile: no
    /// trellis, no scan optimisation), the encoder `vips` uses, with SIMD when built with nasm.
    fn encode_jpeg(
        &self,
        texels: &[T],
        quality: u8,
        subsampling: Subsampling,
        out: &mut Vec<u8>,
    ) -> Result<(), String> {
        let samples = to_u8(texels);
        let side = self.side as usize;
        let colour = match self.stored.channels {
            Channels::Grey => mozjpeg::ColorSpace::JCS_GRAYSCALE,
            _ => mozjpeg::ColorSpace::JCS_RGB,
        };
        let buf = std::mem::take(out);
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> std::io::Result<Vec<u8>> {
            let mut c = mozjpeg::Compress::new(colour);
            c.set_fastest_defaults();
            c.set_size(side, side);
            c.set_quality(quality as f32);
            if colour == mozjpeg::ColorSpace::JCS_RGB {
                let px = match subsampling {
                    Subsampling::S420 => (2, 2),
                    Subsampling::S444 => (1, 1),
                };
                c.set_chroma_sampling_pixel_sizes(px, px);
            }
            let mut started = c.start_compress(buf)?;
            started.write_scanlines(&samples)?;
            started.finish()
        }));
        match result {
            Ok(Ok(bytes)) => {
                *out = bytes;
                Ok(())
            }
            Ok(Err(e)) => Err(e.to_string()),
            Err(_) => Err("libjpeg failed".into()),
        }
    }

    fn encode_png(&self, texels: &[T], level: PngLevel, out: &mut Vec<u8>) -> Result<(), String> {
        let mut enc = png::Encoder::new(&mut *out, self.side, self.side);
        enc.set_color(match self.stored.channels {
            Channels::Grey => png::ColorType::Grayscale,
            Channels::GreyAlpha => png::ColorType::GrayscaleAlpha,
            Channels::Rgb => png::ColorType::Rgb,
            Channels::Rgba => png::ColorType::Rgba,
        });
        enc.set_compression(match level {
            PngLevel::Fast => png::Compression::Fast,
            PngLevel::Default => png::Compression::Balanced,
            PngLevel::Best => png::Compression::High,
        });
        let data: Cow<[u8]> = match self.stored.depth {
            Depth::U8 => {
                enc.set_depth(png::BitDepth::Eight);
                to_u8(texels)
            }
            Depth::U16 => {
                enc.set_depth(png::BitDepth::Sixteen);
                let widen = if T::DEPTH == Depth::U8 { 257 } else { 1 };
                Cow::Owned(texels.iter().flat_map(|s| (s.to_u16() * widen).to_be_bytes()).collect())
            }
        };
        let mut writer = enc.write_header().map_err(|e| e.to_string())?;
        writer.write_image_data(&data).map_err(|e| e.to_string())?;
        writer.finish().map_err(|e| e.to_string())
    }
}

/// Samples as 8-bit, rounding 16-bit ones to the nearest 8-bit value.
fn to_u8<T: Sample>(texels: &[T]) -> Cow<'_, [u8]> {
    match T::DEPTH {
        Depth::U8 => Cow::Borrowed(bytemuck::cast_slice(texels)),
        Depth::U16 => Cow::Owned(texels.iter().map(|s| u16_to_u8(s.to_u16())).collect()),
    }
}

/// Composites straight alpha over `matte` (the colour channels of one texel), rounding once.
fn flatten<T: Sample>(texels: &[T], channels: usize, matte: &[T]) -> Vec<T> {
    let colour = channels - 1;
    let max = T::MAX as u64;
    let mut out = Vec::with_capacity(texels.len() / channels * colour);
    for px in texels.chunks_exact(channels) {
        let a = px[colour].to_u64();
        for c in 0..colour {
            let v = px[c].to_u64() * a + matte[c].to_u64() * (max - a);
            out.push(T::from_u64((2 * v + max) / (2 * max)));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flatten_composites_over_matte() {
        let px = [255u8, 0, 0, 255, 255, 0, 0, 0, 255, 0, 0, 128];
        let out = flatten(&px, 4, &[0, 0, 255]);
        assert_eq!(out, vec![255, 0, 0, 0, 0, 255, 128, 0, 127]);
    }

    #[test]
    fn jpeg_refuses_alpha_unless_flattened() {
        let codec = Codec::Jpeg { quality: 85, subsampling: Subsampling::S420 };
        let rgba = PixelLayout::new(Channels::Rgba, Depth::U16);
        assert!(codec.stored_layout(rgba, false, None).is_err());
        assert!(codec.stored_layout(rgba, true, Some(Depth::U16)).is_err());
        assert_eq!(codec.stored_layout(rgba, true, None).unwrap(), PixelLayout::new(Channels::Rgb, Depth::U8));
    }
}
