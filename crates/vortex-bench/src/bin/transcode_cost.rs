//! What transcoding pages to BC at load costs and gives (issue 17): the runtime's own loader reads
//! the same pages of a pack into each cache format, one thread, and this program times it per
//! page: decoding alone (an RGBA8 cache) against decoding and encoding to BC1 or BC7. It gives the
//! GPU bytes per page, and the PSNR of the transcoded cache against the RGBA8 cache (what
//! transcoding loses) and against the source (what the pack and the transcoding lose together;
//! the source is a lossless PNG pack of the same image). Writes the `transcode` block of
//! docs/accuracy.md.
//!
//! ```sh
//! cargo run --release -p vortex-bench --bin transcode_cost -- PACK SOURCE_PNG_PACK [DOC.md]
//! ```
//! `bench/transcode-cost.sh` makes both packs from the 16384² benchmark image and runs it.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use vortex_bench::run_info;
use vortex_bench::splice::{Block, splice_file};
use vortex_pack::Pack;
use vortex_vt::page::PageId;
use vortex_vt::residency::Slot;
use vortex_vt_wgpu::{CacheFormat, Loader};

/// Pages measured: spread over LOD 0 and a few coarser LODs.
const PAGES: usize = 240;
/// Rounds of loading every page; the median round per format is reported.
const ROUNDS: usize = 3;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [pack, source, ..] = args.as_slice() else {
        bail!("usage: transcode_cost PACK SOURCE_PNG_PACK [DOC.md]");
    };
    let doc = PathBuf::from(args.get(2).map_or("docs/accuracy.md", String::as_str));
    let open = |p: &str| -> Result<Arc<Pack>> { Ok(Arc::new(Pack::open(p).with_context(|| format!("opening {p}"))?)) };
    let (pack, source) = (open(pack)?, open(source)?);
    let loader = Loader::new(vec![Arc::clone(&pack)], 1)?;
    let reference = Loader::new(vec![Arc::clone(&source)], 1)?;
    let texture = loader.textures()[0];
    if reference.textures()[0].grid != texture.grid || !loader.opaque() {
        bail!("the two packs must be opaque and cut alike (same grid, tile size and border)");
    }
    let pages = pick_pages(&texture.grid);
    let truth = reference.load(&pages);

    let mut rows = Vec::new();
    let mut rgba8 = Vec::new();
    for format in [CacheFormat::Rgba8, CacheFormat::Bc1, CacheFormat::Bc7] {
        loader.set_format(format);
        let mut times = Vec::new();
        let mut loaded = Vec::new();
        for _ in 0..ROUNDS {
            let started = Instant::now();
            loaded = loader.load(&pages);
            times.push(started.elapsed().as_secs_f64() * 1e3 / pages.len() as f64);
        }
        times.sort_by(f64::total_cmp);
        let texels: Vec<Vec<u8>> = loaded.iter().map(|p| decode(&p.texels, format, texture.tile_size)).collect();
        if format == CacheFormat::Rgba8 {
            rgba8 = texels.clone();
        }
        let vs_rgba8 = psnr(&texels, &rgba8);
        let vs_source = psnr(&texels, &truth.iter().map(|p| p.texels.clone()).collect::<Vec<_>>());
        rows.push((format, times[ROUNDS / 2], format.tile_bytes(texture.tile_size), vs_rgba8, vs_source));
        eprintln!("{}: {:.3} ms per page", format.name(), times[ROUNDS / 2]);
    }

    let d = pack.description();
    let mut body = format!(
        "Measured by `transcode_cost` (`crates/vortex-bench`) on {} on {} with {} cores: {} pages of `{}` ({}² texels, {}-texel tiles with a {}-texel border, {}), each loaded {} times per format by the runtime's loader on one thread; the median round.\n\n",
        run_info::today(),
        run_info::machine(),
        run_info::cores(),
        pages.len(),
        pack.path().file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
        d.width,
        d.tile_size,
        d.border,
        codec_of(&pack),
        ROUNDS,
    );
    body.push_str(
        "| cache | ms per page | relative | GPU bytes per page | relative | PSNR vs RGBA8 cache | PSNR vs source |\n",
    );
    body.push_str("|---|---:|---:|---:|---:|---:|---:|\n");
    let (base_ms, base_bytes) = (rows[0].1, rows[0].2 as f64);
    for (format, ms, bytes, vs_rgba8, vs_source) in &rows {
        let what = match format {
            CacheFormat::Rgba8 => "rgba8 (decode)",
            CacheFormat::Bc1 => "bc1 (decode + transcode)",
            CacheFormat::Bc7 => "bc7 (decode + transcode)",
        };
        body.push_str(&format!(
            "| {what} | {ms:.3} | {:.2}x | {bytes} | {:.3}x | {} | {} |\n",
            ms / base_ms,
            *bytes as f64 / base_bytes,
            db(*vs_rgba8),
            db(*vs_source),
        ));
    }
    splice_file(&doc, "transcode", &[Block::new("transcode", body.trim_end())])?;
    println!("{}", body);
    Ok(())
}

/// `PAGES` pages: most of LOD 0 spread evenly, then some of LODs 1-3.
fn pick_pages(grid: &vortex_vt::page::TextureGrid) -> Vec<(PageId, Slot)> {
    let mut pages = Vec::new();
    for (lod, share) in [(0u8, 0.7), (1, 0.15), (2, 0.1), (3, 0.05)] {
        if lod >= grid.lod_count() {
            break;
        }
        let [w, h] = grid.pages_at(lod).map(usize::from);
        let want = ((PAGES as f64 * share) as usize).clamp(1, w * h);
        let step = (w * h) / want;
        pages.extend((0..want).map(|i| {
            let at = i * step;
            (PageId::new(0, lod, (at % w) as u16, (at / w) as u16), 0)
        }));
    }
    pages
}

/// Decodes one 4x4 block into RGBA8 rows of `pitch` bytes.
type BlockDecoder = fn(&[u8], &mut [u8], usize);

/// The RGBA8 texels of one slot's bytes in `format`.
fn decode(bytes: &[u8], format: CacheFormat, tile_size: u32) -> Vec<u8> {
    let side = tile_size as usize;
    let (block_len, decode): (usize, BlockDecoder) = match format {
        CacheFormat::Rgba8 => return bytes.to_vec(),
        CacheFormat::Bc1 => (8, |b, out, pitch| bcdec_rs::bc1(b, out, pitch)),
        CacheFormat::Bc7 => (16, |b, out, pitch| bcdec_rs::bc7(b, out, pitch)),
    };
    let mut out = vec![0u8; side * side * 4];
    for (i, block) in bytes.chunks_exact(block_len).enumerate() {
        let (bx, by) = (i % (side / 4), i / (side / 4));
        decode(block, &mut out[(by * 4 * side + bx * 4) * 4..], side * 4);
    }
    out
}

/// PSNR over the colour channels of every page, in dB (infinite when equal).
fn psnr(a: &[Vec<u8>], b: &[Vec<u8>]) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        for (p, q) in x.chunks_exact(4).zip(y.chunks_exact(4)) {
            for c in 0..3 {
                sum += (f64::from(p[c]) - f64::from(q[c])).powi(2);
                n += 1.0;
            }
        }
    }
    vortex_bench::measure::psnr_8bit(sum, n)
}

fn db(v: f64) -> String {
    if v.is_infinite() { "exact".into() } else { format!("{v:.1} dB") }
}

/// The codec of the pack's first stored tile, for the caption.
fn codec_of(pack: &Pack) -> &'static str {
    (0..pack.header().index_count)
        .filter_map(|i| vortex_pack::TileKind::from_u8(pack.entry(i).kind))
        .find(|k| !matches!(k, vortex_pack::TileKind::Absent | vortex_pack::TileKind::Constant))
        .map_or("no stored tiles", |k| k.name())
}
