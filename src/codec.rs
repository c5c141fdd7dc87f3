//! Tile codecs: turning a tile's texels into the bytes of one image file or pack payload.
//!
//! The codec also decides the stored texel format: JPEG holds 8-bit grey or RGB only, so 16-bit
//! tiles are rounded to 8 bits and alpha is either composited away (`--flatten`) or refused.
//! Raw, zstd and Deflate store any layout, as PNG and JPEG XL do. BC1 stores opaque 8-bit RGB and BC7 8-bit
//! RGB or RGBA, so grey becomes RGB (grey + alpha RGBA). Raw, zstd and BC payloads have no file
//! format: they go into packs (docs/pack-format.md) and, raw and zstd, into a TIFF's tiles;
//! Deflate and LZW are a TIFF's only. Compression runs here, on the encoder threads, so that a sink that
//! stores tiles in order (a pack, a TIFF) only writes them.

use std::borrow::Cow;
use std::cell::RefCell;
use std::ops::RangeInclusive;

use crate::error::TilerError;
use crate::layout::Crop;
use crate::pixel::{Channels, Depth, PixelLayout, Sample, u16_to_u8};

pub(crate) const DEFAULT_ZSTD_LEVEL: i32 = 3;
pub(crate) const DEFAULT_BC7_EFFORT: Bc7Effort = Bc7Effort::UltraFast;
/// `--codec jxl`'s default quality: 90, Butteraugli distance 1.0 (libjxl's own default,
/// "visually lossless"; [`vortex_jxl::distance_for_quality`]).
pub(crate) const DEFAULT_JXL_QUALITY: u8 = 90;
/// `--jxl-effort`'s default for lossy tiles (and copied JPEG tiles' recompression): on
/// 256-texel tiles effort 5 made files 4% smaller than 3 and as small as 7 (docs/jxl.md).
pub(crate) const DEFAULT_JXL_EFFORT: JxlEffort = JxlEffort::clamped(5);
/// `--jxl-effort`'s default for lossless tiles: effort 5 took 5 times 3's time for 2% less.
pub(crate) const DEFAULT_JXL_LOSSLESS_EFFORT: JxlEffort = JxlEffort::clamped(3);

impl Codec {
    /// `--codec jxl` at `quality` (`None`: lossless) with the default effort for it.
    pub(crate) fn jxl_default_effort(quality: Option<u8>) -> JxlEffort {
        match quality {
            Some(_) => DEFAULT_JXL_EFFORT,
            None => DEFAULT_JXL_LOSSLESS_EFFORT,
        }
    }
}

/// JPEG XL encoder effort, 1 (fastest) to 9 (smallest): vortex-jxl's, over libjxl.
pub use vortex_jxl::Effort as JxlEffort;

/// How a JPEG codes colour: YCbCr with its chroma subsampled or not, or RGB as it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Subsampling {
    /// 4:2:0: chroma at half resolution both ways (smaller files, what libjpeg does below q90).
    S420,
    /// 4:4:4: full-resolution chroma.
    S444,
    /// RGB without the YCbCr transform, every component at full resolution (an Adobe marker
    /// says so): what Aperio scanners and libvips at Q90 and above store; the largest files.
    Rgb,
}

impl Subsampling {
    /// Every value, in the order `--help` lists them.
    pub const ALL: [Subsampling; 3] = [Subsampling::S420, Subsampling::S444, Subsampling::Rgb];

    /// The name used on the command line (`--subsampling`) and in `info.json`.
    pub fn name(self) -> &'static str {
        match self {
            Subsampling::S420 => "420",
            Subsampling::S444 => "444",
            Subsampling::Rgb => "rgb",
        }
    }

    /// The value `name` names, if any.
    pub fn from_name(name: &str) -> Option<Subsampling> {
        Subsampling::ALL.into_iter().find(|v| v.name() == name)
    }

    /// One line on what the value does (`--help` lists it).
    pub fn about(self) -> &'static str {
        match self {
            Subsampling::S420 => {
                "4:2:0: chroma at half resolution both ways (smaller files, what libjpeg does below q90)"
            }
            Subsampling::S444 => "4:4:4: full-resolution chroma",
            Subsampling::Rgb => "RGB as it is, no YCbCr (what Aperio scanners and libvips at Q90+ store; largest)",
        }
    }

    /// Luma samples per chroma sample, across and down (RGB: every component in full).
    pub(crate) fn factor(self) -> u8 {
        match self {
            Subsampling::S420 => 2,
            Subsampling::S444 | Subsampling::Rgb => 1,
        }
    }
}

/// PNG effort.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PngLevel {
    /// fdeflate: very fast, files a little larger.
    Fast,
    /// zlib-like default.
    Default,
    /// Slowest, smallest.
    Best,
}

impl PngLevel {
    /// Every value, in the order `--help` lists them.
    pub const ALL: [PngLevel; 3] = [PngLevel::Fast, PngLevel::Default, PngLevel::Best];

    /// The name used on the command line (`--png-compression`) and in `info.json`.
    pub fn name(self) -> &'static str {
        match self {
            PngLevel::Fast => "fast",
            PngLevel::Default => "default",
            PngLevel::Best => "best",
        }
    }

    /// The value `name` names, if any.
    pub fn from_name(name: &str) -> Option<PngLevel> {
        PngLevel::ALL.into_iter().find(|v| v.name() == name)
    }

    /// One line on what the value does (`--help` lists it).
    pub fn about(self) -> &'static str {
        match self {
            PngLevel::Fast => "fdeflate: very fast, files a little larger",
            PngLevel::Default => "zlib-like default",
            PngLevel::Best => "Slowest, smallest",
        }
    }
}

/// BC7 encoder effort (the BC encoders are vortex-bc's, shared with the runtime's transcoding).
pub use vortex_bc::Bc7Effort;

/// zstd levels `--zstd-level` accepts (zstd's negative "fast" levels are left out).
pub(crate) const ZSTD_LEVELS: RangeInclusive<i32> = 1..=22;

/// How a tile's texels become bytes (`--codec`, `info.json`'s `codec`). JPEG and PNG tiles
/// are image files, so a tile directory or a viewer layout can hold them; the others only a
/// pack or a TIFF.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    /// JPEG (libjpeg-turbo): 8-bit grey or RGB, lossy.
    Jpeg {
        /// 1 to 100 (`--quality`).
        quality: u8,
        /// Chroma subsampling of RGB tiles; grey tiles have none.
        subsampling: Subsampling,
    },
    /// PNG: any channels, 8 or 16 bits, lossless.
    Png {
        /// Compression effort (`--png-compression`): size and time, never the texels.
        level: PngLevel,
    },
    /// Texels as a GPU uploads them (packs only).
    Raw,
    /// Raw texels compressed with zstd, rows filtered first (packs, and a TIFF's tiles).
    Zstd {
        /// The zstd level, 1 to 22 (`--zstd-level`).
        level: i32,
        /// How each row is filtered first (`--codec zstd-delta`: [`RowFilter::Delta`]).
        filter: RowFilter,
    },
    /// Raw texels as one zlib stream, rows filtered first (a TIFF's tiles only: "Adobe
    /// Deflate", the filter its predictor).
    Deflate {
        /// The zlib level, 0 (stored) to 9.
        level: u32,
        /// How each row is filtered first.
        filter: RowFilter,
    },
    /// Raw texels as one TIFF LZW stream (compression 5: codes most significant bit first,
    /// widened one code early), rows filtered first (a TIFF's tiles only, as for Deflate).
    Lzw {
        /// How each row is filtered first.
        filter: RowFilter,
    },
    /// BC1 blocks, opaque RGB (packs only).
    Bc1,
    /// BC7 blocks, RGB or RGBA (packs only).
    Bc7 {
        /// The encoder's effort (`--bc7-effort`): time against quality.
        effort: Bc7Effort,
    },
    /// JPEG XL (libjxl, through vortex-jxl): any channels, 8 or 16 bits, lossy or lossless.
    Jxl {
        /// `Some(q)`: lossy at the Butteraugli distance quality q (1 to 100, `--quality`) maps
        /// to ([`vortex_jxl::distance_for_quality`]); `None`: lossless (`--lossless`).
        quality: Option<u8>,
        /// Encoder effort (`--jxl-effort`): time against size, never the texels.
        effort: JxlEffort,
    },
}

impl Codec {
    /// The most bytes (capacity) one encoding of a `side`-texel tile stored as `stored` can
    /// hold, for the plan's memory bound (`pyramid::stripes`): raw and BC tiles are a fixed
    /// size; zstd's output buffer is `ZSTD_compressBound`; a JPEG is at most libjpeg-turbo's
    /// `tj3JPEGBufSize` (6 bytes a texel at 4:4:4, 3 at 4:2:0, 2 for grey, and 2048 of
    /// headers), a PNG its filtered rows in stored Deflate blocks with every chunk's framing
    /// (generously: an eighth more and 1 KiB). Both grow their buffer as they write, which
    /// `split`'s encoders shrink to the length once a tile is encoded (`encoders::prepare`).
    pub(crate) fn most_encoded_bytes(&self, side: u32, stored: PixelLayout) -> u64 {
        let side = side as u64;
        let (texels, channels) = (side * side, stored.channels);
        let stored = texels * stored.bytes_per_pixel() as u64;
        match *self {
            Codec::Raw => stored,
            Codec::Zstd { .. } => zstd::zstd_safe::compress_bound(stored as usize) as u64,
            // zlib's stored blocks cost 5 bytes in 64 KiB; an eighth more is generous.
            Codec::Deflate { .. } => stored + stored / 8 + 1024,
            // A code (12 bits at most) for every byte, at worst, and the clear codes between.
            Codec::Lzw { .. } => stored + stored / 2 + 1024,
            Codec::Bc1 => side.div_ceil(4).pow(2) * 8,
            Codec::Bc7 { .. } => side.div_ceil(4).pow(2) * 16,
            Codec::Jpeg { subsampling, .. } => {
                let per_texel = match (channels, subsampling) {
                    (Channels::Grey, _) => 2,
                    (_, Subsampling::S420) => 3,
                    (_, Subsampling::S444 | Subsampling::Rgb) => 6,
                };
                side.next_multiple_of(16).pow(2) * per_texel + 2048
            }
            Codec::Png { .. } => {
                let filtered = stored + side;
                filtered + filtered / 8 + 1024
            }
            Codec::Jxl { .. } => vortex_jxl::most_encoded_bytes(stored as usize) as u64,
        }
    }

    /// The `codec` member of `info.json` (and `--codec`).
    pub fn name(&self) -> &'static str {
        match self {
            Codec::Jpeg { .. } => "jpeg",
            Codec::Png { .. } => "png",
            Codec::Raw => "raw",
            Codec::Zstd { filter: RowFilter::Delta, .. } => "zstd-delta",
            Codec::Zstd { .. } => "zstd",
            // `--codec deflate`: a TIFF filters integer samples and says so in its tags.
            Codec::Deflate { .. } => "deflate",
            Codec::Lzw { .. } => "lzw",
            Codec::Bc1 => "bc1",
            Codec::Bc7 { .. } => "bc7",
            Codec::Jxl { .. } => "jxl",
        }
    }

    /// The usual file extension (for raw, zstd and BC only the names `info.json` records).
    pub fn extension(&self) -> &'static str {
        match self {
            Codec::Jpeg { .. } => "jpg",
            Codec::Png { .. } => "png",
            Codec::Raw => "raw",
            Codec::Zstd { .. } => "zst",
            Codec::Deflate { .. } => "zz",
            Codec::Lzw { .. } => "lzw",
            Codec::Bc1 => "bc1",
            Codec::Bc7 { .. } => "bc7",
            Codec::Jxl { .. } => "jxl",
        }
    }

    /// Whether a tile of this codec is an image file (JPEG, PNG, JPEG XL) that a directory of
    /// tiles can hold; the others are pack payloads only.
    pub(crate) fn writes_files(&self) -> bool {
        matches!(self, Codec::Jpeg { .. } | Codec::Png { .. } | Codec::Jxl { .. })
    }

    /// Whether tiles of this codec lose texels: JPEG, lossy JPEG XL, BC1 and BC7.
    pub(crate) fn is_lossy(&self) -> bool {
        matches!(self, Codec::Jpeg { .. } | Codec::Bc1 | Codec::Bc7 { .. } | Codec::Jxl { quality: Some(_), .. })
    }

    /// Refuses a tile side this codec cannot store: BC blocks are 4x4 texels.
    pub(crate) fn check_tile_size(&self, side: u32) -> Result<(), TilerError> {
        if matches!(self, Codec::Bc1 | Codec::Bc7 { .. }) && !side.is_multiple_of(4) {
            return Err(TilerError::Options(format!(
                "--codec {} stores 4x4-texel blocks, so --tile-size must be a multiple of 4, not {side}",
                self.name()
            )));
        }
        Ok(())
    }

    /// The texel layout tiles are stored in for a source of `source` layout; `depth` asks for
    /// a sample depth other than the source's.
    pub fn stored_layout(
        &self,
        source: PixelLayout,
        flatten: bool,
        depth: Option<Depth>,
    ) -> Result<PixelLayout, TilerError> {
        let channels = if flatten { source.channels.without_alpha() } else { source.channels };
        if !source.depth.is_narrow_int() || depth.is_some_and(|d| !d.is_narrow_int()) {
            return self.stored_wide(source, flatten, depth);
        }
        match self {
            Codec::Png { .. }
            | Codec::Jxl { .. }
            | Codec::Raw
            | Codec::Zstd { .. }
            | Codec::Deflate { .. }
            | Codec::Lzw { .. } => Ok(PixelLayout::new(channels, depth.unwrap_or(source.depth))),
            Codec::Bc1 | Codec::Bc7 { .. } => {
                let name = self.name();
                if depth == Some(Depth::U16) {
                    return Err(TilerError::Options(format!(
                        "--codec {name} stores 8-bit samples only: use --codec png, raw or zstd for 16-bit tiles"
                    )));
                }
                if *self == Codec::Bc1 && channels.has_alpha() {
                    return Err(TilerError::Options(format!(
                        "the source is {source} but --codec bc1 stores opaque RGB: use --codec bc7 to keep alpha, or --flatten to composite it over --background"
                    )));
                }
                let channels = if channels.has_alpha() { Channels::Rgba } else { Channels::Rgb };
                Ok(PixelLayout::new(channels, Depth::U8))
            }
            Codec::Jpeg { .. } => {
                if channels.has_alpha() {
                    return Err(TilerError::Options(format!(
                        "the source is {source} but JPEG has no alpha channel: use --codec png to keep alpha, or --flatten to composite it over --background"
                    )));
                }
                if depth == Some(Depth::U16) {
                    return Err(TilerError::Options(
                        "JPEG stores 8-bit samples only: use --codec png for 16-bit tiles".into(),
                    ));
                }
                Ok(PixelLayout::new(channels, Depth::U8))
            }
        }
    }
}

impl Codec {
    /// [`stored_layout`](Self::stored_layout) for 32-bit and float samples: raw and zstd
    /// tiles keep them as they are, float ones also as half floats (`--tile-type half`); the
    /// other codecs hold 8 or 16 bits, and a silent cut of the range would lose the data.
    fn stored_wide(&self, source: PixelLayout, flatten: bool, depth: Option<Depth>) -> Result<PixelLayout, TilerError> {
        let name = self.name();
        if flatten && source.channels.has_alpha() {
            return Err(TilerError::Options(format!(
                "--flatten composites 8- and 16-bit samples; the source is {source}: keep its alpha with --codec raw or zstd"
            )));
        }
        if !matches!(self, Codec::Raw | Codec::Zstd { .. } | Codec::Deflate { .. } | Codec::Lzw { .. }) {
            return Err(TilerError::Options(format!(
                "the source is {source}, which --codec {name} cannot hold without cutting its range: use --codec raw, zstd or zstd-delta (packs) or --layout ome-zarr to keep it, or map it onto 8 or 16 bits with --range MIN:MAX"
            )));
        }
        let stored = match (source.depth, depth) {
            (d, None) => d,
            (d, Some(want)) if want == d => d,
            (Depth::F32, Some(Depth::F16)) => Depth::F16,
            (d, Some(want)) => {
                return Err(TilerError::Options(format!(
                    "--tile-type {} cannot store {} samples: raw and zstd tiles keep them as {}{}",
                    want.tile_type(),
                    d.tile_type(),
                    d.tile_type(),
                    if d == Depth::F32 { " or half" } else { "" }
                )));
            }
        };
        Ok(PixelLayout::new(source.channels, stored))
    }
}

/// How the rows of a tile's raw bytes are filtered before a lossless codec compresses them
/// (TIFF's `Predictor`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RowFilter {
    /// The bytes as they are (`Predictor` 1).
    None,
    /// Each sample less the same sample of the texel to its left, wrapping at the sample's
    /// width: the pack's `zstd-delta` (docs/pack-format.md) and TIFF's horizontal predictor
    /// (`Predictor` 2) for integer samples.
    Delta,
    /// TIFF's floating-point predictor (`Predictor` 3, Adobe's Photoshop TIFF technical note
    /// 3), for float samples: each row's sample bytes regrouped into planes, the most
    /// significant bytes first, then each byte less the byte one texel's samples before it.
    FloatingPoint,
}

impl RowFilter {
    /// [`RowFilter::Delta`] where `on`, else none.
    pub fn delta(on: bool) -> RowFilter {
        if on { RowFilter::Delta } else { RowFilter::None }
    }
}

/// Encodes tiles of one layout with one codec; shared by all worker threads.
pub struct TileEncoder<T> {
    codec: Codec,
    source: PixelLayout,
    stored: PixelLayout,
    side: u32,
    /// Colour alpha is composited over, in source samples (`--flatten`).
    matte: Vec<T>,
}

impl<T: Sample> TileEncoder<T> {
    /// An encoder of `side`-texel tiles of `source` texels with `codec`: `flatten` composites
    /// alpha over `matte` (one texel in source samples), `depth` asks for stored samples of
    /// another depth. Refuses a codec that cannot store the layout, or a `side` it cannot
    /// take (BC tiles: a multiple of 4), with the message the command line prints.
    pub fn new(
        codec: Codec,
        source: PixelLayout,
        flatten: bool,
        depth: Option<Depth>,
        side: u32,
        matte: Vec<T>,
    ) -> Result<Self, TilerError> {
        let stored = codec.stored_layout(source, flatten, depth)?;
        codec.check_tile_size(side)?;
        Ok(TileEncoder { codec, source, stored, side, matte })
    }

    /// The texels the tiles hold, after flattening and the stored depth.
    pub fn stored_layout(&self) -> PixelLayout {
        self.stored
    }

    pub(crate) fn source_layout(&self) -> PixelLayout {
        self.source
    }

    /// The codec it encodes with.
    pub(crate) fn codec(&self) -> Codec {
        self.codec
    }

    /// Texels in the stored channels: alpha composited away if the stored layout has none, grey
    /// repeated into RGB if it is RGB (BC1, BC7).
    fn flattened<'a>(&self, texels: &'a [T]) -> Cow<'a, [T]> {
        let mut channels = self.source.channels;
        let mut texels = Cow::Borrowed(texels);
        if channels.has_alpha() && !self.stored.channels.has_alpha() {
            texels = Cow::Owned(flatten(&texels, channels.count(), &self.matte));
            channels = channels.without_alpha();
        }
        if channels.count() < self.stored.channels.count() {
            // Grey (+ alpha) to RGB(A).
            let n = channels.count();
            texels = Cow::Owned(
                texels
                    .chunks_exact(n)
                    .flat_map(|t| [t[0], t[0], t[0]].into_iter().chain(t[1..].iter().copied()))
                    .collect(),
            );
        }
        texels
    }

    /// Samples of the stored layout (depth converted), little-endian: a raw tile's bytes.
    fn stored_bytes<'a>(&self, texels: &'a [T]) -> Cow<'a, [u8]> {
        match self.stored.depth {
            Depth::U8 => to_u8(texels),
            Depth::U16 => {
                let widen = if T::DEPTH == Depth::U8 { 257 } else { 1 };
                Cow::Owned(texels.iter().flat_map(|s| (s.to_u16() * widen).to_le_bytes()).collect())
            }
            // `stored_wide` allows these only from samples of the same depth (f32 for half).
            Depth::U32 | Depth::F32 => le_bytes(texels),
            Depth::F16 => Cow::Owned(
                bytemuck::cast_slice::<T, u32>(texels)
                    .iter()
                    .flat_map(|bits| half::f16::from_f32(f32::from_bits(*bits)).to_bits().to_le_bytes())
                    .collect(),
            ),
        }
    }

    /// One source texel as stored (flattened, depth converted), little-endian samples.
    pub(crate) fn stored_texel(&self, texel: &[T]) -> Vec<u8> {
        self.stored_bytes(&self.flattened(texel)).into_owned()
    }

    /// Encodes a `side x side` tile given in the source layout.
    pub fn encode(&self, texels: &[T], out: &mut Vec<u8>) -> Result<(), EncodeError> {
        out.clear();
        let texels = self.flattened(texels);
        let texels = &texels[..];
        match self.codec {
            Codec::Jpeg { quality, subsampling } => {
                self.encode_jpeg(texels, (self.side, self.side), quality, subsampling, out)
            }
            Codec::Png { level } => self.encode_png(texels, (self.side, self.side), level, out),
            Codec::Raw => {
                out.extend_from_slice(&self.stored_bytes(texels));
                Ok(())
            }
            Codec::Zstd { level, filter } => self.encode_zstd(texels, level, filter, out),
            Codec::Deflate { level, filter } => self.encode_deflate(texels, level, filter, out),
            Codec::Lzw { filter } => self.encode_lzw(texels, filter, out),
            Codec::Bc1 => self.encode_bc(texels, None, out),
            Codec::Bc7 { effort } => self.encode_bc(texels, Some(effort), out),
            Codec::Jxl { quality, effort } => self.encode_jxl(texels, (self.side, self.side), quality, effort, out),
        }
    }

    /// Encodes the `crop` part of a `side x side` tile as an image file of the crop's size (a
    /// viewer layout's edge tile). Only image codecs (JPEG, PNG) make files of any size.
    pub(crate) fn encode_crop(&self, texels: &[T], crop: Crop, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        let (side, channels) = (self.side as usize, self.source.channels.count());
        if crop == Crop::whole(self.side) {
            return self.encode(texels, out);
        }
        if crop.x + crop.width > self.side || crop.y + crop.height > self.side || crop.width == 0 || crop.height == 0 {
            return Err(EncodeError::CropOutside { crop, side: self.side });
        }
        let (x, w) = (crop.x as usize * channels, crop.width as usize * channels);
        let mut part = Vec::with_capacity(w * crop.height as usize);
        for row in crop.y as usize..(crop.y + crop.height) as usize {
            part.extend_from_slice(&texels[row * side * channels + x..][..w]);
        }
        out.clear();
        let part = self.flattened(&part);
        let size = (crop.width, crop.height);
        match self.codec {
            Codec::Jpeg { quality, subsampling } => self.encode_jpeg(&part, size, quality, subsampling, out),
            Codec::Png { level } => self.encode_png(&part, size, level, out),
            Codec::Jxl { quality, effort } => self.encode_jxl(&part, size, quality, effort, out),
            other => Err(EncodeError::NotCroppable { codec: other.name() }),
        }
    }

    /// zstd of the raw tile, rows filtered first (`zstd-delta`: the filter of those tiles
    /// in docs/pack-format.md). One compression context per thread.
    fn encode_zstd(&self, texels: &[T], level: i32, filter: RowFilter, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        *out = zstd_frame(&self.filtered_bytes(texels, filter), level).map_err(|m| failed("zstd", m))?;
        Ok(())
    }

    /// One zlib stream of the raw tile, rows filtered first.
    fn encode_deflate(
        &self,
        texels: &[T],
        level: u32,
        filter: RowFilter,
        out: &mut Vec<u8>,
    ) -> Result<(), EncodeError> {
        use std::io::Write;
        let raw = self.filtered_bytes(texels, filter);
        let mut z = flate2::write::ZlibEncoder::new(std::mem::take(out), flate2::Compression::new(level.min(9)));
        *out = z.write_all(&raw).and_then(|()| z.finish()).map_err(|e| failed("deflate", e))?;
        Ok(())
    }

    /// One TIFF LZW stream of the raw tile (a clear code first, the end code last: `weezl`,
    /// the `tiff` crate's coder), rows filtered first.
    fn encode_lzw(&self, texels: &[T], filter: RowFilter, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        let raw = self.filtered_bytes(texels, filter);
        let mut encoder = weezl::encode::Encoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8);
        let result = encoder.into_vec(out).encode_all(&raw);
        result.status.map(drop).map_err(|e| failed("lzw", e))
    }

    /// The raw tile's bytes (little-endian samples), each row filtered as `filter` says:
    /// [`RowFilter::Delta`] by `vortex_pack::format::delta_encode_rows`,
    /// [`RowFilter::FloatingPoint`] by [`float_predict_rows`].
    fn filtered_bytes<'a>(&self, texels: &'a [T], filter: RowFilter) -> Cow<'a, [u8]> {
        let mut raw = self.stored_bytes(texels);
        let (c, sb) = (self.stored.channels.count(), self.stored.depth.bytes());
        match filter {
            RowFilter::None => {}
            RowFilter::Delta => vortex_pack::format::delta_encode_rows(raw.to_mut(), self.side as usize, c, sb),
            RowFilter::FloatingPoint => float_predict_rows(raw.to_mut(), self.side as usize, c, sb),
        }
        raw
    }

    /// BC1 (`bc7` None) or BC7 blocks of an 8-bit RGB or RGBA tile, by Intel's ISPC texture
    /// compressor; the blocks come in rows, top down, as a GPU upload takes them.
    fn encode_bc(&self, texels: &[T], bc7: Option<Bc7Effort>, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        let samples = to_u8(texels);
        let rgba: Cow<[u8]> = match self.stored.channels {
            // Colour under alpha 0 is never seen, but the encoder fits it like any other texel
            // and spends the block's endpoints (alpha's too) on it: noise there cost up to 225
            // code values of alpha (docs/accuracy.md). It is stored as 0.
            Channels::Rgba if samples.chunks_exact(4).any(|t| t[3] == 0 && t[..3] != [0, 0, 0]) => Cow::Owned(
                samples
                    .chunks_exact(4)
                    .flat_map(|t| if t[3] == 0 { [0; 4] } else { [t[0], t[1], t[2], t[3]] })
                    .collect(),
            ),
            Channels::Rgba => samples,
            _ => Cow::Owned(samples.chunks_exact(3).flat_map(|t| [t[0], t[1], t[2], 255]).collect()),
        };
        let side = self.side;
        match bc7 {
            None => vortex_bc::encode_bc1(&rgba, side, side, out),
            Some(effort) => vortex_bc::encode_bc7(&rgba, side, side, effort, self.stored.channels.has_alpha(), out),
        }
        .map_err(|e| failed(if bc7.is_some() { "bc7" } else { "bc1" }, e))
    }

    /// libjpeg-turbo's encoder (MozJPEG in its libjpeg-turbo-compatible "fastest" profile: no
    /// trellis, no scan optimisation), the encoder `vips` uses, with SIMD when built with nasm.
    fn encode_jpeg(
        &self,
        texels: &[T],
        (width, height): (u32, u32),
        quality: u8,
        subsampling: Subsampling,
        out: &mut Vec<u8>,
    ) -> Result<(), EncodeError> {
        let samples = to_u8(texels);
        let buf = std::mem::take(out);
        *out = encode_jpeg(&samples, (width, height), self.stored.channels, quality, subsampling, buf)
            .map_err(|m| failed("jpeg", m))?;
        Ok(())
    }

    /// One JPEG XL file of the stored samples (8 or 16 bits, the source's sRGB colour): lossy
    /// at the distance `quality` maps to, or lossless where it is `None`.
    fn encode_jxl(
        &self,
        texels: &[T],
        (width, height): (u32, u32),
        quality: Option<u8>,
        effort: JxlEffort,
        out: &mut Vec<u8>,
    ) -> Result<(), EncodeError> {
        let quality = match quality {
            Some(q) => vortex_jxl::Quality::Distance(vortex_jxl::distance_for_quality(q)),
            None => vortex_jxl::Quality::Lossless,
        };
        let channels = self.stored.channels.count() as u32;
        let wide: Vec<u16>;
        let narrow: Cow<[u8]>;
        let pixels = match self.stored.depth {
            Depth::U8 => {
                narrow = to_u8(texels);
                vortex_jxl::Pixels::U8(&narrow)
            }
            Depth::U16 => {
                let widen = if T::DEPTH == Depth::U8 { 257 } else { 1 };
                wide = texels.iter().map(|s| s.to_u16() * widen).collect();
                vortex_jxl::Pixels::U16(&wide)
            }
            other => return Err(EncodeError::Samples { codec: "jxl", samples: other.tile_type() }),
        };
        let image = vortex_jxl::Image { width, height, channels, pixels };
        *out = vortex_jxl::encode(&image, quality, effort).map_err(|e| failed("jxl", e))?;
        Ok(())
    }

    fn encode_png(
        &self,
        texels: &[T],
        (width, height): (u32, u32),
        level: PngLevel,
        out: &mut Vec<u8>,
    ) -> Result<(), EncodeError> {
        let mut enc = png::Encoder::new(&mut *out, width, height);
        enc.set_color(match self.stored.channels {
            Channels::Grey => png::ColorType::Grayscale,
            Channels::GreyAlpha => png::ColorType::GrayscaleAlpha,
            Channels::Rgb => png::ColorType::Rgb,
            Channels::Rgba => png::ColorType::Rgba,
        });
        enc.set_compression(match level {
            PngLevel::Fast => png::Compression::Fast,
            PngLevel::Default => png::Compression::Balanced,
            PngLevel::Best => png::Compression::High,
        });
        let data: Cow<[u8]> = match self.stored.depth {
            Depth::U8 => {
                enc.set_depth(png::BitDepth::Eight);
                to_u8(texels)
            }
            Depth::U16 => {
                enc.set_depth(png::BitDepth::Sixteen);
                let widen = if T::DEPTH == Depth::U8 { 257 } else { 1 };
                Cow::Owned(texels.iter().flat_map(|s| (s.to_u16() * widen).to_be_bytes()).collect())
            }
            other => return Err(EncodeError::Samples { codec: "png", samples: other.tile_type() }),
        };
        let mut writer = enc.write_header().map_err(|e| failed("png", e))?;
        writer.write_image_data(&data).map_err(|e| failed("png", e))?;
        writer.finish().map_err(|e| failed("png", e))
    }
}

/// Why a tile could not be encoded ([`TileEncoder::encode`]).
///
/// New variants may come in any release: match the ones you act on and keep a `_` arm.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// The codec stores no samples of this type.
    #[error("{codec} tiles hold 8 or 16-bit samples, not {samples}")]
    Samples {
        /// The codec, by its `--codec` name.
        codec: &'static str,
        /// The samples' `tileType` (`unsignedInt`, `float`, ...).
        samples: &'static str,
    },
    /// The part of the tile asked for is not inside it.
    #[error("crop {crop:?} is not inside a {side}-texel tile")]
    CropOutside {
        /// The part asked for.
        crop: Crop,
        /// The tile's side in texels.
        side: u32,
    },
    /// The codec's tiles are all the tile size: only image files (JPEG, PNG, JPEG XL) are cut
    /// to an edge tile's size.
    #[error("{codec} tiles are square; only jpeg, png and jxl tiles can be cropped")]
    NotCroppable {
        /// The codec, by its `--codec` name.
        codec: &'static str,
    },
    /// The codec's library failed.
    #[error("{codec}: {message}")]
    Failed {
        /// The codec, by its `--codec` name.
        codec: &'static str,
        /// The library's message.
        message: String,
    },
}

/// `codec`'s library failed with `e`.
fn failed(codec: &'static str, e: impl std::fmt::Display) -> EncodeError {
    EncodeError::Failed { codec, message: e.to_string() }
}

/// Samples as 8-bit, rounding 16-bit ones to the nearest 8-bit value. (32-bit and float
/// samples never reach an 8-bit codec: `Codec::stored_wide` refuses them.)
fn to_u8<T: Sample>(texels: &[T]) -> Cow<'_, [u8]> {
    match T::DEPTH {
        Depth::U16 => Cow::Owned(texels.iter().map(|s| u16_to_u8(s.to_u16())).collect()),
        _ => Cow::Borrowed(bytemuck::cast_slice(texels)),
    }
}

/// Samples as their little-endian bytes, as raw tiles store them.
fn le_bytes<T: Sample>(texels: &[T]) -> Cow<'_, [u8]> {
    let bytes: &[u8] = bytemuck::cast_slice(texels);
    if cfg!(target_endian = "little") {
        return Cow::Borrowed(bytes);
    }
    Cow::Owned(bytes.chunks_exact(T::DEPTH.bytes()).flat_map(|s| s.iter().rev().copied()).collect())
}

/// Composites straight alpha over `matte` (the colour channels of one texel), rounding once.
fn flatten<T: Sample>(texels: &[T], channels: usize, matte: &[T]) -> Vec<T> {
    let colour = channels - 1;
    let max = T::MAX;
    let mut out = Vec::with_capacity(texels.len() / channels * colour);
    for px in texels.chunks_exact(channels) {
        let a = px[colour].to_u64();
        for c in 0..colour {
            let v = px[c].to_u64() * a + matte[c].to_u64() * (max - a);
            out.push(T::from_u64((2 * v + max) / (2 * max)));
        }
    }
    out
}

/// One JPEG baseline stream of `width x height` 8-bit `samples` (grey, else RGB, interleaved),
/// at `quality`, coded as `subsampling` says (RGB with an Adobe marker, or YCbCr), written
/// into `buf`'s allocation.
pub(crate) fn encode_jpeg(
    samples: &[u8],
    (width, height): (u32, u32),
    channels: Channels,
    quality: u8,
    subsampling: Subsampling,
    buf: Vec<u8>,
) -> Result<Vec<u8>, String> {
    let colour = match channels {
        Channels::Grey => mozjpeg::ColorSpace::JCS_GRAYSCALE,
        _ => mozjpeg::ColorSpace::JCS_RGB,
    };
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> std::io::Result<Vec<u8>> {
        let mut c = mozjpeg::Compress::new(colour);
        c.set_fastest_defaults();
        c.set_size(width as usize, height as usize);
        c.set_quality(quality as f32);
        if colour == mozjpeg::ColorSpace::JCS_RGB {
            if subsampling == Subsampling::Rgb {
                // Kept as RGB, each component at full resolution, with an Adobe marker.
                c.set_color_space(mozjpeg::ColorSpace::JCS_RGB);
            } else {
                let px = subsampling.factor();
                c.set_chroma_sampling_pixel_sizes((px, px), (px, px));
            }
        }
        let mut started = c.start_compress(buf)?;
        started.write_scanlines(samples)?;
        started.finish()
    }));
    match result {
        Ok(Ok(bytes)) => Ok(bytes),
        Ok(Err(e)) => Err(e.to_string()),
        Err(_) => Err("libjpeg failed".into()),
    }
}

/// TIFF's floating-point predictor (`Predictor` 3) on rows of `width` texels of `channels`
/// little-endian samples of `sample_bytes` bytes: each row's bytes regrouped into planes, every
/// sample's most significant byte first and its least significant last, then each byte less
/// the byte `channels` places before it (one texel back within a plane; the difference runs on
/// across the planes' boundaries, as the technical note defines it).
pub(crate) fn float_predict_rows(bytes: &mut [u8], width: usize, channels: usize, sample_bytes: usize) {
    let samples = width * channels;
    let row_bytes = samples * sample_bytes;
    if row_bytes == 0 {
        return;
    }
    let mut planes = vec![0u8; row_bytes];
    for row in bytes.chunks_exact_mut(row_bytes) {
        for (i, sample) in row.chunks_exact(sample_bytes).enumerate() {
            for (b, byte) in sample.iter().enumerate() {
                planes[(sample_bytes - 1 - b) * samples + i] = *byte;
            }
        }
        for i in (channels..row_bytes).rev() {
            planes[i] = planes[i].wrapping_sub(planes[i - channels]);
        }
        row.copy_from_slice(&planes);
    }
}

/// One zstd frame of `bytes` (tiles, OME-Zarr chunks); one compression context per thread, kept
/// for the next call at the same level.
pub(crate) fn zstd_frame(bytes: &[u8], level: i32) -> Result<Vec<u8>, String> {
    thread_local! {
        static ZSTD: RefCell<Option<(i32, zstd::bulk::Compressor<'static>)>> = const { RefCell::new(None) };
    }
    ZSTD.with(|cell| {
        let mut cell = cell.borrow_mut();
        if cell.as_ref().is_none_or(|(l, _)| *l != level) {
            *cell = Some((level, zstd::bulk::Compressor::new(level).map_err(|e| format!("zstd: {e}"))?));
        }
        let Some((_, compressor)) = cell.as_mut() else { unreachable!("filled above") };
        compressor.compress(bytes).map_err(|e| format!("zstd: {e}"))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Worked by hand from the technical note: 1.0 and 2.0 (00 00 80 3F, 00 00 00 40) regroup
    /// into the planes 3F 40 | 80 00 | 00 00 | 00 00, then each byte less the one before.
    #[test]
    fn the_floating_point_predictor_regroups_then_differences() {
        let mut row: Vec<u8> = [1.0f32, 2.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        float_predict_rows(&mut row, 2, 1, 4);
        assert_eq!(row, [0x3F, 0x01, 0x40, 0x80, 0, 0, 0, 0]);
        // Two channels: each byte less the one two places back; rows are independent.
        let mut rows: Vec<u8> = [1.0f32, 2.0, 1.0, 2.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        float_predict_rows(&mut rows, 1, 2, 4);
        assert_eq!(rows, [0x3F, 0x40, 0x41, 0xC0, 0x80, 0, 0, 0, 0x3F, 0x40, 0x41, 0xC0, 0x80, 0, 0, 0]);
    }

    #[test]
    fn flatten_composites_over_matte() {
        let px = [255u8, 0, 0, 255, 255, 0, 0, 0, 255, 0, 0, 128];
        let out = flatten(&px, 4, &[0, 0, 255]);
        assert_eq!(out, vec![255, 0, 0, 0, 0, 255, 128, 0, 127]);
    }

    #[test]
    fn jpeg_refuses_alpha_unless_flattened() {
        let codec = Codec::Jpeg { quality: 85, subsampling: Subsampling::S420 };
        let rgba = PixelLayout::new(Channels::Rgba, Depth::U16);
        assert!(codec.stored_layout(rgba, false, None).is_err());
        assert!(codec.stored_layout(rgba, true, Some(Depth::U16)).is_err());
        assert_eq!(codec.stored_layout(rgba, true, None).unwrap(), PixelLayout::new(Channels::Rgb, Depth::U8));
    }
}
