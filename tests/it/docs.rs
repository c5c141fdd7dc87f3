//! The specs in docs/ hold examples that must match the tool's real behaviour.

use std::process::Command;

fn between<'a>(text: &'a str, begin: &str, end: &str) -> &'a str {
    let start = text.find(begin).expect("begin marker") + begin.len();
    let stop = text[start..].find(end).expect("end marker") + start;
    &text[start..stop]
}

#[test]
fn info_json_example_is_what_split_writes() {
    let root = env!("CARGO_MANIFEST_DIR");
    let doc = std::fs::read_to_string(format!("{root}/docs/info-json.md")).unwrap();
    let block = between(&doc, "<!-- example:begin -->", "<!-- example:end -->");
    let json = between(block, "```json", "```");
    let documented: serde_json::Value = serde_json::from_str(json).unwrap();

    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let status = Command::new(env!("CARGO_BIN_EXE_vortex-tiler"))
        .args(["split", &format!("{root}/fixtures/sample.png"), "-o", out.to_str().unwrap()])
        .args(["--tile-size", "128", "--border", "4", "-q"])
        .status()
        .unwrap();
    assert!(status.success());
    let written = std::fs::read_to_string(out.join("info.json")).unwrap();
    assert_eq!(written.trim(), json.trim(), "docs/info-json.md's example differs from the real output");
    assert_eq!(serde_json::from_str::<serde_json::Value>(&written).unwrap(), documented);
}

#[test]
fn readme_quick_start_runs() {
    // The README's first command, run from the repository root into a temporary directory.
    let root = env!("CARGO_MANIFEST_DIR");
    let readme = std::fs::read_to_string(format!("{root}/README.md")).unwrap();
    let line = readme.lines().find(|l| l.starts_with("cargo run -- split")).expect("quick-start line");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let args: Vec<&str> = line.split('#').next().unwrap().split_whitespace().skip(3).collect();
    let args: Vec<&str> = args.into_iter().map(|a| if a == "out/" { out.to_str().unwrap() } else { a }).collect();
    let r = Command::new(env!("CARGO_BIN_EXE_vortex-tiler")).current_dir(root).args(&args).output().unwrap();
    assert!(r.status.success(), "{args:?}: {}", String::from_utf8_lossy(&r.stderr));
    assert!(out.join("info.json").is_file());
}

#[test]
fn viewers_iiif_example_names_are_what_split_writes() {
    let root = env!("CARGO_MANIFEST_DIR");
    let doc = std::fs::read_to_string(format!("{root}/docs/viewers.md")).unwrap();
    let block = between(&doc, "<!-- iiif-example:begin", "<!-- iiif-example:end -->");
    let names: Vec<&str> =
        between(block, "```text", "```").lines().filter_map(|l| l.split_whitespace().next()).collect();
    assert_eq!(names.len(), 4, "{block}");
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("img.png");
    image::RgbImage::from_fn(3000, 1100, |x, y| image::Rgb([x as u8, y as u8, 7])).save(&input).unwrap();
    let out = dir.path().join("iiif");
    let status = Command::new(env!("CARGO_BIN_EXE_vortex-tiler"))
        .args(["split", input.to_str().unwrap(), "--layout", "iiif", "--tile-size", "256", "-q", "-o"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    for name in names {
        assert!(out.join(name).is_file(), "docs/viewers.md names {name}, which split does not write");
    }
}

#[test]
fn scale_out_try_it_loop_merges_the_one_machine_pack() {
    // docs/scale-out.md's one-machine loop, run as it is by bash in a temporary directory
    // holding the image it names, with the built binary first on PATH.
    let root = env!("CARGO_MANIFEST_DIR");
    let doc = std::fs::read_to_string(format!("{root}/docs/scale-out.md")).unwrap();
    let script = between(between(&doc, "<!-- try-it:begin -->", "<!-- try-it:end -->"), "```sh", "```");
    assert!(script.contains("--shard $i/4") && script.contains("vortex-tiler merge"), "{script}");
    let cmp = script.lines().find(|l| l.trim_start().starts_with("cmp ")).expect("a cmp line");
    let input = script.split_whitespace().skip_while(|w| *w != "split").nth(1).expect("split INPUT");

    let dir = tempfile::tempdir().unwrap();
    // 1000x700: 9 x 6 pages of 120 texels at LOD 0 (--tile-size 128 --border 4), 5 LODs.
    image::RgbImage::from_fn(1000, 700, |x, y| image::Rgb([(x / 3) as u8, (y * 7 / 19) as u8, ((x ^ y) % 251) as u8]))
        .save(dir.path().join(input))
        .unwrap();
    let bin_dir = std::path::Path::new(env!("CARGO_BIN_EXE_vortex-tiler")).parent().unwrap();
    let path = format!("{}:{}", bin_dir.display(), std::env::var("PATH").unwrap_or_default());
    let out = Command::new("bash")
        .args(["-euo", "pipefail", "-c", script])
        .current_dir(dir.path())
        .env("PATH", path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "docs/scale-out.md's try-it loop failed ({cmp}):\n{script}\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let files: Vec<&str> = cmp.split_whitespace().skip(1).take(2).collect();
    let read = |name: &str| std::fs::read(dir.path().join(name)).unwrap();
    assert!(read(files[0]) == read(files[1]), "{cmp}: the files differ");
    let shards = std::fs::read_dir(dir.path().join("parts")).unwrap().count();
    assert_eq!(shards, 4, "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("shard 3 of 4"), "{}", String::from_utf8_lossy(&out.stderr));
}

/// libvips 8.15 and later write JPEG tiles in "direct mode" only when dzsave gets the quality as
/// `Q=`; a quality inside `suffix` (".jpg[Q=85]") takes a generic path at less than half the
/// speed, which made every ratio against libvips 8.18 in docs/benchmarks.md too flattering until
/// issue 28. Debian's vips 8.14 has no `Q` and no direct mode, so its command lines keep `--suffix`.
#[test]
fn bench_scripts_run_libvips_at_its_best() {
    let root = env!("CARGO_MANIFEST_DIR");
    let mut calls = 0;
    for entry in std::fs::read_dir(format!("{root}/bench")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "sh") {
            continue;
        }
        let script = std::fs::read_to_string(&path).unwrap();
        for (n, line) in
            script.lines().enumerate().filter(|(_, l)| l.contains(".dzsave(") && !l.trim_start().starts_with('#'))
        {
            calls += 1;
            let handicapped =
                line.split("suffix=").skip(1).any(|arg| arg.split([',', ')']).next().unwrap().contains("[Q="));
            assert!(!handicapped, "{}:{}: pass the JPEG quality as Q=, not in suffix: {line}", path.display(), n + 1);
        }
    }
    assert!(calls >= 3, "found only {calls} pyvips dzsave calls in bench/*.sh");
}
