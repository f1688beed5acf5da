//! What a remote client may ask a cell, as the network carries it (JSON, `"op"` names it), and
//! the control-plane request each one becomes: the same requests, with the same validation by
//! the cell, as `supervisor pause` and the others on the cell's own host.
//!
//! ```text
//! {"op": "status"}
//! {"op": "pause"}   {"op": "resume"}   {"op": "abort"}
//! {"op": "speed", "percent": 50}
//! {"op": "estop", "reason": "the operator's button"}
//! {"op": "reset"}   {"op": "start"}
//! {"op": "exec", "name": "pick.prog", "source": "MOVE(60, 40, 0)\nEND\n"}
//! ```
//!
//! The remote e-stop is a convenience: the cell's own e-stop circuit stays its safety function.

use control_plane::Request;
use serde::{Deserialize, Serialize};

/// A remote client's request.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
// Every variant a struct (`Pause {}`): an internally tagged unit variant would take unknown
// fields silently.
#[serde(tag = "op", rename_all = "lowercase", deny_unknown_fields)]
pub enum Command {
    /// The whole of `status --json`.
    Status {},
    /// Decelerate along the path to rest and hold.
    Pause {},
    /// Go on along the path.
    Resume {},
    /// Come to rest along the path and drop the rest of the program.
    Abort {},
    /// The live speed override, 1..=100 % of the programmed speed.
    Speed {
        /// 1..=100.
        percent: f64,
    },
    /// The user's e-stop, with why.
    Estop {
        /// A few words, kept in the e-stop and its events.
        reason: String,
    },
    /// Clear the e-stop and what can be cleared.
    Reset {},
    /// Enable the drives, holding where they stand.
    Start {},
    /// Run a program sent with the command (checked by the cell, with line and column).
    Exec {
        /// Its name, for messages and the report.
        name: String,
        /// Its text.
        source: String,
    },
}

impl Command {
    /// Its `"op"`.
    pub fn op(&self) -> &'static str {
        match self {
            Self::Status {} => "status",
            Self::Pause {} => "pause",
            Self::Resume {} => "resume",
            Self::Abort {} => "abort",
            Self::Speed { .. } => "speed",
            Self::Estop { .. } => "estop",
            Self::Reset {} => "reset",
            Self::Start {} => "start",
            Self::Exec { .. } => "exec",
        }
    }

    /// Whether it changes the cell (every command but `status`): an operator's alone.
    pub fn changes_the_cell(&self) -> bool {
        !matches!(self, Self::Status {})
    }

    /// The control channel's request it becomes.
    pub fn request(&self) -> Request {
        match self {
            Self::Status {} => Request::Status,
            Self::Pause {} => Request::Pause,
            Self::Resume {} => Request::Resume,
            Self::Abort {} => Request::Abort,
            Self::Speed { percent } => Request::Speed { percent: *percent },
            Self::Estop { reason } => Request::Estop {
                reason: reason.clone(),
            },
            Self::Reset {} => Request::Reset,
            Self::Start {} => Request::Start,
            Self::Exec { name, source } => Request::Exec {
                name: name.clone(),
                source: source.as_bytes().to_vec(),
                wait: false,
                trace: false,
                figures: false,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_documented_json_is_the_commands() {
        for (json, command) in [
            (r#"{"op": "status"}"#, Command::Status {}),
            (r#"{"op": "pause"}"#, Command::Pause {}),
            (
                r#"{"op": "speed", "percent": 50}"#,
                Command::Speed { percent: 50.0 },
            ),
            (
                r#"{"op": "estop", "reason": "the operator's button"}"#,
                Command::Estop {
                    reason: "the operator's button".into(),
                },
            ),
            (
                r#"{"op": "exec", "name": "pick.prog", "source": "MOVE(60, 40, 0)\nEND\n"}"#,
                Command::Exec {
                    name: "pick.prog".into(),
                    source: "MOVE(60, 40, 0)\nEND\n".into(),
                },
            ),
        ] {
            let parsed: Command = serde_json::from_str(json).expect(json);
            assert_eq!(parsed, command, "{json}");
            assert_eq!(parsed.op(), command.op());
        }
        for bad in [
            r#"{"op": "down"}"#,
            r#"{"op": "swap", "process": "servo"}"#,
            r#"{"op": "pause", "extra": 1}"#,
            r#"{"op": "speed"}"#,
        ] {
            assert!(serde_json::from_str::<Command>(bad).is_err(), "{bad}");
        }
        assert!(!Command::Status {}.changes_the_cell());
        assert!(Command::Pause {}.changes_the_cell());
        assert_eq!(
            Command::Exec {
                name: "p".into(),
                source: "END\n".into()
            }
            .request(),
            Request::Exec {
                name: "p".into(),
                source: b"END\n".to_vec(),
                wait: false,
                trace: false,
                figures: false
            }
        );
    }
}
