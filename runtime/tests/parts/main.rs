//! The runtime's parts one at a time: the cycle clock, the health detectors, the real-time
//! set-up's guard, the histogram snapshot, the stall watch. Here rather than in each module
//! (`#[cfg(test)]`): the library's own test build compiles every iceoryx2 port of the cell
//! again, optimised (14.7 s of CPU in a clean test build; this binary uses the library as
//! built).

mod cycle;
mod health;
mod notify;
mod rt;
mod snapshot;
mod stall;
