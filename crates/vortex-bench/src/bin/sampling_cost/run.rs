//! One border x filter: its renderer (the harness on the public runtime, paced offline), held
//! still on a view until converged, timed frame by frame and draw by draw (the same draw without
//! streaming), then checked against the models.

use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail};

use crate::api::{
    Effects, Gpu, LodChain, Pacing, Pack, PageSource, Pose, Rgba8Image, SampleFilter as Filter, SceneRenderer,
    TARGET_FORMAT, VirtualTexture, Window,
};
use crate::compare::{Check, Worst, compare, compare_where};
use crate::reference::model;
use crate::{DRAWS_PER_SUBMIT, FRAMES_PER_ROUND, MAX_CONVERGE_FRAMES, PAYLOAD, SIZE, SUBMITS_PER_ROUND, scene};

pub struct Run {
    pub border: u32,
    pub filter: Filter,
    pub renderer: SceneRenderer,
    pub texture: VirtualTexture,
    /// The target of the draws timed alone (never read back).
    pub target: wgpu::TextureView,
    /// Frames the current view took until its feedback showed no fallback.
    pub converged_after: u32,
    /// Pages loaded during timed frames (should stay 0: nothing streams once converged).
    pub loaded_while_timed: usize,
}

impl Run {
    pub fn new(border: u32, filter: Filter, pack: Arc<Pack>) -> Result<Run> {
        let tile = PAYLOAD + 2 * border;
        let effects = Effects { filter: Some(filter), cache_slots_per_side: 16, upload_budget: 64, ..Effects::exact() };
        let gpu = Gpu::headless(16 * tile).context("no GPU device; install mesa-vulkan-drivers for lavapipe")?;
        let sources = vec![pack as Arc<dyn PageSource>];
        let renderer = SceneRenderer::new(gpu, sources, &scene(effects, [0.5, 0.5], 1.0), Pacing::Offline)
            .context("a renderer")?;
        let texture = renderer.runtime().textures()[0];
        let target = renderer
            .gpu()
            .device
            .create_texture(&wgpu::TextureDescriptor {
                label: Some("sampling_cost target"),
                size: wgpu::Extent3d { width: SIZE[0], height: SIZE[1], depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: TARGET_FORMAT,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                view_formats: &[],
            })
            .create_view(&wgpu::TextureViewDescriptor::default());
        let mut run = Run { border, filter, renderer, texture, target, converged_after: 0, loaded_while_timed: 0 };
        // The first draw into the target makes its pipelines: not timed.
        run.draw_alone(&Pose::Window(Window::whole(0)))?;
        Ok(run)
    }

    pub fn label(&self) -> String {
        format!("border {} {}", self.border, self.filter.name())
    }

    /// Draws `pose` until a frame shows no fallback and the next `block²` frames (every pixel
    /// of a feedback block elected once) load nothing.
    pub fn converge(&mut self, pose: &Pose, view: &str) -> Result<()> {
        let block = self.renderer.runtime().config().feedback_block;
        let mut first_clean = None;
        let mut quiet = 0;
        for f in 0..MAX_CONVERGE_FRAMES {
            let (report, _) =
                self.renderer.frame(pose, false).with_context(|| format!("{} on {view:?}", self.label()))?;
            if report.fallback_fraction == 0.0 {
                first_clean.get_or_insert(f);
            } else {
                first_clean = None;
            }
            quiet = if first_clean.is_some() && report.loaded == 0 && report.deferred == 0 { quiet + 1 } else { 0 };
            if quiet >= block * block
                && let Some(first_clean) = first_clean
            {
                self.converged_after = first_clean;
                return Ok(());
            }
        }
        bail!("{} did not converge on view {view:?} in {MAX_CONVERGE_FRAMES} frames", self.label());
    }

    /// Times `FRAMES_PER_ROUND` frames, in ms each.
    pub fn time_frames(&mut self, pose: &Pose, view: &str) -> Result<Vec<f64>> {
        (0..FRAMES_PER_ROUND)
            .map(|_| {
                let start = Instant::now();
                let (report, _) =
                    self.renderer.frame(pose, false).with_context(|| format!("{} on {view:?}", self.label()))?;
                let ms = start.elapsed().as_secs_f64() * 1e3;
                if report.loaded > 0 || report.fallback_fraction > 0.0 {
                    eprintln!("note: {} on {view:?} streamed while timed: {report:?}", self.label());
                    self.loaded_while_timed += report.loaded;
                }
                Ok(ms)
            })
            .collect()
    }

    /// Times `SUBMITS_PER_ROUND` rounds of `DRAWS_PER_SUBMIT` draws of `window` into the run's
    /// own target (`SceneRenderer::draw_to`: no readback, no end of frame, nothing streams), in
    /// ms per draw.
    pub fn time_sampling(&mut self, window: &Window) -> Result<Vec<f64>> {
        let pose = Pose::Window(*window);
        (0..SUBMITS_PER_ROUND)
            .map(|_| {
                let start = Instant::now();
                for _ in 0..DRAWS_PER_SUBMIT - 1 {
                    self.renderer.draw_to(&pose, &self.target, TARGET_FORMAT, (SIZE[0], SIZE[1]));
                }
                self.draw_alone(&pose)?;
                Ok(start.elapsed().as_secs_f64() * 1e3 / DRAWS_PER_SUBMIT as f64)
            })
            .collect()
    }

    /// One draw of `pose` into the run's own target, waited for.
    fn draw_alone(&mut self, pose: &Pose) -> Result<()> {
        self.renderer.draw_to(pose, &self.target, TARGET_FORMAT, (SIZE[0], SIZE[1]));
        self.renderer.gpu().wait_idle().with_context(|| format!("{}: draws alone", self.label()))
    }

    /// Renders one picture of `window` and compares it with the reference sampler's model of
    /// this runtime and with `ideal`.
    pub fn check(&mut self, chain: &LodChain, window: &Window, ideal: &Rgba8Image) -> Result<Check> {
        let (want, mut fallback) = model(self.renderer.runtime(), chain, &self.texture, window, self.filter);
        let (_, picture) = self
            .renderer
            .frame(&Pose::Window(*window), true)
            .with_context(|| format!("{}: the checked frame", self.label()))?;
        let picture = picture.context("the renderer returned no picture though one was asked for")?;
        // The draw without streaming draws the same thing.
        let alone = self
            .renderer
            .still(&Pose::Window(*window), None)
            .with_context(|| format!("{}: the picture without streaming", self.label()))?;
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
        let lod = origin.lod(0.0, self.texture.grid.lod_count());
        let payload = self.texture.payload() as f32;
        let (mut edge_off, mut inner_off, mut edge_max, mut inner_max) = (0, 0, 0, 0);
        let mut worst = Worst { err: 0, x: 0, y: 0, got: picture.texels[0], want: want.texels[0] };
        for (i, (g, w)) in picture.texels.iter().zip(&want.texels).enumerate() {
            let err = (0..3).map(|c| g[c].abs_diff(w[c])).max().unwrap();
            let (x, y) = (i as u32 % SIZE[0], i as u32 / SIZE[0]);
            let at = origin.at(x as f32 + 0.5, y as f32 + 0.5, lod, self.texture.size(), self.texture.payload());
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
        Ok(Check {
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
        })
    }
}
