//! The runtime an application embeds: created on the application's `wgpu::Device` and `Queue`,
//! over up to 16 virtual textures (packs, or any [`PageSource`]). The application draws with
//! its own pipelines and shaders, which include the WGSL module (`crate::shader`) and bind
//! [`Runtime::bind_group`] at the group they chose; after submitting a frame it calls
//! [`Runtime::end_frame`], which never blocks:
//!
//! 1. the frame's feedback buffer is copied into a ring of readback buffers and reset;
//! 2. the oldest feedback the GPU has finished, if any (a frame or more old), is analysed
//!    (`vortex_vt::analysis`): the pages wanted, most urgent first;
//! 3. the residency (`vortex_vt::residency`) picks the pages to load and the slots they go to,
//!    evicting the least recently used; the loads are queued on the loader's threads, and the
//!    evicted pages are unmapped at once;
//! 4. the pages the loader has finished are uploaded into their slots, within the frame's budget
//!    of bytes and of time, coarse before fine (a page is mapped only once its parent is), and
//!    mapped: only the page-table entries that changed are written.
//!
//! Until a page lands, its entries point at its nearest mapped ancestor: the picture falls back to
//! coarser pages and sharpens as the loads land, and no frame waits for a disk.
//!
//! [`Pacing::Offline`] instead waits for each frame's feedback and loads (tests, offline
//! renders: the same pictures and counters on every run); the time it spends waiting for pages is
//! reported as [`FrameStats::io_wait`].

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use vortex_pack::Pack;
use vortex_vt::analysis::Analyzer;
use vortex_vt::invariants::{self, Violation};
use vortex_vt::page::{PageId, TextureGrid};
use vortex_vt::page_table::{Change, PageTable};
use vortex_vt::residency::{ConfigError, Residency, ResidencyConfig, Slot, UpdateError};

use crate::bindings::Bindings;
use crate::clock::Instant;
use crate::feedback::{FeedbackBuffer, FeedbackReadback};
use crate::landing::{Arrivals, Landed};
use crate::layer::{Layer, LayerKind, MAX_LAYERS};
use crate::loader::{DEFAULT_MEMORY_TIER_BYTES, LoadError, Loader, LoaderError};
use crate::page_cache::{CacheError, CacheFormat, PageCache};
use crate::page_table::{GpuPageTable, PageTableError};
use crate::params::Params;
use crate::readback::ReadbackError;
use crate::sample::SampleFilter;
use crate::source::PageSource;
use crate::texture::VirtualTexture;

/// Why a runtime cannot be made or a frame went wrong.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RuntimeError {
    /// The loader cannot be made (its sources).
    #[error("{0}")]
    Loader(#[from] LoaderError),
    /// The physical page cache cannot be made.
    #[error("physical page cache: {0}")]
    Cache(#[from] CacheError),
    /// The residency cannot be made (its configuration).
    #[error("residency: {0}")]
    Residency(#[from] ConfigError),
    /// The residency refused a frame's update.
    #[error("residency: {0}")]
    ResidencyUpdate(#[from] UpdateError),
    /// The page table cannot be made.
    #[error("page table: {0}")]
    PageTable(#[from] PageTableError),
    /// The configuration does not fit the textures (layers of other grids, say).
    #[error("{0}")]
    Config(String),
    /// The checked invariants broke (with `RuntimeConfig::check_invariants`).
    #[error("frame {frame}: the page-table invariants are broken: {violation}")]
    Invariant {
        /// The frame.
        frame: u64,
        /// The first broken rule.
        violation: Violation,
    },
    /// The page table maps other pages than those that landed.
    #[error("frame {frame}: the page table does not map exactly the pages that have landed")]
    Mapping {
        /// The frame.
        frame: u64,
    },
    /// The feedback could not be read back (a lost device).
    #[error("frame {frame}: {source}")]
    Readback {
        /// The frame.
        frame: u64,
        /// What failed.
        #[source]
        source: ReadbackError,
    },
}

/// Whether a frame may wait.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Pacing {
    /// Never wait: feedback is read back when the GPU has finished it, pages are uploaded when
    /// the loader has them. What an interactive application wants.
    #[default]
    RealTime,
    /// Wait for each frame's feedback and for the pages it asks for, so that a page asked for by
    /// frame n is drawn from frame n + 1 on, on every run: tests and offline renders.
    Offline,
}

/// The knobs of a [`Runtime`]. `RuntimeConfig::default()` suits a 1080p view of 128-texel
/// tiles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RuntimeConfig {
    /// The physical cache is this many slots per side (1..=256).
    pub cache_slots_per_side: u16,
    /// The filter; `None` takes the best the textures' border allows ([`SampleFilter::best_for`]).
    pub filter: Option<SampleFilter>,
    /// Most pages the residency sends to the loader per frame.
    pub load_budget: usize,
    /// Most bytes uploaded into the cache per frame (at least one tile).
    pub upload_bytes: u64,
    /// Uploads stop for the frame once they have taken this long (one page always goes).
    pub upload_time: Duration,
    /// Feedback blocks are this many pixels per side: one pixel in `block²` writes per frame.
    pub feedback_block: u32,
    /// The size of the frames drawn, for the feedback buffer ([`Runtime::resize`] changes it).
    pub frame_size: [u32; 2],
    /// Loader threads (0: one per core; sources that wait on I/O want more). In the browser,
    /// pages read at once on the page's event loop (0: six).
    pub loader_threads: usize,
    /// Hold BC7 blocks as stored when the device samples BC and every tile is BC7 or one colour
    /// (with `cache_format` automatic).
    pub bc7: bool,
    /// What the physical cache holds. `None` (the default) chooses BC wherever the device
    /// samples it: BC7 blocks as stored (see `bc7`), else BC1 for opaque textures (an eighth of
    /// RGBA8's GPU memory and upload bytes, 1.2x the loader's time per page) and BC7 for
    /// textures with alpha (a quarter, 17x RGBA8's loader time); RGBA8 on devices without BC.
    /// `Some(Rgba8)` keeps every texel exact (what tests comparing pictures want); `Some(Bc1)`
    /// (opaque textures only) or `Some(Bc7)` force a transcode on the loader's threads.
    pub cache_format: Option<CacheFormat>,
    /// How the frame's end paces loads: real time, or each frame waiting for its pages.
    pub pacing: Pacing,
    /// Bytes of stored (compressed) tiles the loader keeps in RAM, least recently used out first,
    /// so that a page the cache evicted and the view wants again is decoded without a read
    /// ([`Loader::set_memory_tier`]); 0 turns the tier off.
    pub memory_tier_bytes: u64,
}

impl Default for RuntimeConfig {
    fn default() -> RuntimeConfig {
        RuntimeConfig {
            cache_slots_per_side: 16,
            filter: None,
            load_budget: 32,
            upload_bytes: 8 << 20,
            upload_time: Duration::from_millis(2),
            feedback_block: 8,
            frame_size: [1920, 1080],
            loader_threads: 0,
            bc7: true,
            cache_format: None,
            pacing: Pacing::RealTime,
            memory_tier_bytes: DEFAULT_MEMORY_TIER_BYTES,
        }
    }
}

/// The physical cache's format for `config` on a device that samples BC (`bc`) or not.
fn cache_format(config: &RuntimeConfig, bc: bool, loader: &Loader) -> Result<CacheFormat, RuntimeError> {
    // In the browser no BC transcoder builds (Intel's kernels are native code): the cache holds
    // BC7 only as stored, else RGBA8.
    #[cfg(target_arch = "wasm32")]
    return Ok(match config.cache_format {
        None if bc && config.bc7 && loader.holds_only_bc7() => CacheFormat::Bc7,
        None | Some(CacheFormat::Rgba8) => CacheFormat::Rgba8,
        Some(CacheFormat::Bc7) if loader.holds_only_bc7() => CacheFormat::Bc7,
        Some(format) => {
            return Err(RuntimeError::Config(format!(
                "a {} cache needs a transcoder, and none builds for the web: use rgba8 (or a pack of BC7 tiles)",
                format.name()
            )));
        }
    });
    #[cfg(not(target_arch = "wasm32"))]
    Ok(match config.cache_format {
        None if !bc => CacheFormat::Rgba8,
        None if config.bc7 && loader.holds_only_bc7() => CacheFormat::Bc7,
        None if loader.opaque() => CacheFormat::Bc1,
        None => CacheFormat::Bc7,
        Some(CacheFormat::Bc1) if !loader.opaque() => {
            return Err(RuntimeError::Config(
                "a BC1 cache holds no alpha, and these textures have an alpha channel: use bc7".into(),
            ));
        }
        Some(format) => format,
    })
}

/// Every layer's texture `t` must have layer 0's grid, size, tile size and border.
fn same_grids(layers: &[Layer], loaders: &[Loader]) -> Result<(), RuntimeError> {
    let (first, first_loader) = (&layers[0], &loaders[0]);
    for (k, (layer, loader)) in layers.iter().zip(loaders).enumerate().skip(1) {
        if layer.sources.len() != first.sources.len() {
            return Err(RuntimeError::Config(format!(
                "layer {k} has {} textures and layer 0 has {}: every layer has one source per texture",
                layer.sources.len(),
                first.sources.len()
            )));
        }
        for (t, (a, b)) in first_loader.textures().iter().zip(loader.textures()).enumerate() {
            if a != b {
                return Err(RuntimeError::Config(format!(
                    "{}: {}x{} texels in {}-texel tiles with border {}, but {} (layer 0 of texture {t}) has {}x{} in {}-texel tiles with border {}; the layers of a texture share one page grid",
                    layer.sources[t].location().display(),
                    b.width,
                    b.height,
                    b.tile_size,
                    b.border,
                    first.sources[t].location().display(),
                    a.width,
                    a.height,
                    a.tile_size,
                    a.border,
                )));
            }
        }
    }
    Ok(())
}

/// What one [`Runtime::end_frame`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// The frame that ended (0 for the first).
    pub frame: u64,
    /// The frame whose feedback was analysed, if one was ready.
    pub feedback_of: Option<u64>,
    /// Distinct pages the feedback asked for, ancestors included.
    pub requested: usize,
    /// Of those, pages resident or on their way.
    pub hits: usize,
    /// Pages sent to the loader.
    pub queued: usize,
    /// Pages uploaded into the cache and mapped (every layer of each).
    pub uploaded: usize,
    /// Page-table entries written: mapping or unmapping a page rewrites the entries it stands in
    /// for (its own and its unmapped descendants'), once whatever the layers.
    pub table_writes: usize,
    /// Pages evicted this frame.
    pub evicted: usize,
    /// Wanted pages left for later frames (load budget, or a cache full of wanted pages).
    pub deferred: usize,
    /// Pages loaded but no longer wanted by the time they landed (their slot was taken).
    pub discarded: usize,
    /// Queued reads taken back because their page was evicted before a worker started it.
    pub cancelled: usize,
    /// Pages on the loader's threads or waiting for an upload, after this frame.
    pub in_flight: usize,
    /// Share of the last analysed feedback's samples whose page was not mapped when it was
    /// analysed, so drawn from a coarser ancestor.
    pub fallback_fraction: f64,
    /// The LOD bias the next frame's feedback asks with.
    pub lod_bias: f32,
    /// Bytes read by the sources for the pages uploaded, every layer's (none for tiles the
    /// memory tier held).
    pub bytes_read: u64,
    /// Tiles of the pages uploaded that the memory tier held (decoded from RAM, not read), and
    /// those read from the sources.
    pub tier_hits: usize,
    /// Tiles of the pages uploaded read from the sources, the memory tier not holding them.
    pub tier_misses: usize,
    /// Bytes written into the page caches.
    pub bytes_uploaded: u64,
    /// Pages uploaded with the stand-in tile because they failed to load.
    pub load_errors: usize,
    /// Time this call took on the calling thread.
    pub cpu: Duration,
    /// Of that, time spent waiting for pages to be read ([`Pacing::Offline`] only: a real-time
    /// frame never waits, and this is measured, not assumed).
    pub io_wait: Duration,
}

/// The virtual textures of one application, on its device.
pub struct Runtime {
    device: wgpu::Device,
    queue: wgpu::Queue,
    config: RuntimeConfig,
    /// One loader and one cache per layer; layer 0's cache fixes the slots' geometry.
    loaders: Vec<Loader>,
    caches: Vec<PageCache>,
    textures: Vec<VirtualTexture>,
    grids: Vec<TextureGrid>,
    residency: Residency,
    table: PageTable,
    gpu_table: GpuPageTable,
    filter: SampleFilter,
    bindings: Bindings,
    feedback: FeedbackBuffer,
    readback: FeedbackReadback,
    analyzer: Analyzer,
    /// The frame being drawn.
    frame: u64,
    /// Residency updates so far (their frame stamps must increase).
    updates: u64,
    /// Pages given a slot and sent to the loader, not yet uploaded.
    in_flight: HashMap<PageId, Slot>,
    /// Pages some of whose layers have landed.
    arrivals: Arrivals,
    /// Pages every layer of which has landed, waiting for the upload budget or their parent.
    landed: VecDeque<Landed>,
    touched: HashSet<PageId>,
    errors: Vec<LoadError>,
    /// The fallback share of the last feedback analysed.
    fallback: f64,
    /// Check the page-table invariants after every frame (tests; costs a table rebuild).
    pub check_invariants: bool,
}

impl Runtime {
    /// A runtime over packs: [`Runtime::with_sources`].
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        packs: Vec<Arc<Pack>>,
        config: RuntimeConfig,
    ) -> Result<Runtime, RuntimeError> {
        let sources = packs.into_iter().map(|p| p as Arc<dyn PageSource>).collect();
        Runtime::with_sources(device, queue, sources, config)
    }

    /// A runtime over `sources` (texture id = index), which must share a tile size and border.
    /// Loads every texture's coarsest page before returning (blocking, once), so that no frame
    /// ever shows an unmapped texture.
    pub fn with_sources(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        sources: Vec<Arc<dyn PageSource>>,
        config: RuntimeConfig,
    ) -> Result<Runtime, RuntimeError> {
        Runtime::with_layers(device, queue, vec![Layer::colour(sources)], config)
    }

    /// A runtime over layer stacks (`crate::layer`): texture `t` is every layer's source `t`,
    /// all on one page grid; one feedback, page table and residency serve every layer. Up to
    /// [`MAX_LAYERS`] layers, each with the same number of sources; a layer's cache holds the
    /// format that suits its kind (colour as `config.cache_format` says, data in RGBA8), and
    /// each layer has its own loader threads.
    pub fn with_layers(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        layers: Vec<Layer>,
        config: RuntimeConfig,
    ) -> Result<Runtime, RuntimeError> {
        if !(1..=MAX_LAYERS).contains(&layers.len()) {
            return Err(RuntimeError::Config(format!("{} layers: a runtime has 1 to {MAX_LAYERS}", layers.len())));
        }
        let bc = device.features().contains(wgpu::Features::TEXTURE_COMPRESSION_BC);
        let mut loaders = Vec::with_capacity(layers.len());
        for layer in &layers {
            let loader = Loader::with_sources(layer.sources.clone(), config.loader_threads)?;
            // The layers share the tier's budget equally.
            loader.set_memory_tier(config.memory_tier_bytes / layers.len() as u64);
            let format = match layer.kind {
                LayerKind::Colour => cache_format(&config, bc, &loader)?,
                LayerKind::Data => CacheFormat::Rgba8,
            };
            loader.set_kind(layer.kind);
            loader.set_format(format);
            loaders.push(loader);
        }
        same_grids(&layers, &loaders)?;
        let first = &loaders[0];
        let textures = first.textures().to_vec();
        let grids: Vec<TextureGrid> = textures.iter().map(|t| t.grid).collect();
        let tile_bytes: u64 = loaders.iter().map(|l| l.format().tile_bytes(l.tile_size()) as u64).sum();
        if config.upload_bytes < tile_bytes {
            return Err(RuntimeError::Config(format!(
                "an upload budget of {} bytes per frame is less than one {}-byte page",
                config.upload_bytes, tile_bytes
            )));
        }
        let side = config.cache_slots_per_side;
        let (tile_size, border) = (first.tile_size(), first.border());
        let caches = layers
            .iter()
            .zip(&loaders)
            .map(|(layer, l)| PageCache::for_layer(device, side, tile_size, border, l.format(), layer.kind))
            .collect::<Result<Vec<_>, _>>()?;
        let residency =
            Residency::new(&grids, ResidencyConfig::new(caches[0].slot_count() as usize, config.load_budget))?;
        let gpu_table = GpuPageTable::new(device, queue, &grids, side)?;
        let filter = config.filter.unwrap_or(SampleFilter::best_for(border));
        let [w, h] = config.frame_size;
        let feedback = FeedbackBuffer::new(device, w, h, config.feedback_block);
        let readback = FeedbackReadback::new(device, &feedback, 3);
        let bindings = Bindings::new(device, &gpu_table, &caches, &feedback, filter);
        let mut runtime = Runtime {
            device: device.clone(),
            queue: queue.clone(),
            config,
            table: PageTable::new(&grids),
            analyzer: Analyzer::new(),
            frame: 0,
            updates: 0,
            in_flight: HashMap::new(),
            arrivals: Arrivals::new(layers.len()),
            landed: VecDeque::new(),
            touched: HashSet::new(),
            errors: Vec::new(),
            fallback: 0.0,
            check_invariants: false,
            loaders,
            caches,
            textures,
            grids,
            residency,
            gpu_table,
            filter,
            bindings,
            feedback,
            readback,
        };
        // The roots: loaded and mapped before the first frame.
        let update = runtime.residency.update(0, &[])?;
        let pages = runtime.load_now(&update.loads);
        let mut changes = Vec::new();
        for page in pages {
            runtime.upload(page, &mut changes);
        }
        runtime.gpu_table.write_changes(&runtime.queue, &changes);
        runtime.feedback.clear(&runtime.queue);
        runtime.write_params();
        Ok(runtime)
    }

    /// Loads every layer of `pages`, waiting for them: the layers' loaders work at once (each
    /// answers every page, with a stand-in where one fails).
    fn load_now(&self, pages: &[(PageId, Slot)]) -> Vec<Landed> {
        // Layer 0 on this thread, the others on threads of their own meanwhile.
        let Some((first, rest)) = self.loaders.split_first().filter(|_| !pages.is_empty()) else {
            return Vec::new();
        };
        // In the browser there are no threads to wait on: the layers load one after another.
        #[cfg(target_arch = "wasm32")]
        let answers: Vec<_> = std::iter::once(first).chain(rest).map(|l| l.load(pages)).collect();
        #[cfg(not(target_arch = "wasm32"))]
        let answers: Vec<_> = std::thread::scope(|scope| {
            let loads: Vec<_> = rest.iter().map(|l| scope.spawn(move || l.load(pages))).collect();
            let joined = loads.into_iter().map(|h| h.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)));
            std::iter::once(first.load(pages)).chain(joined).collect()
        });
        let mut layers: Vec<_> = answers.into_iter().map(Vec::into_iter).collect();
        pages
            .iter()
            .map(|&(page, slot)| Landed { page, slot, layers: layers.iter_mut().filter_map(Iterator::next).collect() })
            .collect()
    }

    /// The layout of the module's bind group, for the application's pipeline layouts (at the
    /// group index it gave `crate::shader`).
    pub fn bind_group_layout(&self) -> &wgpu::BindGroupLayout {
        self.bindings.layout()
    }

    /// The module's bind group. It changes on [`Runtime::resize`] and [`Runtime::set_filter`]:
    /// take it anew for each frame's passes.
    pub fn bind_group(&self) -> &wgpu::BindGroup {
        self.bindings.group()
    }

    /// Frames are now `width x height` pixels: the feedback buffer follows (feedback in flight
    /// for the old size is dropped).
    pub fn resize(&mut self, width: u32, height: u32) {
        self.config.frame_size = [width, height];
        self.feedback = FeedbackBuffer::new(&self.device, width, height, self.config.feedback_block);
        self.readback = FeedbackReadback::new(&self.device, &self.feedback, 3);
        self.feedback.clear(&self.queue);
        self.rebind();
    }

    /// How the cache is filtered.
    pub fn filter(&self) -> SampleFilter {
        self.filter
    }

    /// Filters the cache as `filter` says from the next frame on.
    pub fn set_filter(&mut self, filter: SampleFilter) {
        self.filter = filter;
        self.rebind();
    }

    fn rebind(&mut self) {
        self.bindings.rebind(&self.device, &self.gpu_table, &self.caches, &self.feedback, self.filter);
        self.write_params();
    }

    /// Writes the uniform block the next frame reads.
    fn write_params(&self) {
        let layout = self.feedback.layout(self.frame);
        let params = Params::new(
            &self.textures,
            &self.caches[0],
            self.filter,
            layout,
            self.residency.lod_bias(),
            self.loaders.iter().enumerate().map(|(k, l)| u32::from(l.straight_alpha()) << k).sum(),
            self.loaders.len() as u32,
        );
        self.queue.write_buffer(self.bindings.params(), 0, bytemuck::bytes_of(&params));
    }

    /// Ends the frame whose commands the application has just submitted: reads back earlier
    /// feedback, streams, uploads and maps (see the module documentation). Never blocks under
    /// [`Pacing::RealTime`].
    pub fn end_frame(&mut self) -> Result<FrameStats, RuntimeError> {
        let started = Instant::now();
        let waited = |loaders: &[Loader]| loaders.iter().map(Loader::waited).sum::<Duration>();
        let waited_before = waited(&self.loaders);
        let offline = self.config.pacing == Pacing::Offline;
        let mut stats = FrameStats { frame: self.frame, ..FrameStats::default() };

        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex feedback copy") });
        self.readback.encode_copy(&mut encoder, &self.feedback);
        self.queue.submit([encoder.finish()]);
        self.readback.submitted();
        self.feedback.clear(&self.queue);

        let failed = |source| RuntimeError::Readback { frame: self.frame, source };
        let read = if offline { self.readback.read_now(&self.device) } else { self.readback.try_read(&self.device) };
        let mut changes = Vec::new();
        if let Some(feedback) = read.map_err(failed)? {
            stats.feedback_of = Some(feedback.frame);
            let loads = self.stream(&feedback.words, &mut stats, &mut changes)?;
            if offline {
                let pages = self.load_now(&loads);
                self.landed.extend(pages);
            } else {
                self.loaders.iter().for_each(|l| l.request(&loads));
            }
        }
        self.collect_landed(&mut stats);
        self.upload_landed(offline, &mut stats, &mut changes);
        stats.table_writes = changes.len();
        self.gpu_table.write_changes(&self.queue, &changes);
        if self.check_invariants {
            self.check()?;
        }

        self.frame += 1;
        self.write_params();
        stats.fallback_fraction = self.fallback;
        stats.in_flight = self.in_flight.len();
        stats.lod_bias = self.residency.lod_bias();
        stats.io_wait = waited(&self.loaders) - waited_before;
        stats.cpu = started.elapsed();
        Ok(stats)
    }

    /// Analyses one feedback buffer, updates the residency and unmaps its evictions; returns the
    /// pages to load, coarse before fine, with their slots.
    fn stream(
        &mut self,
        words: &[u32],
        stats: &mut FrameStats,
        changes: &mut Vec<Change>,
    ) -> Result<Vec<(PageId, Slot)>, RuntimeError> {
        let table = &self.table;
        let analysis = self.analyzer.analyze(words, &self.grids, |p| {
            let entry = table.get(p);
            entry.is_mapped().then_some(entry.lod)
        });
        let fallback: u64 = analysis.requests.iter().filter(|r| r.distance > 0).map(|r| r.direct as u64).sum();
        self.fallback = if analysis.samples == 0 { 0.0 } else { fallback as f64 / analysis.samples as f64 };
        let wanted: Vec<PageId> = analysis.requests.iter().map(|r| r.page).collect();
        self.updates += 1;
        let update = self.residency.update(self.updates, &wanted)?;
        // A page evicted before it landed was never mapped: nothing to unmap, and its read is
        // taken back if no worker has started it (with slow reads, a moving camera would
        // otherwise queue pages it has already left behind).
        let (stale, unmap): (Vec<_>, Vec<_>) =
            update.evictions.iter().copied().partition(|(page, _)| self.in_flight.remove(page).is_some());
        stats.cancelled = self.loaders.iter().map(|l| l.cancel(&stale)).sum();
        for &(page, slot) in &stale {
            self.arrivals.forget(page, slot);
        }
        changes.extend(self.table.apply_mappings(&unmap, &[]));
        self.in_flight.extend(update.loads.iter().copied());
        let s = update.stats;
        (stats.requested, stats.hits, stats.queued) = (s.requested, s.hits, update.loads.len());
        (stats.evicted, stats.deferred) = (s.evicted, s.deferred);
        Ok(update.loads)
    }

    /// Joins the layers the loaders have finished into pages; a layer of a page no longer in
    /// flight for its slot is discarded at once.
    fn collect_landed(&mut self, stats: &mut FrameStats) {
        for (layer, loader) in self.loaders.iter().enumerate() {
            for page in loader.poll() {
                if self.in_flight.get(&page.page) != Some(&page.slot) {
                    stats.discarded += usize::from(layer == 0);
                    continue;
                }
                self.landed.extend(self.arrivals.add(layer, page));
            }
        }
    }

    /// Uploads and maps the landed pages that are still wanted, parents first, within the
    /// frame's budget (none offline); the rest wait for a later frame.
    fn upload_landed(&mut self, offline: bool, stats: &mut FrameStats, changes: &mut Vec<Change>) {
        let started = Instant::now();
        // Coarse before fine, so that a parent landed in the same batch is mapped first.
        self.landed.make_contiguous().sort_by_key(|page| std::cmp::Reverse(page.page.lod));
        let mut waiting = VecDeque::new();
        while let Some(page) = self.landed.pop_front() {
            let (p, slot) = (page.page, page.slot);
            if self.in_flight.get(&p) != Some(&slot) || self.residency.slot_owner(slot) != Some(p) {
                stats.discarded += 1;
                continue;
            }
            let parent_mapped =
                p.parent(&self.grids[p.texture as usize]).is_none_or(|q| self.table.get(q).lod == q.lod);
            let bytes = page.bytes();
            let over_budget = !offline
                && stats.uploaded > 0
                && (stats.bytes_uploaded + bytes > self.config.upload_bytes
                    || started.elapsed() >= self.config.upload_time);
            if !parent_mapped || over_budget {
                waiting.push_back(page);
                continue;
            }
            stats.uploaded += 1;
            stats.bytes_uploaded += bytes;
            stats.bytes_read += page.layers.iter().map(|l| l.bytes_read).sum::<u64>();
            stats.tier_hits += page.layers.iter().map(|l| l.tier_hits as usize).sum::<usize>();
            stats.tier_misses += page.layers.iter().map(|l| l.tier_misses as usize).sum::<usize>();
            stats.load_errors += page.layers.iter().filter(|l| !l.is_ok()).count();
            self.upload(page, changes);
        }
        self.landed = waiting;
    }

    /// Writes every layer of one page into its slot and maps it, once.
    fn upload(&mut self, page: Landed, changes: &mut Vec<Change>) {
        for (cache, layer) in self.caches.iter().zip(&page.layers) {
            cache.upload(&self.queue, page.slot, &layer.texels);
        }
        self.in_flight.remove(&page.page);
        self.arrivals.forget(page.page, page.slot);
        self.touched.insert(page.page);
        changes.extend(self.table.apply_mappings(&[], &[(page.page, page.slot)]));
        self.errors.extend(page.layers.into_iter().filter_map(|l| l.error));
    }

    /// The residency's invariants, and the table mapping exactly the pages that have landed.
    fn check(&self) -> Result<(), RuntimeError> {
        let frame = self.frame;
        invariants::check(&self.residency, &PageTable::rebuild(&self.grids, self.residency.resident()))
            .map_err(|violation| RuntimeError::Invariant { frame, violation })?;
        let landed = self.residency.resident().filter(|(p, _)| !self.in_flight.contains_key(p));
        if PageTable::rebuild(&self.grids, landed) != self.table {
            return Err(RuntimeError::Mapping { frame });
        }
        Ok(())
    }

    /// The frame being drawn (the number of frames ended so far).
    pub fn frame(&self) -> u64 {
        self.frame
    }

    /// The textures, by texture id.
    pub fn textures(&self) -> &[VirtualTexture] {
        &self.textures
    }

    /// Layer 0's loader.
    pub fn loader(&self) -> &Loader {
        &self.loaders[0]
    }

    /// Every layer's loader, layer 0 first.
    pub fn loaders(&self) -> &[Loader] {
        &self.loaders
    }

    /// What is resident, and why.
    pub fn residency(&self) -> &Residency {
        &self.residency
    }

    /// The CPU side of the page table.
    pub fn page_table(&self) -> &PageTable {
        &self.table
    }

    /// Layer 0's cache.
    pub fn cache(&self) -> &PageCache {
        &self.caches[0]
    }

    /// Every layer's cache, layer 0 first: the same slots, each in its layer's format.
    pub fn caches(&self) -> &[PageCache] {
        &self.caches
    }

    /// What it was made with.
    pub fn config(&self) -> &RuntimeConfig {
        &self.config
    }

    /// Distinct pages ever uploaded.
    pub fn pages_touched(&self) -> usize {
        self.touched.len()
    }

    /// The pages that failed to load (drawn with the stand-in tile), in order.
    pub fn errors(&self) -> &[LoadError] {
        &self.errors
    }

    /// Pages in flight: on the loader's threads, or landed and waiting to be uploaded.
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }
}
