//! The motion core of the cell, one library for trajgen and the supervisor:
//!
//! - [`blend`]: one segment of Paul's via-point method (seed 003 §2);
//! - [`generator`]: the real-time state machine that chains segments, holds and IO from a
//!   command queue against real elapsed time (trajgen runs it every cycle);
//! - [`predict`]: the same generator run in simulated time over a whole program, for the
//!   supervisor's prediction of the motion time and its validation of the path before
//!   anything moves (`supervisor check`, `run`, `exec`).
//!
//! One rule, one implementation: what the supervisor predicts is what trajgen will run.

pub mod blend;
pub mod generator;
pub mod predict;

pub use generator::{Generator, Params, Phase, Space};
