//! `supervisor`: launches a cell and runs programs on it.

use cell_config::{Config, DEFAULT_TOML};
use clap::{Parser, Subcommand};
use control_plane::channel as ctl;
use control_plane::{Reply, Request};
use latency::command::{LatencyArgs, LatencyError, latency};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use supervisor::error::RunError;
use supervisor::run::{RunOptions, run};

#[derive(Parser)]
#[command(
    version,
    about = "Real-time cell supervisor: launches trajgen, servo, iobridge and the machine, runs motion programs"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

/// `--instance NAME`: the cell a command acts on, declared once for every command that takes
/// it (`tune` has a default of its own, `latency` none).
#[derive(clap::Args, Clone, Debug)]
struct Instance {
    /// Instance name: prefixes every service and shared-memory file.
    // Its id is `instance`: an id of `name` would be the same argument as `io`'s NAME.
    #[arg(long, value_name = "NAME", default_value = runtime::process::DEFAULT_INSTANCE)]
    instance: String,
}

impl std::ops::Deref for Instance {
    type Target = str;

    fn deref(&self) -> &str {
        &self.instance
    }
}

impl std::fmt::Display for Instance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.instance)
    }
}

/// `supervisor exec`'s arguments.
#[derive(clap::Args, Debug)]
struct ExecArgs {
    /// Program file.
    program: PathBuf,
    #[command(flatten)]
    instance: Instance,
    #[command(flatten)]
    remote: Remote,
    /// Wait until the program ends and print the report `run` prints.
    #[arg(long)]
    wait: bool,
    /// One JSON document on stdout: with --wait, the run's report (or its failure) as `run
    /// --json` prints it, instead of the summary; without --wait, or when the cell refused the
    /// program or failed it before it ran, the cell's reply (`control_plane::Reply`, as the
    /// other commands' --json print it). Exit status as without it.
    #[arg(long)]
    json: bool,
    /// With --wait: write the CSV trace.
    #[arg(long, requires = "wait")]
    trace: Option<PathBuf>,
    /// With --wait: record every service of the cell into this MCAP file while the
    /// program runs.
    #[arg(long, requires = "wait")]
    record: Option<PathBuf>,
    /// With --wait: write the PNG `run --plot` writes.
    #[arg(long, requires = "wait")]
    plot: Option<PathBuf>,
}

/// `--remote CELL`: a cell of the line (docs/network.md) instead of this host's instance; the
/// command goes to the cell's gateway through `gateway line`.
#[derive(clap::Args, Clone, Debug)]
struct Remote {
    /// A cell on the line, by its name there, instead of an instance of this host.
    #[arg(long, value_name = "CELL", conflicts_with = "instance")]
    remote: Option<String>,
    /// With --remote: the line file (endpoints, user, secret); default: $RTC_LINE.
    #[arg(long, value_name = "FILE", requires = "remote")]
    line: Option<PathBuf>,
}

/// `--json` of a command that asks the cell one thing (`pause`, `speed`, `reset`, `swap`, ...):
/// the cell's answer, for a program to read (docs/operations.md).
#[derive(clap::Args, Clone, Copy, Debug)]
struct ReplyJson {
    /// Print the cell's reply as one JSON document on stdout (`control_plane::Reply` as serde
    /// writes it: `{"Done": …}`, `{"Refused": …}`, `{"Failed": …}`, …), whether it was done,
    /// refused or failed; the exit status as without it (0 done, 2 refused, 1 failed). A
    /// command that got no reply (the cell is not up, the channel broke) prints nothing on
    /// stdout.
    #[arg(long)]
    json: bool,
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
        #[command(flatten)]
        instance: Instance,
        /// Write a CSV trace: t_s, cmd_<axis>..., act_<axis>... (one row per setpoint).
        #[arg(long)]
        trace: Option<PathBuf>,
        /// Print one JSON object on stdout instead of the summary.
        #[arg(long)]
        json: bool,
        /// Record every service of the cell into this MCAP file (docs/recording.md).
        #[arg(long)]
        record: Option<PathBuf>,
        /// Write a PNG: the commanded and measured path, the following error of every axis
        /// over the run, each process' wake-up latency histogram.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Run the cell on its virtual clock (`[cell] clock = "virtual"`, docs/virtual-time.md):
        /// the same run every time, as fast as the CPUs allow.
        #[arg(long)]
        virtual_time: bool,
        /// A fault at an instant of the virtual clock (repeatable): `AT:hold:PROCESS:MS` (no
        /// cycle for MS ms from AT), `AT:kill:PROCESS` (SIGKILL at AT), `AT:estop` (the
        /// user's e-stop); AT in seconds of the cell's clock, as the events' times.
        #[arg(long = "fault", value_name = "AT:WHAT")]
        faults: Vec<supervisor::schedule::ScheduledFault>,
    },
    /// Serve the cell in a browser: a 3D view from its kinematics, live, the program line,
    /// plots, the process table, e-stop / reset / start (docs/web.md). It attaches to the
    /// instance whenever it is up, and waits for it when it is not; until SIGINT or SIGTERM.
    Web {
        #[command(flatten)]
        instance: Instance,
        /// Address to listen on (port 0: any free port, printed). Anything but a loopback
        /// address needs --token.
        #[arg(long, default_value = "127.0.0.1:8080")]
        listen: String,
        /// A token every client must give (`?token=` in the page's address).
        #[arg(long)]
        token: Option<String>,
        /// Instead of this host's instance: every cell of a line (its line file,
        /// docs/network.md), listed, and the 3D view of the one chosen. Only shows.
        #[arg(long, value_name = "FILE", conflicts_with = "instance")]
        line: Option<PathBuf>,
    },
    /// Serve the cell live to Foxglove (its WebSocket protocol): every service of the cell as
    /// a channel, the recorder's JSON messages and schemas (docs/recording.md). It reads the
    /// cell while a client is connected, waits for it when it is not up; until SIGINT or
    /// SIGTERM. Only shows: a client may subscribe, nothing else.
    Foxglove {
        #[command(flatten)]
        instance: Instance,
        /// Address to listen on (port 0: any free port, printed). Anything but a loopback
        /// address needs --token.
        #[arg(long, default_value = "127.0.0.1:8765")]
        listen: String,
        /// A token every client must give (`?token=` in the server's address).
        #[arg(long)]
        token: Option<String>,
        /// An origin whose pages may connect, besides the Foxglove app's (repeatable).
        #[arg(long, value_name = "ORIGIN")]
        allow_origin: Vec<String>,
    },
    /// Record every service of a running cell into an MCAP file (for Foxglove, PlotJuggler):
    /// until SIGINT/SIGTERM, `--duration`, or the cell going down (docs/recording.md).
    Record {
        #[command(flatten)]
        args: recorder::RecordArgs,
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        remote: Remote,
    },
    /// Bring a cell up and keep it up, cyclic, drives enabled and holding, until `down`,
    /// SIGTERM or SIGINT. Logs on stderr. Control it from other shells (docs/operations.md).
    Up {
        /// Cell configuration (TOML); without it, the embedded Gantry UBA cell.
        #[arg(long)]
        config: Option<PathBuf>,
        #[command(flatten)]
        instance: Instance,
        /// Record every service of the cell into this MCAP file until it goes down.
        #[arg(long)]
        record: Option<PathBuf>,
        /// As it ends, print how it went down and every event of its life as one JSON
        /// document on stdout (docs/schema/up.schema.json).
        #[arg(long)]
        json: bool,
        /// Run the cell on its virtual clock (`[cell] clock = "virtual"`, docs/virtual-time.md).
        #[arg(long)]
        virtual_time: bool,
    },
    /// Stop a cell that is up: every process leaves safely, nothing of the instance is left.
    Down {
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        json: ReplyJson,
    },
    /// Validate a program and run it on a cell that is up.
    Exec(ExecArgs),
    /// The live speed override: run the path at PERCENT (1..=100) of its programmed speed
    /// from now on, smoothly (within t_acc), without leaving it.
    Speed {
        /// 1 to 100.
        percent: f64,
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        remote: Remote,
        #[command(flatten)]
        json: ReplyJson,
    },
    /// Check a program without starting anything: the same validation `run` and `exec` make
    /// (syntax, names, limits, the whole blended path through trajgen's generator) and its
    /// predicted duration from the axes' configured start. Exit 0, or 2 with the errors.
    Check {
        /// Program file.
        program: PathBuf,
        /// Cell configuration (TOML); the embedded default when omitted.
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Decelerate every axis to rest along the path (within t_acc) and hold.
    Pause {
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        json: ReplyJson,
        #[command(flatten)]
        remote: Remote,
    },
    /// Go on along the path after a pause.
    Resume {
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        json: ReplyJson,
        #[command(flatten)]
        remote: Remote,
    },
    /// Come to rest along the path and drop the rest of the program (not an e-stop).
    Abort {
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        json: ReplyJson,
        #[command(flatten)]
        remote: Remote,
    },
    /// Clear the e-stop and servo's latched faults where their cause is gone; says what
    /// cannot be cleared and why. The drives stay disabled until `start`.
    Reset {
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        json: ReplyJson,
        #[command(flatten)]
        remote: Remote,
    },
    /// Enable the drives, holding where the axes stand (bumpless).
    Start {
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        json: ReplyJson,
        #[command(flatten)]
        remote: Remote,
    },
    /// Stop one process of the cell and start it again.
    Restart {
        /// Its name in the process table.
        process: String,
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        json: ReplyJson,
    },
    /// Replace one process of the cell by a new one (a new build, another program, another
    /// language) while the others keep running.
    Swap {
        /// Its name in the process table.
        process: String,
        /// The new command line ("PROGRAM ARGS…", split on whitespace; {instance} and {name}
        /// are substituted); without it, the configured command starts again.
        #[arg(long)]
        command: Option<String>,
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        json: ReplyJson,
    },
    /// Check a configuration file (or the embedded default) and exit.
    CheckConfig {
        /// Cell configuration (TOML).
        config: Option<PathBuf>,
    },
    /// Print the embedded default configuration.
    DefaultConfig,
    /// List the cells on the line (docs/network.md): name, host, state, program, e-stop.
    Cells {
        /// The line file (endpoints, user, secret); default: $RTC_LINE.
        #[arg(long, value_name = "FILE")]
        line: Option<PathBuf>,
        /// One JSON array instead of the table (with --watch: one JSON object a line).
        #[arg(long)]
        json: bool,
        /// A line each time a cell comes onto the line or leaves it, until Ctrl-C.
        #[arg(long)]
        watch: bool,
    },
    /// Show the processes of a running instance: state, cycles, overruns and wake-up latency
    /// percentiles since they started.
    Status {
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        remote: Remote,
        /// Print one JSON object instead of the table.
        #[arg(long)]
        json: bool,
        /// Refresh in place every half second, like `top`, until Ctrl-C.
        #[arg(long, conflicts_with = "json")]
        watch: bool,
    },
    /// Measure latency like cyclictest: the cycle runtime's timer wake-up (one thread per
    /// CPU) and the one-way IPC hop between two processes, each test for the duration.
    #[command(
        after_help = "Output: one line per thread like cyclictest's (µs), with \
        p50/p99/p99.9/p99.99 and Ovf (samples >= --histogram-us). Ctrl-C prints the figures \
        so far. --histfile writes cyclictest's histogram format; --plot a PNG of it."
    )]
    Latency(LatencyArgs),
    /// Commissioning: start the cell, step one axis (and optionally move it out and back),
    /// report rise time, overshoot, settling time and peak following error, stop the cell.
    Tune {
        /// Axis name.
        #[arg(long)]
        axis: String,
        /// Step amplitude (axis unit; at most half the axis' following-error limit).
        #[arg(long, allow_hyphen_values = true)]
        step: f64,
        /// Also move the axis this far and back at its vmax (axis unit).
        #[arg(long, allow_hyphen_values = true)]
        ramp: Option<f64>,
        /// Cell configuration (TOML); without it, the embedded Gantry UBA cell.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Instance name.
        #[arg(long, default_value = "tune")]
        instance: String,
        /// Print one JSON object on stdout instead of the summary.
        #[arg(long)]
        json: bool,
        /// Write a PNG of command, position and effort.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Print the events of a running instance as they happen (docs/events.md).
    Events {
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        remote: Remote,
        /// Keep printing until Ctrl-C (without it: what arrives within half a second).
        #[arg(long, short = 'f')]
        follow: bool,
        /// One JSON object per line instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Inject a fault condition into a simulated drive of a running instance (or clear it).
    Inject {
        #[command(flatten)]
        instance: Instance,
        /// Axis name.
        #[arg(long)]
        axis: String,
        /// over-current, encoder-loss or following-error.
        fault: String,
        /// Clear the condition instead of raising it.
        #[arg(long)]
        clear: bool,
    },
    /// Raise the user's e-stop on a running instance (seed 002's trigger_estop): every process
    /// reads it in its own cycle; servo brings the axes to rest and disables the drives.
    Estop {
        #[command(flatten)]
        instance: Instance,
        #[command(flatten)]
        remote: Remote,
        /// Why, in a few words (kept in the e-stop and its events).
        #[arg(long, default_value = "operator e-stop")]
        reason: String,
        #[command(flatten)]
        json: ReplyJson,
    },
    /// List the named digital IO of a running instance, or set one: an output as a program's
    /// OUT does, an input as a device of the simulated field would (docs/io.md).
    Io {
        #[command(flatten)]
        instance: Instance,
        /// The IO's name (`[[io]]`); none lists them all.
        name: Option<String>,
        /// 0 or 1.
        value: Option<String>,
    },
    /// The sending side of a latency hop (started by `supervisor latency`).
    #[command(hide = true, name = "latency-peer")]
    LatencyPeer(latency::peer::Args),
}

/// A command for a cell of the line: `gateway line`'s line file and arguments; `None` for a
/// command on this host.
type OnTheLine = Result<(Option<PathBuf>, Vec<String>), String>;

fn remote_of(cmd: &Cmd) -> Option<OnTheLine> {
    let at = |r: &Remote, args: &[&str]| {
        let cell = r.remote.as_ref()?;
        let mut v: Vec<String> = args.iter().map(|a| a.to_string()).collect();
        v.insert(1, cell.clone());
        Some(Ok((r.line.clone(), v)))
    };
    // The line's client prints the cell's answer in words only.
    let json_on_the_line = match cmd {
        Cmd::Pause { remote, json, .. }
        | Cmd::Resume { remote, json, .. }
        | Cmd::Abort { remote, json, .. }
        | Cmd::Reset { remote, json, .. }
        | Cmd::Start { remote, json, .. }
        | Cmd::Speed { remote, json, .. }
        | Cmd::Estop { remote, json, .. } => json.json && remote.remote.is_some(),
        Cmd::Exec(ExecArgs { remote, json, .. }) => *json && remote.remote.is_some(),
        _ => false,
    };
    if json_on_the_line {
        return Some(Err(
            "--json is for an instance of this host, not --remote".into()
        ));
    }
    match cmd {
        Cmd::Pause { remote, .. } => at(remote, &["pause"]),
        Cmd::Resume { remote, .. } => at(remote, &["resume"]),
        Cmd::Abort { remote, .. } => at(remote, &["abort"]),
        Cmd::Reset { remote, .. } => at(remote, &["reset"]),
        Cmd::Start { remote, .. } => at(remote, &["start"]),
        Cmd::Speed {
            remote, percent, ..
        } => at(remote, &["speed", &percent.to_string()]),
        Cmd::Estop { remote, reason, .. } => at(remote, &["estop", "--reason", reason]),
        Cmd::Status {
            remote,
            json,
            watch,
            ..
        } => {
            remote.remote.as_ref()?;
            if *watch {
                return Some(Err(
                    "--watch is for an instance of this host, not --remote".into()
                ));
            }
            at(
                remote,
                if *json {
                    &["status", "--json"]
                } else {
                    &["status"]
                },
            )
        }
        Cmd::Events {
            remote,
            follow,
            json,
            ..
        } => {
            let mut args = vec!["events"];
            if !*follow {
                // As on this host: what arrives within half a second.
                args.extend(["--seconds", "0.5"]);
            }
            if *json {
                args.push("--json");
            }
            at(remote, &args)
        }
        Cmd::Exec(ExecArgs {
            remote,
            program,
            wait,
            ..
        }) => {
            remote.remote.as_ref()?;
            if *wait {
                return Some(Err(
                    "exec --wait (and its report, trace, recording, plot) is for an instance of this host, not --remote".into(),
                ));
            }
            at(remote, &["exec", &program.display().to_string()])
        }
        Cmd::Record { remote, args, .. } => {
            let mut v = vec!["record".to_string()];
            v.extend(args.to_args());
            at(remote, &v.iter().map(String::as_str).collect::<Vec<_>>())
        }
        _ => None,
    }
}

/// Runs `gateway line [--line FILE] ARGS` (next to this program, or on PATH) in this
/// process' place.
fn on_the_line(line: Option<&std::path::Path>, args: &[String]) -> ExitCode {
    use std::os::unix::process::CommandExt;
    let gateway = match cell_config::find_program("gateway") {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: the line's client: {e}");
            return ExitCode::from(2);
        }
    };
    let mut cmd = std::process::Command::new(gateway);
    cmd.arg("line");
    if let Some(l) = line {
        cmd.arg("--line").arg(l);
    }
    let e = cmd.args(args).exec();
    eprintln!("error: cannot run the line's client: {e}");
    ExitCode::FAILURE
}

/// Reports a one-shot command to a running instance (`inject`, `estop`): its message on
/// stdout, exit 0; or its error, exit 2 for bad input, 1 when it failed.
fn control_done(r: Result<String, cell_client::control::ControlError>) -> ExitCode {
    match r {
        Ok(msg) => {
            println!("{msg}");
            ExitCode::SUCCESS
        }
        Err(e) => failed(
            &e,
            matches!(
                e,
                cell_client::control::ControlError::Input(_)
                    | cell_client::control::ControlError::Refused(_)
            ),
        ),
    }
}

/// `supervisor estop --json`: its answer as the cell's [`Reply`] on stdout (the words on
/// stderr as without it), the same exit status. Bad input or no cell: no reply, nothing on
/// stdout.
fn estop_reply(r: Result<String, cell_client::control::ControlError>) -> ExitCode {
    use cell_client::control::ControlError;
    let reply = match r {
        Ok(m) => Reply::Done(m),
        Err(ControlError::Refused(r)) => Reply::Refused(r),
        Err(ControlError::Cell(f)) => Reply::Failed(f),
        Err(ControlError::Failed(what)) => Reply::Failed(control_plane::Failure::System { what }),
        Err(e @ ControlError::Input(_)) => return failed(&e, true),
    };
    ctl_reply(reply, true, None, None)
}

/// Prints a finished `run`'s or `tune`'s report, as JSON with `--json`, else for people.
fn printed(
    json: bool,
    as_json: impl FnOnce() -> String,
    human: impl FnOnce() -> String,
) -> ExitCode {
    if json {
        println!("{}", as_json());
    } else {
        print!("{}", human());
    }
    ExitCode::SUCCESS
}

/// `supervisor up`: the cell up until it is told to go down; with `json`, how it ended and
/// its events as one document on stdout.
fn up(
    config: Option<&Path>,
    instance: &str,
    record: Option<&Path>,
    json: bool,
    virtual_time: bool,
) -> ExitCode {
    let (ended, events) = supervisor::up::up(config, instance, record, virtual_time);
    if json {
        let doc = control_plane::report::UpEnded {
            instance: instance.to_string(),
            ok: ended.is_ok(),
            ended: match &ended {
                Ok(msg) => msg.clone(),
                Err(e) => e.to_string(),
            },
            events,
        };
        println!("{}", serde_json::to_string(&doc).unwrap_or_default());
    }
    match ended {
        Ok(msg) => {
            tracing::info!("{msg}");
            ExitCode::SUCCESS
        }
        Err(e) => run_failed(&e, false),
    }
}

/// Reports a failed `run` or `tune` (on stderr, and as JSON with `--json`) and its exit
/// status: 2 bad input, 1 failed, 130 interrupted.
fn run_failed(e: &RunError, json: bool) -> ExitCode {
    if json {
        println!(
            "{}",
            serde_json::to_string(&e.document()).unwrap_or_default()
        );
    }
    // Through the non-blocking writer where the command has one: a blocked stderr must not
    // keep the verdict (the exit status, the JSON above) from the caller.
    supervisor::out::line(errors(&e).trim_end());
    ExitCode::from(match e {
        RunError::Input(_) => 2,
        RunError::Failed { .. } => 1,
        RunError::Interrupted => 130,
    })
}

/// A client's output piped into a reader that stops early (`status --watch | head`) ends the
/// command quietly, as it ends any Unix tool: SIGPIPE back to its default. Rust ignores it,
/// so the next `println!` panicked, and `abort_on_panic` turned that into an abort with a
/// backtrace. Not for the commands that keep a cell (`up`, `run`, `tune`) or serve one (`web`,
/// `record`): they must never die half-way.
fn quiet_on_a_closed_pipe() {
    use nix::sys::signal::{SigHandler, Signal, signal};
    // SAFETY: SIG_DFL installs no handler of ours; no other thread runs yet.
    let _ = unsafe { signal(Signal::SIGPIPE, SigHandler::SigDfl) };
}

/// Logging on stderr through `tracing`. For the commands that watch a cell (`up`, `run`,
/// `tune`) the writer is non-blocking: a full pipe or a paused terminal loses lines, never
/// stalls the supervisor. The guard flushes on exit.
fn init_logging(watching: bool) -> Vec<tracing_appender::non_blocking::WorkerGuard> {
    if !watching {
        runtime::process::init_logging();
        return Vec::new();
    }
    // The run's events and progress: non-blocking too.
    let (lines, lines_guard) = tracing_appender::non_blocking::NonBlockingBuilder::default()
        .lossy(true)
        .buffered_lines_limit(4096)
        .finish(std::io::stderr());
    supervisor::out::set(lines);
    let guard = runtime::process::init_logging_lossy();
    vec![guard, lines_guard]
}

/// The instance named on the command line, or exit 2.
fn instance_of(name: &str) -> Result<shm_schema::InstanceName, ExitCode> {
    shm_schema::InstanceName::new(name).map_err(|e| {
        eprintln!("error: --instance {name:?}: {e}");
        ExitCode::from(2)
    })
}

/// Sends one request to a cell that is up and reports its answer (with `json`, as one JSON
/// document on stdout): exit 0 done, 2 refused (or not up), 1 failed.
fn ctl_call(instance: &str, req: Request, json: bool) -> ExitCode {
    let instance = match instance_of(instance) {
        Ok(i) => i,
        Err(c) => return c,
    };
    match ctl::call(&instance, &req) {
        Ok(reply) => ctl_reply(reply, json, None, None),
        Err(e) => {
            eprint!("{}", errors(&e));
            ExitCode::from(e.exit_code())
        }
    }
}

/// Reports the cell's answer and its exit status: 0 done, 2 refused, 1 failed. With `json`
/// one JSON document on stdout: a program's report (`exec --wait`) as `run --json` prints it,
/// any other answer as the [`Reply`] itself; a refusal or a failure is said on stderr too.
fn ctl_reply(
    reply: Reply,
    json: bool,
    trace: Option<&std::path::Path>,
    plot: Option<&std::path::Path>,
) -> ExitCode {
    if json && !matches!(reply, Reply::Report { .. }) {
        println!("{}", serde_json::to_string(&reply).unwrap_or_default());
        // The words of a refusal or a failure on stderr, and the exit status, as without it.
        return match reply {
            Reply::Refused(_) | Reply::Failed(_) => ctl_reply(reply, false, trace, plot),
            _ => ExitCode::SUCCESS,
        };
    }
    match reply {
        Reply::Done(m) => {
            println!("{m}");
            ExitCode::SUCCESS
        }
        Reply::Replaced(r) => {
            println!("{}", r.text());
            ExitCode::SUCCESS
        }
        Reply::Info(info) => {
            println!("{}", serde_json::to_string(&info).unwrap_or_default());
            ExitCode::SUCCESS
        }
        Reply::Status(status) => {
            println!("{}", serde_json::to_string(&status).unwrap_or_default());
            ExitCode::SUCCESS
        }
        Reply::Network(network) => {
            println!("{}", serde_json::to_string(&network).unwrap_or_default());
            ExitCode::SUCCESS
        }
        Reply::Refused(m) => {
            eprintln!("error: {m}");
            ExitCode::from(2)
        }
        Reply::Failed(m) => {
            eprintln!("error: {m}");
            ExitCode::FAILURE
        }
        Reply::Report {
            outcome,
            text,
            trace_csv,
            figures,
        } => {
            let ok = outcome.ok();
            // An output that cannot be written fails the command, after the report: the
            // program ran, and what it did is not lost with the file.
            let mut unwritten = false;
            // Asked for but not sent (a report too long for an answer says why in its text):
            // not written, and said so even with --json.
            for (flag, path, sent) in [
                ("--trace", trace, trace_csv.is_some()),
                ("--plot", plot, figures.is_some()),
            ] {
                if let Some(path) = path
                    && !sent
                {
                    eprintln!(
                        "error: {flag} {}: not written: the cell sent no data for it",
                        path.display()
                    );
                    unwritten = true;
                }
            }
            if let (Some(path), Some(csv)) = (trace, trace_csv)
                && let Err(e) = std::fs::write(path, csv)
            {
                eprintln!("error: {}: {e}", path.display());
                unwritten = true;
            }
            // A failed program's figures show it up to the failure.
            if let (Some(path), Some(f)) = (plot, figures) {
                match cell_client::figures::write_png(&f, path) {
                    Ok(()) if !ok => {
                        eprintln!("figures up to the failure: {}", path.display())
                    }
                    Ok(()) => {}
                    Err(e) => {
                        eprint!("{}", errors(&e));
                        unwritten = true;
                    }
                }
            }
            if json {
                println!("{}", outcome.json());
            }
            if ok {
                if !json {
                    print!("{text}");
                }
                if unwritten {
                    ExitCode::FAILURE
                } else {
                    ExitCode::SUCCESS
                }
            } else {
                eprintln!("error: {text}");
                ExitCode::FAILURE
            }
        }
    }
}

/// `supervisor status`: the supervisor's view (control channel) and the processes' own
/// (shared memory).
/// `supervisor check`: see [`Cmd::Check`].
fn check(program: &std::path::Path, config: Option<&std::path::Path>) -> ExitCode {
    let cfg = match Config::load(config) {
        Ok(c) => c,
        Err(e) => {
            eprint!("{}", errors(&e));
            return ExitCode::from(2);
        }
    };
    // A closed stdout (`| head`) ends the listing, never in a panic.
    let mut out = std::io::stdout().lock();
    match supervisor::run::check_program(&cfg, program) {
        Ok((_, p)) => {
            match p.iteration_s {
                Some(i) => writeln!(
                    out,
                    "ok: {}: {:.3} s to the end of its first iteration, then {i:.3} s per \
                     iteration, for ever (WAITs excluded)",
                    program.display(),
                    p.duration_s
                ),
                None => writeln!(
                    out,
                    "ok: {}: predicted motion time {:.3} s (WAITs excluded{})",
                    program.display(),
                    p.duration_s,
                    match p.passed_over {
                        0 => String::new(),
                        n => format!("; {n} loop iterations alike to the one before, passed over"),
                    }
                ),
            }
            .ok();
            for o in &p.outputs {
                for k in 0..64 {
                    if o.mask & (1 << k) != 0 {
                        let name = cfg.io.get(k).map_or("?", |e| e.name.as_str());
                        let _ = writeln!(
                            out,
                            "  {:9.3} s  line {:<4} {name} = {}",
                            o.t_s,
                            o.line,
                            (o.values >> k) & 1
                        );
                    }
                }
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprint!("{}", errors(&e));
            ExitCode::from(2)
        }
    }
}

fn status(instance: &str, json: bool, watch: bool) -> ExitCode {
    let instance = match instance_of(instance) {
        Ok(i) => i,
        Err(c) => return c,
    };
    // One request: the supervisor composes the document from its own ports, so any number of
    // `status` may run at once and none takes a port of the cell.
    let once = || -> Result<control_plane::status::Status, (u8, String)> {
        match ctl::call(&instance, &Request::Status) {
            Ok(Reply::Status(status)) => Ok(*status),
            Ok(Reply::Refused(m)) => Err((2, m.to_string())),
            Ok(other) => Err((1, format!("unexpected answer: {other:?}"))),
            Err(e) => Err((e.exit_code(), e.to_string())),
        }
    };
    loop {
        match once() {
            Ok(status) => {
                let text = control_plane::compose::human(&status);
                if json {
                    println!("{}", serde_json::to_string(&status).unwrap_or_default());
                } else if watch {
                    print!("\x1b[H\x1b[2J{text}");
                    let _ = std::io::Write::flush(&mut std::io::stdout());
                } else {
                    print!("{text}");
                }
            }
            Err((code, e)) => {
                eprint!("{}", errors(&e));
                return ExitCode::from(code);
            }
        }
        if !watch {
            return ExitCode::SUCCESS;
        }
        std::thread::sleep(std::time::Duration::from_millis(500));
    }
}

fn main() -> ExitCode {
    runtime::abort_on_panic();
    // /dev/shm full: every command says so and exits 1 (it died by SIGBUS, exit 135).
    let _ = runtime::signals::explain_sigbus();
    // A shell's 1024 open files are too few for a cell of many ports (its processes inherit it).
    runtime::fds::raise_limit();
    let cli = Cli::parse();
    let watching = matches!(
        cli.cmd,
        Cmd::Up { .. }
            | Cmd::Run { .. }
            | Cmd::Tune { .. }
            | Cmd::Web { .. }
            | Cmd::Foxglove { .. }
            | Cmd::Record { .. }
    );
    if !watching {
        quiet_on_a_closed_pipe();
    }
    let _log = init_logging(watching);
    if let Some(remote) = remote_of(&cli.cmd) {
        return match remote {
            Ok((line, args)) => on_the_line(line.as_deref(), &args),
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        };
    }
    match cli.cmd {
        Cmd::Cells { line, json, watch } => {
            let flags = [(json, "--json"), (watch, "--watch")];
            let args = std::iter::once("cells")
                .chain(flags.iter().filter(|(on, _)| *on).map(|(_, f)| *f))
                .map(str::to_string)
                .collect::<Vec<_>>();
            on_the_line(line.as_deref(), &args)
        }
        Cmd::Status {
            instance,
            json,
            watch,
            ..
        } => status(&instance, json, watch),
        Cmd::Web {
            line: Some(line),
            listen,
            token,
            ..
        } => {
            let mut args = vec!["web".to_string(), "--listen".into(), listen];
            if let Some(t) = token {
                args.extend(["--token".into(), t]);
            }
            on_the_line(Some(&line), &args)
        }
        Cmd::Web {
            instance,
            listen,
            token,
            ..
        } => web(&instance, &listen, token),
        Cmd::Foxglove {
            instance,
            listen,
            token,
            allow_origin,
        } => foxglove(&instance, &listen, token, allow_origin),
        Cmd::Record { args, instance, .. } => record(&args, &instance),
        Cmd::Up {
            config,
            instance,
            record,
            json,
            virtual_time,
        } => up(
            config.as_deref(),
            &instance,
            record.as_deref(),
            json,
            virtual_time,
        ),
        Cmd::Down { instance, json } => down(&instance, json.json),
        Cmd::Exec(args) => exec(&args),
        Cmd::Pause { instance, json, .. } => ctl_call(&instance, Request::Pause, json.json),
        Cmd::Speed {
            percent,
            instance,
            json,
            ..
        } => ctl_call(&instance, Request::Speed { percent }, json.json),
        Cmd::Check { program, config } => check(&program, config.as_deref()),
        Cmd::Resume { instance, json, .. } => ctl_call(&instance, Request::Resume, json.json),
        Cmd::Abort { instance, json, .. } => ctl_call(&instance, Request::Abort, json.json),
        Cmd::Reset { instance, json, .. } => ctl_call(&instance, Request::Reset, json.json),
        Cmd::Start { instance, json, .. } => ctl_call(&instance, Request::Start, json.json),
        Cmd::Restart {
            process,
            instance,
            json,
        } => ctl_call(&instance, Request::Restart { process }, json.json),
        Cmd::Swap {
            process,
            command,
            instance,
            json,
        } => ctl_call(
            &instance,
            Request::Swap {
                process,
                command: command.map(|c| c.split_whitespace().map(str::to_string).collect()),
            },
            json.json,
        ),
        Cmd::Latency(args) => match latency(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => failed(&e, matches!(e, LatencyError::Input(_))),
        },
        Cmd::LatencyPeer(args) => match latency::peer::run(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("latency-peer: {e}");
                ExitCode::FAILURE
            }
        },
        Cmd::Tune {
            axis,
            step,
            ramp,
            config,
            instance,
            json,
            plot,
        } => tune(
            &supervisor::tune::TuneOptions {
                config,
                instance,
                axis,
                step,
                ramp,
                plot,
                progress: !json,
            },
            json,
        ),
        Cmd::Events {
            instance,
            follow,
            json,
            ..
        } => events(&instance, follow, json),
        Cmd::Inject {
            instance,
            axis,
            fault,
            clear,
        } => control_done(cell_client::control::inject(
            &instance, &axis, &fault, clear,
        )),
        Cmd::Estop {
            instance,
            reason,
            json,
            ..
        } => {
            let r = cell_client::control::estop(&instance, &reason);
            if json.json {
                estop_reply(r)
            } else {
                control_done(r)
            }
        }
        Cmd::Io {
            instance,
            name,
            value,
        } => control_done(cell_client::control::io(
            &instance,
            name.as_deref(),
            value.as_deref(),
        )),
        Cmd::DefaultConfig => {
            print!("{DEFAULT_TOML}");
            ExitCode::SUCCESS
        }
        Cmd::CheckConfig { config } => check_config(config.as_deref()),
        Cmd::Run {
            program,
            config,
            instance,
            trace,
            json,
            record,
            plot,
            virtual_time,
            faults,
        } => {
            let opts = RunOptions {
                program,
                config,
                instance: instance.instance,
                trace,
                record,
                plot,
                progress: true,
                virtual_time,
                faults,
            };
            match run(&opts) {
                Ok(report) => printed(json, || report.to_json(), || report.human()),
                Err(e) => run_failed(&e, json),
            }
        }
    }
}

/// `supervisor down`: asked, then waited for until the supervisor has stopped everything and
/// let go of the instance; with `json`, the reply is all it prints on stdout.
fn down(instance: &str, json: bool) -> ExitCode {
    let code = ctl_call(instance, Request::Down, json);
    if code == ExitCode::SUCCESS
        && let Ok(i) = shm_schema::InstanceName::new(instance)
    {
        while ctl::is_up(&i) {
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        if !json {
            println!("instance {i} is down");
        }
    }
    code
}

/// `supervisor tune`: the report, and its figure if asked for.
fn tune(opts: &supervisor::tune::TuneOptions, json: bool) -> ExitCode {
    let report = match supervisor::tune::tune(opts) {
        Ok(r) => r,
        Err(e) => return run_failed(&e, json),
    };
    if let Some(path) = &opts.plot
        && let Err(e) = report.plot().and_then(|png| {
            std::fs::write(path, png).map_err(|e| format!("{}: {e}", path.display()))
        })
    {
        eprint!("{}", errors(&e));
        return ExitCode::FAILURE;
    }
    printed(json, || report.to_json().to_string(), || report.human())
}

/// `supervisor events`.
fn events(instance: &str, follow: bool, json: bool) -> ExitCode {
    match shm_schema::InstanceName::new(instance)
        .map_err(|e| format!("--instance {instance:?}: {e}"))
        .and_then(|i| cell_client::events::follow(&i, follow, json))
    {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprint!("{}", errors(&e));
            ExitCode::from(2)
        }
    }
}

/// `supervisor check-config`: the axes of a valid configuration, or every error in it.
fn check_config(config: Option<&std::path::Path>) -> ExitCode {
    match Config::load(config) {
        Ok(c) => {
            let names: Vec<&str> = c.axis.iter().map(|a| a.name.as_str()).collect();
            println!("ok: {} axes ({})", c.axis.len(), names.join(", "));
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprint!("{}", errors(&e));
            ExitCode::from(2)
        }
    }
}

/// `supervisor exec`: the outputs checked before the program is sent, the recording around it.
fn exec(a: &ExecArgs) -> ExitCode {
    let i = match instance_of(&a.instance) {
        Ok(i) => i,
        Err(c) => return c,
    };
    for (path, flag) in [
        (&a.trace, "--trace"),
        (&a.plot, "--plot"),
        (&a.record, "--record"),
    ] {
        if let Some(Err(e)) = path.as_deref().map(|p| supervisor::out::writable(p, flag)) {
            eprint!("{}", errors(&e));
            return ExitCode::from(2);
        }
    }
    let mut recorder = match a
        .record
        .as_deref()
        .map(|f| recorder::Background::start(&i, f, &mut || {}))
        .transpose()
    {
        Ok(r) => r,
        Err(e) => return run_failed(&RunError::from(e), a.json),
    };
    let source = match std::fs::read(&a.program) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {}: cannot read: {e}", a.program.display());
            return ExitCode::from(2);
        }
    };
    let req = Request::Exec {
        name: a.program.display().to_string(),
        source,
        wait: a.wait,
        trace: a.trace.is_some(),
        figures: a.plot.is_some(),
    };
    let code = match ctl::call(&i, &req) {
        Ok(r) => ctl_reply(r, a.json, a.trace.as_deref(), a.plot.as_deref()),
        Err(e) => {
            eprint!("{}", errors(&e));
            ExitCode::from(e.exit_code())
        }
    };
    match recorder.as_mut().map(|r| r.stop()) {
        Some(Ok(summary)) => eprint!("{summary}"),
        // The program ran; its recording did not: the command fails (exit 1).
        Some(Err(e)) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
        None => {}
    }
    code
}

/// `supervisor record`.
fn record(args: &recorder::RecordArgs, instance: &str) -> ExitCode {
    let i = match instance_of(instance) {
        Ok(i) => i,
        Err(c) => return c,
    };
    let opts = match args.options() {
        Ok(o) => o,
        Err(e) => {
            eprint!("{}", errors(&e));
            return ExitCode::from(2);
        }
    };
    if let Err(e) = runtime::signals::install() {
        eprintln!("error: cannot install signal handlers: {e}");
        return ExitCode::FAILURE;
    }
    let result = recorder::record(&i, &opts, &runtime::signals::stop_requested, &mut |path| {
        use std::io::Write;
        println!("recording instance {i} to {}", path.display());
        let _ = std::io::stdout().flush();
    });
    match result {
        Ok(r) => {
            print!("{}", r.text());
            ExitCode::SUCCESS
        }
        Err(e) => failed(&e, e.is_input()),
    }
}

/// `supervisor web`.
fn web(instance: &str, listen: &str, token: Option<String>) -> ExitCode {
    let (i, listen) = match served(instance, listen, token.as_deref()) {
        Ok(v) => v,
        Err(c) => return c,
    };
    let opts = web_view::WebOptions {
        instance: i,
        listen,
        token,
    };
    let result = web_view::web(&opts, &mut |addr| {
        use std::io::Write;
        println!("serving instance {i} on http://{addr}/");
        let _ = std::io::stdout().flush();
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => failed(&e, e.is_input()),
    }
}

/// What `web` and `foxglove` check before they serve: the instance, the address, the token;
/// then the signal handlers.
fn served(
    instance: &str,
    listen: &str,
    token: Option<&str>,
) -> Result<(shm_schema::InstanceName, std::net::SocketAddr), ExitCode> {
    let i = instance_of(instance)?;
    let Ok(listen) = listen.parse() else {
        eprintln!("error: --listen {listen:?} is not an IP:port address (\"127.0.0.1:8080\")");
        return Err(ExitCode::from(2));
    };
    if let Some(Err(e)) = token.map(web_view::check_token) {
        eprint!("{}", errors(&e));
        return Err(ExitCode::from(2));
    }
    if let Err(e) = runtime::signals::install() {
        eprintln!("error: cannot install signal handlers: {e}");
        return Err(ExitCode::FAILURE);
    }
    Ok((i, listen))
}

/// `supervisor foxglove`.
fn foxglove(instance: &str, listen: &str, token: Option<String>, origins: Vec<String>) -> ExitCode {
    let (i, listen) = match served(instance, listen, token.as_deref()) {
        Ok(v) => v,
        Err(c) => return c,
    };
    let opts = web_view::foxglove::FoxgloveOptions {
        instance: i,
        listen,
        token,
        origins,
    };
    let result = web_view::foxglove::foxglove(&opts, &mut |addr| {
        use std::io::Write;
        println!("serving instance {i} to Foxglove on ws://{addr}/");
        let _ = std::io::stdout().flush();
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => failed(&e, e.is_input()),
    }
}

/// Reports a command's error on stderr; exit 2 when the user's input was wrong, else 1.
fn failed(e: &dyn std::error::Error, input: bool) -> ExitCode {
    eprint!("{}", errors(&e));
    ExitCode::from(if input { 2 } else { 1 })
}

/// `e` for stderr: each of its lines that starts a problem (not an indented continuation)
/// prefixed `error: ` (a configuration with several problems has one line each).
fn errors(e: &dyn std::fmt::Display) -> String {
    let mut out = String::new();
    for line in e.to_string().lines() {
        if !line.starts_with(char::is_whitespace) {
            out += "error: ";
        }
        out += line;
        out += "\n";
    }
    out
}
