//! One measurement: a split through the real pipeline into a temporary pack (timed), its tiles
//! decoded and every texel of every LOD compared with the reference; the errors and times it
//! gives, and the figures derived from them.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use vortex_pack::{Pack, Tile, TileId, WriteOptions};

use crate::choice::Choice;
use crate::images::Img;
use crate::reference::RefLevel;
use crate::tiler::{Background, Layout, PackSink, SplitOptions, split};
use crate::{BORDER, PSNR_CAP, TILE_SIZE};

#[derive(Clone, Copy, Default)]
pub struct Err {
    pub sse: f64,
    pub samples: f64,
    pub max: f64,
    pub sse_a: f64,
    pub samples_a: f64,
    pub max_a: f64,
}

impl Err {
    pub fn add(&mut self, o: &Err) {
        self.sse += o.sse;
        self.samples += o.samples;
        self.max = self.max.max(o.max);
        self.sse_a += o.sse_a;
        self.samples_a += o.samples_a;
        self.max_a = self.max_a.max(o.max_a);
    }

    pub fn psnr(&self) -> f64 {
        psnr(self.sse, self.samples)
    }

    pub fn psnr_alpha(&self) -> f64 {
        psnr(self.sse_a, self.samples_a)
    }
}

pub use vortex_bench::measure::psnr_8bit as psnr;

/// What one choice gave on one image.
pub struct Measured {
    pub choice: Choice,
    pub times: Vec<f64>,
    pub bytes_per_tile: f64,
    /// Per LOD, against the physical reference.
    pub lods: Vec<Err>,
    /// Exact filters: largest difference from the filter's own float definition over LODs 1
    /// and up, colour and alpha.
    pub own_max: Option<(f64, f64)>,
}

impl Measured {
    pub fn median_s(&self) -> f64 {
        vortex_bench::measure::median(&mut self.times.clone())
    }

    /// How far the runs spread: (slowest - fastest) / median, leaving out the slowest and the
    /// fastest run when there are five or more.
    pub fn spread(&self) -> f64 {
        let mut t = self.times.clone();
        t.sort_by(f64::total_cmp);
        let n = t.len();
        let (lo, hi) = if n >= 5 { (t[1], t[n - 2]) } else { (t[0], t[n - 1]) };
        (hi - lo) / self.median_s()
    }

    pub fn ms_per_mpx(&self, img: &Img) -> f64 {
        1000.0 * self.median_s() / img.megapixels()
    }

    pub fn total(&self, range: std::ops::Range<usize>) -> Err {
        let mut e = Err::default();
        for l in &self.lods[range] {
            e.add(l);
        }
        e
    }

    pub fn all(&self) -> Err {
        self.total(0..self.lods.len())
    }

    pub fn coarse(&self) -> Err {
        self.total(1..self.lods.len())
    }

    /// The single error figure of the plots: colour (shown over black) PSNR over every texel
    /// of every LOD.
    pub fn plot_psnr(&self) -> f64 {
        self.all().psnr().min(PSNR_CAP)
    }
}

/// Runs one split into a pack at `dest`; returns its wall time in seconds.
pub fn split_once(img: &Img, layout: &Layout, choice: Choice, dest: &Path) -> Result<f64> {
    let codec = choice.codec.codec();
    let opts = SplitOptions {
        tile_size: TILE_SIZE,
        border: BORDER,
        codec,
        background: Background::Edge,
        flatten: false,
        tile_depth: None,
        filter: choice.filter(),
        max_memory: vortex_tiler::limits::DEFAULT_MEMORY,
        down_to_one_texel: false,
        reencode: None,
        fast_shrink: false,
    };
    let stored = codec.stored_layout(img.layout(), false, None)?;
    let started = Instant::now();
    let sink = PackSink::create(dest, layout, stored, codec, b"{}", WriteOptions::default())?;
    let summary = split::split(Box::new(img.source()), &sink, &opts, &())?;
    sink.finish()?;
    let elapsed = started.elapsed().as_secs_f64();
    if summary.tiles != layout.total_tiles() {
        bail!("{} tiles of {}", summary.tiles, layout.total_tiles());
    }
    Ok(elapsed)
}

/// Decodes every tile of the pack that shows part of the image and compares each LOD with the
/// reference; `time` is the first run's.
pub fn measure(
    pack_path: &Path,
    img: &Img,
    layout: &Layout,
    refs: &[RefLevel],
    choice: Choice,
    shown_lut: &[[f64; 256]],
    time: f64,
) -> Result<Measured> {
    let pack = Pack::open(pack_path)?;
    let (p, b) = (layout.payload(), layout.border);
    let (mut bytes, mut tiles) = (0u64, 0u64);
    let mut lods = Vec::new();
    let filter = choice.filter();
    let mut own_max = filter.is_exact().then_some((0.0f64, 0.0f64));
    for (lod, r) in refs.iter().enumerate() {
        let (lw, lh) = (r.width, r.height);
        let mut texels = vec![0u8; lw as usize * lh as usize * 4];
        for ty in 0..lh.div_ceil(p) {
            for tx in 0..lw.div_ceil(p) {
                let lod = lod as u32;
                bytes += match pack.tile(vortex_pack::TileId::new(lod, tx, ty))? {
                    Tile::Data(_, payload) => payload.len() as u64,
                    _ => 0,
                };
                tiles += 1;
                let rgba = pack.decode_rgba8(TileId { lod, x: tx, y: ty })?.context("a tile is absent")?;
                for y in ty * p..((ty + 1) * p).min(lh) {
                    let src = (((y - ty * p + b) * TILE_SIZE + b) * 4) as usize;
                    let x0 = tx * p;
                    let n = (((tx + 1) * p).min(lw) - x0) as usize * 4;
                    let dst = ((y * lw + x0) * 4) as usize;
                    texels[dst..dst + n].copy_from_slice(&rgba[src..src + n]);
                }
            }
        }
        let mut e = Err::default();
        for (i, px) in texels.chunks_exact(4).enumerate() {
            let a = px[3] as usize;
            for ch in 0..3 {
                let d = shown_lut[a][px[ch] as usize] - r.shown[i][ch];
                e.sse += d * d;
                e.max = e.max.max(d.abs());
            }
            e.samples += 3.0;
            if img.has_alpha() {
                let d = px[3] as f64 - r.alpha[i];
                e.sse_a += d * d;
                e.max_a = e.max_a.max(d.abs());
                e.samples_a += 1.0;
            }
            if let (Some((mc, ma)), true) = (own_max.as_mut(), lod > 0) {
                let own = r.sums[i].own(filter, img.has_alpha());
                for ch in 0..3 {
                    *mc = mc.max((px[ch] as f64 - own[ch]).abs());
                }
                *ma = ma.max((px[3] as f64 - own[3]).abs());
            }
        }
        lods.push(e);
    }
    Ok(Measured { choice, times: vec![time], bytes_per_tile: bytes as f64 / tiles as f64, lods, own_max })
}

pub struct ImageResult {
    pub img: Img,
    pub measured: BTreeMap<Choice, Measured>,
    /// A variant measured with a few choices only, for one table (not plotted).
    pub extra: bool,
}
