//! How each kind of output recognises a previous output of its own, the only thing it may
//! replace without `--force`. Recognition is by content, never by name: a pack by its
//! signature, a tile directory by an `info.json` we can read and tiles its file-name pattern
//! names (nothing else), a render report by its members, a frames folder by its frame names.

use std::fs;
use std::io::Read;
use std::path::Path;

use crate::error::ShowPath;
use crate::formats::tiles::filename::DEFAULT_FILENAME_STEM;
use crate::formats::tiles::filename::FilenameFormat;
use crate::formats::tiles::info::InfoFile;
use crate::formats::viewer::Viewer;

/// What a command writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Product {
    /// A pack file (`split --pack`, `convert --pack`, `pack -o`).
    Pack,
    /// A directory of tiles plus `info.json` (`split -o`, `convert -o`, `unpack -o`).
    TileDir,
    /// The JSON report of `render --report`.
    Report,
    /// The folder of PNG frames of `render --frames`.
    Frames,
    /// A pyramid in a viewer layout (`split --layout dzi|iiif|xyz|google`).
    Viewer(Viewer),
    /// An OME-Zarr image directory (`split --layout ome-zarr -o DIR.ome.zarr`).
    OmeZarr,
    /// A zipped OME-Zarr file (`split --layout ome-zarr -o FILE.ozx`).
    Ozx,
    /// A PMTiles v3 archive (`split --pmtiles`).
    Pmtiles,
    /// A pyramidal TIFF or OME-TIFF (`split -o FILE.tif`, `-o FILE.ome.tif`).
    Tiff,
    /// A DICOM whole-slide image series (`split --layout dicom -o DIR`).
    Dicom,
}

/// The largest report or `info.json` read to recognise it; ours are far smaller.
const MAX_JSON_BYTES: u64 = 64 << 20;

impl Product {
    /// Whether the product is a directory (a tile directory, frames, a viewer layout,
    /// OME-Zarr) rather than one file.
    pub(crate) fn is_dir(self) -> bool {
        matches!(self, Product::TileDir | Product::Frames | Product::Viewer(_) | Product::OmeZarr | Product::Dicom)
    }

    /// The product as the messages name it.
    pub(crate) fn noun(self) -> &'static str {
        match self {
            Product::Pack => "a pack",
            Product::TileDir => "a tile directory",
            Product::Report => "a render report",
            Product::Frames => "a folder of rendered frames",
            Product::Viewer(Viewer::Dzi) => "a Deep Zoom pyramid",
            Product::Viewer(Viewer::Iiif) => "a IIIF image",
            Product::Viewer(Viewer::Xyz | Viewer::Google) => "a web-map tile directory",
            Product::OmeZarr => "an OME-Zarr image",
            Product::Ozx => "a zipped OME-Zarr image",
            Product::Pmtiles => "a PMTiles archive",
            Product::Tiff => "a pyramidal TIFF",
            Product::Dicom => "a DICOM series",
        }
    }

    /// `Ok` if `path` (of the right file type) holds a previous output of this kind, else
    /// what is there instead, for the message.
    pub(super) fn recognise(self, path: &Path) -> Result<(), String> {
        match self {
            Product::Pack => recognise_pack(path),
            Product::TileDir => recognise_tile_dir(path),
            Product::Report => recognise_report(path),
            Product::Frames => recognise_frames(path),
            Product::Viewer(viewer) => crate::formats::viewer::recognise(viewer, path),
            Product::OmeZarr => recognise_dir(path),
            Product::Ozx => recognise_ozx(path),
            Product::Pmtiles => recognise_pmtiles(path),
            Product::Tiff => recognise_tiff(path),
            Product::Dicom => recognise_dicom(path),
        }
    }
}

fn recognise_pack(path: &Path) -> Result<(), String> {
    let mut head = Vec::with_capacity(8);
    fs::File::open(path).and_then(|f| f.take(8).read_to_end(&mut head)).map_err(|e| format!("unreadable ({e})"))?;
    if head.is_empty() {
        return Err("an empty file".into());
    }
    if head[..] != vortex_pack::format::MAGIC[..] {
        return Err("a file without a pack's signature".into());
    }
    Ok(())
}

/// Any PMTiles v3 archive, ours or not: it holds nothing but tiles another run can make again.
fn recognise_pmtiles(path: &Path) -> Result<(), String> {
    let mut head = Vec::with_capacity(8);
    fs::File::open(path).and_then(|f| f.take(8).read_to_end(&mut head)).map_err(|e| format!("unreadable ({e})"))?;
    match &head[..] {
        [] => Err("an empty file".into()),
        b"PMTiles\x03" => Ok(()),
        _ => Err("a file without a PMTiles v3 signature".into()),
    }
}

/// The `Software` tag of the TIFFs this tool writes (`formats::tiff::SIGNATURE`).
const TIFF_SOFTWARE: &str = "vortex-tiler";

/// A TIFF that this tool wrote: one whose first directory's `Software` tag is ours, as the
/// TIFF reader of the sources reads it (a COG's directory follows GDAL's ghost area, the
/// others' follow the tiles). Anybody else's TIFF, a scan above all, is theirs.
fn recognise_tiff(path: &Path) -> Result<(), String> {
    let mut head = Vec::with_capacity(4);
    fs::File::open(path).and_then(|f| f.take(4).read_to_end(&mut head)).map_err(|e| format!("unreadable ({e})"))?;
    match &head[..] {
        [] => Err("an empty file".into()),
        b"II*\0" | b"II+\0" | b"MM\0*" | b"MM\0+" => match crate::source::tiff::software(path) {
            Some(software) if software == TIFF_SOFTWARE => Ok(()),
            _ => Err("a TIFF written by another program".into()),
        },
        _ => Err("a file that is not a TIFF".into()),
    }
}

/// Whether `name` is one a DICOM series' instance files may have (`formats::dicom`'s
/// `Spec::file_name` and `Spec::associated_file_name`, whose unit test holds them to this):
/// `level-N.dcm`, and `KIND.dcm` or `KIND-N.dcm` for an associated image.
pub(crate) fn is_dicom_instance_name(name: &str) -> bool {
    let digits = |n: &str| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit());
    let Some(stem) = name.strip_suffix(".dcm") else { return false };
    if let Some(n) = stem.strip_prefix("level-") {
        return digits(n);
    }
    let kind = stem.split_once('-').map_or(stem, |(kind, n)| if digits(n) { kind } else { "" });
    ["label", "overview", "thumbnail"].contains(&kind)
}

/// An empty directory, or one holding only the instances a DICOM output names
/// (`level-N.dcm`, `label.dcm`, `overview-2.dcm`, ...: [`is_dicom_instance_name`]), each a
/// DICOM Part-10 file whose File Meta names this program as its writer (Implementation
/// Version Name `VORTEX_TILER`, within the first 1 KiB).
fn recognise_dicom(dir: &Path) -> Result<(), String> {
    for entry in entries(dir)? {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if !entry.file_type().is_ok_and(|t| t.is_file()) || !is_dicom_instance_name(&name) {
            return Err(format!("holds {name}, which is not one of its instances"));
        }
        let mut head = Vec::with_capacity(1024);
        fs::File::open(entry.path())
            .and_then(|f| f.take(1024).read_to_end(&mut head))
            .map_err(|e| format!("unreadable ({e})"))?;
        let ours = head.get(128..132) == Some(b"DICM") && head.windows(12).any(|w| w == b"VORTEX_TILER");
        if !ours {
            return Err(format!("holds {name}, a file this tool did not write"));
        }
    }
    Ok(())
}

fn recognise_report(path: &Path) -> Result<(), String> {
    let len = fs::metadata(path).map_err(|e| format!("unreadable ({e})"))?.len();
    if len > MAX_JSON_BYTES {
        return Err(format!("a file of {len} bytes, too large to be a render report"));
    }
    let text = fs::read(path).map_err(|e| format!("unreadable ({e})"))?;
    let value: serde_json::Value = serde_json::from_slice(&text).map_err(|_| "a file that is not JSON".to_string())?;
    let ours = ["adapter", "frames", "pages_touched", "pages_total"].iter().all(|k| value.get(k).is_some());
    if ours { Ok(()) } else { Err("a JSON file with other members".into()) }
}

/// The entries of a directory, or what went wrong as the message says it.
fn entries(dir: &Path) -> Result<Vec<fs::DirEntry>, String> {
    let read = fs::read_dir(dir).map_err(|e| format!("unreadable ({e})"))?;
    read.collect::<Result<Vec<_>, _>>().map_err(|e| format!("unreadable ({e})"))
}

fn recognise_frames(dir: &Path) -> Result<(), String> {
    for entry in entries(dir)? {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let is_frame = entry.file_type().is_ok_and(|t| t.is_file())
            && name
                .strip_prefix("frame-")
                .and_then(|n| n.strip_suffix(".png"))
                .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
        if !is_frame {
            return Err(format!("holds {name}"));
        }
    }
    Ok(())
}

/// An empty directory, or our `info.json` plus only the tiles its pattern names (in any
/// sub-folders the pattern makes).
fn recognise_tile_dir(dir: &Path) -> Result<(), String> {
    let top = entries(dir)?;
    if top.is_empty() {
        return Ok(());
    }
    let info_path = dir.join("info.json");
    if !info_path.is_file() {
        let first = top[0].file_name();
        return Err(format!("holds {} and no info.json", first.to_string_lossy()));
    }
    if fs::metadata(&info_path).map_or(0, |m| m.len()) > MAX_JSON_BYTES {
        return Err("holds an info.json too large to be ours".into());
    }
    let info = InfoFile::read(&info_path).map_err(|e| format!("holds an info.json this tool did not write ({e})"))?;
    let names = tile_names(&info)?;
    let lods = info.lod_count.unwrap_or(u32::MAX);
    let mut stack = vec![(dir.to_path_buf(), String::new(), top)];
    while let Some((path, prefix, list)) = stack.pop() {
        for entry in list {
            let name = entry.file_name();
            let relative = format!("{prefix}{}", name.to_string_lossy());
            let kind = entry.file_type().map_err(|e| format!("unreadable ({e})"))?;
            if kind.is_dir() {
                let child = path.join(&name);
                let list = entries(&child)?;
                stack.push((child, format!("{relative}/"), list));
            } else if kind.is_file() && (relative == "info.json" || is_tile(&names, &relative, lods)) {
                continue;
            } else {
                return Err(format!("holds {relative}, which is not one of its tiles"));
            }
        }
    }
    Ok(())
}

/// How `info`'s tiles are named: its `filenameFormat`, or (files of the original tool may
/// lack one) the default stem with an image extension.
struct TileNames {
    format: FilenameFormat,
    /// Whether the extension is left out of `format` and checked apart.
    any_image_extension: bool,
}

fn tile_names(info: &InfoFile) -> Result<TileNames, String> {
    let (pattern, any_image_extension) = match &info.filename_format {
        Some(f) => (f.as_str(), false),
        None => (DEFAULT_FILENAME_STEM, true),
    };
    let format = FilenameFormat::parse(pattern, 3)
        .map_err(|e| format!("holds an info.json whose filenameFormat does not parse ({e})"))?;
    Ok(TileNames { format, any_image_extension })
}

fn is_tile(names: &TileNames, relative: &str, lods: u32) -> bool {
    let stem = if names.any_image_extension {
        match relative.rsplit_once('.') {
            Some((stem, ext)) if ["jpg", "jpeg", "png"].contains(&ext.to_ascii_lowercase().as_str()) => stem,
            _ => return false,
        }
    } else {
        relative
    };
    names.format.match_name(stem).is_some_and(|args| args.first().is_some_and(|lod| *lod < lods))
}

/// Whether `path` holds a previous OME-Zarr output: an empty directory, or OME metadata at
/// the root and nothing but the level arrays beside it.
pub fn recognise_dir(path: &Path) -> std::result::Result<(), String> {
    let entries: Vec<_> = fs::read_dir(path)
        .and_then(|r| r.collect::<std::io::Result<Vec<_>>>())
        .map_err(|e| format!("unreadable ({e})"))?;
    if entries.is_empty() {
        return Ok(());
    }
    let metadata = ["zarr.json", ".zattrs"].iter().map(|n| path.join(n)).find(|p| p.is_file());
    let Some(metadata) = metadata else {
        let first = entries[0].file_name();
        return Err(format!("holds {} and no OME-Zarr metadata (zarr.json or .zattrs)", first.to_string_lossy()));
    };
    let text = fs::File::open(&metadata)
        .and_then(|f| {
            let mut s = String::new();
            f.take(16 << 20).read_to_string(&mut s).map(|_| s)
        })
        .map_err(|e| format!("unreadable ({e})"))?;
    if !text.contains("\"multiscales\"") {
        return Err(format!("a Zarr hierarchy whose {} has no multiscales", metadata.shown()));
    }
    for entry in entries {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let level = entry.file_type().is_ok_and(|t| t.is_dir()) && name.bytes().all(|b| b.is_ascii_digit());
        if !(level || [".zgroup", ".zattrs", "zarr.json", "labels"].contains(&name.as_ref())) {
            return Err(format!("holds {name}, which is not part of an OME-Zarr image"));
        }
    }
    Ok(())
}

/// Whether `path` holds a previous `.ozx`: a zip whose first entry is the root `zarr.json`.
pub fn recognise_ozx(path: &Path) -> std::result::Result<(), String> {
    let mut head = Vec::with_capacity(40);
    fs::File::open(path).and_then(|f| f.take(39).read_to_end(&mut head)).map_err(|e| format!("unreadable ({e})"))?;
    let first_name = head.get(30..39);
    if head.starts_with(b"PK\x03\x04") && head.get(26..28) == Some(&[9, 0][..]) && first_name == Some(b"zarr.json") {
        Ok(())
    } else {
        Err("a file that is not a zipped OME-Zarr".into())
    }
}

#[cfg(test)]
mod dicom_names {
    use super::is_dicom_instance_name;

    /// Names a series never gives an instance are not taken for one.
    #[test]
    fn other_names_are_not_instances() {
        for name in ["level-.dcm", "level-x.dcm", "label.txt", "macro.dcm", "label-.dcm", "label-a.dcm", "x.dcm"] {
            assert!(!is_dicom_instance_name(name), "{name}");
        }
        assert!(is_dicom_instance_name("overview-3.dcm"));
    }
}
