//! The viewer: device, pack, renderer and view, with the methods the page's script calls.

use std::sync::{Arc, Mutex, PoisonError};

use vortex_vt_wgpu::harness::camera::Keyframe;
use vortex_vt_wgpu::harness::{Effects, FrameReport, Pose, Scene, SceneRenderer, SceneView, Window, WindowKey};
use vortex_vt_wgpu::source::{TileId, TileKind, WebPack};
use vortex_vt_wgpu::{CacheFormat, Gpu, Pacing, PageSource, SampleFilter, StoredRead, StoredTile};
use wasm_bindgen::prelude::*;

/// The most a view zooms in: this many pixels per LOD-0 texel (as `view`).
const MOST_PIXELS_PER_TEXEL: f64 = 64.0;

/// Frames whose feedback was read back, in a row, that asked for nothing new, with nothing in
/// flight or uploaded, before the view counts as converged: the feedback of a frame is read a
/// frame or more later, so one quiet frame may only mean the pages it drew were asked for before.
const QUIET_FRAMES: u32 = 4;

/// A pack drawn into a canvas.
#[wasm_bindgen]
pub struct Viewer {
    renderer: SceneRenderer,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    /// The format drawn in: the canvas's, as sRGB (canvases take no sRGB format of their own).
    view_format: wgpu::TextureFormat,
    pack: Arc<WebPack>,
    image: [u32; 2],
    /// The image UV at the canvas's centre and the share of the image's width shown.
    center: [f64; 2],
    width: f64,
    last: FrameReport,
    gpu_errors: Arc<Mutex<Vec<String>>>,
    quiet: u32,
    frames: u64,
}

#[wasm_bindgen]
impl Viewer {
    /// Opens the pack at `url` into `canvas` at the home view. `hold`: tile reads are held back
    /// until [`Viewer::release`] (the page's `?hold`, for tests of a frame with pages in flight).
    pub async fn open(canvas: web_sys::HtmlCanvasElement, url: String, hold: bool) -> Result<Viewer, JsError> {
        let (w, h) = (canvas.width().max(1), canvas.height().max(1));
        let descriptor = wgpu::InstanceDescriptor {
            backends: wgpu::Backends::BROWSER_WEBGPU,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        };
        let instance = wgpu::Instance::new(descriptor);
        let surface = instance.create_surface(wgpu::SurfaceTarget::Canvas(canvas)).map_err(error)?;
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                compatible_surface: Some(&surface),
                ..Default::default()
            })
            .await
            .map_err(|e| JsError::new(&format!("no WebGPU adapter ({e}): does this browser have WebGPU on?")))?;
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("vortex"),
                required_limits: wgpu::Limits::default().using_resolution(adapter.limits()),
                required_features: adapter.features() & wgpu::Features::TEXTURE_COMPRESSION_BC,
                ..Default::default()
            })
            .await
            .map_err(error)?;
        // WebGPU reports validation errors asynchronously, not as panics: kept for the counters.
        let gpu_errors: Arc<Mutex<Vec<String>>> = Arc::default();
        let kept = Arc::clone(&gpu_errors);
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut errors = kept.lock().unwrap_or_else(PoisonError::into_inner);
            if errors.len() < 8 {
                errors.push(e.to_string());
            }
        }));
        let gpu = Gpu { instance, adapter, device, queue };

        let pack = Arc::new(WebPack::open(&url).await.map_err(error)?);
        if hold {
            pack.hold();
        }
        let texture = pack.texture().map_err(error)?;
        let image = texture.size();

        let caps = surface.get_capabilities(&gpu.adapter);
        let format = caps.formats.first().copied().ok_or_else(|| JsError::new("the canvas offers no format"))?;
        let view_format = format.add_srgb_suffix();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: w,
            height: h,
            present_mode: wgpu::PresentMode::Fifo,
            desired_maximum_frame_latency: 2,
            // Black where nothing is drawn, as `view`'s window.
            alpha_mode: wgpu::CompositeAlphaMode::Opaque,
            view_formats: vec![view_format],
            color_space: Default::default(),
        };
        surface.configure(&gpu.device, &config);

        let (center, width) = home(image, (w, h));
        let scene = Scene {
            textures: vec![],
            layers: vec![],
            size: [w, h],
            frames: 1,
            view: SceneView::Window { texture: 0, path: vec![Keyframe { frame: 0, at: WindowKey { center, width } }] },
            // RGBA8: no BC transcoder builds for the web (a pack of BC7 tiles would still be
            // taken as stored, but the page draws what it is given exactly).
            effects: Effects::exact(),
        };
        let source: Arc<dyn PageSource> = pack.clone();
        let renderer = SceneRenderer::new(gpu, vec![source], &scene, Pacing::RealTime).map_err(error)?;
        Ok(Viewer {
            renderer,
            surface,
            config,
            view_format,
            pack,
            image,
            center,
            width,
            last: FrameReport::default(),
            gpu_errors,
            quiet: 0,
            frames: 0,
        })
    }

    /// Draws one frame and ends it (streams, uploads, maps): never waits.
    pub fn frame(&mut self) -> Result<(), JsError> {
        let started = web_time::Instant::now();
        let texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            // Skipped: the page asks again next frame.
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(()),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.renderer.gpu().device, &self.config);
                return Ok(());
            }
            other => return Err(JsError::new(&format!("the canvas gave no texture to draw in: {other:?}"))),
        };
        let view = texture
            .texture
            .create_view(&wgpu::TextureViewDescriptor { format: Some(self.view_format), ..Default::default() });
        let size = (self.config.width, self.config.height);
        let pose = self.pose();
        self.renderer.draw_to(&pose, &view, self.view_format, size);
        self.renderer.gpu().queue.present(texture);
        let report = self.renderer.end_frame(started.elapsed()).map_err(error)?;
        let busy = report.in_flight > 0 || report.loaded > 0 || report.requested > report.hits || report.deferred > 0;
        // A frame that read back no feedback (requested nothing) says nothing either way.
        if busy {
            self.quiet = 0;
        } else if report.requested > 0 {
            self.quiet += 1;
        }
        self.last = report;
        self.frames += 1;
        Ok(())
    }

    /// Whether the last few frames asked for nothing new and have nothing in flight.
    pub fn converged(&self) -> bool {
        self.quiet >= QUIET_FRAMES
    }

    /// Moves the image by (`dx`, `dy`) canvas pixels (dragging it).
    pub fn pan(&mut self, dx: f64, dy: f64) {
        let w = self.window();
        let size = self.size();
        self.center[0] = (self.center[0] - dx * w.extent[0] / size.0).clamp(0.0, 1.0);
        self.center[1] = (self.center[1] - dy * w.extent[1] / size.1).clamp(0.0, 1.0);
    }

    /// Zooms by `factor` (above 1: closer) keeping the image point under canvas pixel (`x`, `y`)
    /// in place, from twice the image's width across to 64 pixels per texel.
    pub fn zoom(&mut self, factor: f64, x: f64, y: f64) {
        let before = self.window();
        let size = self.size();
        let anchor =
            [before.origin[0] + x / size.0 * before.extent[0], before.origin[1] + y / size.1 * before.extent[1]];
        let least = size.0 / MOST_PIXELS_PER_TEXEL / f64::from(self.image[0].max(1));
        let width = (self.width / factor).clamp(least, 2.0);
        let scale = width / self.width;
        self.width = width;
        self.center = [0, 1].map(|i| anchor[i] + (self.center[i] - anchor[i]) * scale);
    }

    /// The canvas is now `width x height` device pixels: the surface and the feedback follow
    /// (the view keeps its centre and the share of the image's width it shows).
    pub fn resize(&mut self, width: u32, height: u32) {
        let (width, height) = (width.max(1), height.max(1));
        if (width, height) == (self.config.width, self.config.height) {
            return;
        }
        (self.config.width, self.config.height) = (width, height);
        self.surface.configure(&self.renderer.gpu().device, &self.config);
        self.renderer.runtime_mut().resize(width, height);
    }

    /// Back to the whole image, fit and centred.
    pub fn home(&mut self) {
        (self.center, self.width) = home(self.image, (self.config.width, self.config.height));
    }

    /// `nearest`, `bilinear`, `trilinear` (or any filter `render` names).
    pub fn set_filter(&mut self, name: &str) -> Result<(), JsError> {
        let filter = SampleFilter::from_name(name).ok_or_else(|| JsError::new(&format!("no filter {name:?}")))?;
        self.renderer.runtime_mut().set_filter(filter);
        Ok(())
    }

    pub fn filter(&self) -> String {
        self.renderer.runtime().filter().name().to_string()
    }

    /// Most probes per sample: 1 is isotropic.
    pub fn set_anisotropy(&mut self, probes: u32) {
        self.renderer.set_anisotropy(probes);
    }

    pub fn anisotropy(&self) -> u32 {
        self.renderer.anisotropy()
    }

    /// The residency view: a hue per LOD drawn, red where a coarser page stands in.
    pub fn set_residency_view(&mut self, on: bool) {
        self.renderer.set_residency_view(on);
    }

    /// Lets held tile reads go (see [`Viewer::open`]).
    pub fn release(&self) {
        self.pack.release();
    }

    /// The pack's root tile as stored (its payload) and its kind: what the measurement of the
    /// page's decoders decodes.
    pub fn root_payload(&self) -> Result<Vec<u8>, JsError> {
        let (root, kind, bytes) = self.root()?;
        // The texels must decode, or the measurement would time an error.
        self.pack.decode(root, kind, &bytes, CacheFormat::Rgba8).map_err(error)?;
        Ok(bytes.to_vec())
    }

    /// Decodes the root tile `rounds` times with the runtime's decoder (Rust, in wasm); the
    /// milliseconds per decode, on the page's clock (a measurement, docs/benchmarks.md).
    pub fn decode_ms(&self, rounds: u32) -> Result<f64, JsError> {
        let (root, kind, bytes) = self.root()?;
        let started = web_time::Instant::now();
        for _ in 0..rounds.max(1) {
            self.pack.decode(root, kind, &bytes, CacheFormat::Rgba8).map_err(error)?;
        }
        Ok(started.elapsed().as_secs_f64() * 1000.0 / f64::from(rounds.max(1)))
    }

    /// The view as JSON (`center`, `width`), to hand to `render` as a window key.
    pub fn view(&self) -> String {
        serde_json::json!({ "center": self.center, "width": self.width }).to_string()
    }

    /// The last frame's counters, the pack's fetch counters and the runtime's totals, as JSON.
    pub fn counters(&self) -> String {
        let stats = self.pack.stats();
        let runtime = self.renderer.runtime();
        let loader = runtime.loader().counters();
        serde_json::json!({
            "frames": self.frames,
            "converged": self.converged(),
            "last": self.last,
            "resident": runtime.residency().resident().count(),
            "in_flight": runtime.in_flight(),
            "pages_touched": runtime.pages_touched(),
            "load_errors": runtime.errors().len(),
            "pages_decoded": loader.tiles_decoded,
            "requests": stats.requests,
            "bytes_fetched": stats.bytes,
            "retries": stats.retries,
            "corrupt": stats.corrupt,
            "filter": self.filter(),
            "anisotropy": self.anisotropy(),
            "gpu_errors": *self.gpu_errors.lock().unwrap_or_else(PoisonError::into_inner),
        })
        .to_string()
    }
}

impl Viewer {
    fn size(&self) -> (f64, f64) {
        (f64::from(self.config.width), f64::from(self.config.height))
    }

    fn window(&self) -> Window {
        Window::square_pixels(0, self.image, self.center, self.width, (self.config.width, self.config.height))
    }

    /// The root tile, its kind and its stored bytes (fetched at open).
    fn root(&self) -> Result<(TileId, TileKind, Arc<[u8]>), JsError> {
        let lod = self.renderer.runtime().textures()[0].grid.lod_count().saturating_sub(1);
        let root = TileId { lod: lod.into(), x: 0, y: 0 };
        match self.pack.read_stored(root).map_err(error)? {
            Some(StoredRead { tile: StoredTile::Stored { kind, bytes }, .. }) => Ok((root, kind, bytes)),
            _ => Err(JsError::new("the root tile is not stored as a payload")),
        }
    }

    fn pose(&self) -> Pose {
        Pose::Window(self.window())
    }
}

/// The home view of an `image` in a `size` canvas: the whole image, fit and centred (a width of
/// at least 1, more when the image is taller than the canvas).
fn home(image: [u32; 2], size: (u32, u32)) -> ([f64; 2], f64) {
    let image_aspect = f64::from(image[0]) / f64::from(image[1].max(1));
    let canvas_aspect = f64::from(size.0) / f64::from(size.1.max(1));
    ([0.5, 0.5], (canvas_aspect / image_aspect).max(1.0))
}

fn error(e: impl std::fmt::Display) -> JsError {
    JsError::new(&e.to_string())
}
