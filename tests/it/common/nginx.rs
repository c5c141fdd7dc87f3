//! A plain static web server for the browser tests: Debian's nginx, started on a free loopback
//! port as the current user with a config written into a temp dir (pid, logs and temp files
//! there too), serving files as S3 or GitHub Pages would: `Range` requests, no code of ours.

use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The path [`Nginx::requests`] asks for (a 404) before it reads the access log.
const LOG_BARRIER: &str = "/.vortex-log-barrier";

/// One nginx serving `root` at `/` and each alias at its URL prefix; stopped when dropped.
pub struct Nginx {
    child: Child,
    port: u16,
    dir: tempfile::TempDir,
}

/// Where Debian's nginx is, or why it is missing.
pub fn nginx_binary() -> Result<PathBuf, String> {
    ["/usr/sbin/nginx", "/usr/bin/nginx"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.is_file())
        .ok_or_else(|| "no nginx (apt-get install nginx-light)".to_string())
}

impl Nginx {
    /// Serves `root` at `/` and every `(prefix, dir)` of `aliases` at `/prefix/`.
    pub fn start(binary: &Path, root: &Path, aliases: &[(&str, &Path)]) -> Nginx {
        let dir = tempfile::tempdir().unwrap();
        let port = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let d = dir.path().display();
        let locations: String = aliases
            .iter()
            .map(|(prefix, path)| format!("    location /{prefix}/ {{ alias {}/; }}\n", path.display()))
            .collect();
        // One process in the foreground, so that killing the child stops the server; no
        // caching, so that every page load fetches (and the access log counts) everything.
        let config = format!(
            r#"daemon off;
master_process off;
worker_processes 1;
pid {d}/nginx.pid;
error_log {d}/error.log;
events {{ worker_connections 256; }}
http {{
  include /etc/nginx/mime.types;
  default_type application/octet-stream;
  log_format counted '$status $body_bytes_sent "$request" "$http_range"';
  access_log {d}/access.log counted;
  client_body_temp_path {d}/body;
  proxy_temp_path {d}/proxy;
  fastcgi_temp_path {d}/fastcgi;
  uwsgi_temp_path {d}/uwsgi;
  scgi_temp_path {d}/scgi;
  server {{
    listen 127.0.0.1:{port};
    root {root};
    add_header Cache-Control no-store;
{locations}  }}
}}
"#,
            root = root.display(),
        );
        std::fs::write(dir.path().join("nginx.conf"), config).unwrap();
        let child = Command::new(binary)
            .arg("-p")
            .arg(dir.path())
            .arg("-c")
            .arg(dir.path().join("nginx.conf"))
            .arg("-e")
            .arg(dir.path().join("error.log"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("nginx starts");
        let mut nginx = Nginx { child, port, dir };
        let deadline = Instant::now() + Duration::from_secs(20);
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            if let Ok(Some(status)) = nginx.child.try_wait() {
                panic!("nginx exited ({status}): {}", nginx.error_log());
            }
            assert!(Instant::now() < deadline, "nginx did not listen on port {port}: {}", nginx.error_log());
            std::thread::sleep(Duration::from_millis(50));
        }
        nginx
    }

    pub fn url(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    pub fn error_log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("error.log")).unwrap_or_default()
    }

    /// The requests served so far: (status, body bytes, request line, Range header).
    pub fn requests(&self) -> Vec<(u16, u64, String, String)> {
        self.log_barrier();
        let log = std::fs::read_to_string(self.dir.path().join("access.log")).unwrap_or_default();
        log.lines()
            .filter(|line| !line.contains(LOG_BARRIER))
            .filter_map(|line| {
                let (status, rest) = line.split_once(' ')?;
                let (bytes, rest) = rest.split_once(' ')?;
                let mut quoted = rest.split('"').filter(|s| !s.trim().is_empty());
                Some((
                    status.parse().ok()?,
                    bytes.parse().ok()?,
                    quoted.next()?.to_string(),
                    quoted.next()?.to_string(),
                ))
            })
            .collect()
    }

    /// nginx logs a request once its reply is sent, so a client can hold the whole reply before
    /// its line is in the log. Its one worker handles requests in turn: once it has answered one
    /// more, the lines of every request answered before are written. (A wait on an event, not on
    /// a clock.)
    fn log_barrier(&self) {
        use std::io::{Read, Write};
        let mut stream = TcpStream::connect(("127.0.0.1", self.port)).unwrap();
        write!(stream, "GET {LOG_BARRIER} HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
        stream.read_to_end(&mut Vec::new()).unwrap();
    }

    /// Forgets the requests served so far (the access log is written as each one ends).
    pub fn clear_requests(&self) {
        std::fs::write(self.dir.path().join("access.log"), "").unwrap();
    }
}

impl Drop for Nginx {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
