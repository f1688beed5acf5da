//! What the supervisor's benchmarks share: their one option.

use clap::{CommandFactory, FromArgMatches, Parser};
use std::path::{Path, PathBuf};

/// The repository's root.
#[allow(dead_code)] // not every benchmark needs it
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A binary of the release build.
pub fn binary(name: &str) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"))
        .join("release")
        .join(name)
}

#[derive(Parser)]
struct Options {
    /// Rounds, each one run per configuration.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    rounds: u32,
    // `cargo bench` passes it.
    #[arg(long, hide = true)]
    bench: bool,
}

/// The rounds asked for on the command line (`--rounds N`, 3 by default) of the benchmark
/// `name`, which `about` describes; exits with a usage message on anything else.
pub fn rounds(name: &'static str, about: &'static str) -> usize {
    let matches = Options::command().name(name).about(about).get_matches();
    Options::from_arg_matches(&matches).map_or_else(|e| e.exit(), |o| o.rounds as usize)
}
