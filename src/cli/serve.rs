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
    /// Requests answered at once; more wait their turn.
    #[arg(long, value_name = "N", default_value_t = 64)]
    max_concurrent: usize,
    /// Tiles decoded and re-encoded at once [default: the number of cores].
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
        openseadragon: args.openseadragon,
    };
    if !options.addr.ip().is_loopback() {
        eprintln!(
            "warning: listening on {}, reachable from other machines; anyone who can reach it can read every input",
            options.addr
        );
    }
    let catalog = Catalog::open(&args.inputs)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .max_blocking_threads(options.blocking_jobs.max(1) + 4)
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async {
        let server = Server::bind(catalog, &options).await?;
        say!("serving {} inputs on http://{}/", server.input_count(), server.local_addr());
        server.serve(stop_signal(), Duration::from_secs(5)).await?;
        eprintln!("stopped");
        Ok(())
    })
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
