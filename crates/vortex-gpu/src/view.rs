//! What a draw shows: a 2D window onto one virtual texture (how maps, scans and microscopy are
//! viewed), or meshes seen through a camera. Both passes draw the same [`View`].

use vortex_vt::address::WindowOrigin;

use crate::mesh::GpuMesh;
use crate::texture::VirtualTexture;

/// What one draw shows.
#[derive(Clone, Copy, Debug)]
pub enum View<'a> {
    Window(Window),
    /// Meshes (their vertices name their texture) through a column-major view-projection
    /// matrix (wgpu's clip space: depth 0..1).
    Meshes {
        view_proj: [[f32; 4]; 4],
        meshes: &'a [GpuMesh],
    },
}

/// An axis-aligned window onto one texture, in virtual UV (0..1 over the whole page grid) held
/// in f64, so that a window deep inside a huge texture is placed exactly (see
/// `vortex_vt::address`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    pub texture: u8,
    /// Virtual UV of the target's top-left corner.
    pub origin: [f64; 2],
    /// Virtual UV covered by the whole target, per axis (1.0 shows the whole page grid).
    pub extent: [f64; 2],
}

impl Window {
    /// The whole page grid of `texture`.
    pub fn whole(texture: u8) -> Window {
        Window { texture, origin: [0.0; 2], extent: [1.0; 2] }
    }

    /// The origin and step the shaders get for a `size` target (LOD-0 texels).
    pub fn origin_texels(&self, texture: &VirtualTexture, size: (u32, u32)) -> WindowOrigin {
        let side = texture.side_texels() as f64;
        WindowOrigin::new(
            [self.origin[0] * side, self.origin[1] * side],
            [self.extent[0] * side / size.0 as f64, self.extent[1] * side / size.1 as f64],
        )
    }

    /// The virtual UV at the centre of pixel (`x`, `y`) of a `size` target, in f64.
    pub fn uv(&self, x: u32, y: u32, size: (u32, u32)) -> [f64; 2] {
        [
            self.origin[0] + (x as f64 + 0.5) * self.extent[0] / size.0 as f64,
            self.origin[1] + (y as f64 + 0.5) * self.extent[1] / size.1 as f64,
        ]
    }
}
