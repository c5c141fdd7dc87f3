//! LOD filters (`--filter`): how a texel of LOD k+1 is made from the texels under it.
//!
//! The exact filters (`box`, `linear`, `premultiplied`, `linear-premultiplied`) are all means
//! over the texel's source footprint, computed from exact integer sums that cascade down the
//! pyramid ([`crate::pyramid`]) and rounded once per stored texel. They differ only in what is
//! summed: the stored values (`box`), fixed-point linear light decoded from sRGB through a
//! table (`linear`), colour times alpha (`premultiplied`) or both. The resampling filters
//! (`lanczos3`, `mitchell`) compute each LOD from the rounded previous one with
//! `fast_image_resize`, band by band ([`crate::pyramid::resample`]).

use std::sync::OnceLock;

use crate::pixel::{Depth, PixelLayout, Sample};
use crate::pyramid::reduce::{Acc, ExactRow, Reducer};

/// How LOD k+1 is made from LOD k.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Filter {
    /// Exact mean of the stored (sRGB-encoded) values of the source pixels under the texel,
    /// rounded once, halves up.
    Box,
    /// Exact mean in linear light: colour decoded from sRGB, averaged, encoded back (nearest
    /// code value); alpha averaged as stored.
    Linear,
    /// Colour weighted by alpha (premultiplied), then divided by the mean alpha: transparent
    /// texels never tint visible ones; fully transparent results are black. Same as box
    /// without alpha.
    Premultiplied,
    /// Premultiplied and in linear light. Same as linear without alpha. The default: of the
    /// filters measured in docs/accuracy.md it comes closest to the linear-light reference.
    #[default]
    LinearPremultiplied,
    /// Lanczos3 (fast_image_resize) in stored values, each LOD from the previous one, alpha
    /// premultiplied.
    Lanczos3,
    /// Mitchell-Netravali cubic (B = C = 1/3), like lanczos3.
    Mitchell,
    /// For label images: the most frequent texel of each 2x2 block of the previous LOD, ties
    /// to the first of top-left, top-right, bottom-left, bottom-right; never a new value.
    Mode,
    /// For label images: the top-left texel of each 2x2 block; never a new value.
    Nearest,
}

impl Filter {
    /// Every filter of images, in the order `--help` lists them.
    pub const ALL: [Filter; 6] = [
        Filter::Box,
        Filter::Linear,
        Filter::Premultiplied,
        Filter::LinearPremultiplied,
        Filter::Lanczos3,
        Filter::Mitchell,
    ];
    /// The filters of label images, listed after [`ALL`](Self::ALL).
    pub const LABELS: [Filter; 2] = [Filter::Mode, Filter::Nearest];
    /// Every filter by name: [`ALL`](Self::ALL), then [`LABELS`](Self::LABELS).
    pub const NAMED: [Filter; Filter::ALL.len() + Filter::LABELS.len()] = {
        let mut named = [Filter::Box; Filter::ALL.len() + Filter::LABELS.len()];
        let mut i = 0;
        while i < named.len() {
            named[i] = if i < Filter::ALL.len() { Filter::ALL[i] } else { Filter::LABELS[i - Filter::ALL.len()] };
            i += 1;
        }
        named
    };

    /// The name used on the command line and in `info.json`.
    pub fn name(self) -> &'static str {
        match self {
            Filter::Box => "box",
            Filter::Linear => "linear",
            Filter::Premultiplied => "premultiplied",
            Filter::LinearPremultiplied => "linear-premultiplied",
            Filter::Lanczos3 => "lanczos3",
            Filter::Mitchell => "mitchell",
            Filter::Mode => "mode",
            Filter::Nearest => "nearest",
        }
    }

    /// The filter `name` names, if any.
    pub fn from_name(name: &str) -> Option<Filter> {
        Filter::NAMED.into_iter().find(|f| f.name() == name)
    }

    /// One line on what the filter does (`--help` lists it).
    pub fn about(self) -> &'static str {
        match self {
            Filter::Box => {
                "Exact mean of the stored (sRGB-encoded) values of the source pixels under the texel, rounded once, halves up"
            }
            Filter::Linear => {
                "Exact mean in linear light: colour decoded from sRGB, averaged, encoded back (nearest code value); alpha averaged as stored"
            }
            Filter::Premultiplied => {
                "Colour weighted by alpha (premultiplied), then divided by the mean alpha: transparent texels never tint visible ones; fully transparent results are black. Same as box without alpha"
            }
            Filter::LinearPremultiplied => {
                "Premultiplied and in linear light. Same as linear without alpha. The default: of the filters measured in docs/accuracy.md it comes closest to the linear-light reference"
            }
            Filter::Lanczos3 => {
                "Lanczos3 (fast_image_resize) in stored values, each LOD from the previous one, alpha premultiplied"
            }
            Filter::Mitchell => "Mitchell-Netravali cubic (B = C = 1/3), like lanczos3",
            Filter::Mode => {
                "For label images: the most frequent texel of each 2x2 block of the previous LOD, ties to the first of top-left, top-right, bottom-left, bottom-right; never a new value"
            }
            Filter::Nearest => "For label images: the top-left texel of each 2x2 block; never a new value",
        }
    }

    /// Whether this filter is an exact footprint mean (the cascade of sums) rather than a
    /// resampling kernel applied level by level.
    pub fn is_exact(self) -> bool {
        !matches!(self, Filter::Lanczos3 | Filter::Mitchell | Filter::Mode | Filter::Nearest)
    }

    /// Whether this filter picks one texel of each 2x2 block (`pyramid::labels`).
    pub(crate) fn is_label(self) -> bool {
        matches!(self, Filter::Mode | Filter::Nearest)
    }

    /// The filter a run uses on `depth` samples when none is asked for: the default for 8- and
    /// 16-bit images, `box` for 32-bit and float ones (their values are not sRGB codes).
    pub(crate) fn default_for(depth: Depth) -> Filter {
        if depth.is_narrow_int() { Filter::default() } else { Filter::Box }
    }

    /// Refuses a filter that makes no sense on `layout`: the linear-light and premultiplied
    /// filters decode 8/16-bit sRGB codes and weigh them by an alpha of that range, and
    /// lanczos3/mitchell resample 8/16-bit levels, so 32-bit and float images take `box` (an
    /// exact mean), `nearest`, and for 32-bit integers (label images) `mode` too.
    pub fn check(self, layout: PixelLayout) -> Result<(), String> {
        let depth = layout.depth;
        let ok = match self {
            _ if depth.is_narrow_int() => true,
            Filter::Box | Filter::Nearest => true,
            Filter::Mode => !depth.is_float(),
            _ => false,
        };
        if ok {
            return Ok(());
        }
        let why = match self {
            Filter::Mode => "mode compares values exactly, which float samples are not made for; use nearest or box",
            Filter::Lanczos3 | Filter::Mitchell => {
                "it resamples 8- and 16-bit levels; use box (an exact mean) or, for label images, mode or nearest"
            }
            _ => "it decodes 8- and 16-bit sRGB codes (and their alpha); use box, the exact mean of the stored values",
        };
        Err(format!("--filter {self} cannot take a {layout} image: {why}"))
    }

    fn linear(self) -> bool {
        matches!(self, Filter::Linear | Filter::LinearPremultiplied)
    }

    fn premultiplied(self) -> bool {
        matches!(self, Filter::Premultiplied | Filter::LinearPremultiplied)
    }
}

impl std::fmt::Display for Filter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The sRGB decode of `v` in [0, 1] (IEC 61966-2-1), in f64.
pub fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
}

/// The sRGB encode of linear `l` in [0, 1], in f64.
#[cfg_attr(not(feature = "testing"), allow(dead_code))] // read by the tests, through `testing`
pub fn linear_to_srgb(l: f64) -> f64 {
    if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 }
}

/// sRGB code values <-> linear light in fixed point, for one sample depth.
///
/// A code `c` decodes to `round(srgb_to_linear(c / MAX) * scale)`. A fixed-point value `v`
/// encodes to the code nearest to `linear_to_srgb(v / scale)`, exactly: `thresholds[c]` is the
/// smallest fixed-point value whose encoding is `c` or more, `ceil(srgb_to_linear((c - 0.5) /
/// MAX) * scale)`. The scale is large enough that neighbouring codes never share a value (the
/// curve's slope is at least `scale / (MAX * 12.92)`, above 1), so decoding then encoding is
/// the identity.
pub struct SrgbTable {
    /// Largest code value: 255 or 65535.
    #[cfg_attr(not(feature = "testing"), allow(dead_code))] // read by the tests, through `testing`
    pub max_code: u32,
    /// Fixed-point value of linear 1.0: 65535 for 8-bit codes, 2^20 - 1 for 16-bit ones (so
    /// that every sum of a pyramid that `Layout` accepts fits in a u64, see `ExactFilter`).
    pub scale: u32,
    decode: Vec<u32>,
    thresholds: Vec<u32>,
    /// 8-bit codes only: the encoding of every fixed-point value, so encoding is one lookup.
    encode: Vec<u8>,
}

impl SrgbTable {
    fn build(max_code: u32, scale: u32) -> SrgbTable {
        let (m, s) = (max_code as f64, scale as f64);
        let decode = (0..=max_code).map(|c| (srgb_to_linear(c as f64 / m) * s).round() as u32).collect();
        let thresholds = (0..=max_code)
            .map(|c| if c == 0 { 0 } else { (srgb_to_linear((c as f64 - 0.5) / m) * s).ceil() as u32 })
            .collect();
        let mut t = SrgbTable { max_code, scale, decode, thresholds, encode: Vec::new() };
        if max_code == 255 {
            t.encode = (0..=scale).map(|v| t.search(v) as u8).collect();
        }
        t
    }

    /// The table for 8-bit (`Depth::U8`) or 16-bit codes; built once.
    pub fn get(depth: Depth) -> &'static SrgbTable {
        static U8: OnceLock<SrgbTable> = OnceLock::new();
        static U16: OnceLock<SrgbTable> = OnceLock::new();
        match depth {
            Depth::U8 => U8.get_or_init(|| SrgbTable::build(255, 65535)),
            // `Filter::check` keeps 32-bit and float samples away from the sRGB tables.
            _ => U16.get_or_init(|| SrgbTable::build(65535, (1 << 20) - 1)),
        }
    }

    /// Linear light of code `c`, in fixed point.
    #[inline]
    pub fn decode(&self, c: u16) -> u32 {
        self.decode[c as usize]
    }

    /// 8-bit codes only: the code of every fixed-point value up to `scale`, for callers that
    /// encode whole rows (one lookup, no branch per value).
    pub fn encode_table(&self) -> Option<&[u8]> {
        (!self.encode.is_empty()).then_some(self.encode.as_slice())
    }

    /// The code nearest to the fixed-point linear value `v` (clamped to `scale`).
    #[inline]
    pub fn encode(&self, v: u64) -> u16 {
        let v = v.min(self.scale as u64) as u32;
        if self.encode.is_empty() { self.search(v) } else { self.encode[v as usize] as u16 }
    }

    fn search(&self, v: u32) -> u16 {
        (self.thresholds.partition_point(|t| *t <= v) - 1) as u16
    }
}

/// What the exact cascade sums for a filter, and how a texel is made from the sums.
///
/// Per source pixel each colour channel contributes `colour' * alpha'`, where `colour'` is the
/// stored value or, in linear light, its fixed-point decode, and `alpha'` is the stored alpha
/// when premultiplying and 1 otherwise; alpha contributes itself. A texel's colour is then
/// `round(sum / pixels)` or, premultiplied, `round(sum / alpha sum)` (0 if the alpha sum is 0),
/// encoded back to sRGB in linear light; its alpha is `round(alpha sum / pixels)`.
#[derive(Clone, Copy)]
pub struct ExactFilter {
    table: Option<&'static SrgbTable>,
    premultiplied: bool,
    channels: usize,
    /// Index of the alpha channel, if the layout has one.
    alpha: Option<usize>,
    /// Largest value one pixel contributes to a sum.
    max_value: u64,
}

impl ExactFilter {
    /// The sums for `filter` on `layout`; `None` when they are the stored samples themselves
    /// (box, or premultiplied without alpha), which the pyramid sums directly.
    pub fn new(filter: Filter, layout: PixelLayout) -> Option<ExactFilter> {
        let alpha = layout.channels.has_alpha().then(|| layout.channels.count() - 1);
        let premultiplied = filter.premultiplied() && alpha.is_some();
        // 32-bit and float samples take box alone of the exact filters (`Filter::check`).
        if !filter.is_exact() || (!filter.linear() && !premultiplied) || !layout.depth.is_narrow_int() {
            return None;
        }
        let table = filter.linear().then(|| SrgbTable::get(layout.depth));
        let sample_max = if layout.depth == Depth::U8 { 255u64 } else { 65535 };
        let colour_max = table.map_or(sample_max, |t| t.scale as u64);
        let max_value = if premultiplied { colour_max * sample_max } else { colour_max };
        Some(ExactFilter { table, premultiplied, channels: layout.channels.count(), alpha, max_value })
    }

    /// Largest value one pixel contributes to a sum.
    pub fn max_value(&self) -> u64 {
        self.max_value
    }

    /// Whether the sums of a pyramid of `lod_count` levels need a `u128` accumulator: a texel
    /// of the coarsest level sums `4^(lod_count - 1)` pixels, and rounding doubles a sum.
    pub fn needs_u128(&self, lod_count: u32) -> bool {
        sums_need_u128(self.max_value, lod_count)
    }

    /// Adds a source row to `reducer`: linear light without alpha (the default filter on grey
    /// and RGB) is decoded as it is summed; otherwise the row is first made into the values
    /// the cascade sums, in `scratch` (one per sample).
    pub fn push_row<'r, T: Sample, A: Acc>(
        &self,
        reducer: &'r mut Reducer<A>,
        row: &[T],
        scratch: &mut [u64],
    ) -> Option<ExactRow<'r, A>> {
        if let (Some(t), None) = (self.table, self.alpha) {
            return reducer.push_mapped(row, |s: T| A::from(t.decode(s.to_u16()) as u64));
        }
        self.prepare(row, scratch);
        reducer.push(scratch)
    }

    /// Turns a row of samples into the values the cascade sums (`out.len() == row.len()`).
    pub fn prepare<T: Sample>(&self, row: &[T], out: &mut [u64]) {
        let c = self.channels;
        for (px, o) in row.chunks_exact(c).zip(out.chunks_exact_mut(c)) {
            let weight = match self.alpha {
                Some(a) if self.premultiplied => px[a].to_u64(),
                _ => 1,
            };
            for ch in 0..c {
                o[ch] = if Some(ch) == self.alpha {
                    px[ch].to_u64()
                } else {
                    let v = match self.table {
                        Some(t) => t.decode(px[ch].to_u16()) as u64,
                        None => px[ch].to_u64(),
                    };
                    v * weight
                };
            }
        }
    }

    /// Rounds an exact row into samples.
    pub fn finish<T: Sample, A: Acc>(&self, exact: &ExactRow<'_, A>, out: &mut [T]) {
        if let (Some(t), None) = (self.table, self.alpha) {
            match t.encode_table() {
                Some(codes) => {
                    // Clamped to the table's last entry (`scale`), which also spares the
                    // bounds check: this loop is most of a level's rounding.
                    let last = codes.len() as u64 - 1;
                    exact.map_means(out, |v| T::from_u16(codes[v.min(last) as usize] as u16))
                }
                None => exact.map_means(out, |v| T::from_u16(t.encode(v))),
            }
            return;
        }
        let c = self.channels;
        for (x, (sums, o)) in exact.sums.chunks_exact(c).zip(out.chunks_exact_mut(c)).enumerate() {
            let alpha_sum = self.alpha.map(|a| sums[a]);
            for ch in 0..c {
                if Some(ch) == self.alpha {
                    o[ch] = T::from_u64(exact.mean(x, sums[ch]));
                    continue;
                }
                let v = match alpha_sum {
                    Some(a) if self.premultiplied => {
                        if a == A::default() {
                            0
                        } else {
                            sums[ch].round_ratio(a)
                        }
                    }
                    _ => exact.mean(x, sums[ch]),
                };
                o[ch] = match self.table {
                    Some(t) => T::from_u16(t.encode(v)),
                    None => T::from_u64(v),
                };
            }
        }
    }
}

/// Whether sums of `4^(lod_count - 1)` values up to `max_value`, doubled for rounding, can
/// exceed a `u64`.
pub fn sums_need_u128(max_value: u64, lod_count: u32) -> bool {
    let pixels = 1u128 << (2 * lod_count.saturating_sub(1));
    (max_value as u128 * pixels) * 2 + max_value as u128 > u64::MAX as u128
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_filter_is_found_by_its_name_once() {
        for f in Filter::NAMED {
            assert_eq!(Filter::NAMED.iter().filter(|g| g.name() == f.name()).count(), 1, "{f}");
            assert_eq!(Filter::from_name(f.name()), Some(f));
        }
        assert_eq!(Filter::from_name("Box"), None, "names are matched exactly, as clap did");
    }
}
