//! The module's uniform block (`VtParams` in `shaders/vt.wgsl`): the textures' shapes, the
//! cache's geometry, the filter, and this frame's feedback settings. Written by the runtime
//! whenever one of them changes (every frame, since the elected feedback pixel moves).

use vortex_vt::page::MAX_TEXTURES;

use crate::page_cache::PageCache;
use crate::sample::SampleFilter;
use crate::texture::VirtualTexture;

/// `VtTextureInfo` in `vt.wgsl`, 32 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct TextureInfo {
    size: [u32; 2],
    lod_count: u32,
    payload: u32,
    pages: [u32; 2],
    pad: [u32; 2],
}

/// `VtParams` in `vt.wgsl`, 576 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Params {
    tile: [f32; 4],
    /// Block side in pixels, blocks per row, blocks per column, words.
    feedback: [u32; 4],
    elect: [u32; 2],
    feedback_bias: f32,
    filter: u32,
    /// Bit `k` set: layer `k`'s cache holds straight alpha (BC7 blocks as stored).
    straight_alpha: u32,
    layers: u32,
    pad: [u32; 2],
    textures: [TextureInfo; MAX_TEXTURES as usize],
}

/// How the feedback of one frame is gathered: blocks of `block` pixels, `columns x rows` of them,
/// each written by its pixel `elect`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct FeedbackLayout {
    pub(crate) block: u32,
    pub(crate) columns: u32,
    pub(crate) rows: u32,
    pub(crate) elect: [u32; 2],
}

impl Params {
    pub(crate) fn new(
        textures: &[VirtualTexture],
        cache: &PageCache,
        filter: SampleFilter,
        feedback: FeedbackLayout,
        feedback_bias: f32,
        straight_alpha: u32,
        layers: u32,
    ) -> Params {
        assert!(textures.len() <= MAX_TEXTURES as usize, "{} textures, at most {MAX_TEXTURES}", textures.len());
        let mut infos = [TextureInfo::default(); MAX_TEXTURES as usize];
        for (info, t) in infos.iter_mut().zip(textures) {
            *info = TextureInfo {
                size: t.size(),
                lod_count: u32::from(t.grid.lod_count()),
                payload: t.payload(),
                pages: t.grid.pages().map(u32::from),
                pad: [0; 2],
            };
        }
        let FeedbackLayout { block, columns, rows, elect } = feedback;
        Params {
            tile: [cache.tile_size() as f32, cache.border() as f32, cache.payload() as f32, cache.side_texels() as f32],
            feedback: [block, columns, rows, columns * rows],
            elect,
            feedback_bias,
            filter: filter as u32,
            straight_alpha,
            layers,
            pad: [0; 2],
            textures: infos,
        }
    }
}
