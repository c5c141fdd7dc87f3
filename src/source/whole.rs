//! Any other format the `image` crate reads, decoded whole: accepted only when the decoded
//! image fits under `--max-memory`, which is checked from the header before decoding.

use std::path::Path;

use image::{DynamicImage, ImageDecoder, ImageReader};

use super::{ImageHeader, RowSource, check_whole_fits};
use crate::decode::{image_error, layout_of, native_bytes};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};

pub struct WholeSource {
    format: String,
    width: u32,
    height: u32,
    layout: PixelLayout,
    /// Native-endian samples of the whole image.
    bytes: Vec<u8>,
    next: usize,
}

pub fn open(path: &Path, max_memory: u64) -> Result<Box<dyn RowSource>> {
    let reader = ImageReader::open(path)
        .map_err(|e| TilerError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| TilerError::io(path, e))?;
    let format = reader.format().ok_or_else(|| {
        TilerError::decode(
            path,
            "not an image format this tool reads (PNG, TIFF, JPEG, PPM/PGM, WebP, GIF, BMP, TGA, QOI)",
        )
    })?;
    let mut decoder = reader.into_decoder().map_err(|e| image_error(path, e))?;
    let (width, height) = decoder.dimensions();
    let layout = layout_of(decoder.color_type()).ok_or_else(|| {
        TilerError::unsupported(
            path,
            format!(
                "pixel type {:?} is not supported (8/16-bit grey, grey+alpha, RGB, RGBA are)",
                decoder.color_type()
            ),
        )
    })?;
    let why = format!("{format:?} images are not streamed by this tool");
    check_whole_fits(path, width as u64, height as u64, layout, max_memory, &why)?;
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(max_memory);
    decoder.set_limits(limits).map_err(|e| image_error(path, e))?;
    let image = DynamicImage::from_decoder(decoder).map_err(|e| image_error(path, e))?;
    let mut bytes = native_bytes(path, image)?;
    let mut layout = layout;
    // A GIF has no alpha channel, only a palette entry that may be transparent, and is always
    // decoded as RGBA: where no texel is transparent it is RGB (as vips reads it), so that
    // `--codec auto` can take JPEG. This costs one pass over the decoded texels, which stops
    // at the first transparent one, and one more to drop the alpha in place.
    if format == image::ImageFormat::Gif
        && layout == PixelLayout::new(Channels::Rgba, Depth::U8)
        && bytes.chunks_exact(4).all(|texel| texel[3] == 255)
    {
        drop_alpha(&mut bytes);
        layout = PixelLayout::new(Channels::Rgb, Depth::U8);
    }
    Ok(Box::new(WholeSource { format: format!("{format:?}").to_lowercase(), width, height, layout, bytes, next: 0 }))
}

/// 8-bit RGBA texels made RGB in place.
fn drop_alpha(bytes: &mut Vec<u8>) {
    let texels = bytes.len() / 4;
    for i in 0..texels {
        bytes.copy_within(i * 4..i * 4 + 3, i * 3);
    }
    bytes.truncate(texels * 3);
}

impl RowSource for WholeSource {
    fn header(&self) -> ImageHeader {
        ImageHeader { width: self.width, height: self.height, layout: self.layout }
    }

    /// The whole decoded image, held from open to the end.
    fn buffer_bytes(&self) -> u64 {
        self.bytes.capacity() as u64
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let start = self.next * out.len();
        out.copy_from_slice(&self.bytes[start..start + out.len()]);
        self.next += 1;
        Ok(())
    }

    fn describe(&self) -> String {
        format!("{}, decoded whole", self.format)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::read_all;

    /// A GIF of a few colours (no quantisation loss), texel (0, 0) transparent where asked.
    fn gif(path: &Path, transparent: bool) -> Vec<u8> {
        let (w, h) = (23u32, 9u32);
        let colours = [[200u8, 30, 40], [10, 250, 90], [0, 0, 0], [255, 255, 255]];
        let rgba: Vec<u8> = (0..w * h)
            .flat_map(|i| {
                let [r, g, b] = colours[(i % 7 % 4) as usize];
                [r, g, b, if transparent && i == 0 { 0 } else { 255 }]
            })
            .collect();
        let frame = image::Frame::new(image::RgbaImage::from_raw(w, h, rgba.clone()).unwrap());
        let mut encoder = image::codecs::gif::GifEncoder::new(std::fs::File::create(path).unwrap());
        encoder.encode_frame(frame).unwrap();
        rgba
    }

    #[test]
    fn an_opaque_gif_is_rgb_and_a_transparent_one_rgba() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("opaque.gif");
        let rgba = gif(&path, false);
        let mut source = crate::source::open(&path, crate::limits::Budget::new(1 << 20)).unwrap();
        assert_eq!(source.layout(), PixelLayout::new(Channels::Rgb, Depth::U8));
        let rgb: Vec<u8> = rgba.chunks_exact(4).flat_map(|t| [t[0], t[1], t[2]]).collect();
        assert_eq!(read_all(source.as_mut()).unwrap(), rgb);

        let path = dir.path().join("transparent.gif");
        gif(&path, true);
        let mut source = crate::source::open(&path, crate::limits::Budget::new(1 << 20)).unwrap();
        assert_eq!(source.layout(), PixelLayout::new(Channels::Rgba, Depth::U8));
        let got = read_all(source.as_mut()).unwrap();
        assert_eq!(got[3], 0);
        assert!(got[4..].chunks_exact(4).all(|t| t[3] == 255));
    }
}
