//! A `--layout ome-zarr` run as the user asked for it, checked against the source (and, for a
//! label image, the image it belongs to) before the first tile: OME-Zarr fixes what a tile
//! directory or a pack leaves to the user (no border, zstd chunks, the Zarr names), so a flag
//! that would change those is refused, naming it; the rest follows [`resolve`]'s rule, the flag
//! else the default (there is no previous `info.json` to read).

use std::path::Path;

use crate::codec::ZSTD_LEVELS;
use crate::error::{Result, ShowPath, TilerError};
use crate::formats::ome_zarr::{
    DEFAULT_CHUNK, DEFAULT_SHARD_CHUNKS, LabelParent, MAX_SHARD_CHUNKS, PixelSize, Plane, Spec, Version, is_ozx,
};
use crate::job::SplitOptions;
use crate::limits::Limits;
use crate::output::Product;
use crate::pyramid::filter::Filter;
use crate::settings::{CodecChoice, DEFAULT_ZSTD_LEVEL, Requested, resolve};
use crate::source::ImageHeader;

/// What only an OME-Zarr run is asked (`None`: not given).
#[derive(Clone, Debug, Default)]
pub struct OmeZarrRequested {
    /// `--ome-zarr-version` [default: 0.5, or a label image's image's].
    pub version: Option<Version>,
    /// `--shard-chunks` (0.5 only) [default: [`DEFAULT_SHARD_CHUNKS`]].
    pub shard_chunks: Option<u32>,
    /// `--pixel-size`: the levels' scale and the axes' unit.
    pub pixel_size: Option<PixelSize>,
    /// The image's name in `multiscales` (a trailing `.ome` is dropped).
    pub name: String,
    /// Channels written one pass each, where the run does so.
    pub planes: Option<Vec<Plane>>,
}

/// A checked OME-Zarr run: what the sink writes and how the pipeline cuts it.
#[derive(Clone, Debug)]
pub struct OmeZarrPlan {
    /// A directory or a `.ozx` file.
    pub product: Product,
    pub spec: Spec,
    pub opts: SplitOptions,
}

impl OmeZarrPlan {
    /// Plans a run of `source` into `dest` from the settings `asked` and the OME-Zarr ones
    /// `zarr`, within `limits`. `parent` is the image `dest` is a label image of
    /// ([`crate::formats::ome_zarr::label_parent`]), whose version, chunks and size it must match.
    pub fn new(
        asked: &Requested,
        zarr: OmeZarrRequested,
        dest: &Path,
        parent: Option<&LabelParent>,
        source: &ImageHeader,
        limits: &Limits,
    ) -> Result<OmeZarrPlan> {
        refuse_settings(asked)?;
        let version = match (parent, zarr.version) {
            (Some(p), Some(ours)) if p.version != ours => {
                return Err(options(format!(
                    "{} is OME-Zarr {}: its labels are too; leave out --ome-zarr-version {}",
                    p.image.shown(),
                    p.version.name(),
                    ours.name()
                )));
            }
            (Some(p), _) => p.version,
            (None, asked) => asked.unwrap_or(Version::V05),
        };
        if parent.is_some() && !asked.filter.is_some_and(Filter::is_label) {
            return Err(options(format!(
                "{}: a label image's levels need --filter mode or --filter nearest (a mean would invent labels)",
                dest.shown()
            )));
        }
        let shard_chunks = match (version, zarr.shard_chunks) {
            (Version::V04, Some(_)) => {
                return Err(options("--shard-chunks: OME-Zarr 0.4 (Zarr v2) has no shards; it is for 0.5".into()));
            }
            (_, Some(n)) if !(1..=MAX_SHARD_CHUNKS).contains(&n) => {
                return Err(options(format!("--shard-chunks {n} must be from 1 to {MAX_SHARD_CHUNKS}")));
            }
            (_, n) => n.unwrap_or(DEFAULT_SHARD_CHUNKS),
        };
        let product = if is_ozx(dest) { Product::Ozx } else { Product::OmeZarr };
        if product == Product::Ozx && version != Version::V05 {
            return Err(options(format!(
                "{}: a zipped OME-Zarr (.ozx, RFC-9) holds OME-Zarr 0.5; leave out --ome-zarr-version 0.4 or write a directory",
                dest.shown()
            )));
        }
        let requested = Requested {
            // A label image's levels are its image's: the same chunks by default.
            tile_size: Some(asked.tile_size.or(parent.map(|p| p.chunk)).unwrap_or(DEFAULT_CHUNK)),
            border: Some(0),
            // Raw tiles go to the sink, which compresses the chunks itself.
            codec: Some(CodecChoice::Raw),
            background: asked.background,
            flatten: asked.flatten,
            tile_depth: asked.tile_depth,
            // Microscopy samples measure intensity linearly: the mean of the stored values is the
            // right reduction, not one in sRGB's linear light.
            filter: Some(asked.filter.unwrap_or(Filter::Box)),
            max_memory: asked.max_memory,
            ..Requested::default()
        };
        let (opts, _) = resolve(&requested, None, source.layout)?;
        let zstd_level = asked.zstd_level.unwrap_or(DEFAULT_ZSTD_LEVEL);
        if !ZSTD_LEVELS.contains(&zstd_level) {
            return Err(options(format!(
                "zstd level {zstd_level} (--zstd-level) is outside {}..={}",
                ZSTD_LEVELS.start(),
                ZSTD_LEVELS.end()
            )));
        }
        let layout = opts.layout(source.width, source.height)?;
        let stored = opts.codec.stored_layout(source.layout, opts.flatten, opts.tile_depth)?;
        limits.check_pyramid(&layout, false)?;
        if let Some(p) = parent {
            let ours = (layout.width as u64, layout.height as u64, layout.lod_count);
            if ours != (p.size.0, p.size.1, p.levels) {
                return Err(options(format!(
                    "{} is {}x{} in {} levels, but this label image is {}x{} in {} levels (--tile-size {}); a label image matches its image",
                    p.image.shown(),
                    p.size.0,
                    p.size.1,
                    p.levels,
                    ours.0,
                    ours.1,
                    ours.2,
                    layout.tile_size
                )));
            }
        }
        let spec = Spec {
            version,
            layout,
            stored,
            shard_chunks,
            zstd_level,
            pixel_size: zarr.pixel_size,
            name: zarr.name.trim_end_matches(".ome").to_string(),
            filter: opts.filter.name().to_string(),
            label: parent.is_some(),
            planes: zarr.planes,
        };
        limits.check_memory(
            &format!(
                "holding the indexes of {} shards of {shard_chunks}x{shard_chunks} chunks (all open at worst; larger chunks, --tile-size, need fewer)",
                spec.shard_count()
            ),
            spec.index_bytes(),
        )?;
        Ok(OmeZarrPlan { product, spec, opts })
    }
}

/// The settings OME-Zarr fixes: asking for another is an error naming the flag.
fn refuse_settings(asked: &Requested) -> Result<()> {
    if asked.filename_format.is_some() {
        return Err(options(
            "--layout ome-zarr names its chunks as Zarr does; --filename-format is for --layout vortex".into(),
        ));
    }
    // Zarr chunks tile the array edge to edge: a border would be texels stored twice.
    if let Some(border) = asked.border.filter(|b| *b != 0) {
        return Err(options(format!(
            "--border {border}: OME-Zarr chunks have no border (each texel is stored once); leave it out"
        )));
    }
    if let Some(codec) = asked.codec.filter(|c| *c != CodecChoice::Zstd) {
        return Err(options(format!(
            "--codec {}: OME-Zarr chunks are zstd-compressed (the codec every Zarr reader has); leave --codec out or set --zstd-level",
            codec.name()
        )));
    }
    for (given, flag) in [
        (asked.quality.is_some(), "--quality"),
        (asked.subsampling.is_some(), "--subsampling"),
        (asked.png_level.is_some(), "--png-compression"),
        (asked.bc7_effort.is_some(), "--bc7-effort"),
    ] {
        if given {
            return Err(options(format!(
                "{flag} does not apply to --layout ome-zarr, whose chunks are zstd-compressed (--zstd-level)"
            )));
        }
    }
    Ok(())
}

fn options(message: String) -> TilerError {
    TilerError::Options(message)
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;
    use crate::codec::{Bc7Effort, PngLevel, Subsampling};
    use crate::pixel::{Channels, Depth, PixelLayout};

    /// A 1000x600 source of `channels`, 8-bit.
    fn header(channels: Channels) -> ImageHeader {
        ImageHeader { width: 1000, height: 600, layout: PixelLayout::new(channels, Depth::U8) }
    }

    fn plan(
        asked: &Requested,
        zarr: OmeZarrRequested,
        dest: &str,
        parent: Option<&LabelParent>,
    ) -> Result<OmeZarrPlan> {
        let source = header(if parent.is_some() { Channels::Grey } else { Channels::Rgb });
        OmeZarrPlan::new(asked, zarr, Path::new(dest), parent, &source, &Limits::default())
    }

    /// The image of a label image: OME-Zarr 0.4, 128-texel chunks, and the size and levels a
    /// 1000x600 grey source has at that chunk (as the plan without a parent makes them).
    fn parent() -> LabelParent {
        let grey = Requested { tile_size: Some(128), ..Requested::default() };
        let source = header(Channels::Grey);
        let plain = OmeZarrPlan::new(&grey, zarr(), Path::new("i.ome.zarr"), None, &source, &Limits::default())
            .expect("a plan");
        let l = plain.spec.layout;
        LabelParent {
            image: PathBuf::from("image.ome.zarr"),
            version: Version::V04,
            levels: l.lod_count,
            size: (l.width as u64, l.height as u64),
            chunk: 128,
        }
    }

    fn zarr() -> OmeZarrRequested {
        OmeZarrRequested { name: "slide.ome".into(), ..OmeZarrRequested::default() }
    }

    /// Each row: what was asked, of a label image or not, and what the plan holds. Expected
    /// values are written out, not the library's constants, so that a changed default fails
    /// here (docs/ome-zarr.md lists them).
    #[test]
    fn a_flag_wins_over_the_label_image_s_image_which_wins_over_the_default() {
        let none = Requested::default;
        let label = Requested { filter: Some(Filter::Mode), ..none() };
        let image = parent();
        type Check = fn(&OmeZarrPlan) -> String;
        /// What is asked, the destination, the image of a label image, and what to check.
        type Case<'a> = (&'a str, Requested, OmeZarrRequested, &'a str, Option<&'a LabelParent>, Check, &'a str);
        let version: Check = |p| p.spec.version.name().to_string();
        let chunk: Check = |p| p.spec.layout.tile_size.to_string();
        let cases: Vec<Case> = vec![
            ("version by default", none(), zarr(), "o.ome.zarr", None, version, "0.5"),
            (
                "version: the flag",
                none(),
                OmeZarrRequested { version: Some(Version::V04), ..zarr() },
                "o.ome.zarr",
                None,
                version,
                "0.4",
            ),
            ("version: a label image's image's", label.clone(), zarr(), "o", Some(&image), version, "0.4"),
            ("chunk by default", none(), zarr(), "o.ome.zarr", None, chunk, "256"),
            ("chunk: the flag", Requested { tile_size: Some(512), ..none() }, zarr(), "o", None, chunk, "512"),
            ("chunk: a label image's image's", label.clone(), zarr(), "o", Some(&image), chunk, "128"),
            (
                // 150-texel chunks make the image's 4 levels too (128: 8, 4, 2, 1 pages; 150: 7, 4, 2, 1).
                "chunk: the flag over the image's",
                Requested { tile_size: Some(150), ..label.clone() },
                zarr(),
                "o",
                Some(&image),
                |p| format!("{} {}", p.spec.layout.tile_size, p.spec.label),
                "150 true",
            ),
            ("shard chunks by default", none(), zarr(), "o", None, |p| p.spec.shard_chunks.to_string(), "16"),
            (
                "shard chunks: the flag",
                none(),
                OmeZarrRequested { shard_chunks: Some(8), ..zarr() },
                "o",
                None,
                |p| p.spec.shard_chunks.to_string(),
                "8",
            ),
            ("filter by default: box (linear samples)", none(), zarr(), "o", None, |p| p.spec.filter.clone(), "box"),
            (
                "filter: the flag",
                Requested { filter: Some(Filter::Lanczos3), ..none() },
                zarr(),
                "o",
                None,
                |p| p.spec.filter.clone(),
                "lanczos3",
            ),
            ("zstd level by default", none(), zarr(), "o", None, |p| p.spec.zstd_level.to_string(), "3"),
            (
                "zstd level: the flag",
                Requested { zstd_level: Some(9), codec: Some(CodecChoice::Zstd), ..none() },
                zarr(),
                "o",
                None,
                |p| p.spec.zstd_level.to_string(),
                "9",
            ),
            (
                "chunks: raw texels, no border (the sink compresses)",
                Requested { border: Some(0), ..none() },
                zarr(),
                "o",
                None,
                |p| format!("{} {}", p.opts.codec.name(), p.opts.border),
                "raw 0",
            ),
            ("name without .ome", none(), zarr(), "o", None, |p| p.spec.name.clone(), "slide"),
            ("a directory", none(), zarr(), "o.ome.zarr", None, |p| format!("{:?}", p.product), "OmeZarr"),
            ("a zip", none(), zarr(), "o.OZX", None, |p| format!("{:?}", p.product), "Ozx"),
        ];
        for (what, asked, zarr, dest, parent, check, expected) in cases {
            let plan = plan(&asked, zarr, dest, parent).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(check(&plan), expected, "{what}");
        }
    }

    /// Each row: what was asked and the words the refusal must say (the flag, and why).
    #[test]
    fn what_ome_zarr_fixes_is_refused_naming_the_flag() {
        let none = Requested::default;
        let label = Requested { filter: Some(Filter::Nearest), ..none() };
        let image = parent();
        let v04 = || OmeZarrRequested { version: Some(Version::V04), ..zarr() };
        let cases: Vec<(Requested, OmeZarrRequested, &str, Option<&LabelParent>, &str)> = vec![
            (
                Requested { filename_format: Some("t_%d.png".into()), ..none() },
                zarr(),
                "o",
                None,
                "--filename-format is for --layout vortex",
            ),
            (Requested { border: Some(1), ..none() }, zarr(), "o", None, "--border 1: OME-Zarr chunks have no border"),
            (
                Requested { codec: Some(CodecChoice::Png), ..none() },
                zarr(),
                "o",
                None,
                "--codec png: OME-Zarr chunks are zstd-compressed",
            ),
            (Requested { quality: Some(90), ..none() }, zarr(), "o", None, "--quality does not apply"),
            (Requested { subsampling: Some(Subsampling::S444), ..none() }, zarr(), "o", None, "--subsampling does"),
            (Requested { png_level: Some(PngLevel::Best), ..none() }, zarr(), "o", None, "--png-compression does"),
            (Requested { bc7_effort: Some(Bc7Effort::Fast), ..none() }, zarr(), "o", None, "--bc7-effort does"),
            (
                none(),
                OmeZarrRequested { shard_chunks: Some(4), ..v04() },
                "o",
                None,
                "--shard-chunks: OME-Zarr 0.4 (Zarr v2) has no shards",
            ),
            (none(), OmeZarrRequested { shard_chunks: Some(0), ..zarr() }, "o", None, "--shard-chunks 0 must be"),
            (none(), OmeZarrRequested { shard_chunks: Some(257), ..zarr() }, "o", None, "from 1 to 256"),
            (none(), v04(), "o.ozx", None, "o.ozx: a zipped OME-Zarr (.ozx, RFC-9) holds OME-Zarr 0.5"),
            (
                Requested { zstd_level: Some(99), ..none() },
                zarr(),
                "o",
                None,
                "zstd level 99 (--zstd-level) is outside",
            ),
            (
                label.clone(),
                OmeZarrRequested { version: Some(Version::V05), ..zarr() },
                "o",
                Some(&image),
                "image.ome.zarr is OME-Zarr 0.4: its labels are too; leave out --ome-zarr-version 0.5",
            ),
            (none(), zarr(), "o", Some(&image), "o: a label image's levels need --filter mode or --filter nearest"),
            (Requested { tile_size: Some(512), ..label }, zarr(), "o", Some(&image), "a label image matches its image"),
        ];
        for (asked, zarr, dest, parent, expected) in cases {
            match plan(&asked, zarr, dest, parent) {
                Ok(_) => panic!("{expected}: accepted"),
                Err(e) => assert!(e.to_string().contains(expected), "{expected}: said {e}"),
            }
        }
    }
}
