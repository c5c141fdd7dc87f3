//! Embedding the runtime in an application's own renderer: our own device, our own pipeline and
//! shader (which includes the module and calls `vt_sample` and `vt_feedback`), a quad mesh with
//! UVs, N frames headless, the last one saved as a PNG.
//!
//! ```sh
//! cargo run --release -p vortex-vt-wgpu --example embed -- PACK OUT.png [FRAMES]
//! ```
//!
//! The quad fills the frame and the frame is the image's size, so once the pages have landed the
//! picture is the pack's LOD 0, within one code value (the crate's tests check that).

use std::path::Path;
use std::sync::Arc;

use vortex_vt_wgpu::{Runtime, RuntimeConfig, shader};
use wgpu::util::DeviceExt;

/// Our shader: a mesh with a position and an image UV; the module sits in bind group 0.
const SHADER: &str = "
struct Varyings {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
}

@vertex
fn vs_main(@location(0) position: vec2<f32>, @location(1) uv: vec2<f32>) -> Varyings {
    return Varyings(vec4<f32>(position, 0.0, 1.0), uv);
}

@fragment
fn fs_main(v: Varyings) -> @location(0) vec4<f32> {
    let ddx = dpdx(v.uv);
    let ddy = dpdy(v.uv);
    vt_feedback(0u, v.uv, ddx, ddy, v.position.xy);
    return vt_sample(0u, v.uv, ddx, ddy); // premultiplied colour in linear light
}
";

/// Two triangles over the whole frame: clip-space position, image UV (v down).
const QUAD: [[f32; 4]; 6] = [
    [-1.0, 1.0, 0.0, 0.0],
    [-1.0, -1.0, 0.0, 1.0],
    [1.0, -1.0, 1.0, 1.0],
    [-1.0, 1.0, 0.0, 0.0],
    [1.0, -1.0, 1.0, 1.0],
    [1.0, 1.0, 1.0, 0.0],
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [pack, out, ..] = args.as_slice() else {
        return Err("usage: embed PACK OUT.png [FRAMES]".into());
    };
    run(Path::new(pack), Path::new(out), args.get(2).map_or(Ok(60), |n| n.parse())?)
}

/// Draws `pack` for `frames` frames and writes the last one to `out`.
pub fn run(pack: &Path, out: &Path, frames: u32) -> Result<(), Box<dyn std::error::Error>> {
    // The application's device: any adapter, default limits.
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle().with_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))?;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))?;

    // The runtime, on our device, over one pack, for frames of the image's size.
    let pack = Arc::new(vortex_pack::Pack::open(pack)?);
    let [width, height] = [pack.description().width, pack.description().height];
    let config = RuntimeConfig { frame_size: [width, height], cache_slots_per_side: 8, ..RuntimeConfig::default() };
    let mut vt = Runtime::new(&device, &queue, vec![pack], config)?;
    println!("filter: {} (the best the pack's border allows)", vt.filter().name());

    // Our pipeline: our shader after the module, the module's bind group at group 0.
    let module = device.create_shader_module(shader::descriptor(Some("embed"), SHADER, 0));
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("embed"),
        bind_group_layouts: &[Some(vt.bind_group_layout())],
        immediate_size: 0,
    });
    let format = wgpu::TextureFormat::Rgba8UnormSrgb;
    // The runtime's filter fixed in the pipeline: only its code is compiled in (optional).
    let constants = [shader::filter_constant(vt.filter())];
    let options = wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() };
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("embed"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs_main"),
            compilation_options: options.clone(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: 16,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &wgpu::vertex_attr_array![0 => Float32x2, 1 => Float32x2],
            })],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs_main"),
            compilation_options: options,
            targets: &[Some(format.into())],
        }),
        multiview_mask: None,
        cache: None,
    });
    let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("quad"),
        contents: bytemuck::cast_slice(&QUAD),
        usage: wgpu::BufferUsages::VERTEX,
    });
    let target = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("frame"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let view = target.create_view(&Default::default());

    // The frame loop: draw, submit, end the frame (never blocks).
    for _ in 0..frames {
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("embed"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                ..Default::default()
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, vt.bind_group(), &[]);
            pass.set_vertex_buffer(0, vertices.slice(..));
            pass.draw(0..6, 0..1);
        }
        queue.submit([encoder.finish()]);
        let stats = vt.end_frame()?;
        // A real application would sleep until its next vsync; give the loads time to land.
        std::thread::sleep(std::time::Duration::from_millis(5));
        if stats.uploaded > 0 {
            println!("frame {}: {} pages uploaded, {} in flight", stats.frame, stats.uploaded, stats.in_flight);
        }
    }

    // Save the last frame: copy it out, wait for the GPU, write RGBA8.
    let row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: u64::from(row * height),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        target.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: None },
        },
        wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
    );
    queue.submit([encoder.finish()]);
    let (mapped_tx, mapped_rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| drop(mapped_tx.send(r)));
    device.poll(wgpu::PollType::wait_indefinitely())?;
    mapped_rx.recv()??;
    let mapped = buffer.get_mapped_range(..)?;
    let pixels: Vec<u8> = mapped.chunks(row as usize).flat_map(|r| &r[..width as usize * 4]).copied().collect();
    let mut encoder = png::Encoder::new(std::fs::File::create(out)?, width, height);
    encoder.set_color(png::ColorType::Rgba);
    encoder.write_header()?.write_image_data(&pixels)?;
    println!("wrote {}: {width}x{height}, {} pages touched", out.display(), vt.pages_touched());
    Ok(())
}
