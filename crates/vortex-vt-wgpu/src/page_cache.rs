//! The physical page cache: one `Rgba8Unorm` texture of `slots_per_side x slots_per_side`
//! slots, each holding one stored tile (`tile_size` texels per side, its border included).
//! Slot `s` sits at column `s % slots_per_side`, row `s / slots_per_side` (the layout
//! `vortex_vt::page_table::Entry::pack` encodes). Uploads run on the render thread, between the
//! residency update and the page-table update that maps the new pages.
//!
//! The texture's format is `Rgba8Unorm` (writable as storage on every driver, lavapipe included)
//! sampled through an `Rgba8UnormSrgb` view, so that bilinear filtering happens in linear light,
//! as the reference sampler does; tiles are RGBA8 with sRGB-encoded colour. Or, when the adapter
//! samples BC formats and the packs hold BC7 tiles, `Bc7RgbaUnorm` sampled through
//! `Bc7RgbaUnormSrgb`: the packs' blocks are uploaded as they are, a quarter of RGBA8's memory.
//! A cache of a [data layer](crate::layer::LayerKind::Data) is sampled through a plain view: its
//! values are filtered as stored.

use vortex_vt::residency::Slot;

use crate::layer::LayerKind;
use crate::readback::{Readback, ReadbackError};

/// How the cache stores texels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum CacheFormat {
    /// 4 bytes per texel; tiles are uploaded as RGBA8.
    #[default]
    Rgba8,
    /// BC1 blocks (8 bytes per 4x4 texels, opaque): an eighth of RGBA8's memory. Tiles are
    /// transcoded on the loader's threads. Needs what BC7 needs.
    Bc1,
    /// BC7 blocks (16 bytes per 4x4 texels); tiles are uploaded as blocks, rows of blocks top
    /// down. Needs `Features::TEXTURE_COMPRESSION_BC` and a tile side that is a multiple of 4.
    Bc7,
}

impl CacheFormat {
    /// Every format, largest first.
    pub const ALL: [CacheFormat; 3] = [CacheFormat::Rgba8, CacheFormat::Bc7, CacheFormat::Bc1];

    /// The format `name` names (`rgba8`, `bc1`, `bc7`).
    pub fn from_name(name: &str) -> Option<CacheFormat> {
        CacheFormat::ALL.into_iter().find(|f| f.name() == name)
    }

    /// The format in a word (`rgba8`, `bc1`, `bc7`), as the command line spells it.
    pub fn name(self) -> &'static str {
        match self {
            CacheFormat::Rgba8 => "rgba8",
            CacheFormat::Bc1 => "bc1",
            CacheFormat::Bc7 => "bc7",
        }
    }

    /// Bytes of one `tile_size²` tile in this format.
    pub fn tile_bytes(self, tile_size: u32) -> usize {
        let side = tile_size as usize;
        match self {
            CacheFormat::Rgba8 => side * side * 4,
            CacheFormat::Bc1 => (side / 4) * (side / 4) * 8,
            CacheFormat::Bc7 => (side / 4) * (side / 4) * 16,
        }
    }

    /// Bytes per row of texels (or of blocks) of one tile, and rows per tile.
    fn rows(self, tile_size: u32) -> (u32, u32) {
        match self {
            CacheFormat::Rgba8 => (tile_size * 4, tile_size),
            CacheFormat::Bc1 => (tile_size / 4 * 8, tile_size / 4),
            CacheFormat::Bc7 => (tile_size / 4 * 16, tile_size / 4),
        }
    }

    fn formats(self) -> (wgpu::TextureFormat, wgpu::TextureFormat) {
        match self {
            CacheFormat::Rgba8 => (wgpu::TextureFormat::Rgba8Unorm, wgpu::TextureFormat::Rgba8UnormSrgb),
            CacheFormat::Bc1 => (wgpu::TextureFormat::Bc1RgbaUnorm, wgpu::TextureFormat::Bc1RgbaUnormSrgb),
            CacheFormat::Bc7 => (wgpu::TextureFormat::Bc7RgbaUnorm, wgpu::TextureFormat::Bc7RgbaUnormSrgb),
        }
    }
}

/// Why a cache cannot be made.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CacheError {
    /// Slots per side outside what a page-table entry can address.
    #[error("{slots_per_side} slots per side: the page-table entry has room for 1..=256")]
    SlotsPerSide {
        /// Slots per side asked for.
        slots_per_side: u16,
    },
    /// A border that leaves no payload.
    #[error("border {border} leaves no payload in a {tile_size}-texel tile")]
    Border {
        /// Stored tile side.
        tile_size: u32,
        /// Border on each side.
        border: u32,
    },
    /// A cache larger than the device's largest 2D texture.
    #[error("a {side}-texel cache is over the device's {max}-texel 2D texture limit")]
    TooLarge {
        /// The cache's side in texels.
        side: u32,
        /// The device's largest.
        max: u32,
    },
    /// A BC cache the device or the tile size does not allow.
    #[error(
        "a BC cache needs the device feature TEXTURE_COMPRESSION_BC and a tile side that is a multiple of 4 (it is {tile_size})"
    )]
    Bc {
        /// Stored tile side.
        tile_size: u32,
    },
}

/// The physical page cache texture and its geometry.
#[derive(Debug)]
pub struct PageCache {
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    slots_per_side: u16,
    tile_size: u32,
    border: u32,
    format: CacheFormat,
}

impl PageCache {
    /// A cache of `slots_per_side²` slots of `tile_size`-texel tiles with `border` texels of border
    /// on each side, for colour. Its texels start as zero (transparent black).
    pub fn new(
        device: &wgpu::Device,
        slots_per_side: u16,
        tile_size: u32,
        border: u32,
        format: CacheFormat,
    ) -> Result<PageCache, CacheError> {
        PageCache::for_layer(device, slots_per_side, tile_size, border, format, LayerKind::Colour)
    }

    /// [`PageCache::new`] for a layer of `kind`: sampled through an sRGB view for colour, as
    /// stored for data.
    pub fn for_layer(
        device: &wgpu::Device,
        slots_per_side: u16,
        tile_size: u32,
        border: u32,
        format: CacheFormat,
        kind: LayerKind,
    ) -> Result<PageCache, CacheError> {
        if !(1..=256).contains(&slots_per_side) {
            return Err(CacheError::SlotsPerSide { slots_per_side });
        }
        if tile_size == 0 || 2 * border >= tile_size {
            return Err(CacheError::Border { tile_size, border });
        }
        if format != CacheFormat::Rgba8
            && (!tile_size.is_multiple_of(4) || !device.features().contains(wgpu::Features::TEXTURE_COMPRESSION_BC))
        {
            return Err(CacheError::Bc { tile_size });
        }
        let side = slots_per_side as u32 * tile_size;
        let max = device.limits().max_texture_dimension_2d;
        if side > max {
            return Err(CacheError::TooLarge { side, max });
        }
        let (storage, srgb) = format.formats();
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("vortex page cache"),
            size: wgpu::Extent3d { width: side, height: side, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: storage,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[srgb],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some("vortex page cache"),
            format: Some(if kind == LayerKind::Colour { srgb } else { storage }),
            ..Default::default()
        });
        Ok(PageCache { texture, view, slots_per_side, tile_size, border, format })
    }

    /// Writes one stored tile (border included, in the cache's format: `tile_size²` RGBA8 texels
    /// row-major, or BC7 blocks) into `slot`. The write lands before the next submitted command
    /// buffer runs. Panics if `slot` is outside the cache or `texels` is not exactly one tile.
    pub fn upload(&self, queue: &wgpu::Queue, slot: Slot, texels: &[u8]) {
        let ts = self.tile_size;
        assert!((slot as u32) < self.slot_count(), "slot {slot} of a cache of {} slots", self.slot_count());
        let format = self.format;
        assert_eq!(texels.len(), format.tile_bytes(ts), "a tile of {ts}x{ts} texels in {format:?}");
        let (row, rows) = format.rows(ts);
        let (x, y) = self.slot_origin(slot);
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d { x, y, z: 0 },
                aspect: wgpu::TextureAspect::All,
            },
            texels,
            wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: Some(rows) },
            wgpu::Extent3d { width: ts, height: ts, depth_or_array_layers: 1 },
        );
    }

    /// Reads the tile in `slot` back, as [`PageCache::upload`] takes it: blocking, for tests and
    /// debugging. Fails if the device is lost.
    pub fn read_slot(&self, gpu: &crate::Gpu, slot: Slot) -> Result<Vec<u8>, ReadbackError> {
        let ts = self.tile_size;
        let (tile_row, rows) = self.format.rows(ts);
        let readback = Readback::new(&gpu.device, "slot", tile_row, rows);
        let (x, y) = self.slot_origin(slot);
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        readback.encode_copy(
            &mut encoder,
            wgpu::TexelCopyTextureInfo {
                texture: &self.texture,
                mip_level: 0,
                origin: wgpu::Origin3d { x, y, z: 0 },
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::Extent3d { width: ts, height: ts, depth_or_array_layers: 1 },
        );
        gpu.queue.submit([encoder.finish()]);
        readback.read(&gpu.device)
    }

    /// Texel position of the top-left corner of `slot`.
    pub fn slot_origin(&self, slot: Slot) -> (u32, u32) {
        let side = self.slots_per_side as u32;
        (slot as u32 % side * self.tile_size, slot as u32 / side * self.tile_size)
    }

    /// Slots in all.
    pub fn slot_count(&self) -> u32 {
        (self.slots_per_side as u32).pow(2)
    }

    /// Slots per side of the square cache.
    pub fn slots_per_side(&self) -> u16 {
        self.slots_per_side
    }

    /// Side of a stored tile in texels, border included.
    pub fn tile_size(&self) -> u32 {
        self.tile_size
    }

    /// Texels of border on each side of a tile.
    pub fn border(&self) -> u32 {
        self.border
    }

    /// The format texels are held in.
    pub fn format(&self) -> CacheFormat {
        self.format
    }

    /// Side of a tile's payload (the part that is its own page): `tile_size - 2 * border`.
    pub fn payload(&self) -> u32 {
        self.tile_size - 2 * self.border
    }

    /// Side of the whole cache texture in texels.
    pub fn side_texels(&self) -> u32 {
        self.slots_per_side as u32 * self.tile_size
    }

    /// The cache texture (storage format `Rgba8Unorm`).
    pub fn texture(&self) -> &wgpu::Texture {
        &self.texture
    }

    /// The view sampling goes through: sRGB for colour, the storage format for data.
    pub fn view(&self) -> &wgpu::TextureView {
        &self.view
    }
}
