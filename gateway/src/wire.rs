//! What the gateway publishes and answers, as JSON on the network (version 1 of the key space,
//! `docs/network.md`): a foreign client needs only these shapes.
//!
//! ```text
//! rtc/v1/<cell>/status   {"cell": "press-1", "host": "hostname", "status": {...status --json...}}
//! rtc/v1/<cell>/events   {"gateway_started_ms": 1764201600000, "seq": 7, "lost": 0,
//!                         "event": {...one event of events --json...}}
//! rtc/v1/<cell>/control  the answer: {"answer": "done", "message": "..."}
//!                                    {"answer": "refused", "by": "gateway" | "cell", "reason": "..."}
//!                                    {"answer": "failed", "reason": "..."}
//!                                    {"answer": "status", "status": {...}}
//! rtc/v1/<cell>/record          {"source_started_ms": 1764201600000, "seq": 12,
//!                                "messages": [[3, 1764201600123456789, {...}], ...],
//!                                "lost": [0, 0, 2, ...]}
//! rtc/v1/<cell>/record/flush    {"source_started_ms": 1764201600000, "seq": 57}
//! rtc/v1/<cell>/record/topics   {"source_started_ms": 1764201600000,
//!                                "topics": [{"topic": "/servo/state",
//!                                            "schema_name": "rtc.ServoStateV3",
//!                                            "schema": {...JSON Schema...}}, ...]}
//! ```

use control_plane::event::Event;
use control_plane::status::Status;
use control_plane::{Reply, channel::CallError};
use serde::{Deserialize, Serialize};

/// A cell's status on the network, published every `status_period` and answered to a `get`
/// of its key (the latest: a late joiner needs not wait).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StatusMessage {
    /// The cell's name on the line.
    pub cell: String,
    /// The host its gateway runs on.
    pub host: String,
    /// `supervisor status --json` of the cell.
    pub status: Box<Status>,
}

/// One event of a cell, numbered: a subscriber that sees `seq` jump has missed the
/// publications between (the network lost them); `lost` counts the events the gateway itself
/// could not forward just before this one (the cell's events came faster than the network
/// took them). Neither loss is silent.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EventMessage {
    /// When the gateway started (ms since the Unix epoch): a new value is a gateway started
    /// again, and the events between its two lives were not forwarded.
    pub gateway_started_ms: u64,
    /// This publication's number, from 1 as the gateway starts.
    pub seq: u64,
    /// Events lost before this one, on the gateway's side.
    pub lost: u64,
    /// The event, as `supervisor events --json` prints it.
    pub event: Event,
}

/// What a subscriber missed between two event messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Missed {
    /// Nothing.
    Nothing,
    /// This many events: publications the network lost, and events the gateway could not
    /// forward.
    Events(u64),
    /// The gateway started again: the events while it was away are not known (and `lost`
    /// events of its new life).
    Restarted(u64),
}

impl EventMessage {
    /// What was missed between `previous` (the last message taken, if any) and this one.
    pub fn missed_since(&self, previous: Option<&EventMessage>) -> Missed {
        match previous {
            None => Missed::Nothing,
            Some(p) if p.gateway_started_ms != self.gateway_started_ms => {
                Missed::Restarted(self.lost)
            }
            Some(p) => match self.seq.saturating_sub(p.seq + 1) + self.lost {
                0 => Missed::Nothing,
                n => Missed::Events(n),
            },
        }
    }
}

/// The topics of a cell's recording stream: what `record` writes as MCAP channels, in the
/// order the stream's messages number them. Answered to a `get` of
/// `rtc/v1/<cell>/record/topics` (which starts the gateway's recording source if it was not
/// running).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordTopics {
    /// When the gateway's recording source started (ms since the Unix epoch): the stream's
    /// batches of that source carry the same value.
    pub source_started_ms: u64,
    /// Each topic, its schema's name and its JSON Schema.
    pub topics: Vec<recorder::TopicInfo>,
}

/// The answer to a `get` of `rtc/v1/<cell>/record/flush`: the stream's batch `seq` (of the
/// source that started at `source_started_ms`) holds everything the cell published before
/// the question reached its gateway. A recorder that stops asks, and ends once it has that
/// batch: it misses nothing that was in flight.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecordFlushed {
    /// The source the batches are numbered in.
    pub source_started_ms: u64,
    /// The last batch sent.
    pub seq: u64,
}

/// One batch of a cell's recording stream on `rtc/v1/<cell>/record`: every message the
/// gateway's recording source read since the previous batch (a batch every few ms while
/// anyone subscribes; an empty one at least every half second, a heartbeat).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RecordBatch {
    /// When the source started (ms since the Unix epoch): a new value is a new source, whose
    /// topics are asked again.
    pub source_started_ms: u64,
    /// The batch's number, from 1 as its source starts: a jump is a batch the network lost.
    pub seq: u64,
    /// `[topic, log time (ns since the Unix epoch), message]`, the topic as its index in
    /// [`RecordTopics::topics`], the message as a local recording writes it (the same JSON,
    /// byte for byte).
    pub messages: Vec<(u32, u64, Box<serde_json::value::RawValue>)>,
    /// Per topic, the samples the source lost so far (read too late from the cell's shared
    /// memory: a subscriber's buffer overflowed), as a local recording counts them.
    pub lost: Vec<u64>,
}

/// Who refused a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RefusedBy {
    /// The gateway: who asked, or how (the signature, the role, the time).
    Gateway,
    /// The cell: its state does not allow it (as `supervisor pause` would be refused).
    Cell,
}

impl std::fmt::Display for RefusedBy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Gateway => "by the gateway",
            Self::Cell => "by the cell",
        })
    }
}

/// The answer to a command.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "answer", rename_all = "lowercase")]
pub enum Answer {
    /// Done; the cell's words.
    Done {
        /// What the cell says.
        message: String,
    },
    /// Not done, nothing changed.
    Refused {
        /// The gateway or the cell.
        by: RefusedBy,
        /// Why, in words.
        reason: String,
    },
    /// Tried and failed.
    Failed {
        /// Why, in words.
        reason: String,
    },
    /// The status asked for.
    Status {
        /// `supervisor status --json`.
        status: Box<Status>,
    },
}

impl Answer {
    /// The cell's reply to a command, or why none came, as the network's answer.
    pub fn of_reply(reply: Result<Reply, CallError>) -> Self {
        match reply {
            Ok(Reply::Done(message)) => Self::Done { message },
            Ok(Reply::Refused(r)) => Self::Refused {
                by: RefusedBy::Cell,
                reason: r.to_string(),
            },
            Ok(Reply::Failed(f)) => Self::Failed {
                reason: f.to_string(),
            },
            Ok(Reply::Status(status)) => Self::Status { status },
            Ok(other) => Self::Failed {
                reason: format!("the cell answered out of turn: {other:?}"),
            },
            Err(e) => Self::Failed {
                reason: e.to_string(),
            },
        }
    }

    /// A command-line client's exit status: 0 done, 2 refused, 1 failed.
    pub fn exit_code(&self) -> u8 {
        match self {
            Self::Done { .. } | Self::Status { .. } => 0,
            Self::Refused { .. } => 2,
            Self::Failed { .. } => 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(started: u64, seq: u64, lost: u64) -> EventMessage {
        let event = serde_json::from_str(
            r#"{"t_s": 1.0, "stamp_ns": 1, "source": "servo", "seq": 1, "severity": "info",
                "code": 303, "name": "disabling", "axis": null, "value": 0.0, "limit": 0.0,
                "text": ""}"#,
        )
        .expect("an event");
        EventMessage {
            gateway_started_ms: started,
            seq,
            lost,
            event,
        }
    }

    #[test]
    fn no_loss_of_events_goes_unsaid() {
        let first = message(10, 1, 0);
        assert_eq!(first.missed_since(None), Missed::Nothing);
        assert_eq!(
            message(10, 2, 0).missed_since(Some(&first)),
            Missed::Nothing
        );
        // Publications lost on the network, events the gateway could not forward, both.
        assert_eq!(
            message(10, 5, 0).missed_since(Some(&first)),
            Missed::Events(3)
        );
        assert_eq!(
            message(10, 2, 7).missed_since(Some(&first)),
            Missed::Events(7)
        );
        assert_eq!(
            message(10, 4, 7).missed_since(Some(&first)),
            Missed::Events(9)
        );
        // A gateway started again: its numbers start afresh, the gap is unknown.
        assert_eq!(
            message(20, 1, 0).missed_since(Some(&first)),
            Missed::Restarted(0)
        );
    }
}
