//! Pixel layouts the pipeline carries: 1-4 channels of 8-, 16- or 32-bit unsigned samples, or
//! of 32-bit floats.
//!
//! The whole pipeline is generic over the sample type ([`Sample`]) so that 8-bit images pay
//! for 8-bit bands, while 16-bit, 32-bit and float images keep every bit until the codec.
//! Half floats (`--tile-type half`) are only a way to store float tiles: the pipeline carries
//! them as `f32`, which holds every half exactly.

use std::fmt;
use std::ops::Add;

/// Channel arrangement of a texel, in the names `info.json` uses for `tileFormat`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Channels {
    /// One channel, luminance (`luminance`).
    Grey,
    /// Luminance then alpha (`luminanceAlpha`).
    GreyAlpha,
    /// Red, green, blue (`rgb`).
    Rgb,
    /// Red, green, blue, then alpha (`rgba`); colour is not premultiplied.
    Rgba,
}

impl Channels {
    /// Samples per texel: 1 to 4.
    pub fn count(self) -> usize {
        match self {
            Channels::Grey => 1,
            Channels::GreyAlpha => 2,
            Channels::Rgb => 3,
            Channels::Rgba => 4,
        }
    }

    /// Whether the last channel is alpha (`GreyAlpha`, `Rgba`).
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
    pub(crate) fn tile_format(self) -> &'static str {
        match self {
            Channels::Grey => "luminance",
            Channels::GreyAlpha => "luminanceAlpha",
            Channels::Rgb => "rgb",
            Channels::Rgba => "rgba",
        }
    }

    pub(crate) fn from_tile_format(name: &str) -> Option<Channels> {
        [Channels::Grey, Channels::GreyAlpha, Channels::Rgb, Channels::Rgba]
            .into_iter()
            .find(|c| c.tile_format() == name)
    }
}

/// What one sample is: its size and whether it is an unsigned integer or an IEEE float.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Depth {
    /// 8-bit unsigned integers, 0 to 255 (`unsignedByte`).
    U8,
    /// 16-bit unsigned integers, 0 to 65535 (`unsignedShort`).
    U16,
    /// 32-bit unsigned integers (counts, label images with many objects).
    U32,
    /// 32-bit IEEE floats (measurements, HDR, elevation).
    F32,
    /// 16-bit IEEE floats: a way to store `F32` tiles (`--tile-type half`, what a GPU uploads
    /// as R16F), never what the pipeline carries.
    F16,
}

impl Depth {
    /// Every depth, in the order `--tile-type` lists them.
    pub const ALL: [Depth; 5] = [Depth::U8, Depth::U16, Depth::U32, Depth::F32, Depth::F16];

    /// Bytes of one sample: 1, 2 or 4.
    pub fn bytes(self) -> usize {
        match self {
            Depth::U8 => 1,
            Depth::U16 | Depth::F16 => 2,
            Depth::U32 | Depth::F32 => 4,
        }
    }

    /// Whether samples are IEEE floats rather than unsigned integers.
    pub(crate) fn is_float(self) -> bool {
        matches!(self, Depth::F32 | Depth::F16)
    }

    /// Whether this depth is one of the 8/16-bit integer depths that every codec and filter
    /// takes; the others (32-bit, float) go through fewer of them.
    pub(crate) fn is_narrow_int(self) -> bool {
        matches!(self, Depth::U8 | Depth::U16)
    }

    /// `tileType` as written in `info.json`.
    pub fn tile_type(self) -> &'static str {
        match self {
            Depth::U8 => "unsignedByte",
            Depth::U16 => "unsignedShort",
            Depth::U32 => "unsignedInt",
            Depth::F32 => "float",
            Depth::F16 => "half",
        }
    }

    /// The depth `info.json`'s `tileType` (and `--tile-type`) names, as [`Depth::tile_type`]
    /// writes it; `None` for any other name.
    pub fn from_tile_type(name: &str) -> Option<Depth> {
        Depth::ALL.into_iter().find(|d| d.tile_type() == name)
    }

    /// A pack header's `sample_format` for this depth (docs/pack-format.md).
    pub(crate) fn pack_sample_format(self) -> u8 {
        if self.is_float() { vortex_pack::format::SAMPLE_FLOAT } else { vortex_pack::format::SAMPLE_UNSIGNED }
    }

    /// The depth of a pack's `sample_bytes` and `sample_format`, if it is one.
    pub(crate) fn from_pack(sample_bytes: u8, sample_format: u8) -> Option<Depth> {
        Depth::ALL.into_iter().find(|d| d.bytes() == sample_bytes as usize && d.pack_sample_format() == sample_format)
    }
}

/// Channels plus depth: everything needed to interpret a row of samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PixelLayout {
    /// Which channels a texel has, in order.
    pub channels: Channels,
    /// The size and kind of every sample.
    pub depth: Depth,
}

impl PixelLayout {
    /// `channels` of `depth` samples.
    pub fn new(channels: Channels, depth: Depth) -> Self {
        PixelLayout { channels, depth }
    }

    /// Bytes of one texel, all its channels: 1 (8-bit grey) to 16 (32-bit RGBA).
    pub fn bytes_per_pixel(self) -> usize {
        self.channels.count() * self.depth.bytes()
    }
}

impl fmt::Display for PixelLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let bits = self.depth.bytes() * 8;
        let kind = if self.depth.is_float() { " float" } else { "" };
        write!(f, "{} {bits}-bit{kind}", self.channels.tile_format())
    }
}

/// A sample type the pipeline can carry: `u8`, `u16`, `u32` or `f32`.
///
/// The exact filters sum samples into [`Sample::Narrow`] where that cannot overflow over the
/// pyramid's depth, [`Sample::Wide`] otherwise: `u64`/`u128` for the integers (a `u64` holds
/// the sum of 4^24 samples of 16 bits, far beyond any pyramid a 2^24-texel side can have; 32-bit
/// samples need the `u128` past 4^15 of them), [`FloatSum`] for floats.
///
/// The integer conversions (`to_u64`, `from_u64`, `from_u16`, `to_u16`) are those of the
/// 8/16-bit filters and codecs (sRGB tables, premultiplying, 16-to-8 rounding). The filters and
/// codecs that use them refuse 32-bit and float samples before a run starts.
pub trait Sample: Copy + Default + PartialEq + Send + Sync + bytemuck::Pod + 'static {
    /// The [`Depth`] this type carries (`f32` carries both `F32` and `F16` tiles: `F32`).
    const DEPTH: Depth;
    /// The largest sample of an opaque alpha, as a `u64` (floats: 1.0, read as 1).
    const MAX: u64;
    /// Exact sums of pyramids shallow enough not to overflow them.
    type Narrow: Acc + From<Self>;
    /// Exact sums of any pyramid.
    type Wide: Acc + From<Self>;
    /// The sample as an integer: exact for the integer types; for `f32` Rust's saturating
    /// `as` (toward zero, NaN to 0), which a float run never reaches.
    fn to_u64(self) -> u64;
    /// Caller guarantees `v <= MAX`.
    fn from_u64(v: u64) -> Self;
    /// Caller guarantees `v <= MAX`.
    fn from_u16(v: u16) -> Self;
    /// An 8-bit value (a `--background` colour) scaled to the type's full range: times 257
    /// for 16 bits, times 0x01010101 for 32, over 255 for floats (whose range is 0 to 1).
    fn from_u8_scaled(v: u8) -> Self;
    /// The sample as 16 bits, the value itself (no scaling) for `u8` and `u16`; `u32` keeps
    /// its low 16 bits and `f32` saturates, which the 8/16-bit paths that call it never see.
    fn to_u16(self) -> u16;
    /// The means of an exact row's sums: each rounded half up to the nearest integer sample
    /// (`box`), or for floats divided in f64 and rounded to the nearest `f32`.
    fn means<A: Acc>(row: &ExactRow<'_, A>, out: &mut [Self]) {
        row.map_means(out, Self::from_u64);
    }
}

macro_rules! int_sample {
    ($t:ty, $depth:expr, $wide:ty) => {
        impl Sample for $t {
            const DEPTH: Depth = $depth;
            const MAX: u64 = <$t>::MAX as u64;
            type Narrow = u64;
            type Wide = $wide;
            #[inline]
            fn to_u64(self) -> u64 {
                self as u64
            }
            #[inline]
            fn from_u64(v: u64) -> Self {
                v as $t
            }
            #[inline]
            fn from_u16(v: u16) -> Self {
                v as $t
            }
            fn from_u8_scaled(v: u8) -> Self {
                // The byte repeated: 0xAB -> 0xABAB -> 0xABABABAB, so 255 is the maximum.
                (v as u64 * (<$t>::MAX as u64 / 255)) as $t
            }
            #[inline]
            fn to_u16(self) -> u16 {
                self as u16
            }
        }
    };
}

int_sample!(u8, Depth::U8, u128);
int_sample!(u16, Depth::U16, u128);
int_sample!(u32, Depth::U32, u128);

impl Sample for f32 {
    const DEPTH: Depth = Depth::F32;
    const MAX: u64 = 1;
    type Narrow = FloatSum;
    type Wide = FloatSum;
    #[inline]
    fn to_u64(self) -> u64 {
        // Saturating, NaN to 0 (Rust's `as`): never reached by a float run, see the trait.
        self as u64
    }
    #[inline]
    fn from_u64(v: u64) -> Self {
        v as f32
    }
    #[inline]
    fn from_u16(v: u16) -> Self {
        v as f32
    }
    fn from_u8_scaled(v: u8) -> Self {
        v as f32 / 255.0
    }
    #[inline]
    fn to_u16(self) -> u16 {
        self as u16
    }
    fn means<A: Acc>(row: &ExactRow<'_, A>, out: &mut [Self]) {
        row.map_float_means(out);
    }
}

/// The exact pyramid's sum of `f32` samples: an `f64`, whose 53-bit mantissa holds the sum of
/// 2^29 floats of one binade exactly; beyond that, and between magnitudes, each addition rounds
/// once (the bound is in docs/sources.md, "More sample types", and tested in
/// `tests/it/sample_types.rs`). NaN and infinities propagate as IEEE addition makes them: a
/// footprint holding a NaN (or both infinities) is NaN, one holding an infinity is that infinity.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FloatSum(pub f64);

impl std::ops::Add for FloatSum {
    type Output = FloatSum;
    #[inline]
    fn add(self, other: FloatSum) -> FloatSum {
        FloatSum(self.0 + other.0)
    }
}

impl From<f32> for FloatSum {
    #[inline]
    fn from(v: f32) -> FloatSum {
        FloatSum(v as f64)
    }
}

impl From<u8> for FloatSum {
    fn from(v: u8) -> FloatSum {
        FloatSum(v as f64)
    }
}

impl From<u16> for FloatSum {
    fn from(v: u16) -> FloatSum {
        FloatSum(v as f64)
    }
}

impl From<u64> for FloatSum {
    fn from(v: u64) -> FloatSum {
        FloatSum(v as f64)
    }
}

impl Acc for FloatSum {
    // The rounded integer means: what the integer filters would take, saturating (`as`). A
    // float run reads `to_f64` instead (`Sample::means`).
    fn round_shift(self, shift: u32) -> u64 {
        (self.0 / (1u64 << shift) as f64).round() as u64
    }
    fn round_div(self, d: u64) -> u64 {
        (self.0 / d as f64).round() as u64
    }
    fn round_ratio(self, d: Self) -> u64 {
        (self.0 / d.0).round() as u64
    }
    fn to_f64(self) -> f64 {
        self.0
    }
    const BYTES: usize = 8;
    fn to_le(self, out: &mut [u8]) {
        out.copy_from_slice(&self.0.to_le_bytes());
    }
    fn from_le(bytes: &[u8]) -> Self {
        let mut b = [0; 8];
        b.copy_from_slice(bytes);
        FloatSum(f64::from_le_bytes(b))
    }
}

/// 16-bit to 8-bit with correct rounding: `round(v * 255 / 65535)`, which is exact integer
/// arithmetic because 65535 = 255 * 257.
#[inline]
pub(crate) fn u16_to_u8(v: u16) -> u8 {
    ((v as u32 + 128) / 257) as u8
}

/// An exact sum: `u64`, or `u128` for the filters whose sums could exceed it.
pub trait Acc:
    Copy + Default + PartialEq + Send + Sync + 'static + Add<Output = Self> + From<u8> + From<u16> + From<u64>
{
    /// `round_half_up(self / 2^shift)`; the result fits in a `u64`.
    fn round_shift(self, shift: u32) -> u64;
    /// `round_half_up(self / d)`; the result fits in a `u64`.
    fn round_div(self, d: u64) -> u64;
    /// `round_half_up(self / d)` for a divisor that is itself a sum (`d > 0`).
    fn round_ratio(self, d: Self) -> u64;
    /// The sum as an `f64` (rounded to nearest where it does not fit), for float means.
    fn to_f64(self) -> f64;
    /// Bytes of one sum, as a shard stores it (little-endian).
    const BYTES: usize;
    /// Writes the sum into `out`, exactly [`Acc::BYTES`] long, little-endian.
    fn to_le(self, out: &mut [u8]);
    /// The sum [`Acc::to_le`] wrote into `bytes` ([`Acc::BYTES`] long).
    fn from_le(bytes: &[u8]) -> Self;
}

impl Acc for u64 {
    #[inline]
    fn round_shift(self, shift: u32) -> u64 {
        (self + (1 << shift >> 1)) >> shift
    }
    #[inline]
    fn round_div(self, d: u64) -> u64 {
        (2 * self + d) / (2 * d)
    }
    #[inline]
    fn round_ratio(self, d: u64) -> u64 {
        (2 * self + d) / (2 * d)
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    const BYTES: usize = 8;
    fn to_le(self, out: &mut [u8]) {
        out.copy_from_slice(&self.to_le_bytes());
    }
    fn from_le(bytes: &[u8]) -> Self {
        let mut b = [0; 8];
        b.copy_from_slice(bytes);
        u64::from_le_bytes(b)
    }
}

impl Acc for u128 {
    #[inline]
    fn round_shift(self, shift: u32) -> u64 {
        ((self + (1 << shift >> 1)) >> shift) as u64
    }
    #[inline]
    fn round_div(self, d: u64) -> u64 {
        ((2 * self + d as u128) / (2 * d as u128)) as u64
    }
    #[inline]
    fn round_ratio(self, d: u128) -> u64 {
        ((2 * self + d) / (2 * d)) as u64
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
    const BYTES: usize = 16;
    fn to_le(self, out: &mut [u8]) {
        out.copy_from_slice(&self.to_le_bytes());
    }
    fn from_le(bytes: &[u8]) -> Self {
        let mut b = [0; 16];
        b.copy_from_slice(bytes);
        u128::from_le_bytes(b)
    }
}

/// An exact output row: sums plus what they must be divided by.
pub struct ExactRow<'a, A = u64> {
    /// The row's exact sums, channels interleaved: one per sample of the output row.
    pub sums: &'a [A],
    /// Row of the output level.
    pub y: u64,
    pub(crate) row_weight: u64,
    pub(crate) col_weight: &'a [u64],
    /// Leading texels whose footprint is complete: their divisor is `footprint^2`, a shift.
    pub(crate) full_cols: usize,
    pub(crate) footprint: u64,
    pub(crate) channels: usize,
}

impl<A: Acc> ExactRow<'_, A> {
    /// The row's texels rounded to the nearest sample value (halves round up): the `box` filter.
    /// Float samples: each sum divided by its pixel count in f64, then rounded to the nearest
    /// `f32` (see [`crate::pixel::FloatSum`] for the bound).
    pub fn round_into<T: Sample>(&self, out: &mut [T]) {
        T::means(self, out);
    }

    /// `out[i] = mean i` in f64, rounded to the nearest `f32`: a power-of-two divisor for the
    /// complete footprints is exact, any other one rounds once.
    pub(crate) fn map_float_means(&self, out: &mut [f32]) {
        debug_assert_eq!(out.len(), self.sums.len());
        let c = self.channels;
        for (i, (o, s)) in out.iter_mut().zip(self.sums).enumerate() {
            *o = (s.to_f64() / self.weight(i / c) as f64) as f32;
        }
    }

    /// `out[i] = f(mean i)`: every sum divided by its texel's pixel count, rounded half up, in
    /// row order; a shift for the leading texels with complete footprints, a division for the
    /// rest. Two plain loops, not one iterator over both, so that each compiles to a tight one
    /// (this is most of a level's cost: issue 18).
    pub(crate) fn map_means<T>(&self, out: &mut [T], f: impl Fn(u64) -> T) {
        debug_assert_eq!(out.len(), self.sums.len());
        let c = self.channels;
        let (head, tail) = self.sums.split_at(self.full_cols * c);
        let (out_head, out_tail) = out.split_at_mut(self.full_cols * c);
        let shift = (self.footprint * self.footprint).trailing_zeros();
        for (o, s) in out_head.iter_mut().zip(head) {
            *o = f(s.round_shift(shift));
        }
        for (i, (o, s)) in out_tail.iter_mut().zip(tail).enumerate() {
            *o = f(s.round_div(self.weight(self.full_cols + i / c)));
        }
    }

    /// Real source pixels under texel `x`.
    #[inline]
    pub fn weight(&self, x: usize) -> u64 {
        self.col_weight[x] * self.row_weight
    }

    /// `sum` (one of texel `x`'s sums) divided by the texel's pixel count, rounded half up.
    #[inline]
    pub fn mean(&self, x: usize, sum: A) -> u64 {
        if x < self.full_cols {
            sum.round_shift((self.footprint * self.footprint).trailing_zeros())
        } else {
            sum.round_div(self.weight(x))
        }
    }
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
        for d in Depth::ALL {
            assert_eq!(Depth::from_tile_type(d.tile_type()), Some(d));
            assert_eq!(Depth::from_pack(d.bytes() as u8, d.pack_sample_format()), Some(d));
        }
        assert_eq!(Depth::from_pack(1, vortex_pack::format::SAMPLE_FLOAT), None);
    }

    #[test]
    fn a_background_byte_fills_each_range() {
        assert_eq!((u8::from_u8_scaled(0xAB), u16::from_u8_scaled(0xAB)), (0xAB, 0xABAB));
        assert_eq!((u32::from_u8_scaled(255), f32::from_u8_scaled(255)), (u32::MAX, 1.0));
    }
}
