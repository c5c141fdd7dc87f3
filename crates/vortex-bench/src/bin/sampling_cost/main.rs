//! `sampling_cost`: what sampling accuracy costs in time: nearest, bilinear and trilinear filtering over pages
//! with borders of 0, 1 and 4 texels, each timed on the same 2D-window views and compared with
//! the CPU reference sampler (`vortex_vt::sampler`). Splices its tables and verdicts into
//! `docs/gpu-sampling.md` (or OUTPUT.md, which must hold the same markers), whose prose is
//! written by hand.
//!
//! ```sh
//! cargo run --release -p vortex-bench --bin sampling_cost [-- [--anisotropy] OUTPUT.md]
//! ```
//!
//! `--anisotropy` runs only the anisotropy section (`anisotropy`: the plane scene toward the
//! horizon, trilinear against 2x, 4x and 8x anisotropic, against a supersampled ground truth),
//! whose blocks are `gpu-aniso:*`.
//!
//! One synthetic texture (2048² texels: smooth colour, a fine grating, thin dark lines and a
//! little noise; each LOD the 2x2 mean of the one above) is cut into 128-texel payloads with each
//! border and stored raw in three packs. For every border x filter a `SceneRenderer` (the
//! harness, an application of the public runtime, paced offline so that every run streams the
//! same pages) holds each view still until its feedback shows no fallback, then:
//!
//! - **frame time**: `SceneRenderer::frame` without a picture (the draw, whose fragment shader
//!   samples and writes feedback, then `Runtime::end_frame`: feedback copy, readback and
//!   analysis, residency update; what an application pays per frame), median over the timed
//!   frames, interleaved across the nine renderers in rounds so that drift in the machine's
//!   speed spreads over all of them;
//! - **sampling time**: the draw alone (`SceneRenderer::draw_to` a target of its own, several
//!   draws per wait, no readback, no end of frame: nothing streams), through the runtime's cache
//!   and page table;
//! - **error against the runtime's own model**: per pixel, the reference sampler at the LOD of
//!   the page-table entry the pixel reads (what `tests/runtime.rs` checks): any difference beyond
//!   a code value or two is either a missing border (the shader clamps inside the slot, so
//!   border 0 cannot filter across a page edge) or a bug;
//! - **error against an ideal**: trilinear at the exact footprint LOD from the full-resolution
//!   LOD chain, with no page in between: what nearest and bilinear give up in quality.
//!
//! The GPU is pinned to lavapipe (Mesa's CPU Vulkan driver) when it is installed and neither
//! `VK_DRIVER_FILES` nor `VK_ICD_FILENAMES` is set, as in the tests.
#![allow(clippy::unwrap_used, clippy::expect_used)] // measurement programs may panic on a broken set-up

mod anisotropy;
mod api;
mod compare;
mod conclusions;
mod reference;
mod report;
mod run;
mod texture;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use vortex_bench::out;
use vortex_bench::run_info::{cores, load_average, today};
use vortex_bench::splice::{Block, splice_file};

use crate::api::{
    Effects, Keyframe, Pack, Pose, SampleFilter as Filter, Scene, SceneView, TextureGrid, TileKind, VirtualTexture,
    Window, WindowKey, prefer_lavapipe, write_pack,
};
use crate::report::Row;
use crate::run::Run;

/// Payload texels per page side, for every border.
const PAYLOAD: u32 = 128;
/// Pages per side at LOD 0: a 2048² texture, 5 LODs.
const PAGES: u16 = 16;
const BORDERS: [u32; 3] = [0, 1, 4];
const FILTERS: [Filter; 3] = [Filter::Nearest, Filter::Bilinear, Filter::Trilinear];
/// The output size.
const SIZE: [u32; 2] = [512, 384];
/// Timing rounds over all renderers; each round times `FRAMES_PER_ROUND` frames of each and
/// `SUBMITS_PER_ROUND` waits for `DRAWS_PER_SUBMIT` draws alone.
const ROUNDS: usize = 120;
const FRAMES_PER_ROUND: usize = 1;
const SUBMITS_PER_ROUND: usize = 1;
const DRAWS_PER_SUBMIT: usize = 3;
/// Frames a still view may take to converge (including the `block²` quiet frames that show
/// that every pixel of a feedback block was heard) before the run is called off.
const MAX_CONVERGE_FRAMES: u32 = 160;

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

#[expect(unsafe_code, reason = "pinning the Vulkan driver sets environment variables")]
fn main() -> Result<()> {
    // SAFETY: first thing in `main`, before any thread is spawned (the loaders' workers and the
    // drivers' threads start later, in `Run::new`), so no other thread reads the environment.
    unsafe { prefer_lavapipe() };
    let mut args: Vec<_> = std::env::args_os().skip(1).collect();
    let only_anisotropy = args.first().is_some_and(|a| a == "--anisotropy");
    if only_anisotropy {
        args.remove(0);
    }
    let output = args.first().map(PathBuf::from).unwrap_or_else(|| {
        let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs");
        docs.canonicalize().unwrap_or(docs).join("gpu-sampling.md")
    });
    let started = Instant::now();
    let load_before = load_average();

    let side = PAGES as u32 * PAYLOAD;
    let grid = TextureGrid::new(PAGES.into(), PAGES.into()).context("a page grid of PAGES pages per side")?;
    let chain = texture::lod_chain(side, grid.lod_count());
    let dir = tempfile::tempdir().context("a temporary directory")?;
    let packs: Vec<(u32, Arc<Pack>)> = BORDERS
        .iter()
        .map(|&b| {
            let path = dir.path().join(format!("border{b}.vtpk"));
            let texture = VirtualTexture::filling(grid, PAYLOAD + 2 * b, b);
            let pack = write_pack(&path, &chain, &texture, TileKind::Raw)
                .with_context(|| format!("writing the pack {}", path.display()))?;
            Ok((b, pack))
        })
        .collect::<Result<_>>()?;
    eprintln!("packs written in {:.1} s", started.elapsed().as_secs_f64());
    let (_, border1) = packs.iter().find(|(b, _)| *b == 1).context("the border-1 pack")?;
    let (aniso, aniso_adapter) = anisotropy::measure(border1, PAYLOAD + 2, &chain, SIZE)?;
    let aniso_table = anisotropy::table(&aniso);
    println!("{aniso_table}");
    let aniso_blocks = [
        Block::new("gpu-aniso:run", anisotropy::run_line(&aniso_adapter, load_before, load_average())),
        Block::new("gpu-aniso:table", aniso_table),
    ];
    splice_file(&output, "gpu-aniso:", &aniso_blocks)?;
    if only_anisotropy {
        eprintln!("wrote the anisotropy section of {} in {:.1} s", output.display(), started.elapsed().as_secs_f64());
        return Ok(());
    }

    let mut runs: Vec<Run> = Vec::new();
    for (border, pack) in &packs {
        for filter in FILTERS {
            runs.push(Run::new(*border, filter, pack.clone())?);
        }
    }
    let adapter = runs[0].renderer.gpu().adapter_info();
    eprintln!("adapter: {} ({:?}); set up in {:.1} s", adapter.name, adapter.backend, started.elapsed().as_secs_f64());

    let mut rows: Vec<Row> = Vec::new();
    for (v, spec) in VIEWS.iter().enumerate() {
        let window = window(spec, side);
        let pose = Pose::Window(window);
        for run in &mut runs {
            run.converge(&pose, spec.name)?;
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
                frame_ms[i].extend(runs[i].time_frames(&pose, spec.name)?);
                sample_ms[i].extend(runs[i].time_sampling(&window)?);
            }
        }
        let ideal = reference::ideal(&chain, &window, side);
        for (i, run) in runs.iter_mut().enumerate() {
            let check = run.check(&chain, &window, &ideal)?;
            rows.push(Row {
                view: v,
                border: run.border,
                filter: run.filter,
                frame_ms: report::quantile(&mut frame_ms[i], 0.5),
                frame_spread: [report::quantile(&mut frame_ms[i], 0.1), report::quantile(&mut frame_ms[i], 0.9)],
                sample_ms: report::quantile(&mut sample_ms[i], 0.5),
                converged_after: run.converged_after,
                check,
            });
        }
        eprintln!("view {:?} done at {:.1} s", spec.name, started.elapsed().as_secs_f64());
    }

    println!("{}", report::table(&rows));
    println!("{}", report::diagnostics(&rows));
    let load_after = load_average();
    let seconds = started.elapsed().as_secs_f64();
    let blocks = [
        Block::new("gpu-sampling:run", run_line(&adapter.name, load_before, load_after, seconds)),
        Block::new("gpu-sampling:timing", timing()),
        Block::new("gpu-sampling:table", report::table(&rows)),
        Block::new("gpu-sampling:conclusions", conclusions::conclusions(&rows)),
        Block::new("gpu-sampling:surprises", conclusions::surprises(&rows)),
        Block::new("gpu-sampling:details", report::diagnostics(&rows)),
    ];
    splice_file(&output, "gpu-sampling:", &blocks)?;
    eprintln!("wrote {} in {:.1} s", output.display(), started.elapsed().as_secs_f64());
    Ok(())
}

/// The window of `spec` on a `side`-texel texture, as a scene's pose gives it.
fn window(spec: &ViewSpec, side: u32) -> Window {
    let width = spec.texels_per_pixel * SIZE[0] as f64 / side as f64;
    let scene = scene(Effects::exact(), spec.center, width);
    // A square image: the pose needs no texture to know its aspect ratio.
    match scene.pose(0, &[]) {
        Pose::Window(w) => w,
        Pose::Camera(_) => unreachable!("a window scene"),
    }
}

fn scene(effects: Effects, center: [f64; 2], width: f64) -> Scene {
    Scene {
        textures: vec![],
        layers: vec![],
        size: SIZE,
        frames: 1,
        view: SceneView::Window { texture: 0, path: vec![Keyframe { frame: 0, at: WindowKey { center, width } }] },
        effects,
    }
}

/// `gpu-sampling:run`: when, how long, on which adapter and how loaded a machine.
fn run_line(adapter: &str, load_before: Option<f64>, load_after: Option<f64>, seconds: f64) -> String {
    let load = match (load_before, load_after) {
        (Some(a), Some(b)) => format!("{a:.1} at the start and {b:.1} at the end"),
        _ => "unknown".into(),
    };
    let cores = cores();
    let shared = if load_before.is_some_and(|l| l > cores as f64 * 0.5) {
        ": other work shared the machine, which the interleaved rounds spread over every configuration \
         (the p10-p90 column under Details shows the spread). Under such load, repeated runs moved single \
         relative times by up to about 0.1 and the averages in the conclusions by a few hundredths; the \
         errors are the same on every run"
    } else {
        ""
    };
    format!(
        "Measured by `sampling_cost` (`crates/vortex-bench`) on {date} in {seconds:.0} s, on the\n\
         adapter `{adapter}` (lavapipe) with {cores} cores; the 1-minute load average was {load}{shared}.",
        date = today(),
    )
}

/// `gpu-sampling:timing`: how the two times are taken, with this program's counts.
fn timing() -> String {
    let mut s = String::new();
    out!(
        s,
        "- **ms/frame**: the median of {frames} `SceneRenderer::frame(pose, false)` calls, paced offline: the
  draw (its fragment shader samples and writes the feedback of its elected pixels), then
  `Runtime::end_frame` (feedback copy, readback and analysis, residency update); what an
  application pays per frame. Timed in {ROUNDS} rounds over the nine renderers, each round in a
  new order, so that other load on the machine falls on all of them alike.
- **sampling ms**: the draw alone, the median over {submits} waits for {DRAWS_PER_SUBMIT} draws each
  (`SceneRenderer::draw_to` a target of the program's own: no readback, no end of frame, so
  nothing streams), through the runtime's cache and page table.",
        frames = ROUNDS * FRAMES_PER_ROUND,
        submits = ROUNDS * SUBMITS_PER_ROUND,
    );
    s
}
