//! `vortex-tiler render`: streams packs through the GPU runtime along a scene's camera path,
//! headless, writing PNG frames and a JSON residency report. It runs the runtime's own harness
//! (`vortex_vt_wgpu::harness`), which uses the public embedding API as any application does.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::Args;
use vortex_tiler::error::{ShowPath, TilerError};
use vortex_tiler::limits::Limits;
use vortex_tiler::output::{self, Product};
use vortex_vt::sampler::Rgba8Image;
use vortex_vt_wgpu::harness::{Scene, SceneLayer, SceneRenderer};
use vortex_vt_wgpu::source::{Delayed, HttpOptions, HttpPack, HttpStats};
use vortex_vt_wgpu::{CacheFormat, Gpu, Layer, LayerKind, Pacing, PageSource, Runtime, SampleFilter};

use super::{report, signals};

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// A pack to stream (texture 0; repeat the flag for textures 1, 2, ...): a file, or an
    /// http:// or https:// URL read with Range requests (docs/remote.md). Replaces the scene's
    /// own list of textures.
    #[arg(long, value_name = "PACK")]
    pack: Vec<PathBuf>,
    /// The scene (docs/scenes.md); without it, a plane under a zoom-and-pan camera path that
    /// ends still.
    #[arg(long, value_name = "JSON")]
    scene: Option<PathBuf>,
    /// Folder for the PNG frames (frame-0000.png, ...); none are written without it. Written
    /// whole or not at all; replaces only a folder of frames.
    #[arg(long, value_name = "DIR")]
    frames: Option<PathBuf>,
    /// Where to write the JSON report (per-frame counters, pages touched, convergence). An
    /// earlier report is replaced; any other file only with --force.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Replace a regular file at --report that is not a render report.
    #[arg(long)]
    force: bool,
    /// Override the scene's number of frames.
    #[arg(long, value_name = "N")]
    frame_count: Option<u32>,
    /// Override the scene's output size, e.g. 640x480.
    #[arg(long, value_name = "WxH", value_parser = parse_dims)]
    size: Option<[u32; 2]>,
    #[command(flatten)]
    stream: StreamArgs,
    /// Override the most pages uploaded per frame.
    #[arg(long, value_name = "N")]
    budget: Option<usize>,
    /// offline: each frame waits for the pages the previous one asked for (the same pictures on
    /// every run); real-time: no frame waits, pages are drawn when they land [default: offline,
    /// real-time with --io-latency].
    #[arg(long, value_enum)]
    pacing: Option<PacingArg>,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
}

/// How pages are streamed and drawn: the flags `render` and `view` share, each overriding the
/// scene's effect of the same name.
#[derive(Args, Debug)]
pub(super) struct StreamArgs {
    /// The filter [default: the scene's, else auto: trilinear for packs with a border, nearest
    /// for packs without one, whose page edges would show as seams under bilinear and
    /// trilinear].
    #[arg(long, value_enum)]
    filter: Option<FilterArg>,
    /// The cache size: slots per side (the cache holds this squared).
    #[arg(long, value_name = "N")]
    cache_side: Option<u16>,
    /// What the physical cache holds: auto (BC where the GPU samples it: stored BC7 as it is,
    /// else bc1 for opaque packs, bc7 for alpha; RGBA8 without BC), rgba8 (exact texels), bc1
    /// (an eighth of RGBA8's GPU memory, about 32 dB from exact) or bc7 (a quarter, about 43 dB,
    /// 14x bc1's loader time per page): both transcode every page on the loader's threads [default: the
    /// scene's, else auto].
    #[arg(long, value_enum)]
    cache_format: Option<CacheFormatArg>,
    /// Anisotropic filtering: up to N probes per pixel along the footprint of surfaces seen at a
    /// grazing angle, each at the LOD of the footprint's short side: 1 (off), 2, 4, 8 or 16.
    /// Keeps a receding floor sharp toward the horizon where trilinear blurs it, for up to N
    /// samples per pixel there and pages up to log2(N) LODs finer [default: the scene's, else 1].
    #[arg(long, value_name = "N")]
    anisotropy: Option<u32>,
    /// The loader's threads (at most 4 per core); slow reads want more than cores.
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// Add this latency to every page read, e.g. 50ms: what a slow disk or a network does.
    /// Frames do not wait for it in real time: the picture falls back to coarser pages until
    /// the reads land.
    #[arg(long, value_name = "DURATION", value_parser = parse_duration)]
    pub(super) io_latency: Option<Duration>,
    /// The most one HTTP request of an http:// or https:// pack may take, from connecting to
    /// the last byte of its reply, e.g. 30s or 2m: past it the request fails and is retried, so
    /// a server trickling bytes cannot hold the run (docs/remote.md) [default: 30s].
    #[arg(long, value_name = "DURATION", value_parser = parse_deadline)]
    pub(super) http_deadline: Option<Duration>,
    /// Another layer of the textures' stacks, on their page grid: KIND:PACK[,PACK...] with one
    /// pack per texture, KIND colour (sRGB, premultiplied, BC where the GPU samples it) or data
    /// (normals, roughness: filtered as stored, RGBA8). Repeat for more layers (up to 4 in all);
    /// every layer is streamed together, under one page table. Replaces the scene's "layers".
    #[arg(long = "layer", value_name = "KIND:PACKS", value_parser = parse_layer)]
    layers: Vec<SceneLayer>,
    /// The layer drawn: 0 (the packs given first) or one of the --layer layers, counted from 1.
    #[arg(long, value_name = "N")]
    show_layer: Option<u32>,
    /// MiB of stored (compressed) tiles kept in RAM, least recently used out first: a page the
    /// GPU cache evicted and the view wants again is decoded from RAM instead of read from the
    /// pack (the report's tier_hits); 0 turns the tier off [default: the scene's, else 64].
    #[arg(long, value_name = "MIB")]
    memory_tier: Option<u32>,
}

impl StreamArgs {
    /// Sets the scene's layers and effects these flags override.
    pub(super) fn apply(&self, scene: &mut Scene) {
        if !self.layers.is_empty() {
            scene.layers = self.layers.clone();
        }
        let e = &mut scene.effects;
        e.layer = self.show_layer.unwrap_or(e.layer);
        if let Some(f) = self.filter {
            e.filter = f.filter();
        }
        if let Some(f) = self.cache_format {
            e.cache_format = f.format();
        }
        e.cache_slots_per_side = self.cache_side.unwrap_or(e.cache_slots_per_side);
        e.threads = self.threads.unwrap_or(e.threads);
        e.memory_tier_mib = self.memory_tier.unwrap_or(e.memory_tier_mib);
        e.anisotropy = self.anisotropy.unwrap_or(e.anisotropy);
    }
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum FilterArg {
    Auto,
    Nearest,
    Bilinear,
    Trilinear,
}

impl FilterArg {
    /// The scene's filter: `None` for auto.
    fn filter(self) -> Option<SampleFilter> {
        match self {
            FilterArg::Auto => None,
            FilterArg::Nearest => Some(SampleFilter::Nearest),
            FilterArg::Bilinear => Some(SampleFilter::Bilinear),
            FilterArg::Trilinear => Some(SampleFilter::Trilinear),
        }
    }
}

fn parse_layer(s: &str) -> Result<SceneLayer, String> {
    let (kind, packs) = s.split_once(':').ok_or_else(|| format!("{s:?}: give KIND:PACK, e.g. data:normal.vtpk"))?;
    let kind = LayerKind::from_name(kind).ok_or_else(|| format!("layer kind {kind:?}: colour or data"))?;
    Ok(SceneLayer { kind, textures: packs.split(',').map(PathBuf::from).collect() })
}

/// The scene's layer stacks as page sources: its `textures` as layer 0 (colour), then its
/// `layers`, each read `latency` late if given; the largest tile side; and the packs among them
/// read over HTTP (for their counters), each request held to `http_deadline` if given.
pub(super) fn open_layers(
    scene: &Scene,
    latency: Option<Duration>,
    http_deadline: Option<Duration>,
) -> Result<(Vec<Layer>, u32, Vec<Arc<HttpPack>>)> {
    let mut remote = Vec::new();
    let default = HttpOptions::default();
    let http = HttpOptions { deadline: http_deadline.unwrap_or(default.deadline), ..default };
    let (sources, mut tile_size) = open_sources(&scene.textures, latency, http, &mut remote)?;
    let mut layers = vec![Layer::colour(sources)];
    for layer in &scene.layers {
        let (sources, side) = open_sources(&layer.textures, latency, http, &mut remote)?;
        tile_size = tile_size.max(side);
        layers.push(Layer { kind: layer.kind, sources });
    }
    Ok((layers, tile_size, remote))
}

/// The packs at `paths` as page sources (shards refused: they must be merged first), each read
/// `latency` late if given, and their largest tile side. A path that is an `http://` or
/// `https://` URL is read from the web server with `Range` requests as `http` says, and added
/// to `remote`; its requests end when a signal asks the run to stop.
fn open_sources(
    paths: &[PathBuf],
    latency: Option<Duration>,
    http: HttpOptions,
    remote: &mut Vec<Arc<HttpPack>>,
) -> Result<(Vec<Arc<dyn PageSource>>, u32)> {
    let mut tile_size = 0;
    let sources = paths
        .iter()
        .map(|p| {
            let source: Arc<dyn PageSource> = if let Some(url) = as_url(p) {
                let stop = || signals::requested().is_some();
                let opened = HttpPack::open_with_stop(url, http, vortex_pack::Limits::default(), stop);
                if opened.is_err() && signals::requested().is_some() {
                    return Err(TilerError::Interrupted.into());
                }
                let pack = Arc::new(opened.with_context(|| format!("opening {url}"))?);
                vortex_tiler::scale_out::refuse_shard(p, pack.metadata())?;
                tile_size = tile_size.max(pack.layout().header().description.tile_size);
                remote.push(Arc::clone(&pack));
                pack
            } else {
                // A directory maps as "No such device"; say what is wrong instead.
                if p.is_dir() {
                    bail!("{} is a directory, not a pack (split an image with --pack to make one)", p.shown());
                }
                let pack = vortex_pack::Pack::open(p).with_context(|| format!("opening {}", p.shown()))?;
                vortex_tiler::scale_out::refuse_shard(p, pack.metadata())?;
                tile_size = tile_size.max(pack.description().tile_size);
                Arc::new(pack)
            };
            Ok(match latency {
                Some(latency) => Arc::new(Delayed::new(source, latency)),
                None => source,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((sources, tile_size))
}

/// The URL `p` spells, if it is an `http://` or `https://` one rather than a file's path.
fn as_url(p: &Path) -> Option<&str> {
    p.to_str().filter(|s| s.starts_with("http://") || s.starts_with("https://"))
}

/// The counters of the packs read over HTTP, summed.
pub(super) fn remote_stats(remote: &[Arc<HttpPack>]) -> HttpStats {
    let mut sum = HttpStats::default();
    for s in remote.iter().map(|p| p.stats()) {
        sum.requests += s.requests;
        sum.bytes += s.bytes;
        sum.retries += s.retries;
        sum.io_errors += s.io_errors;
        sum.corrupt += s.corrupt;
        sum.whole_file_replies += s.whole_file_replies;
        sum.merged_reads += s.merged_reads;
    }
    sum
}

/// The report's `remote` object: requests, bytes, retries, I/O errors, payloads that failed their
/// CRC, whole-file replies to `Range` requests, reads merged.
fn remote_counters(remote: &[Arc<HttpPack>]) -> serde_json::Value {
    let sum = remote_stats(remote);
    serde_json::json!({
        "packs": remote.len(),
        "requests": sum.requests,
        "bytes": sum.bytes,
        "retries": sum.retries,
        "io_errors": sum.io_errors,
        "corrupt": sum.corrupt,
        "whole_file_replies": sum.whole_file_replies,
        "merged_reads": sum.merged_reads,
    })
}

/// Says so on stderr when the filter shows seams at page edges (a forced bilinear or trilinear
/// filter over packs without a border).
pub(super) fn warn_of_seams(renderer: &SceneRenderer) {
    let filter = renderer.runtime().filter();
    if filter.seams_with(renderer.runtime().cache().border()) {
        eprintln!(
            "warning: the packs have no border, so {} filtering shows seams at every page edge; \
             split them with --border 1, or use --filter auto (nearest for these packs)",
            filter.name()
        );
    }
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum CacheFormatArg {
    Auto,
    Rgba8,
    Bc1,
    Bc7,
}

impl CacheFormatArg {
    /// The scene's cache format: `None` for auto.
    fn format(self) -> Option<CacheFormat> {
        match self {
            CacheFormatArg::Auto => None,
            CacheFormatArg::Rgba8 => Some(CacheFormat::Rgba8),
            CacheFormatArg::Bc1 => Some(CacheFormat::Bc1),
            CacheFormatArg::Bc7 => Some(CacheFormat::Bc7),
        }
    }
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum PacingArg {
    Offline,
    RealTime,
}

/// `50ms`, `0.2s`, `1s` or a bare number of milliseconds.
pub(super) fn parse_duration(s: &str) -> Result<Duration, String> {
    duration_up_to(s, 60.0, "0 to 60 s such as 50ms or 0.2s")
}

/// `--http-deadline`: as `parse_duration`, or minutes (`2m`), from 1 ms to an hour.
fn parse_deadline(s: &str) -> Result<Duration, String> {
    let t = s.trim();
    let minutes = t.strip_suffix('m').and_then(|m| m.trim().parse::<f64>().ok());
    let d = match minutes {
        Some(m) => duration_up_to(&format!("{}s", m * 60.0), 3600.0, ""),
        None => duration_up_to(t, 3600.0, ""),
    };
    d.ok()
        .filter(|d| *d >= Duration::from_millis(1))
        .ok_or_else(|| format!("'{s}' is not a deadline of 1 ms to an hour such as 30s, 500ms or 2m"))
}

/// `s` as a duration of `0..=max_s` seconds: a number with `ms` or `s` (milliseconds without).
fn duration_up_to(s: &str, max_s: f64, what: &str) -> Result<Duration, String> {
    let t = s.trim();
    let (number, scale) = if let Some(ms) = t.strip_suffix("ms") {
        (ms, 1e-3)
    } else if let Some(secs) = t.strip_suffix('s') {
        (secs, 1.0)
    } else {
        (t, 1e-3)
    };
    match number.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (0.0..=max_s).contains(&(v * scale)) => Ok(Duration::from_secs_f64(v * scale)),
        _ => Err(format!("'{s}' is not a duration of {what}")),
    }
}

pub(super) fn parse_dims(s: &str) -> Result<[u32; 2], String> {
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(|| format!("'{s}' is not WIDTHxHEIGHT"))?;
    let n = |t: &str| t.trim().parse::<u32>().map_err(|_| format!("'{s}' is not WIDTHxHEIGHT"));
    Ok([n(w)?, n(h)?])
}

#[expect(unsafe_code, reason = "std::env::set_var before any thread starts")]
pub fn run(a: RenderArgs) -> Result<()> {
    // Mesa's device-select layer complains on stderr about display variables a headless run
    // has no use for; it only picks the default adapter, which wgpu does itself.
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: no other thread has been started yet (the loader's and wgpu's come later).
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
    let mut scene = match &a.scene {
        Some(path) => Scene::read(path)?,
        None => Scene::default_plane(),
    };
    if !a.pack.is_empty() {
        scene.textures = a.pack.clone();
    }
    if scene.textures.is_empty() {
        bail!("no texture: give --pack PACK (or a scene whose \"textures\" names packs)");
    }
    scene.frames = a.frame_count.unwrap_or(scene.frames);
    scene.size = a.size.unwrap_or(scene.size);
    a.stream.apply(&mut scene);
    let e = &mut scene.effects;
    let pacing = match (a.pacing, a.stream.io_latency) {
        (Some(PacingArg::Offline), _) | (None, None) => Pacing::Offline,
        (Some(PacingArg::RealTime), _) | (None, Some(_)) => Pacing::RealTime,
    };
    e.upload_budget = a.budget.unwrap_or(e.upload_budget);
    check_scene(&scene)?;
    let layer_packs = scene.layers.iter().flat_map(|l| &l.textures);
    let inputs: Vec<&Path> =
        scene.textures.iter().chain(layer_packs).map(PathBuf::as_path).chain(a.scene.as_deref()).collect();
    if let Some(path) = &a.report {
        report::claim(path, Product::Report, &inputs, a.force)?;
    }
    if let Some(dir) = &a.frames {
        report::claim(dir, Product::Frames, &inputs, false)?;
    }
    signals::install().context("installing signal handlers")?;
    // Both outputs' temporaries are made before the first frame, so that a destination that
    // cannot be written is refused at once, not after the whole run.
    let report_file = a.report.as_deref().map(StagedFile::create).transpose()?;
    let frames = a.frames.as_deref().map(StagedFrames::create).transpose()?;

    let (layers, tile_size, remote) = open_layers(&scene, a.stream.io_latency, a.stream.http_deadline)?;
    let side = scene.effects.cache_slots_per_side as u32 * tile_size;
    let gpu = Gpu::headless(side.max(scene.size[0]).max(scene.size[1]))?;
    let adapter = gpu.adapter_info();
    let mut runtime = SceneRenderer::with_layers(gpu, layers, &scene, pacing)?;
    warn_of_seams(&runtime);

    let bar = report::progress_bar(scene.frames as u64, "frames", a.quiet);
    let start = Instant::now();
    let report = runtime.run(&scene, frames.is_some(), |f, picture| -> Result<()> {
        if signals::requested().is_some() {
            return Err(TilerError::Interrupted.into());
        }
        if let (Some(frames), Some(picture)) = (&frames, picture) {
            write_png(&frames.staging.join(format!("frame-{:04}.png", f.frame)), &picture)?;
        }
        bar.set_message(format!("{} loaded, {:.1}% fallback", f.loaded, f.fallback_fraction * 100.0));
        bar.inc(1);
        Ok(())
    })?;
    bar.finish_and_clear();
    let took = start.elapsed();
    if let Some(file) = report_file {
        let mut json = serde_json::to_value(&report)?;
        if !remote.is_empty() {
            json["remote"] = remote_counters(&remote);
        }
        file.finish(serde_json::to_string_pretty(&json)?.as_bytes())?;
    }
    if let Some(frames) = frames {
        frames.finish()?;
    }
    let converge = report
        .frames_to_converge
        .map_or("did not converge".to_string(), |n| format!("converged {n} frame(s) after the camera stopped"));
    say!(
        "rendered {} frames of {}x{} on {} ({}, {} filter) in {:.2} s ({:.1} ms/frame; frame CPU p50 {:.2} ms, p99 {:.2} ms; longest wait for pages {:.1} ms); {} of {} pages touched ({:.2}%), {} read, {} tile(s) from the memory tier; {converge}",
        report.frames.len(),
        scene.size[0],
        scene.size[1],
        adapter.name,
        report.pacing,
        report.filter,
        took.as_secs_f64(),
        took.as_secs_f64() * 1e3 / report.frames.len().max(1) as f64,
        report.cpu_ms_p50,
        report.cpu_ms_p99,
        report.io_wait_ms_max,
        report.pages_touched,
        report.pages_total,
        100.0 * report.pages_touched as f64 / report.pages_total.max(1) as f64,
        super::report::mib(report.bytes_read),
        report.tier_hits,
    );
    refuse_load_errors(runtime.runtime())
}

/// The checks `render` and `view` share, after the flags have overridden the scene: the scene's
/// own (`Scene::check`), its texture ids against its packs, and the most frames a run may draw.
pub(super) fn check_scene(scene: &Scene) -> Result<()> {
    scene
        .check()
        .and_then(|()| scene.check_textures(scene.textures.len()))
        .map_err(|m| anyhow::anyhow!("scene: {m}"))?;
    Limits::default().check_frames(u64::from(scene.frames))?;
    Ok(())
}

/// The rule `render` and `view` share once their pictures are out: a page that failed to load
/// was drawn as the magenta and black stand-in, so the pictures are not the packs', and the run
/// fails (exit 1) naming the first such page. What was written stays, to show where.
pub(super) fn refuse_load_errors(runtime: &Runtime) -> Result<()> {
    match runtime.errors() {
        [] => Ok(()),
        [first, ..] => {
            bail!("{} page(s) failed to load and were drawn as a stand-in; first: {first}", runtime.errors().len())
        }
    }
}

fn write_png(path: &Path, image: &Rgba8Image) -> Result<()> {
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, image.width, image.height);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(image.texels.as_flattened())?;
    writer.finish()?;
    fs::write(path, &bytes).with_context(|| format!("writing {}", path.shown()))
}

/// The report while it is written: its temporary beside the destination, made before the first
/// frame (so that a destination that cannot be written fails the run at once) and renamed into
/// place at the end; removed if the run ends early.
struct StagedFile {
    staging: PathBuf,
    file: fs::File,
    dest: PathBuf,
}

impl StagedFile {
    fn create(dest: &Path) -> Result<StagedFile> {
        let staging = output::partial_path(dest);
        let file = fs::File::create(&staging)
            .with_context(|| format!("cannot write {}: creating {}", dest.shown(), staging.shown()))?;
        Ok(StagedFile { staging, file, dest: dest.to_path_buf() })
    }

    fn finish(self, bytes: &[u8]) -> Result<()> {
        (&self.file)
            .write_all(bytes)
            .and_then(|()| fs::rename(&self.staging, &self.dest))
            .with_context(|| format!("writing {}", self.dest.shown()))
    }
}

impl Drop for StagedFile {
    fn drop(&mut self) {
        // After `finish` the temporary has become the destination and is gone.
        let _ = fs::remove_file(&self.staging);
    }
}

/// The frames folder while it is written: a staging folder beside the destination, removed
/// if the run ends early.
struct StagedFrames {
    staging: PathBuf,
    dest: PathBuf,
}

impl StagedFrames {
    fn create(dest: &Path) -> Result<StagedFrames> {
        let staging = output::partial_path(dest);
        fs::create_dir_all(&staging).with_context(|| format!("creating {}", staging.shown()))?;
        Ok(StagedFrames { staging, dest: dest.to_path_buf() })
    }

    fn finish(self) -> Result<()> {
        output::replace_dir(&self.staging, &self.dest).with_context(|| format!("writing {}", self.dest.shown()))
    }
}

impl Drop for StagedFrames {
    fn drop(&mut self) {
        // After `finish` the staging folder has become the destination and is gone.
        let _ = fs::remove_dir_all(&self.staging);
    }
}
