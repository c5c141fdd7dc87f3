//! `vortex-tiler serve` started as a user starts it, on 127.0.0.1:0, asked by a raw HTTP/1.1
//! client (a socket, so malformed requests can be sent too).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use super::cli::{BIN, s};

/// A running `vortex-tiler serve`, killed when dropped.
pub struct Server {
    pub child: Child,
    pub port: u16,
}

/// `vortex-tiler serve ARGS` started (stdout and stderr piped), and the first line it printed:
/// `serving N inputs on http://ADDR/` once it listens, or nothing when it refused to start (its
/// stdout closed; its stderr says why).
pub fn spawn(args: &[&str]) -> (Child, String) {
    let mut child = Command::new(BIN)
        .arg("serve")
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("serve starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
    (child, line)
}

impl Server {
    pub fn start(inputs: &[&Path], extra: &[&str]) -> Server {
        let inputs: Vec<&str> = inputs.iter().map(|p| s(p)).collect();
        let (child, line) = spawn(&[&inputs[..], &["--addr", "127.0.0.1:0"], extra].concat());
        let addr = line
            .trim()
            .strip_prefix(&format!(
                "serving {} input{} on http://",
                inputs.len(),
                if inputs.len() == 1 { "" } else { "s" }
            ))
            .and_then(|rest| rest.strip_suffix('/'))
            .unwrap_or_else(|| panic!("unexpected first line {line:?}"));
        let port = addr.rsplit_once(':').unwrap().1.parse().unwrap();
        Server { child, port }
    }

    /// `http://127.0.0.1:PORT`, without a trailing slash.
    pub fn url(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// Sends `head` (request line and headers, without the blank line) and reads the answer.
    pub fn raw(&self, head: &str) -> Reply {
        let mut stream = TcpStream::connect(("127.0.0.1", self.port)).unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
        stream.write_all(format!("{head}\r\nConnection: close\r\n\r\n").as_bytes()).unwrap();
        let mut bytes = Vec::new();
        stream.read_to_end(&mut bytes).unwrap();
        Reply::parse(&bytes)
    }

    pub fn get(&self, path: &str, headers: &[(&str, &str)]) -> Reply {
        self.request("GET", path, headers)
    }

    pub fn request(&self, method: &str, path: &str, headers: &[(&str, &str)]) -> Reply {
        let mut head = format!("{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{}", self.port);
        for (k, v) in headers {
            head.push_str(&format!("\r\n{k}: {v}"));
        }
        self.raw(&head)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[derive(Debug)]
pub struct Reply {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Reply {
    pub fn parse(bytes: &[u8]) -> Reply {
        let split = bytes.windows(4).position(|w| w == b"\r\n\r\n").expect("a complete head");
        let head = String::from_utf8_lossy(&bytes[..split]).into_owned();
        let mut lines = head.split("\r\n");
        let status = lines.next().unwrap().split(' ').nth(1).unwrap().parse().unwrap();
        let headers = lines
            .filter_map(|l| l.split_once(':'))
            .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
            .collect();
        Reply { status, headers, body: bytes[split + 4..].to_vec() }
    }

    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }

    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    /// The body decoded as an image: (width, height).
    pub fn image_size(&self) -> (u32, u32) {
        let image = image::load_from_memory(&self.body).unwrap_or_else(|e| panic!("not an image ({e}): {self:?}"));
        (image.width(), image.height())
    }
}
