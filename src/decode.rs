//! A tile, or any small image file, decoded whole from memory into the pipeline's texels:
//! what the tiled sources, the viewer layouts and the server read stored tiles with. Below
//! `source` and `viewer`, which both use it.

use std::path::Path;

use image::{DynamicImage, ImageDecoder, ImageReader};

use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};

/// An image's samples in native byte order, in one of the pipeline's layouts.
pub(crate) fn native_bytes(path: &Path, image: DynamicImage) -> Result<Vec<u8>> {
    Ok(match image {
        DynamicImage::ImageLuma8(i) => i.into_raw(),
        DynamicImage::ImageLumaA8(i) => i.into_raw(),
        DynamicImage::ImageRgb8(i) => i.into_raw(),
        DynamicImage::ImageRgba8(i) => i.into_raw(),
        DynamicImage::ImageLuma16(i) => bytemuck::cast_slice(&i.into_raw()).to_vec(),
        DynamicImage::ImageLumaA16(i) => bytemuck::cast_slice(&i.into_raw()).to_vec(),
        DynamicImage::ImageRgb16(i) => bytemuck::cast_slice(&i.into_raw()).to_vec(),
        DynamicImage::ImageRgba16(i) => bytemuck::cast_slice(&i.into_raw()).to_vec(),
        other => return Err(TilerError::unsupported(path, format!("pixel type {:?} is not supported", other.color()))),
    })
}

/// A small image (a tile) decoded whole from memory.
pub struct Decoded {
    pub width: u32,
    pub height: u32,
    pub layout: PixelLayout,
    /// Native-endian samples, rows top down.
    pub bytes: Vec<u8>,
}

/// Decodes a tile file's bytes; `path` names it in errors. Tiles are small, so the `image`
/// crate's default allocation limit applies.
pub fn decode_tile(path: &Path, bytes: &[u8]) -> Result<Decoded> {
    decode_tile_within(path, bytes, (u32::MAX, u32::MAX))
}

/// [`decode_tile`] of a tile at most `max` (width, height) texels: a larger one is refused
/// from its header, before its texels are allocated.
pub fn decode_tile_within(path: &Path, bytes: &[u8], max: (u32, u32)) -> Result<Decoded> {
    if vortex_jxl::is_jxl(bytes) {
        return decode_jxl(path, bytes, max);
    }
    let reader =
        ImageReader::new(std::io::Cursor::new(bytes)).with_guessed_format().map_err(|e| TilerError::io(path, e))?;
    let decoder = reader.into_decoder().map_err(|e| image_error(path, e))?;
    let (width, height) = decoder.dimensions();
    if width > max.0 || height > max.1 {
        let message = format!("is {width}x{height}, larger than the {}x{} a tile of this input can be", max.0, max.1);
        return Err(TilerError::decode(path, message));
    }
    let image = DynamicImage::from_decoder(decoder).map_err(|e| image_error(path, e))?;
    let layout = layout_of(image.color())
        .ok_or_else(|| TilerError::unsupported(path, format!("pixel type {:?} is not supported", image.color())))?;
    Ok(Decoded { width, height, layout, bytes: native_bytes(path, image)? })
}

/// A tile file's size and pixel layout from its header alone, without decoding it.
pub fn probe_tile(path: &Path, bytes: &[u8]) -> Result<(u32, u32, PixelLayout)> {
    use image::ImageDecoder;
    if vortex_jxl::is_jxl(bytes) {
        let header = vortex_jxl::probe(bytes).map_err(|e| jxl_error(path, e))?;
        return Ok((header.width, header.height, jxl_layout(path, header)?));
    }
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| TilerError::io(path, e))?;
    let decoder = reader.into_decoder().map_err(|e| image_error(path, e))?;
    let (width, height) = decoder.dimensions();
    let colour = decoder.color_type();
    let layout = layout_of(colour)
        .ok_or_else(|| TilerError::unsupported(path, format!("pixel type {colour:?} is not supported")))?;
    Ok((width, height, layout))
}

pub(crate) fn layout_of(colour: image::ColorType) -> Option<PixelLayout> {
    use image::ColorType as C;
    let (channels, depth) = match colour {
        C::L8 => (Channels::Grey, Depth::U8),
        C::La8 => (Channels::GreyAlpha, Depth::U8),
        C::Rgb8 => (Channels::Rgb, Depth::U8),
        C::Rgba8 => (Channels::Rgba, Depth::U8),
        C::L16 => (Channels::Grey, Depth::U16),
        C::La16 => (Channels::GreyAlpha, Depth::U16),
        C::Rgb16 => (Channels::Rgb, Depth::U16),
        C::Rgba16 => (Channels::Rgba, Depth::U16),
        _ => return None,
    };
    Some(PixelLayout::new(channels, depth))
}

/// A JPEG XL tile through libjxl's decoder (vortex-jxl): 8-bit samples up to 8 bits coded,
/// 16-bit ones above.
fn decode_jxl(path: &Path, bytes: &[u8], max: (u32, u32)) -> Result<Decoded> {
    let decoded = vortex_jxl::decode(bytes, max).map_err(|e| jxl_error(path, e))?;
    let header = decoded.header;
    let layout = jxl_layout(path, header)?;
    let bytes = match decoded.samples {
        vortex_jxl::Samples::U8(s) => s,
        vortex_jxl::Samples::U16(s) => bytemuck::cast_slice(&s).to_vec(),
    };
    Ok(Decoded { width: header.width, height: header.height, layout, bytes })
}

fn jxl_layout(path: &Path, header: vortex_jxl::Header) -> Result<PixelLayout> {
    let channels = match header.channels {
        1 => Channels::Grey,
        2 => Channels::GreyAlpha,
        3 => Channels::Rgb,
        4 => Channels::Rgba,
        n => return Err(TilerError::unsupported(path, format!("a JPEG XL image of {n} channels"))),
    };
    let depth = if header.bits_per_sample <= 8 { Depth::U8 } else { Depth::U16 };
    Ok(PixelLayout::new(channels, depth))
}

fn jxl_error(path: &Path, e: vortex_jxl::Error) -> TilerError {
    match e {
        vortex_jxl::Error::TooLarge { .. } => TilerError::decode(path, e),
        vortex_jxl::Error::OutOfMemory(_) => TilerError::unsupported(path, format!("{e}; raise --max-memory")),
        other => TilerError::decode(path, format!("corrupt or truncated JPEG XL tile: {other}")),
    }
}

pub(crate) fn image_error(path: &Path, e: image::ImageError) -> TilerError {
    match e {
        image::ImageError::IoError(io) => TilerError::io(path, io),
        image::ImageError::Limits(l) => TilerError::unsupported(path, format!("{l}; raise --max-memory")),
        image::ImageError::Unsupported(u) => TilerError::unsupported(path, u),
        other => TilerError::decode(path, format!("corrupt or truncated image: {other}")),
    }
}
