//! The command line: flags, subcommands, and the glue from them to the library.

/// `println!` for results: a reader that went away (`| head`, `| true`) ends the process
/// quietly with status 141, as coreutils do when SIGPIPE kills them, instead of a panic.
macro_rules! say {
    ($($arg:tt)*) => { $crate::cli::say_line(format_args!($($arg)*)) };
}

mod convert;
mod names;
mod pack;
#[cfg(feature = "gpu")]
mod render;
pub(crate) mod report;
#[cfg(feature = "serve")]
mod serve;
mod shard;
mod signals;
mod split;
#[cfg(feature = "gpu")]
mod view;

use anyhow::Result;
use clap::{Parser, Subcommand};
use names::named;
use vortex_pack::WriteOptions;
use vortex_tiler::pixel::Depth;

#[derive(Parser, Debug)]
#[command(
    name = "vortex-tiler",
    version,
    about = "Cut huge images into virtual-texture tiles with every power-of-two LOD, in bounded memory"
)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Cut one image into tiles plus every power-of-two LOD, streaming it in bands.
    ///
    /// The output directory gets one file per tile of every LOD and an info.json describing the
    /// pyramid (docs/info-json.md). If it already holds an info.json, that file's members set
    /// the defaults for this run (the original tool's behaviour) and flags override them. With
    /// --pack, the tiles go into one pack file instead (docs/pack-format.md).
    ///
    /// Examples:
    ///   vortex-tiler split huge.tif -o out/ --tile-size 128 --border 4 --codec jpeg --quality 85
    ///   vortex-tiler split --input=in.png --output=out
    ///   vortex-tiler split huge.tif --pack world.vtpk --tile-size 128 --border 4
    #[command(verbatim_doc_comment)]
    Split(split::SplitArgs),
    /// Re-tile an already-tiled input to a new tile size and border, regenerating every LOD.
    ///
    /// Only the input tiles of the current band are decoded and held, so memory does not grow
    /// with the grid's height. Output and options are split's.
    ///
    /// Examples:
    ///   vortex-tiler convert in_tiles/ -o out/ --tiled --ff 'x%02s-y%02s.png' --tile-size 128 --border 4
    ///   vortex-tiler convert old/ --pack new.vtpk --tile-size 256        # old/ = split output
    ///   vortex-tiler convert old.vtpk -o out/ --tile-size 64 --border 1
    ///   vortex-tiler convert slide.dzi --pack slide.vtpk                  # Deep Zoom (vips dzsave)
    ///   vortex-tiler convert slide.zip --pack slide.vtpk                  # any of these zipped
    ///   vortex-tiler convert iiif/ --pack iiif.vtpk                       # IIIF 2/3 (iiif/info.json)
    ///   vortex-tiler convert google_tiles/ --input-layout google --pack map.vtpk
    ///   vortex-tiler convert osm_tiles/ --input-layout xyz --pack map.vtpk   # z/x/y
    #[command(verbatim_doc_comment)]
    Convert(convert::ConvertArgs),
    /// Put a tiled directory (info.json + tile files, e.g. from split -o) into one pack file.
    ///
    /// The tile files are stored as they are, unless codec flags name another codec (or other
    /// settings of the same one): then every tile is decoded and encoded again, e.g.
    ///   vortex-tiler pack out/ -o world.vtpk --codec bc7
    #[command(verbatim_doc_comment)]
    Pack(pack::PackArgs),
    /// Write a pack's tiles back out as files plus info.json.
    Unpack(pack::UnpackArgs),
    /// Describe a pack: texture, levels, tile kinds, sizes, deduplication.
    Info(pack::InfoArgs),
    /// Check a pack end to end: structure, every checksum, every byte; report every problem.
    ///
    /// Exits 0 if the pack is sound, 1 otherwise, after listing every problem with its byte
    /// offset and tile. --decode also decodes every tile (sizes checked before allocating).
    Verify(pack::VerifyArgs),
    /// Stream packs through the GPU virtual-texturing runtime along a scene's camera path.
    ///
    /// Headless (a Vulkan, Metal or DX12 adapter; without a GPU, lavapipe from
    /// mesa-vulkan-drivers). Writes PNG frames and a JSON report of what was streamed per frame:
    /// pages requested, loaded and evicted, the share of pixels drawn from a coarser fallback,
    /// the LOD bias, bytes read, pages touched out of all pages, frames to converge. The scene
    /// format is in docs/scenes.md.
    ///
    /// Examples:
    ///   vortex-tiler render --pack world.vtpk --frames out/frames/ --report out/report.json
    ///   vortex-tiler render --pack a.vtpk --pack b.vtpk --scene boxes.json --filter trilinear
    ///   vortex-tiler render --pack albedo.vtpk --layer data:normal.vtpk --show-layer 1
    #[cfg(feature = "gpu")]
    #[command(verbatim_doc_comment)]
    Render(render::RenderArgs),
    /// Show packs in a window: pan and zoom an image, or fly over a scene's geometry.
    ///
    /// Streams in real time through the GPU runtime (no frame waits for a page: the picture
    /// falls back to coarser pages until they land). The title shows the cache's slots in use,
    /// pages in flight, the share of pixels drawn from a coarser page, the filter and the frame
    /// rate.
    ///   drag, wheel, arrows, + -   pan and zoom (2D)     W A S D, Q E, drag   fly (scenes)
    ///   F  next filter    P  residency view (a hue per LOD drawn, red where a coarser page
    ///   stands in)    I  anisotropy 1-16    L  next layer (--layer)    1-9  texture    R  reset
    ///   Esc  quit
    /// --screenshot FILE --frame-count N draws N frames (each waiting for its pages, as render
    /// does), saves the last one and exits: `xvfb-run vortex-tiler view ...` without a display.
    ///
    /// Examples:
    ///   vortex-tiler view world.vtpk
    ///   vortex-tiler view a.vtpk b.vtpk --scene boxes.json --io-latency 50ms
    ///   vortex-tiler view albedo.vtpk --layer data:normal.vtpk --show-layer 1
    ///   xvfb-run vortex-tiler view world.vtpk --size 640x480 --screenshot shot.png --frame-count 30
    #[cfg(feature = "gpu")]
    #[command(verbatim_doc_comment)]
    View(view::ViewArgs),
    /// Serve packs and tile directories over HTTP to web viewers (Deep Zoom, IIIF, XYZ).
    ///
    /// Each input is served under its file stem NAME (a directory under its name):
    ///   /                           the inputs, each with a link to an OpenSeadragon page
    ///   /view/NAME                  OpenSeadragon showing NAME
    ///   /NAME.dzi, /NAME_files/LEVEL/COL_ROW.jpeg|png      Deep Zoom (overlap = border)
    ///   /NAME/iiif/info.json and its tiles                 IIIF Image API 3.0, level 0
    ///   /NAME/xyz/Z/X/Y.jpg|png                            web-map tiles (Leaflet, MapLibre)
    ///   /NAME.vtpk                  the pack itself, with Range requests
    /// Stored JPEG and PNG tiles are sent as they are; edge tiles, levels below one page and
    /// raw, zstd or BC payloads are decoded, cropped and re-encoded (PNG unless the input is
    /// JPEG) and kept in a --cache. Directories written by `split --layout` are served as
    /// their files. Ctrl-C or SIGTERM stop it; the first line on stdout names the address.
    /// Details: docs/serve.md.
    ///
    /// Examples:
    ///   vortex-tiler serve world.vtpk                      # http://127.0.0.1:8080/
    ///   vortex-tiler serve a.vtpk tiles/ dzi_out/ --addr 127.0.0.1:0
    ///   vortex-tiler serve world.vtpk --openseadragon node_modules/openseadragon/build/openseadragon
    ///   vortex-tiler serve world.vtpk --addr 0.0.0.0:8080 --cache 512M   # other machines too
    #[cfg(feature = "serve")]
    #[command(verbatim_doc_comment)]
    Serve(serve::ServeArgs),
    /// Join the shard packs of one split (`split --shard I/N`) into the pack one machine makes.
    ///
    /// Checks that the shards belong together (same input, same options, each index once,
    /// none missing), copies their pages without decoding them, makes the levels above the
    /// shards' cut from the exact sums they carry, and writes a pack byte-identical to
    /// `split --pack` of the same input and options. Details: docs/scale-out.md.
    ///
    /// Examples:
    ///   for i in 0 1 2 3; do vortex-tiler split huge.tif --pack part-$i.vtpk --shard $i/4; done
    ///   vortex-tiler merge part-*.vtpk -o huge.vtpk
    ///   sbatch --array=0-15 ...; vortex-tiler merge parts/*.vtpk -o huge.vtpk   # scripts/slurm/
    ///   vortex-tiler merge s3://tiles/huge.parts/ -o s3://tiles/huge.vtpk   # every object below
    #[command(verbatim_doc_comment)]
    Merge(shard::MergeArgs),
}

/// How a long run works and reports: `split`, `convert` and `merge` share these flags.
#[derive(clap::Args, Debug)]
pub struct RunFlags {
    /// Worker threads for encoding, at most 4 per core [default: one per core]. Output is
    /// identical for any count.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,

    /// No progress bar and no summary line.
    #[arg(short, long)]
    pub quiet: bool,

    /// Print the summary as one JSON object on standard output (for scripts), without the
    /// progress bar.
    #[arg(long)]
    pub json: bool,

    /// After the summary line, a line saying what each stage cost (CPU milliseconds per source
    /// megapixel, which compare across machines' core counts and with other tools, then wall
    /// seconds) and a line saying where the memory went: what each stage held at
    /// most (the source decoder, the read-ahead, the pyramid's rows and bands, the tiles
    /// waiting for or in the encoders, the encoded tiles waiting for the writer) beside
    /// --max-memory and the plan's bound; --json always says it, under `memory`.
    #[arg(short, long, conflicts_with = "quiet")]
    pub verbose: bool,
}

impl RunFlags {
    /// Makes the worker pool `--threads` asks for (checked against the cap first) the process's
    /// global one. The work is then started from the calling thread, not inside the pool: the
    /// encoders' stage waits for batches there, where it blocks no worker.
    pub fn init_pool(&self) -> Result<()> {
        let threads = self.threads.unwrap_or(0);
        vortex_tiler::limits::Limits::default().check_threads(threads)?;
        rayon::ThreadPoolBuilder::new().num_threads(threads).build_global()?;
        Ok(())
    }

    /// The progress bar of a run of `total` tiles; hidden with --quiet or --json.
    pub fn watch(&self, total: u64) -> Result<report::Watch> {
        report::Watch::new(total, self.quiet || self.json)
    }
}

/// Where a pack's bytes go.
#[derive(clap::Args, Debug)]
pub struct PackLayout {
    /// Alignment of a pack's data section, e.g. 4K or 64K.
    #[arg(long, value_name = "SIZE", default_value = "4K", value_parser = parse_size)]
    align: u64,
    /// Alignment of every tile's bytes in a pack; 64K gives each tile its own Vulkan sparse block.
    /// At most 1M: every tile is padded to it.
    #[arg(long, value_name = "SIZE", default_value = "8", value_parser = parse_size)]
    tile_align: u64,
}

impl PackLayout {
    fn options(&self) -> Result<WriteOptions> {
        let check = |v: u64, flag: &str, most: u32| -> Result<u32> {
            match u32::try_from(v) {
                Ok(v) if v.is_power_of_two() && (8..=most).contains(&v) => Ok(v),
                _ => anyhow::bail!(
                    "{flag} {v} must be a power of two from 8 to {}",
                    vortex_tiler::limits::human_bytes(most.into())
                ),
            }
        };
        // The data section is padded to --align once; every tile to --tile-align, hence its
        // lower cap.
        use vortex_tiler::limits::{MAX_ALIGN, MAX_TILE_ALIGN};
        Ok(WriteOptions {
            alignment: check(self.align, "--align", MAX_ALIGN)?,
            payload_alignment: check(self.tile_align, "--tile-align", MAX_TILE_ALIGN)?,
        })
    }
}

pub fn say_line(line: std::fmt::Arguments) {
    use std::io::Write;
    // A name inside a library's description of the source reaches the terminal escaped.
    let line = line.to_string();
    let line = vortex_tiler::error::escape_controls(&line);
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_all(line.as_bytes()).and_then(|()| out.write_all(b"\n")).and_then(|()| out.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(141);
        }
        eprintln!("error: writing to standard output: {e}");
        std::process::exit(1);
    }
}

/// A `--resume` run stopped by a signal: unlike other stopped runs, it leaves what it finished
/// (staged beside its output, or under its `s3://` prefix) for the next `--resume`.
#[derive(Debug, thiserror::Error)]
#[error("interrupted; what was finished stays for --resume")]
pub struct InterruptedForResume;

/// The exit status of a failed run: 128 + the number of the signal that stopped it (130 for
/// Ctrl-C), else 1.
pub fn exit_code(e: &anyhow::Error) -> std::process::ExitCode {
    let interrupted = e.is::<InterruptedForResume>()
        || matches!(
            e.downcast_ref::<vortex_tiler::error::TilerError>(),
            Some(vortex_tiler::error::TilerError::Interrupted)
        );
    match interrupted {
        true => std::process::ExitCode::from(signals::requested().map_or(130, signals::exit_code)),
        false => std::process::ExitCode::FAILURE,
    }
}

pub fn run(args: Args, matches: &clap::ArgMatches) -> Result<()> {
    let sub = matches.subcommand().map(|(_, m)| m);
    match args.command {
        Command::Split(mut a) => {
            a.out.place_flags(sub);
            split::run(a)
        }
        Command::Convert(mut a) => {
            a.out.place_flags(sub);
            convert::run(a)
        }
        Command::Pack(a) => pack::run_pack(a),
        Command::Unpack(a) => pack::run_unpack(a),
        Command::Info(a) => pack::run_info(a),
        Command::Verify(a) => pack::run_verify(a),
        #[cfg(feature = "gpu")]
        Command::Render(a) => render::run(a),
        #[cfg(feature = "gpu")]
        Command::View(a) => view::run(a),
        #[cfg(feature = "serve")]
        Command::Serve(a) => serve::run(a),
        Command::Merge(a) => shard::run_merge(a),
    }
}

fn parse_tile_type(s: &str) -> Result<Depth, String> {
    Depth::from_tile_type(s)
        .ok_or_else(|| format!("'{s}' is not a tile type (unsignedByte, unsignedShort, unsignedInt, float, half)"))
}

/// `1048576`, `512K`, `64M`, `2G`, `1GiB`...
fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim().to_ascii_uppercase();
    let t = t.trim_end_matches("IB").trim_end_matches('B');
    let (num, shift) = match t.chars().last() {
        Some('K') => (&t[..t.len() - 1], 10),
        Some('M') => (&t[..t.len() - 1], 20),
        Some('G') => (&t[..t.len() - 1], 30),
        Some('T') => (&t[..t.len() - 1], 40),
        _ => (t, 0),
    };
    let n: f64 = num.trim().parse().map_err(|_| format!("'{s}' is not a size (e.g. 512M, 4G)"))?;
    if !(n.is_finite() && n >= 0.0) {
        return Err(format!("'{s}' is not a size"));
    }
    let bytes = n * (1u64 << shift) as f64;
    // f64 to u64 saturates: check before converting, so an absurd size is an error.
    if bytes >= (1u64 << 62) as f64 {
        return Err(format!("'{s}' is more than 4E, more than any machine holds"));
    }
    Ok(bytes as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes() {
        assert_eq!(parse_size("1G"), Ok(1 << 30));
        assert_eq!(parse_size("512MiB"), Ok(512 << 20));
        assert_eq!(parse_size("1.5k"), Ok(1536));
        assert_eq!(parse_size("100"), Ok(100));
        assert!(parse_size("lots").is_err());
        assert!(parse_size("16777217T").is_err());
    }
}
