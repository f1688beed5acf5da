//! One integration-test binary (as ripgrep does): `cell` and `drives` run the real processes
//! (the triangle, bad input, killed processes; drive faults, injections, CSP, 4 kHz, tune),
//! `loop_sim` puts servo and the machine model in one process for `closed_loop` and
//! `servo_layer`, `latency` runs the latency tool and `supervisor status`, `no_alloc` proves
//! the cycle code allocation-free, `flavour_interop` has a stock iceoryx2 process exchange
//! samples with ours (here, where the stock flavour's generic code is compiled unoptimised).

mod cell;
mod closed_loop;
mod drives;
mod estop;
mod ethercat;
mod faults;
mod fieldbus;
mod flavour_interop;
mod foxglove;
mod latency;
mod line;
mod loop_sim;
mod masters;
mod no_alloc;
mod operations;
mod programs;
mod recording;
mod servo_layer;
mod up;
mod virtual_time;
mod web;

#[global_allocator]
static ALLOC: runtime::alloc_count::CountingAllocator = runtime::alloc_count::CountingAllocator;

/// `src` as the commands trajgen takes on the default Gantry UBA cell (program `id`).
pub(crate) fn gantry_commands(src: &str, id: u32) -> Vec<shm_schema::MotionCommandV2> {
    let cfg = cell_config::Config::default_cell();
    motion_program::parse(src.as_bytes(), &cfg.cell_spec())
        .expect("the program parses")
        .commands(id)
        .collect()
}
