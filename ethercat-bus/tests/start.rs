//! The bus reaches OP with the cycle running, never before it. The set-up brings the bus to
//! SAFE-OP; a set-up that then takes longer than the SubDevices' process data watchdog (the
//! process' own ports and real-time set-up on a busy host) must not take any SubDevice out of
//! OP, as it did when the set-up brought the bus to OP itself: the cycle's frames ask for OP.
//! On a veth pair in a network namespace of the test's own (root), the emulated line
//! answering on a thread of the test.

mod common;

use common::{Line, config, drive_x};
use ethercat_bus::bringup::{Master, Timing};
use ethercat_bus::frame::{CyclicFrame, Reply};
use ethercat_emulator::bus::Bus;
use ethercat_emulator::drive::{self, Drive};
use ethercat_emulator::terminals::Terminal;
use ethercat_wire::{Received, Wire};
use std::time::{Duration, Instant};

/// The ESC's default process data watchdog (the configuration's `pd_watchdog` 0).
const WATCHDOG: Duration = Duration::from_millis(100);

/// Sends the frame and takes its reply; SubDevice 0's AL status and status code then.
fn exchange(frame: &mut CyclicFrame, wire: &Wire) -> (u16, u16) {
    let mut buf = [0u8; 1536];
    wire.send(frame.next_frame()).expect("sent");
    let end = Instant::now() + Duration::from_secs(5);
    loop {
        if let Ok(Received::Frame(n)) = wire.receive(&mut buf)
            && matches!(frame.take_reply(&buf[..n]), Reply::Ours { .. })
        {
            return frame.al_status(0);
        }
        assert!(Instant::now() < end, "the line answers");
    }
}

#[test]
fn a_set_up_slower_than_the_process_data_watchdog_leaves_no_subdevice_out_of_op() {
    let (axis, scaling) = drive::standalone();
    let d = Drive::new("x", &axis, scaling, 300_000_000);
    let line = Line::new("start", Bus::new([Terminal::Drive(Box::new(d))]));
    let cfg = config(&[drive_x(0)]);
    let mut axes = [axis];
    axes[0].mode = 8;
    let (before, states, silent) = line.on_m0(move |wire| {
        let mut master = Master::new().expect("the process' MainDevice");
        let timing = Timing {
            period_ns: 1_000_000,
            phase_ns: 0,
        };
        let up = master
            .bring_up(&cfg, &axes, timing, wire, &|| false)
            .expect("the bus in SAFE-OP");
        // The rest of the process' set-up, three times the watchdog.
        std::thread::sleep(3 * WATCHDOG);
        let mut frame = CyclicFrame::new(up.layout, None).expect("one frame");
        let before = exchange(&mut frame, wire);
        // The cycle: its frames ask for OP until the reply reads it.
        frame.request_op(true);
        let mut states = Vec::new();
        for _ in 0..20 {
            let s = exchange(&mut frame, wire);
            states.push(s);
            if s.0 == 0x08 {
                frame.request_op(false);
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        // The watchdog does run: a bus in OP left silent as long drops out of it.
        std::thread::sleep(3 * WATCHDOG);
        let silent = exchange(&mut frame, wire);
        (before, states, silent)
    });
    assert_eq!(
        before,
        (0x04, 0),
        "SAFE-OP without an error after the set-up's gap (the watchdog ran out in SAFE-OP, where it changes nothing)"
    );
    assert!(
        states.iter().all(|&(s, code)| s & 0x10 == 0 && code == 0),
        "no error on the way to OP: {states:x?}"
    );
    assert_eq!(states.last(), Some(&(0x08, 0)), "in OP: {states:x?}");
    assert_eq!(
        silent,
        (0x14, 0x001B),
        "a bus in OP left silent for three watchdog times: SAFE-OP, error, watchdog"
    );
}
