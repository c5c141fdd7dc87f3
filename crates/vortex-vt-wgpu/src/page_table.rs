//! The page table on the GPU: one storage buffer of `u32` holding every texture's every LOD,
//! each texel the packed entry of `vortex_vt`'s [`PageTable`] ([`Entry::pack`]: slot column, slot
//! row, LOD of the page it points at). Updated on the render thread after the frame's tiles are
//! uploaded, from the [`Change`]s that [`PageTable::apply`] returns, so only the entries whose
//! value changed are written.
//!
//! # Why a buffer, not a texture per LOD
//!
//! A texture's real page grid is `w x h` pages at LOD 0, of any aspect ratio: a 2^20 x 2^10-texel
//! image in 64-texel pages is 16384 x 16 pages. A 2D texture (array) of the largest grid, one mip
//! level per LOD, would need each side within the device's largest 2D texture (16384 on lavapipe
//! and most GPUs, so a grid of 2^14 pages has no room left, and wider ones none at all) and one
//! square-ish layer per texture sized for the largest (a 8739 x 9 grid in a layer of a 8739 x
//! 8739 texture wastes 300 MB). A buffer holds exactly the entries of the real grids, in any
//! shape, within the device's largest storage-buffer binding (128 MiB by default: 2^25 entries;
//! the largest grid the feedback word allows, 2^24 pages at LOD 0, needs 4/3 of 2^24).
//!
//! # Layout
//!
//! ```text
//! word 0 .. 256            header: word t * 16 + l is the index of entry (0, 0) of texture t's
//!                          LOD l (0 where the texture or LOD does not exist)
//! word 256 ..              texture 0: LOD 0 row by row (w_0 x h_0 entries), LOD 1, ... the root;
//!                          then texture 1, ...
//! ```
//!
//! The shader reads `page_table[page_table[t * 16 + l] + y * w_l + x]` with `w_l` the LOD's
//! pages per row, `((w_0 - 1) >> l) + 1`.
//!
//! [`Entry::pack`]: vortex_vt::page_table::Entry::pack

use vortex_vt::page::{MAX_TEXTURES, TextureGrid};
use vortex_vt::page_table::{Change, PageTable, UNMAPPED_WORD};

/// Header words: one per texture and LOD slot.
const HEADER: usize = MAX_TEXTURES as usize * 16;

/// Why the page table cannot be made on this device.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PageTableError {
    /// The tables are larger than the device lets a shader bind.
    #[error(
        "the page tables of {textures} texture(s) need {bytes} bytes, over the device's largest storage buffer binding of {max} bytes"
    )]
    TooLarge {
        /// Textures.
        textures: usize,
        /// Bytes their tables need.
        bytes: u64,
        /// The device's largest storage buffer binding.
        max: u64,
    },
    /// No texture given.
    #[error("a page table for no texture")]
    NoTextures,
}

/// The page table of every virtual texture of a scene, in one storage buffer.
#[derive(Debug)]
pub struct GpuPageTable {
    buffer: wgpu::Buffer,
    grids: Vec<TextureGrid>,
    /// Word index of entry (0, 0) of each texture's each LOD (the header's values).
    base: Vec<[u32; 16]>,
    cache_side: u16,
}

impl GpuPageTable {
    /// The table of textures `grids` (texture id = index), for a cache of `cache_side` slots per
    /// side; every entry starts [unmapped](UNMAPPED_WORD). Fails if the entries do not fit in one
    /// storage-buffer binding of `device`.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        grids: &[TextureGrid],
        cache_side: u16,
    ) -> Result<GpuPageTable, PageTableError> {
        if grids.is_empty() {
            return Err(PageTableError::NoTextures);
        }
        let mut header = vec![0u32; HEADER];
        let mut base = Vec::with_capacity(grids.len());
        let mut len = HEADER as u64;
        for (t, g) in grids.iter().enumerate() {
            let mut b = [0u32; 16];
            for lod in 0..g.lod_count() {
                // Within u32: checked against the binding size (at most 2^32 bytes) below first.
                b[lod as usize] = len.min(u64::from(u32::MAX)) as u32;
                header[t * 16 + lod as usize] = b[lod as usize];
                len += g.level_len(lod) as u64;
            }
            base.push(b);
        }
        let bytes = len * 4;
        let max = device.limits().max_storage_buffer_binding_size.min(device.limits().max_buffer_size);
        if bytes > max {
            return Err(PageTableError::TooLarge { textures: grids.len(), bytes, max });
        }
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vortex page table"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        queue.write_buffer(&buffer, 0, bytemuck::cast_slice(&header));
        let table = GpuPageTable { buffer, grids: grids.to_vec(), base, cache_side };
        for (t, grid) in grids.iter().enumerate() {
            for lod in 0..grid.lod_count() {
                table.write_level(queue, t as u8, lod, &vec![UNMAPPED_WORD; grid.level_len(lod)]);
            }
        }
        Ok(table)
    }

    /// Uploads every LOD of every texture from `table` (the first frame, or after a reset).
    pub fn write_all(&self, queue: &wgpu::Queue, table: &PageTable) {
        for (t, grid) in self.grids.iter().enumerate() {
            for lod in 0..grid.lod_count() {
                self.write_level(queue, t as u8, lod, &table.packed_level(t as u8, lod, self.cache_side));
            }
        }
    }

    /// Uploads the entries that changed. Runs of horizontally adjacent changes in a row are
    /// written together; other entries are written one by one. An entry may change more than
    /// once (changes gathered from several `apply_mappings`): the later change wins, since the
    /// sort is stable and the writes land in order.
    pub fn write_changes(&self, queue: &wgpu::Queue, changes: &[Change]) {
        let mut mine: Vec<(u8, u8, u16, u16, u32)> =
            changes.iter().map(|c| (c.at.texture, c.at.lod, c.at.y, c.at.x, c.entry.pack(self.cache_side))).collect();
        mine.sort_by_key(|&(t, lod, y, x, _)| (t, lod, y, x));
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
            self.write_words(queue, self.index(t, lod, x0, y), &run);
        }
    }

    /// Uploads a whole LOD level of one texture (`w x h` packed entries, row-major).
    pub fn write_level(&self, queue: &wgpu::Queue, texture: u8, lod: u8, words: &[u32]) {
        let grid = self.grids[texture as usize];
        let [w, h] = grid.pages_at(lod);
        assert_eq!(words.len(), grid.level_len(lod), "LOD {lod} has {w}x{h} entries");
        self.write_words(queue, self.index(texture, lod, 0, 0), words);
    }

    /// Word index of the entry of page (`x`, `y`) of `lod` of `texture`.
    fn index(&self, texture: u8, lod: u8, x: u16, y: u16) -> u64 {
        let grid = self.grids[texture as usize];
        u64::from(self.base[texture as usize][lod as usize]) + u64::from(grid.index(lod, x, y))
    }

    fn write_words(&self, queue: &wgpu::Queue, index: u64, words: &[u32]) {
        queue.write_buffer(&self.buffer, index * 4, bytemuck::cast_slice(words));
    }

    /// The textures' grids, by texture id.
    pub fn grids(&self) -> &[TextureGrid] {
        &self.grids
    }

    /// Slots per side of the cache its entries point into.
    pub fn cache_side(&self) -> u16 {
        self.cache_side
    }

    /// The storage buffer (header and entries, see the module documentation), for binding.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }
}
