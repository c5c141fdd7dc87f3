//! The harness's uniform block (`Frame` in `harness.wgsl`): where the camera is (a window's
//! origin and step, or a view-projection matrix) and an optional fixed LOD. Built on the render
//! thread once per draw.

use super::view::View;
use crate::texture::VirtualTexture;

/// `Frame` in `harness.wgsl`, 96 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Frame {
    view_proj: [[f32; 4]; 4],
    origin_int: [u32; 2],
    origin_frac: [f32; 2],
    step: [f32; 2],
    window_texture: u32,
    lod_override: f32,
}

const IDENTITY: [[f32; 4]; 4] =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

impl Frame {
    /// The parameters of drawing `view` of `textures` into a `size` target; `lod_override`
    /// replaces the LOD from the footprint.
    pub(crate) fn new(textures: &[VirtualTexture], view: &View, size: (u32, u32), lod_override: Option<f32>) -> Frame {
        let mut frame = Frame {
            view_proj: IDENTITY,
            origin_int: [0; 2],
            origin_frac: [0.0; 2],
            step: [0.0; 2],
            window_texture: 0,
            lod_override: lod_override.unwrap_or(-1.0),
        };
        match view {
            View::Window(w) => {
                let o = w.origin_texels(&textures[w.texture as usize], size);
                (frame.origin_int, frame.origin_frac, frame.step) = (o.int, o.frac, o.step);
                frame.window_texture = w.texture as u32;
            }
            View::Meshes { view_proj, .. } => frame.view_proj = *view_proj,
        }
        frame
    }
}
