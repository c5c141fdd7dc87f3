//! One image file directory (IFD) as bytes: its entries in ascending tag order, each value
//! inline where it fits (4 bytes classic, 8 BigTIFF) and otherwise in the value area after
//! the entries, word-aligned, at offsets counted from where the IFD will lie in the file.

use std::collections::BTreeMap;

/// The tags the writer uses, by their TIFF 6.0 / BigTIFF / OME names.
pub(super) mod tag {
    pub const NEW_SUBFILE_TYPE: u16 = 254;
    pub const IMAGE_WIDTH: u16 = 256;
    pub const IMAGE_LENGTH: u16 = 257;
    pub const BITS_PER_SAMPLE: u16 = 258;
    pub const COMPRESSION: u16 = 259;
    pub const PHOTOMETRIC: u16 = 262;
    pub const IMAGE_DESCRIPTION: u16 = 270;
    pub const STRIP_OFFSETS: u16 = 273;
    pub const SAMPLES_PER_PIXEL: u16 = 277;
    pub const ROWS_PER_STRIP: u16 = 278;
    pub const STRIP_BYTE_COUNTS: u16 = 279;
    pub const X_RESOLUTION: u16 = 282;
    pub const Y_RESOLUTION: u16 = 283;
    pub const PLANAR_CONFIGURATION: u16 = 284;
    pub const RESOLUTION_UNIT: u16 = 296;
    pub const SOFTWARE: u16 = 305;
    pub const PREDICTOR: u16 = 317;
    pub const TILE_WIDTH: u16 = 322;
    pub const TILE_LENGTH: u16 = 323;
    pub const TILE_OFFSETS: u16 = 324;
    pub const TILE_BYTE_COUNTS: u16 = 325;
    pub const SUB_IFDS: u16 = 330;
    pub const EXTRA_SAMPLES: u16 = 338;
    pub const SAMPLE_FORMAT: u16 = 339;
    pub const JPEG_TABLES: u16 = 347;
    pub const YCBCR_SUBSAMPLING: u16 = 530;
    pub const REFERENCE_BLACK_WHITE: u16 = 532;
    pub const ICC_PROFILE: u16 = 34675;
}

/// TIFF field types.
const ASCII: u16 = 2;
const SHORT: u16 = 3;
const LONG: u16 = 4;
const RATIONAL: u16 = 5;
const UNDEFINED: u16 = 7;
const DOUBLE: u16 = 12;
const LONG8: u16 = 16;
const IFD: u16 = 13;
const IFD8: u16 = 18;

/// A tag's value.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Value {
    Short(Vec<u16>),
    /// 32-bit integers in classic TIFF, 64-bit (LONG8) in BigTIFF: offsets and byte counts.
    Offsets(Vec<u64>),
    Long(Vec<u32>),
    Rational(Vec<(u32, u32)>),
    Double(Vec<f64>),
    /// Text, written with its terminating NUL.
    Ascii(String),
    /// Bytes of no TIFF type (an ICC profile).
    Undefined(Vec<u8>),
    /// Offsets of other IFDs (IFD or IFD8).
    Ifds(Vec<u64>),
    /// ASCII bytes already in the file at `offset`, `count` of them with the NUL.
    AsciiAt {
        offset: u64,
        count: u64,
    },
}

impl Value {
    fn field_type(&self, big: bool) -> u16 {
        match self {
            Value::Short(_) => SHORT,
            Value::Offsets(_) => {
                if big {
                    LONG8
                } else {
                    LONG
                }
            }
            Value::Long(_) => LONG,
            Value::Rational(_) => RATIONAL,
            Value::Double(_) => DOUBLE,
            Value::Undefined(_) => UNDEFINED,
            Value::Ascii(_) | Value::AsciiAt { .. } => ASCII,
            Value::Ifds(_) => {
                if big {
                    IFD8
                } else {
                    IFD
                }
            }
        }
    }

    fn count(&self) -> u64 {
        match self {
            Value::Short(v) => v.len() as u64,
            Value::Offsets(v) | Value::Ifds(v) => v.len() as u64,
            Value::Long(v) => v.len() as u64,
            Value::Rational(v) => v.len() as u64,
            Value::Double(v) => v.len() as u64,
            Value::Undefined(v) => v.len() as u64,
            Value::Ascii(s) => s.len() as u64 + 1,
            Value::AsciiAt { count, .. } => *count,
        }
    }

    /// The value's bytes, little-endian; empty for one already in the file.
    fn bytes(&self, big: bool) -> Vec<u8> {
        let mut out = Vec::new();
        match self {
            Value::Short(v) => v.iter().for_each(|s| out.extend(s.to_le_bytes())),
            Value::Long(v) => v.iter().for_each(|s| out.extend(s.to_le_bytes())),
            Value::Double(v) => v.iter().for_each(|s| out.extend(s.to_le_bytes())),
            Value::Offsets(v) | Value::Ifds(v) => {
                for &o in v {
                    if big {
                        out.extend(o.to_le_bytes());
                    } else {
                        // The writer checks that a classic file's offsets fit 32 bits.
                        out.extend((o as u32).to_le_bytes());
                    }
                }
            }
            Value::Rational(v) => v.iter().for_each(|(n, d)| {
                out.extend(n.to_le_bytes());
                out.extend(d.to_le_bytes());
            }),
            Value::Ascii(s) => {
                out.extend(s.as_bytes());
                out.push(0);
            }
            Value::Undefined(v) => out.extend(v),
            Value::AsciiAt { .. } => {}
        }
        out
    }
}

/// An IFD being built: its entries, sorted by tag as TIFF requires.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Ifd {
    entries: BTreeMap<u16, Value>,
}

impl Ifd {
    pub fn set(&mut self, tag: u16, value: Value) {
        self.entries.insert(tag, value);
    }

    /// The entry for `tag`, to fill in offsets once they are known.
    pub fn get_mut(&mut self, tag: u16) -> Option<&mut Value> {
        self.entries.get_mut(&tag)
    }

    fn inline(big: bool) -> usize {
        if big { 8 } else { 4 }
    }

    /// Bytes of the entry table: count, entries, next-IFD offset.
    fn table_len(&self, big: bool) -> u64 {
        let n = self.entries.len() as u64;
        if big { 8 + n * 20 + 8 } else { 2 + n * 12 + 4 }
    }

    /// The IFD's length in the file, value area included (each value word-aligned).
    pub fn encoded_len(&self, big: bool) -> u64 {
        let mut len = self.table_len(big);
        for value in self.entries.values() {
            let n = value.bytes(big).len();
            if n > Self::inline(big) {
                len = len.next_multiple_of(2) + n as u64;
            }
        }
        len.next_multiple_of(2)
    }

    /// The IFD as it lies at `at` in the file, pointing on to `next` (0: the last).
    pub fn encode(&self, at: u64, next: u64, big: bool) -> Vec<u8> {
        let inline = Self::inline(big);
        let mut table = Vec::with_capacity(self.table_len(big) as usize);
        let mut area: Vec<u8> = Vec::new();
        let area_start = at + self.table_len(big);
        if big {
            table.extend((self.entries.len() as u64).to_le_bytes());
        } else {
            table.extend((self.entries.len() as u16).to_le_bytes());
        }
        for (&tag, value) in &self.entries {
            table.extend(tag.to_le_bytes());
            table.extend(value.field_type(big).to_le_bytes());
            let count = value.count();
            if big {
                table.extend(count.to_le_bytes());
            } else {
                table.extend((count as u32).to_le_bytes());
            }
            let bytes = value.bytes(big);
            let field = match value {
                Value::AsciiAt { offset, .. } => Some(*offset),
                _ if bytes.len() > inline => {
                    if area.len() % 2 == 1 {
                        area.push(0);
                    }
                    let offset = area_start + area.len() as u64;
                    area.extend(&bytes);
                    Some(offset)
                }
                _ => None,
            };
            match field {
                Some(offset) if big => table.extend(offset.to_le_bytes()),
                Some(offset) => table.extend((offset as u32).to_le_bytes()),
                None => {
                    let mut word = bytes;
                    word.resize(inline, 0);
                    table.extend(word);
                }
            }
        }
        if big {
            table.extend(next.to_le_bytes());
        } else {
            table.extend((next as u32).to_le_bytes());
        }
        table.extend(area);
        if table.len() % 2 == 1 {
            table.push(0);
        }
        debug_assert_eq!(table.len() as u64, self.encoded_len(big));
        table
    }
}
