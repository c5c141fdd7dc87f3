//! Meshes: triangles whose vertices carry a position, an image UV (0..1 over the texture's real
//! image) and the id of the virtual texture they show. Built on the CPU (`scene` makes planes,
//! terrain grids and boxes), uploaded once into vertex and index buffers.

use wgpu::util::DeviceExt;

/// One vertex, as the `vs_mesh` stage of `shaders/virtual.wgsl` reads it.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    /// Position in world units.
    pub position: [f32; 3],
    /// Image UV (0..1 over the texture's real image).
    pub uv: [f32; 2],
    /// The virtual texture it shows.
    pub texture: u32,
}

impl Vertex {
    pub(crate) const LAYOUT: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
        array_stride: size_of::<Vertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x2, 2 => Uint32],
    };
}

/// Indexed triangles (counter-clockwise seen from the front; both faces are drawn).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// The vertices.
    pub vertices: Vec<Vertex>,
    /// Three vertex indices per triangle.
    pub indices: Vec<u32>,
}

impl Mesh {
    /// Appends `other`, renumbering its indices.
    pub fn append(&mut self, other: &Mesh) {
        let base = self.vertices.len() as u32;
        self.vertices.extend_from_slice(&other.vertices);
        self.indices.extend(other.indices.iter().map(|i| i + base));
    }
}

/// A mesh in GPU buffers.
#[derive(Debug)]
pub struct GpuMesh {
    pub(crate) vertices: wgpu::Buffer,
    pub(crate) indices: wgpu::Buffer,
    pub(crate) index_count: u32,
}

impl GpuMesh {
    /// `mesh`'s vertex and index buffers on `device`.
    pub fn upload(device: &wgpu::Device, mesh: &Mesh) -> GpuMesh {
        let buffer = |label, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        GpuMesh {
            vertices: buffer("vortex mesh vertices", bytemuck::cast_slice(&mesh.vertices), wgpu::BufferUsages::VERTEX),
            indices: buffer("vortex mesh indices", bytemuck::cast_slice(&mesh.indices), wgpu::BufferUsages::INDEX),
            index_count: mesh.indices.len() as u32,
        }
    }
}
