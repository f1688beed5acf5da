//! A CoE emergency in place of an SDO answer during start-up: ethercrab 0.7.1 alone panics on
//! it (`ethercat-emulator/tests/it/emergency.rs` pins that), the bus' [`Master`] takes it out of
//! the reply first, tries the SDO once more, and reports the emergency with the SubDevice's
//! position. On a veth pair in a network namespace of the test's own (root), the emulated
//! drive answering on a thread of the test.

mod common;

use common::{Line, config, drive_x};
use ethercat_bus::bringup::{Master, Timing};
use ethercat_emulator::bus::Bus;
use ethercat_emulator::drive::{self, Drive};
use ethercat_emulator::terminals::Terminal;

#[test]
fn an_emergency_answering_a_start_up_sdo_is_taken_out_of_ethercrabs_way_and_reported() {
    // The drive, told to answer the first mailbox request with an encoder-lost emergency
    // (0x7320: the code whose bits make ethercrab reach its assertion).
    let (axis, scaling) = drive::standalone();
    let mut d = Drive::new("x", &axis, scaling, 300_000_000);
    d.emergency_on_next_request(0x7320);
    let line = Line::new("guard", Bus::new([Terminal::Drive(Box::new(d))]));

    let cfg = config(&[drive_x(0)]);
    let mut axes = [axis];
    axes[0].mode = 8;
    let up = std::thread::spawn(move || {
        line.on_m0(move |wire| {
            let mut master = Master::new().expect("the process' MainDevice");
            let timing = Timing {
                period_ns: 1_000_000,
                phase_ns: 0,
            };
            master.bring_up(&cfg, &axes, timing, wire, &|| false)
        })
    })
    .join();
    let up = up
        .expect("no panic: the emergency never reached ethercrab")
        .expect("the bus in OP");
    assert_eq!(up.emergencies, [(0, 0x7320, 0x01)], "{up:?}");
    assert_eq!(up.layout.count, 1);
    assert!(up.layout.slots[0].mailbox_in.1 > 0, "its mailbox known");
}
