//! The headless harness (feature `harness`): scenes read from JSON (`docs/scenes.md`), camera
//! paths, meshes and 2D windows, and a [`SceneRenderer`] that draws them offscreen with its own
//! shader and pipelines on top of the public [`Runtime`](crate::Runtime), exactly as an
//! application would, and reads the pictures back. `vortex-tiler render`, the tests and the
//! measurement programs use it; an application needs none of it.

pub mod camera;
mod draw;
mod frame;
pub mod mesh;
#[cfg(feature = "testing")]
pub mod probe;
mod renderer;
pub mod scene;
pub mod view;

pub use mesh::{GpuMesh, Mesh, Vertex};
pub use renderer::{FrameReport, Report, SceneRenderer, TARGET_FORMAT};
pub use scene::{Effects, Pose, Scene, SceneError, SceneLayer, SceneView, Shape, WindowKey};
pub use view::{View, Window};
