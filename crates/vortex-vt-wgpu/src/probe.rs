//! The address probe: draws a [`View`] writing each pixel's address (page and position in it, at
//! a fixed LOD) instead of a colour, and reads it back. For tests of the shaders' address
//! translation against `vortex_vt::address` and exact arithmetic; blocking, render thread.

use vortex_vt::address::At;

use crate::device::Gpu;
use crate::draw::{self, Pipelines, Target};
use crate::params::Frame;
use crate::readback::{Readback, ReadbackError};
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
    /// Blocking; fails if the device is lost.
    pub fn addresses(
        &self,
        gpu: &Gpu,
        textures: &[VirtualTexture],
        view: &View,
        lod: u8,
        width: u32,
        height: u32,
    ) -> Result<Vec<At>, ReadbackError> {
        let device = &gpu.device;
        let target = Target::new(device, "vortex probe", FORMAT, width, height);
        let frame = Frame::new(textures, None, view, (width, height), 0.0, Some(lod as f32));
        let bind_group = draw::frame_only_bind_group(device, "vortex probe", &self.layout, &frame);
        let readback = Readback::new(device, "probe", width * 16, height);
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex probe") });
        let black = wgpu::Color::TRANSPARENT;
        target.record(&mut encoder, "vortex probe", black, Some((&self.pipelines, &bind_group, view)));
        let (source, extent) = target.copy_source();
        readback.encode_copy(&mut encoder, source, extent);
        gpu.queue.submit([encoder.finish()]);
        let bytes = readback.read(device)?;
        let word = |b: &[u8], i: usize| u32::from_le_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]]);
        Ok(bytes
            .chunks_exact(16)
            .map(|t| At {
                page: [word(t, 0), word(t, 1)],
                within: [f32::from_bits(word(t, 2)), f32::from_bits(word(t, 3))],
            })
            .collect())
    }
}
