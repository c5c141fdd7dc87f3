//! The sampling pass: draws a [`View`] whose fragment shader (`shaders/sample.wgsl`) maps each
//! fragment's address through the page table to the physical page cache and samples it in
//! linear light (nearest, bilinear, or trilinear across two LODs: [`SampleFilter`]). The LOD
//! comes from the screen-space footprint, or is fixed per draw for tests. Recorded and submitted
//! on the render thread. [`RenderTarget`] is an `Rgba8UnormSrgb` texture with a depth buffer that
//! can be read back to the CPU.
//!
//! The module is named after the shader it drives, as `feedback` is: the two passes of a frame.
//! The filter is a `SampleFilter`, not a `Filter`, so that it is never mistaken for the tiler's
//! LOD filter (how a pyramid level is reduced from the one above), which is another thing.

use vortex_vt::sampler::Rgba8Image;

use crate::device::Gpu;
use crate::draw::{self, Pipelines, Target};
use crate::page_cache::PageCache;
use crate::page_table::GpuPageTable;
use crate::params::Frame;
use crate::readback::{Readback, ReadbackError};
use crate::texture::VirtualTexture;
use crate::view::View;

/// The format of render targets: sRGB, so the linear-light samples are encoded on write.
pub const TARGET_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// How the sampling pass filters the cache. Only trilinear reads two LODs per sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SampleFilter {
    Nearest,
    #[default]
    Bilinear,
    /// Bilinear in the LOD below and above the footprint, blended.
    Trilinear,
}

impl SampleFilter {
    /// Every filter, cheapest first.
    pub const ALL: [SampleFilter; 3] = [SampleFilter::Nearest, SampleFilter::Bilinear, SampleFilter::Trilinear];

    /// The name scenes and reports use.
    pub fn name(self) -> &'static str {
        match self {
            SampleFilter::Nearest => "nearest",
            SampleFilter::Bilinear => "bilinear",
            SampleFilter::Trilinear => "trilinear",
        }
    }
}

/// What a draw samples from: the textures' shapes, the page table and the cache.
#[derive(Clone, Copy, Debug)]
pub struct Sources<'a> {
    pub textures: &'a [VirtualTexture],
    pub table: &'a GpuPageTable,
    pub cache: &'a PageCache,
}

/// The pipelines and sampler of the sampling pass with one [`SampleFilter`], made once per device.
#[derive(Debug)]
pub struct SamplePass {
    pipelines: Pipelines,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    filter: SampleFilter,
}

impl SamplePass {
    pub fn new(device: &wgpu::Device, filter: SampleFilter) -> SamplePass {
        let module = draw::shader(device, "vortex sample.wgsl", include_str!("shaders/sample.wgsl"));
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
            ty,
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vortex sample"),
            entries: &[
                draw::frame_entry(),
                entry(
                    1,
                    wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
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
        let constants = [("FILTER", filter as u32 as f64)];
        let pipelines = Pipelines::new(device, "vortex sample", &module, &layout, TARGET_FORMAT, &constants);
        // Within a slot only: the border (or the shader's clamp) keeps neighbouring slots'
        // texels out, so the address mode only matters at the cache's outer edge.
        let mode = if filter == SampleFilter::Nearest { wgpu::FilterMode::Nearest } else { wgpu::FilterMode::Linear };
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("vortex page cache"),
            mag_filter: mode,
            min_filter: mode,
            mipmap_filter: wgpu::MipmapFilterMode::Nearest,
            ..Default::default()
        });
        SamplePass { pipelines, layout, sampler, filter }
    }

    pub fn filter(&self) -> SampleFilter {
        self.filter
    }

    /// Records one draw of `view` into `target`. `lod` fixes the LOD sampled everywhere (tests);
    /// `None` takes it from each fragment's footprint.
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        target: &RenderTarget,
        sources: &Sources,
        view: &View,
        lod: Option<f32>,
    ) {
        let frame = Frame::new(sources.textures, Some(sources.cache), view, (target.width, target.height), 0.0, lod);
        let uniform = draw::uniform(device, "vortex sample frame", bytemuck::bytes_of(&frame));
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vortex sample"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: uniform.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: sources.table.buffer().as_entire_binding() },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(sources.cache.srgb_view()),
                },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::Sampler(&self.sampler) },
            ],
        });
        let draw = Some((&self.pipelines, &bind_group, view));
        target.target.record(encoder, "vortex sample", wgpu::Color::TRANSPARENT, draw);
    }

    /// Draws `view` into `target`, submits, and reads the result back (blocking).
    pub fn render_and_read(
        &self,
        gpu: &Gpu,
        target: &RenderTarget,
        sources: &Sources,
        view: &View,
        lod: Option<f32>,
    ) -> Result<Rgba8Image, ReadbackError> {
        let mut encoder =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex frame") });
        self.encode(&gpu.device, &mut encoder, target, sources, view, lod);
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
    target: Target,
    readback: Readback,
}

impl RenderTarget {
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> RenderTarget {
        let target = Target::new(device, "vortex target", TARGET_FORMAT, width, height);
        let readback = Readback::new(device, "target", width * 4, height);
        RenderTarget { width, height, target, readback }
    }

    pub fn view(&self) -> &wgpu::TextureView {
        &self.target.view
    }

    /// Records the copy of the target into its readback buffer.
    pub fn encode_copy_out(&self, encoder: &mut wgpu::CommandEncoder) {
        let (source, extent) = self.target.copy_source();
        self.readback.encode_copy(encoder, source, extent);
    }

    /// Maps the readback buffer (after a submitted [`RenderTarget::encode_copy_out`]) and returns
    /// its texels; blocks until the GPU is done. Fails if the device is lost.
    pub fn read(&self, gpu: &Gpu) -> Result<Rgba8Image, ReadbackError> {
        let bytes = self.readback.read(&gpu.device)?;
        let texels = bytes.chunks_exact(4).map(|t| [t[0], t[1], t[2], t[3]]).collect();
        Ok(Rgba8Image { width: self.width, height: self.height, texels })
    }
}
