//! What a client asks a running cell ([`Request`]) and what the cell answers ([`Reply`]), as
//! they travel on the control channel ([`crate::channel`], postcard-encoded).

use crate::figures::Figures;
use crate::info::Info;
use crate::report::Outcome;
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
}

/// What the cell answers.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub enum Reply {
    /// Done; a line for the user.
    Done(String),
    /// Not done, nothing changed: bad input or a state that does not allow it (exit 2).
    Refused(String),
    /// Tried and failed (exit 1).
    Failed(String),
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
}
