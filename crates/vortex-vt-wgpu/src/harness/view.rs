//! What a draw shows: a 2D window onto one virtual texture (how maps, scans and microscopy are
//! viewed), or meshes seen through a camera.

use vortex_vt::address::WindowOrigin;

use super::mesh::GpuMesh;
use crate::texture::VirtualTexture;

/// What one draw shows.
#[derive(Clone, Copy, Debug)]
pub enum View<'a> {
    /// A window onto one texture.
    Window(Window),
    /// Meshes (their vertices name their texture) through a column-major view-projection
    /// matrix (wgpu's clip space: depth 0..1).
    Meshes {
        /// The view-projection matrix.
        view_proj: [[f32; 4]; 4],
        /// The meshes.
        meshes: &'a [GpuMesh],
    },
}

/// An axis-aligned window onto one texture, in image UV (0..1 over the real image on each axis,
/// as meshes' UVs) held in f64, so that a window deep inside a huge texture is placed exactly
/// (see `vortex_vt::address`). On a non-square image equal extents in u and v are unequal in
/// texels: [`Window::square_pixels`] makes a window whose pixels are square.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    /// The texture shown.
    pub texture: u8,
    /// Image UV of the target's top-left corner.
    pub origin: [f64; 2],
    /// Image UV covered by the whole target, per axis (1.0 shows the whole image).
    pub extent: [f64; 2],
}

impl Window {
    /// The whole image of `texture`, stretched over the target.
    pub fn whole(texture: u8) -> Window {
        Window { texture, origin: [0.0; 2], extent: [1.0; 2] }
    }

    /// The window centred on image UV `center` that shows `width` of the image's width, its
    /// height chosen so that a pixel covers as many texels down as across on a `size` target:
    /// the extent in v is `width * (image width / image height) / (target width / height)`.
    /// `image` is the image's width and height at LOD 0 ([`VirtualTexture::size`]).
    pub fn square_pixels(texture: u8, image: [u32; 2], center: [f64; 2], width: f64, size: (u32, u32)) -> Window {
        let image_aspect = image[0] as f64 / image[1] as f64;
        let target_aspect = size.0 as f64 / size.1 as f64;
        let extent = [width, width * image_aspect / target_aspect];
        let origin = [center[0] - extent[0] / 2.0, center[1] - extent[1] / 2.0];
        Window { texture, origin, extent }
    }

    /// The origin and step the shaders get for a `size` target (LOD-0 texels: image UV times
    /// the image's size).
    pub fn origin_texels(&self, texture: &VirtualTexture, size: (u32, u32)) -> WindowOrigin {
        let [w, h] = texture.size().map(f64::from);
        WindowOrigin::new(
            [self.origin[0] * w, self.origin[1] * h],
            [self.extent[0] * w / size.0 as f64, self.extent[1] * h / size.1 as f64],
        )
    }

    /// The image UV at the centre of pixel (`x`, `y`) of a `size` target, in f64.
    pub fn uv(&self, x: u32, y: u32, size: (u32, u32)) -> [f64; 2] {
        [
            self.origin[0] + (x as f64 + 0.5) * self.extent[0] / size.0 as f64,
            self.origin[1] + (y as f64 + 0.5) * self.extent[1] / size.1 as f64,
        ]
    }
}
