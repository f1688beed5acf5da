//! The `ethercat-emulator` process answering real frames on a Linux interface: one end of a
//! veth pair in a network namespace the test makes (and removes), ethercrab's own raw-socket
//! TX/RX task on the other end. Nothing touches the host's interfaces. Needs root (CI is).
//! (SOEM and kickcat, two masters we did not write, check the same process from the
//! integration tests: `tests/tests/it/masters.rs`.)

use crate::common::{MAX_PDI, MAX_SUBDEVICES, Storage};
use std::time::{Duration, Instant};

static PDU_STORAGE: Storage = Storage::new();

#[test]
fn ethercrab_on_a_veth_brings_the_emulator_process_to_op_and_its_outputs_come_back() {
    let line = integration_tests::EmulatedLine::up(
        std::path::Path::new(env!("CARGO_BIN_EXE_ethercat-emulator")),
        "ethercrab",
        &["--loopback", "--pd-watchdog-ms", "2000"],
    );
    let (tx, rx, pdu_loop) = PDU_STORAGE.try_split().expect("split once");
    // ethercrab's raw socket is opened in the namespace: by a thread that entered it.
    let ns = line.ns.clone();
    let wire = std::thread::spawn(move || {
        let f = std::fs::File::open(format!("/run/netns/{ns}")).expect("the namespace");
        nix::sched::setns(f, nix::sched::CloneFlags::CLONE_NEWNET).expect("setns");
        let task = ethercrab::std::tx_rx_task("m0", tx, rx).expect("ethercrab's raw socket on m0");
        let _ = futures_lite::future::block_on(task);
    });
    let maindevice = crate::common::maindevice_on(pdu_loop);
    futures_lite::future::block_on(async {
        // The emulator may still be opening its socket: the first scans may find nothing.
        let start = Instant::now();
        let group = loop {
            match maindevice
                .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercrab::std::ethercat_now)
                .await
            {
                Ok(g) if g.len() == 3 => break g,
                other => {
                    assert!(
                        start.elapsed() < Duration::from_secs(60),
                        "ethercrab never found the line: {:?}",
                        other.map(|g| g.len())
                    );
                    std::thread::sleep(Duration::from_millis(100));
                }
            }
        };
        let names: Vec<String> = group
            .iter(&maindevice)
            .map(|sd| sd.name().to_string())
            .collect();
        assert_eq!(names, ["EK1100", "EL1008", "EL2008"]);
        let group = group.into_op(&maindevice).await.expect("OP over the veth");
        // What ethercrab writes to the EL2008 comes back on the EL1008 (the test cable) in a
        // later exchange; every exchange has the working counter 3.
        for k in 0u8..20 {
            let pattern = k.wrapping_mul(73) ^ 0xC3;
            group
                .subdevice(&maindevice, 2)
                .expect("EL2008")
                .outputs_raw_mut()[0] = pattern;
            let mut back = None;
            for _ in 0..3 {
                let r = group.tx_rx(&maindevice).await.expect("tx_rx over the veth");
                assert_eq!(r.working_counter, 3, "cycle {k}");
                let seen = group
                    .subdevice(&maindevice, 1)
                    .expect("EL1008")
                    .inputs_raw()[0];
                if seen == pattern {
                    back = Some(seen);
                    break;
                }
            }
            assert_eq!(
                back,
                Some(pattern),
                "cycle {k}: the outputs did not come back"
            );
        }
        let group = group.into_safe_op(&maindevice).await.expect("SAFE-OP");
        let group = group.into_pre_op(&maindevice).await.expect("PRE-OP");
        let _ = group.into_init(&maindevice).await.expect("INIT");
    });
    // SAFETY: the MainDevice is not used after this; its loop tells the TX/RX task to stop.
    let _ = unsafe { maindevice.release_all() };
    wire.join().expect("the TX/RX thread");
    drop(line);
}
