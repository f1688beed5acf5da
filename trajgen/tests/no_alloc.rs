//! trajgen's cycle code allocates nothing: a whole triangle, command intake included.

use runtime::alloc_count::{CountingAllocator, count};
use shm_schema::{MAX_AXES, MotionState};
use trajgen::generator::{Generator, Params};

#[global_allocator]
static A: CountingAllocator = CountingAllocator;

#[test]
fn the_generator_cycle_does_not_allocate() {
    let mut p = Params {
        axes: 3,
        vmax: [1.0; MAX_AXES],
        min: [-1000.0; MAX_AXES],
        max: [1000.0; MAX_AXES],
        t_acc: 0.525,
    };
    p.vmax[..3].copy_from_slice(&[16.0, 16.0, 30.0]);
    let cmds = motion_program::parse(include_str!("../../examples/triangle.prog"), 3)
        .expect("parses")
        .to_commands(1, 1);
    let mut g = Generator::new(p, &[40.0, 40.0, 0.0]);
    let ((cycles, state), allocs) = count(|| {
        for c in &cmds {
            g.push_command(c);
        }
        let mut n = 0u64;
        let mut sp = g.step(0);
        while sp.state == MotionState::Moving as u32 {
            n += 1;
            sp = g.step(n * 1_000_000);
            let _ = g.next_transition_ns();
        }
        (n, sp.state)
    });
    assert_eq!(state, MotionState::Done as u32);
    assert!(cycles > 19_000, "{cycles}");
    assert_eq!(allocs, 0, "allocations in {cycles} generator cycles");
}

#[test]
fn the_counter_sees_allocations() {
    let (_, n) = count(|| std::hint::black_box(vec![1u8; 64]));
    assert!(n >= 1);
}
