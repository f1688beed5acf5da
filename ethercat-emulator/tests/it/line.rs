//! The emulated line checked by a MainDevice we did not write: ethercrab (0.7.1) scans it,
//! reads each SubDevice's identity and name from its SII, configures the SyncManagers and
//! FMMUs from the EEPROM's categories, brings the line to OP and exchanges process data
//! with the expected working counter. In process: ethercrab's frames go straight into the
//! emulator (`PduTx`/`PduRx`) and its replies come straight back, no network.

use crate::common::{MAX_PDI, MAX_SUBDEVICES, Storage, main_device};
use ethercat_emulator::bus::Bus;
use ethercat_emulator::esc::AlState;
use ethercat_emulator::terminals::{BECKHOFF, Terminal};
use std::sync::{Arc, Mutex};

static PDU_STORAGE: Storage = Storage::new();

#[test]
fn ethercrab_brings_the_emulated_line_to_op_and_exchanges_its_process_data() {
    let bus = Arc::new(Mutex::new(Bus::new([
        Terminal::Ek1100,
        Terminal::El1008 { inputs: 0 },
        Terminal::El2008 { outputs: 0 },
    ])));
    let (maindevice, wire) = main_device(&PDU_STORAGE, bus.clone());
    futures_lite::future::block_on(async {
        let group = maindevice
            .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercrab::std::ethercat_now)
            .await
            .expect("ethercrab's init of the emulated line");
        assert_eq!(group.len(), 3, "three SubDevices found");
        let expected = [
            ("EK1100", 0x044C_2C52),
            ("EL1008", 0x03F0_3052),
            ("EL2008", 0x07D8_3052),
        ];
        for (sd, (name, product)) in group.iter(&maindevice).zip(expected) {
            let id = sd.identity();
            assert_eq!(sd.name(), name);
            assert_eq!((id.vendor_id, id.product_id), (BECKHOFF, product), "{name}");
            assert_ne!(sd.configured_address(), 0, "{name} has a station address");
        }
        {
            let b = bus.lock().expect("bus");
            for d in &b.devices {
                assert_eq!(d.esc.al_state(), Some(AlState::PreOp), "{d:?}");
            }
        }
        let group = group
            .into_op(&maindevice)
            .await
            .expect("the line goes to OP");
        {
            let b = bus.lock().expect("bus");
            for d in &b.devices {
                assert_eq!(d.esc.al_state(), Some(AlState::Op), "{d:?}");
            }
        }
        // Each cycle: the field sets the EL1008's inputs, ethercrab writes the EL2008's
        // outputs; both arrive in the next exchange. The working counter of one LRW: the
        // EL1008 read (+1), the EL2008 written (+2).
        for k in 0u8..20 {
            let pattern = k.wrapping_mul(37) ^ 0x5A;
            if let Terminal::El1008 { inputs } = &mut bus.lock().expect("bus").devices[1].terminal {
                *inputs = pattern;
            }
            group
                .subdevice(&maindevice, 2)
                .expect("EL2008")
                .outputs_raw_mut()[0] = !pattern;
            let r = group.tx_rx(&maindevice).await.expect("tx_rx");
            assert_eq!(r.working_counter, 3, "cycle {k}");
            assert!(r.all_op(), "cycle {k}: {:?}", r.subdevice_states);
            let seen = group
                .subdevice(&maindevice, 1)
                .expect("EL1008")
                .inputs_raw()[0];
            assert_eq!(seen, pattern, "cycle {k}: the EL1008's inputs as read");
            let driven = match bus.lock().expect("bus").devices[2].terminal {
                Terminal::El2008 { outputs } => outputs,
                _ => unreachable!("the EL2008 is third"),
            };
            assert_eq!(
                driven, !pattern,
                "cycle {k}: the EL2008's outputs as driven"
            );
        }
        let group = group
            .into_safe_op(&maindevice)
            .await
            .expect("back to SAFE-OP");
        // Outputs go off out of OP.
        let _ = group.tx_rx(&maindevice).await;
        let driven = match bus.lock().expect("bus").devices[2].terminal {
            Terminal::El2008 { outputs } => outputs,
            _ => unreachable!("the EL2008 is third"),
        };
        assert_eq!(driven, 0, "outputs off in SAFE-OP");
        let group = group
            .into_pre_op(&maindevice)
            .await
            .expect("back to PRE-OP");
        let _ = group.into_init(&maindevice).await.expect("back to INIT");
        let b = bus.lock().expect("bus");
        for d in &b.devices {
            assert_eq!(d.esc.al_state(), Some(AlState::Init), "{d:?}");
        }
    });
    // SAFETY: the MainDevice is not used after this; its loop tells the wire to stop.
    let _ = unsafe { maindevice.release_all() };
    wire.join().expect("the wire thread");
}

/// DL status (0x0110) as a MainDevice reads the line's topology from it: link on port 0
/// everywhere, on port 1 except at the line's end, whose loop is closed; on a ring
/// (`close_ring`, the emulator's `--ring`) the last port 1 has its link and is open too.
#[test]
fn the_dl_status_shows_where_the_line_ends_and_a_ring_has_no_end() {
    let link1 = 1 << 5;
    let closed1 = 1 << 10;
    let terminals = || [Terminal::Ek1100, Terminal::El1008 { inputs: 0 }];
    let status = |bus: &mut Bus, k: usize| {
        let mut b = [0u8; 2];
        assert!(bus.devices[k].esc.read(0x0110, &mut b, false));
        u16::from_le_bytes(b)
    };
    let mut line = Bus::new(terminals());
    for k in 0..2 {
        assert_ne!(status(&mut line, k) & 1 << 4, 0, "port 0 has a link at {k}");
    }
    assert_eq!(status(&mut line, 0) & (link1 | closed1), link1);
    assert_eq!(status(&mut line, 1) & (link1 | closed1), closed1);
    let mut ring = Bus::new(terminals());
    ring.close_ring();
    for k in 0..2 {
        assert_eq!(status(&mut ring, k) & (link1 | closed1), link1, "at {k}");
    }
}
