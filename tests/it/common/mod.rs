//! Shared test helpers: in-memory sources, a sink that keeps tiles, and a naive whole-image
//! pyramid (the oracle the streaming pipeline must match byte for byte).

pub mod cli;
pub mod compare;
pub mod nginx;
pub mod picture;
pub mod s3;
pub mod server;
pub mod webdriver;

use std::collections::BTreeMap;
use std::sync::Mutex;

use vortex_tiler::background::Background;
use vortex_tiler::codec::{Codec, PngLevel};
use vortex_tiler::error::Result;
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
use vortex_tiler::pyramid::Filter;
use vortex_tiler::sink::TileSink;
use vortex_tiler::source::{ImageHeader, RowSource};
use vortex_tiler::split::{SplitOptions, Summary, split};

/// Outside CI a test that lacks an outside part skips with a note; under `CI=true` (where
/// `.ci/run` installs every part) it fails instead, saying what was missing.
pub fn skip_unless_ci(what: &str, why: &str) {
    assert!(std::env::var("CI").map_or(true, |v| v != "true"), "CI=true and {why}");
    eprintln!("note: skipping {what}: {why}");
}

/// The Python named by `VORTEX_PYVIPS` if it imports `modules` (`"zarr, numpy"`); else
/// [`skip_unless_ci`] naming `what` and the packages that Python needs (`install`).
pub fn python_with(modules: &str, what: &str, install: &str) -> Option<std::path::PathBuf> {
    let python = std::env::var_os("VORTEX_PYVIPS").map(std::path::PathBuf::from);
    let imports = python.as_ref().is_some_and(|p| {
        std::process::Command::new(p)
            .args(["-c", &format!("import {modules}")])
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if !imports {
        skip_unless_ci(what, &format!("no {modules}: set VORTEX_PYVIPS to a Python with {install}"));
        return None;
    }
    python
}

/// Whether `program arg` runs; if not, [`skip_unless_ci`] naming the Debian `package` that has it.
pub fn have_program(program: &str, arg: &str, package: &str) -> bool {
    let found = std::process::Command::new(program).arg(arg).output().is_ok();
    if !found {
        skip_unless_ci(&format!("a test that runs {program}"), &format!("no {program} (apt-get install {package})"));
    }
    found
}
use vortex_tiler::testing::{SrgbTable, resample_level};

/// An image in memory: samples widened to u16 whatever the depth.
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub layout: PixelLayout,
    pub samples: Vec<u16>,
}

impl Image {
    pub fn channels(&self) -> usize {
        self.layout.channels.count()
    }

    /// Deterministic pseudo-random content from `seed`.
    pub fn random(width: u32, height: u32, layout: PixelLayout, seed: u64) -> Image {
        let max = if layout.depth == Depth::U8 { 255u64 } else { 65535 };
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let n = width as usize * height as usize * layout.channels.count();
        let samples = (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state % (max + 1)) as u16
            })
            .collect();
        Image { width, height, layout, samples }
    }

    pub fn source(&self) -> Box<dyn RowSource> {
        Box::new(MemSource { image: self.clone(), next: 0 })
    }
}

struct MemSource {
    image: Image,
    next: usize,
}

impl RowSource for MemSource {
    fn header(&self) -> ImageHeader {
        ImageHeader { width: self.image.width, height: self.image.height, layout: self.image.layout }
    }
    fn read_row(&mut self, row: &mut [u8]) -> Result<()> {
        let n = self.image.width as usize * self.image.channels();
        let src = &self.image.samples[self.next * n..(self.next + 1) * n];
        match self.image.layout.depth {
            Depth::U8 => row.iter_mut().zip(src).for_each(|(o, s)| *o = *s as u8),
            // Test images are 8- or 16-bit.
            _ => row.chunks_exact_mut(2).zip(src).for_each(|(o, s)| o.copy_from_slice(&s.to_ne_bytes())),
        }
        self.next += 1;
        Ok(())
    }
    fn describe(&self) -> String {
        "memory".into()
    }
    fn rewind(&mut self) -> Result<()> {
        self.next = 0;
        Ok(())
    }
}

/// Keeps every tile's encoded bytes.
#[derive(Default)]
pub struct MemSink {
    pub tiles: Mutex<BTreeMap<(u32, u32, u32), Vec<u8>>>,
}

impl TileSink for MemSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let old = self.tiles.lock().unwrap().insert((lod, x, y), bytes.to_vec());
        assert!(old.is_none(), "tile ({lod}, {x}, {y}) written twice");
        Ok(())
    }
    fn bytes_written(&self) -> u64 {
        self.tiles.lock().unwrap().values().map(|v| v.len() as u64).sum()
    }
}

pub fn png_options(tile_size: u32, border: u32, background: Background) -> SplitOptions {
    SplitOptions {
        tile_size,
        border,
        codec: Codec::Png { level: PngLevel::Fast },
        background,
        flatten: false,
        tile_depth: None,
        filter: Filter::Box,
        max_memory: 1 << 30,
        down_to_one_texel: false,
        reencode: None,
        fast_shrink: false,
    }
}

/// Tiles by (lod, x, y), decoded to u16 samples.
pub type Tiles = BTreeMap<(u32, u32, u32), Vec<u16>>;

/// Runs the real pipeline on `threads` threads and returns every tile decoded to u16 samples.
pub fn run_pipeline(image: &Image, opts: &SplitOptions, threads: usize) -> (Summary, Tiles) {
    let sink = MemSink::default();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    let summary = pool.install(|| split(image.source(), &sink, opts, &())).expect("pipeline runs");
    let tiles = sink.tiles.into_inner().unwrap().into_iter().map(|(k, png)| (k, decode_png(&png))).collect();
    (summary, tiles)
}

pub fn decode_png(bytes: &[u8]) -> Vec<u16> {
    decode_png_sized(bytes).2
}

/// A PNG's decoded width, height and samples (widened to u16).
pub fn decode_png_sized(bytes: &[u8]) -> (u32, u32, Vec<u16>) {
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let samples = match info.bit_depth {
        png::BitDepth::Sixteen => buf.chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect(),
        _ => buf.into_iter().map(u16::from).collect(),
    };
    (info.width, info.height, samples)
}

/// LOD `lod` of `image` computed directly from the source: each texel is the rounded mean of
/// the real source pixels under it (halves round up). Returns (width, height, samples).
pub fn naive_level(image: &Image, lod: u32) -> (u32, u32, Vec<u16>) {
    naive_level_filtered(image, lod, Filter::Box)
}

/// LOD `lod` of `image` by an exact filter, texel by texel from the source footprint (the
/// definitions in docs/info-json.md): the mean of the stored values (`box`), of their
/// fixed-point linear-light decodes, encoded back (`linear`), or of colour weighted by alpha
/// divided by the alpha sum, 0 where that is 0 (`premultiplied`). u128 sums, rounded once,
/// halves up.
pub fn naive_level_filtered(image: &Image, lod: u32, filter: Filter) -> (u32, u32, Vec<u16>) {
    let f = 1u64 << lod;
    let (w, h) = (image.width as u64, image.height as u64);
    let (lw, lh) = (w.div_ceil(f), h.div_ceil(f));
    let c = image.channels();
    let alpha = image.layout.channels.has_alpha().then(|| c - 1);
    let linear = matches!(filter, Filter::Linear | Filter::LinearPremultiplied);
    let premultiplied = matches!(filter, Filter::Premultiplied | Filter::LinearPremultiplied) && alpha.is_some();
    let table = SrgbTable::get(image.layout.depth);
    let round = |sum: u128, n: u128| ((2 * sum + n) / (2 * n)) as u64;
    let mut out = Vec::with_capacity((lw * lh) as usize * c);
    for y in 0..lh {
        for x in 0..lw {
            let px = |sx: u64, sy: u64, ch: usize| image.samples[((sy * w + sx) as usize) * c + ch];
            let footprint =
                || (y * f..((y + 1) * f).min(h)).flat_map(|sy| (x * f..((x + 1) * f).min(w)).map(move |sx| (sx, sy)));
            let n = footprint().count() as u128;
            let alpha_sum: u128 = alpha.map_or(0, |a| footprint().map(|(sx, sy)| px(sx, sy, a) as u128).sum());
            for ch in 0..c {
                if Some(ch) == alpha {
                    out.push(round(alpha_sum, n) as u16);
                    continue;
                }
                let value = |sx, sy| {
                    let v = px(sx, sy, ch);
                    let v = if linear { table.decode(v) as u128 } else { v as u128 };
                    if premultiplied { v * px(sx, sy, alpha.unwrap()) as u128 } else { v }
                };
                let sum: u128 = footprint().map(|(sx, sy)| value(sx, sy)).sum();
                let mean = match (premultiplied, alpha_sum) {
                    (true, 0) => 0,
                    (true, a) => round(sum, a),
                    (false, _) => round(sum, n),
                };
                out.push(if linear { table.encode(mean) } else { mean as u16 });
            }
        }
    }
    (lw as u32, lh as u32, out)
}

/// Every level of `image` by `filter`, from LOD 0 to `count - 1`. Resampling filters take each
/// level from the previous one, resized whole in one call, which the banded pipeline must match.
pub fn naive_levels(image: &Image, filter: Filter, count: u32) -> Vec<(u32, u32, Vec<u16>)> {
    if filter.is_exact() {
        // LOD 0 is the source as it is, whatever the filter.
        return (0..count)
            .map(|lod| naive_level_filtered(image, lod, if lod == 0 { Filter::Box } else { filter }))
            .collect();
    }
    let c = image.channels();
    let mut levels = vec![(image.width, image.height, image.samples.clone())];
    while levels.len() < count as usize {
        let (w, h, prev) = levels.last().unwrap();
        let (w, h) = (*w as usize, *h as usize);
        let next: Vec<u16> = match image.layout.depth {
            Depth::U8 => {
                let p: Vec<u8> = prev.iter().map(|v| *v as u8).collect();
                resample_level(filter, image.layout, &p, w, h).unwrap().into_iter().map(u16::from).collect()
            }
            _ => resample_level(filter, image.layout, prev, w, h).unwrap(),
        };
        assert_eq!(next.len(), w.div_ceil(2) * h.div_ceil(2) * c);
        levels.push((w.div_ceil(2) as u32, h.div_ceil(2) as u32, next));
    }
    levels
}

/// Every stored tile of the naive pyramid, with borders and padding, in u16 samples. The grid
/// is worked out here from its definition, not taken from `Layout`: each LOD has as many pages
/// per axis as its image needs, and the last LOD is the first with a single page.
pub fn naive_tiles(image: &Image, opts: &SplitOptions) -> Tiles {
    let c = image.channels();
    let wide = image.layout.depth == Depth::U16;
    let bg: Option<Vec<u16>> = if wide {
        opts.background.texel::<u16>(image.layout.channels)
    } else {
        opts.background.texel::<u8>(image.layout.channels).map(|t| t.into_iter().map(u16::from).collect())
    };
    let (p, b, t) = ((opts.tile_size - 2 * opts.border) as i64, opts.border as i64, opts.tile_size as i64);
    let pages = |texels: u32| (texels as i64 + p - 1) / p;
    let mut lod_count = 1;
    while pages(image.width.div_ceil(1 << (lod_count - 1))) > 1
        || pages(image.height.div_ceil(1 << (lod_count - 1))) > 1
    {
        lod_count += 1;
    }
    let mut tiles = BTreeMap::new();
    for (lod, (lw, lh, level)) in naive_levels(image, opts.filter, lod_count).into_iter().enumerate() {
        let lod = lod as u32;
        let (columns, rows) = (pages(lw), pages(lh));
        let (last_x, last_y) = (columns * p - 1, rows * p - 1);
        for ty in 0..rows as u32 {
            for tx in 0..columns as u32 {
                let mut tile = Vec::with_capacity((t * t) as usize * c);
                for j in 0..t {
                    let vy = (ty as i64 * p - b + j).clamp(0, last_y);
                    for i in 0..t {
                        let vx = (tx as i64 * p - b + i).clamp(0, last_x);
                        let inside = vx < lw as i64 && vy < lh as i64;
                        match (&bg, inside) {
                            (Some(bg), false) => tile.extend_from_slice(bg),
                            _ => {
                                let (x, y) = (vx.min(lw as i64 - 1) as usize, vy.min(lh as i64 - 1) as usize);
                                let at = (y * lw as usize + x) * c;
                                tile.extend_from_slice(&level[at..at + c]);
                            }
                        }
                    }
                }
                tiles.insert((lod, tx, ty), tile);
            }
        }
    }
    tiles
}

pub fn layouts() -> Vec<PixelLayout> {
    let mut v = Vec::new();
    for c in [Channels::Grey, Channels::GreyAlpha, Channels::Rgb, Channels::Rgba] {
        for d in [Depth::U8, Depth::U16] {
            v.push(PixelLayout::new(c, d));
        }
    }
    v
}

/// `pack` rewritten to `dest` with `metadata` in place of its own, tiles unchanged and every
/// checksum valid (as a forger would write it).
pub fn with_metadata(pack: &std::path::Path, metadata: &str, dest: &std::path::Path) {
    use vortex_pack::{NewTile, Pack, PackWriter, Tile, WriteOptions};
    let p = Pack::open(pack).unwrap();
    let mut w =
        PackWriter::create(dest, *p.description(), p.levels().to_vec(), metadata.as_bytes(), WriteOptions::default())
            .unwrap();
    for id in p.ids() {
        let tile = match p.tile_checked(id).unwrap() {
            Tile::Absent => NewTile::Absent,
            Tile::Constant(t) => NewTile::Constant(t),
            Tile::Data(k, b) => NewTile::Data(k, b),
        };
        w.add(id, tile).unwrap();
    }
    w.finish().unwrap();
}
