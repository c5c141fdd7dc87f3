//! JPEG XL frames (transfer syntaxes 1.2.840.10008.1.2.4.110 JPEG XL Lossless, .111 JPEG XL
//! JPEG Recompression and .112 JPEG XL): each frame one JPEG XL codestream or container,
//! decoded by libjxl through vortex-jxl (the decoder `convert` reads JPEG XL tile directories
//! with, `decode::decode_tile`), one row of frames at a time, the frames of a row in parallel
//! on the rayon pool, each read straight from the file. A frame's header is checked before its
//! texels are allocated: it must be the instance's Columns x Rows, of its samples (grey or RGB,
//! no alpha; 8 or 16 bits as Bits Allocated says). A damaged or truncated frame is an error
//! naming the file and the frame's index, column and row. A recompressed JPEG decodes to
//! RGB (or grey) as libjxl decodes it: the Photometric Interpretation the instance states for
//! the JPEG it rebuilds (`YBR_FULL_422`) is not applied again.

use std::path::{Path, PathBuf};

use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::tiff::jp2k::Codestreams;
use crate::source::tile_rows::TileRows;
use crate::source::{Embedded, ImageHeader, RowSource};

/// The frames of one instance and where its rows are.
pub(super) struct JxlFrames {
    path: PathBuf,
    /// Each grid cell's frame in the file, row-major.
    frames: Codestreams,
    size: (u32, u32),
    tile: (u32, u32),
    layout: PixelLayout,
    /// The decoded row of frames and where the reader is.
    rows: TileRows,
    label: String,
    embedded: Embedded,
}

/// The row source of the JPEG XL frames at `offsets` and `counts` (one per cell of the `tile`
/// grid over `size`) of `layout` samples; refused where a row of decoded frames and the
/// frames being decoded would not fit `max_memory`.
#[expect(clippy::too_many_arguments, reason = "the instance's attributes, each checked by the caller")]
pub(super) fn open(
    path: &Path,
    size: (u32, u32),
    tile: (u32, u32),
    (offsets, counts): (Vec<u64>, Vec<u64>),
    layout: PixelLayout,
    label: String,
    embedded: Embedded,
    max_memory: u64,
) -> Result<Box<dyn RowSource>> {
    let across = size.0.div_ceil(tile.0);
    let frame = u64::from(tile.0) * u64::from(tile.1) * layout.bytes_per_pixel() as u64;
    // A row of frames, and per worker a compressed frame (at most twice its texels, checked
    // per frame) and the decoded one before it is cropped.
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let workers = cores.min(across as usize) as u64;
    let need = (frame * u64::from(across)).saturating_add(frame.saturating_mul(3).saturating_mul(workers));
    if need > max_memory {
        return Err(TilerError::unsupported(
            path,
            format!(
                "its JPEG XL frames are {}x{}: a row of them and the frames being decoded ({} MiB) would have to be held in memory, more than --max-memory ({} MiB); raise --max-memory",
                tile.0,
                tile.1,
                need.div_ceil(1 << 20),
                max_memory >> 20
            ),
        ));
    }
    let frames = Codestreams::new(path, (offsets, counts), tile, layout.bytes_per_pixel() as u64, "frame")?;
    Ok(Box::new(JxlFrames {
        path: path.to_path_buf(),
        frames,
        size,
        tile,
        layout,
        rows: TileRows::new(size, tile, layout.bytes_per_pixel(), "frame"),
        label,
        embedded,
    }))
}

impl JxlFrames {
    /// Frame `index` into `texels`: its `w` x `h` texels inside the image, as the layout's
    /// samples (native byte order).
    fn decode_frame(&self, index: usize, w: u32, h: u32, texels: &mut Vec<u8>) -> std::result::Result<(), String> {
        let raw = self.frames.read(index)?;
        if !vortex_jxl::is_jxl(&raw) {
            return Err("it is no JPEG XL codestream or container".into());
        }
        let decoded =
            vortex_jxl::decode(&raw, self.tile).map_err(|e| format!("corrupt or truncated JPEG XL data: {e}"))?;
        let header = decoded.header;
        let channels = self.layout.channels.count() as u32;
        let wide = header.bits_per_sample > 8;
        if (header.width, header.height) != self.tile
            || header.channels != channels
            || wide != (self.layout.depth == Depth::U16)
        {
            return Err(format!(
                "the JPEG XL image is {}x{} of {} channels of {} bits; the instance's frames are {}x{} {}",
                header.width,
                header.height,
                header.channels,
                header.bits_per_sample,
                self.tile.0,
                self.tile.1,
                self.layout
            ));
        }
        let bytes: Vec<u8> = match decoded.samples {
            vortex_jxl::Samples::U8(s) => s,
            vortex_jxl::Samples::U16(s) => bytemuck::cast_slice(&s).to_vec(),
        };
        let pixel = self.layout.bytes_per_pixel();
        let (stride, row) = (self.tile.0 as usize * pixel, w as usize * pixel);
        texels.clear();
        texels.reserve(row * h as usize);
        for r in 0..h as usize {
            texels.extend_from_slice(&bytes[r * stride..r * stride + row]);
        }
        Ok(())
    }
}

impl RowSource for JxlFrames {
    rows_of_tile_rows!(decode_frame);

    fn header(&self) -> ImageHeader {
        ImageHeader { width: self.size.0, height: self.size.1, layout: self.layout }
    }

    fn embedded(&self) -> Embedded {
        self.embedded.clone()
    }

    fn describe(&self) -> String {
        let colour = match self.layout.channels {
            Channels::Grey => "grey",
            _ => "RGB",
        };
        format!(
            "{}, JPEG XL frames ({colour}, libjxl), streamed by row of frames ({}x{} frames, decoded in parallel)",
            self.label, self.tile.0, self.tile.1
        )
    }
}

/// The samples JPEG XL frames of `samples` samples of `bits` bits decode to, as an instance
/// states them: grey (`MONOCHROME2`) or RGB (`RGB`, or the `YBR_FULL_422`/`RGB` a JPEG XL JPEG
/// Recompression instance states for the JPEGs it rebuilds), 8 or 16 bits; `Err(why)` for
/// anything else.
pub(super) fn layout_of(photometric: &str, samples: u64, bits: u64) -> std::result::Result<PixelLayout, String> {
    let depth = match bits {
        8 => Depth::U8,
        16 => Depth::U16,
        _ => return Err(format!("JPEG XL frames of {bits} bits (Bits Allocated) are not read (8 and 16 are)")),
    };
    let channels = match (photometric, samples) {
        ("MONOCHROME2", 1) => Channels::Grey,
        ("RGB" | "YBR_FULL_422" | "YBR_FULL", 3) => Channels::Rgb,
        (other, n) => {
            return Err(format!(
                "JPEG XL frames of Photometric Interpretation {other} with {n} samples are not read (MONOCHROME2, RGB, YBR_FULL_422 are)"
            ));
        }
    };
    Ok(PixelLayout::new(channels, depth))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What an instance states picks the samples; what no JPEG XL frame of ours can be is
    /// named.
    #[test]
    fn the_samples_are_what_the_instance_states() {
        assert_eq!(layout_of("RGB", 3, 8), Ok(PixelLayout::new(Channels::Rgb, Depth::U8)));
        assert_eq!(layout_of("YBR_FULL_422", 3, 8), Ok(PixelLayout::new(Channels::Rgb, Depth::U8)));
        assert_eq!(layout_of("MONOCHROME2", 1, 16), Ok(PixelLayout::new(Channels::Grey, Depth::U16)));
        assert!(layout_of("MONOCHROME1", 1, 8).unwrap_err().contains("MONOCHROME1"));
        assert!(layout_of("RGB", 1, 8).is_err());
        assert!(layout_of("RGB", 3, 12).unwrap_err().contains("12 bits"));
    }
}
