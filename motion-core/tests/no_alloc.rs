//! The generator's cycle allocates nothing: a whole program with moves, joint moves, IO,
//! waits, delays, a speed change and a loop, command intake included.

use motion_core::Phase;
use motion_core::generator::{Generator, Params};
use motion_program::CellSpec;
use runtime::alloc_count::{CountingAllocator, count};
use shm_schema::{MAX_AXES, MotionCommandV2, MotionState};

#[global_allocator]
static A: CountingAllocator = CountingAllocator;

const PROGRAM: &str = "\
REPEAT 2
  MOVE(140, 40, 0)
  STOP
  OUT(gripper, 1)
  WAIT(gripper_closed, 1, 2)
  SPEED(50)
  MOVEJ(90, 126, 0)
  DELAY(0.2)
  OUT(gripper, 0)
ENDREPEAT
MOVE(40, 40, 0)
END
";

#[test]
fn the_generator_cycle_does_not_allocate() {
    let mut p = Params {
        axes: 3,
        coords: 3,
        vmax: [1.0; MAX_AXES],
        coord_vmax: [1.0; MAX_AXES],
        min: [-1000.0; MAX_AXES],
        max: [1000.0; MAX_AXES],
        t_acc: 0.525,
    };
    p.vmax[..3].copy_from_slice(&[16.0, 16.0, 30.0]);
    p.coord_vmax = p.vmax;
    let mut cell = CellSpec::cartesian(&[("x", "mm"), ("y", "mm"), ("theta", "deg")]);
    cell.outputs = vec![("gripper".into(), 1)];
    cell.inputs = vec![("gripper_closed".into(), 2)];
    let cmds: Vec<MotionCommandV2> = motion_program::parse(PROGRAM.as_bytes(), &cell)
        .expect("parses")
        .commands(1)
        .collect();
    let mut g = Generator::new(p, &[40.0, 40.0, 0.0]);
    let ((cycles, state, outs), allocs) = count(|| {
        for c in &cmds {
            g.push_command(c);
        }
        let (mut n, mut outs) = (0u64, 0u32);
        let mut inputs = 0u64;
        let mut sp = g.step(0, Some(inputs));
        while sp.state == MotionState::Moving as u32 || n == 0 {
            n += 1;
            let now = n * 1_000_000;
            if let Some(o) = g.take_outputs() {
                outs += 1;
                // The gripper's sensor follows its output.
                inputs = if o.values & 2 != 0 { 4 } else { 0 };
            }
            if let Phase::Waiting { .. } = g.phase() {
                assert!(inputs & 4 != 0 || n < 100_000);
            }
            sp = g.step(now, Some(inputs));
            if n > 200_000 {
                break;
            }
        }
        (n, sp.state, outs)
    });
    assert_eq!(state, MotionState::Done as u32);
    assert_eq!(outs, 4, "two OUTs per iteration");
    assert!(cycles > 1000, "{cycles}");
    assert_eq!(allocs, 0, "allocations during {cycles} cycles");
}
