//! The window: winit's event loop, the wgpu surface, and one frame per redraw through the scene
//! renderer. Input goes to `controls`; the title shows the residency, the filter and the frame
//! rate.

use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow};
use vortex_vt_wgpu::harness::{FrameReport, Pose, Scene, SceneRenderer};
use vortex_vt_wgpu::source::HttpPack;
use vortex_vt_wgpu::{Gpu, Pacing, SampleFilter};
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, KeyEvent, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{Key, KeyCode, NamedKey, PhysicalKey};
use winit::window::{Window, WindowId};

use super::Start;
use super::screenshot;
use crate::cli::render::{open_layers, refuse_load_errors, remote_stats, warn_of_seams};
use vortex_tiler::error::ShowPath;

pub(super) struct Options {
    pub scene: Scene,
    pub start: Start,
    pub io_latency: Option<Duration>,
    pub http_deadline: Option<Duration>,
    pub residency_view: bool,
    /// Where to save the last of how many frames.
    pub screenshot: Option<(PathBuf, u32)>,
}

pub(super) fn run(options: Options) -> Result<()> {
    let event_loop = EventLoop::new().context("opening the display (is DISPLAY or WAYLAND_DISPLAY set?)")?;
    let mut app = App { options, state: None, error: None };
    event_loop.run_app(&mut app).context("running the window's event loop")?;
    match (app.error, &app.state) {
        (Some(e), _) => Err(e),
        // Pages drawn as the stand-in fail the run, as they fail `render`.
        (None, Some(state)) => refuse_load_errors(state.renderer.runtime()),
        (None, None) => Ok(()),
    }
}

struct App {
    options: Options,
    state: Option<State>,
    error: Option<anyhow::Error>,
}

/// The window and everything drawn into it.
struct State {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    renderer: SceneRenderer,
    view: Start,
    /// Each texture's image size, for the 2D view.
    images: Vec<[u32; 2]>,
    cursor: [f64; 2],
    dragging: bool,
    held: HashSet<KeyCode>,
    frames: u32,
    last_frame: Instant,
    title_at: Instant,
    frames_since_title: u32,
    last: FrameReport,
    /// The packs read over HTTP, whose requests the title counts.
    remote: Vec<Arc<HttpPack>>,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.state.is_none() {
            match State::new(event_loop, &self.options) {
                Ok(state) => self.state = Some(state),
                Err(e) => {
                    self.error = Some(e);
                    event_loop.exit();
                }
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        let Some(state) = self.state.as_mut() else { return };
        let result = match event {
            WindowEvent::CloseRequested => {
                event_loop.exit();
                Ok(())
            }
            WindowEvent::Resized(size) => {
                state.resize(size);
                Ok(())
            }
            WindowEvent::RedrawRequested => state.redraw(self.options.screenshot.as_ref()).map(|done| {
                if done {
                    event_loop.exit();
                }
            }),
            WindowEvent::KeyboardInput { event, .. } => {
                if state.key(&event, &self.options) {
                    event_loop.exit();
                }
                Ok(())
            }
            WindowEvent::CursorMoved { position, .. } => {
                state.moved(position);
                Ok(())
            }
            WindowEvent::MouseInput { state: pressed, button: MouseButton::Left, .. } => {
                state.dragging = pressed == ElementState::Pressed;
                Ok(())
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => f64::from(y),
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                state.wheel(lines);
                Ok(())
            }
            _ => Ok(()),
        };
        if let Err(e) = result {
            self.error = Some(e);
            event_loop.exit();
        }
    }

    fn about_to_wait(&mut self, _: &ActiveEventLoop) {
        if let Some(state) = &self.state {
            state.window.request_redraw();
        }
    }
}

impl State {
    fn new(event_loop: &ActiveEventLoop, options: &Options) -> Result<State> {
        let scene = &options.scene;
        let [w, h] = scene.size;
        let attributes = Window::default_attributes()
            .with_title("vortex view")
            .with_inner_size(PhysicalSize::new(w, h))
            .with_resizable(options.screenshot.is_none());
        let window = Arc::new(event_loop.create_window(attributes).context("opening a window")?);
        let descriptor = wgpu::InstanceDescriptor {
            backends: wgpu::Backends::PRIMARY,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        };
        let instance = wgpu::Instance::new(descriptor.with_env());
        let surface = instance.create_surface(Arc::clone(&window)).context("making the window's GPU surface")?;
        let (layers, tile_size, remote) = open_layers(scene, options.io_latency, options.http_deadline)?;
        let side = u32::from(scene.effects.cache_slots_per_side) * tile_size;
        let gpu = Gpu::for_surface(instance, &surface, side)?;

        let size = window.inner_size();
        let (width, height) = (size.width.max(1), size.height.max(1));
        let mut config = surface
            .get_default_config(&gpu.adapter, width, height)
            .ok_or_else(|| anyhow!("the adapter {} cannot present to this window", gpu.adapter_info().name))?;
        let caps = surface.get_capabilities(&gpu.adapter);
        config.format = caps
            .formats
            .iter()
            .copied()
            .find(|f| f.is_srgb())
            .ok_or_else(|| anyhow!("the window offers no sRGB format ({:?})", caps.formats))?;
        if options.screenshot.is_some() {
            if !caps.usages.contains(wgpu::TextureUsages::COPY_SRC) {
                return Err(anyhow!("this window system's surface cannot be read back, so no --screenshot"));
            }
            config.usage |= wgpu::TextureUsages::COPY_SRC;
        }
        config.present_mode = wgpu::PresentMode::AutoVsync;
        // Black where nothing is drawn (beside the image, around the meshes), never what lies
        // behind the window: the frame is cleared to transparent.
        if caps.alpha_modes.contains(&wgpu::CompositeAlphaMode::Opaque) {
            config.alpha_mode = wgpu::CompositeAlphaMode::Opaque;
        }
        surface.configure(&gpu.device, &config);

        // A screenshot waits for each frame's pages, as `render` does; a person never waits.
        let pacing = if options.screenshot.is_some() { Pacing::Offline } else { Pacing::RealTime };
        let mut scene = scene.clone();
        scene.size = [width, height];
        let mut renderer = SceneRenderer::with_layers(gpu, layers, &scene, pacing)?;
        renderer.set_residency_view(options.residency_view);
        warn_of_seams(&renderer);
        let images = renderer.runtime().textures().iter().map(|t| t.size()).collect();
        let now = Instant::now();
        Ok(State {
            window,
            surface,
            config,
            renderer,
            view: options.start,
            images,
            cursor: [0.0; 2],
            dragging: false,
            held: HashSet::new(),
            frames: 0,
            last_frame: now,
            title_at: now,
            frames_since_title: 0,
            last: FrameReport::default(),
            remote,
        })
    }

    fn size(&self) -> (u32, u32) {
        (self.config.width, self.config.height)
    }

    fn resize(&mut self, size: PhysicalSize<u32>) {
        if size.width == 0 || size.height == 0 {
            return;
        }
        (self.config.width, self.config.height) = (size.width, size.height);
        self.surface.configure(&self.renderer.gpu().device, &self.config);
        self.renderer.runtime_mut().resize(size.width, size.height);
    }

    fn pose(&self) -> Pose {
        match self.view {
            Start::Image(v) => v.pose(self.images[v.texture as usize], self.size()),
            Start::Fly(f) => f.pose(self.size()),
        }
    }

    /// Draws one frame; saves it if it is the screenshot's. Returns whether the run is done.
    fn redraw(&mut self, screenshot: Option<&(PathBuf, u32)>) -> Result<bool> {
        let dt = self.last_frame.elapsed().as_secs_f32().min(0.1);
        self.last_frame = Instant::now();
        self.fly(dt);
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(false),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.renderer.gpu().device, &self.config);
                return Ok(false);
            }
            other => return Err(anyhow!("the window's surface failed: {other:?}")),
        };
        let target = frame.texture.create_view(&wgpu::TextureViewDescriptor::default());
        let started = Instant::now();
        let pose = self.pose();
        self.renderer.draw_to(&pose, &target, self.config.format, self.size());
        let recorded = started.elapsed();
        let last = screenshot.filter(|(_, n)| self.frames + 1 >= *n);
        if let Some((path, _)) = last {
            screenshot::save(self.renderer.gpu(), &frame.texture, path)?;
        }
        self.last = self.renderer.end_frame(recorded)?;
        self.renderer.gpu().queue.present(frame);
        self.frames += 1;
        self.frames_since_title += 1;
        if self.title_at.elapsed() >= Duration::from_millis(250) {
            self.update_title();
        }
        Ok(last.is_some())
    }

    fn update_title(&mut self) {
        let fps = f64::from(self.frames_since_title) / self.title_at.elapsed().as_secs_f64();
        let rt = self.renderer.runtime();
        let texture = match self.view {
            Start::Image(v) => v.texture as usize,
            Start::Fly(_) => 0,
        };
        let [w, h] = self.images[texture];
        let name = self.renderer.runtime().loader().sources()[texture].location().shown().to_string();
        let remote = match remote_stats(&self.remote) {
            _ if self.remote.is_empty() => String::new(),
            s => format!(
                " | {} requests, {:.1} MiB, {} retries",
                s.requests,
                s.bytes as f64 / (1 << 20) as f64,
                s.retries
            ),
        };
        self.window.set_title(&format!(
            "vortex view: {name} ({w}x{h}){} | {}/{} slots, {} in flight, {:.1}% fallback | {}{}{}{remote} | {fps:.0} fps",
            match rt.caches().len() {
                1 => String::new(),
                n => format!(" layer {} of {n}", self.renderer.layer()),
            },
            rt.residency().resident_count(),
            rt.residency().slots(),
            rt.in_flight(),
            self.last.fallback_fraction * 100.0,
            rt.filter().name(),
            match self.renderer.anisotropy() {
                1 => String::new(),
                n => format!(", {n}x anisotropic"),
            },
            if self.renderer.residency_view() { ", residency view" } else { "" },
        ));
        self.title_at = Instant::now();
        self.frames_since_title = 0;
    }

    /// Handles a key; returns whether to quit.
    fn key(&mut self, event: &KeyEvent, options: &Options) -> bool {
        let PhysicalKey::Code(code) = event.physical_key else { return false };
        if event.state == ElementState::Released {
            self.held.remove(&code);
            return false;
        }
        self.held.insert(code);
        let size = self.size();
        let centre = [f64::from(size.0) / 2.0, f64::from(size.1) / 2.0];
        match (&event.logical_key, code) {
            (Key::Named(NamedKey::Escape), _) => return true,
            (_, KeyCode::KeyF) if !event.repeat => {
                let rt = self.renderer.runtime_mut();
                let next = SampleFilter::ALL[(rt.filter() as usize + 1) % SampleFilter::ALL.len()];
                rt.set_filter(next);
                warn_of_seams(&self.renderer);
            }
            (_, KeyCode::KeyI) if !event.repeat => {
                // 1, 2, 4, 8, 16, 1, ...: each value makes its pipelines once.
                let next = self.renderer.anisotropy() * 2;
                self.renderer.set_anisotropy(if next > vortex_vt::anisotropy::MAX_ANISOTROPY { 1 } else { next });
            }
            (_, KeyCode::KeyP) if !event.repeat => {
                let on = !self.renderer.residency_view();
                self.renderer.set_residency_view(on);
            }
            (_, KeyCode::KeyL) if !event.repeat => {
                let layers = self.renderer.runtime().caches().len() as u32;
                self.renderer.set_layer((self.renderer.layer() + 1) % layers);
            }
            (_, KeyCode::KeyR | KeyCode::Home) => self.view = options.start,
            (Key::Character(c), _) if c.as_str() == "+" || c.as_str() == "=" => self.zoom(1.25, centre),
            (Key::Character(c), _) if c.as_str() == "-" => self.zoom(0.8, centre),
            (Key::Character(c), _) => {
                let digit = c.chars().next().and_then(|c| c.to_digit(10));
                if let (Some(d), Start::Image(v)) = (digit, &mut self.view)
                    && (1..=self.images.len() as u32).contains(&d)
                {
                    v.texture = (d - 1) as u8;
                }
            }
            (Key::Named(NamedKey::ArrowLeft), _) => self.pan([f64::from(size.0) / 10.0, 0.0]),
            (Key::Named(NamedKey::ArrowRight), _) => self.pan([-f64::from(size.0) / 10.0, 0.0]),
            (Key::Named(NamedKey::ArrowUp), _) => self.pan([0.0, f64::from(size.1) / 10.0]),
            (Key::Named(NamedKey::ArrowDown), _) => self.pan([0.0, -f64::from(size.1) / 10.0]),
            _ => {}
        }
        self.update_title();
        false
    }

    fn moved(&mut self, position: PhysicalPosition<f64>) {
        let now = [position.x, position.y];
        let delta = [now[0] - self.cursor[0], now[1] - self.cursor[1]];
        self.cursor = now;
        if !self.dragging {
            return;
        }
        match &mut self.view {
            Start::Image(_) => self.pan(delta),
            Start::Fly(f) => f.look(delta),
        }
    }

    fn wheel(&mut self, lines: f64) {
        match &mut self.view {
            Start::Image(_) => self.zoom(1.25f64.powf(lines), self.cursor),
            Start::Fly(f) => f.fly(lines as f32 * 0.05, 0.0, 0.0),
        }
    }

    fn pan(&mut self, pixels: [f64; 2]) {
        let size = self.size();
        if let Start::Image(v) = &mut self.view {
            v.pan(pixels, self.images[v.texture as usize], size);
        }
    }

    fn zoom(&mut self, factor: f64, at: [f64; 2]) {
        let size = self.size();
        if let Start::Image(v) = &mut self.view {
            v.zoom(factor, at, self.images[v.texture as usize], size);
        }
    }

    /// Moves the fly camera by the keys held for `dt` seconds (Shift: four times as fast).
    fn fly(&mut self, dt: f32) {
        let Start::Fly(f) = &mut self.view else { return };
        let held = |k| self.held.contains(&k);
        let axis = |plus, minus| f32::from(u8::from(held(plus))) - f32::from(u8::from(held(minus)));
        let fast = if held(KeyCode::ShiftLeft) || held(KeyCode::ShiftRight) { 4.0 } else { 1.0 };
        let step = 0.3 * fast * dt;
        f.fly(
            axis(KeyCode::KeyW, KeyCode::KeyS) * step,
            axis(KeyCode::KeyD, KeyCode::KeyA) * step,
            axis(KeyCode::KeyE, KeyCode::KeyQ) * step,
        );
    }
}
