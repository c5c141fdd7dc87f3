//! What the runtime needs to know of one virtual texture to address it: its page grid and the
//! real image it holds. UV 0..1 spans the image on both axes (LOD-0 texel = `uv * size`); the
//! grid covers it from the top-left, rectangular, its last row and column of pages possibly
//! part padding, which no sample reaches.

use vortex_vt::page::{GridError, TextureGrid};

/// The shape of one virtual texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VirtualTexture {
    /// Its pages at every LOD.
    pub grid: TextureGrid,
    /// Real image size at LOD 0, in texels.
    pub width: u32,
    /// Real image height at LOD 0, in texels.
    pub height: u32,
    /// Stored tile side, borders included.
    pub tile_size: u32,
    /// Texels of border on each side of a tile.
    pub border: u32,
}

impl VirtualTexture {
    /// The texture of a `width x height` image in tiles of `tile_size` texels with `border`
    /// texels of border per side: `ceil(width / payload) x ceil(height / payload)` pages at
    /// LOD 0. Panics if the border leaves no payload.
    pub fn new(width: u32, height: u32, tile_size: u32, border: u32) -> Result<VirtualTexture, GridError> {
        assert!(2 * border < tile_size, "a {tile_size}-texel tile with a {border}-texel border has no payload");
        let grid = TextureGrid::for_image(width, height, tile_size - 2 * border)?;
        Ok(VirtualTexture { grid, width, height, tile_size, border })
    }

    /// A texture whose image fills its whole page grid (`pages * payload` texels per axis).
    pub fn filling(grid: TextureGrid, tile_size: u32, border: u32) -> VirtualTexture {
        let payload = tile_size - 2 * border;
        let [w, h] = grid.pages().map(|p| u32::from(p) * payload);
        VirtualTexture { grid, width: w, height: h, tile_size, border }
    }

    /// Side of a page's own texels (the tile without its borders).
    pub fn payload(&self) -> u32 {
        self.tile_size - 2 * self.border
    }

    /// The image's width and height at LOD 0, in texels: what UV 0..1 spans.
    pub fn size(&self) -> [u32; 2] {
        [self.width, self.height]
    }
}
