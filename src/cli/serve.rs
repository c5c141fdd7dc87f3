//! `serve`: the flags, the tokio runtime and the signals around `vortex_tiler::serve`.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use vortex_tiler::serve::{Catalog, ServeOptions, Server};

#[derive(clap::Args, Debug)]
pub struct ServeArgs {
    /// Packs (.vtpk), split directories (info.json + tiles) or directories written by
    /// `split --layout dzi|iiif|xyz|google`. Each is served under its file stem (a directory
    /// under its name); two inputs with the same name are refused.
    #[arg(value_name = "PATH", required = true)]
    inputs: Vec<PathBuf>,
    /// Address to listen on. Port 0 picks a free port (printed at start). Other hosts than
    /// loopback are allowed, with a warning: there is no authentication.
    #[arg(long, value_name = "HOST:PORT", default_value = "127.0.0.1:8080")]
    addr: SocketAddr,
    /// Memory for re-encoded tiles (edge tiles, levels below one page, non-image payloads),
    /// least recently used evicted first; 0 turns the cache off.
    #[arg(long, value_name = "SIZE", default_value = "64M", value_parser = super::parse_size)]
    cache: u64,
    /// Requests answered at once, 1 to 65536; more wait their turn.
    #[arg(long, value_name = "N", default_value_t = 64)]
    max_concurrent: usize,
    /// Connections open at once, 1 to 65536; more wait in the listen queue until one closes.
    /// Each takes a file descriptor: the default stays under a `ulimit -n` of 256, so idle
    /// clients cannot exhaust the descriptors the server needs to open tiles.
    #[arg(long, value_name = "N", default_value_t = 200)]
    max_connections: usize,
    /// Seconds a connection may take to send a request's headers, and may stay idle between
    /// requests, before it is closed (1 to 3600). It frees the connections of clients that
    /// connect and send nothing, or trickle their headers (slowloris).
    #[arg(long, value_name = "SECONDS", default_value_t = 15)]
    idle_timeout: u64,
    /// Tiles decoded and re-encoded at once, 1 to 4 per core [default: the number of cores].
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// A local OpenSeadragon build to serve at /openseadragon/ for the viewer pages, e.g.
    /// node_modules/openseadragon/build/openseadragon; without it the pages load
    /// OpenSeadragon 6.1 from the jsDelivr CDN.
    #[arg(long, value_name = "DIR")]
    openseadragon: Option<PathBuf>,
}

pub fn run(args: ServeArgs) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let options = ServeOptions {
        addr: args.addr,
        cache_bytes: args.cache,
        max_concurrent: args.max_concurrent,
        blocking_jobs: args.threads.unwrap_or(cores),
        max_connections: args.max_connections,
        idle_timeout: Duration::from_secs(args.idle_timeout),
        openseadragon: args.openseadragon,
    };
    // Before the runtime is sized from them.
    options.check()?;
    let catalog = Catalog::open(&args.inputs)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .max_blocking_threads(options.blocking_jobs + 4)
        .build()
        .context("starting the async runtime")?;
    let served = runtime.block_on(async {
        let server = Server::bind(catalog, &options).await?;
        let addr = server.local_addr();
        if !addr.ip().is_loopback() {
            eprintln!(
                "warning: listening on {addr}, reachable from other machines; anyone who can reach it can read every input"
            );
        }
        let n = server.input_count();
        say!("serving {n} input{} on http://{addr}/", if n == 1 { "" } else { "s" });
        server.serve(stop_signal(), Duration::from_secs(5)).await?;
        eprintln!("stopped");
        anyhow::Ok(())
    });
    // A read still blocked on a slow disk after the grace period is not waited for (dropping
    // the runtime would wait for its blocking threads for ever).
    runtime.shutdown_background();
    served
}

/// Completes on Ctrl-C or SIGTERM, saying which on stderr.
async fn stop_signal() {
    let ctrl_c = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    let which = tokio::select! {
        () = ctrl_c => "SIGINT",
        () = terminate => "SIGTERM",
    };
    eprintln!("{which} received: stopping (open requests may finish, at most 5 s)");
}
