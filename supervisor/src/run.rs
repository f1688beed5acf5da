//! `supervisor run`: one program on one instance of the cell, start to clean exit: `up`,
//! `exec --wait` and `down` in one command.
//!
//! 1. Load and validate the configuration and the program (nothing starts on an error).
//! 2. Open the cell ([`crate::cell::open_cell`]): the instance's lock, cleanup of what a
//!    killed run left, the services, every process.
//! 3. Serve it ([`crate::serve`]) with the program queued: enable the arm, run the program
//!    ([`crate::job::Job`]), answer control requests meanwhile (`status`, `estop`, `pause`…).
//! 4. Stop every process (SIGTERM, then SIGKILL), drop our ports, check that no iceoryx2
//!    resource of the instance is left, and report.

use crate::cell::{Mode, open_recorded};
use crate::error::RunError;
use crate::out::writable;
use crate::program::{Checked, Predicted};
use crate::report::Report;
use crate::report::trace_csv;
use crate::serve::{self, End, ProgramJob};
use cell_config::Config;
use control_plane::Failure;
use shm_schema::InstanceName;
use std::path::PathBuf;

/// What `supervisor run` was asked to do.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// The program file.
    pub program: PathBuf,
    /// The configuration file; `None` for the embedded default.
    pub config: Option<PathBuf>,
    /// Instance name.
    pub instance: String,
    /// Trace CSV to write.
    pub trace: Option<PathBuf>,
    /// MCAP file to record the cell into (`--record`).
    pub record: Option<PathBuf>,
    /// PNG of the run's figures to write (`--plot`).
    pub plot: Option<PathBuf>,
    /// Show progress on stderr.
    pub progress: bool,
    /// Run on the virtual clock whatever the configuration says (`--virtual-time`).
    pub virtual_time: bool,
    /// Faults at instants of the virtual clock (`--fault`).
    pub faults: Vec<crate::schedule::ScheduledFault>,
}

/// Reads and checks the program at `path` on `cfg`'s cell from the axes' configured start
/// (`supervisor check`, and `run` before anything starts): parsed, every target within the
/// limits, run through trajgen's generator. Returns it with its prediction.
pub fn check_program(
    cfg: &Config,
    path: &std::path::Path,
) -> Result<(Checked, Predicted), RunError> {
    let bytes = std::fs::read(path)
        .map_err(|e| RunError::Input(format!("{}: cannot read: {e}", path.display())))?;
    let program = Checked::new(cfg, &path.display().to_string(), &bytes)?;
    let start: Vec<f64> = cfg.axis.iter().map(|a| a.start).collect();
    let predicted = program.predict(cfg, &start)?;
    Ok((program, predicted))
}

/// Runs a program; see the module documentation.
pub fn run(opts: &RunOptions) -> Result<Report, RunError> {
    let mut cfg =
        Config::load(opts.config.as_deref()).map_err(|e| RunError::Input(e.to_string()))?;
    if opts.virtual_time {
        cfg.cell.clock = cell_config::Clock::Virtual;
    }
    let (program, _) = check_program(&cfg, &opts.program)?;
    let instance = InstanceName::new(&opts.instance)
        .map_err(|e| RunError::Input(format!("--instance {:?}: {e}", opts.instance)))?;
    for (path, flag) in [
        (&opts.trace, "--trace"),
        (&opts.plot, "--plot"),
        (&opts.record, "--record"),
    ] {
        if let Some(p) = path {
            writable(p, flag).map_err(RunError::Input)?;
        }
    }
    let faults = crate::schedule::plan(&opts.faults, &cfg).map_err(RunError::Input)?;
    let (mut cell, mut server, recorder) =
        open_recorded(&cfg, instance, Mode::Run, opts.record.as_deref())?;
    cell.schedule(&faults);
    let first = ProgramJob {
        program,
        progress: opts.progress,
        plot: opts.plot.is_some(),
    };
    let served = serve::serve(
        &cfg,
        &mut cell,
        &mut server,
        Some(serve::First::Program(first)),
        recorder,
    );
    cell.refresh_latency();
    let processes = serve::process_reports(&cell);
    let latency_figures = serve::latency_figures(&cell);
    let sense_to_command = cell.sense_to_command.take();
    let recorded = served.recorded.transpose();
    if let Ok(Some(summary)) = &recorded {
        crate::out::line(summary.trim_end());
    }
    let virtual_time = cell.clock.as_ref().map(|c| {
        let (virtual_s, wall_s) = (c.virtual_s(), c.wall_s());
        control_plane::report::VirtualTime {
            virtual_s,
            wall_s,
            speed_up: virtual_s / wall_s.max(1e-9),
            cycles: c.grants(),
        }
    });
    let closed = cell.close(server);
    let mut report = match served.end {
        End::Program(r) => match *r {
            Ok(r) => r,
            Err(RunError::Failed {
                failure, figures, ..
            }) => {
                // The figures up to the failure: what a user looks at to see why.
                if let (Some(path), Some(mut f)) = (&opts.plot, figures) {
                    f.latency = latency_figures;
                    match cell_client::figures::write_png(&f, path) {
                        Ok(()) => eprintln!("figures up to the failure: {}", path.display()),
                        Err(e) => eprintln!("{e}"),
                    }
                }
                return Err(RunError::Failed {
                    failure,
                    events: closed.events,
                    figures: None,
                });
            }
            Err(e) => return Err(e),
        },
        End::Interrupted => return Err(RunError::Interrupted),
        End::Failed(e) => return Err(*e),
        End::Down | End::Tuned(_) => {
            return Err(RunError::failed(Failure::Down {
                job: "the program".into(),
            }));
        }
    };
    report.add_cell_figures(processes, latency_figures, sense_to_command.as_deref());
    report.run.events = closed.events;
    report.run.virtual_time = virtual_time;
    if let Some(e) = closed.problem {
        return Err(e);
    }
    // The program ran; its recording did not (a disk full): the run fails.
    recorded?;
    if let Some(path) = &opts.trace {
        std::fs::write(path, trace_csv(&report))
            .map_err(|e| RunError::system(format!("{}: {e}", path.display())))?;
    }
    if let (Some(path), Some(f)) = (&opts.plot, &report.figures) {
        cell_client::figures::write_png(f, path).map_err(RunError::system)?;
    }
    Ok(report)
}
