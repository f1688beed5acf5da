//! Latency measurements of the framework's own code paths, in cyclictest's terms.
//!
//! - **timer** ([`Test::Timer`]): the wake-up latency of [`runtime::cycle::CycleClock`], the
//!   very clock every process of a cell runs on, one thread per CPU (as `cyclictest -S`), each
//!   pinned and under `SCHED_FIFO`.
//! - **ipc** ([`Test::Ipc`]): the one-way latency of a setpoint from a trajgen-style publisher
//!   (a separate process: [`peer`]) to a servo-style wake-up: `Pub::send` + `Notifier::notify`
//!   on one side, `Listener::wait` on the other, first across two CPUs, then on one CPU.
//! - **pipe** ([`Test::Pipe`]): the same hop through a raw pipe (`write` of the stamp, blocking
//!   `read`), the baseline an IPC hop is compared with; **unix** ([`Test::Unix`]): the same
//!   through a raw Unix datagram socket, the kernel mechanism iceoryx2's notification uses.
//!
//! A hop's latency is measured against one clock: the sender writes `CLOCK_MONOTONIC` into the
//! message just before publishing, the receiver reads the clock as soon as its wait returns.
//!
//! Figures per series: samples, min, avg, max, p50/p99/p99.9/p99.99 (from the fixed-size
//! [`shm_schema::LatencyHistogramV1`]), and cyclictest's 1-µs histogram with its overflows
//! ([`histfile`]); as text like cyclictest's, as JSON ([`report`]) or as a PNG (the `plot` crate draws it).

pub mod command;
pub mod histfile;
pub mod measure;
pub mod peer;
pub mod report;

pub use measure::{Options, Results, Series, Test, Threads, run};
