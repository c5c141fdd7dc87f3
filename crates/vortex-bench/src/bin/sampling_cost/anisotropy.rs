//! The anisotropy section: the default plane scene's still view (low over the plane, looking
//! toward its far edge) drawn trilinear with at most 1, 2, 4 and 8 probes per sample over the
//! 2048² synthetic texture (border 1), each against a supersampled ground truth and timed.
//!
//! The ground truth is computed on the CPU: each pixel's ray meets the plane at a UV, the UVs of
//! the pixels to the right and below give its derivatives, and
//! `vortex_vt::sampler::supersampled_linear` integrates LOD 0 over the parallelogram they span
//! (two samples per texel along each derivative, at most [`MAX_PER_AXIS`]). Pixels within two
//! pixels of the plane's edge are left out (the GPU's derivatives there come from the quad, half
//! of it off the plane). PSNR is over RGB in sRGB code values, for all plane pixels and for the
//! far ones (footprint at least 4 times longer than wide: toward the horizon).

use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use vortex_vt::sampler::{encode, supersampled_linear};

use crate::api::{
    Effects, Gpu, LodChain, Pacing, Pack, PageSource, Pose, Rgba8Image, SampleFilter, Scene, SceneRenderer, SceneView,
    Shape,
};
use vortex_bench::run_info::{cores, today};

use crate::report::quantile;

pub const ANISOTROPY: [u32; 4] = [1, 2, 4, 8];
/// Ground-truth samples per derivative at most: footprints up to half as many texels long are
/// fully sampled.
const MAX_PER_AXIS: u32 = 96;
const ROUNDS: usize = 100;
const MAX_CONVERGE_FRAMES: u32 = 400;

/// One anisotropy's numbers.
pub struct Row {
    pub anisotropy: u32,
    pub frame_ms: f64,
    pub psnr_all: f64,
    pub psnr_far: f64,
    pub pages_resident: usize,
}

/// The plane scene over `pack` with `anisotropy`.
fn scene(size: [u32; 2], anisotropy: u32) -> Scene {
    let mut scene = Scene::default_plane();
    scene.size = size;
    // Exact texels: what is measured is the filter, not the cache's compression.
    scene.effects = Effects::exact();
    scene.effects.filter = Some(SampleFilter::Trilinear);
    // The whole texture fits (341 pages): what is measured is the filter, not the eviction.
    scene.effects.cache_slots_per_side = 19;
    scene.effects.upload_budget = 64;
    scene.effects.anisotropy = anisotropy;
    scene
}

/// Measures the section on `pack` (tiles of `tile` texels, border 1), whose LODs are `chain`.
pub fn measure(pack: &Arc<Pack>, tile: u32, chain: &LodChain, size: [u32; 2]) -> Result<(Vec<Row>, String)> {
    let base = scene(size, 1);
    let frame = base.frames - 1;
    let mut runs = Vec::new();
    for n in ANISOTROPY {
        let gpu = Gpu::headless(19 * tile).context("no GPU device; install mesa-vulkan-drivers for lavapipe")?;
        let sources = vec![pack.clone() as Arc<dyn PageSource>];
        let mut r = SceneRenderer::new(gpu, sources, &scene(size, n), Pacing::Offline).context("a plane renderer")?;
        let pose = base.pose(frame, r.runtime().textures());
        converge(&mut r, &pose, n)?;
        runs.push((n, r, pose, Vec::new()));
    }
    for _ in 0..ROUNDS {
        for (_, r, pose, ms) in &mut runs {
            let start = Instant::now();
            r.frame(pose, false)?;
            ms.push(start.elapsed().as_secs_f64() * 1e3);
        }
    }
    let adapter = runs[0].1.gpu().adapter_info().name;
    let truth = ground_truth(&base, chain);
    let mut rows = Vec::new();
    for (n, r, pose, mut ms) in runs {
        let picture = r.still(&pose, None)?;
        let (psnr_all, psnr_far) = psnr(&picture, &truth);
        let table = r.runtime().page_table();
        let lods = table.grids()[0].lod_count();
        let pages_resident = (0..lods).map(|l| table.level(0, l).iter().filter(|e| e.lod == l).count()).sum();
        rows.push(Row { anisotropy: n, frame_ms: quantile(&mut ms, 0.5), psnr_all, psnr_far, pages_resident });
    }
    Ok((rows, adapter))
}

/// Draws `pose` until no pixel falls back and 64 more frames (every pixel of an 8x8 feedback
/// block heard) load nothing.
fn converge(r: &mut SceneRenderer, pose: &Pose, n: u32) -> Result<()> {
    let mut quiet = 0;
    for _ in 0..MAX_CONVERGE_FRAMES {
        let (report, _) = r.frame(pose, false)?;
        quiet = if report.fallback_fraction == 0.0 && report.loaded == 0 { quiet + 1 } else { 0 };
        if quiet >= 64 {
            return Ok(());
        }
    }
    bail!("anisotropy {n}: the plane did not converge in {MAX_CONVERGE_FRAMES} frames")
}

/// Per pixel: the ground truth and the footprint's anisotropy (long / short), or `None` off the
/// plane or near its edge.
struct Truth {
    width: u32,
    pixels: Vec<Option<([u8; 4], f32)>>,
}

fn ground_truth(scene: &Scene, chain: &LodChain) -> Truth {
    let SceneView::Camera { fov_y_deg, path, geometry } = &scene.view else { unreachable!("the plane scene") };
    let camera = path.last().expect("a path").at;
    let size = match geometry[0] {
        Shape::Plane { size, .. } => size,
        _ => unreachable!("a plane"),
    };
    let [w, h] = scene.size;
    let uv = |x: f32, y: f32| camera.plane_uv(*fov_y_deg, [w as f32, h as f32], size, x, y);
    let texels = [chain.0[0].width as f32, chain.0[0].height as f32];
    let rows: Vec<u32> = (0..h).collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let pixels = std::thread::scope(|s| {
        let parts: Vec<_> = rows
            .chunks(h.div_ceil(threads as u32) as usize)
            .map(|part| {
                s.spawn(move || {
                    let mut out = Vec::new();
                    for &y in part {
                        for x in 0..w {
                            let (x, y) = (x as f32 + 0.5, y as f32 + 0.5);
                            // Two pixels either way on the plane, inside its edge.
                            let inside = [(-2.0, 0.0), (2.0, 0.0), (0.0, -2.0), (0.0, 2.0), (0.0, 0.0)].iter().all(
                                |(dx, dy)| uv(x + dx, y + dy).is_some_and(|p| p.iter().all(|c| (0.0..1.0).contains(c))),
                            );
                            out.push(inside.then(|| {
                                let (p, px, py) = (uv(x, y).unwrap(), uv(x + 1.0, y).unwrap(), uv(x, y + 1.0).unwrap());
                                let ddx = [px[0] - p[0], px[1] - p[1]];
                                let ddy = [py[0] - p[0], py[1] - p[1]];
                                let len =
                                    |d: [f32; 2]| ((d[0] * texels[0]).powi(2) + (d[1] * texels[1]).powi(2)).sqrt();
                                let (a, b) = (len(ddx), len(ddy));
                                (encode(supersampled_linear(chain, p, ddx, ddy, MAX_PER_AXIS)), a.max(b) / a.min(b))
                            }));
                        }
                    }
                    out
                })
            })
            .collect();
        parts.into_iter().flat_map(|p| p.join().expect("a ground-truth thread")).collect()
    });
    Truth { width: w, pixels }
}

/// PSNR of `picture` against the truth over all plane pixels and over the far ones.
fn psnr(picture: &Rgba8Image, truth: &Truth) -> (f64, f64) {
    let (mut all, mut far) = ((0.0, 0usize), (0.0, 0usize));
    for (i, t) in truth.pixels.iter().enumerate() {
        let Some((want, ratio)) = t else { continue };
        let got = picture.texels[i];
        let sq: f64 = (0..3).map(|c| (got[c] as f64 - want[c] as f64).powi(2)).sum();
        all = (all.0 + sq, all.1 + 3);
        if *ratio >= 4.0 {
            far = (far.0 + sq, far.1 + 3);
        }
    }
    debug_assert_eq!(picture.width, truth.width);
    let db = |(sq, n): (f64, usize)| 10.0 * (255.0f64.powi(2) / (sq / n.max(1) as f64)).log10();
    (db(all), db(far))
}

/// Where and when the section was measured.
pub fn run_line(adapter: &str, load_before: Option<f64>, load_after: Option<f64>) -> String {
    let load = match (load_before, load_after) {
        (Some(a), Some(b)) => format!("{a:.1} at the start and {b:.1} at the end"),
        _ => "unknown".into(),
    };
    format!(
        "Measured by `sampling_cost --anisotropy` on {} on the adapter `{adapter}` (lavapipe) with {} cores; \
         the 1-minute load average was {load} (frame times of the four filters interleaved, so that load \
         spreads over all of them; the PSNRs are the same on every run).",
        today(),
        cores()
    )
}

/// The section's table.
pub fn table(rows: &[Row]) -> String {
    let mut t = String::from(
        "| filter | frame (ms, median) | PSNR vs ground truth, plane (dB) | PSNR, far: footprint >= 4:1 (dB) | pages resident |\n|---|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let name = if r.anisotropy == 1 {
            "trilinear".to_string()
        } else {
            format!("trilinear, {}x anisotropic", r.anisotropy)
        };
        t +=
            &format!("| {name} | {:.1} | {:.2} | {:.2} | {} |\n", r.frame_ms, r.psnr_all, r.psnr_far, r.pages_resident);
    }
    t.trim_end().to_string()
}
