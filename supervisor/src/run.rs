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

use crate::cell::{Cell, Mode, open_cell};
use crate::config::Config;
use crate::job::Enabling;
use crate::report::Report;
use crate::serve::{self, End, ProgramJob};
use motion_program::Program;
use runtime::signals;
use shm_schema::{InstanceName, SetpointV1};
use std::path::PathBuf;
use std::time::Duration;

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
    /// Show progress on stderr.
    pub progress: bool,
}

/// Why a run failed.
#[derive(Debug)]
pub enum RunError {
    /// Bad input (program, configuration, instance): nothing was started. Exit code 2.
    Input(String),
    /// The run started and failed. Exit code 1.
    Failed {
        /// What went wrong.
        message: String,
        /// The events of the run up to the failure (`docs/events.md`).
        events: Vec<serde_json::Value>,
    },
    /// Ctrl-C / SIGTERM. Exit code 130.
    Interrupted,
}

impl RunError {
    /// A started run failed (its events are attached when the run ends).
    pub fn failed(message: impl Into<String>) -> Self {
        Self::Failed {
            message: message.into(),
            events: Vec::new(),
        }
    }

    /// The events the failed run recorded.
    pub fn events(&self) -> &[serde_json::Value] {
        match self {
            Self::Failed { events, .. } => events,
            _ => &[],
        }
    }
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Input(m) | RunError::Failed { message: m, .. } => f.write_str(m),
            RunError::Interrupted => f.write_str("interrupted; every process was stopped"),
        }
    }
}

pub(crate) const TICK: Duration = Duration::from_millis(10);

/// Parses `src` (named `name` in messages) and checks it against the cell's limits.
pub(crate) fn parse_program(cfg: &Config, name: &str, src: &str) -> Result<Program, RunError> {
    motion_program::parse(src, cfg.axis.len())
        .and_then(|p| p.check_limits(&cfg.axis_specs()).map(|()| p))
        .map_err(|e| RunError::Input(format!("{name}:{}:{}: {}", e.line, e.col, e.message)))
}

/// Runs a program; see the module documentation.
pub fn run(opts: &RunOptions) -> Result<Report, RunError> {
    let cfg = Config::load(opts.config.as_deref()).map_err(|e| RunError::Input(e.to_string()))?;
    let src = std::fs::read_to_string(&opts.program)
        .map_err(|e| RunError::Input(format!("{}: cannot read: {e}", opts.program.display())))?;
    let name = opts.program.display().to_string();
    let program = parse_program(&cfg, &name, &src)?;
    let instance = InstanceName::new(&opts.instance)
        .map_err(|e| RunError::Input(format!("--instance {:?}: {e}", opts.instance)))?;
    let (mut cell, mut server) = open_cell(&cfg, instance, Mode::Run)?;
    let first = ProgramJob {
        name,
        program,
        src,
        progress: opts.progress,
    };
    let end = serve::serve(&cfg, &mut cell, &mut server, Some(first));
    cell.refresh_latency();
    let processes = serve::process_reports(&cell);
    let sense_to_command = cell.sense_to_command.take();
    let closed = cell.close(server);
    let mut report = match end {
        End::Program(r) => match *r {
            Ok(r) => r,
            Err(RunError::Failed { message, .. }) => {
                return Err(RunError::Failed {
                    message,
                    events: closed.events,
                });
            }
            Err(e) => return Err(e),
        },
        End::Interrupted => return Err(RunError::Interrupted),
        End::Down => {
            return Err(RunError::failed(
                "`supervisor down` stopped the cell before the program ended",
            ));
        }
    };
    report.sense_to_command = sense_to_command
        .as_deref()
        .filter(|h| h.count > 0)
        .map(latency::report::Summary::of);
    report.processes = processes;
    report.events = closed.events;
    if let Some(e) = closed.problem {
        return Err(e);
    }
    if let Some(path) = &opts.trace {
        std::fs::write(path, trace_csv(&report))
            .map_err(|e| RunError::failed(format!("{}: {e}", path.display())))?;
    }
    Ok(report)
}

/// The trace as CSV: `t_s, cmd_<axis>..., act_<axis>...`, one row per setpoint.
pub(crate) fn trace_csv(report: &Report) -> String {
    use std::fmt::Write as _;
    let n = report.axes.len();
    let mut out = String::new();
    let mut header = vec!["t_s".to_string()];
    header.extend(report.axes.iter().map(|a| format!("cmd_{a}")));
    header.extend(report.axes.iter().map(|a| format!("act_{a}")));
    let _ = writeln!(out, "{}", header.join(","));
    for r in &report.trace {
        let _ = write!(out, "{:.6}", r.t_s);
        for v in &r.cmd[..n] {
            let _ = write!(out, ",{v:.6}");
        }
        for v in &r.act[..n] {
            let _ = write!(out, ",{v:.6}");
        }
        let _ = writeln!(out);
    }
    out
}

/// Blocking helpers for commands that drive the cell step by step (`tune`).
impl Cell {
    /// One tick: fails on any incident, an e-stop or a signal.
    pub(crate) fn check_health(&mut self, cfg: &Config) -> Result<(), RunError> {
        if signals::stop_requested() {
            return Err(RunError::Interrupted);
        }
        if let Some(i) = self.tick(cfg).first() {
            return Err(RunError::failed(i.to_string()));
        }
        if self.estop.is_some() && !self.reactions_pending() {
            return Err(RunError::failed(
                self.estop_text().unwrap_or_else(|| "e-stop".into()),
            ));
        }
        Ok(())
    }

    /// Enables the arm; the first setpoint from after the enable.
    pub(crate) fn startup(&mut self, cfg: &Config) -> Result<SetpointV1, RunError> {
        let mut en = Enabling::new(cfg);
        loop {
            self.check_health(cfg)?;
            self.drain_motion();
            if let Some(r) = en.step(self) {
                return r;
            }
            std::thread::sleep(TICK);
        }
    }
}
