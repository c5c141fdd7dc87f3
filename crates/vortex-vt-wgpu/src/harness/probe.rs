//! The probes, for tests of the module against its CPU mirrors (`vortex_vt::address`,
//! `vortex_vt::feedback`); render thread. They need no pages: their page tables and caches are
//! placeholders, only the textures' shapes count.
//!
//! - [`AddressProbe`] draws a [`View`] writing each pixel's address (page and position in it, at
//!   a fixed LOD) instead of a colour, and reads it back; blocking.
//! - [`FeedbackProbe`] draws a [`View`] through the harness's own shader (which calls
//!   `vt_feedback` from every fragment, as any application does) into a feedback buffer of its
//!   own, as frame `n` of a runtime with LOD bias `bias` would, and copies the words into a
//!   [`FeedbackReadback`] ring: the feedback words without a runtime's streaming in the way.

use vortex_vt::address::At;

use super::draw::{self, Pipelines, Target};
use super::frame::Frame;
use super::renderer::TARGET_FORMAT;
use super::view::View;
use crate::bindings::Bindings;
use crate::device::Gpu;
use crate::feedback::{FeedbackBuffer, FeedbackReadback};
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
        let (table, cache) = placeholders(gpu, textures);
        let feedback = FeedbackBuffer::new(device, 1, 1, 1);
        let bindings = Bindings::new(device, &table, std::slice::from_ref(&cache), &feedback, SampleFilter::Nearest);
        let params = Params::new(textures, &cache, SampleFilter::Nearest, feedback.layout(0), 0.0, 0, 1);
        gpu.queue.write_buffer(bindings.params(), 0, bytemuck::bytes_of(&params));
        let module = draw::shader(device, "vortex probe", include_str!("probe.wgsl"));
        let frame_layout = draw::frame_only_layout(device, "vortex probe frame");
        let pipelines =
            Pipelines::new(device, "vortex probe", &module, [&frame_layout, bindings.layout()], FORMAT, "probe_", &[]);
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

/// The harness's pipelines over placeholder bindings and a feedback buffer of its own.
pub struct FeedbackProbe {
    pipelines: Pipelines,
    frame_layout: wgpu::BindGroupLayout,
    bindings: Bindings,
    cache: PageCache,
    feedback: FeedbackBuffer,
    readback: FeedbackReadback,
    target: Target,
    textures: Vec<VirtualTexture>,
}

impl FeedbackProbe {
    /// A probe of `textures` (texture id = index; at least one, all with one tile size and
    /// border) drawing `width x height` frames, with feedback blocks of `block` pixels and a
    /// readback ring of `ring` buffers. Panics if the placeholders cannot be made.
    pub fn new(
        gpu: &Gpu,
        textures: &[VirtualTexture],
        width: u32,
        height: u32,
        block: u32,
        ring: usize,
    ) -> FeedbackProbe {
        let device = &gpu.device;
        let (table, cache) = placeholders(gpu, textures);
        let feedback = FeedbackBuffer::new(device, width, height, block);
        let readback = FeedbackReadback::new(device, &feedback, ring);
        let bindings = Bindings::new(device, &table, std::slice::from_ref(&cache), &feedback, SampleFilter::Nearest);
        let module = draw::shader(device, "vortex feedback probe", "");
        let frame_layout = draw::frame_only_layout(device, "vortex feedback probe frame");
        let layouts = [&frame_layout, bindings.layout()];
        let pipelines = Pipelines::new(device, "vortex feedback probe", &module, layouts, TARGET_FORMAT, "", &[]);
        let target = Target::new(device, "vortex feedback probe", TARGET_FORMAT, width, height);
        FeedbackProbe {
            pipelines,
            frame_layout,
            bindings,
            cache,
            feedback,
            readback,
            target,
            textures: textures.to_vec(),
        }
    }

    /// The buffer the draws write (its blocks per row and column).
    pub fn feedback(&self) -> &FeedbackBuffer {
        &self.feedback
    }

    /// The ring the words are copied into: read them with `try_read` or `read_now`.
    pub fn readback(&mut self) -> &mut FeedbackReadback {
        &mut self.readback
    }

    /// Clears the feedback buffer, draws `view` (nothing if `None`) as frame `frame` (whose
    /// elected pixel writes, `feedback::elected`) asking with LOD bias `bias`, and copies the
    /// words into the ring; submits. The number the ring reads the copy back under, or `None`
    /// when every buffer of the ring is in flight (the words are then not copied).
    pub fn submit(&mut self, gpu: &Gpu, view: Option<&View>, frame: u64, bias: f32) -> Option<u64> {
        let device = &gpu.device;
        let params =
            Params::new(&self.textures, &self.cache, SampleFilter::Nearest, self.feedback.layout(frame), bias, 0, 1);
        gpu.queue.write_buffer(self.bindings.params(), 0, bytemuck::bytes_of(&params));
        self.feedback.clear(&gpu.queue);
        let mut encoder =
            device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("vortex feedback probe") });
        let size = (self.target.width, self.target.height);
        let frame_group = view.map(|view| {
            let frame = Frame::new(&self.textures, view, size, None);
            draw::frame_only_bind_group(device, "vortex feedback probe", &self.frame_layout, &frame)
        });
        let draw =
            view.zip(frame_group.as_ref()).map(|(view, group)| (&self.pipelines, [group, self.bindings.group()], view));
        self.target.record(&mut encoder, "vortex feedback probe", wgpu::Color::TRANSPARENT, draw);
        let copied = self.readback.encode_copy(&mut encoder, &self.feedback);
        gpu.queue.submit([encoder.finish()]);
        self.readback.submitted();
        copied
    }
}

/// A page table with nothing mapped and a one-slot cache for `textures`: what a probe binds,
/// which reads only the textures' shapes. Panics if they cannot be made (a page table over the
/// device's limit).
#[expect(clippy::expect_used, reason = "a test tool: its textures are the test's")]
fn placeholders(gpu: &Gpu, textures: &[VirtualTexture]) -> (GpuPageTable, PageCache) {
    let t = textures[0];
    let grids: Vec<_> = textures.iter().map(|t| t.grid).collect();
    (
        GpuPageTable::new(&gpu.device, &gpu.queue, &grids, 1).expect("a page table for the probe"),
        PageCache::new(&gpu.device, 1, t.tile_size, t.border, CacheFormat::Rgba8).expect("a cache for the probe"),
    )
}
