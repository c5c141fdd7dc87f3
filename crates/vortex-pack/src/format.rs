//! The on-disk structures of a pack, exactly as `docs/pack-format.md` draws them: a 192-byte
//! header, a level table of 32-byte rows, an index of 24-byte entries, then metadata and data.
//! All integers are little-endian. Encoding and decoding live side by side so that reader and
//! writer cannot disagree.

/// `\x89VTP\r\n\x1a\n`: the high bit catches 7-bit transfers, CR LF and LF catch newline
/// conversion, 0x1A stops `type` on DOS, as in PNG's signature.
pub const MAGIC: [u8; 8] = *b"\x89VTP\r\n\x1a\n";
/// The format's major version: a reader reads packs of its own major version only.
pub const MAJOR: u16 = 1;
/// 1.1 adds the `zstd-delta` tile kind (and required-feature bit 0 for it) and specifies the
/// BC1 and BC7 payloads that 1.0 reserved.
pub const MINOR: u16 = 1;
/// Bytes of the header.
pub const HEADER_LEN: usize = 192;
/// Bytes of one level-table row.
pub const LEVEL_LEN: usize = 32;
/// Bytes of one index entry.
pub const ENTRY_LEN: usize = 24;
/// Required-feature bit 0: the pack holds `zstd-delta` tiles (kind 8), which a 1.0 reader does
/// not know. A writer sets it exactly when it stores such a tile.
pub const REQUIRED_ZSTD_DELTA: u64 = 1 << 0;
/// Required-feature bit 1: the samples are 32-bit, or floats ([`Description::sample_format`]
/// 1): a 1.1 reader without this bit would take float bits for integers. A writer sets it
/// exactly for such packs, so that every other pack's bytes are as 1.1 made them.
pub const REQUIRED_WIDE_SAMPLES: u64 = 1 << 1;
/// Required-feature bit 2: the pack holds JPEG XL tiles (kind 9), which an older reader does
/// not know. A writer sets it exactly when it stores such a tile.
pub const REQUIRED_JXL: u64 = 1 << 2;
/// Required-feature bits this reader understands.
pub const KNOWN_REQUIRED_FEATURES: u64 = REQUIRED_ZSTD_DELTA | REQUIRED_WIDE_SAMPLES | REQUIRED_JXL;
/// [`Description::sample_format`] of unsigned integer samples.
pub const SAMPLE_UNSIGNED: u8 = 0;
/// [`Description::sample_format`] of IEEE 754 float samples (binary16 or binary32).
pub const SAMPLE_FLOAT: u8 = 1;

/// How a tile's bytes are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum TileKind {
    /// No data: a runtime falls back to the parent tile.
    Absent = 0,
    /// Every texel has one value, held in the entry itself; no payload.
    Constant = 1,
    /// Texels as they are uploaded: `tile_size^2 x channels x sample_bytes` bytes, rows top down.
    Raw = 2,
    /// `Raw` compressed with zstd.
    Zstd = 3,
    /// A PNG file of the tile (8 or 16-bit samples, big-endian as PNG defines them).
    Png = 4,
    /// A baseline JPEG file of the tile (8-bit samples; grey or RGB).
    Jpeg = 5,
    /// BC1 blocks (opaque RGB, 8 bytes per 4x4 texels), uploadable as-is.
    Bc1 = 6,
    /// BC7 blocks (RGB or RGBA, 16 bytes per 4x4 texels), uploadable as-is.
    Bc7 = 7,
    /// `Raw` with every row left-delta filtered ([`delta_encode_rows`]), then compressed with
    /// zstd. Since 1.1; a pack holding one sets [`REQUIRED_ZSTD_DELTA`].
    ZstdDelta = 8,
    /// A JPEG XL file of the tile (a bare codestream or the container; 8 or 16-bit samples,
    /// grey or RGB, with or without alpha). A pack holding one sets [`REQUIRED_JXL`].
    Jxl = 9,
}

impl TileKind {
    /// Every kind, in the order of their bytes (`ALL[k as usize] == k`).
    pub const ALL: [TileKind; 10] = {
        use TileKind::*;
        [Absent, Constant, Raw, Zstd, Png, Jpeg, Bc1, Bc7, ZstdDelta, Jxl]
    };

    /// The kind of byte `v` of an index entry; `None` for a byte no kind has.
    pub fn from_u8(v: u8) -> Option<TileKind> {
        TileKind::ALL.get(v as usize).copied()
    }

    /// The kind in a word, as the tiler's options and reports spell it.
    pub fn name(self) -> &'static str {
        match self {
            TileKind::Absent => "absent",
            TileKind::Constant => "constant",
            TileKind::Raw => "raw",
            TileKind::Zstd => "zstd",
            TileKind::Png => "png",
            TileKind::Jpeg => "jpeg",
            TileKind::Bc1 => "bc1",
            TileKind::Bc7 => "bc7",
            TileKind::ZstdDelta => "zstd-delta",
            TileKind::Jxl => "jxl",
        }
    }

    /// BC1 or BC7: 4x4 blocks a GPU samples directly.
    pub fn is_block_compressed(self) -> bool {
        matches!(self, TileKind::Bc1 | TileKind::Bc7)
    }

    /// The required-feature bit a pack holding this kind must set (0 for kinds of 1.0).
    pub fn required_feature(self) -> u64 {
        match self {
            TileKind::ZstdDelta => REQUIRED_ZSTD_DELTA,
            TileKind::Jxl => REQUIRED_JXL,
            _ => 0,
        }
    }

    /// Kinds whose entry points at payload bytes.
    pub fn has_payload(self) -> bool {
        !matches!(self, TileKind::Absent | TileKind::Constant)
    }
}

/// What the texture is: everything a runtime needs to address and clamp it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Description {
    /// Real image size at LOD 0, in texels.
    pub width: u32,
    /// Real image height at LOD 0, in texels.
    pub height: u32,
    /// Stored tile side, borders included.
    pub tile_size: u32,
    /// Texels of each tile's border, repeated from its neighbours, on each side.
    pub border: u32,
    /// Levels in the level table, LOD 0 first.
    pub level_count: u32,
    /// 1 grey, 2 grey+alpha, 3 RGB, 4 RGBA.
    pub channels: u8,
    /// 1, 2 or 4.
    pub sample_bytes: u8,
    /// What a sample is: [`SAMPLE_UNSIGNED`] (0) or [`SAMPLE_FLOAT`] (1, with 2 or 4 bytes).
    pub sample_format: u8,
}

impl Description {
    /// Bytes of one raw tile.
    pub fn raw_tile_len(&self) -> Option<u64> {
        (self.tile_size as u64)
            .checked_mul(self.tile_size as u64)?
            .checked_mul(self.channels as u64 * self.sample_bytes as u64)
    }

    /// Bytes of one tile of BC1 (8 per block) or BC7 (16 per block) blocks, `None` for other
    /// kinds.
    pub fn block_tile_len(&self, kind: TileKind) -> Option<u64> {
        let blocks = (self.tile_size as u64).div_ceil(4).pow(2);
        match kind {
            TileKind::Bc1 => Some(blocks * 8),
            TileKind::Bc7 => Some(blocks * 16),
            _ => None,
        }
    }

    /// Whether the texel format is one a pack holds: 1-4 channels of 1, 2 or 4-byte unsigned
    /// samples or 2 or 4-byte floats.
    pub fn texel_ok(&self) -> bool {
        (1..=4).contains(&self.channels)
            && match self.sample_format {
                SAMPLE_UNSIGNED => matches!(self.sample_bytes, 1 | 2 | 4),
                SAMPLE_FLOAT => matches!(self.sample_bytes, 2 | 4),
                _ => false,
            }
    }

    /// The required-feature bits the texel format needs ([`REQUIRED_WIDE_SAMPLES`]).
    pub fn required_features(&self) -> u64 {
        if self.sample_bytes == 4 || self.sample_format != SAMPLE_UNSIGNED { REQUIRED_WIDE_SAMPLES } else { 0 }
    }

    /// The texel format in words, for messages.
    pub fn texel_name(&self) -> String {
        let kind = if self.sample_format == SAMPLE_FLOAT { " float" } else { "" };
        format!("{} channels of {} bytes{kind}", self.channels, self.sample_bytes)
    }

    /// Why tiles of `kind` cannot be stored in a pack of this description, if they cannot: BC
    /// blocks need a tile size that is a multiple of 4 and 8-bit samples, BC1 RGB texels, BC7
    /// RGB or RGBA texels.
    pub fn refuses(&self, kind: TileKind) -> Option<String> {
        let name = kind.name();
        if !kind.is_block_compressed() {
            return None;
        }
        if !self.tile_size.is_multiple_of(4) {
            return Some(format!("{name} tiles need a tile size that is a multiple of 4, not {}", self.tile_size));
        }
        let channels_ok = match kind {
            TileKind::Bc1 => self.channels == 3,
            _ => matches!(self.channels, 3 | 4),
        };
        if self.sample_bytes != 1 || !channels_ok {
            let allowed = if kind == TileKind::Bc1 { "3 channels" } else { "3 or 4 channels" };
            return Some(format!(
                "{name} tiles need {allowed} of 1 byte, not {} channel(s) of {} byte(s)",
                self.channels, self.sample_bytes
            ));
        }
        None
    }
}

/// The row filter of `zstd-delta` tiles, in place: in each row of `width` texels of `channels`
/// samples of `sample_bytes` (1, or 2 or 4 little-endian; floats as their bits), every sample
/// after the row's first texel becomes its difference from the same channel's sample of the
/// texel to its left, modulo 2^(8 x sample_bytes). Rows are independent; a partial row at the
/// end is filtered as a row.
pub fn delta_encode_rows(bytes: &mut [u8], width: usize, channels: usize, sample_bytes: usize) {
    let texel = channels * sample_bytes;
    for row in bytes.chunks_mut((width * texel).max(1)) {
        // Right to left, so that each left neighbour is still unfiltered when it is subtracted.
        match sample_bytes {
            2 => {
                for i in (texel..row.len() - row.len() % 2).step_by(2).rev() {
                    let v = u16::from_le_bytes([row[i], row[i + 1]]);
                    let left = u16::from_le_bytes([row[i - texel], row[i + 1 - texel]]);
                    row[i..i + 2].copy_from_slice(&v.wrapping_sub(left).to_le_bytes());
                }
            }
            4 => {
                for i in (texel..row.len() - row.len() % 4).step_by(4).rev() {
                    let v = u32_at(row, i);
                    let left = u32_at(row, i - texel);
                    row[i..i + 4].copy_from_slice(&v.wrapping_sub(left).to_le_bytes());
                }
            }
            _ => {
                for i in (texel..row.len()).rev() {
                    row[i] = row[i].wrapping_sub(row[i - texel]);
                }
            }
        }
    }
}

/// Undoes [`delta_encode_rows`] in place.
pub fn delta_decode_rows(bytes: &mut [u8], width: usize, channels: usize, sample_bytes: usize) {
    let texel = channels * sample_bytes;
    for row in bytes.chunks_mut((width * texel).max(1)) {
        match sample_bytes {
            2 => {
                for i in (texel..row.len() - row.len() % 2).step_by(2) {
                    let d = u16::from_le_bytes([row[i], row[i + 1]]);
                    let left = u16::from_le_bytes([row[i - texel], row[i + 1 - texel]]);
                    row[i..i + 2].copy_from_slice(&d.wrapping_add(left).to_le_bytes());
                }
            }
            4 => {
                for i in (texel..row.len() - row.len() % 4).step_by(4) {
                    let d = u32_at(row, i);
                    let left = u32_at(row, i - texel);
                    row[i..i + 4].copy_from_slice(&d.wrapping_add(left).to_le_bytes());
                }
            }
            _ => {
                for i in texel..row.len() {
                    row[i] = row[i].wrapping_add(row[i - texel]);
                }
            }
        }
    }
}

/// The fixed header at offset 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// Format major version ([`MAJOR`]).
    pub major: u16,
    /// Format minor version ([`MINOR`]): what this writer's format adds, which older readers of the
    /// same major version ignore.
    pub minor: u16,
    /// Features a reader must understand to read the pack (bits such as [`REQUIRED_ZSTD_DELTA`]).
    pub required_features: u64,
    /// Features a reader may ignore.
    pub optional_features: u64,
    /// The file's length in bytes.
    pub file_len: u64,
    /// Identifies the content: FNV-1a 64 over the metadata and every index entry.
    pub content_hash: u64,
    /// What the texture is.
    pub description: Description,
    /// Power of two >= 8: the data section starts at a multiple of it.
    pub alignment: u32,
    /// Power of two >= 8: every payload starts at a multiple of it (65536 gives each tile its
    /// own Vulkan sparse block).
    pub payload_alignment: u32,
    /// Where the level table starts.
    pub levels_offset: u64,
    /// Where the index starts.
    pub index_offset: u64,
    /// Index entries: every tile of every level.
    pub index_count: u64,
    /// CRC-32C of the level table and the index together.
    pub index_crc: u32,
    /// Where the metadata (JSON text) starts.
    pub meta_offset: u64,
    /// Bytes of metadata.
    pub meta_len: u32,
    /// CRC-32C of the metadata.
    pub meta_crc: u32,
    /// Where the data section (the payloads) starts.
    pub data_offset: u64,
    /// Bytes of the data section, which ends the file.
    pub data_len: u64,
}

/// One row of the level table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Level {
    /// Columns of tiles.
    pub tiles_w: u32,
    /// Rows of tiles.
    pub tiles_h: u32,
    /// Index position of tile (0, 0) of this level: the levels' entries follow each other,
    /// LOD 0 first. A reader finds it in the file; `PackWriter` (feature `write`) places the
    /// levels itself and ignores what a level given to it says.
    pub first_entry: u64,
    /// Real image width at this level in texels (`ceil(width / 2^lod)`).
    pub width: u32,
    /// Real image height at this level in texels.
    pub height: u32,
}

impl Level {
    /// A level of `tiles_w x tiles_h` tiles covering `width x height` texels of the image, for
    /// a writer (which places it in the index: `first_entry` is 0 until then).
    pub fn new(tiles_w: u32, tiles_h: u32, width: u32, height: u32) -> Level {
        Level { tiles_w, tiles_h, first_entry: 0, width, height }
    }
}

/// One index entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry {
    /// Payload offset in the file; for `Constant`, the texel's samples (little-endian, packed
    /// from byte 0); 0 for `Absent`.
    pub offset_or_value: u64,
    /// Payload bytes (0 without payload).
    pub len: u32,
    /// CRC-32C of the payload (0 without payload).
    pub crc: u32,
    /// The tile's [`TileKind`], as its byte (an unknown byte is an error of the entry).
    pub kind: u8,
}

impl Entry {
    /// The entry of an absent tile.
    pub const ABSENT: Entry = Entry { offset_or_value: 0, len: 0, crc: 0, kind: TileKind::Absent as u8 };
}

fn put_u16(b: &mut [u8], at: usize, v: u16) {
    b[at..at + 2].copy_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_u32(b: &mut [u8], at: usize, v: u32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_u64(b: &mut [u8], at: usize, v: u64) {
    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
}
/// The `N` bytes at `at` (panics past the end, like indexing: callers check lengths first).
fn bytes_at<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    out.copy_from_slice(&b[at..at + N]);
    out
}
pub(crate) fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes(bytes_at(b, at))
}
pub(crate) fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes_at(b, at))
}
pub(crate) fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(bytes_at(b, at))
}

/// Byte offsets of the header's fields (see the spec's diagram). The crate's own: a reader or
/// writer of packs goes through [`Header`]; the tests and fuzzers that edit a pack's bytes get
/// them from the hidden `fuzzing` feature.
pub(crate) mod at {
    // Each is named as the field it locates, which `Header` documents.
    #![allow(missing_docs)]
    pub const MAJOR: usize = 8;
    pub const MINOR: usize = 10;
    pub const HEADER_LEN: usize = 12;
    pub const REQUIRED: usize = 16;
    pub const OPTIONAL: usize = 24;
    pub const FILE_LEN: usize = 32;
    pub const CONTENT_HASH: usize = 40;
    pub const WIDTH: usize = 48;
    pub const HEIGHT: usize = 52;
    pub const TILE_SIZE: usize = 56;
    pub const BORDER: usize = 60;
    pub const LEVEL_COUNT: usize = 64;
    pub const CHANNELS: usize = 68;
    pub const SAMPLE_BYTES: usize = 69;
    /// Since 1.1 with required-feature bit 1; zero (unsigned) in every other pack.
    pub const SAMPLE_FORMAT: usize = 70;
    pub const ALIGNMENT: usize = 72;
    pub const PAYLOAD_ALIGNMENT: usize = 76;
    pub const LEVELS_OFFSET: usize = 80;
    pub const INDEX_OFFSET: usize = 88;
    pub const INDEX_COUNT: usize = 96;
    pub const ENTRY_LEN: usize = 104;
    pub const INDEX_CRC: usize = 108;
    pub const META_OFFSET: usize = 112;
    pub const META_LEN: usize = 120;
    pub const META_CRC: usize = 124;
    pub const DATA_OFFSET: usize = 128;
    pub const DATA_LEN: usize = 136;
    /// Bytes 144..188 are reserved and must be zero.
    pub const RESERVED: usize = 144;
    pub const HEADER_CRC: usize = 188;
}

impl Header {
    /// The 192 header bytes, CRC included.
    pub fn encode(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        let d = &self.description;
        b[..8].copy_from_slice(&MAGIC);
        put_u16(&mut b, at::MAJOR, self.major);
        put_u16(&mut b, at::MINOR, self.minor);
        put_u32(&mut b, at::HEADER_LEN, HEADER_LEN as u32);
        put_u64(&mut b, at::REQUIRED, self.required_features);
        put_u64(&mut b, at::OPTIONAL, self.optional_features);
        put_u64(&mut b, at::FILE_LEN, self.file_len);
        put_u64(&mut b, at::CONTENT_HASH, self.content_hash);
        put_u32(&mut b, at::WIDTH, d.width);
        put_u32(&mut b, at::HEIGHT, d.height);
        put_u32(&mut b, at::TILE_SIZE, d.tile_size);
        put_u32(&mut b, at::BORDER, d.border);
        put_u32(&mut b, at::LEVEL_COUNT, d.level_count);
        b[at::CHANNELS] = d.channels;
        b[at::SAMPLE_BYTES] = d.sample_bytes;
        b[at::SAMPLE_FORMAT] = d.sample_format;
        put_u32(&mut b, at::ALIGNMENT, self.alignment);
        put_u32(&mut b, at::PAYLOAD_ALIGNMENT, self.payload_alignment);
        put_u64(&mut b, at::LEVELS_OFFSET, self.levels_offset);
        put_u64(&mut b, at::INDEX_OFFSET, self.index_offset);
        put_u64(&mut b, at::INDEX_COUNT, self.index_count);
        put_u32(&mut b, at::ENTRY_LEN, ENTRY_LEN as u32);
        put_u32(&mut b, at::INDEX_CRC, self.index_crc);
        put_u64(&mut b, at::META_OFFSET, self.meta_offset);
        put_u32(&mut b, at::META_LEN, self.meta_len);
        put_u32(&mut b, at::META_CRC, self.meta_crc);
        put_u64(&mut b, at::DATA_OFFSET, self.data_offset);
        put_u64(&mut b, at::DATA_LEN, self.data_len);
        let crc = crc32c::crc32c(&b[..at::HEADER_CRC]);
        put_u32(&mut b, at::HEADER_CRC, crc);
        b
    }

    /// Reads the fields; the caller has checked magic, length and CRC.
    pub(crate) fn decode(b: &[u8]) -> Header {
        Header {
            major: u16_at(b, at::MAJOR),
            minor: u16_at(b, at::MINOR),
            required_features: u64_at(b, at::REQUIRED),
            optional_features: u64_at(b, at::OPTIONAL),
            file_len: u64_at(b, at::FILE_LEN),
            content_hash: u64_at(b, at::CONTENT_HASH),
            description: Description {
                width: u32_at(b, at::WIDTH),
                height: u32_at(b, at::HEIGHT),
                tile_size: u32_at(b, at::TILE_SIZE),
                border: u32_at(b, at::BORDER),
                level_count: u32_at(b, at::LEVEL_COUNT),
                channels: b[at::CHANNELS],
                sample_bytes: b[at::SAMPLE_BYTES],
                sample_format: b[at::SAMPLE_FORMAT],
            },
            alignment: u32_at(b, at::ALIGNMENT),
            payload_alignment: u32_at(b, at::PAYLOAD_ALIGNMENT),
            levels_offset: u64_at(b, at::LEVELS_OFFSET),
            index_offset: u64_at(b, at::INDEX_OFFSET),
            index_count: u64_at(b, at::INDEX_COUNT),
            index_crc: u32_at(b, at::INDEX_CRC),
            meta_offset: u64_at(b, at::META_OFFSET),
            meta_len: u32_at(b, at::META_LEN),
            meta_crc: u32_at(b, at::META_CRC),
            data_offset: u64_at(b, at::DATA_OFFSET),
            data_len: u64_at(b, at::DATA_LEN),
        }
    }
}

impl Level {
    /// The row's bytes.
    pub fn encode(&self) -> [u8; LEVEL_LEN] {
        let mut b = [0u8; LEVEL_LEN];
        put_u32(&mut b, 0, self.tiles_w);
        put_u32(&mut b, 4, self.tiles_h);
        put_u64(&mut b, 8, self.first_entry);
        put_u32(&mut b, 16, self.width);
        put_u32(&mut b, 20, self.height);
        b
    }

    pub(crate) fn decode(b: &[u8]) -> Level {
        Level {
            tiles_w: u32_at(b, 0),
            tiles_h: u32_at(b, 4),
            first_entry: u64_at(b, 8),
            width: u32_at(b, 16),
            height: u32_at(b, 20),
        }
    }
}

impl Entry {
    /// The entry's bytes.
    pub fn encode(&self) -> [u8; ENTRY_LEN] {
        let mut b = [0u8; ENTRY_LEN];
        put_u64(&mut b, 0, self.offset_or_value);
        put_u32(&mut b, 8, self.len);
        put_u32(&mut b, 12, self.crc);
        b[16] = self.kind;
        b
    }

    pub(crate) fn decode(b: &[u8]) -> Entry {
        Entry { offset_or_value: u64_at(b, 0), len: u32_at(b, 8), crc: u32_at(b, 12), kind: b[16] }
    }
}

/// FNV-1a, 64 bits: the content hash is for identification (cache keys, "same pack?"), not
/// for security; per-tile CRC-32C values are what it covers.
pub(crate) fn fnv1a(hash: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(hash, |h, b| (h ^ *b as u64).wrapping_mul(0x0000_0100_0000_01B3))
}

/// FNV-1a's offset basis: the hash of no bytes.
pub(crate) const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
