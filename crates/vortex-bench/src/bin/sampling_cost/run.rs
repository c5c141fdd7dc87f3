//! One border x filter: its runtime, held still on a view until converged, timed frame by frame
//! and through a sampling-only pass over the runtime's cache, then checked against the models.

use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail};

use crate::api::{
    Effects, Gpu, GpuPageTable, Loader, LodChain, Pack, Pose, RenderTarget, Rgba8Image, Runtime,
    SampleFilter as Filter, SamplePass, Sources, View, VirtualTexture, Window,
};
use crate::compare::{Check, Worst, compare, compare_where};
use crate::reference::model;
use crate::{DRAWS_PER_SUBMIT, FRAMES_PER_ROUND, MAX_CONVERGE_FRAMES, PAYLOAD, SIZE, SUBMITS_PER_ROUND, scene};

pub struct Run {
    pub border: u32,
    pub filter: Filter,
    pub rt: Runtime,
    pub texture: VirtualTexture,
    /// The sampling-only path: its own pass, target and copy of the runtime's page table.
    pub pass: SamplePass,
    pub target: RenderTarget,
    pub table: GpuPageTable,
    /// Frames the current view took until its feedback showed no fallback.
    pub converged_after: u32,
    /// Pages loaded during timed frames (should stay 0: nothing streams once converged).
    pub loaded_while_timed: usize,
}

impl Run {
    pub fn new(border: u32, filter: Filter, pack: Arc<Pack>) -> Result<Run> {
        let tile = PAYLOAD + 2 * border;
        let effects = Effects { filter, cache_slots_per_side: 16, upload_budget: 64, ..Effects::default() };
        let gpu = Gpu::headless(16 * tile).context("no GPU device; install mesa-vulkan-drivers for lavapipe")?;
        let loader = Loader::new(vec![pack], 2).context("a loader")?;
        let rt = Runtime::new(gpu, loader, &scene(effects, [0.5, 0.5], 1.0)).context("a runtime")?;
        let texture = rt.textures()[0];
        let device = &rt.gpu().device;
        let pass = SamplePass::new(device, filter);
        let target = RenderTarget::new(device, SIZE[0], SIZE[1]);
        let table = GpuPageTable::new(device, &rt.gpu().queue, &[texture.grid], rt.cache().slots_per_side())
            .context("a page table")?;
        Ok(Run { border, filter, rt, texture, pass, target, table, converged_after: 0, loaded_while_timed: 0 })
    }

    pub fn label(&self) -> String {
        format!("border {} {}", self.border, self.filter.name())
    }

    /// Draws `pose` until a frame shows no fallback and the next 16 load nothing, then copies
    /// the page table for the sampling-only pass.
    pub fn converge(&mut self, pose: &Pose, view: &str) -> Result<()> {
        let mut first_clean = None;
        let mut quiet = 0;
        for f in 0..MAX_CONVERGE_FRAMES {
            let (report, _) = self.rt.frame(pose, false).with_context(|| format!("{} on {view:?}", self.label()))?;
            if report.fallback_fraction == 0.0 {
                first_clean.get_or_insert(f);
            } else {
                first_clean = None;
            }
            quiet = if first_clean.is_some() && report.loaded == 0 && report.deferred == 0 { quiet + 1 } else { 0 };
            // The feedback jitter visits every sample position of a pixel block within 16 frames.
            if quiet >= 16
                && let Some(first_clean) = first_clean
            {
                self.converged_after = first_clean;
                self.table.write_all(&self.rt.gpu().queue, self.rt.page_table());
                return Ok(());
            }
        }
        bail!("{} did not converge on view {view:?} in {MAX_CONVERGE_FRAMES} frames", self.label());
    }

    /// Times `FRAMES_PER_ROUND` runtime frames, in ms each.
    pub fn time_frames(&mut self, pose: &Pose, view: &str) -> Result<Vec<f64>> {
        (0..FRAMES_PER_ROUND)
            .map(|_| {
                let start = Instant::now();
                let (report, _) =
                    self.rt.frame(pose, false).with_context(|| format!("{} on {view:?}", self.label()))?;
                let ms = start.elapsed().as_secs_f64() * 1e3;
                if report.loaded > 0 || report.fallback_fraction > 0.0 {
                    eprintln!("note: {} on {view:?} streamed while timed: {report:?}", self.label());
                    self.loaded_while_timed += report.loaded;
                }
                Ok(ms)
            })
            .collect()
    }

    /// Times `SUBMITS_PER_ROUND` submissions of `DRAWS_PER_SUBMIT` sampling-only draws, in ms per
    /// draw.
    pub fn time_sampling(&self, window: &Window) -> Result<Vec<f64>> {
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
                gpu.wait_idle().with_context(|| format!("{}: sampling-only draws", self.label()))?;
                Ok(start.elapsed().as_secs_f64() * 1e3 / DRAWS_PER_SUBMIT as f64)
            })
            .collect()
    }

    /// Renders one picture of `window` and compares it with the reference sampler's model of
    /// this runtime and with `ideal`.
    pub fn check(&mut self, chain: &LodChain, window: &Window, ideal: &Rgba8Image) -> Result<Check> {
        let (want, mut fallback) = model(&self.rt, chain, &self.texture, window, self.filter);
        let (_, picture) = self
            .rt
            .frame(&Pose::Window(*window), true)
            .with_context(|| format!("{}: the checked frame", self.label()))?;
        let picture = picture.context("the runtime returned no picture though one was asked for")?;
        // The sampling-only path draws the same thing.
        let sources = Sources { textures: self.rt.textures(), table: &self.table, cache: self.rt.cache() };
        let alone = self
            .pass
            .render_and_read(self.rt.gpu(), &self.target, &sources, &View::Window(*window), None)
            .with_context(|| format!("{}: the sampling-only picture", self.label()))?;
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
