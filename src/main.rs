//! `vortex-tiler`: the command line. Parses flags, opens the input, runs the library's
//! pipeline with a progress bar and prints one summary line. All tiling logic lives in the
//! library; this file is glue.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Args::parse();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", cli::report::chain(&e));
            match e.downcast_ref::<vortex_tiler::error::TilerError>() {
                Some(vortex_tiler::error::TilerError::Interrupted) => cli::interrupted_exit_code(),
                _ => ExitCode::FAILURE,
            }
        }
    }
}
