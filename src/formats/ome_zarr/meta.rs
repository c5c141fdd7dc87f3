//! The JSON of an OME-Zarr image: the group's `multiscales` and `omero` attributes and one
//! array per level, as Zarr v2 (`.zgroup`, `.zattrs`, `.zarray`: OME-Zarr 0.4) or Zarr v3
//! (`zarr.json` with the sharding codec: OME-Zarr 0.5). Everything here follows from the grid
//! and the stored texels, so it is known before the first tile.

use serde_json::{Value, json};

use crate::layout::Layout;
use crate::pixel::{Channels, Depth, PixelLayout};

/// Which OME-Zarr (and so which Zarr) to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Version {
    /// OME-Zarr 0.4 on Zarr v2: one file per chunk.
    V04,
    /// OME-Zarr 0.5 on Zarr v3: chunks gathered into shards.
    V05,
}

impl Version {
    /// The version as the metadata and messages write it: `0.4` or `0.5`.
    pub fn name(self) -> &'static str {
        match self {
            Version::V04 => "0.4",
            Version::V05 => "0.5",
        }
    }
}

/// The physical side of a source pixel (`--pixel-size 0.25um`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelSize {
    /// The side in `unit`s (positive).
    pub value: f64,
    /// An OME-Zarr space unit (UDUNITS-2 name), e.g. `micrometer`.
    pub unit: &'static str,
}

impl std::str::FromStr for PixelSize {
    type Err = String;

    /// `0.25um`, `0.25 µm`, `250nm`, `1.5mm`; a bare number is in micrometres.
    fn from_str(s: &str) -> Result<Self, String> {
        let t = s.trim();
        let split = t.find(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == 'E' || c == '-' || c == '+'));
        let (number, unit) = match split {
            Some(i) => (&t[..i], t[i..].trim()),
            None => (t, "um"),
        };
        let unit = match unit {
            "nm" | "nanometer" => "nanometer",
            "um" | "µm" | "μm" | "micron" | "micrometer" => "micrometer",
            "mm" | "millimeter" => "millimeter",
            "cm" | "centimeter" => "centimeter",
            "m" | "meter" => "meter",
            other => return Err(format!("'{other}' in '{s}' is not a length unit (nm, um, mm, cm, m)")),
        };
        match number.parse::<f64>() {
            Ok(value) if value.is_finite() && value > 0.0 => Ok(PixelSize { value, unit }),
            _ => Err(format!("'{s}' is not a pixel size (a positive number and a unit, e.g. 0.25um)")),
        }
    }
}

/// Everything the metadata says.
#[derive(Clone, Debug)]
pub struct Spec {
    pub version: Version,
    /// The page grid (border 0): a level's chunks are its pages.
    pub layout: Layout,
    /// The samples of each texel as stored.
    pub stored: PixelLayout,
    /// Chunks per shard side (0.5).
    pub shard_chunks: u32,
    pub zstd_level: i32,
    pub pixel_size: Option<PixelSize>,
    /// The image's name in `multiscales`.
    pub name: String,
    /// How the levels were made (`multiscales.type`).
    pub filter: String,
    /// A label image (`IMAGE/labels/NAME`): `image-label` metadata instead of `omero`.
    pub label: bool,
    /// Channels written one pass each ([`crate::source::channels`]): a `c` axis of their
    /// count, chunks of one channel. `None`: the stored texels' 1 to 4 samples, in each chunk.
    pub planes: Option<Vec<Plane>>,
}

/// A channel written in a pass of its own.
#[derive(Clone, Debug, PartialEq)]
pub struct Plane {
    /// The channel's name in the OME metadata (`omero.channels`' `label`).
    pub name: String,
    /// The smallest and largest sample, where known before the metadata is written.
    pub window: Option<(f64, f64)>,
    /// The channel's colour where the source gives it (an OME-TIFF's `Channel Color`): RGBA,
    /// red in the high byte. `None`: the viewers' default for its place (`PLANE_COLOURS`).
    pub colour: Option<u32>,
}

/// Colours of the channels written one pass each, in turn: the ones microscopy viewers give
/// fluorescence channels by default, so that any few channels are told apart.
const PLANE_COLOURS: [&str; 7] = ["0000FF", "00FF00", "FF0000", "FF00FF", "00FFFF", "FFFF00", "FFFFFF"];

impl Spec {
    pub fn channels(&self) -> usize {
        match &self.planes {
            Some(planes) => planes.len(),
            None => self.stored.channels.count(),
        }
    }

    /// Grey images are 2-D (`y`, `x`); others, and channels written one pass each, have a
    /// channel axis first (`c`, `y`, `x`).
    pub fn has_channel_axis(&self) -> bool {
        self.channels() > 1 || self.planes.is_some()
    }

    /// An array's shape for `y, x` extents, with the channel axis where there is one.
    fn shape(&self, y: u64, x: u64) -> Vec<u64> {
        match self.has_channel_axis() {
            true => vec![self.channels() as u64, y, x],
            false => vec![y, x],
        }
    }

    /// The metadata files, root first, then each level's: (path in the hierarchy, bytes).
    pub fn files(&self) -> Vec<(String, Vec<u8>)> {
        let pretty = |v: &Value| serde_json::to_vec_pretty(v).unwrap_or_default();
        let mut files = Vec::new();
        match self.version {
            Version::V04 => {
                files.push((".zgroup".to_string(), pretty(&json!({ "zarr_format": 2 }))));
                let mut multiscale = self.multiscale();
                multiscale["version"] = json!("0.4");
                let attributes = match self.label {
                    true => json!({ "multiscales": [multiscale], "image-label": self.image_label(Some("0.4")) }),
                    false => {
                        let mut omero = self.omero();
                        omero["version"] = json!("0.4");
                        json!({ "multiscales": [multiscale], "omero": omero })
                    }
                };
                files.push((".zattrs".to_string(), pretty(&attributes)));
                for lod in 0..self.layout.lod_count {
                    files.push((format!("{lod}/.zarray"), pretty(&self.zarray(lod))));
                }
            }
            Version::V05 => {
                let mut ome = json!({ "version": "0.5", "multiscales": [self.multiscale()] });
                match self.label {
                    true => ome["image-label"] = self.image_label(None),
                    false => ome["omero"] = self.omero(),
                }
                let root = json!({ "zarr_format": 3, "node_type": "group", "attributes": { "ome": ome } });
                files.push(("zarr.json".to_string(), pretty(&root)));
                for lod in 0..self.layout.lod_count {
                    files.push((format!("{lod}/zarr.json"), pretty(&self.zarr_json(lod))));
                }
            }
        }
        files
    }

    fn multiscale(&self) -> Value {
        let unit = self.pixel_size.map(|p| p.unit);
        let space = |name: &str| match unit {
            Some(unit) => json!({ "name": name, "type": "space", "unit": unit }),
            None => json!({ "name": name, "type": "space" }),
        };
        let mut axes = vec![space("y"), space("x")];
        if self.has_channel_axis() {
            axes.insert(0, json!({ "name": "c", "type": "channel" }));
        }
        let side = self.pixel_size.map_or(1.0, |p| p.value);
        let datasets: Vec<Value> = (0..self.layout.lod_count)
            .map(|lod| {
                let s = side * (1u64 << lod) as f64;
                let scale = match self.has_channel_axis() {
                    true => json!([1.0, s, s]),
                    false => json!([s, s]),
                };
                json!({ "path": lod.to_string(), "coordinateTransformations": [{ "type": "scale", "scale": scale }] })
            })
            .collect();
        json!({ "name": self.name, "axes": axes, "datasets": datasets, "type": self.filter })
    }

    /// Rendering hints for viewers: each channel's name, colour and value range (the data's
    /// where known, else the sample type's).
    fn omero(&self) -> Value {
        let max = self.max_value();
        if let Some(planes) = &self.planes {
            let channels: Vec<Value> = planes
                .iter()
                .enumerate()
                .map(|(c, plane)| {
                    let (start, end) = plane.window.unwrap_or((0.0, max as f64));
                    // Integer samples' ranges are written as integers.
                    let number = |v: f64| match v.fract() == 0.0 && v.abs() < 9e15 {
                        true => json!(v as i64),
                        false => json!(v),
                    };
                    let (start, end) = (number(start), number(end));
                    json!({
                        "label": plane.name,
                        "color": match plane.colour {
                            Some(rgba) => format!("{:06X}", rgba >> 8),
                            None => PLANE_COLOURS[c % PLANE_COLOURS.len()].to_string(),
                        },
                        "active": true,
                        "coefficient": 1,
                        "family": "linear",
                        "inverted": false,
                        "window": { "min": 0, "max": max, "start": start, "end": end },
                    })
                })
                .collect();
            return json!({ "channels": channels, "rdefs": { "model": "color" } });
        }
        let names: &[(&str, &str)] = match self.stored.channels {
            Channels::Grey => &[("grey", "FFFFFF")],
            Channels::GreyAlpha => &[("grey", "FFFFFF"), ("alpha", "FFFFFF")],
            Channels::Rgb => &[("red", "FF0000"), ("green", "00FF00"), ("blue", "0000FF")],
            Channels::Rgba => &[("red", "FF0000"), ("green", "00FF00"), ("blue", "0000FF"), ("alpha", "FFFFFF")],
        };
        let channels: Vec<Value> = names
            .iter()
            .map(|(label, colour)| {
                json!({
                    "label": label,
                    "color": colour,
                    "active": *label != "alpha",
                    "coefficient": 1,
                    "family": "linear",
                    "inverted": false,
                    "window": { "min": 0, "max": max, "start": 0, "end": max },
                })
            })
            .collect();
        let model = if self.has_channel_axis() { "color" } else { "greyscale" };
        json!({ "channels": channels, "rdefs": { "model": model } })
    }

    /// A label image's tie to its image, two levels up (`IMAGE/labels/NAME`).
    fn image_label(&self, version: Option<&str>) -> Value {
        let mut label = json!({ "source": { "image": "../../" } });
        if let Some(v) = version {
            label["version"] = json!(v);
        }
        label
    }

    fn max_value(&self) -> u32 {
        match self.stored.depth {
            Depth::U8 => u8::MAX as u32,
            Depth::U16 => u16::MAX as u32,
            Depth::U32 => u32::MAX,
            // The window of floats: 0 to 1, the range of normalised data (a reader rescales it).
            Depth::F32 | Depth::F16 => 1,
        }
    }

    fn level_shape(&self, lod: u32) -> Vec<u64> {
        let (w, h) = self.layout.level_extent(lod);
        self.shape(h as u64, w as u64)
    }

    fn chunk_shape(&self, side: u64) -> Vec<u64> {
        match self.planes {
            Some(_) => vec![1, side, side],
            None => self.shape(side, side),
        }
    }

    fn zarray(&self, lod: u32) -> Value {
        let dtype = match self.stored.depth {
            Depth::U8 => "|u1",
            Depth::U16 => "<u2",
            Depth::U32 => "<u4",
            Depth::F32 => "<f4",
            Depth::F16 => "<f2",
        };
        json!({
            "zarr_format": 2,
            "shape": self.level_shape(lod),
            "chunks": self.chunk_shape(self.layout.tile_size as u64),
            "dtype": dtype,
            "compressor": { "id": "zstd", "level": self.zstd_level },
            "fill_value": 0,
            "order": "C",
            "filters": null,
            "dimension_separator": "/",
        })
    }

    fn zarr_json(&self, lod: u32) -> Value {
        let data_type = match self.stored.depth {
            Depth::U8 => "uint8",
            Depth::U16 => "uint16",
            Depth::U32 => "uint32",
            Depth::F32 => "float32",
            Depth::F16 => "float16",
        };
        let chunk = self.layout.tile_size as u64;
        let shard = chunk * self.shard_chunks as u64;
        let names: Vec<&str> = if self.has_channel_axis() { vec!["c", "y", "x"] } else { vec!["y", "x"] };
        let bytes = json!({ "name": "bytes", "configuration": { "endian": "little" } });
        json!({
            "zarr_format": 3,
            "node_type": "array",
            "shape": self.level_shape(lod),
            "data_type": data_type,
            "chunk_grid": { "name": "regular", "configuration": { "chunk_shape": self.chunk_shape(shard) } },
            "chunk_key_encoding": { "name": "default", "configuration": { "separator": "/" } },
            "fill_value": 0,
            "codecs": [{
                "name": "sharding_indexed",
                "configuration": {
                    "chunk_shape": self.chunk_shape(chunk),
                    "codecs": [bytes, { "name": "zstd", "configuration": { "level": self.zstd_level, "checksum": false } }],
                    "index_codecs": [bytes, { "name": "crc32c" }],
                    "index_location": "end",
                },
            }],
            "dimension_names": names,
            "attributes": {},
        })
    }

    /// Shards over all levels (0.5; 0 for 0.4).
    pub fn shard_count(&self) -> u64 {
        if self.version == Version::V04 {
            return 0;
        }
        let n = self.shard_chunks;
        let count = |lod| {
            let (columns, rows) = self.layout.grid(lod);
            columns.div_ceil(n) as u64 * rows.div_ceil(n) as u64
        };
        let planes = self.planes.as_ref().map_or(1, |p| p.len() as u64);
        (0..self.layout.lod_count).map(count).sum::<u64>() * planes
    }

    /// The most memory the open shards' indexes can take: every shard open at once (an image
    /// cut in vertical stripes keeps a level's shards open from one stripe to the next).
    pub fn index_bytes(&self) -> u64 {
        let n = self.shard_chunks as u64;
        self.shard_count() * (n * n * 16 + 4)
    }

    /// Where chunk (`x`, `y`) of level `lod` goes (of channel `c`, for channels written one
    /// pass each): its file (0.4) or its shard's (0.5).
    pub fn chunk_key(&self, lod: u32, c: u32, x: u32, y: u32) -> String {
        let c = match (self.has_channel_axis(), &self.planes) {
            (true, Some(_)) => format!("{c}/"),
            (true, None) => "0/".to_string(),
            (false, _) => String::new(),
        };
        match self.version {
            Version::V04 => format!("{lod}/{c}{y}/{x}"),
            Version::V05 => {
                let n = self.shard_chunks;
                format!("{lod}/c/{c}{}/{}", y / n, x / n)
            }
        }
    }

    /// The zip comment of a `.ozx` (RFC-9): the OME-Zarr version, and that every `zarr.json`
    /// comes first in the central directory.
    pub fn zip_comment(&self) -> String {
        json!({ "ome": { "version": self.version.name(), "zipFile": { "centralDirectory": { "jsonFirst": true } } } })
            .to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_sizes_parse_with_units() {
        assert_eq!("0.25um".parse::<PixelSize>(), Ok(PixelSize { value: 0.25, unit: "micrometer" }));
        assert_eq!("250 nm".parse::<PixelSize>(), Ok(PixelSize { value: 250.0, unit: "nanometer" }));
        assert_eq!("2".parse::<PixelSize>(), Ok(PixelSize { value: 2.0, unit: "micrometer" }));
        assert!("0um".parse::<PixelSize>().is_err());
        assert!("1 parsec".parse::<PixelSize>().unwrap_err().contains("parsec"));
    }
}
