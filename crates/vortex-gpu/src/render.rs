//! The sampling pass: a full-screen triangle whose fragment shader (`shaders/sample.wgsl`) maps
//! each pixel's virtual UV through the page table to the physical page cache and samples it
//! bilinearly in linear light. Recorded and submitted on the render thread.
//!
//! For now the LOD is chosen per draw ([`ViewParams::lod`]) rather than from screen-space
//! derivatives, and the view is an axis-aligned window of the virtual texture; scenes come later.
//! [`RenderTarget`] is an `Rgba8UnormSrgb` texture that can be read back to the CPU.

use vortex_vt::sampler::Rgba8Image;

use crate::device::Gpu;
use crate::fullscreen;
use crate::page_cache::PageCache;
use crate::page_table::GpuPageTable;

/// The format of render targets: sRGB, so the linear-light samples are encoded on write.
pub const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// What one draw shows: a window of the virtual texture, sampled at one LOD.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewParams {
    /// Virtual UV of the target's top-left corner.
    pub origin: [f32; 2],
    /// Virtual UV covered by the whole target, per axis (1.0 shows the whole texture).
    pub extent: [f32; 2],
    /// The LOD whose page-table level is read (the entry then names the resident LOD sampled).
    pub lod: u8,
}

impl ViewParams {
    /// The whole texture at `lod`.
    pub fn whole(lod: u8) -> ViewParams {
        ViewParams { origin: [0.0; 2], extent: [1.0; 2], lod }
    }

    /// The virtual UV that pixel (`x`, `y`) of a `width x height` target samples (at its centre),
    /// computed as the shader does.
    pub fn uv(&self, x: u32, y: u32, width: u32, height: u32) -> [f32; 2] {
        let step = [self.extent[0] / width as f32, self.extent[1] / height as f32];
        [self.origin[0] + (x as f32 + 0.5) * step[0], self.origin[1] + (y as f32 + 0.5) * step[1]]
    }
}

/// The uniform block of `sample.wgsl` (`Params`), 48 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    window: [f32; 4],
    pages: u32,
    lod: u32,
    pad: [u32; 2],
    tile: [f32; 4],
}

/// The pipeline and sampler of the sampling pass, made once per device.
#[derive(Debug)]
pub struct SamplePass {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
}

impl SamplePass {
    pub fn new(device: &wgpu::Device) -> SamplePass {
        let module = fullscreen::shader(device, "vortex sample.wgsl", include_str!("shaders/sample.wgsl"));
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty,
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vortex sample"),
            entries: &[
                entry(
                    0,
                    wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: wgpu::BufferSize::new(size_of::<Params>() as u64),
                    },
                ),
                entry(
                    1,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                ),
                entry(
                    2,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                ),
                entry(3, wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering)),
            ],
        });
        let pipeline = fullscreen::pipeline(device, "vortex sample", &module, &layout, TARGET_FORMAT);
        // Bilinear within a slot; the border makes the neighbouring slots' texels unreachable, so
        // the address mode only matters at the cache's outer edge.
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("vortex page cache"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Nearest,
            ..Default::default()
        });
        SamplePass { pipeline, layout, sampler }
    }

    /// Records one draw of `view` into `target`, reading `table` and `cache`.
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        target: &RenderTarget,
        cache: &PageCache,
        table: &GpuPageTable,
        view: &ViewParams,
    ) {
        let (w, h) = (target.width as f32, target.height as f32);
        let params = Params {
            window: [view.origin[0], view.origin[1], view.extent[0] / w, view.extent[1] / h],
            pages: table.grid().pages as u32,
            lod: view.lod.min(table.grid().lod_count - 1) as u32,
            pad: [0; 2],
            tile: [cache.tile_size() as f32, cache.border() as f32, cache.payload() as f32, cache.side_texels() as f32],
        };
        let uniform = fullscreen::uniform(device, "vortex sample params", bytemuck::bytes_of(&params));
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vortex sample"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(table.view()) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(cache.srgb_view()) },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::Sampler(&self.sampler) },
            ],
        });
        fullscreen::record(
            encoder,
            "vortex sample",
            &target.view,
            wgpu::Color::TRANSPARENT,
            Some((&self.pipeline, &bind_group)),
        );
    }

    /// Draws `view` into `target`, submits, and reads the result back (blocking).
    pub fn render_and_read(
        &self,
        gpu: &Gpu,
        target: &RenderTarget,
        cache: &PageCache,
        table: &GpuPageTable,
        view: &ViewParams,
    ) -> Rgba8Image {
        let mut encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex frame") });
        self.encode(&gpu.device, &mut encoder, target, cache, table, view);
        target.encode_copy_out(&mut encoder);
        gpu.queue.submit([encoder.finish()]);
        target.read(gpu)
    }
}

/// An `Rgba8UnormSrgb` colour target with a buffer to read it back through.
#[derive(Debug)]
pub struct RenderTarget {
    pub width: u32,
    pub height: u32,
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    readback: wgpu::Buffer,
    /// Bytes per row in `readback`: a multiple of 256, as buffer copies require.
    padded_row: u32,
}

impl RenderTarget {
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> RenderTarget {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("vortex target"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: TARGET_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let padded_row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vortex target readback"),
            size: padded_row as u64 * height as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        RenderTarget { width, height, texture, view, readback, padded_row }
    }

    pub fn view(&self) -> &wgpu::TextureView {
        &self.view
    }

    /// Records the copy of the target into its readback buffer.
    pub fn encode_copy_out(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.copy_texture_to_buffer(
            self.texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.padded_row),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 },
        );
    }

    /// Maps the readback buffer (after a submitted [`RenderTarget::encode_copy_out`]) and returns
    /// its texels; blocks until the GPU is done.
    pub fn read(&self, gpu: &Gpu) -> Rgba8Image {
        let slice = self.readback.slice(..);
        slice.map_async(wgpu::MapMode::Read, |r| r.expect("mapping the readback buffer"));
        gpu.wait_idle();
        let texels = {
            let bytes = slice.get_mapped_range().expect("the readback buffer is mapped");
            bytes
                .chunks_exact(self.padded_row as usize)
                .flat_map(|row| row[..self.width as usize * 4].chunks_exact(4).map(|t| [t[0], t[1], t[2], t[3]]))
                .collect()
        };
        self.readback.unmap();
        Rgba8Image { width: self.width, height: self.height, texels }
    }
}
