//! The module's bind group (`shaders/vt.wgsl`, bindings 0-7): the uniform block, the page table,
//! layer 0's cache, the caches' sampler (nearest for the nearest filter, linear otherwise), the
//! feedback buffer, and layers 1-3's caches (bindings 5-7; layer 0's again where a runtime has
//! fewer layers, so that one layout serves every runtime). One layout per runtime; the group is remade when what it
//! binds changes (a resize makes a new feedback buffer, a filter change a new sampler).

use crate::feedback::FeedbackBuffer;
use crate::layer::MAX_LAYERS;
use crate::page_cache::PageCache;
use crate::page_table::GpuPageTable;
use crate::params::Params;
use crate::sample::SampleFilter;

/// The layout, the group and the uniform buffer of the module's bindings.
#[derive(Debug)]
pub(crate) struct Bindings {
    layout: wgpu::BindGroupLayout,
    group: wgpu::BindGroup,
    params: wgpu::Buffer,
}

impl Bindings {
    pub(crate) fn new(
        device: &wgpu::Device,
        table: &GpuPageTable,
        caches: &[PageCache],
        feedback: &FeedbackBuffer,
        filter: SampleFilter,
    ) -> Bindings {
        let layout = layout(device);
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("vortex vt_params"),
            size: size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let sampler = sampler(device, filter);
        let group = group(device, &layout, &params, table.buffer(), caches, &sampler, feedback.buffer());
        Bindings { layout, group, params }
    }

    /// Remakes the group (same layout, same uniform buffer) over a new feedback buffer or filter.
    pub(crate) fn rebind(
        &mut self,
        device: &wgpu::Device,
        table: &GpuPageTable,
        caches: &[PageCache],
        feedback: &FeedbackBuffer,
        filter: SampleFilter,
    ) {
        let sampler = sampler(device, filter);
        self.group = group(device, &self.layout, &self.params, table.buffer(), caches, &sampler, feedback.buffer());
    }

    pub(crate) fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.layout
    }

    pub(crate) fn group(&self) -> &wgpu::BindGroup {
        &self.group
    }

    pub(crate) fn params(&self) -> &wgpu::Buffer {
        &self.params
    }
}

/// The binding of layer `layer`'s cache.
fn cache_binding(layer: usize) -> u32 {
    if layer == 0 { 2 } else { 4 + layer as u32 }
}

/// The layout of bindings 0-7, visible to vertex and fragment stages (a vertex shader may sample
/// a virtual texture too, e.g. a height field).
fn layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    let stages = wgpu::ShaderStages::VERTEX_FRAGMENT;
    let entry = |binding, visibility, ty| wgpu::BindGroupLayoutEntry { binding, visibility, ty, count: None };
    let storage = |read_only| wgpu::BindingType::Buffer {
        ty: wgpu::BufferBindingType::Storage { read_only },
        has_dynamic_offset: false,
        min_binding_size: None,
    };
    let cache = wgpu::BindingType::Texture {
        sample_type: wgpu::TextureSampleType::Float { filterable: true },
        view_dimension: wgpu::TextureViewDimension::D2,
        multisampled: false,
    };
    let mut entries = vec![
        entry(
            0,
            stages,
            wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: wgpu::BufferSize::new(size_of::<Params>() as u64),
            },
        ),
        entry(1, stages, storage(true)),
        entry(3, stages, wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering)),
        // Written from fragment shaders only: vertex-stage storage writes need a feature.
        entry(4, wgpu::ShaderStages::FRAGMENT, storage(false)),
    ];
    entries.extend((0..MAX_LAYERS).map(|layer| entry(cache_binding(layer), stages, cache)));
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("vortex vt"), entries: &entries })
}

/// The cache's sampler: within a slot only (the border, or the shader's clamp, keeps neighbouring
/// slots' texels out, so the address mode only matters at the cache's outer edge).
fn sampler(device: &wgpu::Device, filter: SampleFilter) -> wgpu::Sampler {
    let mode = if filter == SampleFilter::Nearest { wgpu::FilterMode::Nearest } else { wgpu::FilterMode::Linear };
    device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("vortex page cache"),
        mag_filter: mode,
        min_filter: mode,
        mipmap_filter: wgpu::MipmapFilterMode::Nearest,
        ..Default::default()
    })
}

fn group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    params: &wgpu::Buffer,
    table: &wgpu::Buffer,
    caches: &[PageCache],
    sampler: &wgpu::Sampler,
    feedback: &wgpu::Buffer,
) -> wgpu::BindGroup {
    let mut entries = vec![
        wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 1, resource: table.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::Sampler(sampler) },
        wgpu::BindGroupEntry { binding: 4, resource: feedback.as_entire_binding() },
    ];
    entries.extend((0..MAX_LAYERS).map(|layer| wgpu::BindGroupEntry {
        binding: cache_binding(layer),
        resource: wgpu::BindingResource::TextureView(caches.get(layer).unwrap_or(&caches[0]).view()),
    }));
    device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("vortex vt"), layout, entries: &entries })
}
