//! Pixel layouts the pipeline carries: 1-4 channels of 8- or 16-bit unsigned samples.
//!
//! The whole pipeline is generic over the sample type ([`Sample`]) so that 8-bit images pay
//! for 8-bit bands, while 16-bit images keep every bit until the codec.

use std::fmt;

/// Channel arrangement of a texel, in the names `info.json` uses for `tileFormat`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Channels {
    Grey,
    GreyAlpha,
    Rgb,
    Rgba,
}

impl Channels {
    pub fn count(self) -> usize {
        match self {
            Channels::Grey => 1,
            Channels::GreyAlpha => 2,
            Channels::Rgb => 3,
            Channels::Rgba => 4,
        }
    }

    pub fn has_alpha(self) -> bool {
        matches!(self, Channels::GreyAlpha | Channels::Rgba)
    }

    /// The same colour channels without alpha.
    pub fn without_alpha(self) -> Channels {
        match self {
            Channels::GreyAlpha => Channels::Grey,
            Channels::Rgba => Channels::Rgb,
            other => other,
        }
    }

    /// `tileFormat` as written in `info.json`.
    pub fn tile_format(self) -> &'static str {
        match self {
            Channels::Grey => "luminance",
            Channels::GreyAlpha => "luminanceAlpha",
            Channels::Rgb => "rgb",
            Channels::Rgba => "rgba",
        }
    }

    pub fn from_tile_format(name: &str) -> Option<Channels> {
        [Channels::Grey, Channels::GreyAlpha, Channels::Rgb, Channels::Rgba]
            .into_iter()
            .find(|c| c.tile_format() == name)
    }
}

/// Bits per sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Depth {
    U8,
    U16,
}

impl Depth {
    pub fn bytes(self) -> usize {
        match self {
            Depth::U8 => 1,
            Depth::U16 => 2,
        }
    }

    /// `tileType` as written in `info.json`.
    pub fn tile_type(self) -> &'static str {
        match self {
            Depth::U8 => "unsignedByte",
            Depth::U16 => "unsignedShort",
        }
    }

    pub fn from_tile_type(name: &str) -> Option<Depth> {
        [Depth::U8, Depth::U16].into_iter().find(|d| d.tile_type() == name)
    }
}

/// Channels plus depth: everything needed to interpret a row of samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PixelLayout {
    pub channels: Channels,
    pub depth: Depth,
}

impl PixelLayout {
    pub fn new(channels: Channels, depth: Depth) -> Self {
        PixelLayout { channels, depth }
    }

    pub fn bytes_per_pixel(self) -> usize {
        self.channels.count() * self.depth.bytes()
    }
}

impl fmt::Display for PixelLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let bits = self.depth.bytes() * 8;
        write!(f, "{} {bits}-bit", self.channels.tile_format())
    }
}

/// A sample type the pipeline can carry. Sums are taken in `u64`, which holds the sum of
/// 4^24 samples of 16 bits, far beyond any pyramid a 2^24-texel side can have (some LOD
/// filters sum wider values, in `u128` where needed).
pub trait Sample: Copy + Default + PartialEq + Send + Sync + Into<u64> + Into<u128> + bytemuck::Pod + 'static {
    const DEPTH: Depth;
    const MAX: u16;
    fn to_u64(self) -> u64;
    /// Caller guarantees `v <= MAX`.
    fn from_u64(v: u64) -> Self;
    fn from_u16(v: u16) -> Self;
    fn to_u16(self) -> u16;
}

impl Sample for u8 {
    const DEPTH: Depth = Depth::U8;
    const MAX: u16 = u8::MAX as u16;
    #[inline]
    fn to_u64(self) -> u64 {
        self as u64
    }
    #[inline]
    fn from_u64(v: u64) -> Self {
        v as u8
    }
    #[inline]
    fn from_u16(v: u16) -> Self {
        v as u8
    }
    #[inline]
    fn to_u16(self) -> u16 {
        self as u16
    }
}

impl Sample for u16 {
    const DEPTH: Depth = Depth::U16;
    const MAX: u16 = u16::MAX;
    #[inline]
    fn to_u64(self) -> u64 {
        self as u64
    }
    #[inline]
    fn from_u64(v: u64) -> Self {
        v as u16
    }
    #[inline]
    fn from_u16(v: u16) -> Self {
        v
    }
    #[inline]
    fn to_u16(self) -> u16 {
        self
    }
}

/// 16-bit to 8-bit with correct rounding: `round(v * 255 / 65535)`, which is exact integer
/// arithmetic because 65535 = 255 * 257.
#[inline]
pub fn u16_to_u8(v: u16) -> u8 {
    ((v as u32 + 128) / 257) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn u16_to_u8_rounds_to_nearest() {
        for v in 0..=u16::MAX {
            let exact = v as f64 * 255.0 / 65535.0;
            let got = u16_to_u8(v) as f64;
            assert!((got - exact).abs() <= 0.5, "{v} -> {got}, exact {exact}");
        }
        assert_eq!(u16_to_u8(257 * 200), 200);
    }

    #[test]
    fn names_round_trip() {
        for c in [Channels::Grey, Channels::GreyAlpha, Channels::Rgb, Channels::Rgba] {
            assert_eq!(Channels::from_tile_format(c.tile_format()), Some(c));
        }
        for d in [Depth::U8, Depth::U16] {
            assert_eq!(Depth::from_tile_type(d.tile_type()), Some(d));
        }
    }
}
