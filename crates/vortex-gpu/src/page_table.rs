//! The page table on the GPU: one `R32Uint` texture per virtual texture, `pages x pages` texels
//! at mip 0 and one mip level per LOD, each texel the packed entry of `vortex_vt`'s
//! [`PageTable`] ([`Entry::pack`]: slot column, slot row, LOD of the page it points at). Updated
//! on the render thread after the frame's tiles are uploaded, from the [`Change`]s that
//! [`PageTable::apply`] returns, so only the texels whose value changed are written.
//!
//! [`Entry::pack`]: vortex_vt::page_table::Entry::pack

use vortex_vt::page::TextureGrid;
use vortex_vt::page_table::{Change, PageTable, UNMAPPED_WORD};

/// The page-table texture of one virtual texture.
#[derive(Debug)]
pub struct GpuPageTable {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    texture_id: u8,
    grid: TextureGrid,
    cache_side: u16,
}

impl GpuPageTable {
    /// The table of texture `texture_id` with grid `grid`, for a cache of `cache_side` slots per
    /// side; every entry starts [unmapped](UNMAPPED_WORD).
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        texture_id: u8,
        grid: TextureGrid,
        cache_side: u16,
    ) -> GpuPageTable {
        let side = grid.pages as u32;
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("vortex page table"),
            size: wgpu::Extent3d { width: side, height: side, depth_or_array_layers: 1 },
            mip_level_count: grid.lod_count as u32,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::R32Uint,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let table = GpuPageTable { texture, view, texture_id, grid, cache_side };
        for lod in 0..grid.lod_count {
            let n = (grid.pages_per_side(lod) as usize).pow(2);
            table.write_level(queue, lod, &vec![UNMAPPED_WORD; n]);
        }
        table
    }

    /// Uploads every LOD of this texture from `table` (the first frame, or after a reset).
    pub fn write_all(&self, queue: &wgpu::Queue, table: &PageTable) {
        for lod in 0..self.grid.lod_count {
            self.write_level(queue, lod, &table.packed_level(self.texture_id, lod, self.cache_side));
        }
    }

    /// Uploads the entries that changed. Changes of other textures are ignored, so one frame's
    /// whole list can be handed to every table. Runs of horizontally adjacent changes in a row are
    /// written together; other entries are written one by one.
    pub fn write_changes(&self, queue: &wgpu::Queue, changes: &[Change]) {
        let mut mine: Vec<(u8, u16, u16, u32)> = changes
            .iter()
            .filter(|c| c.at.texture == self.texture_id)
            .map(|c| (c.at.lod, c.at.y, c.at.x, c.entry.pack(self.cache_side)))
            .collect();
        mine.sort_unstable_by_key(|&(lod, y, x, _)| (lod, y, x));
        let mut run: Vec<u32> = Vec::new();
        let mut i = 0;
        while i < mine.len() {
            let (lod, y, x0, _) = mine[i];
            run.clear();
            while let Some(&(l, yy, x, word)) = mine.get(i) {
                if l != lod || yy != y || x != x0 + run.len() as u16 {
                    break;
                }
                run.push(word);
                i += 1;
            }
            self.write_rect(queue, lod, x0 as u32, y as u32, run.len() as u32, 1, &run);
        }
    }

    /// Uploads a whole LOD level (`pages_per_side(lod)²` packed entries, row-major).
    pub fn write_level(&self, queue: &wgpu::Queue, lod: u8, words: &[u32]) {
        let side = self.grid.pages_per_side(lod) as u32;
        assert_eq!(words.len(), (side * side) as usize, "LOD {lod} has {side}x{side} entries");
        self.write_rect(queue, lod, 0, 0, side, side, words);
    }

    #[allow(clippy::too_many_arguments)]
    fn write_rect(&self, queue: &wgpu::Queue, lod: u8, x: u32, y: u32, w: u32, h: u32, words: &[u32]) {
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: lod as u32,
                origin: wgpu::Origin3d { x, y, z: 0 },
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(words),
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(w * 4), rows_per_image: Some(h) },
            wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        );
    }

    pub fn texture_id(&self) -> u8 {
        self.texture_id
    }

    pub fn grid(&self) -> TextureGrid {
        self.grid
    }

    pub fn cache_side(&self) -> u16 {
        self.cache_side
    }

    /// A view of all its mip levels (one per LOD), for `textureLoad`.
    pub fn view(&self) -> &wgpu::TextureView {
        &self.view
    }

    pub fn texture(&self) -> &wgpu::Texture {
        &self.texture
    }
}
