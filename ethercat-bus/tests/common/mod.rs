//! An emulated line on a veth pair in a network namespace of the test's own (root): the
//! emulator answers on `s0` on a thread of the test, the bus' end is `m0`.

// Each test binary that includes this module uses part of it.
#![allow(dead_code)]

use ethercat_emulator::bus::Bus;
use ethercat_emulator::drive;
use ethercat_wire::{Received, Wire};
use shm_schema::{EthercatConfigV1, EthercatSubDeviceV1, fixed_str};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
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

/// Whether `link` in namespace `ns` is operationally up (its `operstate` in `ip -j`'s JSON).
fn operational(ns: &str, link: &str) -> bool {
    Command::new("ip")
        .args(["-j", "-n", ns, "link", "show", "dev", link])
        .output()
        .ok()
        .and_then(|o| serde_json::from_slice::<serde_json::Value>(&o.stdout).ok())
        .is_some_and(|v| v[0]["operstate"] == "UP")
}

/// The namespace, removed when dropped.
pub struct Netns(pub String);

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = Command::new("ip").args(["netns", "del", &self.0]).status();
    }
}

/// Enters namespace `ns` on this thread.
pub fn enter(ns: &str) {
    let f = std::fs::File::open(format!("/run/netns/{ns}")).expect("the namespace");
    nix::sched::setns(f, nix::sched::CloneFlags::CLONE_NEWNET).expect("setns");
}

/// `bus` answering on `s0` of a veth pair `m0`–`s0` in a new namespace named after `test`,
/// until [`Line::stop`] hands it back.
pub struct Line {
    pub ns: Netns,
    stop: Arc<AtomicBool>,
    answering: Option<JoinHandle<Bus>>,
}

impl Line {
    pub fn new(test: &str, mut bus: Bus) -> Self {
        let ns = Netns(format!("rtc-{}-{test}", std::process::id()));
        ip(&["netns", "add", &ns.0]);
        ip(&[
            "-n", &ns.0, "link", "add", "m0", "type", "veth", "peer", "name", "s0",
        ]);
        ip(&["-n", &ns.0, "link", "set", "s0", "up"]);
        ip(&["-n", &ns.0, "link", "set", "m0", "up"]);
        // Frames go out once the kernel's link watch has seen the carrier (it attaches the
        // queues and says "state UP"); before, they are dropped. It can lag behind while other
        // tests make and remove links of their own, and a scan's first frame lost is a failed
        // bring-up.
        for end in ["m0", "s0"] {
            let start = std::time::Instant::now();
            while !operational(&ns.0, end) {
                assert!(
                    start.elapsed() < Duration::from_secs(60),
                    "{end} in {} not up after 60 s",
                    ns.0
                );
                std::thread::sleep(Duration::from_millis(5));
            }
        }
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
                bus
            })
        };
        answers
            .recv_timeout(Duration::from_secs(60))
            .expect("the line answers");
        Self {
            ns,
            stop,
            answering: Some(answering),
        }
    }

    /// Runs `f` on a thread in the namespace with the bus' end `m0` open.
    pub fn on_m0<T: Send + 'static>(&self, f: impl FnOnce(&Wire) -> T + Send + 'static) -> T {
        let ns = self.ns.0.clone();
        std::thread::spawn(move || {
            enter(&ns);
            let wire = Wire::open("m0", Duration::from_millis(1)).expect("m0");
            f(&wire)
        })
        .join()
        .expect("no panic on the bus' side")
    }

    /// Stops answering and hands the line back.
    pub fn stop(mut self) -> Bus {
        self.stop.store(true, Ordering::Relaxed);
        self.answering
            .take()
            .expect("answering")
            .join()
            .expect("the emulated line")
    }
}

impl Drop for Line {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.answering.take() {
            let _ = t.join();
        }
    }
}

/// A bus on `m0` of `subdevices`.
pub fn config(subdevices: &[EthercatSubDeviceV1]) -> EthercatConfigV1 {
    let mut cfg = EthercatConfigV1 {
        interface: fixed_str("m0"),
        count: subdevices.len() as u32,
        ..EthercatConfigV1::default()
    };
    cfg.subdevice[..subdevices.len()].copy_from_slice(subdevices);
    cfg
}

/// The emulator's drive "x" moving axis 0 (its standalone axis: 1000 counts per mm, a rated
/// torque of 10), with `flags`.
pub fn drive_x(flags: u32) -> EthercatSubDeviceV1 {
    EthercatSubDeviceV1 {
        name: fixed_str("x"),
        vendor: drive::VENDOR,
        product: drive::PRODUCT,
        flags,
        axis: 0,
        counts_per_unit: 1000.0,
        rated_effort: 10.0,
        ..EthercatSubDeviceV1::default()
    }
}
