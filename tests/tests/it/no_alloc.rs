//! The cycle code of servo, the machine, iobridge and the cycle clock allocates nothing:
//! 20 000 closed-loop cycles under the counting allocator (trajgen has its own test), through
//! every path of the servo layer: enabling, following a program, an injected drive fault and
//! its reset, a tuning step, a setpoint that is not a number (command validation latches),
//! reset and enable again.

use cell_config::Config;
use machine_sim::Machine;
use motion_core::generator::{Generator, Params};
use runtime::alloc_count::count;
use runtime::cycle::CycleClock;
use servo::{Controller, Params as ServoParams};
use shm_schema::drive::{injected, servo_status as st};
use shm_schema::event::code;
use shm_schema::{EventQueue, FaultInjectionV1, RequestKind, ServoRequestV1};

#[test]
fn the_cycles_of_servo_machine_iobridge_and_the_clock_do_not_allocate() {
    integration_tests::wall_clock(|| {
        let cell = Config::default_cell().to_shm();
        let mut machine = Machine::new(&cell, cell.period_of("drives").expect("machine"));
        let mut servo = Controller::new(ServoParams::from_cell(
            &cell,
            cell.period_of("servo").expect("servo"),
            cell.period_of("trajgen").expect("trajgen"),
        ));
        let mut generator = Generator::new(Params::from_cell(&cell), &[40.0, 40.0, 0.0]);
        let cmds = crate::gantry_commands("MOVE(60,50,10)\nSTOP\nEND", 1);
        for c in &cmds {
            generator.push_command(c);
        }
        let mut clock = CycleClock::new(1_000_000, 0, 1_000_000_000);
        let ms = 1_000_000u64;
        let request = |seq: u64, kind: RequestKind, value: f64| ServoRequestV1 {
            seq,
            kind: kind as u32,
            axis: 0,
            value,
        };
        let inject = |seq: u64, active: u16| FaultInjectionV1 {
            seq,
            axis: 1,
            code: injected::OVER_CURRENT,
            active,
        };
        // What happened, without allocating: the events seen and the states reached.
        let watched = [
            code::ENABLED,
            code::DRIVE_FAULT,
            code::FAULT_CLEARED,
            code::TUNE_STEP,
            code::COMMAND_NOT_FINITE,
        ];
        let mut seen = [0u32; 5];
        let mut followed = false;
        let mut q = EventQueue::default();
        let (cycles, allocs) = count(|| {
            let mut cmd = None;
            let mut n = 0u64;
            for k in 1..=20_000u64 {
                let now = 1_000_000_000 + k * ms;
                let wake = clock.woke(clock.next_deadline_ns(), true, now);
                let req = match k {
                    3 | 6_000 | 12_000 => Some(request(k, RequestKind::Enable, 0.0)),
                    5_000 | 11_000 => Some(request(k, RequestKind::Reset, 0.0)),
                    7_000 => Some(request(k, RequestKind::Step, 0.2)),
                    8_000 => Some(request(k, RequestKind::Step, 0.0)),
                    _ => None,
                };
                let inj = match k {
                    4_000 => Some(inject(1, 1)),
                    4_100 => Some(inject(2, 0)),
                    _ => None,
                };
                let mut sp = (k % 4 == 0).then(|| generator.step(now, None));
                if k == 10_000
                    && let Some(s) = sp.as_mut()
                {
                    s.position[0] = f64::NAN;
                }
                // The cell's order: the drives sample and apply, then servo reads and commands.
                let fb = machine.cycle(now, cmd.as_ref(), inj.as_ref(), &mut q);
                let (c, state) =
                    servo.cycle(now + 300_000, req.as_ref(), sp.as_ref(), Some(&fb), &mut q);
                cmd = Some(c);
                followed |= state.status & st::ENABLED != 0 && state.cmd_velocity[0] > 1.0;
                for e in q.as_slice() {
                    if let Some(i) = watched.iter().position(|c| *c == e.code) {
                        seen[i] += 1;
                    }
                }
                q.clear();
                std::hint::black_box(iobridge::write_image(k, now, &state));
                clock.finish(&wake, now + 50_000);
                n += 1;
            }
            n
        });
        assert_eq!(cycles, 20_000);
        assert_eq!(allocs, 0, "allocations in {cycles} cycles");
        assert!(followed, "the arm never followed the program");
        for (c, n) in watched.iter().zip(seen) {
            assert!(n > 0, "event {c} never happened: {seen:?}");
        }
        assert_eq!(seen[0], 3, "enabled three times: {seen:?}");
    });
}
