//! `info.json`: the description of a tiled pyramid, as the thesis's tiler wrote it, extended
//! with what a runtime needs. Its specification is `docs/info-json.md`.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Result, TilerError};
use crate::layout::lods_for;

/// The `formatVersion` this tool writes. Files without the member are the thesis's version 0.
pub(crate) const FORMAT_VERSION: u32 = 2;

/// The border of the tiles a file without `border` describes: the thesis's files have no such
/// member, and their tiles no border.
pub(crate) const BORDER_WHEN_ABSENT: u32 = 0;

/// Every member; on reading, all are optional (the thesis's files have only the first six).
/// Each field is the camel-case member of the same name; `docs/info-json.md` is the
/// specification, and `None` means the member is absent.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase", deny_unknown_fields)]
pub struct InfoFile {
    /// `formatVersion`: 2 as this tool writes it; absent in the thesis's files (version 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub format_version: Option<u32>,
    /// Side of every stored tile in texels, borders included.
    pub tile_size: Option<u32>,
    /// Pages per side of a square power-of-two grid: written only for such grids (the
    /// thesis's layout), read from the files that have no `tileColumns`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tile_count: Option<u32>,
    /// Pages per row at LOD 0 (since format version 2).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tile_columns: Option<u32>,
    /// Page rows at LOD 0 (since format version 2).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tile_rows: Option<u32>,
    /// Number of LODs, LOD 0 the finest, down to the first of one page.
    pub lod_count: Option<u32>,
    /// Channels of a texel: `luminance`, `luminanceAlpha`, `rgb` or `rgba`.
    pub tile_format: Option<String>,
    /// Sample type: `unsignedByte`, `unsignedShort`, and in packs `unsignedInt`, `float`, `half`.
    pub tile_type: Option<String>,
    /// Tile file names, printf-like: `%1$` the LOD, `%2$` x, `%3$` y.
    pub filename_format: Option<String>,
    /// Texels each tile repeats from its neighbours on every side (the thesis's files: 0).
    pub border: Option<u32>,
    /// Width of the real image at LOD 0 in texels.
    pub width: Option<u32>,
    /// Height of the real image at LOD 0 in texels.
    pub height: Option<u32>,
    /// What fills the padding: `edge`, `#rrggbb` or `#rrggbbaa`.
    pub background: Option<String>,
    /// `jpeg`, `png` or `jxl`; in a pack's metadata also `raw`, `zstd`, `zstd-delta`, `bc1`, `bc7`.
    pub codec: Option<String>,
    /// JPEG and lossy JPEG XL: quality, 1 to 100 (JPEG XL's maps to a distance).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quality: Option<u8>,
    /// JPEG XL only: `true` for lossless tiles.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lossless: Option<bool>,
    /// JPEG XL only: the encoder's effort, 1 to 9.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub jxl_effort: Option<u8>,
    /// JPEG only: chroma subsampling, `420` or `444`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub subsampling: Option<String>,
    /// PNG only: `fast`, `default` or `best`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub png_compression: Option<String>,
    /// zstd and zstd-delta only: the level, 1 to 22.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zstd_level: Option<i32>,
    /// BC7 only: the encoder's effort (`ultra-fast` to `slow`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bc7_effort: Option<String>,
    /// How LODs were made (`--filter`); absent in files written before it existed (`box`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub filter: Option<String>,
    /// The source's ICC profile, base64, when `--keep-icc` left the texels in its colours.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub icc_profile: Option<String>,
}

/// A complete description, as written after a successful run.
pub(crate) type Info = InfoFile;

impl InfoFile {
    /// Reads and checks an existing `info.json`.
    pub fn read(path: &Path) -> Result<InfoFile> {
        let text = std::fs::read_to_string(path).map_err(|e| TilerError::io(path, e))?;
        let info: InfoFile = serde_json::from_str(&text).map_err(|e| TilerError::Info {
            path: path.to_path_buf(),
            field: format!("line {} column {}", e.line(), e.column()),
            message: e.to_string(),
        })?;
        info.check(path)?;
        Ok(info)
    }

    /// Members that contradict each other.
    fn check(&self, path: &Path) -> Result<()> {
        let err =
            |field: &str, message: String| TilerError::Info { path: path.to_path_buf(), field: field.into(), message };
        if let Some(v) = self.format_version.filter(|v| *v > FORMAT_VERSION) {
            return Err(err("formatVersion", format!("{v} is newer than this tool understands ({FORMAT_VERSION})")));
        }
        match (self.tile_columns, self.tile_rows) {
            (Some(c), Some(r)) => {
                if c == 0 || r == 0 {
                    return Err(err(if c == 0 { "tileColumns" } else { "tileRows" }, "must be at least 1".into()));
                }
                let lods = lods_for(c.max(r));
                if let Some(l) = self.lod_count.filter(|l| *l != lods) {
                    return Err(err(
                        "lodCount",
                        format!(
                            "{l} contradicts a grid of {c} x {r} pages (the first LOD of one page is {})",
                            lods - 1
                        ),
                    ));
                }
                if let Some(t) = self.tile_count.filter(|t| (*t, *t) != (c, r)) {
                    return Err(err("tileCount", format!("{t} contradicts tileColumns {c} and tileRows {r}")));
                }
                return Ok(());
            }
            (Some(_), None) => return Err(err("tileRows", "is required with tileColumns".into())),
            (None, Some(_)) => return Err(err("tileColumns", "is required with tileRows".into())),
            (None, None) => {}
        }
        if let Some(c) = self.tile_count {
            if !c.is_power_of_two() {
                return Err(err("tileCount", format!("{c} is not a power of two")));
            }
            if let Some(l) = self.lod_count.filter(|l| *l != c.trailing_zeros() + 1) {
                return Err(err(
                    "lodCount",
                    format!(
                        "{l} contradicts tileCount {c} (lodCount = log2(tileCount) + 1 = {})",
                        c.trailing_zeros() + 1
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Pages per row and page rows at LOD 0: `tileColumns` and `tileRows`, or the square
    /// `tileCount` of older files.
    pub fn grid(&self) -> Option<(u32, u32)> {
        match (self.tile_columns, self.tile_rows, self.tile_count) {
            (Some(c), Some(r), _) => Some((c, r)),
            (_, _, Some(t)) => Some((t, t)),
            _ => None,
        }
    }

    /// The file's text as this tool writes it: pretty-printed JSON, members in the order
    /// above, absent ones left out where the specification allows, and a final newline.
    #[expect(clippy::expect_used, reason = "plain data always serialises")]
    pub fn to_json_pretty(&self) -> String {
        let mut s = serde_json::to_string_pretty(self).expect("plain data serialises");
        s.push('\n');
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_thesis_example() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("info.json");
        std::fs::write(&p, r#"{"tileSize":128,"tileCount":512,"lodCount":10,"tileFormat":"rgb","tileType":"unsignedByte","filenameFormat":"lod%1$02s-x%2$04s-y%3$04s.jpg"}"#).unwrap();
        let i = InfoFile::read(&p).unwrap();
        assert_eq!((i.tile_size, i.tile_count, i.lod_count), (Some(128), Some(512), Some(10)));
        assert_eq!((i.format_version, i.grid()), (None, Some((512, 512))));
    }

    #[test]
    fn reads_per_axis_grids() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("info.json");
        std::fs::write(&p, r#"{"formatVersion":2,"tileColumns":6,"tileRows":4,"lodCount":4}"#).unwrap();
        assert_eq!(InfoFile::read(&p).unwrap().grid(), Some((6, 4)));
    }

    #[test]
    fn names_the_bad_member() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("info.json");
        std::fs::write(&p, r#"{"tileCount":512,"lodCount":9}"#).unwrap();
        let e = InfoFile::read(&p).unwrap_err().to_string();
        assert!(e.contains("lodCount") && e.contains("info.json"), "{e}");
        std::fs::write(&p, r#"{"tileColumns":6,"tileRows":4,"lodCount":3}"#).unwrap();
        let e = InfoFile::read(&p).unwrap_err().to_string();
        assert!(e.contains("lodCount") && e.contains("6 x 4"), "{e}");
        std::fs::write(&p, r#"{"tileColumns":6,"lodCount":4}"#).unwrap();
        let e = InfoFile::read(&p).unwrap_err().to_string();
        assert!(e.contains("tileRows"), "{e}");
        std::fs::write(&p, r#"{"tilesize":128}"#).unwrap();
        let e = InfoFile::read(&p).unwrap_err().to_string();
        assert!(e.contains("tilesize"), "{e}");
    }
}
