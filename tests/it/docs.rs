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
    let line = readme.lines().find(|l| l.starts_with("cargo run --release -- split")).expect("quick-start line");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let args: Vec<&str> = line.split('#').next().unwrap().split_whitespace().skip(4).collect();
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
