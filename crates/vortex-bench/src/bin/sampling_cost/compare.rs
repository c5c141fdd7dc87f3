//! How far a picture is from a model: PSNR and largest difference, where the mismatches lie
//! (page edges or inside pages), and the pixels drawn from a coarser page than they want.

use crate::SIZE;
use crate::api::{PageId, Rgba8Image};
use crate::report::db;

/// The pixels of a picture drawn from a coarser page than they want: how many, their bounding
/// box, and the wanted pages (with the LOD drawn instead).
#[derive(Clone, Debug, Default)]
pub struct Fallback {
    pub pixels: u64,
    /// x0, y0, x1, y1, inclusive.
    pub bounds: Option<[u32; 4]>,
    pub pages: Vec<(PageId, u8)>,
    /// The pixels' indices, row-major.
    pub at: Vec<usize>,
    /// Filled in by `Run::check`: the largest difference from the ideal over these pixels, and
    /// the PSNR against the ideal over all other pixels.
    pub ideal_max: u8,
    pub ideal_elsewhere: f64,
}

impl Fallback {
    pub fn add(&mut self, x: u32, y: u32, page: PageId, drawn: u8) {
        self.pixels += 1;
        self.at.push((y * SIZE[0] + x) as usize);
        self.bounds = Some(match self.bounds {
            None => [x, y, x, y],
            Some([x0, y0, x1, y1]) => [x0.min(x), y0.min(y), x1.max(x), y1.max(y)],
        });
        if !self.pages.iter().any(|&(p, _)| p == page) {
            self.pages.push((page, drawn));
        }
    }

    pub fn describe(&self) -> String {
        let Some([x0, y0, x1, y1]) = self.bounds else { return "none".into() };
        let pages: Vec<String> = self
            .pages
            .iter()
            .map(|(p, drawn)| format!("LOD {} page ({}, {}) drawn from LOD {drawn}", p.lod, p.x, p.y))
            .collect();
        format!(
            "{} pixels in x {x0}..={x1}, y {y0}..={y1} ({}); up to {} code values from the ideal there, \
             and {} against the ideal elsewhere",
            self.pixels,
            pages.join("; "),
            self.ideal_max,
            db(self.ideal_elsewhere)
        )
    }
}

/// PSNR (dB) and largest difference over the colour channels (alpha is opaque everywhere).
#[derive(Clone, Copy, Debug)]
pub struct Diff {
    pub psnr: f64,
    pub max: u8,
}

pub fn compare(got: &Rgba8Image, want: &Rgba8Image) -> Diff {
    compare_where(got, want, &vec![true; got.texels.len()])
}

/// [`compare`] over the pixels whose `mask` is true.
pub fn compare_where(got: &Rgba8Image, want: &Rgba8Image, mask: &[bool]) -> Diff {
    let mut sq = 0.0;
    let mut max = 0;
    let mut n = 0;
    for ((g, w), _) in got.texels.iter().zip(&want.texels).zip(mask).filter(|(_, m)| **m) {
        n += 1;
        for c in 0..3 {
            max = max.max(g[c].abs_diff(w[c]));
            sq += (g[c] as f64 - w[c] as f64).powi(2);
        }
    }
    let mse = sq / (n * 3).max(1) as f64;
    Diff { psnr: if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64.powi(2) / mse).log10() }, max }
}

#[derive(Clone, Debug)]
pub struct Check {
    pub own: Diff,
    pub ideal: Diff,
    pub fallback: Fallback,
    /// Pixels more than 2 code values off the own model, within a texel of a page edge / inside.
    pub edge_off: u64,
    pub inner_off: u64,
    /// Largest difference from the own model there.
    pub edge_max: u8,
    pub inner_max: u8,
    /// The pixel with the largest difference.
    pub worst: Worst,
    pub sampling_only_differs: bool,
    pub loaded_while_timed: usize,
}

/// The pixel farthest from the model (the first of them), in colour code values.
#[derive(Clone, Copy, Debug)]
pub struct Worst {
    pub err: u8,
    pub x: u32,
    pub y: u32,
    pub got: [u8; 4],
    pub want: [u8; 4],
}
