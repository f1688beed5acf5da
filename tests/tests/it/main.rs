//! One integration-test binary (as ripgrep does): `cell` and `drives` run the real processes
//! (the triangle, bad input, killed processes; drive faults, injections, CSP, 4 kHz, tune),
//! `loop_sim` puts servo and the machine model in one process for `closed_loop` and
//! `servo_layer`, `latency` runs the latency tool and `supervisor status`, `no_alloc` proves
//! the cycle code allocation-free.

mod cell;
mod closed_loop;
mod drives;
mod estop;
mod latency;
mod loop_sim;
mod no_alloc;
mod operations;
mod servo_layer;

#[global_allocator]
static ALLOC: runtime::alloc_count::CountingAllocator = runtime::alloc_count::CountingAllocator;
