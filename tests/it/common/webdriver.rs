//! A minimal W3C WebDriver client for the browser test: `chromedriver` drives Debian's
//! Chromium headless over plain HTTP and JSON, so the test can wait until the page says it is
//! done instead of guessing a time (headless `--screenshot` races with tile loading).

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

/// The key W3C WebDriver gives an element reference under.
const ELEMENT: &str = "element-6066-11e4-a52e-4f735466cecf";

/// A `chromedriver` with one headless Chromium session; both end when dropped.
pub struct Browser {
    driver: Child,
    port: u16,
    session: String,
}

/// The port chromedriver says it listens on, read from its standard output (which is then
/// drained on a thread, so the driver never blocks on a full pipe); what it said instead when
/// it exits without, or says nothing for two minutes (a fail-safe, not a timing).
fn listening_port(stdout: std::process::ChildStdout) -> Result<u16, String> {
    use std::io::BufRead;
    let (tell, told) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut said = String::new();
        let mut lines = std::io::BufReader::new(stdout).lines();
        for line in lines.by_ref().map_while(Result::ok) {
            let port = line
                .strip_prefix("ChromeDriver was started successfully on port ")
                .and_then(|rest| rest.trim_end_matches('.').parse::<u16>().ok());
            if let Some(port) = port {
                let _ = tell.send(Ok(port));
                lines.for_each(drop);
                return;
            }
            said += &line;
            said.push('\n');
        }
        let _ = tell.send(Err(said));
    });
    told.recv_timeout(Duration::from_secs(120)).unwrap_or_else(|_| Err("nothing for two minutes".into()))
}

impl Browser {
    /// Starts `chromedriver` and a headless `chromium` of `width x height` CSS pixels.
    pub fn start(chromedriver: &Path, chromium: &Path, size: (u32, u32)) -> Browser {
        Browser::start_with(chromedriver, chromium, size, &["--disable-gpu"])
    }

    /// [`Browser::start`] with `flags` (e.g. WebGPU's) in place of `--disable-gpu`.
    pub fn start_with(chromedriver: &Path, chromium: &Path, (width, height): (u32, u32), flags: &[&str]) -> Browser {
        // Port 0: chromedriver binds a port the kernel picks and says which ("ChromeDriver
        // was started successfully on port N."), so no port is found free and released first,
        // for another process to take in between.
        let mut driver = Command::new(chromedriver)
            .arg("--port=0")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver starts");
        let port = match listening_port(driver.stdout.take().expect("piped")) {
            Ok(port) => port,
            Err(said) => {
                let _ = driver.kill();
                let _ = driver.wait();
                panic!("chromedriver did not start: {said}");
            }
        };
        let mut browser = Browser { driver, port, session: String::new() };
        let mut args = vec![
            "--headless=new".to_string(),
            "--no-sandbox".into(),
            "--hide-scrollbars".into(),
            "--allow-file-access-from-files".into(),
            format!("--window-size={},{}", width + 200, height + 400),
        ];
        args.extend(flags.iter().map(|f| f.to_string()));
        let caps = json!({ "capabilities": { "alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": { "binary": chromium, "args": args },
        }}});
        let reply = browser.call("POST", "/session", &caps);
        browser.session = reply["sessionId"].as_str().unwrap_or_else(|| panic!("no session: {reply}")).to_string();
        browser
    }

    /// Opens `url` and waits until `ready` (a JavaScript expression) is true.
    pub fn open_and_wait(&self, url: &str, ready: &str, timeout: Duration) {
        self.call("POST", &self.path("url"), &json!({ "url": url }));
        let deadline = Instant::now() + timeout;
        loop {
            let done = self.call(
                "POST",
                &self.path("execute/sync"),
                &json!({ "script": format!("return !!({ready});"), "args": [] }),
            );
            if done == json!(true) {
                return;
            }
            assert!(Instant::now() < deadline, "{url}: not ready after {timeout:?} ({ready})");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Opens `url` without waiting for anything but the load.
    pub fn open(&self, url: &str) {
        self.call("POST", &self.path("url"), &json!({ "url": url }));
    }

    /// Waits until `ready` (a JavaScript expression) is true, polling every 100 ms.
    pub fn wait_js(&self, ready: &str, timeout: Duration) {
        let deadline = Instant::now() + timeout;
        loop {
            let done = self.execute(&format!("return !!({ready});"));
            if done == json!(true) {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "not ready after {timeout:?} ({ready}): {}",
                self.execute("return document.body.innerText;")
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Runs `script` (a function body) in the page and returns what it returns.
    pub fn execute(&self, script: &str) -> Value {
        self.call("POST", &self.path("execute/sync"), &json!({ "script": script, "args": [] }))
    }

    /// A PNG screenshot of the first element matching `css`.
    pub fn screenshot(&self, css: &str) -> Vec<u8> {
        let element = self.call("POST", &self.path("element"), &json!({ "using": "css selector", "value": css }));
        let id = element[ELEMENT].as_str().unwrap_or_else(|| panic!("no element {css}: {element}"));
        let shot = self.call("GET", &self.path(&format!("element/{id}/screenshot")), &Value::Null);
        base64_decode(shot.as_str().expect("base64 PNG"))
    }

    fn path(&self, rest: &str) -> String {
        format!("/session/{}/{rest}", self.session)
    }

    /// One WebDriver command; its `value`, or a panic with the driver's error.
    fn call(&self, method: &str, path: &str, body: &Value) -> Value {
        let body = if body.is_null() { String::new() } else { body.to_string() };
        let mut stream = TcpStream::connect(("127.0.0.1", self.port)).unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
        let head = format!(
            "{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
            self.port,
            body.len()
        );
        stream.write_all(head.as_bytes()).unwrap();
        stream.write_all(body.as_bytes()).unwrap();
        // chromedriver keeps the connection open: read the head, then Content-Length bytes.
        let mut reply = Vec::new();
        let mut chunk = [0u8; 65536];
        let (start, length) = loop {
            let n = stream.read(&mut chunk).unwrap();
            assert!(n > 0, "{method} {path}: the driver closed the connection");
            reply.extend_from_slice(&chunk[..n]);
            if let Some(end) = reply.windows(4).position(|w| w == b"\r\n\r\n") {
                let head = String::from_utf8_lossy(&reply[..end]).to_ascii_lowercase();
                let length = head
                    .lines()
                    .find_map(|l| l.strip_prefix("content-length:"))
                    .and_then(|v| v.trim().parse::<usize>().ok())
                    .expect("a Content-Length");
                break (end + 4, length);
            }
        };
        while reply.len() < start + length {
            let n = stream.read(&mut chunk).unwrap();
            assert!(n > 0, "{method} {path}: the reply ended early");
            reply.extend_from_slice(&chunk[..n]);
        }
        let doc: Value = serde_json::from_slice(&reply[start..start + length])
            .unwrap_or_else(|e| panic!("{method} {path}: {e}: {}", String::from_utf8_lossy(&reply)));
        if doc["value"].get("error").is_some() {
            panic!("{method} {path}: {}", doc["value"]);
        }
        doc["value"].clone()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        if !self.session.is_empty() {
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                self.call("DELETE", &format!("/session/{}", self.session), &Value::Null)
            }));
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

/// Standard base64 (RFC 4648) without line breaks, as WebDriver sends screenshots.
fn base64_decode(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => panic!("not base64: {c}"),
    };
    let bytes: Vec<u8> = text.bytes().filter(|c| *c != b'=').map(value).collect();
    bytes
        .chunks(4)
        .flat_map(|q| {
            let n = q.iter().enumerate().fold(0u32, |n, (i, v)| n | (*v as u32) << (18 - 6 * i));
            let out = [(n >> 16) as u8, (n >> 8) as u8, n as u8];
            out.into_iter().take(q.len() - 1)
        })
        .collect()
}

#[test]
fn base64_round_trip() {
    assert_eq!(base64_decode("aGVsbG8="), b"hello");
    assert_eq!(base64_decode("aGk="), b"hi");
    assert_eq!(base64_decode("YWJj"), b"abc");
}
