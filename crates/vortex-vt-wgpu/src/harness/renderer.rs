//! The headless renderer of scenes, built on the public API as any application is: a
//! [`Runtime`] on a headless device, the harness's own shader and pipelines (which include the
//! module, `crate::shader`), an offscreen target read back to the CPU, and a frame loop along the
//! scene's camera path that calls [`Runtime::end_frame`] after each frame. `vortex-tiler render`
//! and the tests drive it.

use std::cell::RefCell;
use std::sync::Arc;
use std::time::Duration;

use crate::clock::Instant;

use serde::Serialize;
use vortex_vt::sampler::Rgba8Image;

use super::draw::{self, Pipelines, Target};
use super::frame::Frame;
use super::mesh::GpuMesh;
use super::scene::{Pose, Scene};
use super::view::View;
use crate::device::Gpu;
use crate::layer::Layer;
use crate::readback::{Readback, ReadbackError};
use crate::runtime::{FrameStats, Pacing, Runtime, RuntimeConfig, RuntimeError};
use crate::sample::SampleFilter;
use crate::shader;
use crate::source::PageSource;

/// The format of the harness's colour target: sRGB, so the linear-light samples are encoded on
/// write.
pub const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// What a pipeline of the harness is specialised for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PipelineKey {
    format: wgpu::TextureFormat,
    filter: SampleFilter,
    anisotropy: u32,
    residency_view: bool,
    layer: u32,
}

/// The counters of one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FrameReport {
    /// The frame's number, from 0.
    pub frame: u64,
    /// Distinct pages the analysed feedback asked for, ancestors included.
    pub requested: usize,
    /// Of those, pages resident or on their way.
    pub hits: usize,
    /// Pages uploaded and mapped (every layer of each).
    pub loaded: usize,
    /// Page-table entries written (a page mapped rewrites the entries it stands in for), the same
    /// whatever the layers.
    pub table_writes: usize,
    /// Pages evicted.
    pub evicted: usize,
    /// Wanted pages left for later frames (budget or cache full).
    pub deferred: usize,
    /// Pages on the loader's threads or waiting to be uploaded after the frame.
    pub in_flight: usize,
    /// Share of the analysed feedback's samples whose page was not mapped, so drawn from a
    /// coarser ancestor.
    pub fallback_fraction: f64,
    /// The LOD bias the next frame's feedback asks with.
    pub lod_bias: f32,
    /// Bytes read from the sources for the pages uploaded.
    pub bytes_read: u64,
    /// Tiles of the pages uploaded found in the memory tier (nothing read), and read from the
    /// sources.
    pub tier_hits: usize,
    /// Tiles of the pages uploaded read from the sources.
    pub tier_misses: usize,
    /// Pages that failed to load (drawn with a stand-in; see `loader`).
    pub load_errors: usize,
    /// CPU time of the frame on the render thread: recording and submitting its passes and
    /// `Runtime::end_frame`, not the wait for the picture's readback.
    pub cpu_ms: f64,
    /// Of that, time spent waiting for pages to be read (never, in real time).
    pub io_wait_ms: f64,
}

/// What a whole run did: the report `vortex-tiler render --report` writes.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Report {
    /// The GPU adapter's name and driver.
    pub adapter: String,
    /// Output width and height in pixels.
    pub size: [u32; 2],
    /// The sample filter's name.
    pub filter: String,
    /// Most probes per sample: 1 is isotropic.
    pub anisotropy: u32,
    /// `real-time` (frames never wait) or `offline` (each frame waits for its pages).
    pub pacing: String,
    /// Layer 0's cache: `rgba8`, `bc1` or `bc7`.
    pub cache_format: String,
    /// Slots of the page cache.
    pub cache_slots: usize,
    /// Most pages uploaded per frame.
    pub upload_budget: usize,
    /// Every frame's counters.
    pub frames: Vec<FrameReport>,
    /// Layers of every texture, and the one drawn.
    pub layers: usize,
    /// The layer drawn.
    pub layer: u32,
    /// Distinct pages ever loaded, against all pages of all textures.
    pub pages_touched: usize,
    /// Pages of all textures.
    pub pages_total: u64,
    /// Payload bytes read from the sources, the roots pinned before the first frame included.
    pub bytes_read: u64,
    /// The memory tier's budget in bytes (0: off).
    pub memory_tier_bytes: u64,
    /// Tiles found in the memory tier over the run, the roots included.
    pub tier_hits: u64,
    /// Tiles read from the sources over the run.
    pub tier_misses: u64,
    /// Bytes the tier held at the end: its cost in RAM (stored tiles and their bookkeeping).
    pub memory_tier_held: u64,
    /// Resident hits over pages requested, over all frames.
    pub hit_rate: f64,
    /// The first frame of the still camera.
    pub still_from: u32,
    /// Frames after `still_from` until the first frame without fallback that stays so to the
    /// end; `None` if the last frame still falls back.
    pub frames_to_converge: Option<u32>,
    /// Median and 99th percentile of the frames' `cpu_ms`.
    pub cpu_ms_p50: f64,
    /// 99th percentile of the frames' `cpu_ms`.
    pub cpu_ms_p99: f64,
    /// The largest `io_wait_ms` of any frame.
    pub io_wait_ms_max: f64,
    /// Messages of the pages that failed to load (at most 20).
    pub errors: Vec<String>,
}

/// A scene's runtime, pipelines, target and meshes, driven a frame at a time. It draws into its
/// own offscreen target, or into any colour view ([`SceneRenderer::draw_to`], e.g. a window's
/// surface).
pub struct SceneRenderer {
    gpu: Gpu,
    runtime: Runtime,
    module: wgpu::ShaderModule,
    /// The pipelines made so far, one pair per target format, filter and view (picture or
    /// residency): the filter and the view are pipeline constants, so that a pipeline holds only
    /// its own filter's code.
    pipelines: RefCell<Vec<(PipelineKey, Pipelines)>>,
    frame_layout: wgpu::BindGroupLayout,
    target: Target,
    readback: Readback,
    meshes: Vec<GpuMesh>,
    /// The depth buffer of other targets, for their size.
    other_depth: Option<((u32, u32), wgpu::TextureView)>,
    residency_view: bool,
    /// The layer drawn (the scene effect `layer`).
    layer: u32,
    /// Most probes per sample (`shader::anisotropy_constant`): 1 is isotropic.
    anisotropy: u32,
}

impl SceneRenderer {
    /// Sets up `scene` (its size, geometry and effects) over `sources` (texture id = index).
    pub fn new(
        gpu: Gpu,
        sources: Vec<Arc<dyn PageSource>>,
        scene: &Scene,
        pacing: Pacing,
    ) -> Result<SceneRenderer, RuntimeError> {
        SceneRenderer::with_layers(gpu, vec![Layer::colour(sources)], scene, pacing)
    }

    /// Sets up `scene` over layer stacks (`crate::layer`), drawing the layer its effect `layer`
    /// names.
    pub fn with_layers(
        gpu: Gpu,
        layers: Vec<Layer>,
        scene: &Scene,
        pacing: Pacing,
    ) -> Result<SceneRenderer, RuntimeError> {
        scene.check().map_err(RuntimeError::Config)?;
        scene.check_textures(layers.first().map_or(0, |l| l.sources.len())).map_err(RuntimeError::Config)?;
        if scene.effects.layer as usize >= layers.len() {
            return Err(RuntimeError::Config(format!(
                "effects.layer {} is not one of the {} layers",
                scene.effects.layer,
                layers.len()
            )));
        }
        let e = &scene.effects;
        let config = RuntimeConfig {
            cache_slots_per_side: e.cache_slots_per_side,
            filter: e.filter,
            load_budget: e.upload_budget,
            feedback_block: e.feedback_divisor,
            frame_size: scene.size,
            loader_threads: e.threads,
            bc7: e.bc7,
            cache_format: e.cache_format,
            memory_tier_bytes: u64::from(e.memory_tier_mib) << 20,
            pacing,
            ..RuntimeConfig::default()
        };
        let runtime = Runtime::with_layers(&gpu.device, &gpu.queue, layers, config)?;
        let device = &gpu.device;
        let module = draw::shader(device, "vortex harness", "");
        let frame_layout = draw::frame_only_layout(device, "vortex harness frame");
        let [w, h] = scene.size;
        let target = Target::new(device, "vortex target", TARGET_FORMAT, w, h);
        let readback = Readback::new(device, "target", w * 4, h);
        let mesh = scene.mesh();
        let meshes = if mesh.indices.is_empty() { vec![] } else { vec![GpuMesh::upload(device, &mesh)] };
        Ok(SceneRenderer {
            gpu,
            runtime,
            module,
            pipelines: RefCell::new(Vec::new()),
            frame_layout,
            target,
            readback,
            meshes,
            other_depth: None,
            residency_view: false,
            layer: scene.effects.layer,
            anisotropy: e.anisotropy,
        })
    }

    /// The pipelines drawing into `format` with the runtime's filter and the current view.
    fn pipelines(&self, format: wgpu::TextureFormat) -> Pipelines {
        let key = PipelineKey {
            format,
            filter: self.runtime.filter(),
            anisotropy: self.anisotropy,
            residency_view: self.residency_view,
            layer: self.layer,
        };
        let mut made = self.pipelines.borrow_mut();
        if let Some((_, p)) = made.iter().find(|(k, _)| *k == key) {
            return p.clone();
        }
        let constants = [
            shader::filter_constant(key.filter),
            shader::anisotropy_constant(key.anisotropy),
            ("RESIDENCY_VIEW", f64::from(u8::from(key.residency_view))),
            ("LAYER", f64::from(key.layer)),
        ];
        let layouts = [&self.frame_layout, self.runtime.bind_group_layout()];
        let p = Pipelines::new(&self.gpu.device, "vortex harness", &self.module, layouts, format, "", &constants);
        made.push((key, p.clone()));
        p
    }

    /// Records one draw at `pose` into `colour`, a `size` view of a `format` texture, with
    /// `depth`; `lod` fixes the LOD sampled everywhere.
    #[allow(clippy::too_many_arguments)]
    fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        pose: &Pose,
        lod: Option<f32>,
        colour: &wgpu::TextureView,
        format: wgpu::TextureFormat,
        depth: &wgpu::TextureView,
        size: (u32, u32),
    ) {
        let pipelines = self.pipelines(format);
        let view = match *pose {
            Pose::Window(w) => View::Window(w),
            Pose::Camera(view_proj) => View::Meshes { view_proj, meshes: &self.meshes },
        };
        let frame = Frame::new(self.runtime.textures(), &view, size, lod);
        let frame_group =
            draw::frame_only_bind_group(&self.gpu.device, "vortex harness frame", &self.frame_layout, &frame);
        let groups = [&frame_group, self.runtime.bind_group()];
        let draw = Some((&pipelines, groups, &view));
        draw::record(encoder, "vortex frame", colour, depth, wgpu::Color::TRANSPARENT, draw);
    }

    /// Records and submits one draw at `pose` into the offscreen target (`lod` fixes the LOD
    /// sampled everywhere), with the picture's copy if `image`.
    fn draw(&self, pose: &Pose, lod: Option<f32>, image: bool) {
        let mut encoder =
            self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex frame") });
        let t = &self.target;
        self.encode(&mut encoder, pose, lod, &t.view, TARGET_FORMAT, &t.depth, (t.width, t.height));
        if image {
            let (source, extent) = self.target.copy_source();
            self.readback.encode_copy(&mut encoder, source, extent);
        }
        self.gpu.queue.submit([encoder.finish()]);
    }

    /// Records and submits one draw at `pose` into `colour`, a `size` view of a `format` texture
    /// (a window's surface), without ending the frame: call [`SceneRenderer::end_frame`] after.
    pub fn draw_to(&mut self, pose: &Pose, colour: &wgpu::TextureView, format: wgpu::TextureFormat, size: (u32, u32)) {
        let device = &self.gpu.device;
        if self.other_depth.as_ref().is_none_or(|(s, _)| *s != size) {
            self.other_depth = Some((size, draw::depth_texture(device, size.0, size.1)));
        }
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex frame") });
        if let Some((_, depth)) = &self.other_depth {
            self.encode(&mut encoder, pose, None, colour, format, depth, size);
        }
        self.gpu.queue.submit([encoder.finish()]);
    }

    /// Ends a frame drawn by [`SceneRenderer::draw_to`] ([`Runtime::end_frame`]); `recorded` is
    /// the CPU time its recording took, added to the report's `cpu_ms`.
    pub fn end_frame(&mut self, recorded: Duration) -> Result<FrameReport, RuntimeError> {
        let stats = self.runtime.end_frame()?;
        Ok(report(&stats, recorded + stats.cpu))
    }

    /// Draws the residency view (a hue per LOD drawn, red where a coarser page stands in)
    /// instead of the picture.
    pub fn set_residency_view(&mut self, on: bool) {
        self.residency_view = on;
    }

    /// Whether pages are drawn tinted by their LOD ([`SceneRenderer::set_residency_view`]).
    pub fn residency_view(&self) -> bool {
        self.residency_view
    }

    /// Draws layer `layer` of the stacks from now on (clamped to the layers there are).
    pub fn set_layer(&mut self, layer: u32) {
        self.layer = layer.min(self.runtime.caches().len() as u32 - 1);
    }

    /// The layer drawn.
    pub fn layer(&self) -> u32 {
        self.layer
    }

    fn read_picture(&self) -> Result<Rgba8Image, ReadbackError> {
        let bytes = self.readback.read(&self.gpu.device)?;
        let texels = bytes.chunks_exact(4).map(|t| [t[0], t[1], t[2], t[3]]).collect();
        Ok(Rgba8Image { width: self.target.width, height: self.target.height, texels })
    }

    /// Draws one frame at `pose`, ends it (streaming what earlier feedback asked for), and
    /// returns its counters and, if `image`, the picture.
    pub fn frame(&mut self, pose: &Pose, image: bool) -> Result<(FrameReport, Option<Rgba8Image>), RuntimeError> {
        let started = Instant::now();
        self.draw(pose, None, image);
        let report = self.end_frame(started.elapsed())?;
        let frame = report.frame;
        let picture = if image {
            Some(self.read_picture().map_err(|source| RuntimeError::Readback { frame, source })?)
        } else {
            None
        };
        Ok((report, picture))
    }

    /// Draws `pose` at the fixed LOD `lod` (or the footprint's) and reads the picture back,
    /// without ending the frame: nothing streams. For tests that hold the picture against the
    /// reference sampler at the page table's current state.
    pub fn still(&self, pose: &Pose, lod: Option<f32>) -> Result<Rgba8Image, ReadbackError> {
        self.draw(pose, lod, true);
        self.read_picture()
    }

    /// Renders every frame of `scene`, handing each frame's counters (and picture, if `images`)
    /// to `each`, and sums them up.
    pub fn run<E: From<RuntimeError>>(
        &mut self,
        scene: &Scene,
        images: bool,
        mut each: impl FnMut(&FrameReport, Option<Rgba8Image>) -> Result<(), E>,
    ) -> Result<Report, E> {
        let mut frames = Vec::with_capacity(scene.frames as usize);
        for f in 0..scene.frames {
            let (report, picture) = self.frame(&scene.pose(f, self.runtime.textures()), images)?;
            each(&report, picture)?;
            frames.push(report);
        }
        Ok(self.report(scene, frames))
    }

    /// The run's summary over `frames`.
    pub fn report(&self, scene: &Scene, frames: Vec<FrameReport>) -> Report {
        let still_from = scene.still_from();
        let converged_at = frames.iter().rposition(|f| f.fallback_fraction > 0.0).map_or(0, |i| i + 1);
        let frames_to_converge =
            (converged_at < frames.len()).then(|| converged_at.saturating_sub(still_from as usize) as u32);
        let (hits, requested) = frames.iter().fold((0, 0), |(h, r), f| (h + f.hits, r + f.requested));
        let mut cpu: Vec<f64> = frames.iter().map(|f| f.cpu_ms).collect();
        cpu.sort_by(f64::total_cmp);
        let rt = &self.runtime;
        let config = rt.config();
        Report {
            adapter: self.gpu.adapter_info().name,
            size: scene.size,
            filter: rt.filter().name().into(),
            anisotropy: self.anisotropy,
            pacing: match config.pacing {
                Pacing::RealTime => "real-time".into(),
                Pacing::Offline => "offline".into(),
            },
            cache_format: rt.cache().format().name().into(),
            layers: rt.caches().len(),
            layer: self.layer,
            cache_slots: rt.residency().slots(),
            upload_budget: config.load_budget,
            pages_touched: rt.pages_touched(),
            pages_total: rt.textures().iter().map(|t| t.grid.page_count()).sum(),
            bytes_read: rt.loaders().iter().map(|l| l.counters().bytes_read).sum(),
            memory_tier_bytes: config.memory_tier_bytes,
            tier_hits: rt.loaders().iter().map(|l| l.counters().tier_hits).sum(),
            tier_misses: rt.loaders().iter().map(|l| l.counters().tier_misses).sum(),
            memory_tier_held: rt.loaders().iter().map(|l| l.memory_tier().bytes).sum(),
            hit_rate: if requested == 0 { 0.0 } else { hits as f64 / requested as f64 },
            still_from,
            frames_to_converge,
            cpu_ms_p50: percentile(&cpu, 0.5),
            cpu_ms_p99: percentile(&cpu, 0.99),
            io_wait_ms_max: frames.iter().map(|f| f.io_wait_ms).fold(0.0, f64::max),
            errors: rt.errors().iter().take(20).map(|e| e.to_string()).collect(),
            frames,
        }
    }

    /// The device it draws on.
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The runtime it draws with.
    pub fn runtime(&self) -> &Runtime {
        &self.runtime
    }

    /// The runtime, to change its settings between frames.
    pub fn runtime_mut(&mut self) -> &mut Runtime {
        &mut self.runtime
    }

    /// Most probes per sample (1: isotropic).
    pub fn anisotropy(&self) -> u32 {
        self.anisotropy
    }

    /// Changes the anisotropy from the next frame on (a pipeline per value, made once; clamped to
    /// 1..=16).
    pub fn set_anisotropy(&mut self, anisotropy: u32) {
        self.anisotropy = anisotropy.clamp(1, vortex_vt::anisotropy::MAX_ANISOTROPY);
    }
}

fn report(s: &FrameStats, cpu: Duration) -> FrameReport {
    FrameReport {
        frame: s.frame,
        requested: s.requested,
        hits: s.hits,
        loaded: s.uploaded,
        table_writes: s.table_writes,
        evicted: s.evicted,
        deferred: s.deferred,
        in_flight: s.in_flight,
        fallback_fraction: s.fallback_fraction,
        lod_bias: s.lod_bias,
        bytes_read: s.bytes_read,
        tier_hits: s.tier_hits,
        tier_misses: s.tier_misses,
        load_errors: s.load_errors,
        cpu_ms: cpu.as_secs_f64() * 1e3,
        io_wait_ms: s.io_wait.as_secs_f64() * 1e3,
    }
}

/// The `q` quantile of sorted `values` (nearest rank), 0 for none.
fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}
