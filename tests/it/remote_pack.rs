//! Packs read over HTTP (`render --pack http://...`, `vortex_vt_wgpu::source::HttpPack`): from a
//! plain static server (nginx, started by the test) they give the very frames the local file
//! gives; from a server of the test's own that misbehaves (drops connections, sends wrong bytes,
//! ignores `Range`, holds replies back) the run survives, retries, reports what happened in its
//! JSON, draws no corrupt byte, and never holds a real-time frame for a read. Outside CI a
//! missing nginx or GPU skips with a note; under `CI=true` it fails.

use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use vortex_pack::{Pack, Tile};
use vortex_vt::page::PageId;
use vortex_vt_wgpu::loader::{LoadError, Loader, RetryPolicy};
use vortex_vt_wgpu::source::{HttpOptions, HttpPack};
use vortex_vt_wgpu::{CacheFormat, PageSource, ReadErrorKind, StoredTile, TileKind};

use crate::common::cli::{fails_with, fixture, run, s};
use crate::common::nginx::{Nginx, nginx_binary};
use crate::common::skip_unless_ci;
use crate::render::{no_gpu, report, sample_pack};

/// nginx serving `dir`, or `None` (with a note; a failure under CI) when it is not installed.
fn nginx(dir: &Path, test: &str) -> Option<Nginx> {
    match nginx_binary() {
        Ok(binary) => Some(Nginx::start(&binary, dir, &[])),
        Err(why) => {
            skip_unless_ci(test, &why);
            None
        }
    }
}

/// Renders `pack` (a path or URL) offline into `dir/NAME` frames and `dir/NAME.json`; `None`
/// without a GPU.
fn render(pack: &str, dir: &Path, name: &str, extra: &[&str]) -> Option<(PathBuf, serde_json::Value)> {
    let (frames, json) = (dir.join(name), dir.join(format!("{name}.json")));
    let args = ["render", "--pack", pack, "--size", "128x96", "--frames", s(&frames), "--report", s(&json), "-q"];
    let out = run(&[&args[..], extra].concat());
    if no_gpu(&out) {
        return None;
    }
    assert!(out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stderr));
    Some((frames, report(&json)))
}

/// Every frame of `a` is byte for byte the frame of the same name in `b`.
fn same_frames(a: &Path, b: &Path) {
    let mut names: Vec<_> = std::fs::read_dir(a).unwrap().map(|e| e.unwrap().file_name()).collect();
    names.sort();
    assert!(!names.is_empty());
    for name in names {
        let (x, y) = (std::fs::read(a.join(&name)).unwrap(), std::fs::read(b.join(&name)).unwrap());
        assert!(x == y, "{} differs between {} and {}", name.to_string_lossy(), a.display(), b.display());
    }
}

#[test]
fn a_pack_on_nginx_renders_the_frames_of_the_local_file() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let Some(server) = nginx(dir.path(), "a_pack_on_nginx_renders_the_frames_of_the_local_file") else { return };
    let url = format!("{}/sample.vtpk", server.url());
    // RGBA8 and the automatic cache format (BC1 here, transcoded on the loader's threads): the
    // same pages through the same GPU path, so the same bytes, no tolerance.
    for format in ["rgba8", "auto"] {
        let extra = ["--cache-format", format, "--threads", "4"];
        let Some((local, _)) = render(s(&pack), dir.path(), &format!("local-{format}"), &extra) else { return };
        server.clear_requests();
        let (remote, r) = render(&url, dir.path(), &format!("remote-{format}"), &extra).unwrap();
        same_frames(&local, &remote);
        let requests = server.requests();
        let counted = &r["remote"];
        assert_eq!(counted["requests"].as_u64().unwrap(), requests.len() as u64, "{requests:?}");
        assert!(requests.iter().all(|(status, _, _, range)| *status == 206 && range.starts_with("bytes=")));
        let served: u64 = requests.iter().map(|r| r.1).sum();
        assert_eq!(counted["bytes"].as_u64().unwrap(), served);
        assert_eq!((counted["retries"].as_u64(), counted["corrupt"].as_u64()), (Some(0), Some(0)));
        // Only what the view needed: less than the file.
        assert!(served < std::fs::metadata(&pack).unwrap().len(), "{served}");
    }
}

#[test]
fn view_of_a_pack_on_nginx_shows_the_local_files_picture() {
    let Some(x) = crate::view::Xvfb::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let Some(server) = nginx(dir.path(), "view_of_a_pack_on_nginx_shows_the_local_files_picture") else { return };
    let url = format!("{}/sample.vtpk", server.url());
    let mut shots = Vec::new();
    for (name, pack) in [("local", s(&pack)), ("remote", &url)] {
        let shot = dir.path().join(format!("{name}.png"));
        let args =
            [pack, "--size", "320x240", "--screenshot", s(&shot), "--frame-count", "12", "--cache-format", "rgba8"];
        let out = x.view(&args);
        assert!(out.status.success(), "view {name}: {}", String::from_utf8_lossy(&out.stderr));
        shots.push(std::fs::read(&shot).unwrap());
    }
    // The same pages in the same window path: the same PNG.
    assert!(shots[0] == shots[1], "the remote pack's window differs from the local file's");
    assert!(server.requests().iter().all(|r| r.0 == 206), "{:?}", server.requests());
}

/// What the test server does with one request.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Act {
    Serve,
    /// Close the connection without a reply.
    Drop,
    /// Reply 200 with the whole file, as a server that ignores `Range` does.
    Whole,
    /// Reply 206 with the range asked for, every byte inverted.
    Garble,
    /// Reply only once `release` says so.
    Hold,
    /// Reply 206 with the range asked for, one byte of it every 200 ms (until the client hangs
    /// up): a request that never ends on its own, whose connection is never idle.
    Trickle,
    /// Reply 302 to this `Location`.
    Redirect(&'static str),
}

/// A server of the test's own over one file: HTTP/1.1, one request per connection, each
/// answered as `act(request number, start, end)` says.
struct Misbehaving {
    port: u16,
    requests: Arc<AtomicUsize>,
}

type Decide = dyn Fn(usize, u64, u64) -> Act + Send + Sync;

impl Misbehaving {
    fn start(file: &Path, act: Arc<Decide>, release: Arc<dyn Fn() -> bool + Send + Sync>) -> Misbehaving {
        let bytes: Arc<[u8]> = std::fs::read(file).unwrap().into();
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let requests = Arc::new(AtomicUsize::new(0));
        let count = Arc::clone(&requests);
        std::thread::spawn(move || {
            for stream in listener.incoming() {
                let Ok(stream) = stream else { continue };
                let n = count.fetch_add(1, Ordering::Relaxed);
                let (bytes, act, release) = (Arc::clone(&bytes), Arc::clone(&act), Arc::clone(&release));
                std::thread::spawn(move || answer(stream, n, &bytes, &*act, &*release));
            }
        });
        Misbehaving { port, requests }
    }

    fn url(&self) -> String {
        format!("http://127.0.0.1:{}/sample.vtpk", self.port)
    }
}

fn answer(mut stream: TcpStream, n: usize, file: &[u8], act: &Decide, release: &dyn Fn() -> bool) {
    let mut range = None;
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let mut line = String::new();
    while reader.read_line(&mut line).is_ok_and(|read| read > 0) && line != "\r\n" {
        if let Some(v) = line.to_ascii_lowercase().strip_prefix("range: bytes=") {
            let (a, b) = v.trim().split_once('-').unwrap();
            range = Some((a.parse::<u64>().unwrap(), b.parse::<u64>().unwrap() + 1));
        }
        line.clear();
    }
    let len = file.len() as u64;
    let (start, end) = range.map_or((0, len), |(a, b)| (a, b.min(len)));
    let act = act(n, start, end);
    if act == Act::Hold {
        // The condition is another process's sign (the render child's report file written): no
        // event here to wait on (holding until the client hangs up would hold its loader's
        // threads, which it joins before it exits). Polled a bounded number of times; nothing is
        // asserted about when, and a reply past the bound is one the test's checks then see.
        for _ in 0..12_000 {
            if release() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    }
    let mut reply = |status: &str, headers: String, body: &[u8]| {
        let head = format!("HTTP/1.1 {status}\r\nContent-Length: {}\r\nConnection: close\r\n{headers}\r\n", body.len());
        let _ = stream.write_all(head.as_bytes()).and_then(|()| stream.write_all(body));
    };
    match act {
        Act::Drop => {}
        Act::Whole => reply("200 OK", String::new(), file),
        Act::Redirect(to) => reply("302 Found", format!("Location: {to}\r\n"), b""),
        Act::Trickle => {
            let head = format!(
                "HTTP/1.1 206 Partial Content\r\nContent-Length: {}\r\nContent-Range: bytes {start}-{}/{len}\r\nConnection: close\r\n\r\n",
                end - start,
                end - 1
            );
            if stream.write_all(head.as_bytes()).is_err() {
                return;
            }
            for byte in &file[start as usize..end as usize] {
                std::thread::sleep(Duration::from_millis(200));
                if stream.write_all(&[*byte]).is_err() {
                    return;
                }
            }
        }
        Act::Serve | Act::Hold | Act::Garble => {
            let mut body = file[start as usize..end as usize].to_vec();
            if act == Act::Garble {
                body.iter_mut().for_each(|b| *b = !*b);
            }
            reply("206 Partial Content", format!("Content-Range: bytes {start}-{}/{len}\r\n", end - 1), &body);
        }
    }
}

/// The byte range of the coarsest tile's payload (the root page, loaded before the first frame).
fn root_payload(pack: &Path) -> (u64, u64) {
    let p = Pack::open(pack).unwrap();
    let lod = p.levels().len() as u32 - 1;
    let e = p.entry(p.position(vortex_pack::TileId { lod, x: 0, y: 0 }).unwrap());
    (e.offset_or_value, e.offset_or_value + e.len as u64)
}

#[test]
fn a_server_that_drops_garbles_and_ignores_ranges_is_survived() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let data = Pack::open(&pack).unwrap().header().data_offset;
    let garbled = Arc::new(AtomicUsize::new(0));
    let once = Arc::clone(&garbled);
    // Every third request dropped, every fifth answered with the whole file, and the first
    // payload request after the root's answered with wrong bytes (once: read again, it is right).
    let act = move |n: usize, start: u64, _end: u64| match n {
        _ if n % 3 == 2 => Act::Drop,
        _ if n % 5 == 4 => Act::Whole,
        _ if n > 4 && start >= data && once.fetch_add(1, Ordering::Relaxed) == 0 => Act::Garble,
        _ => Act::Serve,
    };
    let server = Misbehaving::start(&pack, Arc::new(act), Arc::new(|| true));
    let extra = ["--cache-format", "rgba8", "--threads", "4"];
    let Some((local, _)) = render(s(&pack), dir.path(), "local", &extra) else { return };
    let (remote, r) = render(&server.url(), dir.path(), "remote", &extra).unwrap();
    same_frames(&local, &remote);
    let c = &r["remote"];
    let n = |key: &str| c[key].as_u64().unwrap();
    assert_eq!(n("requests"), server.requests.load(Ordering::Relaxed) as u64, "{c}");
    assert!(n("io_errors") >= 1 && n("retries") == n("io_errors"), "{c}");
    assert!(n("whole_file_replies") >= 1, "{c}");
    assert_eq!(n("corrupt"), 1, "{c}");
    assert!(garbled.load(Ordering::Relaxed) >= 1);
    assert!(r["errors"].as_array().unwrap().is_empty(), "{}", r["errors"]);
}

#[test]
fn a_tile_the_server_always_garbles_is_reported_and_never_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let root = root_payload(&pack);
    let data = Pack::open(&pack).unwrap().header().data_offset;
    // Every payload but the root's comes back wrong, however often it is asked for.
    let act = move |_: usize, start: u64, end: u64| {
        if start >= data && (start, end) != root { Act::Garble } else { Act::Serve }
    };
    let server = Misbehaving::start(&pack, Arc::new(act), Arc::new(|| true));
    let json = dir.path().join("r.json");
    let args = ["render", "--pack", &server.url(), "--size", "128x96", "--frame-count", "20", "--report", s(&json)];
    let out = run(&[&args[..], &["--threads", "1", "-q"]].concat());
    if no_gpu(&out) {
        return;
    }
    // The stand-in is drawn instead (the run fails, as for a damaged local file), naming the tile.
    fails_with(&out, &["page(s) failed to load and were drawn as a stand-in", "payload checksum mismatch"]);
    let r = report(&json);
    assert!(!r["errors"].as_array().unwrap().is_empty());
    // Each bad payload read twice (once again in case the fault was passing), then given up.
    let corrupt = r["remote"]["corrupt"].as_u64().unwrap();
    assert!(corrupt >= 2 && corrupt.is_multiple_of(2), "{}", r["remote"]);
}

#[test]
fn held_reads_never_hold_up_a_real_time_frame() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let root = root_payload(&pack);
    let data = Pack::open(&pack).unwrap().header().data_offset;
    let json = dir.path().join("r.json");
    // Every payload but the root's is held until the run has written its report: every frame
    // is drawn while the reads are under way.
    let act = move |_: usize, start: u64, end: u64| {
        if start >= data && (start, end) != root { Act::Hold } else { Act::Serve }
    };
    let written = json.clone();
    let server = Misbehaving::start(&pack, Arc::new(act), Arc::new(move || written.exists()));
    let args = ["render", "--pack", &server.url(), "--size", "128x96", "--pacing", "real-time", "--threads", "4"];
    let out = run(&[&args[..], &["--frame-count", "30", "--report", s(&json), "-q"]].concat());
    if no_gpu(&out) {
        return;
    }
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r = report(&json);
    let frames = r["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 30);
    // Thirty frames drawn, none waiting, while no read could land: the pages were asked for and
    // stayed in flight.
    for f in frames {
        assert_eq!(f["io_wait_ms"], 0.0, "frame {} waited for pages", f["frame"]);
        assert_eq!(f["loaded"].as_u64(), Some(0), "frame {}: nothing can have landed", f["frame"]);
    }
    assert!(frames.iter().any(|f| f["in_flight"].as_u64().unwrap() > 0));
}

#[test]
fn a_page_on_a_dead_server_costs_the_http_attempts_only() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let data = Pack::open(&pack).unwrap().header().data_offset;
    // The head and index are served; then the server dies: every payload request is dropped.
    let act = move |_: usize, start: u64, _: u64| if start >= data { Act::Drop } else { Act::Serve };
    let server = Misbehaving::start(&pack, Arc::new(act), Arc::new(|| true));
    // No waits: the backoffs are what a real outage is waited out with, not what is counted here.
    let options = HttpOptions { attempts: 5, backoff: Duration::ZERO, ..HttpOptions::default() };
    let remote = Arc::new(HttpPack::open_with(&server.url(), options, vortex_pack::Limits::default()).unwrap());
    let loader = Loader::with_sources(vec![Arc::clone(&remote) as Arc<dyn PageSource>], 1).unwrap();
    loader.set_retry(RetryPolicy { attempts: 3, backoff: Duration::ZERO });
    let opened = server.requests.load(Ordering::Relaxed);
    let root = PageId::new(0, loader.textures()[0].grid.lod_count() - 1, 0, 0);
    let page = loader.load(&[(root, 0)]).remove(0);
    assert!(matches!(page.error, Some(LoadError::Tile { kind: ReadErrorKind::Io, .. })), "{:?}", page.error);
    // HttpPack's 5 tries of the one request, not 5 for each of the loader's 3 reads.
    assert_eq!(server.requests.load(Ordering::Relaxed) - opened, 5);
    assert_eq!((remote.stats().io_errors, loader.counters().read_retries), (5, 0));
}

#[test]
fn an_index_read_in_blocks_gives_every_tile_of_the_local_file() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("sample.vtpk");
    // 16-texel tiles: 36 x 36 at LOD 0, some 1,700 tiles, an index of 7 blocks of 256 entries.
    let r = run(&["split", s(&fixture("sample.png")), "--pack", s(&pack), "--tile-size", "16", "--border", "1"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let Some(server) = nginx(dir.path(), "an_index_read_in_blocks_gives_every_tile_of_the_local_file") else { return };
    let url = format!("{}/sample.vtpk", server.url());
    let options = HttpOptions { whole_index_up_to: 0, ..HttpOptions::default() };
    let remote = HttpPack::open_with(&url, options, vortex_pack::Limits::default()).unwrap();
    let local = Pack::open(&pack).unwrap();
    assert!(local.header().index_count > 3 * vortex_vt_wgpu::source::INDEX_BLOCK);
    assert_eq!(remote.metadata(), local.metadata());
    for id in local.ids() {
        let stored = remote.read_stored(id).unwrap().unwrap().tile;
        let want = match local.tile_checked(id).unwrap() {
            Tile::Absent => StoredTile::Absent,
            Tile::Constant(v) => StoredTile::Stored { kind: TileKind::Constant, bytes: v.into() },
            Tile::Data(kind, bytes) => StoredTile::Stored { kind, bytes: bytes.into() },
        };
        assert_eq!(stored, want, "{id:?}");
        assert_eq!(remote.read_tile(id, CacheFormat::Rgba8).unwrap(), local.read_tile(id, CacheFormat::Rgba8).unwrap());
    }
    let stats = remote.stats();
    assert_eq!(stats.requests as usize, server.requests().len());
    assert_eq!((stats.retries, stats.corrupt), (0, 0));
}

#[test]
fn a_wrong_index_block_is_caught_by_the_index_checksum() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("sample.vtpk");
    let r = run(&["split", s(&fixture("sample.png")), "--pack", s(&pack), "--tile-size", "16", "--border", "1"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let local = Pack::open(&pack).unwrap();
    let h = *local.header();
    // The last index block comes back with every byte inverted.
    let last_block = h.index_offset + (h.index_count - 1) / 256 * 256 * 24;
    let act = move |_: usize, start: u64, _: u64| if start == last_block { Act::Garble } else { Act::Serve };
    let server = Misbehaving::start(&pack, Arc::new(act), Arc::new(|| true));
    let options = HttpOptions { whole_index_up_to: 0, ..HttpOptions::default() };
    let remote = HttpPack::open_with(&server.url(), options, vortex_pack::Limits::default()).unwrap();
    let mut failures = Vec::new();
    for id in local.ids() {
        if let Err(e) = remote.read_stored(id) {
            assert_eq!(e.kind, ReadErrorKind::Corrupt, "{}", e.message);
            failures.push(e.message);
        }
    }
    // Garbled entries fail their own checks (unknown kinds, bytes outside the data section); once
    // every block has arrived, the index's CRC fails and every later read says so.
    assert!(failures.iter().any(|m| m.contains("level table or index checksum mismatch")), "{failures:?}");
    assert!(failures.len() as u64 >= h.index_count - (h.index_count - 1) / 256 * 256, "{}", failures.len());
}

#[test]
fn a_pack_replaced_on_the_server_is_refused_not_mixed() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let Some(server) = nginx(dir.path(), "a_pack_replaced_on_the_server_is_refused_not_mixed") else { return };
    let remote = HttpPack::open(&format!("{}/sample.vtpk", server.url())).unwrap();
    // Another pack of the same length (one payload byte changed), an hour newer: nginx's ETag
    // (modification time and length) changes.
    let mut bytes = std::fs::read(&pack).unwrap();
    let (first, entry) = Pack::open(&pack).unwrap().ids_in_file_order()[0];
    bytes[entry.offset_or_value as usize] ^= 1;
    std::fs::write(&pack, &bytes).unwrap();
    let hour_later = std::time::SystemTime::now() + std::time::Duration::from_secs(3600);
    std::fs::File::options().write(true).open(&pack).unwrap().set_modified(hour_later).unwrap();
    let e = remote.read_stored(first).unwrap_err();
    assert!(e.message.contains("the pack changed on the server since it was opened"), "{}", e.message);
    assert_eq!(e.kind, ReadErrorKind::Unavailable, "not worth reading again");
    assert_eq!(remote.stats().retries, 0, "a changed pack is not retried");
}

#[test]
fn damaged_packs_are_refused_over_http_as_the_local_reader_refuses_them() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let good = std::fs::read(&pack).unwrap();
    let h = *Pack::open(&pack).unwrap().header();
    let flip = |at: u64| {
        let mut b = good.clone();
        b[at as usize] ^= 0x40;
        b
    };
    let damaged = [
        ("truncated", good[..good.len() - 1].to_vec()),
        ("header", flip(40)),
        ("metadata", flip(h.meta_offset)),
        ("index", flip(h.index_offset + 3)),
        ("signature", flip(1)),
    ];
    for (name, bytes) in &damaged {
        std::fs::write(dir.path().join(format!("{name}.vtpk")), bytes).unwrap();
    }
    let Some(server) = nginx(dir.path(), "damaged_packs_are_refused_over_http_as_the_local_reader_refuses_them") else {
        return;
    };
    for (name, _) in damaged {
        let (path, url) = (dir.path().join(format!("{name}.vtpk")), format!("{}/{name}.vtpk", server.url()));
        // Opening checks the index too when it is read whole (the local reader always).
        let local = Pack::open(&path).err().unwrap().to_string();
        let remote = HttpPack::open(&url).err().unwrap().to_string();
        assert_eq!(remote.replace(&url, "PACK"), local.replace(s(&path), "PACK"), "{name}");
    }
}

#[test]
fn urls_that_do_not_serve_a_pack_are_named() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("note.txt"),
        "not a pack at all, but long enough to have a header's bytes: ".repeat(8),
    )
    .unwrap();
    let Some(server) = nginx(dir.path(), "urls_that_do_not_serve_a_pack_are_named") else { return };
    let missing = format!("{}/missing.vtpk", server.url());
    fails_with(&run(&["render", "--pack", &missing, "-q"]), &["opening", "missing.vtpk", "HTTP 404"]);
    let text = format!("{}/note.txt", server.url());
    fails_with(&run(&["render", "--pack", &text, "-q"]), &["note.txt", "bad signature: not a Vortex pack"]);
    // Nobody listening: retried with backoff, then named (the port was free a moment ago).
    let port = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let refused = format!("http://127.0.0.1:{port}/x.vtpk");
    fails_with(&run(&["render", "--pack", &refused, "-q"]), &["opening http://127.0.0.1", "(6 attempts)"]);
}

/// A server that answers every request with the whole file is refused when the pack opens,
/// with a message that says why, not by 6 failed tries of every read after the first.
#[test]
fn a_host_that_ignores_range_is_refused_at_open() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let server = Misbehaving::start(&pack, Arc::new(|_, _, _| Act::Whole), Arc::new(|| true));
    let e = HttpPack::open(&server.url()).err().expect("a pack on a host that ignores Range opens").to_string();
    assert!(e.contains("this host ignores Range requests") && e.contains("sample.vtpk"), "{e}");
    assert_eq!(server.requests.load(Ordering::Relaxed), 1, "refused at the first reply, not retried");
    fails_with(&run(&["render", "--pack", &server.url(), "-q"]), &["sample.vtpk", "this host ignores Range requests"]);
}

/// A reply that trickles forever ends at the request's deadline, and the error names it.
#[test]
fn a_trickling_reply_ends_at_the_deadline() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let server = Misbehaving::start(&pack, Arc::new(|_, _, _| Act::Trickle), Arc::new(|| true));
    // One attempt: the body (2 KiB at a byte per 200 ms) would take minutes; bytes keep coming,
    // so only the deadline can end it.
    let options = HttpOptions { attempts: 1, deadline: Duration::from_millis(500), ..HttpOptions::default() };
    let e = HttpPack::open_with(&server.url(), options, vortex_pack::Limits::default()).err().unwrap().to_string();
    assert!(e.contains("no complete reply within the deadline of 0.5 s per request"), "{e}");
    let out = run(&["render", "--pack", &server.url(), "--http-deadline", "300ms", "-q"]);
    fails_with(&out, &["sample.vtpk", "deadline of 0.3 s per request", "(6 attempts)"]);
}

/// SIGTERM while a remote pack opens (its first reply trickling) ends the run as a signal does
/// (exit 143), not when the reply is done.
#[test]
fn a_stop_signal_ends_the_open_of_a_remote_pack() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let server = Misbehaving::start(&pack, Arc::new(|_, _, _| Act::Trickle), Arc::new(|| true));
    let json = dir.path().join("r.json");
    let child = std::process::Command::new(crate::common::cli::BIN)
        .args(["render", "--pack", &server.url(), "--report", s(&json), "-q"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The first request arrives once the handlers are installed (they are before any pack opens).
    for _ in 0..6000 {
        if server.requests.load(Ordering::Relaxed) > 0 {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(server.requests.load(Ordering::Relaxed) > 0, "render never asked for the pack");
    let pid = child.id();
    assert!(std::process::Command::new("kill").args(["-TERM", &pid.to_string()]).status().unwrap().success());
    let out = crate::common::cli::wait_or_kill(pid, "render stopped while opening", move || {
        child.wait_with_output().unwrap()
    });
    assert_eq!(out.status.code(), Some(143), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(!json.exists());
}

/// A redirect to something that is not http(s) is named as such.
#[test]
fn a_redirect_out_of_http_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let server = Misbehaving::start(&pack, Arc::new(|_, _, _| Act::Redirect("file:///etc/passwd")), Arc::new(|| true));
    let e = HttpPack::open(&server.url()).err().unwrap().to_string();
    assert!(e.contains("redirected to file:///etc/passwd") && e.contains("not an http:// or https:// URL"), "{e}");
}

/// The test server never mistakes another server for itself: with its first port taken (by a
/// listener that accepts and never answers, as a stranger that took the port between our
/// finding it free and nginx binding it would), nginx fails to bind, and the helper starts it
/// on the next port and serves from there. (Before, the helper took any connection on the port
/// as nginx being up, and the tests then talked to the stranger.)
#[test]
fn the_test_server_moves_off_a_taken_port() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("hello.txt"), b"hello").unwrap();
    let Ok(binary) = nginx_binary() else {
        skip_unless_ci("the nginx port test", "no nginx (apt-get install nginx-light)");
        return;
    };
    let stranger = TcpListener::bind("127.0.0.1:0").unwrap();
    let taken = stranger.local_addr().unwrap().port();
    let free = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let server = Nginx::start_on(&binary, dir.path(), &[], [taken, free]);
    assert_eq!(server.url(), format!("http://127.0.0.1:{free}"));
    let mut stream = TcpStream::connect(("127.0.0.1", free)).unwrap();
    use std::io::Read;
    write!(stream, "GET /hello.txt HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
    let mut reply = String::new();
    stream.read_to_string(&mut reply).unwrap();
    assert!(reply.starts_with("HTTP/1.1 200") && reply.ends_with("hello"), "{reply}");
}
