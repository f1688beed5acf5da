//! One integration-test binary (as ripgrep does): `cell` runs the real processes,
//! `closed_loop` runs servo and the machine model in-process, `latency` runs the latency tool
//! and `supervisor status`, `no_alloc` proves the cycle code allocation-free.

mod cell;
mod closed_loop;
mod drives;
mod latency;
mod loop_sim;
mod no_alloc;
mod servo_layer;

#[global_allocator]
static ALLOC: runtime::alloc_count::CountingAllocator = runtime::alloc_count::CountingAllocator;
