//! `serve` against a hostile or unlucky directory and hostile clients: links out of a served
//! directory, FIFOs and devices, files that are no tiles, damaged packs, idle and trickling
//! connections, out-of-range flags and HTTP corner cases. Each case runs the built binary.

use std::fs;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::common::cli::{fails_with, fixture, ok, run, s, wait_or_kill};
use crate::common::server::{self, Reply, Server};

/// Fail-safe for reads that must end: far past any timeout the server is given here.
const FAIL_SAFE: Duration = Duration::from_secs(60);

/// sample.png as PNG pages of 64 texels without border (IIIF and XYZ tiles are the stored
/// files): `-o dir` or `--pack file`.
fn split_png(out: &[&str]) {
    let args = ["--tile-size", "64", "--border", "0", "--codec", "png", "-q"];
    ok(&[&["split", s(&fixture("sample.png"))][..], out, &args].concat());
}

/// The file of page (lod, x, y) of a split directory.
fn page_file(dir: &Path, lod: u32, x: u32, y: u32) -> PathBuf {
    let info: serde_json::Value = serde_json::from_slice(&fs::read(dir.join("info.json")).unwrap()).unwrap();
    let names =
        vortex_tiler::formats::tiles::filename::FilenameFormat::parse(info["filenameFormat"].as_str().unwrap(), 3)
            .unwrap();
    dir.join(names.format(&[lod, x, y]))
}

fn mkfifo(path: &Path) {
    assert!(Command::new("mkfifo").arg(path).status().unwrap().success());
}

/// The same page by its three names: Deep Zoom, IIIF, XYZ (zoom 4 is LOD 0 of sample.png in
/// 64-texel pages).
fn three_names(name: &str, x: u32, y: u32) -> [String; 3] {
    [
        format!("/{name}_files/10/{x}_{y}.png"),
        format!("/{name}/iiif/{},{},64,64/64,64/0/default.png", x * 64, y * 64),
        format!("/{name}/xyz/4/{x}/{y}.png"),
    ]
}

#[test]
fn a_link_out_of_a_split_directory_is_never_followed() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = dir.path().join("tiles");
    split_png(&["-o", s(&tiles)]);
    let secret = dir.path().join("secret.png");
    fs::write(&secret, "the secret").unwrap();
    let page = page_file(&tiles, 0, 1, 1);
    fs::remove_file(&page).unwrap();
    std::os::unix::fs::symlink(&secret, &page).unwrap();
    let server = Server::start(&[&tiles], &[]);
    for path in three_names("tiles", 1, 1) {
        let r = server.get(&path, &[]);
        assert_eq!(r.status, 500, "{path}: {r:?}");
        assert!(r.text().contains("leads out of") && !r.text().contains("the secret"), "{path}: {r:?}");
    }
    // Its neighbours are served.
    for path in three_names("tiles", 2, 1) {
        assert_eq!(server.get(&path, &[]).status, 200, "{path}");
    }

    // A manifest of a viewer directory linked out of it is refused at start.
    let map = dir.path().join("map");
    ok(&["split", s(&fixture("sample.png")), "-o", s(&map), "--layout", "xyz", "-q"]);
    let outside = dir.path().join("tilejson.json");
    fs::rename(map.join("tilejson.json"), &outside).unwrap();
    std::os::unix::fs::symlink(&outside, map.join("tilejson.json")).unwrap();
    fails_with(&run(&["serve", s(&map), "--addr", "127.0.0.1:0"]), &["tilejson.json", "leads out of"]);
}

#[test]
fn fifos_devices_and_oversized_tiles_are_never_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tiles = d.join("tiles");
    split_png(&["-o", s(&tiles)]);
    // A FIFO (an open would wait for a writer for ever), a link to /dev/zero (endless), and a
    // sparse 64 MiB file where a 64-texel page belongs.
    let fifo = page_file(&tiles, 0, 1, 1);
    fs::remove_file(&fifo).unwrap();
    mkfifo(&fifo);
    let zero = page_file(&tiles, 0, 2, 1);
    fs::remove_file(&zero).unwrap();
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    fs::OpenOptions::new().write(true).open(page_file(&tiles, 0, 3, 1)).unwrap().set_len(64 << 20).unwrap();
    let deep = d.join("deep");
    ok(&["split", s(&fixture("sample.png")), "-o", s(&deep), "--layout", "dzi", "-q"]);
    let deep_fifo = deep.join("sample_files/10/0_0.jpeg");
    fs::remove_file(&deep_fifo).unwrap();
    mkfifo(&deep_fifo);

    let mut server = Server::start(&[&tiles, &deep], &[]);
    for (x, why) in [(1, "not a regular file"), (2, "leads out of"), (3, "over")] {
        for path in three_names("tiles", x, 1) {
            let r = server.get(&path, &[]);
            assert_eq!(r.status, 500, "{path}: {r:?}");
            assert!(r.text().contains(why), "{path}: {r:?}");
        }
    }
    assert_eq!(server.get("/deep_files/10/0_0.jpeg", &[]).status, 404);
    assert_eq!(server.get("/deep_files/10/1_0.jpeg", &[]).status, 200);

    // And it still stops at once on SIGTERM.
    let kill = Command::new("kill").args(["-TERM", &server.child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let child = &mut server.child;
    let status = wait_or_kill(child.id(), "serve after SIGTERM", || child.wait().unwrap());
    assert_eq!(status.code(), Some(0));

    // A FIFO or a device as an input is refused before anything opens it.
    let input_fifo = d.join("input.vtpk");
    mkfifo(&input_fifo);
    fails_with(&run(&["serve", s(&input_fifo), "--addr", "127.0.0.1:0"]), &["input.vtpk", "regular file"]);
    fails_with(&run(&["serve", "/dev/zero", "--addr", "127.0.0.1:0"]), &["/dev/zero", "regular file"]);
}

#[test]
fn viewer_directories_serve_their_files_streamed_and_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sample = fixture("sample.png");
    let (deep, image, map) = (d.join("deep"), d.join("image"), d.join("map"));
    ok(&["split", s(&sample), "-o", s(&deep), "--layout", "dzi", "-q"]);
    ok(&["split", s(&sample), "-o", s(&image), "--layout", "iiif", "-q"]);
    ok(&["split", s(&sample), "-o", s(&map), "--layout", "xyz", "-q"]);
    for root in [&deep.join("sample_files"), &image, &map] {
        fs::write(root.join(".env"), "SECRET=1").unwrap();
        fs::write(root.join("notes.txt"), "mine").unwrap();
        fs::create_dir_all(root.join(".git")).unwrap();
        fs::write(root.join(".git/config"), "[core]").unwrap();
    }
    // A large tile (several chunks of a streamed body).
    let large: Vec<u8> = (0..1_000_003u32).map(|i| (i % 251) as u8).collect();
    fs::write(deep.join("sample_files/10/1_1.jpeg"), &large).unwrap();
    let server = Server::start(&[&deep, &image, &map], &[]);

    for path in [
        "/deep_files/.env",
        "/deep_files/notes.txt",
        "/deep_files/.git/config",
        "/image/iiif/.env",
        "/image/iiif/notes.txt",
        "/image/iiif/.git/config",
        "/map/xyz/.env",
        "/map/xyz/notes.txt",
        "/map/xyz/.git/config",
    ] {
        let r = server.get(path, &[]);
        assert!(r.status == 404 || r.status == 400, "{path}: {r:?}");
        assert!(!r.text().contains("SECRET") && !r.text().contains("mine") && !r.text().contains("[core]"));
    }
    assert_eq!(server.get("/map/xyz/tilejson.json", &[]).status, 200);
    assert_eq!(server.get("/map/xyz/0/0/0.jpg", &[]).status, 200);
    assert_eq!(server.get("/image/iiif/full/350,250/0/default.jpg", &[]).status, 200);
    assert_eq!(server.get("/deep.dzi", &[]).status, 200);

    let whole = server.get("/deep_files/10/1_1.jpeg", &[]);
    assert_eq!((whole.status, whole.header("content-length")), (200, Some("1000003")));
    assert!(whole.body == large);
    let head = server.request("HEAD", "/deep_files/10/1_1.jpeg", &[]);
    assert_eq!((head.status, head.header("content-length"), head.body.len()), (200, Some("1000003"), 0));
    let etag = whole.header("etag").unwrap();
    assert_eq!(server.get("/deep_files/10/1_1.jpeg", &[("If-None-Match", etag)]).status, 304);
}

#[test]
fn a_damaged_stored_tile_is_a_500_by_every_route() {
    let dir = tempfile::tempdir().unwrap();
    let pack_path = dir.path().join("p.vtpk");
    split_png(&["--pack", s(&pack_path)]);
    let at = {
        let pack = vortex_pack::Pack::open(&pack_path).unwrap();
        let vortex_pack::Tile::Data(vortex_pack::TileKind::Png, bytes) =
            pack.tile(vortex_pack::TileId::new(0, 1, 1)).unwrap()
        else {
            panic!("a PNG page")
        };
        bytes.as_ptr() as usize - pack.file().as_ptr() as usize + bytes.len() / 2
    };
    let mut file = fs::read(&pack_path).unwrap();
    file[at] ^= 0x55;
    fs::write(&pack_path, &file).unwrap();
    let server = Server::start(&[&pack_path], &[]);
    for path in three_names("p", 1, 1) {
        let r = server.get(&path, &[]);
        assert_eq!(r.status, 500, "{path}: {r:?}");
        assert!(r.text().contains("checksum"), "{path}: {r:?}");
    }
    assert_eq!(server.get(&three_names("p", 2, 1)[0], &[]).status, 200);
}

/// A connection that sends `sent` and nothing more.
fn hold(port: u16, sent: &str) -> TcpStream {
    let mut stream = TcpStream::connect(("127.0.0.1", port)).unwrap();
    stream.write_all(sent.as_bytes()).unwrap();
    stream
}

/// Reads until the server closes `stream` (whatever it sent first); panics past the fail-safe.
fn wait_closed(mut stream: TcpStream) -> Vec<u8> {
    stream.set_read_timeout(Some(FAIL_SAFE)).unwrap();
    let mut bytes = Vec::new();
    match stream.read_to_end(&mut bytes) {
        Ok(_) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => bytes,
        Err(e) => panic!("the server kept an idle connection open: {e}"),
    }
}

/// One request on an open keep-alive connection, its answer read by its Content-Length.
fn ask(stream: &mut TcpStream, path: &str) -> Reply {
    stream.set_read_timeout(Some(FAIL_SAFE)).unwrap();
    stream.write_all(format!("GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").as_bytes()).unwrap();
    let mut bytes = Vec::new();
    let mut byte = [0u8; 1];
    while !bytes.ends_with(b"\r\n\r\n") {
        assert_eq!(stream.read(&mut byte).unwrap(), 1, "closed before the answer");
        bytes.push(byte[0]);
    }
    let head = Reply::parse(&bytes);
    let mut body = vec![0u8; head.header("content-length").unwrap().parse().unwrap()];
    stream.read_exact(&mut body).unwrap();
    Reply { body, ..head }
}

#[test]
fn idle_and_trickling_connections_are_closed_after_the_idle_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("p.vtpk");
    split_png(&["--pack", s(&pack)]);
    let server = Server::start(&[&pack], &["--idle-timeout", "1"]);
    let silent = hold(server.port, "");
    let trickle = hold(server.port, "GET /p.dzi HTTP/1.1\r\nHost: x\r\n");
    let mut kept = hold(server.port, "");
    assert_eq!(ask(&mut kept, "/p.dzi").status, 200);
    // Each is closed by the server (a reply to the trickling one, if any, is not a 200).
    assert!(wait_closed(silent).is_empty());
    assert!(!String::from_utf8_lossy(&wait_closed(trickle)).contains(" 200 "));
    assert!(wait_closed(kept).is_empty());
    assert_eq!(server.get("/p.dzi", &[]).status, 200);
}

#[test]
fn connections_past_the_cap_wait_for_one_to_close() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("p.vtpk");
    split_png(&["--pack", s(&pack)]);
    // Two connections at once, and a timeout that never fires during the test.
    let server = Server::start(&[&pack], &["--max-connections", "2", "--idle-timeout", "3600"]);
    let idle = hold(server.port, "");
    let mut second = hold(server.port, "");
    // The second one is answered: both are taken, every permit is held.
    assert_eq!(ask(&mut second, "/p.dzi").status, 200);
    let third = hold(server.port, "GET /p.dzi HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
    // Another request on the second connection: by its answer the server has had every chance
    // to take the third, and must not have.
    assert_eq!(ask(&mut second, "/p.dzi").status, 200);
    third.set_nonblocking(true).unwrap();
    let mut byte = [0u8; 1];
    let early = third.peek(&mut byte);
    assert!(matches!(&early, Err(e) if e.kind() == std::io::ErrorKind::WouldBlock), "answered past the cap: {early:?}");
    third.set_nonblocking(false).unwrap();
    // Once a connection closes, the third is taken and answered.
    drop(idle);
    let answer = wait_closed(third);
    assert_eq!(Reply::parse(&answer).status, 200);
}

#[test]
fn out_of_range_counts_are_refused_naming_the_flag() {
    // The flags are checked before the inputs are opened (the input here does not exist).
    let missing = "missing.vtpk";
    for (flag, value, needle) in [
        ("--threads", "0", "--threads 0 is not between 1 and"),
        ("--threads", "99999999", "4 per core"),
        ("--max-concurrent", "0", "--max-concurrent 0 is not between 1 and 65536"),
        ("--max-concurrent", "2305843009213693952", "--max-concurrent 2305843009213693952 is not between"),
        ("--max-connections", "0", "--max-connections 0 is not between"),
        ("--idle-timeout", "0", "--idle-timeout 0 is not between 1 and 3600 seconds"),
        ("--idle-timeout", "18446744073709551615", "--idle-timeout 18446744073709551615 is not"),
    ] {
        fails_with(&run(&["serve", missing, "--addr", "127.0.0.1:0", flag, value]), &[needle]);
    }
}

#[test]
fn http_corner_cases() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("p.vtpk");
    split_png(&["--pack", s(&pack)]);
    let image = dir.path().join("image");
    ok(&["split", s(&fixture("sample.png")), "-o", s(&image), "--layout", "iiif", "-q"]);
    let file = fs::read(&pack).unwrap();
    let server = Server::start(&[&pack, &image], &[]);

    // Two Host headers: 400.
    let two = server.raw("GET /p/iiif/info.json HTTP/1.1\r\nHost: a.test\r\nHost: b.test");
    assert_eq!(two.status, 400, "{two:?}");
    // The Host shapes the IIIF id: caches must keep one per Host.
    for path in ["/p/iiif/info.json", "/image/iiif/info.json"] {
        assert_eq!(server.get(path, &[]).header("vary"), Some("Host"), "{path}");
    }
    // A Range in another unit is ignored: the whole file.
    let other = server.get("/p.vtpk", &[("Range", "lines=0-1")]);
    assert_eq!(other.status, 200);
    assert!(other.body == file);
    // If-None-Match naming the ETag wins over Range: 304.
    let etag = server.get("/p.vtpk", &[]).header("etag").unwrap().to_string();
    let held = server.get("/p.vtpk", &[("If-None-Match", &etag), ("Range", "bytes=0-9")]);
    assert_eq!((held.status, held.body.len()), (304, 0));
    assert_eq!(server.get("/p.vtpk", &[("If-None-Match", "\"x\""), ("Range", "bytes=0-9")]).status, 206);
}

#[test]
fn start_messages_name_things_once_and_the_real_port() {
    let dir = tempfile::tempdir().unwrap();
    let shard = dir.path().join("part.vtpk");
    ok(&["split", s(&fixture("sample.png")), "--pack", s(&shard), "--shard", "0/2", "-q"]);
    let out = run(&["serve", s(&shard), "--addr", "127.0.0.1:0"]);
    fails_with(&out, &["part.vtpk", "merge"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.matches("part.vtpk").count(), 1, "{err}");

    let pack = dir.path().join("p.vtpk");
    split_png(&["--pack", s(&pack)]);
    let (mut child, line) = server::spawn(&[s(&pack), "--addr", "0.0.0.0:0"]);
    let port = line.trim().trim_end_matches('/').rsplit_once(':').unwrap().1.to_string();
    child.kill().unwrap();
    child.wait().unwrap();
    let mut err = String::new();
    child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    assert!(port != "0" && err.contains(&format!("listening on 0.0.0.0:{port},")), "{line} {err}");
}
