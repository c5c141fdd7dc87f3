//! `--screenshot`: the window's frame read back from its surface texture and saved as an RGBA
//! PNG, marked as ours so that a later run may replace it (and nothing else).

use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use vortex_tiler::error::ShowPath;
use vortex_tiler::output;
use vortex_vt_wgpu::Gpu;

/// The PNG text chunk that marks a screenshot of ours.
const MARK: (&str, &str) = ("Software", "vortex-tiler view");

/// Reads `texture` (a surface texture with `COPY_SRC`, 8-bit RGBA or BGRA) back, waiting for the
/// GPU, and writes it to `path` as an RGBA PNG.
pub(super) fn save(gpu: &Gpu, texture: &wgpu::Texture, path: &Path) -> Result<()> {
    refuse_others(path)?;
    let (width, height) = (texture.width(), texture.height());
    let bgra = match texture.format() {
        wgpu::TextureFormat::Bgra8UnormSrgb | wgpu::TextureFormat::Bgra8Unorm => true,
        wgpu::TextureFormat::Rgba8UnormSrgb | wgpu::TextureFormat::Rgba8Unorm => false,
        other => bail!("cannot save a {other:?} surface as a PNG"),
    };
    let row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("vortex screenshot"),
        size: u64::from(row) * u64::from(height),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: None },
        },
        wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
    );
    gpu.queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| drop(tx.send(r)));
    gpu.wait_idle()?;
    rx.try_recv().map_err(|_| anyhow!("the GPU never answered the screenshot's readback"))??;
    let mapped = buffer.get_mapped_range(..).map_err(|e| anyhow!("reading the screenshot back: {e}"))?;
    let mut pixels = Vec::with_capacity(width as usize * height as usize * 4);
    for line in mapped.chunks(row as usize) {
        for t in line[..width as usize * 4].chunks_exact(4) {
            pixels.extend_from_slice(&if bgra { [t[2], t[1], t[0], t[3]] } else { [t[0], t[1], t[2], t[3]] });
        }
    }
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, width, height);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.add_text_chunk(MARK.0.into(), MARK.1.into())?;
    let mut writer = encoder.write_header()?;
    writer.write_image_data(&pixels)?;
    writer.finish()?;
    output::write_file(path, &bytes).with_context(|| format!("writing {}", path.shown()))
}

/// Refuses to replace a file at `path` that is not a screenshot of ours.
pub(super) fn refuse_others(path: &Path) -> Result<()> {
    let Ok(existing) = std::fs::read(path) else { return Ok(()) };
    let ours = existing.starts_with(b"\x89PNG") && existing.windows(MARK.1.len()).any(|w| w == MARK.1.as_bytes());
    if !ours {
        bail!("{} exists and is not a screenshot of vortex-tiler view; remove it or choose another name", path.shown());
    }
    Ok(())
}
