//! The supervisor: loads the cell configuration, launches the processes, runs programs,
//! watches their health, stops them and removes every shared-memory resource.

pub mod cell;
pub mod control;
pub mod error;
pub mod events;
pub mod figures;
pub mod job;
pub mod latency_cmd;
pub mod launch;
pub mod out;
pub mod program;
pub mod record;
pub mod report;
pub mod run;
pub mod serve;
pub mod stall;
pub mod status;
pub mod swap;
pub mod tune;
pub mod up;
pub mod web;
