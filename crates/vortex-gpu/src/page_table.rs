//! The page table on the GPU: one `R32Uint` 2D array texture, one layer per virtual texture (its
//! texture id), `pages x pages` texels at mip 0 (the largest texture's pages; smaller textures use
//! the top-left corner) and one mip level per LOD, each texel the packed entry of `vortex_vt`'s
//! [`PageTable`] ([`Entry::pack`]: slot column, slot row, LOD of the page it points at). Updated
//! on the render thread after the frame's tiles are uploaded, from the [`Change`]s that
//! [`PageTable::apply`] returns, so only the texels whose value changed are written.
//!
//! [`Entry::pack`]: vortex_vt::page_table::Entry::pack

use vortex_vt::page::TextureGrid;
use vortex_vt::page_table::{Change, PageTable, UNMAPPED_WORD};

/// The page-table texture of every virtual texture of a scene.
#[derive(Debug)]
pub struct GpuPageTable {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    grids: Vec<TextureGrid>,
    cache_side: u16,
}

impl GpuPageTable {
    /// The table of textures `grids` (texture id = index), for a cache of `cache_side` slots per
    /// side; every entry starts [unmapped](UNMAPPED_WORD).
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, grids: &[TextureGrid], cache_side: u16) -> GpuPageTable {
        assert!(!grids.is_empty(), "a page table for no texture");
        let side = grids.iter().map(|g| g.pages as u32).max().unwrap_or(1);
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("vortex page table"),
            size: wgpu::Extent3d { width: side, height: side, depth_or_array_layers: grids.len() as u32 },
            mip_level_count: side.trailing_zeros() + 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::R32Uint,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let table = GpuPageTable { texture, view, grids: grids.to_vec(), cache_side };
        for (t, grid) in grids.iter().enumerate() {
            for lod in 0..grid.lod_count {
                let n = (grid.pages_per_side(lod) as usize).pow(2);
                table.write_level(queue, t as u8, lod, &vec![UNMAPPED_WORD; n]);
            }
        }
        table
    }

    /// Uploads every LOD of every texture from `table` (the first frame, or after a reset).
    pub fn write_all(&self, queue: &wgpu::Queue, table: &PageTable) {
        for (t, grid) in self.grids.iter().enumerate() {
            for lod in 0..grid.lod_count {
                self.write_level(queue, t as u8, lod, &table.packed_level(t as u8, lod, self.cache_side));
            }
        }
    }

    /// Uploads the entries that changed. Runs of horizontally adjacent changes in a row are
    /// written together; other entries are written one by one.
    pub fn write_changes(&self, queue: &wgpu::Queue, changes: &[Change]) {
        let mut mine: Vec<(u8, u8, u16, u16, u32)> =
            changes.iter().map(|c| (c.at.texture, c.at.lod, c.at.y, c.at.x, c.entry.pack(self.cache_side))).collect();
        mine.sort_unstable_by_key(|&(t, lod, y, x, _)| (t, lod, y, x));
        let mut run: Vec<u32> = Vec::new();
        let mut i = 0;
        while i < mine.len() {
            let (t, lod, y, x0, _) = mine[i];
            run.clear();
            while let Some(&(tt, l, yy, x, word)) = mine.get(i) {
                if tt != t || l != lod || yy != y || x != x0 + run.len() as u16 {
                    break;
                }
                run.push(word);
                i += 1;
            }
            self.write_rect(queue, t, lod, [x0 as u32, y as u32], [run.len() as u32, 1], &run);
        }
    }

    /// Uploads a whole LOD level of one texture (`pages_per_side(lod)²` packed entries,
    /// row-major).
    pub fn write_level(&self, queue: &wgpu::Queue, texture: u8, lod: u8, words: &[u32]) {
        let side = self.grids[texture as usize].pages_per_side(lod) as u32;
        assert_eq!(words.len(), (side * side) as usize, "LOD {lod} has {side}x{side} entries");
        self.write_rect(queue, texture, lod, [0, 0], [side, side], words);
    }

    fn write_rect(&self, queue: &wgpu::Queue, texture: u8, lod: u8, at: [u32; 2], size: [u32; 2], words: &[u32]) {
        let [w, h] = size;
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: lod as u32,
                origin: wgpu::Origin3d { x: at[0], y: at[1], z: texture as u32 },
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(words),
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(w * 4), rows_per_image: Some(h) },
            wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        );
    }

    pub fn grids(&self) -> &[TextureGrid] {
        &self.grids
    }

    pub fn cache_side(&self) -> u16 {
        self.cache_side
    }

    /// A 2D-array view of all its layers and mip levels (one per LOD), for `textureLoad`.
    pub fn view(&self) -> &wgpu::TextureView {
        &self.view
    }

    pub fn texture(&self) -> &wgpu::Texture {
        &self.texture
    }
}
