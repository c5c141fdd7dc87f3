//! Recognising a previous output in a viewer layout, the only directory `split --layout` may
//! replace: its manifest as we write it, and nothing but the tile names of the layout. A
//! folder of photos named `2024/01/05.jpg` has no manifest, so it is never taken for tiles.

use std::fs;
use std::path::Path;

use super::{Viewer, xyz};

/// The largest manifest read to recognise it; ours are a few hundred bytes.
const MAX_MANIFEST_BYTES: u64 = 1 << 20;

/// `Ok` if `dir` is empty or holds a previous `viewer` output of ours, else what it holds.
pub fn recognise(viewer: Viewer, dir: &Path) -> Result<(), String> {
    let files = files_under(dir)?;
    if files.is_empty() {
        return Ok(());
    }
    let manifest = |name: &str| -> Result<String, String> {
        let path = dir.join(name);
        match fs::metadata(&path) {
            Ok(m) if m.is_file() && m.len() <= MAX_MANIFEST_BYTES => {
                fs::read_to_string(&path).map_err(|e| format!("an unreadable {name} ({e})"))
            }
            Ok(_) => Err(format!("a {name} that is not ours")),
            Err(_) => Err(format!("holds {} and no {name}", files[0])),
        }
    };
    let is_tile: Box<dyn Fn(&str) -> bool> = match viewer {
        Viewer::Dzi => {
            let dzis: Vec<&String> = files.iter().filter(|f| !f.contains('/') && f.ends_with(".dzi")).collect();
            let [dzi] = dzis[..] else {
                return Err(format!("holds {} .dzi descriptors, not one", dzis.len()));
            };
            if !manifest(dzi)?.contains("schemas.microsoft.com/deepzoom") {
                return Err(format!("holds {dzi}, which is not a Deep Zoom descriptor"));
            }
            let prefix = format!("{}_files/", dzi.trim_end_matches(".dzi"));
            let dzi = dzi.clone();
            Box::new(move |f: &str| {
                f == dzi
                    || f.strip_prefix(&prefix).and_then(|t| t.split_once('/')).is_some_and(|(level, tile)| {
                        numbers(level, ',') == Some(1)
                            && image(tile)
                                .and_then(|stem| stem.split_once('_'))
                                .is_some_and(|(c, r)| numbers(c, ',') == Some(1) && numbers(r, ',') == Some(1))
                    })
            })
        }
        Viewer::Iiif => {
            let info: serde_json::Value = serde_json::from_str(&manifest("info.json")?)
                .map_err(|_| "an info.json that is not JSON".to_string())?;
            let ours = info["@context"].as_str().is_some_and(|c| c.contains("iiif.io/api/image"))
                && info["profile"] == "level0";
            if !ours {
                return Err("an info.json that is not a IIIF level-0 image".into());
            }
            Box::new(|f: &str| f == "info.json" || is_iiif_tile(f))
        }
        Viewer::Xyz | Viewer::Google => {
            let doc: serde_json::Value = serde_json::from_str(&manifest(xyz::TILEJSON)?)
                .map_err(|_| format!("a {} that is not JSON", xyz::TILEJSON))?;
            if doc.get("tilejson").is_none() || doc.get("vortex").is_none() {
                return Err(format!("a {} this tool did not write", xyz::TILEJSON));
            }
            Box::new(|f: &str| {
                f == xyz::TILEJSON
                    || f.split_once('/').is_some_and(|(z, rest)| {
                        numbers(z, ',') == Some(1)
                            && rest.split_once('/').is_some_and(|(a, b)| {
                                numbers(a, ',') == Some(1) && image(b).is_some_and(|s| numbers(s, ',') == Some(1))
                            })
                    })
            })
        }
    };
    match files.iter().find(|f| !is_tile(f)) {
        Some(other) => Err(format!("holds {other}, which is not one of its tiles")),
        None => Ok(()),
    }
}

/// `{x},{y},{w},{h}/{w},{h}/0/default.EXT` or `full/{w},{h}|max/0/default.EXT`.
fn is_iiif_tile(f: &str) -> bool {
    let parts: Vec<&str> = f.split('/').collect();
    let [region, size, "0", file] = parts[..] else { return false };
    let region_ok = region == "full" || numbers(region, ',') == Some(4);
    let size_ok = size == "max" || numbers(size, ',') == Some(2);
    region_ok && size_ok && image(file) == Some("default")
}

/// The stem of a tile image's file name.
fn image(name: &str) -> Option<&str> {
    let (stem, ext) = name.rsplit_once('.')?;
    ["jpg", "jpeg", "png", "jxl"].contains(&ext).then_some(stem)
}

/// How many decimal numbers `text` is, separated by `sep`; `None` if anything else is in it.
fn numbers(text: &str, sep: char) -> Option<usize> {
    let parts: Vec<&str> = text.split(sep).collect();
    parts.iter().all(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit())).then_some(parts.len())
}

/// Every file under `dir`, as paths relative to it with `/`; a link or special file is an error.
fn files_under(dir: &Path) -> Result<Vec<String>, String> {
    let mut files = Vec::new();
    let mut stack = vec![(dir.to_path_buf(), String::new())];
    while let Some((path, prefix)) = stack.pop() {
        let read = fs::read_dir(&path).map_err(|e| format!("unreadable ({e})"))?;
        for entry in read {
            let entry = entry.map_err(|e| format!("unreadable ({e})"))?;
            let relative = format!("{prefix}{}", entry.file_name().to_string_lossy());
            let kind = entry.file_type().map_err(|e| format!("unreadable ({e})"))?;
            if kind.is_dir() {
                stack.push((entry.path(), format!("{relative}/")));
            } else if kind.is_file() {
                files.push(relative);
            } else {
                return Err(format!("holds {relative}, which is not a regular file"));
            }
        }
    }
    files.sort();
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, files: &[(&str, &str)]) {
        for (name, text) in files {
            let path = dir.join(name);
            fs::create_dir_all(path.parent().unwrap()).unwrap();
            fs::write(path, text).unwrap();
        }
    }

    #[test]
    fn deep_zoom() {
        let d = tempfile::tempdir().unwrap();
        assert_eq!(recognise(Viewer::Dzi, d.path()), Ok(()));
        let dzi = "<Image xmlns=\"http://schemas.microsoft.com/deepzoom/2008\"/>";
        write(d.path(), &[("a.dzi", dzi), ("a_files/0/0_0.jpeg", ""), ("a_files/10/2_1.jpeg", "")]);
        assert_eq!(recognise(Viewer::Dzi, d.path()), Ok(()));
        write(d.path(), &[("a_files/vips-properties.xml", "")]);
        assert!(recognise(Viewer::Dzi, d.path()).unwrap_err().contains("vips-properties.xml"));
        let photos = tempfile::tempdir().unwrap();
        write(photos.path(), &[("2024/01/05.jpg", "")]);
        assert!(recognise(Viewer::Dzi, photos.path()).is_err());
        assert!(recognise(Viewer::Xyz, photos.path()).unwrap_err().contains("no tilejson.json"));
    }

    #[test]
    fn iiif_and_xyz() {
        let d = tempfile::tempdir().unwrap();
        let info = r#"{"@context": "http://iiif.io/api/image/3/context.json", "profile": "level0"}"#;
        write(
            d.path(),
            &[("info.json", info), ("0,0,512,500/512,500/0/default.jpg", ""), ("full/max/0/default.jpg", "")],
        );
        assert_eq!(recognise(Viewer::Iiif, d.path()), Ok(()));
        write(d.path(), &[("notes.txt", "")]);
        assert!(recognise(Viewer::Iiif, d.path()).is_err());
        let x = tempfile::tempdir().unwrap();
        write(x.path(), &[("tilejson.json", r#"{"tilejson": "3.0.0", "vortex": {}}"#), ("3/1/2.png", "")]);
        assert_eq!(recognise(Viewer::Xyz, x.path()), Ok(()));
        write(x.path(), &[("3/1/a.png", "")]);
        assert!(recognise(Viewer::Google, x.path()).is_err());
    }
}
