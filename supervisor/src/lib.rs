//! The supervisor: loads the cell configuration, launches the processes, runs programs,
//! watches their health, stops them and removes every shared-memory resource.

pub mod cell;
pub mod error;
pub mod job;
pub mod launch;
pub mod out;
pub mod program;
pub mod report;
pub mod run;
pub mod schedule;
pub mod serve;
pub mod swap;
pub mod tune;
pub mod tuning;
pub mod up;
