//! Sharded splits: `merge` of any number of shards gives the pack one machine makes, byte for
//! byte, whatever the image, options and pass plan; shards that do not belong together are
//! refused by name.

use std::path::{Path, PathBuf};

use crate::common::*;
use proptest::prelude::*;
use vortex_pack::WriteOptions;
use vortex_tiler::background::Background;
use vortex_tiler::codec::Codec;
use vortex_tiler::formats::pack::PackSink;
use vortex_tiler::formats::tiles::filename::FilenameFormat;
use vortex_tiler::layout::Layout;
use vortex_tiler::pyramid::Filter;
use vortex_tiler::scale_out::{ShardJob, merge, write_shard};
use vortex_tiler::settings;
use vortex_tiler::split::{SplitOptions, split};
use vortex_tiler::testing::one_band_bytes;

const EXACT: [Filter; 4] = [Filter::Box, Filter::Linear, Filter::Premultiplied, Filter::LinearPremultiplied];

/// A scratch directory, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Scratch {
        static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("vortex-shard-{name}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }
    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The metadata `split --pack` writes for `image` and `opts`.
fn info(image: &Image, opts: &SplitOptions) -> String {
    let layout = opts.layout(image.width, image.height).unwrap();
    let stored = opts.codec.stored_layout(image.layout, opts.flatten, opts.tile_depth).unwrap();
    let names =
        FilenameFormat::parse(&format!("{}.{}", settings::DEFAULT_FILENAME_STEM, opts.codec.extension()), 3).unwrap();
    settings::describe(&layout, stored, opts, &names).to_json_pretty()
}

/// `split --pack` of `image` into `dest`.
fn one_machine(image: &Image, opts: &SplitOptions, dest: &Path) {
    try_one_machine(image, opts, dest).unwrap();
}

/// [`one_machine`], or why it could not run (a budget too small for the pack's run).
fn try_one_machine(image: &Image, opts: &SplitOptions, dest: &Path) -> Result<(), vortex_tiler::error::TilerError> {
    let layout = opts.layout(image.width, image.height).unwrap();
    let stored = opts.codec.stored_layout(image.layout, opts.flatten, opts.tile_depth).unwrap();
    let sink =
        PackSink::create(dest, &layout, stored, opts.codec, info(image, opts).as_bytes(), WriteOptions::default())
            .unwrap();
    split(image.source(), &sink, opts, &())?;
    sink.finish().map(|_| ())
}

/// `split --shard i/count --pack` of every shard; the shard files.
fn shards(image: &Image, opts: &SplitOptions, count: u32, input: &Path, dir: &Scratch) -> Vec<PathBuf> {
    (0..count)
        .map(|index| {
            let dest = dir.path(&format!("shard-{index}.vtpk"));
            let job = ShardJob { index, count, input, info: info(image, opts), pack: WriteOptions::default() };
            write_shard(image.source(), &dest, opts, &job, &()).unwrap();
            dest
        })
        .collect()
}

fn input_file(dir: &Scratch, content: &[u8]) -> PathBuf {
    let input = dir.path("input.raw");
    std::fs::write(&input, content).unwrap();
    input
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    #[test]
    fn merged_shards_are_the_one_machine_pack(
        w in 1u32..260,
        h in 1u32..260,
        layout_idx in 0usize..8,
        filter_idx in 0usize..EXACT.len(),
        tile in 8u32..24,
        border in 0u32..3,
        colour in proptest::option::of(any::<[u8; 4]>()),
        raw in any::<bool>(),
        count in 1u32..12,
        striped in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let image = Image::random(w, h, layouts()[layout_idx], seed);
        let background = colour.map_or(Background::Edge, Background::Colour);
        let mut opts = SplitOptions { filter: EXACT[filter_idx], ..png_options(tile, border, background) };
        if raw {
            opts.codec = Codec::Raw;
        }
        let layout = Layout::new(w as u64, h as u64, tile, border).unwrap();
        let count = count.min(layout.columns * layout.rows);
        if striped {
            // The one-machine run in stripes: its pack's order differs, and merge follows it.
            opts.max_memory = one_band_bytes(&layout, image.layout.bytes_per_pixel() as u64) / 2;
        }
        let dir = Scratch::new("prop");
        let whole = dir.path("whole.vtpk");
        // A budget too small for the pack's run (its encodings wait for the writer) is refused.
        prop_assume!(try_one_machine(&image, &opts, &whole).is_ok());
        let input = input_file(&dir, &seed.to_le_bytes());
        let written: Vec<PathBuf> = (0..count)
            .map(|index| {
                let dest = dir.path(&format!("shard-{index}.vtpk"));
                let job = ShardJob { index, count, input: &input, info: info(&image, &opts), pack: WriteOptions::default() };
                write_shard(image.source(), &dest, &opts, &job, &()).map(|_| dest)
            })
            .collect::<Result<_, _>>()
            .unwrap_or_default();
        // A shard whose region does not fit the small budget is refused (and said so).
        prop_assume!(written.len() == count as usize);
        let mut given = written.clone();
        given.reverse();
        let merged = dir.path("merged.vtpk");
        merge(&given, &merged, &()).unwrap();
        let (a, b) = (std::fs::read(&whole).unwrap(), std::fs::read(&merged).unwrap());
        prop_assert!(a == b, "{}x{} {} tile {} border {} in {} shards: {} against {} bytes", w, h, image.layout, tile, border, count, a.len(), b.len());
    }
}

#[test]
fn a_deep_pyramid_in_many_shards_is_the_one_machine_pack() {
    // 1100 x 37 RGBA 16-bit in 8-texel pages: 138 x 5 pages, 9 LODs, u128 sums under the
    // premultiplied linear filter.
    let image = Image::random(1100, 37, layouts()[7], 3);
    let opts = SplitOptions { filter: Filter::LinearPremultiplied, ..png_options(8, 1, Background::Edge) };
    let dir = Scratch::new("deep");
    let whole = dir.path("whole.vtpk");
    one_machine(&image, &opts, &whole);
    let input = input_file(&dir, b"deep");
    for count in [2, 7, 64] {
        let merged = dir.path(&format!("merged-{count}.vtpk"));
        merge(&shards(&image, &opts, count, &input, &dir), &merged, &()).unwrap();
        assert!(std::fs::read(&whole).unwrap() == std::fs::read(&merged).unwrap(), "{count} shards");
    }
}

#[test]
fn a_long_strip_with_far_coordinates_in_odd_shards_is_the_one_machine_pack() {
    // 100003 x 3 grey-alpha 16-bit in 8-texel pages, border 1: 16668 pages in a row, 16 LODs,
    // regions at texel offsets near 100000 and a last page of one texel.
    let image = Image::random(100_003, 3, layouts()[3], 11);
    let opts = SplitOptions { codec: Codec::Raw, filter: Filter::Premultiplied, ..png_options(8, 1, Background::Edge) };
    let dir = Scratch::new("strip");
    let whole = dir.path("whole.vtpk");
    one_machine(&image, &opts, &whole);
    let input = input_file(&dir, b"strip");
    let merged = dir.path("merged.vtpk");
    merge(&shards(&image, &opts, 13, &input, &dir), &merged, &()).unwrap();
    assert!(std::fs::read(&whole).unwrap() == std::fs::read(&merged).unwrap());
}

#[test]
fn identical_pages_in_different_shards_are_stored_once() {
    // A pattern that repeats every page: LOD 0 is 12 x 8 copies of one page, split over 5 shards.
    let (w, h, p) = (192u32, 128u32, 16u32);
    let layout = layouts()[4];
    let samples = (0..h)
        .flat_map(|y| (0..w).flat_map(move |x| [(x % p * 13) as u16, (y % p * 7) as u16, ((x % p) ^ (y % p)) as u16]));
    let image = Image { width: w, height: h, layout, samples: samples.collect() };
    let opts = SplitOptions { codec: Codec::Raw, ..png_options(p, 0, Background::Edge) };
    let dir = Scratch::new("dedup");
    let whole = dir.path("whole.vtpk");
    one_machine(&image, &opts, &whole);
    let input = input_file(&dir, b"dedup");
    let merged = dir.path("merged.vtpk");
    let summary = merge(&shards(&image, &opts, 5, &input, &dir), &merged, &()).unwrap();
    assert!(summary.pack.deduplicated >= 95, "{:?}", summary.pack);
    assert!(std::fs::read(&whole).unwrap() == std::fs::read(&merged).unwrap());
}

#[test]
fn shards_that_do_not_belong_together_are_named() {
    let image = Image::random(100, 80, layouts()[4], 5);
    let opts = png_options(16, 0, Background::Edge);
    let dir = Scratch::new("refuse");
    let input = input_file(&dir, b"one");
    let four = shards(&image, &opts, 4, &input, &dir);
    let out = dir.path("out.vtpk");
    let error = |paths: &[PathBuf]| merge(paths, &out, &()).unwrap_err().to_string();

    let e = error(&four[..3]);
    assert!(e.contains("shard 3 of 4 missing"), "{e}");
    let e = error(&[four[0].clone(), four[1].clone(), four[1].clone(), four[2].clone(), four[3].clone()]);
    assert!(e.contains("shard-1.vtpk") && e.contains("given twice"), "{e}");

    // A shard of another input (same image, other file) and one of other options.
    let other_dir = Scratch::new("refuse-other");
    let other = input_file(&other_dir, b"two");
    let foreign = shards(&image, &opts, 4, &other, &other_dir);
    let e = error(&[four[0].clone(), four[1].clone(), foreign[2].clone(), four[3].clone()]);
    assert!(e.contains(&foreign[2].display().to_string()) && e.contains("same input"), "{e}");
    let q_dir = Scratch::new("refuse-q");
    let jpeg = SplitOptions {
        codec: Codec::Jpeg { quality: 70, subsampling: vortex_tiler::codec::Subsampling::S420 },
        ..opts.clone()
    };
    let q = shards(&image, &jpeg, 4, &input, &q_dir);
    let e = error(&[four[0].clone(), q[1].clone(), four[2].clone(), four[3].clone()]);
    assert!(e.contains("other options") && e.contains("codec"), "{e}");

    // A pack that is not a shard.
    let plain = dir.path("plain.vtpk");
    one_machine(&image, &opts, &plain);
    let e = error(std::slice::from_ref(&plain));
    assert!(e.contains("plain.vtpk") && e.contains("not a shard"), "{e}");
    assert!(!out.exists());
}

#[test]
fn a_shard_made_again_merges_to_the_same_bytes() {
    let image = Image::random(300, 200, layouts()[2], 9);
    let opts = png_options(32, 2, Background::Edge);
    let dir = Scratch::new("again");
    let input = input_file(&dir, b"again");
    let paths = shards(&image, &opts, 5, &input, &dir);
    let (first, second) = (dir.path("first.vtpk"), dir.path("second.vtpk"));
    merge(&paths, &first, &()).unwrap();
    let job = ShardJob { index: 3, count: 5, input: &input, info: info(&image, &opts), pack: WriteOptions::default() };
    write_shard(image.source(), &paths[3], &opts, &job, &()).unwrap();
    merge(&paths, &second, &()).unwrap();
    assert!(std::fs::read(&first).unwrap() == std::fs::read(&second).unwrap());
}

// From the command line.

const BIN: &str = env!("CARGO_BIN_EXE_vortex-tiler");

fn vortex(args: &[&str]) -> std::process::Output {
    std::process::Command::new(BIN)
        .args(args)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> String {
    let out = vortex(args);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn fails(args: &[&str]) -> String {
    let out = vortex(args);
    // 1 for our errors, 2 for clap's usage errors; never a panic.
    assert!(matches!(out.status.code(), Some(1 | 2)), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A PPM with some structure: several LODs, no two pages alike.
fn ppm(dir: &Scratch, w: u32, h: u32) -> PathBuf {
    let path = dir.path("in.ppm");
    let mut bytes = format!("P6 {w} {h} 255\n").into_bytes();
    for y in 0..h {
        for x in 0..w {
            bytes.extend([(x * 7 + y) as u8, (y * 5 + x / 3) as u8, (x ^ y) as u8]);
        }
    }
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn split_and_convert_shards_merge_to_the_one_machine_pack_from_the_command_line() {
    let dir = Scratch::new("cli");
    let input = ppm(&dir, 700, 500);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (input, whole, merged) = (s(&input), s(&dir.path("whole.vtpk")), s(&dir.path("merged.vtpk")));
    let opts = ["--tile-size", "64", "--border", "2", "--codec", "png"];
    ok(&[&["split", &input, "--pack", &whole], &opts[..]].concat());
    let part = s(&dir.path("part-{shard}.vtpk"));
    for i in 0..3 {
        let out =
            ok(&[&["split", &input, "--pack", &part, "--shard", &format!("{i}/3"), "--json"], &opts[..]].concat());
        let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!((doc["shard"]["index"].as_u64(), doc["shard"]["count"].as_u64()), (Some(i), Some(3)), "{out}");
    }
    let parts: Vec<String> = (0..3).map(|i| s(&dir.path(&format!("part-{i}.vtpk")))).collect();
    let report =
        ok(&[&["merge"], &parts.iter().map(String::as_str).collect::<Vec<_>>()[..], &["-o", &merged]].concat());
    assert!(report.contains("merged 3 shards"), "{report}");
    assert!(std::fs::read(&whole).unwrap() == std::fs::read(&merged).unwrap());

    // convert: a tile directory (split's output) in shards, each decoding only its cells.
    let tiles = s(&dir.path("tiles"));
    ok(&["split", &input, "-o", &tiles, "--tile-size", "100", "--codec", "png"]);
    let (one, joined) = (s(&dir.path("conv.vtpk")), s(&dir.path("conv-merged.vtpk")));
    ok(&[&["convert", &tiles, "--pack", &one], &opts[..]].concat());
    let cpart = s(&dir.path("conv-{shard}.vtpk"));
    for i in 0..4 {
        ok(&[&["convert", &tiles, "--pack", &cpart, "--shard", &format!("{i}/4"), "-q"], &opts[..]].concat());
    }
    let cparts: Vec<String> = (0..4).map(|i| s(&dir.path(&format!("conv-{i}.vtpk")))).collect();
    ok(&[&["merge", "-q", "-o", &joined], &cparts.iter().map(String::as_str).collect::<Vec<_>>()[..]].concat());
    assert!(std::fs::read(&one).unwrap() == std::fs::read(&joined).unwrap());
}

#[test]
fn shard_flags_are_checked_and_explained() {
    let dir = Scratch::new("flags");
    let input = ppm(&dir, 300, 200);
    let input = input.to_str().unwrap();
    let pack = dir.path("p.vtpk");
    let pack = pack.to_str().unwrap();
    let out = dir.path("o");
    let e = fails(&["split", input, "-o", out.to_str().unwrap(), "--shard", "0/2"]);
    assert!(e.contains("--shard writes a shard pack: give --pack"), "{e}");
    let e = fails(&["split", input, "--pack", &dir.path("p-{shard}.vtpk").to_string_lossy()]);
    assert!(e.contains("add --shard"), "{e}");
    let e = fails(&["split", input, "--pack", pack, "--shard", "2/2"]);
    assert!(e.contains("counts from 0"), "{e}");
    let e = fails(&["split", input, "--pack", pack, "--shard", "auto"]);
    assert!(e.contains("SLURM_ARRAY_TASK_ID") && e.contains("JOB_COMPLETION_INDEX"), "{e}");
    let e = fails(&["split", input, "--pack", pack, "--shard", "0/500", "--tile-size", "64"]);
    assert!(e.contains("500 shards for 20 pages"), "{e}");
    let e = fails(&["split", input, "--pack", pack, "--shard", "0/2", "--filter", "lanczos3"]);
    assert!(e.contains("lanczos3") && e.contains("sharded"), "{e}");
    let e = fails(&["split", input, "-o", out.to_str().unwrap(), "--layout", "dzi", "--shard", "0/2"]);
    assert!(e.contains("--shard"), "{e}");

    // A Kubernetes Indexed Job's index, with --shards.
    let k8s = std::process::Command::new(BIN)
        .args([
            "split",
            input,
            "--pack",
            &dir.path("new/k-{shard}.vtpk").to_string_lossy(),
            "--shard",
            "auto",
            "--shards",
            "3",
        ])
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env("JOB_COMPLETION_INDEX", "1")
        .output()
        .unwrap();
    assert!(k8s.status.success(), "{}", String::from_utf8_lossy(&k8s.stderr));
    assert!(String::from_utf8_lossy(&k8s.stderr).contains("JOB_COMPLETION_INDEX=1"));
    assert!(dir.path("new/k-1.vtpk").is_file());
    // A shard is not a whole pyramid: what needs one says to merge first; info says what it is.
    let e = fails(&["unpack", &dir.path("new/k-1.vtpk").to_string_lossy(), "-o", &dir.path("u").to_string_lossy()]);
    assert!(e.contains("shard 1 of 3") && e.contains("vortex-tiler merge"), "{e}");
    assert!(ok(&["info", &dir.path("new/k-1.vtpk").to_string_lossy()]).contains("shard 1 of 3"));

    // merge names what is wrong and writes nothing.
    let merged = dir.path("m.vtpk");
    let e = fails(&["merge", &dir.path("new/k-1.vtpk").to_string_lossy(), "-o", &merged.to_string_lossy()]);
    assert!(e.contains("shards 0, 2 of 3 missing"), "{e}");
    let e = fails(&["merge", input, "-o", &merged.to_string_lossy()]);
    assert!(e.contains("in.ppm"), "{e}");
    assert!(!merged.exists());
}

// Damaged and forged shards: each refused with an error naming the shard (and the field),
// exit 1, nothing written; never an abort, a panic or a wrong pack.

/// Three shards of `input` made by the binary (PNG unless `codec` says otherwise), and their
/// file names as strings.
fn cli_shards(dir: &Scratch, input: &str, codec: &str) -> Vec<String> {
    let part = dir.path("part-{shard}.vtpk").to_string_lossy().into_owned();
    for i in 0..3 {
        ok(&[
            "split",
            input,
            "--pack",
            &part,
            "--shard",
            &format!("{i}/3"),
            "--tile-size",
            "64",
            "--codec",
            codec,
            "-q",
        ]);
    }
    (0..3).map(|i| dir.path(&format!("part-{i}.vtpk")).to_string_lossy().into_owned()).collect()
}

/// `shard` rewritten in place with its manifest changed by `edit`, tiles and checksums intact
/// (as a forger would: every checksum of the file matches).
fn edit_manifest(shard: &str, edit: impl Fn(&mut serde_json::Value)) {
    let metadata = vortex_pack::Pack::open(shard).unwrap().metadata().to_vec();
    let mut manifest: serde_json::Value = serde_json::from_slice(&metadata).unwrap();
    edit(&mut manifest);
    let edited = format!("{shard}.edited");
    crate::common::with_metadata(Path::new(shard), &manifest.to_string(), Path::new(&edited));
    std::fs::rename(&edited, shard).unwrap();
}

/// `merge` of `shards` into `out` fails (exit 1) with a short error holding every one of `words`.
fn merge_fails(shards: &[String], out: &Path, words: &[&str]) {
    let args: Vec<&str> =
        ["merge", "-o", out.to_str().unwrap()].into_iter().chain(shards.iter().map(String::as_str)).collect();
    let out_ = vortex(&args);
    let e = String::from_utf8_lossy(&out_.stderr);
    assert_eq!(out_.status.code(), Some(1), "{args:?}: {e}");
    // Short: a count from the file once made a 7.9 MB error line (only its start is shown).
    let start: String = e.chars().take(600).collect();
    assert!(words.iter().all(|w| e.contains(w)) && e.len() < 1000, "{args:?} should say {words:?}: {start}");
    assert!(!out.exists());
}

#[test]
fn a_count_of_billions_is_refused_before_anything_is_sized_from_it() {
    let dir = Scratch::new("count");
    let input = ppm(&dir, 300, 200);
    let parts = cli_shards(&dir, input.to_str().unwrap(), "png");
    let out = dir.path("m.vtpk");
    for part in &parts {
        edit_manifest(part, |m| m["count"] = 1_000_000.into());
    }
    merge_fails(&parts, &out, &["shards 3, 4, 5, 6, 7, 8, 9, 10, and 999989 more of 1000000 missing"]);
    // One shard that says it is one of 2^32 - 1: the table of shards by index would be 1.8 TB.
    edit_manifest(&parts[0], |m| m["count"] = u32::MAX.into());
    merge_fails(&parts[..1], &out, &["shards 1, 2,", "and 4294967286 more of 4294967295 missing"]);
}

#[test]
fn stored_options_other_than_split_writes_are_refused_by_field() {
    let dir = Scratch::new("options");
    let input = ppm(&dir, 300, 200);
    let parts = cli_shards(&dir, input.to_str().unwrap(), "png");
    let out = dir.path("m.vtpk");
    let all = |field: &str, value: u64| {
        for part in &parts {
            edit_manifest(part, |m| m["options"][field] = value.into());
        }
    };
    // 0 and 1 made a worker panic reading the sums, 2^32 - 1 an abort; 16 is what a deeper
    // pyramid or another filter stores, not this one.
    for bytes in [0, 1, 16, u32::MAX as u64] {
        all("sumBytes", bytes);
        merge_fails(&parts, &out, &["part-0.vtpk", "options.sumBytes", &format!("is {bytes},"), "8"]);
    }
    all("sumBytes", 8);
    all("payloadAlignment", 1 << 31);
    merge_fails(&parts, &out, &["part-0.vtpk", "options.payloadAlignment", "1.0 MiB"]);
    all("payloadAlignment", 12);
    merge_fails(&parts, &out, &["options.payloadAlignment", "is 12,"]);
    all("payloadAlignment", 8);
    ok(&[&["merge", "-q", "-o", out.to_str().unwrap()], &parts.iter().map(String::as_str).collect::<Vec<_>>()[..]]
        .concat());
}

#[test]
fn forged_root_sums_out_of_range_are_refused_naming_the_shard() {
    use base64::Engine;
    let b64 = base64::engine::general_purpose::STANDARD;
    let dir = Scratch::new("sums");
    let input = ppm(&dir, 300, 200);
    let parts = cli_shards(&dir, input.to_str().unwrap(), "png");
    let out = dir.path("m.vtpk");
    // Every byte of shard 1's sums 0xFF: as many bytes as it holds, so every row reads whole.
    edit_manifest(&parts[1], |m| {
        for root in m["roots"].as_array_mut().unwrap() {
            let sums = zstd::decode_all(&b64.decode(root["sums"].as_str().unwrap()).unwrap()[..]).unwrap();
            let forged = zstd::encode_all(&vec![0xFFu8; sums.len()][..], 3).unwrap();
            root["sums"] = b64.encode(forged).into();
        }
    });
    merge_fails(
        &parts,
        &out,
        &["part-1.vtpk", "root sums are out of range", "LOD 1", "for each of the 4 source pixels"],
    );
}

#[test]
fn a_flipped_index_byte_in_a_shard_is_refused_naming_it() {
    use vortex_pack::{Pack, TileKind};
    let dir = Scratch::new("index");
    let input = ppm(&dir, 300, 200);
    let parts = cli_shards(&dir, input.to_str().unwrap(), "jpeg");
    let out = dir.path("m.vtpk");
    // A JPEG page's kind turned to constant: it reads as a valid constant page, and only the
    // index checksum tells.
    let mut bytes = std::fs::read(&parts[2]).unwrap();
    let kind_at = {
        let p = Pack::open(&parts[2]).unwrap();
        let position = (0..p.header().index_count).find(|&i| p.entry(i).kind == TileKind::Jpeg as u8).unwrap();
        (p.header().index_offset + position * vortex_pack::format::ENTRY_LEN as u64 + 16) as usize
    };
    bytes[kind_at] = TileKind::Constant as u8;
    std::fs::write(&parts[2], bytes).unwrap();
    merge_fails(&parts, &out, &["part-2.vtpk", "index", "checksum mismatch"]);
}

#[test]
fn shards_of_one_input_spelled_two_ways_merge() {
    let dir = Scratch::new("spelling");
    let input = ppm(&dir, 300, 200);
    let plain = input.to_str().unwrap();
    let dotted = dir.0.join(".").join("in.ppm");
    let part = dir.path("part-{shard}.vtpk").to_string_lossy().into_owned();
    for (i, spelled) in [plain, dotted.to_str().unwrap(), plain].into_iter().enumerate() {
        ok(&["split", spelled, "--pack", &part, "--shard", &format!("{i}/3"), "--tile-size", "64", "-q"]);
    }
    let whole = dir.path("whole.vtpk");
    ok(&["split", plain, "--pack", whole.to_str().unwrap(), "--tile-size", "64", "-q"]);
    let parts: Vec<String> =
        (0..3).map(|i| dir.path(&format!("part-{i}.vtpk")).to_string_lossy().into_owned()).collect();
    let merged = dir.path("merged.vtpk");
    ok(&[&["merge", "-q", "-o", merged.to_str().unwrap()], &parts.iter().map(String::as_str).collect::<Vec<_>>()[..]]
        .concat());
    assert!(std::fs::read(&whole).unwrap() == std::fs::read(&merged).unwrap());
}

#[test]
fn tile_alignment_is_capped_at_one_mebibyte() {
    let dir = Scratch::new("align");
    let input = ppm(&dir, 100, 80);
    let input = input.to_str().unwrap();
    let pack = dir.path("p.vtpk");
    let pack = pack.to_str().unwrap();
    for command in [&["split", input, "--pack", pack][..], &["split", input, "--pack", pack, "--shard", "0/2"]] {
        let e = fails(&[command, &["--tile-align", "2M"]].concat());
        assert!(e.contains("--tile-align 2097152") && e.contains("1.0 MiB"), "{e}");
    }
    let tiles = dir.path("tiles");
    ok(&["split", input, "-o", tiles.to_str().unwrap(), "-q"]);
    let e = fails(&["pack", tiles.to_str().unwrap(), "-o", pack, "--tile-align", "2G"]);
    assert!(e.contains("--tile-align") && e.contains("1.0 MiB"), "{e}");
    assert!(!Path::new(pack).exists());
    ok(&["split", input, "--pack", pack, "--tile-align", "1M", "-q"]);
}
