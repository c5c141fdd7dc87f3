//! What the runtime needs to know of one virtual texture to address it: its page grid and how
//! the real image sits in it. A texture is square, a power of two of pages per side; the image
//! fills its top-left corner (`uv_scale` of it per axis) and image UV 0..1 spans just the image.

use vortex_vt::page::TextureGrid;

/// The shape of one virtual texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VirtualTexture {
    pub grid: TextureGrid,
    /// Real image size at LOD 0, in texels.
    pub width: u32,
    pub height: u32,
    /// Stored tile side, borders included.
    pub tile_size: u32,
    pub border: u32,
}

impl VirtualTexture {
    /// A texture whose image fills its whole page grid (`grid.pages * payload` texels per side).
    pub fn square(grid: TextureGrid, tile_size: u32, border: u32) -> VirtualTexture {
        let side = grid.pages as u32 * (tile_size - 2 * border);
        VirtualTexture { grid, width: side, height: side, tile_size, border }
    }

    /// Side of a page's own texels (the tile without its borders).
    pub fn payload(&self) -> u32 {
        self.tile_size - 2 * self.border
    }

    /// Texels per side of the page grid at LOD 0.
    pub fn side_texels(&self) -> u64 {
        self.grid.pages as u64 * self.payload() as u64
    }

    /// The fraction of the page grid the image covers, per axis: image UV times this is the
    /// virtual UV.
    pub fn uv_scale(&self) -> [f32; 2] {
        let side = self.side_texels() as f64;
        [(self.width as f64 / side) as f32, (self.height as f64 / side) as f32]
    }
}
