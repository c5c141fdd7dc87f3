//! A GeoTIFF's georeferencing: the tags GDAL writes to place an image on the earth, read from
//! the source's image directory as the file stores them, for a TIFF output to write again in
//! its full-resolution IFD (docs/tiff.md, "Georeferencing").
//!
//! The tags are kept as they are, not interpreted: the model transform (`ModelPixelScale` with
//! `ModelTiepoint`, or `ModelTransformation`), the key directory and its parameters (the CRS,
//! pixel-is-area or pixel-is-point), and GDAL's no-data value. Level 0 of the output has the
//! source's size and pixels, so the same tags say the same of it; GDAL derives a reduced
//! level's transform from its size, as it does for its own overviews, which carry none.
//!
//! The key directory is checked when read: each key's values must lie inside the array the
//! key points into. A damaged directory is kept as its description ([`GeoTags::check`]): a
//! TIFF output refuses the run, naming the tag, where writing the tags again would give GIS
//! tools a file they misplace; the other outputs, which carry no georeferencing, ignore it.

use std::fs::File;
use std::io::BufReader;

use tiff::decoder::Decoder;
use tiff::tags::Tag;

/// The GeoTIFF tags read, by their number, in ascending order (as an IFD holds them).
pub(crate) mod tag {
    pub const MODEL_PIXEL_SCALE: u16 = 33550;
    pub const MODEL_TIEPOINT: u16 = 33922;
    pub const MODEL_TRANSFORMATION: u16 = 34264;
    pub const GEO_KEY_DIRECTORY: u16 = 34735;
    pub const GEO_DOUBLE_PARAMS: u16 = 34736;
    pub const GEO_ASCII_PARAMS: u16 = 34737;
    pub const GDAL_NODATA: u16 = 42113;
}

/// Each tag's name in messages.
fn name(tag: u16) -> &'static str {
    match tag {
        tag::MODEL_PIXEL_SCALE => "ModelPixelScaleTag (33550)",
        tag::MODEL_TIEPOINT => "ModelTiepointTag (33922)",
        tag::MODEL_TRANSFORMATION => "ModelTransformationTag (34264)",
        tag::GEO_KEY_DIRECTORY => "GeoKeyDirectoryTag (34735)",
        tag::GEO_DOUBLE_PARAMS => "GeoDoubleParamsTag (34736)",
        tag::GEO_ASCII_PARAMS => "GeoAsciiParamsTag (34737)",
        _ => "GDAL_NODATA (42113)",
    }
}

/// The values a GeoTIFF tag holds at most here. The key directory's offsets are 16-bit, so
/// no array a key points into is longer; a list of ground control points (tiepoints) of this
/// many values is 20 000 points.
const MOST_VALUES: u64 = 1 << 17;

/// One tag's value, as the file stores it.
#[derive(Clone, Debug, PartialEq)]
pub enum GeoValue {
    /// SHORT values (the key directory).
    Shorts(Vec<u16>),
    /// DOUBLE values (the model transform, the double parameters).
    Doubles(Vec<f64>),
    /// ASCII text, up to its first NUL (the ASCII parameters, GDAL's no-data value).
    Ascii(String),
}

/// The GeoTIFF tags of a source image, or what is wrong with them.
#[derive(Clone, Debug, PartialEq)]
pub struct GeoTags {
    /// The tags found, ascending.
    tags: Vec<(u16, GeoValue)>,
    /// Why they cannot be carried, naming the tag; `None` where they can.
    damage: Option<String>,
}

impl GeoTags {
    /// The tags, ascending, for an output to write as they are; or, where they are damaged,
    /// what is wrong, naming the tag.
    pub fn check(&self) -> Result<&[(u16, GeoValue)], &str> {
        match &self.damage {
            Some(why) => Err(why),
            None => Ok(&self.tags),
        }
    }

    /// `tags` checked: damaged where a key's values lie outside the array it points into, or
    /// the directory or the model transform is not what GeoTIFF 1.1 says it is.
    fn new(tags: Vec<(u16, GeoValue)>) -> GeoTags {
        let damage = damage(&tags).err();
        GeoTags { tags, damage }
    }
}

fn find(tags: &[(u16, GeoValue)], tag: u16) -> Option<&GeoValue> {
    tags.iter().find(|(t, _)| *t == tag).map(|(_, v)| v)
}

/// What is wrong with `tags`, naming the tag.
fn damage(tags: &[(u16, GeoValue)]) -> Result<(), String> {
    let wrong = |tag: u16, why: String| Err(format!("its {} {why}", name(tag)));
    for (tag, value) in tags {
        let len = match value {
            GeoValue::Shorts(v) => v.len(),
            GeoValue::Doubles(v) => v.len(),
            GeoValue::Ascii(_) => 1,
        };
        let ok = match *tag {
            tag::MODEL_PIXEL_SCALE => len == 3,
            tag::MODEL_TIEPOINT => len > 0 && len.is_multiple_of(6),
            tag::MODEL_TRANSFORMATION => len == 16,
            _ => len > 0,
        };
        if !ok {
            return wrong(*tag, format!("holds {len} values, which GeoTIFF does not allow"));
        }
    }
    let Some(directory) = find(tags, tag::GEO_KEY_DIRECTORY) else {
        return Err("it has model tags but no GeoKeyDirectoryTag (34735), so no coordinate system".into());
    };
    let GeoValue::Shorts(keys) = directory else { return wrong(tag::GEO_KEY_DIRECTORY, "is not SHORT values".into()) };
    let directory_wrong = |why: String| wrong(tag::GEO_KEY_DIRECTORY, why);
    let Some(&[version, _, _, count]) = keys.get(..4) else {
        return directory_wrong(format!("holds {} values, fewer than its 4-value header", keys.len()));
    };
    if version != 1 {
        return directory_wrong(format!("is version {version}; GeoTIFF's is 1"));
    }
    let entries = &keys[4..];
    if entries.len() < count as usize * 4 {
        return directory_wrong(format!("says {count} keys, and its {} values hold {}", keys.len(), entries.len() / 4));
    }
    let doubles = match find(tags, tag::GEO_DOUBLE_PARAMS) {
        Some(GeoValue::Doubles(v)) => v.len(),
        _ => 0,
    };
    let ascii = match find(tags, tag::GEO_ASCII_PARAMS) {
        // The key counts the NUL (or `|`) that ends each string.
        Some(GeoValue::Ascii(s)) => s.len() + 1,
        _ => 0,
    };
    for key in entries.chunks_exact(4).take(count as usize) {
        let [id, location, n, offset] = [key[0], key[1], key[2], key[3]];
        let (array, len) = match location {
            0 if n <= 1 => continue,
            0 => return directory_wrong(format!("gives key {id} {n} values in place of one")),
            tag::GEO_DOUBLE_PARAMS => (location, doubles),
            tag::GEO_ASCII_PARAMS => (location, ascii),
            tag::GEO_KEY_DIRECTORY => (location, keys.len()),
            other => {
                return directory_wrong(format!("puts key {id}'s values in tag {other}, which is no GeoTIFF array"));
            }
        };
        if offset as usize + n as usize > len {
            return directory_wrong(format!(
                "puts key {id}'s {n} values at {offset} of {}, which holds {len}",
                name(array)
            ));
        }
    }
    let model = [tag::MODEL_TIEPOINT, tag::MODEL_TRANSFORMATION].iter().any(|t| find(tags, *t).is_some());
    if !model {
        return Err("it has a GeoKeyDirectoryTag (34735) but neither ModelTiepointTag (33922) nor ModelTransformationTag (34264), so no place on the earth".into());
    }
    Ok(())
}

/// The GeoTIFF tags of `decoder`'s current directory, `None` where it has none. A tag that
/// cannot be read (of the wrong type, too long, past the end of the file) makes them damaged,
/// naming it; each tag's length is checked before it is read.
pub(super) fn read(decoder: &mut Decoder<BufReader<File>>) -> Option<GeoTags> {
    let all = [
        tag::MODEL_PIXEL_SCALE,
        tag::MODEL_TIEPOINT,
        tag::MODEL_TRANSFORMATION,
        tag::GEO_KEY_DIRECTORY,
        tag::GEO_DOUBLE_PARAMS,
        tag::GEO_ASCII_PARAMS,
        tag::GDAL_NODATA,
    ];
    let mut tags = Vec::new();
    for t in all {
        let Some(entry) = decoder.image_ifd().find_entry(Tag::from_u16_exhaustive(t)) else { continue };
        if entry.count() > MOST_VALUES {
            let why =
                format!("its {} holds {} values, more than GeoTIFF's 16-bit offsets reach", name(t), entry.count());
            return Some(GeoTags { tags, damage: Some(why) });
        }
        let value = decoder.get_tag(Tag::from_u16_exhaustive(t));
        let value = match t {
            tag::GEO_KEY_DIRECTORY => value.and_then(|v| v.into_u16_vec()).map(GeoValue::Shorts),
            tag::GEO_ASCII_PARAMS | tag::GDAL_NODATA => value.and_then(|v| v.into_string()).map(GeoValue::Ascii),
            _ => value.and_then(|v| v.into_f64_vec()).map(GeoValue::Doubles),
        };
        match value {
            Ok(value) => tags.push((t, value)),
            Err(e) => {
                let why = format!("its {} cannot be read: {e}", name(t));
                return Some(GeoTags { tags, damage: Some(why) });
            }
        }
    }
    // GDAL_NODATA alone is no georeferencing.
    if tags.iter().all(|(t, _)| *t == tag::GDAL_NODATA) {
        return None;
    }
    Some(GeoTags::new(tags))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(count: u16, entries: &[[u16; 4]]) -> (u16, GeoValue) {
        let mut v = vec![1, 1, 0, count];
        entries.iter().for_each(|e| v.extend(e));
        (tag::GEO_KEY_DIRECTORY, GeoValue::Shorts(v))
    }

    fn utm() -> Vec<(u16, GeoValue)> {
        vec![
            (tag::MODEL_PIXEL_SCALE, GeoValue::Doubles(vec![10.0, 10.0, 0.0])),
            (tag::MODEL_TIEPOINT, GeoValue::Doubles(vec![0.0, 0.0, 0.0, 500000.0, 4600000.0, 0.0])),
            // Model type projected, raster pixel-is-area, the CRS by EPSG code, its citation.
            keys(4, &[[1024, 0, 1, 1], [1025, 0, 1, 1], [1026, 34737, 22, 0], [3072, 0, 1, 32633]]),
            (tag::GEO_ASCII_PARAMS, GeoValue::Ascii("WGS 84 / UTM zone 33N|".into())),
        ]
    }

    #[test]
    fn a_gdal_directory_is_kept_whole() {
        let geo = GeoTags::new(utm());
        assert_eq!(geo.check().map(|t| t.len()), Ok(4));
    }

    /// Each damage names the tag and says what is wrong.
    #[test]
    fn damaged_tags_are_named() {
        type Change = Box<dyn Fn(&mut Vec<(u16, GeoValue)>)>;
        let cases: Vec<(Change, &str)> = vec![
            (Box::new(|t| t[2] = keys(5, &[[1024, 0, 1, 1]])), "GeoKeyDirectoryTag (34735) says 5 keys"),
            (Box::new(|t| t[2] = keys(1, &[[1026, 34737, 40, 0]])), "key 1026's 40 values at 0 of GeoAsciiParamsTag"),
            (Box::new(|t| t[2] = keys(1, &[[2057, 34736, 1, 0]])), "GeoDoubleParamsTag (34736), which holds 0"),
            (Box::new(|t| t[2] = keys(1, &[[2057, 999, 1, 0]])), "tag 999, which is no GeoTIFF array"),
            (Box::new(|t| t[2] = (tag::GEO_KEY_DIRECTORY, GeoValue::Shorts(vec![1, 1]))), "fewer than its 4-value"),
            (Box::new(|t| t[0].1 = GeoValue::Doubles(vec![1.0])), "ModelPixelScaleTag (33550) holds 1 values"),
            (Box::new(|t| t[1].1 = GeoValue::Doubles(vec![0.0; 5])), "ModelTiepointTag (33922) holds 5 values"),
            (Box::new(|t| t.truncate(2)), "no GeoKeyDirectoryTag"),
            (Box::new(|t| drop(t.remove(1))), "neither ModelTiepointTag"),
        ];
        for (change, says) in cases {
            let mut tags = utm();
            change(&mut tags);
            let geo = GeoTags::new(tags);
            let why = geo.check().err().unwrap_or("");
            assert!(why.contains(says), "{why:?} does not say {says:?}");
        }
    }
}
