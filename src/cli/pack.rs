//! `pack`, `unpack` and `info`: between tiled directories and pack files.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};
use vortex_pack::{Pack, TileKind, VerifyOptions, verify};
use vortex_tiler::error::ShowPath;
use vortex_tiler::formats::tiles::TiledDir;
use vortex_tiler::output::Product;
use vortex_tiler::{repack, settings};

use super::PackLayout;
use super::report;

#[derive(clap::Args, Debug)]
pub struct PackArgs {
    /// A tiled directory: info.json plus one file per tile (what `split -o` writes).
    #[arg(value_name = "DIR")]
    input: PathBuf,
    /// The pack file to write (replaced only when complete). An existing pack is replaced;
    /// any other file only with --force.
    #[arg(short, long, value_name = "FILE")]
    output: PathBuf,
    /// Replace a regular file at --output that is not a pack. Never replaces a directory, a
    /// device, a FIFO, a link or the input.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    layout: PackLayout,
    /// Codec flags re-encode every tile (decoded from its file) unless they describe the
    /// directory's own codec; without them the tile files are stored as they are.
    #[command(flatten)]
    enc: super::split::CodecArgs,
    /// No progress bar and no summary line.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(clap::Args, Debug)]
pub struct UnpackArgs {
    #[arg(value_name = "PACK")]
    input: PathBuf,
    /// Output directory for the tile files and info.json (created; replaced only if it holds
    /// nothing but a previous output).
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    /// No progress bar and no summary line.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    #[arg(value_name = "PACK")]
    input: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args, Debug)]
pub struct VerifyArgs {
    #[arg(value_name = "PACK")]
    input: PathBuf,
    /// Also decode every tile and check its size.
    #[arg(long)]
    decode: bool,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run_verify(a: VerifyArgs) -> Result<()> {
    let started = Instant::now();
    // Opened without holding the index to its checksum: `verify` reports a mismatch with every
    // other problem it finds (every other command refuses such a pack at open).
    let opened =
        refuse_directory(&a.input).and_then(|()| Ok(Pack::open_to_verify(&a.input, vortex_pack::Limits::default())?));
    let report = match opened {
        Ok(pack) => verify(&pack, VerifyOptions { decode: a.decode }),
        Err(e) if a.json => {
            // The structure is unusable: one problem, in the same shape as a full report's.
            let json = serde_json::json!({"path": a.input, "ok": false, "problems": [{"section": "open", "message": e.to_string()}]});
            say!("{}", serde_json::to_string_pretty(&json)?);
            anyhow::bail!("{}: cannot be opened as a pack", a.input.shown());
        }
        Err(e) => return Err(e),
    };
    if a.json {
        say!("{}", report.to_json());
    } else {
        say!("{}", report.to_string().trim_end_matches('\n'));
        say!("checked in {:.2} s", started.elapsed().as_secs_f64());
    }
    if !report.is_ok() {
        anyhow::bail!("{}: {} problem(s) found", a.input.shown(), report.problems.len());
    }
    Ok(())
}

pub fn run_pack(a: PackArgs) -> Result<()> {
    let started = Instant::now();
    report::claim(&a.output, Product::Pack, &[&a.input], a.force)?;
    let t = TiledDir::read(&a.input)?;
    let codec = match a.enc.any() {
        true => Some(settings::resolve_codec(&a.enc.requested(), &a.input.join("info.json"), &t.info, t.layout())?),
        false => None,
    };
    let watch = report::Watch::new(t.tile_total(), a.quiet)?;
    let written = repack::pack_dir(&a.input, &a.output, a.layout.options()?, codec, &watch);
    watch.bar.finish_and_clear();
    let written = written?;
    if !a.quiet {
        say!("{} -> {} in {:.2} s", report::pack_line(&written), a.output.shown(), started.elapsed().as_secs_f64());
    }
    Ok(())
}

pub fn run_unpack(a: UnpackArgs) -> Result<()> {
    let started = Instant::now();
    let pack = open_pack(&a.input)?;
    let claim = report::claim(&a.output, Product::TileDir, &[&a.input], false)?;
    let watch = report::Watch::new(pack.header().index_count, a.quiet)?;
    let count = repack::unpack(&pack, &claim, &watch);
    watch.bar.finish_and_clear();
    let count = count?;
    if !a.quiet {
        say!(
            "wrote {count} tile files and info.json to {} in {:.2} s",
            a.output.shown(),
            started.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// Opens a pack, telling a directory (a tile directory, most likely) from a broken pack.
fn open_pack(path: &Path) -> Result<Pack> {
    refuse_directory(path)?;
    Ok(Pack::open(path)?)
}

/// A directory given for a pack: most likely a tile directory, which `pack` would pack.
fn refuse_directory(path: &Path) -> Result<()> {
    if path.is_dir() {
        bail!(
            "{}: is a directory, not a pack; `vortex-tiler pack {} -o FILE` packs a tile directory",
            path.shown(),
            path.shown()
        );
    }
    Ok(())
}

pub fn run_info(a: InfoArgs) -> Result<()> {
    let pack = open_pack(&a.input)?;
    let h = pack.header();
    let d = pack.description();
    let mut kinds = std::collections::BTreeMap::<&str, (u64, u64)>::new();
    let mut offsets = std::collections::HashSet::new();
    let (mut referenced, mut stored) = (0u64, 0u64);
    for i in 0..h.index_count {
        let e = pack.entry(i);
        let name = TileKind::from_u8(e.kind).map_or("unknown", TileKind::name);
        let k = kinds.entry(name).or_default();
        k.0 += 1;
        k.1 += e.len as u64;
        if TileKind::from_u8(e.kind).is_some_and(TileKind::has_payload) {
            referenced += e.len as u64;
            if offsets.insert(e.offset_or_value) {
                stored += e.len as u64;
            }
        }
    }
    let metadata = String::from_utf8_lossy(pack.metadata());
    if a.json {
        let levels: Vec<serde_json::Value> = pack
            .levels()
            .iter()
            .enumerate()
            .map(|(lod, l)| serde_json::json!({"lod": lod, "tilesW": l.tiles_w, "tilesH": l.tiles_h, "width": l.width, "height": l.height, "firstEntry": l.first_entry}))
            .collect();
        let kinds: serde_json::Map<String, serde_json::Value> =
            kinds.iter().map(|(k, (n, b))| (k.to_string(), serde_json::json!({"tiles": n, "bytes": b}))).collect();
        let out = serde_json::json!({
            "path": a.input,
            "version": format!("{}.{}", h.major, h.minor),
            "contentHash": format!("{:016x}", h.content_hash),
            "fileBytes": h.file_len,
            "width": d.width, "height": d.height, "tileSize": d.tile_size, "border": d.border,
            "channels": d.channels, "sampleBytes": d.sample_bytes,
            "alignment": h.alignment, "tileAlignment": h.payload_alignment,
            "levels": levels,
            "kinds": kinds,
            "payloadBytesReferenced": referenced,
            "payloadBytesStored": stored,
            "metadata": serde_json::from_str::<serde_json::Value>(&metadata).unwrap_or(serde_json::Value::Null),
        });
        say!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    say!(
        "{}: Vortex pack {}.{}, {} bytes, content hash {:016x}",
        a.input.shown(),
        h.major,
        h.minor,
        h.file_len,
        h.content_hash
    );
    say!(
        "texture {}x{} texels, {}-texel tiles with a {}-texel border, {} channel(s) of {} byte(s), {} levels",
        d.width,
        d.height,
        d.tile_size,
        d.border,
        d.channels,
        d.sample_bytes,
        d.level_count
    );
    say!("data aligned to {} bytes, tiles to {}", h.alignment, h.payload_alignment);
    if let Some(shard) = vortex_tiler::scale_out::describe(pack.metadata()) {
        say!("{shard}");
    }
    say!("{:>4} {:>11} {:>15} {:>12}", "lod", "tiles", "image texels", "first entry");
    for (lod, l) in pack.levels().iter().enumerate() {
        say!(
            "{lod:>4} {:>11} {:>15} {:>12}",
            format!("{}x{}", l.tiles_w, l.tiles_h),
            format!("{}x{}", l.width, l.height),
            l.first_entry
        );
    }
    for (kind, (n, bytes)) in &kinds {
        say!("{kind:>9}: {n} tiles, {}", report::mib(*bytes));
    }
    let saved = referenced - stored;
    say!(
        "payload {} stored for {} referenced ({} saved by sharing identical tiles)",
        report::mib(stored),
        report::mib(referenced),
        report::mib(saved)
    );
    Ok(())
}
