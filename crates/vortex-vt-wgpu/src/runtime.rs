//! The frame loop of virtual texturing, on the render thread (the loader's workers decode pages
//! on theirs). Per frame:
//!
//! 1. draw the feedback pass (at the residency's LOD bias) and the sampling pass, and copy the
//!    feedback (and, if asked, the image) out;
//! 2. read this frame's feedback back and analyse it (`vortex_vt::analysis`): the pages wanted,
//!    most urgent first, and the share of samples drawn from a coarser fallback;
//! 3. update the residency (`vortex_vt::residency`): which pages to load into which slots,
//!    which to evict, within the upload budget, coarse before fine;
//! 4. have the loader read and decode the loads from the packs, upload them into the cache;
//! 5. apply the update to the page table and upload only the entries that changed.
//!
//! So a page the frame asks for is drawn from the next frame on. The headless loop waits for
//! each frame's feedback (a one-frame latency, and counters that are the same on every run); an
//! interactive loop would use `FeedbackReadback::try_read` and the loader's `request`/`poll`
//! instead and never wait.

use std::collections::HashSet;

use serde::Serialize;
use vortex_vt::analysis::Analyzer;
use vortex_vt::invariants::{self, Violation};
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt::page_table::PageTable;
use vortex_vt::residency::{ConfigError, FrameUpdate, Residency, ResidencyConfig};
use vortex_vt::sampler::Rgba8Image;

use crate::device::Gpu;
use crate::feedback::{FeedbackPass, FeedbackReadback, FeedbackTarget};
use crate::loader::{LoadError, Loader};
use crate::mesh::GpuMesh;
use crate::page_cache::{CacheError, CacheFormat, PageCache};
use crate::page_table::{GpuPageTable, PageTableError};
use crate::readback::ReadbackError;
use crate::sample::{RenderTarget, SamplePass, Sources};
use crate::scene::{Pose, Scene};
use crate::texture::VirtualTexture;
use crate::view::View;

/// Why a runtime cannot be made or a frame went wrong.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    #[error("physical page cache: {0}")]
    Cache(#[from] CacheError),
    #[error("residency: {0}")]
    Residency(#[from] ConfigError),
    #[error("page table: {0}")]
    PageTable(#[from] PageTableError),
    #[error("scene: {0}")]
    Scene(String),
    #[error("frame {frame}: the page-table invariants are broken: {violation}")]
    Invariant { frame: u64, violation: Violation },
    /// The picture or the feedback could not be read back (a lost device).
    #[error("frame {frame}: {source}")]
    Readback {
        frame: u64,
        #[source]
        source: ReadbackError,
    },
}

/// The counters of one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FrameReport {
    pub frame: u64,
    /// Distinct pages the feedback asked for, ancestors included.
    pub requested: usize,
    /// Of those, pages already resident.
    pub hits: usize,
    pub loaded: usize,
    pub evicted: usize,
    /// Wanted pages left for later frames (budget or cache full).
    pub deferred: usize,
    /// Share of feedback samples whose page was not resident, so drawn from a coarser ancestor.
    pub fallback_fraction: f64,
    /// The LOD bias this frame's feedback was drawn with.
    pub lod_bias: f32,
    /// Payload bytes read from the packs for this frame's loads.
    pub bytes_read: u64,
    /// Pages that failed to load (drawn with a stand-in; see `loader`).
    pub load_errors: usize,
}

/// What a whole run did: the report `vortex-tiler render --report` writes.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Report {
    pub adapter: String,
    pub size: [u32; 2],
    pub filter: String,
    /// `rgba8`, or `bc7` when the packs' BC7 blocks went to the GPU as they are.
    pub cache_format: String,
    pub cache_slots: usize,
    pub upload_budget: usize,
    pub frames: Vec<FrameReport>,
    /// Distinct pages ever loaded, against all pages of all textures.
    pub pages_touched: usize,
    pub pages_total: u64,
    /// Payload bytes read from the packs, the roots pinned before the first frame included.
    pub bytes_read: u64,
    /// Resident hits over pages requested, over all frames.
    pub hit_rate: f64,
    /// The first frame of the still camera.
    pub still_from: u32,
    /// Frames after `still_from` until the first frame without fallback that stays so to the
    /// end; `None` if the last frame still falls back.
    pub frames_to_converge: Option<u32>,
    /// Messages of the pages that failed to load (at most 20).
    pub errors: Vec<String>,
}

/// Everything one scene needs on the GPU and the CPU, driven a frame at a time.
pub struct Runtime {
    gpu: Gpu,
    loader: Loader,
    textures: Vec<VirtualTexture>,
    grids: Vec<TextureGrid>,
    residency: Residency,
    table: PageTable,
    gpu_table: GpuPageTable,
    cache: PageCache,
    sample: SamplePass,
    feedback: FeedbackPass,
    target: RenderTarget,
    feedback_target: FeedbackTarget,
    readback: FeedbackReadback,
    analyzer: Analyzer,
    meshes: Vec<GpuMesh>,
    frame: u64,
    touched: HashSet<PageId>,
    errors: Vec<LoadError>,
    last_update: FrameUpdate,
    /// Check the page-table invariants after every frame (tests; costs a table rebuild).
    pub check_invariants: bool,
}

impl Runtime {
    /// Sets up `scene` (its size, geometry and effects) over the loader's textures.
    pub fn new(gpu: Gpu, loader: Loader, scene: &Scene) -> Result<Runtime, RuntimeError> {
        scene.check().map_err(RuntimeError::Scene)?;
        let textures = loader.textures().to_vec();
        scene.check_textures(textures.len()).map_err(RuntimeError::Scene)?;
        let grids: Vec<TextureGrid> = textures.iter().map(|t| t.grid).collect();
        let e = &scene.effects;
        let side = e.cache_slots_per_side;
        // BC7 blocks go to the GPU as they are, where the adapter samples them and the scene
        // allows it; otherwise tiles are decoded to RGBA8.
        let bc = gpu.device.features().contains(wgpu::Features::TEXTURE_COMPRESSION_BC);
        let format = if e.bc7 && bc && loader.holds_only_bc7() { CacheFormat::Bc7 } else { CacheFormat::Rgba8 };
        loader.set_format(format);
        let cache = PageCache::new(&gpu.device, side, loader.tile_size(), loader.border(), format)?;
        let residency = Residency::new(&grids, ResidencyConfig::new(cache.slot_count() as usize, e.upload_budget))?;
        let gpu_table = GpuPageTable::new(&gpu.device, &gpu.queue, &grids, side)?;
        let [w, h] = scene.size;
        let feedback_target = FeedbackTarget::new(&gpu.device, w, h, e.feedback_divisor);
        let readback = FeedbackReadback::new(&gpu.device, feedback_target.width, feedback_target.height, 2);
        let mesh = scene.mesh();
        let meshes = if mesh.indices.is_empty() { vec![] } else { vec![GpuMesh::upload(&gpu.device, &mesh)] };
        let mut runtime = Runtime {
            sample: SamplePass::new(&gpu.device, e.filter),
            feedback: FeedbackPass::new(&gpu.device),
            target: RenderTarget::new(&gpu.device, w, h),
            table: PageTable::new(&grids),
            analyzer: Analyzer::new(),
            frame: 0,
            touched: HashSet::new(),
            errors: Vec::new(),
            last_update: FrameUpdate::default(),
            check_invariants: false,
            gpu,
            loader,
            textures,
            grids,
            residency,
            gpu_table,
            cache,
            feedback_target,
            readback,
            meshes,
        };
        // Pin every texture's root before the first draw, so that no frame shows an unmapped
        // entry.
        runtime.stream(0, &[])?;
        Ok(runtime)
    }

    /// Draws one frame at `pose`, streams what its feedback asks for, and returns its counters
    /// and, if `image`, the picture.
    pub fn frame(&mut self, pose: &Pose, image: bool) -> Result<(FrameReport, Option<Rgba8Image>), RuntimeError> {
        let view = match *pose {
            Pose::Window(w) => View::Window(w),
            Pose::Camera(view_proj) => View::Meshes { view_proj, meshes: &self.meshes },
        };
        let lod_bias = self.residency.lod_bias();
        let device = &self.gpu.device;
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex frame") });
        let jitter = crate::feedback::jitter(self.frame);
        self.feedback.encode(
            device,
            &mut encoder,
            &self.feedback_target,
            &self.textures,
            Some(&view),
            lod_bias,
            jitter,
        );
        self.readback.encode_copy(&mut encoder, &self.feedback_target);
        let sources = Sources { textures: &self.textures, table: &self.gpu_table, cache: &self.cache };
        self.sample.encode(device, &mut encoder, &self.target, &sources, &view, None);
        if image {
            self.target.encode_copy_out(&mut encoder);
        }
        self.gpu.queue.submit([encoder.finish()]);
        self.readback.submitted();
        let failed = |source| RuntimeError::Readback { frame: self.frame, source };
        let picture = if image { Some(self.target.read(&self.gpu).map_err(failed)?) } else { None };
        let words = self.readback.read_now(device).map_err(failed)?.map(|f| f.words).unwrap_or_default();

        let residency = &self.residency;
        let grids = &self.grids;
        let analysis = self.analyzer.analyze(&words, grids, |p| {
            let lod = residency.finest_resident_lod(p);
            residency.is_resident(PageId { lod, ..p }).map(|_| lod)
        });
        let fallback: u64 = analysis.requests.iter().filter(|r| r.distance > 0).map(|r| r.direct as u64).sum();
        let fallback_fraction = if analysis.samples == 0 { 0.0 } else { fallback as f64 / analysis.samples as f64 };
        let wanted: Vec<PageId> = analysis.requests.iter().map(|r| r.page).collect();

        let (update, bytes_read, load_errors) = self.stream(self.frame + 1, &wanted)?;
        let s = update.stats;
        let report = FrameReport {
            frame: self.frame,
            requested: s.requested,
            hits: s.hits,
            loaded: s.loaded,
            evicted: s.evicted,
            deferred: s.deferred,
            fallback_fraction,
            lod_bias,
            bytes_read,
            load_errors,
        };
        self.last_update = update;
        self.frame += 1;
        Ok((report, picture))
    }

    /// Updates the residency with `wanted`, loads and uploads the new pages, and maps them.
    /// Returns the update, the bytes read and the pages that failed to load.
    /// `stamp` is the residency's frame number: `new` pins the roots at 0, frame `n` is `n + 1`.
    fn stream(&mut self, stamp: u64, wanted: &[PageId]) -> Result<(FrameUpdate, u64, usize), RuntimeError> {
        let update = self.residency.update(stamp, wanted);
        let mut bytes_read = 0;
        let mut load_errors = 0;
        for page in self.loader.load(&update.loads) {
            self.cache.upload(&self.gpu.queue, page.slot, &page.texels);
            self.touched.insert(page.page);
            bytes_read += page.bytes_read;
            if let Some(e) = page.error {
                load_errors += 1;
                self.errors.push(e);
            }
        }
        let changes = self.table.apply(&update);
        self.gpu_table.write_changes(&self.gpu.queue, &changes);
        if self.check_invariants {
            invariants::check(&self.residency, &self.table)
                .map_err(|violation| RuntimeError::Invariant { frame: self.frame, violation })?;
        }
        Ok((update, bytes_read, load_errors))
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
            let (report, picture) = self.frame(&scene.pose(f, &self.textures), images)?;
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
        Report {
            adapter: self.gpu.adapter_info().name,
            size: scene.size,
            filter: self.sample.filter().name().into(),
            cache_format: self.cache.format().name().into(),
            cache_slots: self.residency.slots(),
            upload_budget: self.residency.config().upload_budget,
            pages_touched: self.touched.len(),
            pages_total: self.grids.iter().map(|g| g.page_count()).sum(),
            bytes_read: self.loader.counters().bytes_read,
            hit_rate: if requested == 0 { 0.0 } else { hits as f64 / requested as f64 },
            still_from,
            frames_to_converge,
            errors: self.errors.iter().take(20).map(|e| e.to_string()).collect(),
            frames,
        }
    }

    /// The residency update of the last frame (its loads, in upload order, and evictions).
    pub fn last_update(&self) -> &FrameUpdate {
        &self.last_update
    }

    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    pub fn loader(&self) -> &Loader {
        &self.loader
    }

    pub fn residency(&self) -> &Residency {
        &self.residency
    }

    pub fn page_table(&self) -> &PageTable {
        &self.table
    }

    pub fn cache(&self) -> &PageCache {
        &self.cache
    }

    pub fn textures(&self) -> &[VirtualTexture] {
        &self.textures
    }
}
