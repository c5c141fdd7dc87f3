//! A real S3 server for the object-storage tests: moto's (`moto_server`, PyPI `moto[server]`),
//! started on a free port of 127.0.0.1 and stopped when dropped, with boto3 to look at what
//! the tool left in it. `.ci/run` installs both in `target/moto` and names its `bin/` in
//! `VORTEX_MOTO`; outside CI a test without them skips with a note.

use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

/// What the boto3 helper does: `mb BUCKET`, `put BUCKET KEY TEXT`, `get BUCKET PREFIX DIR`
/// (every object under PREFIX into DIR, printing each key), `count BUCKET PREFIX` (objects
/// under PREFIX, up to 10), `keys BUCKET PREFIX` (every key under PREFIX, a line each), `uploads
/// BUCKET` (open multipart uploads, one key a line).
const BOTO: &str = r#"
import os, sys, boto3
s3 = boto3.client("s3")
cmd, bucket = sys.argv[1], sys.argv[2]
if cmd == "mb":
    s3.create_bucket(Bucket=bucket)
elif cmd == "put":
    s3.put_object(Bucket=bucket, Key=sys.argv[3], Body=sys.argv[4].encode())
elif cmd == "get":
    prefix, out = sys.argv[3], sys.argv[4]
    for page in s3.get_paginator("list_objects_v2").paginate(Bucket=bucket, Prefix=prefix):
        for o in page.get("Contents", []):
            rel = o["Key"][len(prefix):].lstrip("/") or o["Key"].rsplit("/", 1)[-1]
            path = os.path.join(out, rel)
            os.makedirs(os.path.dirname(path) or out, exist_ok=True)
            s3.download_file(bucket, o["Key"], path)
            print(o["Key"])
elif cmd == "count":
    print(s3.list_objects_v2(Bucket=bucket, Prefix=sys.argv[3], MaxKeys=10).get("KeyCount", 0))
elif cmd == "keys":
    for page in s3.get_paginator("list_objects_v2").paginate(Bucket=bucket, Prefix=sys.argv[3]):
        for o in page.get("Contents", []):
            print(o["Key"])
elif cmd == "uploads":
    for u in s3.list_multipart_uploads(Bucket=bucket).get("Uploads", []):
        print(u["Key"])
"#;

/// A running moto server; killed when dropped.
pub struct Moto {
    child: Child,
    port: u16,
    bin: PathBuf,
}

impl Moto {
    /// Starts moto, or `None` (after [`super::skip_unless_ci`]) where it is not installed.
    pub fn start(what: &str) -> Option<Moto> {
        let bin = std::env::var_os("VORTEX_MOTO")
            .map(PathBuf::from)
            .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target/moto/bin"));
        if !bin.join("moto_server").is_file() {
            super::skip_unless_ci(
                what,
                "no moto_server: set VORTEX_MOTO to the bin/ of a venv with `pip install 'moto[server]' boto3`",
            );
            return None;
        }
        let port = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let child = Command::new(bin.join("moto_server"))
            .args(["-H", "127.0.0.1", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("moto_server starts");
        let mut moto = Moto { child, port, bin };
        // Waits for it to listen, however long a loaded machine takes; a server that exits
        // first is named (one that hangs is ended by CI's test timeout).
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            if let Some(status) = moto.child.try_wait().unwrap() {
                panic!("moto_server exited ({status}) before listening on {port}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        Some(moto)
    }

    /// The AWS environment a client of this server needs, and a heartbeat of 1 s for the
    /// runs that write a prefix (so that a killed run's prefix is taken over after 4 s).
    pub fn env(&self) -> Vec<(&'static str, String)> {
        vec![
            ("VORTEX_S3_HEARTBEAT_SECS", "1".into()),
            ("AWS_ENDPOINT_URL", format!("http://127.0.0.1:{}", self.port)),
            ("AWS_ACCESS_KEY_ID", "test".into()),
            ("AWS_SECRET_ACCESS_KEY", "test".into()),
            ("AWS_REGION", "us-east-1".into()),
            ("AWS_ALLOW_HTTP", "true".into()),
        ]
    }

    /// Runs the boto3 helper; its standard output, one line a key.
    pub fn boto(&self, args: &[&str]) -> Vec<String> {
        let out =
            Command::new(self.bin.join("python")).arg("-c").arg(BOTO).args(args).envs(self.env()).output().unwrap();
        assert!(out.status.success(), "boto3 {args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).lines().map(str::to_string).collect()
    }

    /// Objects under `prefix` (up to 1,000), asked without starting Python: an unsigned
    /// ListObjectsV2 (moto takes it), a few milliseconds, for a test to watch a run's progress.
    pub fn quick_count(&self, bucket: &str, prefix: &str) -> usize {
        use std::io::{Read, Write};
        let mut stream = TcpStream::connect(("127.0.0.1", self.port)).unwrap();
        let prefix = prefix.replace('/', "%2F");
        write!(stream, "GET /{bucket}?list-type=2&prefix={prefix} HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
        let mut reply = String::new();
        stream.read_to_string(&mut reply).unwrap();
        assert!(reply.starts_with("HTTP/1.") && reply.contains(" 200 "), "{reply}");
        reply.matches("<Key>").count()
    }

    /// The tool run with this server's environment (and `tmpdir` as its `TMPDIR`).
    pub fn command(&self, args: &[&str], tmpdir: &Path) -> Command {
        let mut cmd = Command::new(super::cli::BIN);
        cmd.args(args).env("NO_COLOR", "1").env("TMPDIR", tmpdir).envs(self.env());
        cmd
    }

    /// The tool run to the end with this server's environment.
    pub fn run(&self, args: &[&str], tmpdir: &Path) -> Output {
        self.command(args, tmpdir).output().expect("binary runs")
    }

    /// Stops the server (its objects go with it).
    pub fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Moto {
    fn drop(&mut self) {
        self.stop();
    }
}
