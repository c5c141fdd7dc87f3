//! What the user sees while and after a run: the progress bar and the summary line.

use std::path::Path;

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};
use vortex_tiler::error::ShowPath;
use vortex_tiler::formats::tiff::Flavour;
use vortex_tiler::output::{self, Claim, Product};
use vortex_tiler::outputs::Figures;
use vortex_tiler::split::{Progress, Summary};

use super::signals;
use super::split::Finished;

/// The progress bar of a run that SIGINT, SIGTERM or SIGHUP stop cleanly.
pub struct Watch {
    pub bar: ProgressBar,
}

impl Watch {
    pub fn new(total_tiles: u64, quiet: bool) -> Result<Watch> {
        signals::install().context("installing signal handlers")?;
        Ok(Watch { bar: progress_bar(total_tiles, "tiles", quiet) })
    }
}

impl Progress for Watch {
    fn advance(&self, tiles: u64) {
        self.bar.inc(tiles);
    }
    fn total(&self, tiles: u64) {
        self.bar.set_length(tiles);
    }
    fn cancelled(&self) -> bool {
        signals::requested().is_some()
    }
}

/// Claims `dest` for `product` (see `output::claim`), then [`prepare`]s it.
pub fn claim(dest: &Path, product: Product, inputs: &[&Path], force: bool) -> Result<Claim> {
    let claim = output::claim(dest, product, inputs, force)?;
    prepare(dest)?;
    Ok(claim)
}

/// For a claimed destination: removes what dead runs left while writing it and says so (a run
/// killed outright, by power loss or SIGKILL, cannot clean up), and has a signal remove what
/// this run leaves.
pub fn prepare(dest: &Path) -> Result<()> {
    signals::remove_on_forced_exit(dest);
    remove_stale(dest)
}

/// [`prepare`] for a resumable run (`--resume`): what it stages stays when it is stopped, even
/// by a second signal, for the next `--resume` to go on from.
pub fn prepare_resumable(dest: &Path) -> Result<()> {
    remove_stale(dest)
}

fn remove_stale(dest: &Path) -> Result<()> {
    let removed = output::remove_stale(dest)
        .with_context(|| format!("removing temporaries that earlier runs left beside {}", dest.shown()))?;
    for path in removed {
        let journal = path.file_name().is_some_and(|n| n.to_string_lossy().contains(".resume-"));
        let hint = if journal { " (a journal: --resume would have gone on from that run's tiles)" } else { "" };
        eprintln!("note: removed {}, left by a run that did not finish{hint}", path.shown());
    }
    Ok(())
}

/// A progress bar on stderr counting `unit` (`tiles`, `frames`), with a rate and an ETA; hidden
/// when `quiet`.
pub fn progress_bar(total: u64, unit: &'static str, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr_with_hz(10));
    let template = format!(
        "{{elapsed_precise}} [{{bar:40.cyan/blue}}] {{human_pos}}/{{human_len}} {unit} ({{rate}}, eta {{eta}}) {{msg}}"
    );
    // The template is ours and fixed; should indicatif ever refuse it, a plain bar still works.
    let style = ProgressStyle::with_template(&template).unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(
        style
            .with_key("rate", move |s: &ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{:.0} {unit}/s", s.per_sec());
            })
            .progress_chars("=> "),
    );
    bar
}

/// One line: what was written, how fast, how much memory.
pub fn summary_line(done: &Finished, out: &Path) -> String {
    let s = &done.summary;
    let secs = done.took.as_secs_f64().max(1e-9);
    let mpx = done.width as f64 * done.height as f64 / 1e6;
    let peak = peak_rss().map(|b| format!(", peak memory {}", mib(b))).unwrap_or_default();
    let stripes = match (s.stripes, s.passes) {
        // One read; or none, where the slide's own levels were copied.
        (_, 0 | 1) => String::new(),
        (0, n) => format!(", in {n} rectangles of the source"),
        (_, n) => format!(
            ", in {} vertical stripe{} and a coarse pass (the source read {n} times)",
            s.stripes,
            if s.stripes == 1 { "" } else { "s" }
        ),
    };
    let stored = s.stored_tiles.as_ref().map(|t| stored_clause(s, t)).unwrap_or_default();
    let kept = match s.kept {
        0 => String::new(),
        k => format!(", {k} kept from the interrupted run"),
    };
    format!(
        "wrote {} tiles ({} encoded{kept}, {} LODs from {} x {} pages, {}x{} {}) totalling {} to {} in {:.2} s: {:.1} source Mpx/s [{}]{stripes}{peak}{stored}",
        s.tiles,
        s.encoded,
        s.layout.lod_count,
        s.layout.columns,
        s.layout.rows,
        s.layout.tile_size,
        s.layout.tile_size,
        s.stored,
        mib(s.bytes),
        out.shown(),
        secs,
        mpx / secs,
        done.decoder,
    )
}

/// What became of the source's stored JPEG tiles, for the summary line.
fn stored_clause(s: &Summary, t: &vortex_tiler::split::StoredReport) -> String {
    let (copied, cropped, r) = (s.copied, s.cropped, &s.recompressed);
    let quality = t.quality.map(|q| format!(" ({q} by their quantisation tables)")).unwrap_or_default();
    let tiles = format!("the source's {}x{} JPEG tiles{quality}", t.tile_size.0, t.tile_size.1);
    let recompressed = match (r.tiles, r.refused) {
        (0, 0) => String::new(),
        (n, refused) => {
            let percent = 100.0 * r.saved() as f64 / r.jpeg_bytes.max(1) as f64;
            let refused = match refused {
                0 => String::new(),
                k => format!("; {k} libjxl could not rebuild exactly were encoded from their texels"),
            };
            format!(
                "; {n} of them recompressed losslessly into JPEG XL, {} of JPEG in {} (saved {} bytes, {percent:.1}%){refused}",
                mib(r.jpeg_bytes),
                mib(r.jxl_bytes),
                r.saved()
            )
        }
    };
    let halved = if t.halved { ", LOD 1 from them decoded at half size (--fast-shrink)" } else { "" };
    match &t.declined {
        None => format!(
            "; {copied} tiles copied as stored, {cropped} of them cropped losslessly at the edge, from {tiles}{recompressed}{halved}"
        ),
        Some(why) => format!("; {tiles} re-encoded, not copied: {why}"),
    }
}

/// The summary as one JSON object (`--json`), for scripts: the same numbers as the line.
pub fn summary_json(done: &Finished, layout: &str, out: &Path, figures: &Figures) -> String {
    summary_value(done, layout, out, figures).to_string()
}

/// [`summary_json`]'s object; the format's own figures under its name (`pack`, `pmtiles`,
/// `tiff`, `dicom`).
pub fn summary_value(done: &Finished, layout: &str, out: &Path, figures: &Figures) -> serde_json::Value {
    let s = &done.summary;
    let mut doc = serde_json::json!({
        "output": out.display().to_string(),
        "layout": layout,
        "width": done.width,
        "height": done.height,
        "source": done.decoder,
        "tiles": s.tiles,
        "encoded": s.encoded,
        "kept": s.kept,
        "copied": s.copied,
        "cropped": s.cropped,
        "bytes": s.bytes,
        "lodCount": s.layout.lod_count,
        "tileColumns": s.layout.columns,
        "tileRows": s.layout.rows,
        "tileSize": s.layout.tile_size,
        "border": s.layout.border,
        "stored": s.stored.to_string(),
        "stripes": s.stripes,
        "passes": s.passes,
        "seconds": done.took.as_secs_f64(),
        "peakMemoryBytes": peak_rss(),
        "stages": stages_json(&s.stages),
        "memory": memory_json(&s.memory),
    });
    if !matches!(layout, "vortex" | "pack" | "shard") {
        // The viewer's own terms: its tile side without the overlap (Deep Zoom's TileSize).
        doc["viewer"] = serde_json::json!({ "tileSize": s.layout.payload(), "overlap": s.layout.border });
    }
    if let Some(t) = &s.stored_tiles {
        doc["storedTiles"] = serde_json::json!({
            "tileWidth": t.tile_size.0,
            "tileHeight": t.tile_size.1,
            "quality": t.quality.map(|q| q.estimate),
            "qualityExact": t.quality.map(|q| q.exact),
            "copied": s.copied,
            "cropped": s.cropped,
            "declined": t.declined,
            "halved": t.halved,
            "recompressed": {
                "tiles": s.recompressed.tiles,
                "jpegBytes": s.recompressed.jpeg_bytes,
                "jxlBytes": s.recompressed.jxl_bytes,
                "savedBytes": s.recompressed.saved(),
                "refused": s.recompressed.refused,
            },
        });
    }
    let own = match figures {
        Figures::Pack(w) => Some((
            "pack",
            serde_json::json!({
                "storedPayloads": w.stored_payloads,
                "deduplicated": w.deduplicated,
                "constant": w.constant,
                "absent": w.absent,
                "payloadBytes": w.payload_bytes,
                "fileBytes": w.file_bytes,
                "contentHash": format!("{:016x}", w.content_hash),
            }),
        )),
        Figures::Pmtiles(w) => Some(("pmtiles", pmtiles_json(w))),
        Figures::Tiff(w) => Some(("tiff", tiff_json(w))),
        Figures::Dicom(w) => Some(("dicom", dicom_json(w))),
        _ => None,
    };
    if let Some((key, value)) = own {
        doc[key] = value;
    }
    doc
}

/// Where a run's wall time went, in seconds per stage (`split::Summary::stages`), and its CPU
/// time per stage (`null` where the platform has no per-thread CPU clock).
fn stages_json(t: &vortex_tiler::split::StageTimes) -> serde_json::Value {
    let cpu = t.cpu.map(|c| {
        serde_json::json!({
            "readSeconds": c.read.as_secs_f64(),
            "decodeSeconds": c.decode.as_secs_f64(),
            "pyramidSeconds": c.pyramid.as_secs_f64(),
            "cutSeconds": c.cut.as_secs_f64(),
            "encodeSeconds": c.encode.as_secs_f64(),
            "storeSeconds": c.store.as_secs_f64(),
        })
    });
    serde_json::json!({
        "readSeconds": t.read.as_secs_f64(),
        "decodeSeconds": t.decode.as_secs_f64(),
        "readWaitSeconds": t.read_wait.as_secs_f64(),
        "pyramidSeconds": t.pyramid.as_secs_f64(),
        "cutSeconds": t.cut.as_secs_f64(),
        "producerBlockedSeconds": t.producer_blocked.as_secs_f64(),
        "encodersIdleSeconds": t.encoders_idle.as_secs_f64(),
        "encodeSeconds": t.encode.as_secs_f64(),
        "storeSeconds": t.store.as_secs_f64(),
        "cpu": cpu,
    })
}

/// With `--verbose`, the line that says what each stage cost: CPU milliseconds per source
/// megapixel (the work, whatever the cores; compare it with another tool's), then wall seconds.
pub fn stages_line(t: &vortex_tiler::split::StageTimes, width: u32, height: u32) -> String {
    let mpx = (width as f64 * height as f64 / 1e6).max(1e-9);
    let wall = format!(
        "wall s: read {:.2}, decode {:.2} per pool thread, pyramid {:.2}, cut {:.2}, encode {:.2} per encoder, store {:.2}",
        t.read.as_secs_f64(),
        t.decode.as_secs_f64(),
        t.pyramid.as_secs_f64(),
        t.cut.as_secs_f64(),
        t.encode.as_secs_f64(),
        t.store.as_secs_f64()
    );
    let Some(c) = t.cpu else { return format!("stages (no per-thread CPU clock here): {wall}") };
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3 / mpx;
    format!(
        "stages, CPU ms per source Mpx: read {:.1}, decode {:.1}, pyramid {:.1}, cut {:.1}, encode {:.1}, store {:.1} (together {:.1}); {wall}",
        ms(c.read),
        ms(c.decode),
        ms(c.pyramid),
        ms(c.cut),
        ms(c.encode),
        ms(c.store),
        ms(c.total()),
    )
}

/// Where a run's memory went (`split::Summary::memory`): the budget, the plan's bound and what
/// each stage held at most by its own count (docs/cli.md).
fn memory_json(m: &vortex_tiler::split::MemoryReport) -> serde_json::Value {
    use vortex_tiler::limits::Part;
    let part = |p| m.peaks.part(p);
    serde_json::json!({
        "maxMemoryBytes": m.budget,
        "plannedBytes": m.planned,
        "peakBytes": m.peaks.total,
        "decoderBytes": part(Part::Decoder),
        "readAheadBytes": part(Part::ReadAhead),
        "sumRowsBytes": part(Part::SumRows),
        "bandBytes": part(Part::Bands),
        "tilesBytes": part(Part::Tiles),
        "encodedBytes": part(Part::Encoded),
    })
}

/// With `--verbose`, the line after the summary: where the memory went, in MiB.
pub fn memory_line(m: &vortex_tiler::split::MemoryReport) -> String {
    use vortex_tiler::limits::Part;
    let part = |p| mib(m.peaks.part(p));
    let planned = m.planned.map(|b| format!(", planned {}", mib(b))).unwrap_or_default();
    format!(
        "memory held by the stages: peak {} of --max-memory {}{planned}; each part at most: decoder {}, read-ahead {}, sum rows {}, bands {}, tiles {}, encoded {}",
        mib(m.peaks.total),
        mib(m.budget),
        part(Part::Decoder),
        part(Part::ReadAhead),
        part(Part::SumRows),
        part(Part::Bands),
        part(Part::Tiles),
        part(Part::Encoded),
    )
}

/// What a pack writer stored: deduplication and one-colour tiles.
/// The line of a format's own figures, said before the output's summary line.
pub fn figures_line(figures: &Figures) -> Option<String> {
    match figures {
        Figures::Pack(w) => Some(pack_line(w)),
        Figures::Pmtiles(w) => Some(pmtiles_line(w)),
        Figures::Tiff(w) => Some(tiff_line(w)),
        Figures::Dicom(w) => Some(dicom_line(w)),
        _ => None,
    }
}

pub fn pack_line(w: &vortex_pack::WriteSummary) -> String {
    format!(
        "pack: {} tiles, {} payloads stored ({} duplicates shared, {} one-colour, {} absent), {} in {} file bytes, content hash {:016x}",
        w.tiles,
        w.stored_payloads,
        w.deduplicated,
        w.constant,
        w.absent,
        mib(w.payload_bytes),
        w.file_bytes,
        w.content_hash
    )
}

pub fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64)
}

/// Peak resident set size, from /proc on Linux.
pub fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The error and its causes on one line, without repeating a cause the message already holds.
pub fn chain(e: &anyhow::Error) -> String {
    let mut out = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !out.contains(&c) {
            out.push_str(": ");
            out.push_str(&c);
        }
    }
    out
}

/// A PMTiles archive's figures, for `--json`.
fn pmtiles_json(w: &vortex_tiler::formats::pmtiles::PmtilesSummary) -> serde_json::Value {
    serde_json::json!({
        "tiles": w.tiles,
        "entries": w.entries,
        "contents": w.contents,
        "leafDirectories": w.leaves,
        "dataBytes": w.data_bytes,
        "fileBytes": w.file_bytes,
    })
}

/// A PMTiles archive's figures, in a line.
fn pmtiles_line(w: &vortex_tiler::formats::pmtiles::PmtilesSummary) -> String {
    format!(
        "pmtiles: {} tiles in {} directory entries, {} distinct payloads, {} leaf directories, {} file bytes",
        w.tiles, w.entries, w.contents, w.leaves, w.file_bytes
    )
}

/// A TIFF's figures, for `--json`.
fn tiff_json(w: &vortex_tiler::formats::tiff::TiffSummary) -> serde_json::Value {
    serde_json::json!({
        "flavour": w.flavour.name(),
        "bigtiff": w.bigtiff,
        "levels": w.levels,
        "planes": w.planes,
        "tiles": w.tiles,
        "compression": w.compression,
        "tileBytes": w.tile_bytes,
        "fileBytes": w.file_bytes,
        "levelsCopied": w.levels_copied,
        "levelsDeclined": w.levels_declined,
        "associated": w.associated.iter().map(|a| serde_json::json!({
            "kind": a.kind,
            "width": a.width,
            "height": a.height,
            "from": a.origin,
            "page": a.page,
            "bytes": a.bytes,
        })).collect::<Vec<_>>(),
        "associatedLeftOut": w.associated_left_out,
    })
}

/// A TIFF's figures, in a line.
fn tiff_line(w: &vortex_tiler::formats::tiff::TiffSummary) -> String {
    let carried: Vec<String> = w
        .associated
        .iter()
        .map(|a| format!("{} {}x{} ({}, page {})", a.kind, a.width, a.height, a.origin, a.page))
        .collect();
    let associated = match (carried.is_empty(), w.associated_left_out) {
        (true, 0) => String::new(),
        (false, _) => format!("; associated images after the levels: {}", carried.join(", ")),
        (true, n) if w.flavour == Flavour::Cog => {
            format!("; {n} associated image(s) left out: a generic TIFF or an OME-TIFF carries them")
        }
        (true, n) => format!("; {n} associated image(s) left out (--no-associated)"),
    };
    let planes = match w.planes {
        1 => String::new(),
        n => format!(" in each of {n} planes (a channel each)"),
    };
    format!(
        "{}: {} levels{planes} ({}), {} {} tiles, {}, {} file bytes{associated}",
        w.flavour.name(),
        w.levels,
        levels_clause(w.levels_copied, &w.levels_declined, "tile"),
        w.tiles,
        w.compression,
        if w.bigtiff { "BigTIFF" } else { "classic TIFF" },
        w.file_bytes
    )
}

/// Whose levels an output holds: the slide's own, each `unit` copied, or our pyramid, and why
/// not the slide's where it would have copied them.
fn levels_clause(copied: bool, declined: &Option<String>, unit: &str) -> String {
    match (copied, declined) {
        (true, _) => format!("the slide's own, every {unit} copied as stored"),
        (false, None) => "our power-of-two pyramid".to_string(),
        (false, Some(why)) => format!("our power-of-two pyramid; the slide's own levels not copied: {why}"),
    }
}

/// A DICOM series' figures, for `--json`.
fn dicom_json(w: &vortex_tiler::formats::dicom::DicomSummary) -> serde_json::Value {
    serde_json::json!({
        "instances": w.instances,
        "frames": w.frames,
        "photometricInterpretation": w.photometric,
        "transferSyntax": w.transfer_syntax,
        "frameCoding": w.frame_coding,
        "seriesInstanceUID": w.series_uid,
        "extendedOffsetTables": w.extended_offsets,
        "frameBytes": w.frame_bytes,
        "fileBytes": w.file_bytes,
        "levelsAsked": w.levels.name(),
        "levels": if w.levels_copied { "stored" } else { "pow2" },
        "levelsDeclined": w.levels_declined,
        "associated": w.associated.iter().map(|a| serde_json::json!({
            "kind": a.kind,
            "width": a.width,
            "height": a.height,
            "from": a.origin,
            "file": a.file,
            "photometricInterpretation": a.photometric,
            "frameBytes": a.frame_bytes,
        })).collect::<Vec<_>>(),
        "associatedLeftOut": w.associated_left_out,
        "levelFrames": w.level_frames.iter().map(|l| serde_json::json!({
            "transferSyntax": l.transfer_syntax,
            "photometricInterpretation": l.photometric,
            "storedFrames": l.stored,
        })).collect::<Vec<_>>(),
    })
}

/// A DICOM series' figures, in a line.
fn dicom_line(w: &vortex_tiler::formats::dicom::DicomSummary) -> String {
    let carried: Vec<String> =
        w.associated.iter().map(|a| format!("{} {}x{} ({})", a.kind, a.width, a.height, a.origin)).collect();
    let associated = match (carried.is_empty(), w.associated_left_out) {
        (true, 0) => String::new(),
        (false, _) => format!("; associated images, each its own instance: {}", carried.join(", ")),
        (true, n) => format!("; {n} associated image(s) left out (--no-associated)"),
    };
    // Where an instance's transfer syntax is not the series' (a JPEG XL instance of only
    // recompressed JPEG tiles), each level's.
    let per_level = match w.level_frames.iter().all(|l| l.transfer_syntax == w.transfer_syntax) {
        true => String::new(),
        false => {
            let each: Vec<String> = (w.level_frames.iter().enumerate())
                .map(|(k, l)| format!("level {k} {} {}", l.transfer_syntax, l.photometric))
                .collect();
            format!(" ({})", each.join(", "))
        }
    };
    format!(
        "dicom: {} instances (one a level: {}), {} {} frames, {}{per_level}, series {}, {} file bytes{associated}",
        w.instances,
        levels_clause(w.levels_copied, &w.levels_declined, "frame"),
        w.frames,
        w.frame_coding,
        w.photometric,
        w.series_uid,
        w.file_bytes
    )
}
