//! Scenes: what a headless run renders, read from JSON (`docs/scenes.md`) or built in code. A
//! scene names its virtual textures, its geometry (a 2D window, or planes, terrain grids and
//! boxes), a camera path, the output size, and the effects it needs (filter, feedback size,
//! cache size, upload budget). The runtime turns on only what the scene asks for: one sampling
//! pipeline for its filter, the mesh pipelines only for meshes, and only the pages its
//! feedback requests are ever read.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::camera::{Camera, Keyframe, at_frame, lerp3};
use super::mesh::{Mesh, Vertex};
use super::view::Window;
use crate::layer::LayerKind;
use crate::page_cache::CacheFormat;
use crate::sample::SampleFilter;
use crate::texture::VirtualTexture;

/// Why a scene cannot be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// The file cannot be read.
    #[error("cannot read scene {path}: {source}")]
    Read {
        /// The scene file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The file is not a scene's JSON.
    #[error("scene {path}: {source}")]
    Parse {
        /// The scene file.
        path: PathBuf,
        /// What the parser said.
        source: serde_json::Error,
    },
    /// The scene does not make sense (a texture it does not have, an empty path).
    #[error("scene {path}: {message}")]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// A scene as written in JSON. Every member but `view` has a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Packs, texture id = position; relative paths are relative to the scene file. May be
    /// empty when the command line names the packs.
    #[serde(default)]
    pub textures: Vec<PathBuf>,
    /// More layers of the same textures (`crate::layer`): `textures` is layer 0 (colour), and
    /// each of these names its kind and one pack per texture, on the same page grid.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub layers: Vec<SceneLayer>,
    /// Output width and height in pixels.
    #[serde(default = "default_size")]
    pub size: [u32; 2],
    /// Frames to render.
    #[serde(default = "default_frames")]
    pub frames: u32,
    /// What the camera looks at.
    pub view: SceneView,
    /// Filtering, caching and loading settings.
    #[serde(default)]
    pub effects: Effects,
}

/// A layer beyond the first: its kind and its packs (one per texture, paths as `textures`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneLayer {
    /// Colour or data.
    #[serde(with = "layer_kind_name", default)]
    pub kind: LayerKind,
    /// Its pack of each texture, in the order of the scene's textures.
    pub textures: Vec<PathBuf>,
}

mod layer_kind_name {
    use serde::{Deserialize, Deserializer, Serializer, de::Error};

    use crate::layer::LayerKind;

    pub fn serialize<S: Serializer>(k: &LayerKind, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(k.name())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<LayerKind, D::Error> {
        let name = String::deserialize(d)?;
        LayerKind::from_name(&name)
            .ok_or_else(|| D::Error::custom(format!("unknown layer kind {name:?}: colour or data")))
    }
}

/// What the camera looks at.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum SceneView {
    /// A 2D window onto one texture, moving along `path` (a viewer's pan and zoom).
    Window {
        /// The texture shown.
        #[serde(default)]
        texture: u8,
        /// Where the window is, by frame.
        path: Vec<Keyframe<WindowKey>>,
    },
    /// Meshes through a perspective camera moving along `path`.
    Camera {
        /// Vertical field of view in degrees.
        #[serde(default = "default_fov")]
        fov_y_deg: f32,
        /// Where the camera is, by frame.
        path: Vec<Keyframe<Camera>>,
        /// The meshes.
        geometry: Vec<Shape>,
    },
}

/// Where a window is: the image UV at its centre (0..1 over the real image on each axis) and how
/// much of the image's width it shows (1 = all of it; 0.01 = a hundredth); its height follows
/// from square pixels (`Window::square_pixels`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindowKey {
    /// Image UV at the window's centre.
    pub center: [f64; 2],
    /// Share of the image's width shown.
    pub width: f64,
}

/// One piece of geometry; UV 0..1 spans the texture's real image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Shape {
    /// A flat square in the y = 0 plane, centred on the origin, `size` units per side.
    Plane {
        /// The texture shown.
        #[serde(default)]
        texture: u8,
        /// Units per side.
        #[serde(default = "one")]
        size: f32,
    },
    /// A height field over a square (`size` units, `cells` per side) with rolling hills of
    /// amplitude `height`.
    Terrain {
        /// The texture shown.
        #[serde(default)]
        texture: u8,
        /// Units per side.
        #[serde(default = "one")]
        size: f32,
        /// Cells per side.
        #[serde(default = "default_cells")]
        cells: u32,
        /// The hills' amplitude in units.
        #[serde(default = "default_height")]
        height: f32,
    },
    /// An axis-aligned box; each face shows the whole image.
    Box {
        /// The texture shown.
        #[serde(default)]
        texture: u8,
        /// Its centre.
        center: [f32; 3],
        /// Its extent along x, y and z.
        size: [f32; 3],
    },
}

/// The effects a scene needs; nothing else runs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Effects {
    /// The filter; `auto` (the default) takes the best the textures' border allows
    /// ([`SampleFilter::best_for`]: trilinear with a border, nearest without).
    #[serde(with = "filter_name")]
    pub filter: Option<SampleFilter>,
    /// One pixel in each block of `feedback_divisor²` writes feedback per frame.
    pub feedback_divisor: u32,
    /// The physical cache is this many slots per side (1..=256).
    pub cache_slots_per_side: u16,
    /// Most pages uploaded per frame.
    pub upload_budget: usize,
    /// Loader threads.
    pub threads: usize,
    /// Use a BC7 cache when the adapter samples BC and every tile is BC7 (or one colour).
    pub bc7: bool,
    /// What the physical cache holds: `auto` (the default: BC where the adapter samples it:
    /// stored BC7 as `bc7` says, else BC1 for opaque textures and BC7 for alpha; RGBA8 without
    /// BC), `rgba8` (exact), or `bc1` / `bc7`: every page transcoded on the loader's threads.
    #[serde(with = "cache_format_name")]
    pub cache_format: Option<CacheFormat>,
    /// The layer of the textures' stacks drawn (0, the colour of `textures`, by default).
    pub layer: u32,
    /// MiB of stored (compressed) tiles the loader keeps in RAM, so that pages the cache
    /// evicted come back without a read ([`RuntimeConfig::memory_tier_bytes`](crate::RuntimeConfig));
    /// 0 turns the tier off.
    pub memory_tier_mib: u32,
    /// Anisotropic filtering: at most this many probes per sample along the pixel's footprint,
    /// at the LOD of its shorter axis (1, the default, is isotropic; 2, 4, 8 or 16). Sharper
    /// surfaces seen at a grazing angle, for up to that many samples per pixel there
    /// (docs/gpu-sampling.md).
    pub anisotropy: u32,
}

impl Default for Effects {
    fn default() -> Effects {
        Effects {
            filter: None,
            feedback_divisor: 8,
            cache_slots_per_side: 16,
            upload_budget: 32,
            threads: 2,
            bc7: true,
            cache_format: None,
            layer: 0,
            memory_tier_mib: (crate::DEFAULT_MEMORY_TIER_BYTES >> 20) as u32,
            anisotropy: 1,
        }
    }
}

impl Effects {
    /// The defaults with an RGBA8 cache, whose texels are the pack's exactly: what pictures
    /// compared with the reference sampler want (the default cache is BC where the adapter
    /// samples it, which is 32-43 dB from exact).
    pub fn exact() -> Effects {
        Effects { cache_format: Some(CacheFormat::Rgba8), ..Effects::default() }
    }
}

mod cache_format_name {
    use serde::{Deserialize, Deserializer, Serializer, de::Error};

    use crate::page_cache::CacheFormat;

    pub fn serialize<S: Serializer>(f: &Option<CacheFormat>, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(f.map_or("auto", CacheFormat::name))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<CacheFormat>, D::Error> {
        let name = String::deserialize(d)?;
        if name == "auto" {
            return Ok(None);
        }
        CacheFormat::from_name(&name)
            .map(Some)
            .ok_or_else(|| D::Error::custom(format!("unknown cache format {name:?}: auto, rgba8, bc1 or bc7")))
    }
}

mod filter_name {
    use serde::{Deserialize, Deserializer, Serializer, de::Error};

    use crate::sample::SampleFilter;

    pub fn serialize<S: Serializer>(f: &Option<SampleFilter>, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(f.map_or("auto", SampleFilter::name))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<SampleFilter>, D::Error> {
        let name = String::deserialize(d)?;
        if name == "auto" {
            return Ok(None);
        }
        let filter = SampleFilter::from_name(&name);
        filter
            .map(Some)
            .ok_or_else(|| D::Error::custom(format!("unknown filter {name:?}: auto, nearest, bilinear or trilinear")))
    }
}

fn default_size() -> [u32; 2] {
    [512, 384]
}
fn default_frames() -> u32 {
    60
}
fn default_fov() -> f32 {
    60.0
}
fn one() -> f32 {
    1.0
}
/// The most cells per side of a terrain: 2 million triangles, far more than a test scene needs,
/// and a mesh that fits in memory.
pub const MAX_TERRAIN_CELLS: u32 = 1024;

fn default_cells() -> u32 {
    64
}
fn default_height() -> f32 {
    0.1
}

impl Scene {
    /// The built-in scene: a plane seen from above, zooming in towards one spot while panning,
    /// then holding still for the last third of the frames so that streaming can converge.
    pub fn default_plane() -> Scene {
        let key = |frame, eye, target| Keyframe { frame, at: Camera { eye, target } };
        Scene {
            textures: vec![],
            layers: vec![],
            size: default_size(),
            frames: 60,
            view: SceneView::Camera {
                fov_y_deg: 60.0,
                path: vec![
                    key(0, [0.0, 0.9, 0.35], [0.0, 0.0, 0.0]),
                    key(20, [0.12, 0.25, 0.18], [0.1, 0.0, -0.02]),
                    key(40, [0.22, 0.08, 0.05], [0.28, 0.0, -0.12]),
                ],
                geometry: vec![Shape::Plane { texture: 0, size: 1.0 }],
            },
            effects: Effects::default(),
        }
    }

    /// Reads a scene file; relative texture paths become relative to the file's folder.
    pub fn read(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Read { path: path.into(), source })?;
        let mut scene: Scene =
            serde_json::from_str(&text).map_err(|source| SceneError::Parse { path: path.into(), source })?;
        let dir = path.parent().unwrap_or(Path::new(""));
        let layers = scene.layers.iter_mut().flat_map(|l| l.textures.iter_mut());
        for t in scene.textures.iter_mut().chain(layers) {
            if t.is_relative() {
                *t = dir.join(&*t);
            }
        }
        scene.check().map_err(|message| SceneError::Invalid { path: path.into(), message })?;
        Ok(scene)
    }

    /// Checks what serde cannot: sizes, counts, keyframe order, texture ids below `textures`
    /// (when known; pass `None` before the packs are chosen).
    pub fn check(&self) -> Result<(), String> {
        let [w, h] = self.size;
        if !(1..=8192).contains(&w) || !(1..=8192).contains(&h) {
            return Err(format!("size {w}x{h}: each side must be 1..=8192"));
        }
        if self.frames == 0 {
            return Err("frames must be at least 1".into());
        }
        let e = &self.effects;
        if e.feedback_divisor == 0 {
            return Err("effects.feedback_divisor must be at least 1".into());
        }
        if !(1..=256).contains(&e.cache_slots_per_side) {
            return Err(format!("effects.cache_slots_per_side {} must be 1..=256", e.cache_slots_per_side));
        }
        if ![1, 2, 4, 8, 16].contains(&e.anisotropy) {
            return Err(format!("effects.anisotropy {} must be 1 (off), 2, 4, 8 or 16", e.anisotropy));
        }
        let most_threads = 4 * std::thread::available_parallelism().map_or(1, |n| n.get());
        if !(1..=most_threads).contains(&e.threads) {
            return Err(format!("effects.threads {} must be 1..={most_threads} (4 per core)", e.threads));
        }
        let frames: Vec<u32> = match &self.view {
            SceneView::Window { path, .. } => {
                if let Some(k) = path.iter().find(|k| !(k.at.width > 0.0 && k.at.width.is_finite())) {
                    return Err(format!("view.window.path: frame {} has width {}, must be > 0", k.frame, k.at.width));
                }
                path.iter().map(|k| k.frame).collect()
            }
            SceneView::Camera { path, fov_y_deg, geometry } => {
                if !(1.0..=170.0).contains(fov_y_deg) {
                    return Err(format!("view.camera.fov_y_deg {fov_y_deg} must be 1..=170"));
                }
                if geometry.is_empty() {
                    return Err("view.camera.geometry is empty: nothing to draw".into());
                }
                for (i, shape) in geometry.iter().enumerate() {
                    if let Shape::Terrain { cells, .. } = shape
                        && !(1..=MAX_TERRAIN_CELLS).contains(cells)
                    {
                        return Err(format!("view.camera.geometry[{i}].cells {cells} must be 1..={MAX_TERRAIN_CELLS}"));
                    }
                }
                if let Some(k) = path.iter().find(|k| k.at.eye == k.at.target) {
                    return Err(format!("view.camera.path: frame {} has eye == target", k.frame));
                }
                path.iter().map(|k| k.frame).collect()
            }
        };
        if frames.is_empty() {
            return Err("the view's path has no keyframe".into());
        }
        if frames.windows(2).any(|w| w[0] >= w[1]) {
            return Err(format!("the view's path frames {frames:?} must increase"));
        }
        Ok(())
    }

    /// Checks that every texture id used is below `count`.
    pub fn check_textures(&self, count: usize) -> Result<(), String> {
        let used: Vec<u8> = match &self.view {
            SceneView::Window { texture, .. } => vec![*texture],
            SceneView::Camera { geometry, .. } => geometry.iter().map(Shape::texture).collect(),
        };
        match used.into_iter().find(|&t| t as usize >= count) {
            Some(t) => Err(format!("texture {t} is used but the scene has {count} texture(s)")),
            None => Ok(()),
        }
    }

    /// The first frame from which the camera no longer moves (the last keyframe's).
    pub fn still_from(&self) -> u32 {
        let last = match &self.view {
            SceneView::Window { path, .. } => path.last().map(|k| k.frame),
            SceneView::Camera { path, .. } => path.last().map(|k| k.frame),
        };
        last.unwrap_or(0).min(self.frames.saturating_sub(1))
    }

    /// The meshes of a camera scene, all in one (empty for a window).
    pub fn mesh(&self) -> Mesh {
        let mut mesh = Mesh::default();
        if let SceneView::Camera { geometry, .. } = &self.view {
            for shape in geometry {
                mesh.append(&shape.mesh());
            }
        }
        mesh
    }

    /// Where the camera is at `frame`, over `textures` (the loader's: a window's height depends
    /// on its image's aspect ratio; a texture id without one is taken as square). The scene must
    /// have passed [`Scene::check`], which refuses a path without keyframes.
    #[expect(clippy::expect_used, reason = "Scene::check refuses a path without keyframes")]
    pub fn pose(&self, frame: u32, textures: &[VirtualTexture]) -> Pose {
        let aspect = self.size[0] as f32 / self.size[1] as f32;
        match &self.view {
            SceneView::Window { texture, path } => {
                let k = at_frame(path, frame, |a, b, t| {
                    let t = t as f64;
                    // Zoom geometrically, so that a deep zoom moves at an even pace.
                    WindowKey {
                        center: [
                            a.center[0] + (b.center[0] - a.center[0]) * t,
                            a.center[1] + (b.center[1] - a.center[1]) * t,
                        ],
                        width: a.width * (b.width / a.width).powf(t),
                    }
                })
                .expect("checked: a path has keyframes");
                let size = (self.size[0], self.size[1]);
                let image = textures.get(*texture as usize).map_or([1, 1], VirtualTexture::size);
                Pose::Window(Window::square_pixels(*texture, image, k.center, k.width, size))
            }
            SceneView::Camera { fov_y_deg, path, .. } => {
                let cam = at_frame(path, frame, |a, b, t| Camera {
                    eye: lerp3(a.eye, b.eye, t),
                    target: lerp3(a.target, b.target, t),
                })
                .expect("checked: a path has keyframes");
                Pose::Camera(cam.view_proj(*fov_y_deg, aspect))
            }
        }
    }
}

/// Where the camera is in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pose {
    /// A window onto one texture.
    Window(Window),
    /// A view-projection matrix for the scene's meshes.
    Camera([[f32; 4]; 4]),
}

impl Shape {
    /// The texture it shows.
    pub fn texture(&self) -> u8 {
        match self {
            Shape::Plane { texture, .. } | Shape::Terrain { texture, .. } | Shape::Box { texture, .. } => *texture,
        }
    }

    /// The shape's triangles.
    pub fn mesh(&self) -> Mesh {
        match *self {
            Shape::Plane { texture, size } => grid(texture as u32, size, 1, |_, _| 0.0),
            Shape::Terrain { texture, size, cells, height } => {
                // `Scene::check` refuses other counts; the clamp only keeps an unchecked shape's
                // mesh within memory.
                grid(texture as u32, size, cells.clamp(1, MAX_TERRAIN_CELLS), |x, z| {
                    let (x, z) = (x / size * std::f32::consts::TAU, z / size * std::f32::consts::TAU);
                    height * 0.5 * ((2.0 * x).sin() * (3.0 * z).cos() + 0.5 * (5.0 * x + z).sin())
                })
            }
            Shape::Box { texture, center, size } => cuboid(texture as u32, center, size),
        }
    }
}

/// A square of `cells x cells` quads in x and z, centred on the origin, heights from `y(x, z)`;
/// UV (0, 0) at (-size/2, -size/2).
fn grid(texture: u32, size: f32, cells: u32, y: impl Fn(f32, f32) -> f32) -> Mesh {
    let n = cells + 1;
    let mut mesh = Mesh::default();
    for j in 0..n {
        for i in 0..n {
            let (u, v) = (i as f32 / cells as f32, j as f32 / cells as f32);
            let (x, z) = ((u - 0.5) * size, (v - 0.5) * size);
            mesh.vertices.push(Vertex { position: [x, y(x, z), z], uv: [u, v], texture });
        }
    }
    for j in 0..cells {
        for i in 0..cells {
            let a = j * n + i;
            mesh.indices.extend_from_slice(&[a, a + n, a + 1, a + 1, a + n, a + n + 1]);
        }
    }
    mesh
}

/// Six faces, each a quad showing the whole image.
fn cuboid(texture: u32, center: [f32; 3], size: [f32; 3]) -> Mesh {
    let mut mesh = Mesh::default();
    let h = size.map(|s| s / 2.0);
    // Each face: its normal axis and sign; the other two axes span it.
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let base = mesh.vertices.len() as u32;
            for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                let mut p = center;
                p[axis] += sign * h[axis];
                p[a] += (u * 2.0 - 1.0) * h[a];
                p[b] += (v * 2.0 - 1.0) * h[b];
                mesh.vertices.push(Vertex { position: p, uv: [u, v], texture });
            }
            mesh.indices.extend_from_slice(&[base, base + 1, base + 2, base + 2, base + 1, base + 3]);
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_scene_is_valid_and_ends_still() {
        let s = Scene::default_plane();
        s.check().unwrap();
        s.check_textures(1).unwrap();
        assert!(s.still_from() < s.frames - 10);
        assert_eq!(s.pose(s.still_from(), &[]), s.pose(s.frames - 1, &[]));
        assert_ne!(s.pose(0, &[]), s.pose(s.still_from(), &[]));
        assert_eq!(s.mesh().indices.len(), 6);
    }

    #[test]
    fn json_round_trips_and_bad_members_are_named() {
        let s = Scene::default_plane();
        let json = serde_json::to_string_pretty(&s).unwrap();
        assert_eq!(serde_json::from_str::<Scene>(&json).unwrap(), s);
        assert!(json.contains("\"filter\": \"auto\""), "{json}");
        let bad = json.replace("\"auto\"", "\"bicubic\"");
        assert!(serde_json::from_str::<Scene>(&bad).unwrap_err().to_string().contains("unknown filter \"bicubic\""));
        let extra = json.replacen("\"frames\"", "\"frame_count\": 3, \"frames\"", 1);
        assert!(serde_json::from_str::<Scene>(&extra).unwrap_err().to_string().contains("frame_count"));
    }

    #[test]
    fn layers_read_with_their_kind_and_paths_beside_the_scene() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("stack.json");
        let json = r#"{"textures": ["albedo.vtpk"], "layers": [{"kind": "data", "textures": ["normal.vtpk"]}],
            "view": {"window": {"path": [{"frame": 0, "center": [0.5, 0.5], "width": 1.0}]}}, "effects": {"layer": 1}}"#;
        std::fs::write(&path, json).unwrap();
        let s = Scene::read(&path).unwrap();
        assert_eq!(s.layers, [SceneLayer { kind: LayerKind::Data, textures: vec![dir.path().join("normal.vtpk")] }]);
        assert_eq!(s.effects.layer, 1);
        let bad = json.replace("\"data\"", "\"bump\"");
        assert!(serde_json::from_str::<Scene>(&bad).unwrap_err().to_string().contains("unknown layer kind \"bump\""));
    }

    #[test]
    fn checks_catch_what_serde_cannot() {
        let mut s = Scene::default_plane();
        s.effects.cache_slots_per_side = 0;
        assert!(s.check().unwrap_err().contains("cache_slots_per_side"));
        for (n, ok) in [(0, false), (1, true), (3, false), (8, true), (16, true), (32, false)] {
            let mut s = Scene::default_plane();
            s.effects.anisotropy = n;
            assert_eq!(s.check().is_ok(), ok, "anisotropy {n}");
        }
        let mut s = Scene::default_plane();
        if let SceneView::Camera { path, .. } = &mut s.view {
            path[1].frame = 0;
        }
        assert!(s.check().unwrap_err().contains("must increase"));
        let mut s = Scene::default_plane();
        if let SceneView::Camera { geometry, .. } = &mut s.view {
            geometry.push(Shape::Box { texture: 3, center: [0.0; 3], size: [0.1; 3] });
        }
        assert!(s.check_textures(2).unwrap_err().contains("texture 3"));
        for (cells, ok) in
            [(0, false), (1, true), (MAX_TERRAIN_CELLS, true), (MAX_TERRAIN_CELLS + 1, false), (u32::MAX, false)]
        {
            let mut s = Scene::default_plane();
            if let SceneView::Camera { geometry, .. } = &mut s.view {
                geometry.push(Shape::Terrain { texture: 0, size: 1.0, cells, height: 0.1 });
            }
            match s.check() {
                Ok(()) => assert!(ok, "cells {cells} accepted"),
                Err(e) => assert!(!ok && e.contains("view.camera.geometry[1].cells"), "cells {cells}: {e}"),
            }
        }
    }

    #[test]
    fn window_paths_zoom_geometrically() {
        let key = |frame, width| Keyframe { frame, at: WindowKey { center: [0.5, 0.5], width } };
        let s = Scene {
            size: [100, 50],
            view: SceneView::Window { texture: 0, path: vec![key(0, 1.0), key(10, 0.01)] },
            ..Scene::default_plane()
        };
        s.check().unwrap();
        let Pose::Window(w) = s.pose(5, &[]) else { panic!() };
        assert!((w.extent[0] - 0.1).abs() < 1e-9, "{w:?}");
        assert!((w.extent[1] - 0.05).abs() < 1e-9);
        assert!((w.origin[0] - 0.45).abs() < 1e-9);
        // A 4:1 image: the same tenth of its width is a fifth of its height on a 2:1 target.
        let wide = VirtualTexture::new(4000, 1000, 128, 4).unwrap();
        let Pose::Window(w) = s.pose(5, &[wide]) else { panic!() };
        assert!((w.extent[1] - 0.2).abs() < 1e-9, "{w:?}");
        let o = w.origin_texels(&wide, (100, 50));
        assert_eq!(o.step[0], o.step[1], "square pixels");
    }

    #[test]
    fn boxes_and_terrain_have_sound_indices() {
        for shape in [
            Shape::Box { texture: 1, center: [0.0, 0.5, 0.0], size: [1.0, 1.0, 2.0] },
            Shape::Terrain { texture: 0, size: 2.0, cells: 8, height: 0.2 },
        ] {
            let m = shape.mesh();
            assert!(m.indices.iter().all(|&i| (i as usize) < m.vertices.len()));
            assert_eq!(m.indices.len() % 3, 0);
            assert!(m.vertices.iter().all(|v| v.uv.iter().all(|t| (0.0..=1.0).contains(t))));
        }
    }
}
