//! The generated blocks of `docs/accuracy.md`: every table, figure list and sentence that
//! carries a number or a verdict of this run, each named by its marker (`accuracy:NAME`). The
//! prose around them is written by hand in the document; [`blocks`] is the whole list.

mod alpha0;
mod codecs;
mod defaults;
mod filters;
mod fronts;
mod overview;

use vortex_bench::splice::Block;

use crate::choice::Choice;
use crate::images::Img;
use crate::measure::{ImageResult, Measured};
use crate::sweep::Defaults;
use crate::tiler::{Codec, Filter, Layout, PngLevel, Subsampling};

/// What the report says about the run itself.
pub struct RunInfo {
    pub size: (u32, u32),
    pub layout: Layout,
    pub rounds: usize,
    pub load_start: Option<f64>,
    pub load_end: Option<f64>,
    pub seconds: f64,
}

/// Every block of the document, named as its markers are.
pub fn blocks(all: &[ImageResult], d: &Defaults, run: &RunInfo) -> Vec<Block> {
    let res = Results { all, main: all.iter().filter(|r| !r.extra).collect() };
    vec![
        Block::new("accuracy:run", overview::run(run)),
        Block::new("accuracy:summary", overview::summary(&res, d)),
        Block::new("accuracy:setup", overview::setup(all, run)),
        Block::new("accuracy:measured", overview::measured(&res, run)),
        Block::new("accuracy:filters-table", filters::table(&res, d)),
        Block::new("accuracy:filters-findings", filters::findings(&res)),
        Block::new("accuracy:per-lod", filters::per_lod(&res, &run.layout)),
        Block::new("accuracy:codecs-table", codecs::table(&res, d)),
        Block::new("accuracy:codecs-findings", codecs::findings(&res, d)),
        Block::new("accuracy:every-choice", codecs::every_choice(&res, d)),
        Block::new("accuracy:alpha0-table", alpha0::table(&res)),
        Block::new("accuracy:alpha0-findings", alpha0::findings(&res, d)),
        Block::new("accuracy:fronts", fronts::fronts(&res, d)),
        Block::new("accuracy:defaults", defaults::defaults(&res, d)),
    ]
}

pub fn db(v: f64) -> String {
    if v.is_infinite() {
        "exact".into()
    } else if v.is_nan() {
        "n/a".into()
    } else {
        format!("{v:.2}")
    }
}

/// One decimal, "n/a" for a missing number.
pub fn f1(v: f64) -> String {
    if v.is_nan() { "n/a".into() } else { format!("{v:.1}") }
}

pub fn f2(v: f64) -> String {
    if v.is_nan() { "n/a".into() } else { format!("{v:.2}") }
}

pub fn kib(bytes: f64) -> String {
    format!("{:.1}", bytes / 1024.0)
}

pub fn get(r: &ImageResult, filter: Filter, codec: Codec) -> Option<&Measured> {
    r.measured.get(&Choice::new(filter, codec))
}

/// What the document reads: the results by image key.
pub struct Results<'a> {
    pub all: &'a [ImageResult],
    /// The plotted images (not the extra variant).
    pub main: Vec<&'a ImageResult>,
}

impl<'a> Results<'a> {
    pub fn image(&self, key: &str) -> Option<&'a ImageResult> {
        self.all.iter().find(|r| r.img.key == key)
    }

    /// A number from one choice on one image, NaN if it was not measured.
    pub fn num(&self, key: &str, filter: Filter, codec: Codec, f: impl Fn(&Measured, &Img) -> f64) -> f64 {
        self.image(key).and_then(|r| get(r, filter, codec).map(|m| f(m, &r.img))).unwrap_or(f64::NAN)
    }

    /// Total median time over total megapixels of the main images that have the choice.
    pub fn ms(&self, filter: Filter, codec: Codec) -> f64 {
        let (mut t, mut mpx) = (0.0, 0.0);
        for r in &self.main {
            if let Some(m) = get(r, filter, codec) {
                t += m.median_s();
                mpx += r.img.megapixels();
            }
        }
        if mpx == 0.0 { f64::NAN } else { 1000.0 * t / mpx }
    }

    /// Time of `a` over time of `b`, summed over the main images that have both.
    pub fn ratio(&self, a: (Filter, Codec), b: (Filter, Codec)) -> f64 {
        let (mut ta, mut tb) = (0.0, 0.0);
        for r in &self.main {
            if let (Some(x), Some(y)) = (get(r, a.0, a.1), get(r, b.0, b.1)) {
                ta += x.median_s();
                tb += y.median_s();
            }
        }
        if tb == 0.0 { f64::NAN } else { ta / tb }
    }

    /// Mean over the main images that have the choice of its bytes per tile.
    pub fn bytes(&self, filter: Filter, codec: Codec) -> f64 {
        let v: Vec<f64> = self.main.iter().filter_map(|r| get(r, filter, codec).map(|m| m.bytes_per_tile)).collect();
        if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
    }

    /// Bytes of `a` over bytes of `b`, summed over the main images that have both.
    pub fn bytes_ratio(&self, a: (Filter, Codec), b: (Filter, Codec)) -> f64 {
        let (mut ba, mut bb) = (0.0, 0.0);
        for r in &self.main {
            if let (Some(x), Some(y)) = (get(r, a.0, a.1), get(r, b.0, b.1)) {
                ba += x.bytes_per_tile;
                bb += y.bytes_per_tile;
            }
        }
        if bb == 0.0 { f64::NAN } else { ba / bb }
    }
}

pub const PNG_FAST: Codec = Codec::Png { level: PngLevel::Fast };

pub fn jpeg(quality: u8, s444: bool) -> Codec {
    Codec::Jpeg { quality, subsampling: if s444 { Subsampling::S444 } else { Subsampling::S420 } }
}
