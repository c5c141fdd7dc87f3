//! `web/vtpk/vtpk.js` in Node, without a browser: what it refuses in a pack (what `verify` and
//! `vortex_pack`'s reader refuse, among the bytes it reads) and what it does with servers that
//! misbehave (replies longer than asked, compressed, endless, cut short, or none at all). Each
//! failure must be a `VtpkError` whose `kind` says what the caller can do and whose message names
//! the URL and what is wrong. The browser side (Chromium and nginx) is `static_web.rs`.
//!
//! Needs `node` (Debian's nodejs, which `.ci/run` installs with npm); outside CI a missing one
//! skips with a note, under `CI=true` it fails.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::common::cli::{ok, s};
use crate::common::skip_unless_ci;

fn node(test: &str) -> Option<PathBuf> {
    let found = ["/usr/bin/node", "/usr/local/bin/node"].iter().map(PathBuf::from).find(|p| p.is_file());
    if found.is_none() {
        skip_unless_ci(test, "no node (apt-get install nodejs)");
    }
    found
}

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// A 300x200 gradient split into a pack in `dir` with `args`.
fn pack(dir: &Path, name: &str, args: &[&str]) -> (PathBuf, Vec<u8>) {
    let input = dir.join("photo.png");
    if !input.exists() {
        image::RgbImage::from_fn(300, 200, |x, y| image::Rgb([x as u8, y as u8, (x ^ y) as u8])).save(&input).unwrap();
    }
    let path = dir.join(name);
    ok(&[&["split", s(&input), "--pack", s(&path), "-q"], args].concat());
    let bytes = std::fs::read(&path).unwrap();
    (path, bytes)
}

/// Forges packs as a buggy writer would: fields changed and every checksum over them made
/// valid again, so that only the check of the field itself can catch them.
struct Forge {
    bytes: Vec<u8>,
    header: vortex_pack::Header,
}

impl Forge {
    fn new(path: &Path, bytes: &[u8]) -> Forge {
        Forge { bytes: bytes.to_vec(), header: *vortex_pack::Pack::open(path).unwrap().header() }
    }

    /// Header bytes at `at` set to `value`, the header CRC made valid.
    fn header(&self, at: usize, value: &[u8]) -> Vec<u8> {
        let mut b = self.bytes.clone();
        b[at..at + value.len()].copy_from_slice(value);
        seal_header(&mut b);
        b
    }

    /// Bytes `at` of index entry `position` set to `value`; the index CRC, the content hash and
    /// the header CRC made valid.
    fn entry(&self, position: u64, at: usize, value: &[u8]) -> Vec<u8> {
        let h = &self.header;
        let mut b = self.bytes.clone();
        let start = (h.index_offset + 24 * position) as usize + at;
        b[start..start + value.len()].copy_from_slice(value);
        let index = h.index_offset as usize..(h.index_offset + 24 * h.index_count) as usize;
        let crc = crc32c::crc32c(&b[h.levels_offset as usize..index.end]);
        b[108..112].copy_from_slice(&crc.to_le_bytes());
        let meta = &b[h.meta_offset as usize..][..h.meta_len as usize];
        // FNV-1a 64 over the metadata, then the index (docs/pack-format.md, content_hash).
        let fnv = |h: u64, bytes: &[u8]| bytes.iter().fold(h, |h, v| (h ^ u64::from(*v)).wrapping_mul(0x100_0000_01b3));
        let hash = fnv(fnv(0xcbf2_9ce4_8422_2325, meta), &b[index]);
        b[40..48].copy_from_slice(&hash.to_le_bytes());
        seal_header(&mut b);
        b
    }

    /// Byte `at` of the file with one bit flipped (bit rot: no checksum fixed).
    fn flipped(&self, at: usize) -> Vec<u8> {
        let mut b = self.bytes.clone();
        b[at] ^= 0x01;
        b
    }
}

fn seal_header(b: &mut [u8]) {
    let crc = crc32c::crc32c(&b[..188]);
    b[188..192].copy_from_slice(&crc.to_le_bytes());
}

/// One pack shown to vtpk.js: what is expected (`OK`, or the error's kind and a part of its
/// message) and how it is read.
struct Case {
    name: &'static str,
    bytes: Vec<u8>,
    kind: &'static str,
    expected: &'static str,
    read: Read,
}

#[derive(Clone, Copy)]
enum Read {
    /// Open with the index read whole, then tile (0, 0, 0)'s entry and payload.
    Whole,
    /// Open with the index read in blocks, ask for every tile's entry (their failures ignored),
    /// then tile (0, 0, 0)'s entry and payload again: the index is whole by then.
    Blocks,
    /// As `Whole`, from a host that ignores `Range`.
    NoRanges,
    /// As `Whole`, from another origin that does not expose `Content-Range`.
    HiddenRange,
}

fn case(name: &'static str, bytes: Vec<u8>, kind: &'static str, expected: &'static str) -> Case {
    Case { name, bytes, kind, expected, read: Read::Whole }
}

/// The JS reader's checks, run in Node with a `fetch` that answers `Range` requests from a file
/// as a static host would: each damaged or forged pack is refused with the error kind and a
/// message naming what is wrong. The forged ones (checksums made valid again) are what `verify`
/// refuses beyond the checksums: a content hash that is not the index's, a payload off its
/// alignment, a raw tile of the wrong length, a kind-8 or kind-9 entry without its feature bit. An index
/// read in blocks that fails its CRC once whole fails every later read, as in the Rust reader of
/// remote packs, not only the `onError` callback.
#[test]
fn vtpk_js_refuses_what_verify_refuses() {
    let Some(node) = node("the vtpk.js pack test") else { return };
    let dir = tempfile::tempdir().unwrap();
    let (good_path, bytes) = pack(dir.path(), "good.vtpk", &["--tile-size", "64"]);
    let good = Forge::new(&good_path, &bytes);
    let (many_path, many_bytes) = pack(dir.path(), "many.vtpk", &["--tile-size", "32"]);
    let many = Forge::new(&many_path, &many_bytes);
    assert!(many.header.index_count > 64, "the index must span more than one block of 64 entries");
    let (raw_path, raw_bytes) = pack(dir.path(), "raw.vtpk", &["--tile-size", "64", "--codec", "raw"]);
    let raw = Forge::new(&raw_path, &raw_bytes);
    let h = good.header;
    let first = vortex_pack::Pack::open(&good_path).unwrap().entry(0);
    assert_eq!(first.kind, 5, "tile (0, 0, 0) must be a JPEG tile");
    let raw_first = vortex_pack::Pack::open(&raw_path).unwrap().entry(0);
    assert_eq!(raw_first.kind, 2, "tile (0, 0, 0) of the raw pack must be raw");

    let mut zeroed = bytes.clone();
    zeroed[..192].fill(0);
    let mut extended = bytes.clone();
    extended.extend_from_slice(&[0; 16]);
    let cases = vec![
        case("good", bytes.clone(), "OK", ""),
        Case { read: Read::Blocks, ..case("good, index in blocks", many_bytes.clone(), "OK", "") },
        case("good raw", raw_bytes.clone(), "OK", ""),
        case("truncated", bytes[..bytes.len() - 1].to_vec(), "corrupt", "truncated or extended"),
        case("extended", extended, "corrupt", "truncated or extended"),
        case("unfinished", zeroed, "corrupt", "unfinished pack"),
        case("not a pack", b"GIF89a, not a pack at all".to_vec(), "corrupt", "no pack signature"),
        case("short", bytes[..100].to_vec(), "corrupt", "shorter than a pack header"),
        case("header bit", good.flipped(50), "corrupt", "header's CRC-32C does not match"),
        case("major 2", good.header(8, &2u16.to_le_bytes()), "unsupported", "major version 2"),
        case("unknown feature", good.header(16, &8u64.to_le_bytes()), "unsupported", "required features"),
        // Node decodes no images: a JPEG XL pack is refused as in a browser without JPEG XL.
        case("jxl where none decodes", good.header(16, &4u64.to_le_bytes()), "unsupported", "does not decode"),
        case("32-bit samples", good.header(69, &[4]), "corrupt", "without required-feature bit 0x2"),
        case("wide samples", good.header(16, &2u64.to_le_bytes()), "unsupported", "8- and 16-bit"),
        case("huge tile", good.header(56, &65536u32.to_le_bytes()), "unsupported", "tile_size 65536"),
        case("border too wide", good.header(60, &32u32.to_le_bytes()), "corrupt", "border 32"),
        case("too many tiles", good.header(96, &(1u64 << 40).to_le_bytes()), "unsupported", "over the cap"),
        case("index elsewhere", good.header(88, &(h.index_offset + 8).to_le_bytes()), "corrupt", "index_offset"),
        case("metadata past its section", good.header(120, &u32::MAX.to_le_bytes()), "corrupt", "data_offset"),
        case("metadata bit", good.flipped(h.meta_offset as usize), "corrupt", "metadata's CRC-32C"),
        case("index bit", good.flipped(h.index_offset as usize + 3), "corrupt", "index is damaged"),
        case("level table bit", good.flipped(192 + 16), "corrupt", "level 0"),
        case("content hash", good.header(40, &(h.content_hash ^ 1).to_le_bytes()), "corrupt", "content hash"),
        case(
            "misaligned payload",
            good.entry(0, 0, &(first.offset_or_value + 1).to_le_bytes()),
            "corrupt",
            "not aligned to 8 bytes",
        ),
        case("raw tile length", raw.entry(0, 8, &(raw_first.len - 8).to_le_bytes()), "corrupt", "a raw tile of"),
        case("zstd-delta without its bit", good.entry(0, 16, &[8]), "corrupt", "without required-feature bit 0x1"),
        case("jxl without its bit", good.entry(0, 16, &[9]), "corrupt", "without required-feature bit 0x4"),
        Case {
            read: Read::Blocks,
            // Entry 70's offset, far from tile (0, 0, 0)'s block; no checksum fixed.
            ..case(
                "index bit, in blocks",
                many.flipped(many.header.index_offset as usize + 70 * 24 + 5),
                "corrupt",
                "index is damaged",
            )
        },
        Case { read: Read::NoRanges, ..case("no ranges", bytes.clone(), "host", "ignored the Range header") },
        Case {
            read: Read::HiddenRange,
            ..case("hidden range", bytes.clone(), "host", "Access-Control-Expose-Headers")
        },
    ];
    // The raw pack's tile (0, 0, 0) must really be the raw pack's first entry of payload.
    assert!(raw_first.len > 8);

    let mut list = Vec::new();
    for (i, c) in cases.iter().enumerate() {
        let path = dir.path().join(format!("case{i}.vtpk"));
        std::fs::write(&path, &c.bytes).unwrap();
        let read = match c.read {
            Read::Whole => "whole",
            Read::Blocks => "blocks",
            Read::NoRanges => "no ranges",
            Read::HiddenRange => "hidden range",
        };
        list.push(serde_json::json!({ "name": c.name, "path": path, "read": read }));
    }
    let module = repo("web/vtpk/vtpk.js");
    // The fake host: 206 with Content-Range for a range (hidden from the page for one case),
    // the whole file with 200 when it ignores ranges, 416 past the end.
    let script = format!(
        r#"import {{ readFileSync }} from "node:fs";
import {{ VtpkPack }} from {module:?};
const out = [];
for (const c of {cases}) {{
  const file = readFileSync(c.path);
  const fetch = async (url, init) => {{
    const [, a, b] = /bytes=(\d+)-(\d+)/.exec(init.headers.Range).map(Number);
    if (c.read === "no ranges") return new Response(file, {{ status: 200 }});
    if (a >= file.length) return new Response("", {{ status: 416 }});
    const end = Math.min(b + 1, file.length);
    return new Response(file.subarray(a, end), {{ status: 206,
      headers: c.read === "hidden range" ? {{}} : {{ "Content-Range": `bytes ${{a}}-${{end - 1}}/${{file.length}}` }} }});
  }};
  const onError = () => {{}};
  try {{
    const blocks = c.read === "blocks";
    const pack = await VtpkPack.open("http://host/" + c.name + ".vtpk", {{ fetch, onError, wholeIndexUpTo: blocks ? 0 : 1 << 20 }});
    if (blocks) {{
      const all = [];
      pack.levels.forEach((l, lod) => {{
        for (let y = 0; y < l.tilesH; y++) for (let x = 0; x < l.tilesW; x++) all.push(pack.entry(lod, x, y).catch(() => {{}}));
      }});
      await Promise.all(all);
      if (pack.indexChecked === null) throw new Error("the index was not checked once every block was in");
    }}
    const entry = await pack.entry(0, 0, 0);
    if (entry.len) await pack.payload(entry, "tile (0, 0, 0)");
    out.push([c.name, "OK", ""]);
  }} catch (e) {{
    out.push([c.name, e.name === "VtpkError" ? String(e.kind) : `${{e.name}} (not a VtpkError)`, String(e.message)]);
  }}
}}
console.log(JSON.stringify(out));
"#,
        module = module.display().to_string(),
        cases = serde_json::Value::Array(list),
    );
    let run = Command::new(node).args(["--input-type=module", "-e", &script]).output().unwrap();
    assert!(run.status.success(), "node: {}", String::from_utf8_lossy(&run.stderr));
    let results: Vec<(String, String, String)> = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(results.len(), cases.len());
    let mut wrong = Vec::new();
    for (c, (name, kind, message)) in cases.iter().zip(&results) {
        eprintln!("{name}: {kind}: {message}");
        if kind != c.kind || !message.contains(c.expected) {
            wrong.push(format!("{name}: expected {}: \"{}\", got {kind}: {message}", c.kind, c.expected));
        }
    }
    assert!(wrong.is_empty(), "refused wrongly or not at all:\n{}", wrong.join("\n"));
}

/// What one run of `tests/vtpk/hostile_hosts.mjs` gave.
struct Outcome {
    kind: String,
    message: String,
    /// Body bytes the server wrote before the client hung up.
    served: u64,
    /// Node's peak resident memory.
    max_rss_kib: u64,
    seen: Value,
}

/// Runs one case of the hostile-host script in a Node of 64 MiB of heap. A run still going after
/// `GUARD` is killed and fails the test: a reader without a deadline waits forever on a silent
/// server, and the test must say so rather than hang.
fn hostile(node: &Path, case: &str, pack: Option<&Path>) -> Outcome {
    const GUARD: Duration = Duration::from_secs(180);
    let mut command = Command::new(node);
    command.arg("--max-old-space-size=64").arg(repo("tests/vtpk/hostile_hosts.mjs")).arg(case);
    if let Some(pack) = pack {
        command.arg(pack);
    }
    let mut child = command.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let started = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > GUARD {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("{case}: vtpk.js did not give up within {GUARD:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{case}: node: {}", String::from_utf8_lossy(&out.stderr));
    let line: Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{case}: {e}: {}", String::from_utf8_lossy(&out.stdout)));
    Outcome {
        kind: line["kind"].as_str().unwrap_or("(no kind)").to_string(),
        message: line["message"].as_str().unwrap_or_default().to_string(),
        served: line["served"].as_u64().unwrap(),
        max_rss_kib: line["maxRssKiB"].as_u64().unwrap(),
        seen: line["seen"].clone(),
    }
}

/// Servers on 127.0.0.1 that answer a correct `206` head and then an endless body, a gzip bomb
/// (1 KiB per MiB it inflates to, with its `Content-Encoding` shown and hidden as from another
/// origin), a `Content-Length` of 1 GiB for 512 bytes, nothing at all, a trickle, a body cut
/// short, a refused connection, 503 and 404. vtpk.js must stop at the bytes it asked for: each
/// pouring server offers 256 MiB, and Node's peak memory (VmHWM) must stay under 160 MiB (the
/// script alone is about 55 MiB, the cases 54 to 66 MiB; the old reader, which read whole
/// bodies, peaked at 821 to 845 MiB, 3,147 MiB on the 1 GiB Content-Length), with the pouring
/// stopped well short of the 256 MiB. A silent or trickling server is given up on at the
/// request deadline (`timeout`, 1 s here). Each failure has the kind that says what to do.
#[test]
fn vtpk_js_stops_at_the_bytes_asked_from_hostile_hosts() {
    let Some(node) = node("the vtpk.js hostile-host test") else { return };
    const POURED: u64 = 256 << 20;
    const MOST_RSS_KIB: u64 = 160 << 10;
    let cases: [(&str, &str, &str); 10] = [
        ("endless body", "host", "runs past the 512 bytes asked"),
        ("gzip bomb", "host", "Content-Encoding: gzip"),
        ("gzip bomb, encoding hidden", "host", "runs past the 512 bytes asked"),
        ("oversize Content-Length", "host", "a reply of 1073741824 bytes (Content-Length) for 512 bytes asked"),
        ("silent", "io", "no complete reply within 1000 ms"),
        ("trickle", "io", "no complete reply within 1000 ms"),
        ("cut short", "io", "broke off after 100 of 512 bytes"),
        ("refused", "io", "ECONNREFUSED"),
        ("503", "io", "HTTP 503"),
        ("404", "unavailable", "HTTP 404"),
    ];
    let mut wrong = Vec::new();
    for (case, kind, expected) in cases {
        let o = hostile(&node, case, None);
        eprintln!("{case}: {}: {} ({} bytes served, peak {} KiB)", o.kind, o.message, o.served, o.max_rss_kib);
        if o.kind != kind || !o.message.contains(expected) {
            wrong.push(format!("{case}: expected {kind}: \"{expected}\", got {}: {}", o.kind, o.message));
        }
        if o.max_rss_kib > MOST_RSS_KIB || o.served >= POURED / 4 {
            wrong.push(format!(
                "{case}: {} bytes served, peak {} KiB: the reply was read past the bytes asked",
                o.served, o.max_rss_kib
            ));
        }
    }
    // The same machinery with a plain static host: the pack opens and a tile reads, and Node's
    // fetch sent `Accept-Encoding: identity` with each `Range` (the Fetch standard's rule, which
    // Chromium follows too: docs/web.md).
    let dir = tempfile::tempdir().unwrap();
    let (path, _) = pack(dir.path(), "good.vtpk", &["--tile-size", "64"]);
    let o = hostile(&node, "good", Some(&path));
    assert_eq!((o.kind.as_str(), o.message.as_str()), ("OK", ""), "a good pack from a good host");
    let seen = o.seen.as_array().unwrap();
    assert!(!seen.is_empty() && seen.iter().all(|r| r["accept-encoding"] == "identity"), "{seen:?}");
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
