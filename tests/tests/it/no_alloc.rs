//! The cycle code of servo, the machine, iobridge and the cycle clock allocates nothing:
//! 20 000 closed-loop cycles under the counting allocator (trajgen has its own test).

use machine_sim::Machine;
use runtime::alloc_count::count;
use runtime::cycle::CycleClock;
use servo::{Controller, Params as ServoParams};
use supervisor::config::Config;
use trajgen::generator::{Generator, Params};

#[test]
fn the_cycles_of_servo_machine_iobridge_and_the_clock_do_not_allocate() {
    let cell = Config::default_cell().to_shm();
    let mut machine = Machine::new(&cell);
    let mut servo = Controller::new(ServoParams::from_cell(&cell));
    let mut generator = Generator::new(Params::from_cell(&cell), &[40.0, 40.0, 0.0]);
    let cmds = motion_program::parse("MOVE(140,40,90)\nMOVE(90,126,0)\nSTOP\nEND", 3)
        .expect("parses")
        .to_commands(1, 1);
    for c in &cmds {
        generator.push_command(c);
    }
    let mut clock = CycleClock::new(1_000_000, 0, 1_000_000_000);
    let ms = 1_000_000u64;
    let enable = shm_schema::ServoRequestV1 {
        seq: 1,
        kind: shm_schema::RequestKind::Enable as u32,
        axis: 0,
        value: 0.0,
    };
    let mut q = shm_schema::EventQueue::default();
    let mut events = 0;
    let (cycles, allocs) = count(|| {
        let mut fb = None;
        let mut n = 0u64;
        for k in 1..=20_000u64 {
            let now = 1_000_000_000 + k * ms;
            let wake = clock.woke(clock.next_deadline_ns(), true, now);
            let sp = (k % 4 == 0).then(|| generator.step(now));
            let req = (k == 1).then_some(enable);
            let (cmd, state) = servo.cycle(now, req.as_ref(), sp.as_ref(), fb.as_ref(), &mut q);
            fb = Some(machine.cycle(now, Some(&cmd), None, &mut q));
            events += q.as_slice().len();
            q.clear();
            std::hint::black_box(iobridge::write_image(k, now, &state));
            clock.finish(&wake, now + 50_000);
            n += 1;
        }
        n
    });
    assert_eq!(cycles, 20_000);
    assert_eq!(allocs, 0, "allocations in {cycles} cycles");
    assert!(
        events >= 5,
        "the cycles ran the drives' and servo's state machines: {events} events"
    );
}
