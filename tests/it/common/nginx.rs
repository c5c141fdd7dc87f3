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

/// Tries with a new port when the one found free was taken before nginx bound it.
const PORT_ATTEMPTS: u32 = 8;

/// The path that answers with this server's own token, so that a readiness check cannot be
/// answered by another server that took the port.
const WHOAMI: &str = "/.vortex-whoami";

impl Nginx {
    /// Serves `root` at `/` and every `(prefix, dir)` of `aliases` at `/prefix/`. A port is
    /// found free and then released before nginx binds it, so another process may take it in
    /// between: nginx then exits with "Address already in use" and another port is tried (at
    /// most [`PORT_ATTEMPTS`]); and the server is taken as started only once the port answers
    /// [`WHOAMI`] with this instance's token, never because something answers there.
    pub fn start(binary: &Path, root: &Path, aliases: &[(&str, &Path)]) -> Nginx {
        let free = || TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        Nginx::start_on(binary, root, aliases, std::iter::repeat_with(free))
    }

    /// [`Nginx::start`] trying `ports` in turn (the first [`PORT_ATTEMPTS`] of them).
    pub fn start_on(
        binary: &Path,
        root: &Path,
        aliases: &[(&str, &Path)],
        ports: impl IntoIterator<Item = u16>,
    ) -> Nginx {
        let mut last = String::new();
        for port in ports.into_iter().take(PORT_ATTEMPTS as usize) {
            match Nginx::try_start(binary, root, aliases, port) {
                Ok(nginx) => return nginx,
                Err(log) if log.contains("Address already in use") => last = log,
                Err(log) => panic!("nginx exited: {log}"),
            }
        }
        panic!("nginx found every port taken ({PORT_ATTEMPTS} tries); the last: {last}");
    }

    /// nginx on `port`; its error log if it exits before it serves.
    fn try_start(binary: &Path, root: &Path, aliases: &[(&str, &Path)], port: u16) -> Result<Nginx, String> {
        let dir = tempfile::tempdir().unwrap();
        let token = format!("vortex-nginx {} {}", std::process::id(), dir.path().display());
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
    location = {WHOAMI} {{ access_log off; default_type text/plain; return 200 "{token}"; }}
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
        // A fail-safe against an nginx that neither serves nor exits, not a timing.
        let deadline = Instant::now() + Duration::from_secs(20);
        while !nginx.answers(&token) {
            if let Ok(Some(status)) = nginx.child.try_wait() {
                return Err(format!("nginx exited ({status}) on port {port}: {}", nginx.error_log()));
            }
            assert!(Instant::now() < deadline, "nginx did not serve on port {port}: {}", nginx.error_log());
            std::thread::sleep(Duration::from_millis(50));
        }
        Ok(nginx)
    }

    /// Whether this server's port answers [`WHOAMI`] with `token`.
    fn answers(&self, token: &str) -> bool {
        use std::io::{Read, Write};
        let Ok(mut stream) = TcpStream::connect(("127.0.0.1", self.port)) else { return false };
        // Something else holding the port may accept and never answer: give up on it then (the
        // caller asks again, or finds that nginx exited).
        if stream.set_read_timeout(Some(Duration::from_secs(2))).is_err() {
            return false;
        }
        let mut reply = Vec::new();
        let asked = write!(stream, "GET {WHOAMI} HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n");
        asked.is_ok()
            && stream.read_to_end(&mut reply).is_ok()
            && reply.starts_with(b"HTTP/1.1 200")
            && reply.ends_with(token.as_bytes())
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
