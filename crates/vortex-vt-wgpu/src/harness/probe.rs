//! The address probe: draws a [`View`] writing each pixel's address (page and position in it, at
//! a fixed LOD) instead of a colour, and reads it back. For tests of the module's address
//! translation against `vortex_vt::address` and exact arithmetic; blocking, render thread. It
//! needs no pages: its page table and cache are placeholders, only the textures' shapes count.

use vortex_vt::address::At;

use super::draw::{self, Pipelines, Target};
use super::frame::Frame;
use super::view::View;
use crate::bindings::Bindings;
use crate::device::Gpu;
use crate::feedback::FeedbackBuffer;
use crate::page_cache::{CacheFormat, PageCache};
use crate::page_table::GpuPageTable;
use crate::params::Params;
use crate::readback::{Readback, ReadbackError};
use crate::sample::SampleFilter;
use crate::texture::VirtualTexture;

const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;

/// The probe's pipelines and the module's bindings for its textures.
pub struct AddressProbe {
    pipelines: Pipelines,
    frame_layout: wgpu::BindGroupLayout,
    bindings: Bindings,
    textures: Vec<VirtualTexture>,
}

impl AddressProbe {
    /// A probe of `textures` (texture id = index; at least one, all with one tile size and
    /// border). Panics if the placeholders cannot be made (a page table over the device's limit).
    pub fn new(gpu: &Gpu, textures: &[VirtualTexture]) -> AddressProbe {
        let device = &gpu.device;
        let t = textures[0];
        let grids: Vec<_> = textures.iter().map(|t| t.grid).collect();
        #[expect(clippy::expect_used, reason = "a test tool: its textures are the test's")]
        let (table, cache) = (
            GpuPageTable::new(device, &gpu.queue, &grids, 1).expect("a page table for the probe"),
            PageCache::new(device, 1, t.tile_size, t.border, CacheFormat::Rgba8).expect("a cache for the probe"),
        );
        let feedback = FeedbackBuffer::new(device, 1, 1, 1);
        let bindings = Bindings::new(device, &table, &cache, &feedback, SampleFilter::Nearest);
        let params = Params::new(textures, &cache, SampleFilter::Nearest, feedback.layout(0), 0.0);
        gpu.queue.write_buffer(bindings.params(), 0, bytemuck::bytes_of(&params));
        let module = draw::shader(device, "vortex probe", include_str!("probe.wgsl"));
        let frame_layout = draw::frame_only_layout(device, "vortex probe frame");
        let pipelines =
            Pipelines::new(device, "vortex probe", &module, [&frame_layout, bindings.layout()], FORMAT, "probe_");
        AddressProbe { pipelines, frame_layout, bindings, textures: textures.to_vec() }
    }

    /// The address of every pixel of a `width x height` draw of `view` at `lod`, row-major.
    /// Blocking; fails if the device is lost.
    pub fn addresses(
        &self,
        gpu: &Gpu,
        view: &View,
        lod: u8,
        width: u32,
        height: u32,
    ) -> Result<Vec<At>, ReadbackError> {
        let device = &gpu.device;
        let target = Target::new(device, "vortex probe", FORMAT, width, height);
        let frame = Frame::new(&self.textures, view, (width, height), Some(lod as f32));
        let frame_group = draw::frame_only_bind_group(device, "vortex probe", &self.frame_layout, &frame);
        let readback = Readback::new(device, "probe", width * 16, height);
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex probe") });
        let groups = [&frame_group, self.bindings.group()];
        target.record(&mut encoder, "vortex probe", wgpu::Color::TRANSPARENT, Some((&self.pipelines, groups, view)));
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
