//! What sampling accuracy costs in time: nearest, bilinear and trilinear filtering over pages
//! with borders of 0, 1 and 4 texels, each timed on the same 2D-window views and compared with
//! the CPU reference sampler (`vortex_vt::sampler`). Writes `docs/gpu-sampling.md`.
//!
//! ```sh
//! cargo run --release -p vortex-gpu --example sampling_cost [-- OUTPUT.md]
//! ```
//!
//! One synthetic texture (2048² texels: smooth colour, a fine grating, thin dark lines and a
//! little noise; each LOD the 2x2 mean of the one above) is cut into 128-texel payloads with each
//! border and stored raw in three packs. For every border x filter a [`Runtime`] holds each view
//! still until its feedback shows no fallback, then:
//!
//! - **frame time**: `Runtime::frame` without a picture (feedback pass, sampling pass, feedback
//!   readback and analysis, residency update: what an application pays per frame), median over
//!   the timed frames, interleaved across the nine runtimes in rounds so that drift in the
//!   machine's speed spreads over all of them;
//! - **sampling time**: the sampling pass alone (several draws per submission, no readback),
//!   through the runtime's own cache and a copy of its page table;
//! - **error against the runtime's own model**: per pixel, the reference sampler at the LOD of
//!   the page-table entry the pixel reads (what `tests/runtime.rs` checks): any difference beyond
//!   a code value or two is either a missing border (the shader clamps inside the slot, so
//!   border 0 cannot filter across a page edge) or a bug;
//! - **error against an ideal**: trilinear at the exact footprint LOD from the full-resolution
//!   LOD chain, with no page in between: what nearest and bilinear give up in quality.
//!
//! The GPU is pinned to lavapipe (Mesa's CPU Vulkan driver) when it is installed and neither
//! `VK_DRIVER_FILES` nor `VK_ICD_FILENAMES` is set, as in the tests.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use vortex_gpu::SampleFilter as Filter;
use vortex_gpu::camera::Keyframe;
use vortex_gpu::scene::WindowKey;
use vortex_gpu::{
    Effects, Gpu, GpuPageTable, Loader, Pose, RenderTarget, Runtime, SamplePass, Scene, SceneView, Sources, View,
    VirtualTexture, Window,
};
use vortex_pack::format::pyramid_levels;
use vortex_pack::{Description, NewTile, Pack, PackWriter, TileId, TileKind, WriteOptions};
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt::sampler::{LodChain, LodImages, Rgba8Image, bilinear, nearest, trilinear};

#[path = "../../../examples/common/run_info.rs"]
mod run_info;
use run_info::{cores, load_average, today, write_atomically};

/// Payload texels per page side, for every border.
const PAYLOAD: u32 = 128;
/// Pages per side at LOD 0: a 2048² texture, 5 LODs.
const PAGES: u16 = 16;
const BORDERS: [u32; 3] = [0, 1, 4];
const FILTERS: [Filter; 3] = [Filter::Nearest, Filter::Bilinear, Filter::Trilinear];
/// The output size.
const SIZE: [u32; 2] = [512, 384];
/// Timing rounds over all runtimes; each round times `FRAMES_PER_ROUND` frames of each and
/// `SUBMITS_PER_ROUND` submissions of `DRAWS_PER_SUBMIT` sampling-only draws.
const ROUNDS: usize = 120;
const FRAMES_PER_ROUND: usize = 1;
const SUBMITS_PER_ROUND: usize = 1;
const DRAWS_PER_SUBMIT: usize = 3;
/// Frames a still view may take to converge before the run is called off.
const MAX_CONVERGE_FRAMES: u32 = 60;

/// One still view: LOD-0 texels per output pixel and the window's centre in virtual UV.
struct ViewSpec {
    name: &'static str,
    texels_per_pixel: f64,
    center: [f64; 2],
}

/// Non-dyadic centres, so that pixel centres do not fall on texel edges; each window crosses
/// several page edges.
const VIEWS: [ViewSpec; 3] = [
    ViewSpec { name: "magnified 0.5", texels_per_pixel: 0.5, center: [0.312_7, 0.441_9] },
    ViewSpec { name: "1.07", texels_per_pixel: 1.07, center: [0.581_3, 0.379_1] },
    ViewSpec { name: "minified 2.7", texels_per_pixel: 2.7, center: [0.487_1, 0.523_3] },
];

fn main() {
    let output = std::env::args_os().nth(1).map(PathBuf::from).unwrap_or_else(|| {
        let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs");
        docs.canonicalize().unwrap_or(docs).join("gpu-sampling.md")
    });
    pin_lavapipe();
    let started = Instant::now();
    let load_before = load_average();

    let side = PAGES as u32 * PAYLOAD;
    let chain = lod_chain(side, TextureGrid::new(PAGES).unwrap().lod_count);
    let dir = tempfile::tempdir().expect("a temporary directory");
    let packs: Vec<(u32, Arc<Pack>)> = BORDERS
        .iter()
        .map(|&b| (b, write_pack(&dir.path().join(format!("border{b}.vtpk")), &chain, PAYLOAD + 2 * b, b)))
        .collect();
    eprintln!("packs written in {:.1} s", started.elapsed().as_secs_f64());

    let mut runs: Vec<Run> = Vec::new();
    for (border, pack) in &packs {
        for filter in FILTERS {
            runs.push(Run::new(*border, filter, pack.clone()));
        }
    }
    let adapter = runs[0].rt.gpu().adapter_info();
    eprintln!("adapter: {} ({:?}); set up in {:.1} s", adapter.name, adapter.backend, started.elapsed().as_secs_f64());

    let mut rows: Vec<Row> = Vec::new();
    for (v, spec) in VIEWS.iter().enumerate() {
        let window = window(spec, side);
        let pose = Pose::Window(window);
        for run in &mut runs {
            run.converge(&pose, spec.name);
        }
        let mut frame_ms: Vec<Vec<f64>> = vec![Vec::new(); runs.len()];
        let mut sample_ms: Vec<Vec<f64>> = vec![Vec::new(); runs.len()];
        let mut order: Vec<usize> = (0..runs.len()).collect();
        let mut random = 0x9e37_79b9_7f4a_7c15u64 ^ v as u64;
        for _ in 0..ROUNDS {
            // A new order in each round (Fisher-Yates, xorshift), so that no run always follows
            // the same one.
            for k in (1..order.len()).rev() {
                random ^= random << 13;
                random ^= random >> 7;
                random ^= random << 17;
                order.swap(k, (random % (k as u64 + 1)) as usize);
            }
            for &i in &order {
                frame_ms[i].extend(runs[i].time_frames(&pose, spec.name));
                sample_ms[i].extend(runs[i].time_sampling(&window));
            }
        }
        let ideal = ideal(&chain, &window, side);
        for (i, run) in runs.iter_mut().enumerate() {
            let check = run.check(&chain, &window, &ideal);
            rows.push(Row {
                view: v,
                border: run.border,
                filter: run.filter,
                frame_ms: quantile(&mut frame_ms[i], 0.5),
                frame_spread: [quantile(&mut frame_ms[i], 0.1), quantile(&mut frame_ms[i], 0.9)],
                sample_ms: quantile(&mut sample_ms[i], 0.5),
                converged_after: run.converged_after,
                check,
            });
        }
        eprintln!("view {:?} done at {:.1} s", spec.name, started.elapsed().as_secs_f64());
    }

    let table = table(&rows);
    println!("{table}");
    let diagnostics = diagnostics(&rows);
    println!("{diagnostics}");
    let load = match (load_before, load_average()) {
        (Some(a), Some(b)) => format!("{a:.1} at the start and {b:.1} at the end"),
        _ => "unknown".into(),
    };
    let cores = cores();
    let machine = format!(
        "{cores} cores; the 1-minute load average was {load}{}",
        if load_before.is_some_and(|l| l > cores as f64 * 0.5) {
            ": other work shared the machine, which the interleaved rounds spread over every configuration \
             (the p10-p90 column under Details shows the spread). Under such load, repeated runs moved single \
             relative times by up to about 0.1 and the averages in the conclusions by a few hundredths; the \
             errors are the same on every run"
        } else {
            ""
        }
    );
    let doc = document(&adapter.name, &machine, &table, &diagnostics, &rows, started.elapsed().as_secs_f64());
    write_atomically(&output, doc.as_bytes()).unwrap_or_else(|e| panic!("cannot write {}: {e}", output.display()));
    eprintln!("wrote {} in {:.1} s", output.display(), started.elapsed().as_secs_f64());
}

/// Points the Vulkan loader at lavapipe, as the tests do, unless a driver is already chosen.
fn pin_lavapipe() {
    // SAFETY: called in `main` before any other thread exists (the loaders' workers
    // and the drivers' threads are started later), so nothing reads the environment meanwhile.
    unsafe { vortex_gpu::device::prefer_lavapipe() };
}

/// The window of `spec` on a `side`-texel texture, as a scene's pose gives it.
fn window(spec: &ViewSpec, side: u32) -> Window {
    let width = spec.texels_per_pixel * SIZE[0] as f64 / side as f64;
    let scene = scene(Effects::default(), spec.center, width);
    match scene.pose(0) {
        Pose::Window(w) => w,
        Pose::Camera(_) => unreachable!("a window scene"),
    }
}

fn scene(effects: Effects, center: [f64; 2], width: f64) -> Scene {
    Scene {
        textures: vec![],
        size: SIZE,
        frames: 1,
        view: SceneView::Window { texture: 0, path: vec![Keyframe { frame: 0, at: WindowKey { center, width } }] },
        effects,
    }
}

// ---------------------------------------------------------------------------------------------
// The synthetic texture and its packs.

/// An integer hash of a texel position, for noise that is the same on every run.
fn hash(x: u32, y: u32) -> u32 {
    let mut h = x.wrapping_mul(0x2c1b_3c6d) ^ y.wrapping_mul(0x297a_2d39) ^ 0x5bd1_e995;
    h ^= h >> 15;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^ (h >> 16)
}

/// LOD 0, texel (`x`, `y`), of a `side`-texel texture: slow colour waves and a diagonal ramp,
/// a diagonal grating of 4.7 texels whose contrast varies slowly, dark lines one texel wide every
/// 37 texels across and 29 down, and a little noise.
fn source_texel(x: u32, y: u32, side: u32) -> [u8; 4] {
    let (fx, fy) = (x as f64, y as f64);
    let ramp = (fx + fy) / (2.0 * (side - 1) as f64);
    let base = [
        128.0 + 70.0 * (fx * 0.0041 + fy * 0.0023).sin(),
        120.0 + 70.0 * (fy * 0.0037 - fx * 0.0013 + 1.7).sin(),
        50.0 + 150.0 * ramp,
    ];
    let contrast = 0.5 + 0.5 * (fx * 0.0029 - fy * 0.0051 + 0.4).sin();
    let grating = 38.0 * contrast * ((fx * 0.8 + fy * 0.6) * std::f64::consts::TAU / 4.7).sin();
    let line = if x % 37 == 11 || y % 29 == 5 { -70.0 } else { 0.0 };
    let noise = (hash(x, y) % 17) as f64 - 8.0;
    let code = |v: f64| v.round().clamp(0.0, 255.0) as u8;
    let detail = grating + line + noise;
    [code(base[0] + detail), code(base[1] + detail), code(base[2] + 0.6 * detail), 255]
}

/// The texture's LODs: LOD 0 from [`source_texel`], each further LOD the 2x2 mean of the one
/// before in code values, rounded half up (the tiler's `box` filter on an image that fills its
/// page grid).
fn lod_chain(side: u32, lods: u8) -> LodChain {
    let mut levels = vec![Rgba8Image::from_fn(side, side, |x, y| source_texel(x, y, side))];
    for _ in 1..lods {
        let fine = levels.last().unwrap();
        let texel = |x: u32, y: u32| fine.texels[(y * fine.width + x) as usize];
        let coarse = Rgba8Image::from_fn(fine.width / 2, fine.height / 2, |x, y| {
            let quad =
                [texel(2 * x, 2 * y), texel(2 * x + 1, 2 * y), texel(2 * x, 2 * y + 1), texel(2 * x + 1, 2 * y + 1)];
            std::array::from_fn(|c| ((quad.iter().map(|t| t[c] as u32).sum::<u32>() + 2) / 4) as u8)
        });
        levels.push(coarse);
    }
    LodChain(levels)
}

/// The stored tile of `page`: its payload and `border` texels of its neighbours on each side,
/// texels beyond the level's edge repeating the edge (the tiler's layout), RGBA8.
fn stored_tile(chain: &LodChain, page: PageId, tile_size: u32, border: u32) -> Vec<u8> {
    let (w, h) = chain.size(page.lod);
    let payload = (tile_size - 2 * border) as i64;
    let mut bytes = Vec::with_capacity((tile_size * tile_size * 4) as usize);
    for j in 0..tile_size as i64 {
        let y = (page.y as i64 * payload + j - border as i64).clamp(0, h as i64 - 1) as u32;
        for i in 0..tile_size as i64 {
            let x = (page.x as i64 * payload + i - border as i64).clamp(0, w as i64 - 1) as u32;
            bytes.extend_from_slice(&chain.texel(page.lod, x, y));
        }
    }
    bytes
}

/// A pack of every page of `chain` in `tile_size`-texel raw tiles with `border`.
fn write_pack(path: &Path, chain: &LodChain, tile_size: u32, border: u32) -> Arc<Pack> {
    let (side, _) = chain.size(0);
    let d = Description {
        width: side,
        height: side,
        tile_size,
        border,
        level_count: chain.lod_count() as u32,
        channels: 4,
        sample_bytes: 1,
    };
    let levels = pyramid_levels(&d, PAGES as u32);
    let mut writer = PackWriter::create(path, d, levels.clone(), b"{}", WriteOptions::default()).expect("a pack");
    for (lod, level) in levels.iter().enumerate() {
        for y in 0..level.tiles_h {
            for x in 0..level.tiles_w {
                let tile = stored_tile(chain, PageId::new(0, lod as u8, x as u16, y as u16), tile_size, border);
                writer.add(TileId { lod: lod as u32, x, y }, NewTile::Data(TileKind::Raw, &tile)).expect("a tile");
            }
        }
    }
    writer.finish().expect("the pack is written");
    Arc::new(Pack::open(path).expect("the pack opens"))
}

// ---------------------------------------------------------------------------------------------
// One border x filter: its runtime and a sampling-only pass over the runtime's cache.

struct Run {
    border: u32,
    filter: Filter,
    rt: Runtime,
    texture: VirtualTexture,
    /// The sampling-only path: its own pass, target and copy of the runtime's page table.
    pass: SamplePass,
    target: RenderTarget,
    table: GpuPageTable,
    /// Frames the current view took until its feedback showed no fallback.
    converged_after: u32,
    /// Pages loaded during timed frames (should stay 0: nothing streams once converged).
    loaded_while_timed: usize,
}

impl Run {
    fn new(border: u32, filter: Filter, pack: Arc<Pack>) -> Run {
        let tile = PAYLOAD + 2 * border;
        let effects = Effects { filter, cache_slots_per_side: 16, upload_budget: 64, ..Effects::default() };
        let gpu = Gpu::headless(16 * tile).unwrap_or_else(|e| {
            eprintln!("error: no GPU device ({e}); install mesa-vulkan-drivers for lavapipe");
            std::process::exit(2)
        });
        let loader = Loader::new(vec![pack], 2).expect("a loader");
        let rt = Runtime::new(gpu, loader, &scene(effects, [0.5, 0.5], 1.0)).expect("a runtime");
        let texture = rt.textures()[0];
        let device = &rt.gpu().device;
        let pass = SamplePass::new(device, filter);
        let target = RenderTarget::new(device, SIZE[0], SIZE[1]);
        let table = GpuPageTable::new(device, &rt.gpu().queue, &[texture.grid], rt.cache().slots_per_side());
        Run { border, filter, rt, texture, pass, target, table, converged_after: 0, loaded_while_timed: 0 }
    }

    fn label(&self) -> String {
        format!("border {} {}", self.border, self.filter.name())
    }

    /// Draws `pose` until a frame shows no fallback and the next 16 load nothing, then copies
    /// the page table for the sampling-only pass.
    fn converge(&mut self, pose: &Pose, view: &str) {
        let mut first_clean = None;
        let mut quiet = 0;
        for f in 0..MAX_CONVERGE_FRAMES {
            let (report, _) = self.rt.frame(pose, false).expect("a frame");
            if report.fallback_fraction == 0.0 {
                first_clean.get_or_insert(f);
            } else {
                first_clean = None;
            }
            quiet = if first_clean.is_some() && report.loaded == 0 && report.deferred == 0 { quiet + 1 } else { 0 };
            // The feedback jitter visits every sample position of a pixel block within 16 frames.
            if quiet >= 16 {
                self.converged_after = first_clean.unwrap();
                self.table.write_all(&self.rt.gpu().queue, self.rt.page_table());
                return;
            }
        }
        panic!("{} did not converge on view {view:?} in {MAX_CONVERGE_FRAMES} frames", self.label());
    }

    /// Times `FRAMES_PER_ROUND` runtime frames, in ms each.
    fn time_frames(&mut self, pose: &Pose, view: &str) -> Vec<f64> {
        (0..FRAMES_PER_ROUND)
            .map(|_| {
                let start = Instant::now();
                let (report, _) = self.rt.frame(pose, false).expect("a frame");
                let ms = start.elapsed().as_secs_f64() * 1e3;
                if report.loaded > 0 || report.fallback_fraction > 0.0 {
                    eprintln!("note: {} on {view:?} streamed while timed: {report:?}", self.label());
                    self.loaded_while_timed += report.loaded;
                }
                ms
            })
            .collect()
    }

    /// Times `SUBMITS_PER_ROUND` submissions of `DRAWS_PER_SUBMIT` sampling-only draws, in ms per
    /// draw.
    fn time_sampling(&self, window: &Window) -> Vec<f64> {
        let gpu = self.rt.gpu();
        let sources = Sources { textures: self.rt.textures(), table: &self.table, cache: self.rt.cache() };
        let view = View::Window(*window);
        (0..SUBMITS_PER_ROUND)
            .map(|_| {
                let start = Instant::now();
                let mut encoder = gpu.device.create_command_encoder(&Default::default());
                for _ in 0..DRAWS_PER_SUBMIT {
                    self.pass.encode(&gpu.device, &mut encoder, &self.target, &sources, &view, None);
                }
                gpu.queue.submit([encoder.finish()]);
                gpu.wait_idle().expect("the GPU finishes");
                start.elapsed().as_secs_f64() * 1e3 / DRAWS_PER_SUBMIT as f64
            })
            .collect()
    }

    /// Renders one picture of `window` and compares it with the reference sampler's model of
    /// this runtime and with `ideal`.
    fn check(&mut self, chain: &LodChain, window: &Window, ideal: &Rgba8Image) -> Check {
        let (want, mut fallback) = model(&self.rt, chain, &self.texture, window, self.filter);
        let (_, picture) = self.rt.frame(&Pose::Window(*window), true).expect("a frame");
        let picture = picture.expect("a picture was asked for");
        // The sampling-only path draws the same thing.
        let sources = Sources { textures: self.rt.textures(), table: &self.table, cache: self.rt.cache() };
        let alone = self
            .pass
            .render_and_read(self.rt.gpu(), &self.target, &sources, &View::Window(*window), None)
            .expect("a picture");
        let sampling_only_differs = alone != picture;

        let own = compare(&picture, &want);
        let ideal_all = compare(&picture, ideal);
        if fallback.pixels > 0 {
            let mut outside = vec![true; picture.texels.len()];
            for &i in &fallback.at {
                outside[i] = false;
                let (g, w) = (picture.texels[i], ideal.texels[i]);
                fallback.ideal_max = fallback.ideal_max.max((0..3).map(|c| g[c].abs_diff(w[c])).max().unwrap());
            }
            fallback.ideal_elsewhere = compare_where(&picture, ideal, &outside).psnr;
        }
        let ideal = ideal_all;
        // Where the mismatches with the own model are: within a texel of a page edge (of the
        // LOD sampled) or inside a page.
        let origin = window.origin_texels(&self.texture, (SIZE[0], SIZE[1]));
        let lod = origin.lod(0.0, self.texture.grid.lod_count);
        let payload = self.texture.payload() as f32;
        let (mut edge_off, mut inner_off, mut edge_max, mut inner_max) = (0, 0, 0, 0);
        let mut worst = Worst { err: 0, x: 0, y: 0, got: picture.texels[0], want: want.texels[0] };
        for (i, (g, w)) in picture.texels.iter().zip(&want.texels).enumerate() {
            let err = (0..3).map(|c| g[c].abs_diff(w[c])).max().unwrap();
            let (x, y) = (i as u32 % SIZE[0], i as u32 / SIZE[0]);
            let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, PAGES as u32, self.texture.payload());
            let at_edge = at.within.iter().any(|&t| t < 1.0 || t > payload - 1.0);
            if at_edge {
                edge_max = edge_max.max(err);
            } else {
                inner_max = inner_max.max(err);
            }
            if err > 2 {
                *(if at_edge { &mut edge_off } else { &mut inner_off }) += 1;
            }
            if err > worst.err {
                worst = Worst { err, x, y, got: *g, want: *w };
            }
        }
        Check {
            own,
            ideal,
            fallback,
            edge_off,
            inner_off,
            edge_max,
            inner_max,
            worst,
            sampling_only_differs,
            loaded_while_timed: self.loaded_while_timed,
        }
    }
}

/// What the runtime's picture of `window` must be, as `tests/runtime.rs` computes it: at each
/// pixel the reference sample at the LOD of the page-table entry of the pixel's wanted page
/// (trilinear at the footprint LOD when that entry is the wanted page itself). Also returns the
/// pixels drawn from a coarser fallback page.
fn model(
    rt: &Runtime,
    chain: &LodChain,
    tex: &VirtualTexture,
    window: &Window,
    filter: Filter,
) -> (Rgba8Image, Fallback) {
    let size = (SIZE[0], SIZE[1]);
    let origin = window.origin_texels(tex, size);
    let lod = origin.lod(0.0, tex.grid.lod_count);
    let footprint = origin.step[0].max(origin.step[1]).log2().max(0.0);
    let table = rt.page_table();
    let mut fallback = Fallback::default();
    let image = Rgba8Image::from_fn(size.0, size.1, |x, y| {
        let [u, v] = window.uv(x, y, size).map(|t| t as f32);
        let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, PAGES as u32, tex.payload());
        let entry = table.entry(0, lod, at.page[0] as u16, at.page[1] as u16);
        if entry.lod != lod {
            fallback.add(x, y, PageId::new(0, lod, at.page[0] as u16, at.page[1] as u16), entry.lod);
        }
        match filter {
            Filter::Nearest => nearest(chain, entry.lod, u, v),
            Filter::Trilinear if entry.lod == lod => trilinear(chain, footprint, u, v),
            _ => bilinear(chain, entry.lod, u, v),
        }
    });
    (image, fallback)
}

/// The pixels of a picture drawn from a coarser page than they want: how many, their bounding
/// box, and the wanted pages (with the LOD drawn instead).
#[derive(Clone, Debug, Default)]
struct Fallback {
    pixels: u64,
    /// x0, y0, x1, y1, inclusive.
    bounds: Option<[u32; 4]>,
    pages: Vec<(PageId, u8)>,
    /// The pixels' indices, row-major.
    at: Vec<usize>,
    /// Filled in by `Run::check`: the largest difference from the ideal over these pixels, and
    /// the PSNR against the ideal over all other pixels.
    ideal_max: u8,
    ideal_elsewhere: f64,
}

impl Fallback {
    fn add(&mut self, x: u32, y: u32, page: PageId, drawn: u8) {
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

    fn describe(&self) -> String {
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

/// The ideal picture of `window`: trilinear at the exact footprint LOD from the whole LOD chain.
fn ideal(chain: &LodChain, window: &Window, side: u32) -> Rgba8Image {
    let size = (SIZE[0], SIZE[1]);
    let step = (window.extent[0] * side as f64 / size.0 as f64).max(window.extent[1] * side as f64 / size.1 as f64);
    let footprint = (step as f32).log2().max(0.0);
    Rgba8Image::from_fn(size.0, size.1, |x, y| {
        let [u, v] = window.uv(x, y, size).map(|t| t as f32);
        trilinear(chain, footprint, u, v)
    })
}

/// PSNR (dB) and largest difference over the colour channels (alpha is opaque everywhere).
#[derive(Clone, Copy, Debug)]
struct Diff {
    psnr: f64,
    max: u8,
}

fn compare(got: &Rgba8Image, want: &Rgba8Image) -> Diff {
    compare_where(got, want, &vec![true; got.texels.len()])
}

/// [`compare`] over the pixels whose `mask` is true.
fn compare_where(got: &Rgba8Image, want: &Rgba8Image, mask: &[bool]) -> Diff {
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
struct Check {
    own: Diff,
    ideal: Diff,
    fallback: Fallback,
    /// Pixels more than 2 code values off the own model, within a texel of a page edge / inside.
    edge_off: u64,
    inner_off: u64,
    /// Largest difference from the own model there.
    edge_max: u8,
    inner_max: u8,
    /// The pixel with the largest difference.
    worst: Worst,
    sampling_only_differs: bool,
    loaded_while_timed: usize,
}

/// The pixel farthest from the model (the first of them), in colour code values.
#[derive(Clone, Copy, Debug)]
struct Worst {
    err: u8,
    x: u32,
    y: u32,
    got: [u8; 4],
    want: [u8; 4],
}

struct Row {
    view: usize,
    border: u32,
    filter: Filter,
    frame_ms: f64,
    /// The 10th and 90th percentiles of the frame times.
    frame_spread: [f64; 2],
    sample_ms: f64,
    converged_after: u32,
    check: Check,
}

/// The `q` quantile of `v` (0.5: the median), interpolated between the closest ranks.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let at = q * (v.len() - 1) as f64;
    let (lo, hi) = (at.floor() as usize, at.ceil() as usize);
    v[lo] + (v[hi] - v[lo]) * (at - lo as f64)
}

// ---------------------------------------------------------------------------------------------
// The report.

/// The row of bilinear, border 4 on the same view: what times are relative to.
fn baseline(rows: &[Row], view: usize) -> &Row {
    rows.iter().find(|r| r.view == view && r.border == 4 && r.filter == Filter::Bilinear).expect("a baseline row")
}

fn db(psnr: f64) -> String {
    if psnr.is_infinite() { "exact".into() } else { format!("{psnr:.1} dB") }
}

fn table(rows: &[Row]) -> String {
    let mut s = String::new();
    s.push_str("| border | filter | view | ms/frame | relative | sampling ms | relative | PSNR vs own model | max err | PSNR vs ideal |\n");
    s.push_str("|---:|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
    let mut sorted: Vec<&Row> = rows.iter().collect();
    sorted.sort_by_key(|r| (r.view, r.border, r.filter as u8));
    for r in sorted {
        let base = baseline(rows, r.view);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} |",
            r.border,
            r.filter.name(),
            VIEWS[r.view].name,
            r.frame_ms,
            r.frame_ms / base.frame_ms,
            r.sample_ms,
            r.sample_ms / base.sample_ms,
            db(r.check.own.psnr),
            r.check.own.max,
            db(r.check.ideal.psnr),
        );
    }
    s
}

/// Where each run differs from its own model, and anything unexpected.
fn diagnostics(rows: &[Row]) -> String {
    let mut s = String::new();
    s.push_str(
        "| border | filter | view | ms/frame p10-p90 | frames to converge | px > 2 off, at page edges | px > 2 off, inside pages | max err at edges | max err inside | worst pixel (x, y): GPU vs model |\n",
    );
    s.push_str("|---:|---|---|---:|---:|---:|---:|---:|---:|---|\n");
    let mut sorted: Vec<&Row> = rows.iter().collect();
    sorted.sort_by_key(|r| (r.view, r.border, r.filter as u8));
    for r in sorted {
        let c = &r.check;
        let Worst { x, y, got: g, want: w, .. } = c.worst;
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2}-{:.2} | {} | {} | {} | {} | {} | ({x}, {y}): {:?} vs {:?} |",
            r.border,
            r.filter.name(),
            VIEWS[r.view].name,
            r.frame_spread[0],
            r.frame_spread[1],
            r.converged_after,
            c.edge_off,
            c.inner_off,
            c.edge_max,
            c.inner_max,
            &g[..3],
            &w[..3],
        );
    }
    let notes: Vec<String> = rows
        .iter()
        .flat_map(|r| {
            let label = format!("border {} {} on {}", r.border, r.filter.name(), VIEWS[r.view].name);
            let c = &r.check;
            let mut n = Vec::new();
            if c.fallback.pixels > 0 {
                n.push(format!("{label}: drawn from a coarser page after convergence: {}", c.fallback.describe()));
            }
            if c.sampling_only_differs {
                n.push(format!("{label}: the sampling-only draw differs from the runtime's frame"));
            }
            if c.loaded_while_timed > 0 {
                n.push(format!("{label}: {} pages loaded during the timed frames", c.loaded_while_timed));
            }
            n
        })
        .collect();
    if notes.is_empty() {
        s.push_str(
            "\nEvery picture was drawn without fallback, nothing streamed during the timed frames, and the \
             sampling-only draws gave the runtime's picture exactly.\n",
        );
    } else {
        s.push('\n');
        for n in notes {
            let _ = writeln!(s, "- {n}");
        }
    }
    s
}

fn document(adapter: &str, machine: &str, table: &str, diagnostics: &str, rows: &[Row], seconds: f64) -> String {
    let mut s = String::new();
    let _ = write!(
        s,
        "# What sampling accuracy costs on the GPU

Measured by `crates/vortex-gpu/examples/sampling_cost.rs` on {date} in {seconds:.0} s, on the
adapter `{adapter}` (lavapipe) with {machine}.

```sh
cargo run --release -p vortex-gpu --example sampling_cost
```

One synthetic 2048² texture (smooth colour, a diagonal grating of 4.7 texels, dark lines one
texel wide, a little noise; each LOD the 2x2 mean of the one above) is stored raw in 128-texel
payloads with borders of 0, 1 and 4 texels (tiles of 128, 130 and 136). For each border and
filter, `vortex_gpu::Runtime` shows a {w}x{h} 2D window, held still on three views: magnified
(0.5 LOD-0 texels per pixel, LOD 0), about 1:1 (1.07 texels per pixel: LOD 0, trilinear blends
in 10% of LOD 1) and minified (2.7 texels per pixel: LOD 1.43, between LOD 1 and 2). Each view is
held until the feedback shows no fallback; then:

- **ms/frame**: the median of {frames} `Runtime::frame(pose, false)` calls: feedback pass, sampling
  pass, feedback readback and analysis, residency update; what an application pays per frame.
  Timed in {rounds} rounds over the nine runtimes, each round in a new order, so that other
  load on the machine falls on all of them alike.
- **sampling ms**: the sampling pass alone, the median over {submits} submissions of {draws} draws
  each (no readback), through the runtime's cache and a copy of its page table.
- **relative**: to bilinear with border 4 on the same view in the same run. Times on lavapipe
  (Mesa's CPU Vulkan driver) say how the configurations compare with each other, not what a
  GPU would take.
- **PSNR vs own model**, **max err**: against the CPU reference sampler (`vortex_vt::sampler`)
  at each pixel's page-table LOD, as `tests/runtime.rs` checks; max err in 8-bit code values.
  A GPU quantises filter weights, so 1 or 2 code values off is a match.
- **PSNR vs ideal**: against trilinear at the exact footprint LOD from the full-resolution LOD
  chain, with no pages in between: what each filter gives up in quality. This ideal is trilinear
  by definition, so trilinear scores its own agreement with it; at 0.5 texels per pixel it is
  bilinear on LOD 0.

PSNR is over the colour channels (alpha is opaque everywhere).

{table}
## Conclusions

{conclusions}
## Surprises

{surprises}
## Details

A pixel is *at a page edge* when its sample lies within one texel (of the LOD sampled) of the
edge of its page's payload. Frames to converge count from the first frame on the view (the
runtime came from the previous view, or from the whole texture for the first).

{diagnostics}",
        date = today(),
        w = SIZE[0],
        h = SIZE[1],
        frames = ROUNDS * FRAMES_PER_ROUND,
        rounds = ROUNDS,
        submits = ROUNDS * SUBMITS_PER_ROUND,
        draws = DRAWS_PER_SUBMIT,
        conclusions = conclusions(rows),
        surprises = surprises(rows),
    );
    s
}

/// The conclusions, from the numbers of this run.
fn conclusions(rows: &[Row]) -> String {
    let get = |view: usize, border: u32, filter: Filter| {
        rows.iter().find(|r| r.view == view && r.border == border && r.filter == filter).expect("every combination ran")
    };
    let views = 0..VIEWS.len();
    let (magnified, near_one, minified) = (0, 1, VIEWS.len() - 1);
    // Relative to bilinear border 4, averaged over the views (and over `borders`).
    let relative = |filter: Filter, borders: &[u32], sampling: bool| {
        let values: Vec<f64> = views
            .clone()
            .flat_map(|v| borders.iter().map(move |&b| (v, b)))
            .map(|(v, b)| {
                let (r, base) = (get(v, b, filter), baseline(rows, v));
                if sampling { r.sample_ms / base.sample_ms } else { r.frame_ms / base.frame_ms }
            })
            .collect();
        values.iter().sum::<f64>() / values.len() as f64
    };
    let (nearest_frame, trilinear_frame) =
        (relative(Filter::Nearest, &BORDERS, false), relative(Filter::Trilinear, &BORDERS, false));
    let border_rel: Vec<f64> = [0, 1].iter().map(|&b| relative(Filter::Bilinear, &[b], false)).collect();
    let ideal = |v: usize, f: Filter| get(v, 4, f).check.ideal.psnr;
    let nearest_range = views
        .clone()
        .map(|v| ideal(v, Filter::Nearest))
        .fold([f64::INFINITY, 0.0], |[lo, hi], p| [lo.min(p), hi.max(p)]);
    let seams = get(magnified, 0, Filter::Bilinear);
    let gain = ideal(minified, Filter::Trilinear) - ideal(minified, Filter::Bilinear);
    let border_memory = ((PAYLOAD + 8) as f64 / (PAYLOAD + 2) as f64).powi(2) - 1.0;

    let mut s = String::new();
    let _ = writeln!(
        s,
        "- **Cost.** Over the three views and borders, a frame with nearest takes {nearest_frame:.2}x the time of \
         bilinear and one with trilinear {trilinear_frame:.2}x (the sampling pass alone: {:.2}x and {:.2}x). The \
         border costs no time: bilinear with border 0 and 1 takes {:.2}x and {:.2}x.",
        relative(Filter::Nearest, &BORDERS, true),
        relative(Filter::Trilinear, &BORDERS, true),
        border_rel[0],
        border_rel[1],
    );
    let _ = writeln!(
        s,
        "- **Quality.** Against the ideal, nearest reaches only {:.0}-{:.0} dB on every view. Bilinear is close \
         to it magnified ({}) but drops to {} at 1.07 texels per pixel and {} between LODs, where trilinear \
         holds {}. Border 0 \
         rules out filtering: bilinear shows seams at page edges, up to {} code values off ({} against its own \
         model, {} pixels more than 2 off, all at page edges); one texel of border removes them.",
        nearest_range[0],
        nearest_range[1],
        db(ideal(magnified, Filter::Bilinear)),
        db(ideal(near_one, Filter::Bilinear)),
        db(ideal(minified, Filter::Bilinear)),
        db(ideal(minified, Filter::Trilinear)),
        seams.check.own.max,
        db(seams.check.own.psnr),
        seams.check.edge_off + seams.check.inner_off,
    );
    let pick = if gain >= 6.0 && trilinear_frame <= 1.6 {
        format!(
            "trilinear, with a border of at least 1. For {:.0}% more frame time it is {gain:.0} dB closer to \
             the ideal at 2.7 texels per pixel (LOD 1.43), and a continuous zoom rests between two LODs most \
             of the time; bilinear remains the choice when frame time is what is short, and nearest saves {:.0}% \
             for {:.0} dB or more less PSNR, never worth it.",
            (trilinear_frame - 1.0) * 100.0,
            (1.0 - nearest_frame) * 100.0,
            ideal(magnified, Filter::Bilinear) - ideal(magnified, Filter::Nearest),
        )
    } else {
        format!(
            "bilinear, with a border of at least 1: trilinear gains {gain:.1} dB between LODs for {:.0}% more \
             frame time, and nearest saves {:.0}% for a far worse picture.",
            (trilinear_frame - 1.0) * 100.0,
            (1.0 - nearest_frame) * 100.0,
        )
    };
    let _ = writeln!(
        s,
        "- **Default.** I would pick {pick} Border 4 buys these filters nothing over border 1 and costs {:.0}% \
         more cache memory and upload per page; keep a wider border only for anisotropic filtering, or \
         for BC7 tiles, whose side must be a multiple of 4 (130 is not; 132 and 136 are).",
        border_memory * 100.0,
    );
    s
}

/// What the numbers show that one would not expect.
fn surprises(rows: &[Row]) -> String {
    let mut s = String::new();
    let model_ok = rows.iter().filter(|r| r.border > 0).all(|r| r.check.own.max <= 2);
    if model_ok {
        s.push_str(
            "- With a border of 1 or 4, every picture matches the reference sampler's model of the runtime \
             within 2 code values (nearest exactly): no GPU-vs-model mismatch.\n",
        );
    } else {
        for r in rows.iter().filter(|r| r.border > 0 && r.check.own.max > 2) {
            let w = r.check.worst;
            let _ = writeln!(
                s,
                "- **Mismatch**: border {} {} on {}: {} code values off its own model, worst at pixel ({}, {}): \
                 GPU {:?}, model {:?}. With a border the GPU should match; this is a bug in the runtime or \
                 the model.",
                r.border,
                r.filter.name(),
                VIEWS[r.view].name,
                r.check.own.max,
                w.x,
                w.y,
                &w.got[..3],
                &w.want[..3],
            );
        }
    }
    let mut strips: Vec<(usize, String)> = rows
        .iter()
        .filter(|r| r.check.fallback.pixels > 0 && r.border == 4 && r.filter == Filter::Bilinear)
        .map(|r| (r.view, r.check.fallback.describe()))
        .collect();
    strips.dedup_by_key(|(v, _)| *v);
    for (v, what) in strips {
        let _ = writeln!(
            s,
            "- **A converged still view keeps a coarse strip.** On {:?} (every border and filter) the \
             feedback reports no fallback, yet the picture has {what}: a page seen only between the \
             feedback's samples (1 per 8x8 pixels, jittered from frame to frame) was not requested in time.",
            VIEWS[v].name,
        );
    }
    let (magnified_bi, magnified_tri) = (
        baseline(rows, 0),
        rows.iter().find(|r| r.view == 0 && r.border == 4 && r.filter == Filter::Trilinear).expect("a row"),
    );
    let _ = writeln!(
        s,
        "- Magnified, trilinear draws the bilinear picture exactly (its blend weight is 0 below LOD 0: the \
         same PSNRs) and still takes {:.2}x the frame time, although `sample.wgsl` skips the coarser LOD's \
         sample when its weight is 0. The branch depends on a per-fragment value, and lavapipe runs \
         fragments in SIMD groups under a mask, so it appears to pay for the skipped sample anyway; a GPU \
         that branches per warp would not.",
        magnified_tri.frame_ms / magnified_bi.frame_ms,
    );
    s
}
