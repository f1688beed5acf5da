//! The supervisor: loads the cell configuration, launches the processes, runs programs,
//! watches their health, stops them and removes every shared-memory resource.

pub mod config;
pub mod control;
pub mod events;
pub mod latency_cmd;
pub mod launch;
pub mod report;
pub mod run;
pub mod status;
pub mod tune;
