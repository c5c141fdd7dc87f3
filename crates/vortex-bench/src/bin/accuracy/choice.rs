//! What is measured: a [`Choice`] is one way to build the pyramid (a LOD filter and a tile
//! codec), with its label in tables and plots and its plot family.

use crate::tiler::{Bc7Effort, Codec, Filter, JxlEffort, PngLevel, RowFilter, Subsampling};

/// Every LOD filter, in the order of the tables.
pub const FILTERS: [Filter; 6] = Filter::ALL;

/// One way to build the pyramid: a filter and a codec.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub struct Choice {
    pub filter: u8,
    pub codec: CodecKey,
}

/// A sortable stand-in for `Codec`.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub enum CodecKey {
    Jpeg(u8, bool),
    Png(u8),
    Raw,
    Zstd(bool, i32),
    Bc1,
    Bc7(u8),
    /// A TIFF's Deflate tiles (not in the sweep).
    Deflate(bool, u8),
    /// A TIFF's LZW tiles (not in the sweep).
    Lzw(bool),
    /// JPEG XL at a quality (`None`: lossless) and an effort (not in the sweep yet).
    Jxl(Option<u8>, u8),
}

pub const PNG_LEVELS: [PngLevel; 3] = [PngLevel::Fast, PngLevel::Default, PngLevel::Best];
pub const BC7_EFFORTS: [Bc7Effort; 5] =
    [Bc7Effort::UltraFast, Bc7Effort::VeryFast, Bc7Effort::Fast, Bc7Effort::Basic, Bc7Effort::Slow];

impl CodecKey {
    pub fn of(codec: Codec) -> CodecKey {
        match codec {
            Codec::Jpeg { quality, subsampling } => CodecKey::Jpeg(quality, subsampling == Subsampling::S444),
            Codec::Png { level } => CodecKey::Png(PNG_LEVELS.iter().position(|l| *l == level).unwrap_or(0) as u8),
            Codec::Raw => CodecKey::Raw,
            // The sweep filters by rows' deltas only (no float samples, so no floating-point predictor).
            Codec::Zstd { level, filter } => CodecKey::Zstd(filter != RowFilter::None, level),
            Codec::Bc1 => CodecKey::Bc1,
            Codec::Deflate { level, filter } => CodecKey::Deflate(filter != RowFilter::None, level as u8),
            Codec::Lzw { filter } => CodecKey::Lzw(filter != RowFilter::None),
            Codec::Bc7 { effort } => CodecKey::Bc7(BC7_EFFORTS.iter().position(|e| *e == effort).unwrap_or(0) as u8),
            Codec::Jxl { quality, effort } => CodecKey::Jxl(quality, effort.get()),
        }
    }

    pub fn codec(self) -> Codec {
        match self {
            CodecKey::Jpeg(quality, s444) => {
                Codec::Jpeg { quality, subsampling: if s444 { Subsampling::S444 } else { Subsampling::S420 } }
            }
            CodecKey::Png(l) => Codec::Png { level: PNG_LEVELS[l as usize] },
            CodecKey::Raw => Codec::Raw,
            CodecKey::Zstd(delta, level) => Codec::Zstd { level, filter: RowFilter::delta(delta) },
            CodecKey::Bc1 => Codec::Bc1,
            CodecKey::Deflate(delta, level) => Codec::Deflate { level: level as u32, filter: RowFilter::delta(delta) },
            CodecKey::Lzw(delta) => Codec::Lzw { filter: RowFilter::delta(delta) },
            CodecKey::Bc7(e) => Codec::Bc7 { effort: BC7_EFFORTS[e as usize] },
            CodecKey::Jxl(quality, effort) => Codec::Jxl { quality, effort: JxlEffort::clamped(effort) },
        }
    }

    pub fn label(self) -> String {
        match self {
            CodecKey::Jpeg(q, s444) => format!("jpeg q{q} {}", if s444 { "4:4:4" } else { "4:2:0" }),
            CodecKey::Png(l) => format!("png {}", ["fast", "default", "best"][l as usize]),
            CodecKey::Raw => "raw".into(),
            CodecKey::Zstd(false, l) => format!("zstd {l}"),
            CodecKey::Zstd(true, l) => format!("zstd-delta {l}"),
            CodecKey::Bc1 => "bc1".into(),
            CodecKey::Deflate(false, l) => format!("deflate {l}"),
            CodecKey::Deflate(true, l) => format!("deflate-delta {l}"),
            CodecKey::Lzw(false) => "lzw".into(),
            CodecKey::Lzw(true) => "lzw-delta".into(),
            CodecKey::Bc7(e) => format!("bc7 {}", ["ultra-fast", "very-fast", "fast", "basic", "slow"][e as usize]),
            CodecKey::Jxl(Some(q), e) => format!("jxl q{q} e{e}"),
            CodecKey::Jxl(None, e) => format!("jxl lossless e{e}"),
        }
    }

    /// Plot family.
    pub fn family(self) -> usize {
        match self {
            CodecKey::Jpeg(_, false) => 2,
            CodecKey::Jpeg(_, true) => 3,
            CodecKey::Png(_) => 4,
            CodecKey::Raw => 5,
            CodecKey::Zstd(false, _) => 6,
            CodecKey::Zstd(true, _) => 7,
            CodecKey::Bc1 => 8,
            CodecKey::Bc7(_) => 9,
            // Not in the sweep; plotted beside zstd-delta, their lossless kin, if they ever are.
            CodecKey::Deflate(..) | CodecKey::Lzw(_) => 7,
            // Not in the sweep yet; lossy beside JPEG, lossless beside zstd-delta.
            CodecKey::Jxl(Some(_), _) => 2,
            CodecKey::Jxl(None, _) => 7,
        }
    }
}

impl Choice {
    pub fn new(filter: Filter, codec: Codec) -> Choice {
        let f = FILTERS.iter().position(|f| *f == filter).expect("a known filter") as u8;
        Choice { filter: f, codec: CodecKey::of(codec) }
    }

    pub fn filter(self) -> Filter {
        FILTERS[self.filter as usize]
    }

    pub fn label(self) -> String {
        if self.filter() == Filter::default() {
            self.codec.label()
        } else {
            format!("{} + {}", self.filter().name(), self.codec.label())
        }
    }

    /// Plot family: 0 other filters with PNG fast, 1 with raw, then the codec families (with
    /// the default filter), last other filters with JPEG.
    pub fn family(self) -> usize {
        match (self.filter(), self.codec) {
            (f, c) if f == Filter::default() => c.family(),
            (_, CodecKey::Raw) => 1,
            (_, CodecKey::Png(0)) => 0,
            _ => 10,
        }
    }
}

pub const FAMILIES: [&str; 11] = [
    "other filter + png fast",
    "other filter + raw",
    "jpeg 4:2:0",
    "jpeg 4:4:4",
    "png",
    "raw",
    "zstd",
    "zstd-delta",
    "bc1",
    "bc7",
    "other filter + jpeg",
];
