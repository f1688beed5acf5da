//! What a client asks a running cell ([`Request`]) and what the cell answers ([`Reply`]), as
//! they travel on the control channel ([`crate::channel`], postcard-encoded).

use crate::Failure;
use crate::figures::Figures;
use crate::info::Info;
use crate::report::Outcome;
use crate::status::Status;
use serde::{Deserialize, Serialize};

/// What a client asks a running cell.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub enum Request {
    /// The cell's own view: processes (pid, state, restarts), the arm, the e-stop, the job.
    /// Answered with [`Reply::Info`] (the `supervisor` part of `status --json`).
    Info,
    /// Validate and run a program. `wait`: answer when it ends, with its report.
    Exec {
        /// The program's name as the user gave it (for messages and the report).
        name: String,
        /// Its source, the file's bytes (checked, with line and column, by the cell).
        source: Vec<u8>,
        /// Answer when the program ends (with [`Reply::Report`]), not when it starts.
        wait: bool,
        /// With `wait`: include the trace (CSV) in the report.
        trace: bool,
        /// With `wait`: include the figures (`--plot`) in the report.
        figures: bool,
    },
    /// Decelerate along the path to rest and hold.
    Pause,
    /// Go on along the path.
    Resume,
    /// Come to rest along the path and drop the rest of the program.
    Abort,
    /// The live speed override: the path at `percent` (1..=100) of its programmed speed.
    Speed {
        /// 1..=100.
        percent: f64,
    },
    /// Clear the e-stop and what can be cleared.
    Reset,
    /// Enable the drives, holding where they stand.
    Start,
    /// Stop a process of the table and start it again.
    Restart {
        /// Its name in the table.
        process: String,
    },
    /// Replace a process of the table by a new one (its command, or `command`).
    Swap {
        /// Its name in the table.
        process: String,
        /// The new command line; `None` runs the configured one again (a new build).
        command: Option<Vec<String>>,
    },
    /// Stop the cell.
    Down,
    /// The user's e-stop (origin `external`, as from a button), published by the supervisor
    /// on its own long-lived port: a command-line client that published it itself made each
    /// real-time process connect to a new publisher inside its cycle (about one overrun and
    /// three skipped cycles each time). Answered once a process reports it latched. Taken
    /// whatever the cell is doing (a program, a swap, a tuning session, going down).
    Estop {
        /// Why, in a few words (kept in the e-stop and its events).
        reason: String,
    },
    /// The whole of `supervisor status --json`: the supervisor's view ([`Request::Info`]) with
    /// the processes' own (their statuses, latency, servo's axes, the IO), as the supervisor
    /// last read them from shared memory. Answered with [`Reply::Status`]; a client needs no
    /// port of its own, so any number of them may ask at once.
    Status,
    /// The cell's `[network]` section, as its gateway needs it ([`Reply::Network`]).
    Network,
}

/// What the cell answers.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub enum Reply {
    /// Done; a line for the user.
    Done(String),
    /// A process replaced (`swap`, `restart`).
    Replaced(Box<Replaced>),
    /// Not done, nothing changed: bad input or a state that does not allow it (exit 2).
    Refused(Refusal),
    /// Tried and failed (exit 1): why.
    Failed(Failure),
    /// The supervisor's view of the cell (`Info`).
    Info(Box<Info>),
    /// A program's end: its report (or why it failed), as text, and its trace.
    Report {
        /// The report (`run --json`'s document), or the failure.
        outcome: Outcome,
        /// The summary `run` prints (or the error).
        text: String,
        /// The trace as CSV (`run --trace`), when asked for and the program completed.
        trace_csv: Option<String>,
        /// What `--plot` draws, when asked for and the program completed.
        figures: Option<Box<Figures>>,
    },
    /// `supervisor status --json` ([`Request::Status`]).
    Status(Box<Status>),
    /// The cell's `[network]` section with its name on the line resolved (`name` always
    /// given); `None`: the cell is not on the network ([`Request::Network`]).
    Network(Option<Box<cell_config::network::NetworkSettings>>),
}

/// Why the cell refused a request: nothing was changed (the CLI exits 2). A client acts on
/// the variant; its `Display` is the line for the user.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub enum Refusal {
    /// The instance is going down: the axes come to rest, then the processes stop.
    GoingDown {
        /// The instance.
        instance: String,
    },
    /// A tuning session has the cell (`supervisor tune`); `down` ends it.
    Tuning {
        /// The axis being tuned.
        axis: String,
    },
    /// A process is being replaced (`swap`, `restart`).
    Replacing {
        /// The process.
        process: String,
    },
    /// A program runs.
    ProgramRunning {
        /// The program's name.
        program: String,
    },
    /// trajgen still brings the previous program to rest.
    Settling {
        /// The program line it is at.
        line: u32,
    },
    /// The drives are being enabled.
    Enabling,
    /// The e-stop is latched; `supervisor reset` first.
    EstopLatched {
        /// The e-stop: who raised it and why (a [`Failure::Estop`], or servo's own fault).
        estop: Box<Failure>,
    },
    /// Servo's fault is latched; `supervisor reset` first.
    FaultLatched {
        /// The fault: its name, axis and the event that explains it.
        fault: Box<Failure>,
    },
    /// The drives are disabled; `supervisor start` enables them.
    Disabled,
    /// Enabling the drives was refused (servo refused the request: why, in its words).
    Enable {
        /// Why.
        error: String,
    },
    /// trajgen has published no setpoint yet: where the axes stand is not known.
    NoSetpoint,
    /// The program is wrong or would break a limit (its file, line and column, and why).
    Program {
        /// What is wrong, and where.
        error: String,
    },
    /// A speed override outside 1 to 100 %.
    Speed {
        /// The percentage asked for.
        percent: f64,
    },
    /// Pause, resume or abort with no program running.
    NoProgram,
    /// The program's motion has ended; the axes settle.
    MotionEnded,
    /// trajgen is swapped while the program moves, not while it is paused.
    Paused,
    /// trajgen is swapped while the program moves, not while it holds at a `WAIT` or `DELAY`.
    Holding {
        /// `WAIT` or `DELAY`.
        instruction: String,
        /// Its line.
        line: u32,
    },
    /// No process of that name in the cell's table.
    NoSuchProcess {
        /// The name asked for.
        process: String,
        /// The table's names.
        known: Vec<String>,
    },
    /// A replacement's command line cannot run.
    Command {
        /// Why (an empty line, a program not found).
        error: String,
    },
    /// A process of the motion path is replaced only while no program runs.
    MotionPath {
        /// The process.
        process: String,
        /// The program that runs.
        program: String,
    },
    /// The e-stop cannot be cleared.
    Reset {
        /// What holds it (an e-stop input still open, ...).
        blockers: Vec<String>,
    },
    /// The request ended before its frame was complete.
    Incomplete {
        /// Bytes received.
        bytes: usize,
    },
    /// No complete request within the channel's time after connecting.
    Slow {
        /// The time allowed (s).
        seconds: u64,
    },
    /// A frame longer than the channel takes.
    TooLong {
        /// The frame's length.
        bytes: usize,
        /// The longest taken.
        limit: usize,
    },
    /// Bytes inside the frame after the request.
    AfterRequest {
        /// How many.
        bytes: usize,
    },
    /// Bytes after the frame: one request per connection.
    AfterFrame {
        /// How many.
        bytes: usize,
    },
    /// The frame is not a request (undecodable: another version?), or could not be read.
    Malformed {
        /// What is wrong with it.
        error: String,
    },
    /// Another user: the cell belongs to `owner`.
    ForeignUser {
        /// The cell's uid.
        owner: u32,
        /// The peer's uid.
        uid: u32,
    },
    /// The peer's credentials cannot be read.
    UnknownPeer {
        /// Why.
        error: String,
    },
    /// The channel holds as many connections as it takes.
    Connections {
        /// Its limit.
        limit: usize,
    },
    /// A program is being validated before it starts.
    Validating {
        /// Its name.
        program: String,
    },
    /// The axes moved while the program was validated (from where they stood): it did not
    /// start.
    MovedMeanwhile {
        /// Its name.
        program: String,
    },
    /// An e-stop latched (and was reset) while the program was validated: it did not start.
    StoppedMeanwhile {
        /// Its name.
        program: String,
    },
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::GoingDown { instance } => write!(
                f,
                "instance {instance} is going down: the axes come to rest, then the processes stop"
            ),
            Self::Tuning { axis } => write!(
                f,
                "busy: axis {axis} is being tuned (`supervisor tune`); `supervisor down` ends it"
            ),
            Self::Replacing { process } => write!(
                f,
                "busy: {process} is being replaced (`swap`/`restart`); try again in a moment"
            ),
            Self::ProgramRunning { program } => {
                write!(f, "busy: {program} is running (`supervisor abort` ends it)")
            }
            Self::Validating { program } => write!(
                f,
                "busy: {program} is being validated; it starts once that is done"
            ),
            Self::MovedMeanwhile { program } => write!(
                f,
                "{program}: the axes moved while it was validated; send it again"
            ),
            Self::StoppedMeanwhile { program } => write!(
                f,
                "{program}: an e-stop came while it was validated; send it again"
            ),
            Self::Settling { line } => write!(
                f,
                "trajgen is still bringing the previous program to rest (line {line}); try again in a moment"
            ),
            Self::Enabling => f.write_str("the drives are being enabled; try again in a moment"),
            Self::EstopLatched { estop } => write!(
                f,
                "the e-stop is latched: {estop}\n  `supervisor reset`, then `supervisor start`"
            ),
            Self::FaultLatched { fault } => {
                write!(f, "{fault}\n  `supervisor reset`, then `supervisor start`")
            }
            Self::Disabled => {
                f.write_str("the drives are disabled: `supervisor start` enables them")
            }
            Self::NoSetpoint => f.write_str("trajgen publishes no setpoint"),
            Self::Program { error } | Self::Malformed { error } | Self::Enable { error } => {
                f.write_str(error)
            }
            Self::Speed { percent } => {
                write!(f, "speed {percent} %: 1 to 100 % of the programmed speed")
            }
            Self::NoProgram => f.write_str("no program is running"),
            Self::MotionEnded => f.write_str(
                "the program's motion has ended; the axes are settling: try again in a moment",
            ),
            Self::Paused => f.write_str(
                "the program is paused: `supervisor resume` first (a swap pauses and resumes it itself)",
            ),
            Self::Holding { instruction, line } => write!(
                f,
                "the program holds at a {instruction} (line {line}): trajgen is swapped while the \
                 program moves or with no program; nothing was changed"
            ),
            Self::NoSuchProcess { process, known } => write!(
                f,
                "no process {process:?} in this cell (it has {})",
                known.join(", ")
            ),
            Self::Command { error } => write!(f, "--command: {error}; nothing was changed"),
            Self::MotionPath { process, program } => write!(
                f,
                "{process} can be replaced only while no program runs ({program} is running; \
                 `supervisor abort` ends it, or wait for it)"
            ),
            Self::Reset { blockers } => {
                write!(f, "the e-stop cannot be cleared: {}", blockers.join("; "))
            }
            Self::Incomplete { bytes } => write!(
                f,
                "the request ended after {bytes} bytes, before its frame was complete"
            ),
            Self::TooLong { bytes, limit } => write!(
                f,
                "a request of {bytes} bytes: at most {limit} are accepted \
                 (a program's source is at most {} bytes)",
                motion_program::MAX_SOURCE_BYTES
            ),
            Self::AfterRequest { bytes } => write!(
                f,
                "{bytes} bytes of junk after the request inside its frame: refused, nothing done"
            ),
            Self::AfterFrame { bytes } => write!(
                f,
                "{bytes} bytes follow the request's frame: one request per connection, nothing after it"
            ),
            Self::Slow { seconds } => {
                write!(f, "no complete request within {seconds} s of connecting")
            }
            Self::ForeignUser { owner, uid } => write!(
                f,
                "refused: this cell belongs to uid {owner}; uid {uid} may not control it"
            ),
            Self::UnknownPeer { error } => {
                write!(f, "refused: cannot read the peer's credentials: {error}")
            }
            Self::Connections { limit } => {
                write!(f, "refused: busy, {limit} connections are open; try again")
            }
        }
    }
}

impl std::error::Error for Refusal {}

/// A process replaced by `swap` or `restart`: the answer's data, and its words
/// ([`Replaced::text`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Replaced {
    /// The process' name in the table.
    pub process: String,
    /// `swap` (true) or `restart`.
    pub swapped: bool,
    /// From the request to the new process holding its part (ms).
    pub took_ms: f64,
    /// The old process' pid; `None` when it was not running.
    pub old_pid: Option<u32>,
    /// The new process' pid.
    pub new_pid: u32,
    /// The fieldbus image during the handover (make before break): (images, largest gap in
    /// ms).
    pub image: Option<(u64, f64)>,
    /// trajgen during a program: the program, and the line it paused and resumed at.
    pub program: Option<(String, u32)>,
    /// The drives are enabled again (a process of the motion path replaced with the brakes
    /// on).
    pub reenabling: bool,
}

impl Replaced {
    /// The answer in words, e.g. `iobridge swapped in 141 ms (pid 26957 → 26994); fieldbus
    /// image: 37 images during the handover, largest gap 7.17 ms`.
    pub fn text(&self) -> String {
        let what = if self.swapped { "swapped" } else { "restarted" };
        let old = self.old_pid.map_or("-".to_string(), |p| p.to_string());
        let mut s = match &self.program {
            Some((program, line)) => format!(
                "{} {what} during {program} in {:.0} ms (pid {old} → {}): paused at line {line} \
                 on the path, resumed from there",
                self.process, self.took_ms, self.new_pid
            ),
            None => format!(
                "{} {what} in {:.0} ms (pid {old} → {})",
                self.process, self.took_ms, self.new_pid
            ),
        };
        if let Some((images, gap_ms)) = self.image {
            s += &format!(
                "; fieldbus image: {images} images during the handover, largest gap {gap_ms:.2} ms"
            );
        }
        if self.reenabling {
            s += "; re-enabling the drives";
        }
        s
    }
}
