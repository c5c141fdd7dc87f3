//! The synthetic test images: deterministic 8-bit pictures, each built to stress one thing a
//! LOD filter or a codec can get wrong (smooth areas and edges, detail at and beyond Nyquist,
//! thin strokes on paper, colour under alpha 0), and the row source through which the
//! pipeline reads them.

mod alpha;
mod high_frequency;
mod noise;
mod photo;
mod text;

use std::sync::Arc;

use crate::tiler::{Channels, Depth, ImageHeader, PixelLayout, RowSource, TilerResult};

/// The images of a run, each with whether it is the extra variant (measured with a few choices
/// only, for one table, not plotted).
pub fn all(w: u32, h: u32) -> Vec<(Img, bool)> {
    vec![
        (photo::photo(w, h), false),
        (high_frequency::high_frequency(w, h), false),
        (text::text_art(w, h), false),
        (alpha::alpha_cutouts(w, h, false), false),
        (alpha::alpha_cutouts(w, h, true), true),
    ]
}

/// An 8-bit image in memory, RGB or RGBA, rows top down.
pub struct Img {
    pub key: &'static str,
    pub title: &'static str,
    pub what: &'static str,
    pub width: u32,
    pub height: u32,
    pub channels: usize,
    pub data: Arc<Vec<u8>>,
}

impl Img {
    pub fn layout(&self) -> PixelLayout {
        PixelLayout::new(if self.channels == 4 { Channels::Rgba } else { Channels::Rgb }, Depth::U8)
    }

    pub fn has_alpha(&self) -> bool {
        self.channels == 4
    }

    pub fn source(&self) -> MemSource {
        let header = ImageHeader { width: self.width, height: self.height, layout: self.layout() };
        MemSource { header, data: self.data.clone(), next: 0 }
    }

    pub fn megapixels(&self) -> f64 {
        self.width as f64 * self.height as f64 / 1e6
    }

    /// Builds an image from a function of (x, y) giving RGBA in [0, 255] (alpha ignored for RGB).
    pub fn from_fn(w: u32, h: u32, channels: usize, f: impl Fn(u32, u32) -> [f64; 4]) -> Vec<u8> {
        let mut data = Vec::with_capacity(w as usize * h as usize * channels);
        for y in 0..h {
            for x in 0..w {
                let px = f(x, y);
                data.extend(px[..channels].iter().map(|v| v.round().clamp(0.0, 255.0) as u8));
            }
        }
        data
    }
}

/// The image as the pipeline reads it, one row at a time.
pub struct MemSource {
    pub header: ImageHeader,
    pub data: Arc<Vec<u8>>,
    pub next: usize,
}

impl RowSource for MemSource {
    fn header(&self) -> ImageHeader {
        self.header
    }
    fn read_row(&mut self, row: &mut [u8]) -> TilerResult<()> {
        let n = row.len();
        row.copy_from_slice(&self.data[self.next * n..(self.next + 1) * n]);
        self.next += 1;
        Ok(())
    }
    fn describe(&self) -> String {
        "memory".into()
    }
}
