//! A client of a running cell, never its supervisor: what the CLI, the web view and other
//! tools use to read a cell and to act on it through its shared memory.
//!
//! - [`events`]: the cell's events as they happen (`supervisor events`);
//! - [`control`]: the e-stop, the named IO and injected faults, written straight into the
//!   cell's shared memory (as a PLC would), with no supervisor in between;
//! - [`figures`]: a run's figures (path, following error, latency) drawn into a PNG, and the
//!   bounded gathering of their data.
//!
//! The control channel's requests (`pause`, `exec`, `swap`, …) go through
//! [`control_plane::channel`] instead: those the supervisor serves.

pub mod control;
pub mod events;
pub mod figures;
