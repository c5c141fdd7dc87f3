//! The address probe: draws a [`View`] writing each pixel's address (page and position in it, at
//! a fixed LOD) instead of a colour, and reads it back. For tests of the shaders' address
//! translation against `vortex_vt::address` and exact arithmetic; blocking, render thread.

use vortex_vt::address::At;

use crate::device::Gpu;
use crate::draw::{self, Pipelines};
use crate::params::Frame;
use crate::texture::VirtualTexture;
use crate::view::View;

const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;

/// The probe's pipelines.
#[derive(Debug)]
pub struct AddressProbe {
    pipelines: Pipelines,
    layout: wgpu::BindGroupLayout,
}

impl AddressProbe {
    pub fn new(device: &wgpu::Device) -> AddressProbe {
        let module = draw::shader(device, "vortex probe.wgsl", include_str!("shaders/probe.wgsl"));
        let layout = draw::frame_only_layout(device, "vortex probe");
        AddressProbe { pipelines: Pipelines::new(device, "vortex probe", &module, &layout, FORMAT, &[]), layout }
    }

    /// The address of every pixel of a `width x height` draw of `view` at `lod`, row-major.
    pub fn addresses(
        &self,
        gpu: &Gpu,
        textures: &[VirtualTexture],
        view: &View,
        lod: u8,
        width: u32,
        height: u32,
    ) -> Vec<At> {
        let device = &gpu.device;
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("vortex probe"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let colour = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let depth = draw::depth_texture(device, width, height);
        let frame = Frame::new(textures, None, view, (width, height), 0.0, Some(lod as f32));
        let bind_group = draw::frame_only_bind_group(device, "vortex probe", &self.layout, &frame);
        let row = (width * 16).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vortex probe readback"),
            size: row as u64 * height as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex probe") });
        let black = wgpu::Color::TRANSPARENT;
        draw::record(&mut encoder, "vortex probe", &colour, &depth, black, Some((&self.pipelines, &bind_group, view)));
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
        gpu.queue.submit([encoder.finish()]);
        buffer.slice(..).map_async(wgpu::MapMode::Read, |r| r.expect("mapping the probe buffer"));
        gpu.wait_idle();
        let bytes = buffer.slice(..).get_mapped_range().expect("the probe buffer is mapped");
        let word = |b: &[u8], i: usize| u32::from_le_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]]);
        bytes
            .chunks_exact(row as usize)
            .flat_map(|r| {
                r[..width as usize * 16].chunks_exact(16).map(|t| At {
                    page: [word(t, 0), word(t, 1)],
                    within: [f32::from_bits(word(t, 2)), f32::from_bits(word(t, 3))],
                })
            })
            .collect()
    }
}
