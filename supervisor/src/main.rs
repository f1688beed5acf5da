//! `supervisor`: launches a cell and runs programs on it.

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use supervisor::config::{Config, DEFAULT_TOML};
use supervisor::run::{RunError, RunOptions, run};

#[derive(Parser)]
#[command(
    version,
    about = "Real-time cell supervisor: launches trajgen, servo, iobridge and the machine, runs motion programs"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run a motion program: start the cell, move, settle, stop everything, report.
    Run {
        /// Program file (MOVE/STOP/END, seed 003).
        program: PathBuf,
        /// Cell configuration (TOML); without it, the embedded Gantry UBA cell.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Instance name: prefixes every service and shared-memory file.
        #[arg(long, default_value = runtime::process::DEFAULT_INSTANCE)]
        instance: String,
        /// Write a CSV trace: t_s, cmd_<axis>..., act_<axis>... (one row per setpoint).
        #[arg(long)]
        trace: Option<PathBuf>,
        /// Print one JSON object on stdout instead of the summary.
        #[arg(long)]
        json: bool,
    },
    /// Check a configuration file (or the embedded default) and exit.
    CheckConfig {
        /// Cell configuration (TOML).
        config: Option<PathBuf>,
    },
    /// Print the embedded default configuration.
    DefaultConfig,
}

fn main() -> ExitCode {
    runtime::process::init_logging();
    match Cli::parse().cmd {
        Cmd::DefaultConfig => {
            print!("{DEFAULT_TOML}");
            ExitCode::SUCCESS
        }
        Cmd::CheckConfig { config } => match Config::load(config.as_deref()) {
            Ok(c) => {
                println!(
                    "ok: {} axes ({})",
                    c.axis.len(),
                    c.axis
                        .iter()
                        .map(|a| a.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
        Cmd::Run {
            program,
            config,
            instance,
            trace,
            json,
        } => {
            let opts = RunOptions {
                program,
                config,
                instance,
                trace,
                progress: true,
            };
            match run(&opts) {
                Ok(report) => {
                    if json {
                        println!("{}", report.to_json());
                    } else {
                        print!("{}", report.human());
                    }
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    if json {
                        println!(
                            "{}",
                            serde_json::json!({"ok": false, "error": e.to_string()})
                        );
                    }
                    ExitCode::from(match e {
                        RunError::Input(_) => 2,
                        RunError::Failed(_) => 1,
                        RunError::Interrupted => 130,
                    })
                }
            }
        }
    }
}
