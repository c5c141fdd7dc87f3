//! The uniform block both passes read (`Frame` in `shaders/virtual.wgsl`), built on the render
//! thread once per draw.

use vortex_vt::page::MAX_TEXTURES;

use crate::page_cache::PageCache;
use crate::texture::VirtualTexture;
use crate::view::View;

/// `Texture` in `virtual.wgsl`, 32 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct TextureParams {
    size: [u32; 2],
    lod_count: u32,
    payload: u32,
    pages: [u32; 2],
    pad: [u32; 2],
}

/// `Frame` in `virtual.wgsl`, 656 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Frame {
    view_proj: [[f32; 4]; 4],
    origin_int: [u32; 2],
    origin_frac: [f32; 2],
    step: [f32; 2],
    window_texture: u32,
    lod_override: f32,
    tile: [f32; 4],
    bias: f32,
    pad0: f32,
    jitter: [f32; 2],
    jitter_ndc: [f32; 2],
    pad1: [f32; 2],
    textures: [TextureParams; MAX_TEXTURES as usize],
}

impl Frame {
    /// Samples at `jitter` (in pixels, within ±0.5) from each pixel's centre instead of at it.
    pub(crate) fn jittered(mut self, jitter: [f32; 2], size: (u32, u32)) -> Frame {
        self.jitter = jitter;
        // Sampling a point `j` to the right (and down) is drawing the image `j` to the left
        // (and up); clip-space y points up, framebuffer y down.
        self.jitter_ndc = [-2.0 * jitter[0] / size.0 as f32, 2.0 * jitter[1] / size.1 as f32];
        self
    }

    /// The parameters of drawing `view` into a `size` target: `bias` is added to every LOD,
    /// `lod_override` (sampling only) replaces the LOD from derivatives.
    pub(crate) fn new(
        textures: &[VirtualTexture],
        cache: Option<&PageCache>,
        view: &View,
        size: (u32, u32),
        bias: f32,
        lod_override: Option<f32>,
    ) -> Frame {
        assert!(textures.len() <= MAX_TEXTURES as usize, "{} textures, at most {MAX_TEXTURES}", textures.len());
        let mut params = [TextureParams::default(); MAX_TEXTURES as usize];
        for (p, t) in params.iter_mut().zip(textures) {
            *p = TextureParams {
                size: t.size(),
                lod_count: u32::from(t.grid.lod_count()),
                payload: t.payload(),
                pages: t.grid.pages().map(u32::from),
                ..TextureParams::default()
            };
        }
        let mut frame = Frame {
            view_proj: IDENTITY,
            origin_int: [0; 2],
            origin_frac: [0.0; 2],
            step: [0.0; 2],
            window_texture: 0,
            lod_override: lod_override.unwrap_or(-1.0),
            tile: cache.map_or([0.0; 4], |c| {
                [c.tile_size() as f32, c.border() as f32, c.payload() as f32, c.side_texels() as f32]
            }),
            bias,
            pad0: 0.0,
            jitter: [0.0; 2],
            jitter_ndc: [0.0; 2],
            pad1: [0.0; 2],
            textures: params,
        };
        match view {
            View::Window(w) => {
                let t = &textures[w.texture as usize];
                let o = w.origin_texels(t, size);
                frame.origin_int = o.int;
                frame.origin_frac = o.frac;
                frame.step = o.step;
                frame.window_texture = w.texture as u32;
            }
            View::Meshes { view_proj, .. } => frame.view_proj = *view_proj,
        }
        frame
    }
}

const IDENTITY: [[f32; 4]; 4] =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
