//! A CoE emergency in place of an SDO answer during start-up: ethercrab 0.7.1 alone panics on
//! it (`ethercat-emulator/tests/emergency.rs` pins that), the bus' [`Master`] takes it out of
//! the reply first, tries the SDO once more, and reports the emergency with the SubDevice's
//! position. On a veth pair in a network namespace of the test's own (root), the emulated
//! drive answering on a thread of the test.

use ethercat_bus::bringup::Master;
use ethercat_emulator::bus::Bus;
use ethercat_emulator::drive::{self, Drive};
use ethercat_emulator::terminals::Terminal;
use ethercat_wire::{Received, Wire};
use shm_schema::{EthercatConfigV1, EthercatSubDeviceV1, fixed_str};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

fn ip(args: &[&str]) {
    let out = Command::new("ip")
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("this test needs iproute2's `ip`: {e}"));
    assert!(
        out.status.success(),
        "ip {args:?} (this test makes a network namespace: it needs root): {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The namespace, removed when dropped.
struct Netns(String);

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = Command::new("ip").args(["netns", "del", &self.0]).status();
    }
}

/// Enters namespace `ns` on this thread.
fn enter(ns: &str) {
    let f = std::fs::File::open(format!("/run/netns/{ns}")).expect("the namespace");
    nix::sched::setns(f, nix::sched::CloneFlags::CLONE_NEWNET).expect("setns");
}

#[test]
fn an_emergency_answering_a_start_up_sdo_is_taken_out_of_ethercrabs_way_and_reported() {
    let ns = Netns(format!("rtc-{}-guard", std::process::id()));
    ip(&["netns", "add", &ns.0]);
    ip(&[
        "-n", &ns.0, "link", "add", "m0", "type", "veth", "peer", "name", "s0",
    ]);
    ip(&["-n", &ns.0, "link", "set", "s0", "up"]);
    ip(&["-n", &ns.0, "link", "set", "m0", "up"]);

    // The drive, told to answer the first mailbox request with an encoder-lost emergency
    // (0x7320: the code whose bits make ethercrab reach its assertion).
    let (axis, scaling) = drive::standalone();
    let mut d = Drive::new("x", &axis, scaling, 300_000_000);
    d.emergency_on_next_request(0x7320);
    let mut bus = Bus::new([Terminal::Drive(Box::new(d))]);
    let stop = Arc::new(AtomicBool::new(false));
    let (ready, answers) = std::sync::mpsc::channel();
    let answering = {
        let (ns, stop) = (ns.0.clone(), stop.clone());
        std::thread::spawn(move || {
            enter(&ns);
            let wire = Wire::open("s0", Duration::from_millis(5)).expect("s0");
            ready.send(()).expect("the test waits");
            let mut buf = vec![0u8; 9216];
            while !stop.load(Ordering::Relaxed) {
                match wire.receive(&mut buf) {
                    Ok(Received::Frame(n)) => {
                        if bus.handle(&mut buf[..n]).is_ok() {
                            let _ = wire.send(&buf[..n]);
                        }
                    }
                    _ => bus.idle(),
                }
            }
        })
    };

    let mut cfg = EthercatConfigV1 {
        interface: fixed_str("m0"),
        count: 1,
        ..EthercatConfigV1::default()
    };
    cfg.subdevice[0] = EthercatSubDeviceV1 {
        name: fixed_str("x"),
        vendor: 0xE1A0_0001,
        product: 0x402,
        axis: 0,
        counts_per_unit: 1000.0,
        rated_effort: 10.0,
        ..EthercatSubDeviceV1::default()
    };
    answers
        .recv_timeout(Duration::from_secs(60))
        .expect("the line answers");
    let mut axes = [axis];
    axes[0].mode = 8;
    let up = std::thread::spawn({
        let ns = ns.0.clone();
        move || {
            enter(&ns);
            let wire = Wire::open("m0", Duration::from_millis(1)).expect("m0");
            let mut master = Master::new().expect("the process' MainDevice");
            master.bring_up(
                &cfg,
                &axes,
                ethercat_bus::bringup::Timing {
                    period_ns: 1_000_000,
                    phase_ns: 0,
                },
                &wire,
                &|| false,
            )
        }
    })
    .join();
    stop.store(true, Ordering::Relaxed);
    answering.join().expect("the emulated line");
    let up = up
        .expect("no panic: the emergency never reached ethercrab")
        .expect("the bus in OP");
    assert_eq!(up.emergencies, [(0, 0x7320, 0x01)], "{up:?}");
    assert_eq!(up.layout.count, 1);
    assert!(up.layout.slots[0].mailbox_in.1 > 0, "its mailbox known");
}
