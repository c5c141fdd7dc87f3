//! `vortex-tiler view`: packs in an interactive window. A 2D pan and zoom over one image, or a fly
//! camera over a scene's geometry; the residency in the title; keys to switch the filter and to
//! show which LOD each pixel is drawn from. The window draws through the runtime's harness
//! (`vortex_vt_wgpu::harness::SceneRenderer::draw_to`), the same shader `render` uses, into the
//! window's surface, in real time: no frame waits for a page. With `--screenshot` it draws a
//! fixed number of frames, each waiting for the pages the previous one asked for (as `render`
//! does by default), saves the last one and exits: what the tests compare with `render`.

mod app;
mod controls;
mod screenshot;

use std::path::PathBuf;

use anyhow::{Result, bail};
use clap::Args;
use vortex_vt_wgpu::harness::camera::at_frame;
use vortex_vt_wgpu::harness::{Scene, SceneView};

use super::render::{StreamArgs, check_scene, parse_dims};
use controls::{Fly, PanZoom};

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// Packs to show (texture 0, 1, ...; keys 1-9 switch the 2D view between them): files, or
    /// http:// or https:// URLs read with Range requests (docs/remote.md).
    #[arg(value_name = "PACK")]
    packs: Vec<PathBuf>,
    /// A scene (docs/scenes.md) for its geometry and effects: the fly camera starts at its
    /// path's first keyframe. Without it, a 2D view of the first pack.
    #[arg(long, value_name = "JSON")]
    scene: Option<PathBuf>,
    /// The window's size in pixels.
    #[arg(long, value_name = "WxH", value_parser = parse_dims, default_value = "1024x768")]
    size: [u32; 2],
    #[command(flatten)]
    stream: StreamArgs,
    /// Draw --frame-count frames, save the window's last frame as a PNG here and exit. Each
    /// frame waits for the pages the previous one asked for, as `render` does, so the picture
    /// is the same on every run; and as `render` does, the run fails (exit 1) if a page failed
    /// to load and was drawn as the magenta stand-in.
    #[arg(long, value_name = "PNG", requires = "frame_count")]
    screenshot: Option<PathBuf>,
    /// Frames to draw before the screenshot: 1 to 1,000,000, as `render` allows.
    #[arg(long, value_name = "N")]
    frame_count: Option<u32>,
    /// Start with the residency view (P toggles it): a hue per LOD drawn, red where a coarser
    /// page stands in for one not loaded yet.
    #[arg(long)]
    residency_view: bool,
}

/// Where the view starts.
#[derive(Clone, Copy, Debug)]
enum Start {
    Image(PanZoom),
    Fly(Fly),
}

pub fn run(a: ViewArgs) -> Result<()> {
    if let Some(path) = &a.screenshot {
        screenshot::refuse_others(path)?;
    }
    let mut scene = match &a.scene {
        Some(path) => Scene::read(path)?,
        None => whole_image_scene(),
    };
    if !a.packs.is_empty() {
        scene.textures = a.packs.clone();
    }
    if scene.textures.is_empty() {
        bail!("no texture: give a PACK (or a --scene whose \"textures\" names packs)");
    }
    scene.size = a.size;
    // `render`'s checks, the cap on frames included: 0 and 4294967295 are refused, not drawn.
    scene.frames = a.frame_count.unwrap_or(1);
    a.stream.apply(&mut scene);
    check_scene(&scene)?;
    let start = match &scene.view {
        SceneView::Window { texture, path } => {
            let key = at_frame(path, 0, |a, _, _| *a).ok_or_else(|| anyhow::anyhow!("scene: no keyframe"))?;
            Start::Image(PanZoom { texture: *texture, center: key.center, width: key.width })
        }
        SceneView::Camera { fov_y_deg, path, .. } => {
            let key = at_frame(path, 0, |a, _, _| *a).ok_or_else(|| anyhow::anyhow!("scene: no keyframe"))?;
            Start::Fly(Fly::looking(key, *fov_y_deg))
        }
    };
    app::run(app::Options {
        scene,
        start,
        io_latency: a.stream.io_latency,
        http_deadline: a.stream.http_deadline,
        residency_view: a.residency_view,
        screenshot: a.screenshot.zip(a.frame_count),
    })
}

/// A 2D view of the whole of texture 0.
fn whole_image_scene() -> Scene {
    let json = r#"{"view": {"window": {"path": [{"frame": 0, "center": [0.5, 0.5], "width": 1.0}]}}}"#;
    #[expect(clippy::expect_used, reason = "a fixed scene, parsed by the test below")]
    serde_json::from_str(json).expect("the whole-image scene parses")
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_default_scene_is_a_window_on_the_whole_first_image() {
        let scene = super::whole_image_scene();
        assert!(scene.check().is_ok());
        assert!(matches!(scene.view, vortex_vt_wgpu::harness::SceneView::Window { texture: 0, .. }));
    }
}
