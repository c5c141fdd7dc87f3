//! The harness's pipelines, targets and passes: its shader (`harness.wgsl` after the module), a
//! pipeline per kind of [`View`] (a full-screen window, or meshes with a depth test) with the
//! harness's uniform in group 0 and the module's bindings in group 1, the colour target with its
//! depth buffer, and the recording of one pass: clear, then draw. Render thread.

use super::mesh::Vertex;
use super::view::View;

pub(crate) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The bind group index of the module's bindings in the harness's shaders.
pub(crate) const VT_GROUP: u32 = 1;

/// The harness's shader after the module, followed by `extra` (the probe's fragment stages).
pub(crate) fn shader(device: &wgpu::Device, label: &str, extra: &str) -> wgpu::ShaderModule {
    let application = format!("{}\n{extra}", include_str!("harness.wgsl"));
    device.create_shader_module(crate::shader::descriptor(Some(label), &application, VT_GROUP))
}

/// The two pipelines of a pass.
#[derive(Clone, Debug)]
pub(crate) struct Pipelines {
    window: wgpu::RenderPipeline,
    mesh: wgpu::RenderPipeline,
}

impl Pipelines {
    /// Pipelines writing `format` without blending, with fragment stages `fs_{prefix}window` and
    /// `fs_{prefix}mesh`, over `layouts` (group 0, the harness's; group 1, the module's), with
    /// the shader's overrides set to `constants`.
    pub(crate) fn new(
        device: &wgpu::Device,
        label: &str,
        module: &wgpu::ShaderModule,
        layouts: [&wgpu::BindGroupLayout; 2],
        format: wgpu::TextureFormat,
        prefix: &str,
        constants: &[(&str, f64)],
    ) -> Pipelines {
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(layouts[0]), Some(layouts[1])],
            immediate_size: 0,
        });
        let make = |is_window: bool| {
            let options = wgpu::PipelineCompilationOptions { constants, ..Default::default() };
            let fragment = format!("fs_{prefix}{}", if is_window { "window" } else { "mesh" });
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module,
                    entry_point: Some(if is_window { "vs_window" } else { "vs_mesh" }),
                    compilation_options: options.clone(),
                    buffers: if is_window { &[] } else { &[Some(Vertex::LAYOUT)] },
                },
                primitive: wgpu::PrimitiveState::default(),
                // The window lies at the far plane, behind every mesh.
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(!is_window),
                    depth_compare: Some(wgpu::CompareFunction::LessEqual),
                    stencil: wgpu::StencilState::default(),
                    bias: wgpu::DepthBiasState::default(),
                }),
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module,
                    entry_point: Some(&fragment),
                    compilation_options: options,
                    targets: &[Some(wgpu::ColorTargetState {
                        format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        Pipelines { window: make(true), mesh: make(false) }
    }
}

/// The entry of binding 0 of group 0: the harness's `Frame` uniform.
pub(crate) fn frame_entry() -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding: 0,
        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: wgpu::BufferSize::new(size_of::<super::frame::Frame>() as u64),
        },
        count: None,
    }
}

/// The layout and bind group of group 0: the `Frame` uniform alone.
pub(crate) fn frame_only_layout(device: &wgpu::Device, label: &str) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &[frame_entry()] })
}

pub(crate) fn frame_only_bind_group(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    frame: &super::frame::Frame,
) -> wgpu::BindGroup {
    let buffer = uniform(device, label, bytemuck::bytes_of(frame));
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &[wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() }],
    })
}

/// A uniform buffer holding `bytes`. Written through a mapping at creation, as
/// `DeviceExt::create_buffer_init` does, except that a buffer that cannot be mapped (the device
/// is lost, so the buffer is invalid) is left unwritten instead of panicking: the pass that uses
/// it is invalid too, and the frame's readback reports the loss as an error.
pub(crate) fn uniform(device: &wgpu::Device, label: &str, bytes: &[u8]) -> wgpu::Buffer {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: (bytes.len() as u64).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT),
        usage: wgpu::BufferUsages::UNIFORM,
        mapped_at_creation: true,
    });
    if let Ok(mut view) = buffer.get_mapped_range_mut(..) {
        view.slice(..bytes.len()).copy_from_slice(bytes);
    }
    buffer.unmap();
    buffer
}

/// What a pass draws into: a `width x height` colour texture that can be copied out (to a
/// [`Readback`](crate::readback::Readback)), its view, and a depth buffer of the same size.
#[derive(Debug)]
pub(crate) struct Target {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) texture: wgpu::Texture,
    pub(crate) view: wgpu::TextureView,
    pub(crate) depth: wgpu::TextureView,
}

impl Target {
    pub(crate) fn new(
        device: &wgpu::Device,
        label: &str,
        format: wgpu::TextureFormat,
        width: u32,
        height: u32,
    ) -> Target {
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let depth = depth_texture(device, width, height);
        Target { width, height, texture, view, depth }
    }

    /// The whole colour texture, as the source of a copy.
    pub(crate) fn copy_source(&self) -> (wgpu::TexelCopyTextureInfo<'_>, wgpu::Extent3d) {
        (
            self.texture.as_image_copy(),
            wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 },
        )
    }

    /// Records a pass into this target: see [`record`]. (The address probe's.)
    #[cfg(feature = "testing")]
    pub(crate) fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        label: &str,
        clear: wgpu::Color,
        draw: Option<(&Pipelines, [&wgpu::BindGroup; 2], &View)>,
    ) {
        record(encoder, label, &self.view, &self.depth, clear, draw);
    }
}

/// A depth buffer for a `width x height` target.
pub(crate) fn depth_texture(device: &wgpu::Device, width: u32, height: u32) -> wgpu::TextureView {
    device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some("vortex depth"),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        })
        .create_view(&wgpu::TextureViewDescriptor::default())
}

/// Clears `colour` to `clear` and the depth to the far plane, then draws `view` with
/// `pipelines` and the bind groups (the harness's, the module's) if given.
pub(crate) fn record(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    colour: &wgpu::TextureView,
    depth: &wgpu::TextureView,
    clear: wgpu::Color,
    draw: Option<(&Pipelines, [&wgpu::BindGroup; 2], &View)>,
) {
    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: colour,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(clear), store: wgpu::StoreOp::Store },
        })],
        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
            view: depth,
            depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    let Some((pipelines, [frame, vt], view)) = draw else { return };
    pass.set_bind_group(0, frame, &[]);
    pass.set_bind_group(VT_GROUP, vt, &[]);
    match view {
        View::Window(_) => {
            pass.set_pipeline(&pipelines.window);
            pass.draw(0..3, 0..1);
        }
        View::Meshes { meshes, .. } => {
            pass.set_pipeline(&pipelines.mesh);
            for mesh in *meshes {
                pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..mesh.index_count, 0, 0..1);
            }
        }
    }
}
