//! One integration-test binary (as ripgrep does): `cell` runs the real processes,
//! `closed_loop` runs servo and the machine model in-process.

mod cell;
mod closed_loop;
