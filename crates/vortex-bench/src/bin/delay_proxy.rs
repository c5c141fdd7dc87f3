//! `delay_proxy LISTEN UPSTREAM MS`: an HTTP/1.1 proxy that adds `MS` milliseconds before each
//! request reaches `UPSTREAM` (host:port), what a link with that round trip does; for
//! `bench/render-remote.sh`, which measures `render --pack http://...` through it. One thread per
//! connection; each request head is read whole, held, then passed on with its reply streamed
//! back. Keep-alive works as the two ends agree (the proxy forwards bytes as they are; a
//! request with a body is not expected: `render` only sends GETs).
//!
//!     cargo run -p vortex-bench --bin delay_proxy -- 127.0.0.1:8081 127.0.0.1:8080 50

use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::time::Duration;

use anyhow::{Context, Result, bail};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [listen, upstream, ms] = args.as_slice() else {
        bail!("usage: delay_proxy LISTEN UPSTREAM MS, e.g. 127.0.0.1:8081 127.0.0.1:8080 50");
    };
    let delay = Duration::from_millis(ms.parse().context("MS: a number of milliseconds")?);
    let listener = TcpListener::bind(listen).with_context(|| format!("listening on {listen}"))?;
    eprintln!("delay_proxy: {listen} -> {upstream}, +{} ms per request", delay.as_millis());
    for client in listener.incoming() {
        let Ok(client) = client else { continue };
        let upstream = upstream.clone();
        std::thread::spawn(move || {
            if let Err(e) = serve(client, &upstream, delay) {
                eprintln!("delay_proxy: {e:#}");
            }
        });
    }
    Ok(())
}

/// Each request on `client`: its head held `delay`, sent upstream, the reply copied back.
fn serve(client: TcpStream, upstream: &str, delay: Duration) -> Result<()> {
    let server = TcpStream::connect(upstream).with_context(|| format!("connecting to {upstream}"))?;
    let (mut to_server, mut to_client) = (server.try_clone()?, client.try_clone()?);
    // Replies flow back on their own thread as they come; requests are read and held here.
    let back = std::thread::spawn(move || {
        let mut from_server = server;
        let _ = std::io::copy(&mut from_server, &mut to_client);
        let _ = to_client.shutdown(std::net::Shutdown::Both);
    });
    let mut from_client = BufReader::new(client);
    loop {
        let mut head = Vec::new();
        loop {
            let mut line = Vec::new();
            if from_client.read_until(b'\n', &mut line)? == 0 {
                let _ = to_server.shutdown(std::net::Shutdown::Write);
                let _ = back.join();
                return Ok(());
            }
            head.extend_from_slice(&line);
            if line == b"\r\n" || line == b"\n" {
                break;
            }
        }
        std::thread::sleep(delay);
        to_server.write_all(&head)?;
    }
}
