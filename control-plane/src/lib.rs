//! The control plane of a cell: everything a running cell says and is asked, as types shared
//! by the supervisor (which serves it), its CLI, the observer tools and the tests.
//!
//! - [`Request`] and [`Reply`]: what a client asks and what the cell answers on the control
//!   channel; [`channel`]: the Unix socket that carries them (who may talk, framing, bounds)
//!   and [`channel::call`], the client.
//! - [`Info`]: the supervisor's own view of its cell (the answer to [`Request::Info`]).
//! - [`status::Status`]: `supervisor status --json`, the processes' view from shared memory
//!   with the supervisor's, as the supervisor composes it ([`Request::Status`]).
//! - [`report::RunReport`] and [`report::RunFailure`]: a program's end (`run --json`), with its
//!   [`event::Event`]s.
//! - [`figures::Figures`]: what `--plot` draws, gathered by the supervisor, drawn by the client.
//! - [`Failure`]: why a started job failed, as data (a variant per cause), its words for the
//!   user from `Display`.
//!
//! The JSON documents (`status --json`, `run --json`) are these types serialized; their JSON Schemas are
//! generated from them ([`schema`]) and checked in under `docs/schema/`.

pub mod channel;
pub mod compose;
pub mod event;
pub mod failure;
pub mod figures;
pub mod info;
pub mod report;
mod request;
pub mod schema;
pub mod status;

pub use failure::Failure;
pub use info::Info;
pub use request::{Refusal, Replaced, Reply, Request};

/// A unit variant's JSON name (`"running"` for [`info::Life::Running`]), for text.
pub fn word<T: serde::Serialize>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(serde_json::Value::String(s)) => s,
        _ => "?".into(),
    }
}
