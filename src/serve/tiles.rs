//! A stored page into a viewer's tile: the stored bytes when they already are that tile, else
//! the page decoded, cropped (and, below the pack's last LOD, halved) and encoded again.
//!
//! A JPEG, PNG or JPEG XL page whose crop is the whole page and whose format is the one served
//! is sent as stored. Everything else is decoded to its own texel layout (image files as
//! `convert` reads tile files; raw, zstd and BC payloads by `vortex_pack`), cropped and encoded
//! by the tiler's own [`TileEncoder::encode_crop`]: JPEG for JPEG inputs (at the input's
//! quality), JPEG XL for JPEG XL inputs (at the input's quality or lossless, effort 1: a tile
//! made while a browser waits), PNG (fast) for everything else, 16-bit samples kept.
//!
//! Deep Zoom's levels go on below one page down to 1 x 1 texel; those few tiny levels are made
//! here by halving the last stored LOD's image with a 2 x 2 box (the mean of the real texels
//! under each, rounded half up), so unlike every stored LOD they are means of rounded means,
//! not the exact pipeline's.

use bytes::Bytes;

use crate::codec::{Codec, TileEncoder};
use crate::decode::{Decoded, decode_tile};
use crate::formats::viewer::Crop;
use crate::pixel::{Depth, PixelLayout};

/// The image format of the tiles an input is served in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Jpeg,
    Png,
    Jxl,
}

impl Format {
    pub fn content_type(self) -> &'static str {
        match self {
            Format::Jpeg => "image/jpeg",
            Format::Png => "image/png",
            Format::Jxl => "image/jxl",
        }
    }

    /// The file extension `viewer` names these tiles with.
    pub fn extension(self, viewer: crate::formats::viewer::Viewer) -> &'static str {
        viewer.extension(match self {
            Format::Jpeg => "jpg",
            Format::Png => "png",
            Format::Jxl => "jxl",
        })
    }
}

/// A page as stored, before any decoding.
pub enum Page {
    /// An image file (a JPEG or PNG payload, a tile file of a split directory).
    Image(Format, Bytes),
    /// Texels already decoded (raw, zstd, BC payloads; one-colour tiles).
    Texels(Decoded),
}

/// What to make of a page: a viewer tile `crop` of it (in the page's texels), after halving
/// the image part of the page `halvings` times (Deep Zoom's levels below one page).
#[derive(Clone, Copy, Debug)]
pub struct Job {
    pub side: u32,
    pub border: u32,
    pub crop: Crop,
    /// For `halvings > 0`: the real image's extent in the page, from (border, border).
    pub extent: (u32, u32),
    pub halvings: u32,
    pub codec: Codec,
}

/// The stored bytes, if they are already the tile `job` asks for.
pub fn as_stored(page: &Page, job: &Job, format: Format) -> Option<Bytes> {
    match page {
        Page::Image(f, bytes) if *f == format && job.halvings == 0 && job.crop == Crop::whole(job.side) => {
            Some(bytes.clone())
        }
        _ => None,
    }
}

/// Decodes, crops and encodes: the CPU-bound part, run on a blocking thread.
pub fn render(page: Page, job: &Job) -> Result<Bytes, String> {
    let decoded = match page {
        Page::Image(_, bytes) => decode_tile(std::path::Path::new("page"), &bytes).map_err(|e| e.to_string())?,
        Page::Texels(d) => d,
    };
    if (decoded.width, decoded.height) != (job.side, job.side) {
        return Err(format!("the page is {}x{}, not {side}x{side}", decoded.width, decoded.height, side = job.side));
    }
    if !decoded.layout.depth.is_narrow_int() {
        return Err(format!("{} pages have no image tile to serve (image tiles hold 8 or 16 bits)", decoded.layout));
    }
    let (decoded, crop) = if job.halvings > 0 { halved_page(&decoded, job)? } else { (decoded, job.crop) };
    let mut out = Vec::new();
    match decoded.layout.depth {
        Depth::U8 => encoder::<u8>(job, decoded.layout)?
            .encode_crop(&decoded.bytes, crop, &mut out)
            .map_err(|e| e.to_string())?,
        _ => {
            let samples: Vec<u16> = bytemuck::pod_collect_to_vec(&decoded.bytes);
            encoder::<u16>(job, decoded.layout)?.encode_crop(&samples, crop, &mut out).map_err(|e| e.to_string())?
        }
    }
    Ok(Bytes::from(out))
}

fn encoder<T: crate::pixel::Sample>(job: &Job, layout: PixelLayout) -> Result<TileEncoder<T>, String> {
    TileEncoder::new(job.codec, layout, false, None, job.side, Vec::new()).map_err(|e| e.to_string())
}

/// The page's image part halved `job.halvings` times, placed at the crop's corner of a page
/// of the same side.
fn halved_page(page: &Decoded, job: &Job) -> Result<(Decoded, Crop), String> {
    let bpp = page.layout.bytes_per_pixel();
    let (mut w, mut h) = job.extent;
    let (b, side) = (job.border as usize, job.side as usize);
    if b + w as usize > side || b + h as usize > side {
        return Err(format!("a {w}x{h} image does not fit a {side}-texel page with border {b}"));
    }
    let mut image = Vec::with_capacity(w as usize * h as usize * bpp);
    for y in 0..h as usize {
        image.extend_from_slice(&page.bytes[((b + y) * side + b) * bpp..][..w as usize * bpp]);
    }
    for _ in 0..job.halvings {
        (image, w, h) = halve(&image, w, h, page.layout);
    }
    let crop = job.crop;
    if (crop.width, crop.height) != (w, h) || crop.x as usize + w as usize > side || crop.y as usize + h as usize > side
    {
        return Err(format!("the halved image is {w}x{h}, the tile {}x{}", crop.width, crop.height));
    }
    let mut bytes = vec![0u8; side * side * bpp];
    for y in 0..h as usize {
        let at = ((crop.y as usize + y) * side + crop.x as usize) * bpp;
        bytes[at..at + w as usize * bpp].copy_from_slice(&image[y * w as usize * bpp..][..w as usize * bpp]);
    }
    Ok((Decoded { width: job.side, height: job.side, layout: page.layout, bytes }, crop))
}

/// A 2 x 2 box halving of a `w x h` image of native-endian samples: each texel the mean of the
/// real texels under it (one or two on an odd edge), rounded half up. 8- and 16-bit samples
/// only (`render` serves no others).
pub fn halve(image: &[u8], w: u32, h: u32, layout: PixelLayout) -> (Vec<u8>, u32, u32) {
    let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
    let channels = layout.channels.count();
    let sample_bytes = layout.depth.bytes();
    let get = |x: u32, y: u32, c: usize| -> u64 {
        let at = ((y as usize * w as usize + x as usize) * channels + c) * sample_bytes;
        match layout.depth {
            Depth::U8 => image[at] as u64,
            _ => u16::from_ne_bytes([image[at], image[at + 1]]) as u64,
        }
    };
    let mut out = Vec::with_capacity(nw as usize * nh as usize * channels * sample_bytes);
    for y in 0..nh {
        let ys: &[u32] = if 2 * y + 1 < h { &[2 * y, 2 * y + 1] } else { &[2 * y] };
        for x in 0..nw {
            let xs: &[u32] = if 2 * x + 1 < w { &[2 * x, 2 * x + 1] } else { &[2 * x] };
            let n = (xs.len() * ys.len()) as u64;
            for c in 0..channels {
                let sum: u64 =
                    ys.iter().flat_map(|&yy| xs.iter().map(move |&xx| (xx, yy))).map(|(xx, yy)| get(xx, yy, c)).sum();
                let mean = (sum + n / 2) / n;
                match layout.depth {
                    Depth::U8 => out.push(mean as u8),
                    _ => out.extend_from_slice(&(mean as u16).to_ne_bytes()),
                }
            }
        }
    }
    (out, nw, nh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::PngLevel;
    use crate::pixel::Channels;

    #[test]
    fn halving_averages_real_texels_and_rounds_half_up() {
        let grey = PixelLayout::new(Channels::Grey, Depth::U8);
        // 3 x 3: the last column and row average only what is there.
        let image = [0, 1, 10, 2, 2, 20, 100, 101, 7];
        let (out, w, h) = halve(&image, 3, 3, grey);
        assert_eq!((w, h), (2, 2));
        // (0+1+2+2)/4 = 1.25 -> 1; (10+20)/2 = 15; (100+101)/2 = 100.5 -> 101; 7.
        assert_eq!(out, vec![1, 15, 101, 7]);
    }

    #[test]
    fn a_page_below_the_last_lod_is_the_halved_image_at_the_crop() {
        // An 8-texel page, border 1, holding a 4 x 2 RGB image of value 10 at (1, 1).
        let layout = PixelLayout::new(Channels::Rgb, Depth::U8);
        let mut bytes = vec![0u8; 8 * 8 * 3];
        for y in 1..3 {
            for x in 1..5 {
                bytes[(y * 8 + x) * 3..][..3].copy_from_slice(&[10, 20, 30]);
            }
        }
        let page = Page::Texels(Decoded { width: 8, height: 8, layout, bytes });
        let job = Job {
            side: 8,
            border: 1,
            crop: Crop { x: 1, y: 1, width: 2, height: 1 },
            extent: (4, 2),
            halvings: 1,
            codec: Codec::Png { level: PngLevel::Fast },
        };
        let png = render(page, &job).unwrap();
        let decoded = decode_tile(std::path::Path::new("t"), &png).unwrap();
        assert_eq!((decoded.width, decoded.height), (2, 1));
        assert_eq!(decoded.bytes, vec![10, 20, 30, 10, 20, 30]);
    }
}
