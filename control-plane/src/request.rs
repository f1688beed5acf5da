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
    /// A process replaced (`swap`, `restart`).
    Replaced(Box<Replaced>),
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
