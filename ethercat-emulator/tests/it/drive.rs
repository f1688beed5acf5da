//! The emulated CiA 402 drive under a MainDevice we did not write (ethercrab 0.7.1, in
//! process): its identity and 0x6502 by SDO, its PDO mapping written in PRE-OP as the cell's
//! bus process writes it (refused objects answered with an abort), OP, the CiA 402 power-up
//! sequence seen in the statusword, a position target followed through the model of
//! `machine-sim`; then the master goes silent mid-motion: a drive whose SyncManager watchdog
//! the master set (1.5 s) drops to SAFE-OP with AL code 0x001B and quick-stops to Switch on
//! disabled; one whose watchdog the master turned off faults by its own command watchdog
//! (0xFF01).

use crate::common::{MAX_PDI, MAX_SUBDEVICES, Storage, main_device};
use ethercat_emulator::bus::Bus;
use ethercat_emulator::drive::{self, Drive, RX_DEFAULT, TX_DEFAULT, mapping, obj};
use ethercat_emulator::terminals::Terminal;
use std::sync::{Arc, Mutex};
use std::time::Duration;

static PDU_STORAGE: Storage = Storage::new();

/// The drives' command watchdog (ns), as long as the ESC's of x.
const WATCHDOG_NS: u64 = 1_500_000_000;

/// The outputs of the default RxPDO.
fn outputs(controlword: u16, mode: i8, position: i32) -> Vec<u8> {
    let mut o = Vec::new();
    o.extend_from_slice(&controlword.to_le_bytes());
    o.extend_from_slice(&mode.to_le_bytes());
    o.extend_from_slice(&position.to_le_bytes());
    o.extend_from_slice(&0i32.to_le_bytes()); // target velocity
    o.extend_from_slice(&0i16.to_le_bytes()); // target torque
    o.extend_from_slice(&0i32.to_le_bytes()); // velocity offset
    o.extend_from_slice(&0i16.to_le_bytes()); // torque offset
    o
}

/// The default TxPDO's statusword, error code and position actual value.
fn inputs(i: &[u8]) -> (u16, u16, i32) {
    (
        u16::from_le_bytes([i[0], i[1]]),
        u16::from_le_bytes([i[3], i[4]]),
        i32::from_le_bytes([i[5], i[6], i[7], i[8]]),
    )
}

#[test]
fn ethercrab_maps_enables_and_moves_the_emulated_drives_and_their_watchdogs_stop_them() {
    let (axis, scaling) = drive::standalone();
    // Watchdogs of 1.5 s (the drives' own, the ESC's of x): room for the host's stalls while
    // the test exchanges. This VM stalls a process for tens of ms now and then, and the host
    // both vCPUs for up to about a second (../shared/notes/machine.md); 300 ms was tripped
    // by cells of other tests starting beside this one at SCHED_FIFO.
    let drive = |name| Terminal::Drive(Box::new(Drive::new(name, &axis, scaling, WATCHDOG_NS)));
    let bus = Arc::new(Mutex::new(Bus::new([drive("x"), drive("y")])));
    let (maindevice, wire) = main_device(&PDU_STORAGE, bus.clone());
    futures_lite::future::block_on(async {
        let group = maindevice
            .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercrab::std::ethercat_now)
            .await
            .expect("ethercrab's init of the emulated drive");
        for (k, sd) in group.iter(&maindevice).enumerate() {
            assert_eq!(sd.identity().vendor_id, drive::VENDOR);
            assert_eq!(sd.identity().product_id, drive::PRODUCT);
            let modes: u32 = sd.sdo_read(obj::SUPPORTED_MODES, 0).await.expect("0x6502");
            assert_eq!(modes, 0x0380, "CSP, CSV, CST");
            let identity: u32 = sd.sdo_read(obj::IDENTITY, 2).await.expect("0x1018:2");
            assert_eq!(identity, drive::PRODUCT);
            // The mapping as the bus process writes it: assignment off, entries, count, on.
            for (assign, pdo, entries) in [
                (obj::SM2_ASSIGN, obj::RXPDO, &RX_DEFAULT),
                (obj::SM3_ASSIGN, obj::TXPDO, &TX_DEFAULT),
            ] {
                sd.sdo_write(assign, 0, 0u8).await.expect("assignment off");
                sd.sdo_write(pdo, 0, 0u8).await.expect("mapping off");
                for (k, &(index, bits)) in entries.iter().enumerate() {
                    sd.sdo_write(pdo, k as u8 + 1, mapping(index, 0, bits))
                        .await
                        .expect("an entry");
                }
                sd.sdo_write(pdo, 0, entries.len() as u8)
                    .await
                    .expect("count");
                sd.sdo_write(assign, 1, pdo).await.expect("assign");
                sd.sdo_write(assign, 0, 1u8).await.expect("assignment on");
            }
            // The process data watchdog in increments of 100 µs on x, off on y.
            let time = if k == 0 {
                u16::try_from(WATCHDOG_NS / 100_000).expect("fits the register")
            } else {
                0
            };
            sd.register_write(0x0420u16, time)
                .await
                .expect("watchdog time");
        }
        let sd = group.subdevice(&maindevice, 0).expect("the drive");
        // An input object in the outputs' mapping, and too many entries: refused, named.
        let e = sd
            .sdo_write(obj::RXPDO, 8, mapping(obj::STATUSWORD, 0, 16))
            .await
            .expect_err("the statusword cannot be an output");
        // ethercrab's names of 0x06040041 and 0x06040042.
        assert!(format!("{e:?}").contains("PdoMappingFailed"), "{e:?}");
        let e = sd
            .sdo_write(obj::RXPDO, 0, 40u8)
            .await
            .expect_err("40 entries");
        assert!(format!("{e:?}").contains("PdoTooSmall"), "{e:?}");

        let group = group
            .into_op(&maindevice)
            .await
            .expect("the drive goes to OP");
        {
            let sd = group.subdevice(&maindevice, 0).expect("the drive");
            assert_eq!((sd.outputs_raw().len(), sd.inputs_raw().len()), (19, 19));
            // The mapping cannot change outside PRE-OP.
            let e = sd
                .sdo_write(obj::RXPDO, 0, 0u8)
                .await
                .expect_err("mapping in OP");
            assert!(format!("{e:?}").contains("InvalidState"), "{e:?}");
        }

        let start = scaling.counts(40.0);
        let exchange = |cw: u16, pos: i32| {
            let group = &group;
            let maindevice = &maindevice;
            async move {
                for k in 0..2 {
                    group
                        .subdevice(maindevice, k)
                        .expect("a drive")
                        .outputs_raw_mut()
                        .copy_from_slice(&outputs(cw, 8, pos));
                }
                let r = group.tx_rx(maindevice).await.expect("tx_rx");
                assert_eq!(r.working_counter, 6, "LRW: each drive read and written");
                std::thread::sleep(Duration::from_millis(1));
                let x = inputs(&group.subdevice(maindevice, 0).expect("x").inputs_raw());
                let y = inputs(&group.subdevice(maindevice, 1).expect("y").inputs_raw());
                assert_eq!(x.0 & 0x6F, y.0 & 0x6F, "both drives in the same state");
                x
            }
        };
        // Shutdown, Switch on, Enable operation: the states in the statusword (0x6F mask).
        let mut seen = Vec::new();
        for cw in [0x06, 0x06, 0x07, 0x07, 0x0F, 0x0F, 0x0F] {
            let (sw, _, _) = exchange(cw, start).await;
            seen.push(sw & 0x6F);
        }
        assert!(seen.contains(&0x21), "Ready to switch on in {seen:x?}");
        assert!(seen.contains(&0x23), "Switched on in {seen:x?}");
        assert_eq!(
            *seen.last().expect("states"),
            0x27,
            "Operation enabled: {seen:x?}"
        );
        // CSP: a ramp of 5 units over 0.5 s, then hold; the axes follow.
        let mut actual = 0;
        for k in 0..=700 {
            let target = 40.0 + 5.0 * (f64::from(k) / 500.0).min(1.0);
            let (sw, _, pos) = exchange(0x0F, scaling.counts(target)).await;
            assert_eq!(sw & 0x6F, 0x27, "still enabled at cycle {k}");
            actual = pos;
        }
        let reached = scaling.units(actual);
        assert!(
            (reached - 45.0).abs() < 0.05,
            "the axis at {reached}, not 45"
        );
        // Back to 40 at 10 units/s; half way the master goes silent (the emulator's idle
        // ticks run the ESCs and the models).
        // The last frame is sent after `silent`: each watchdog counts from it or later.
        let mut silent = std::time::Instant::now();
        for k in 0..=250 {
            let target = 45.0 - 5.0 * f64::from(k) / 500.0;
            silent = std::time::Instant::now();
            exchange(0x0F, scaling.counts(target)).await;
        }
        // Until both watchdogs have tripped and the drives are where the checks below look
        // for them (x stopped to Switch on disabled, y in Fault), or 10 s of silence; when
        // each drive left Operation enabled.
        let mut left: [Option<Duration>; 2] = [None; 2];
        loop {
            std::thread::sleep(Duration::from_millis(10));
            let mut b = bus.lock().expect("bus");
            b.idle();
            let state = |k: usize| match &b.devices[k].terminal {
                Terminal::Drive(d) => d.dictionary().u16(obj::STATUSWORD),
                _ => unreachable!("two drives"),
            };
            for (k, at) in left.iter_mut().enumerate() {
                if at.is_none() && state(k) & 0x6F != 0x27 {
                    *at = Some(silent.elapsed());
                }
            }
            let ended = (state(0) & 0x4F, state(1) & 0x4F) == (0x40, 0x08);
            if ended || silent.elapsed() > Duration::from_secs(10) {
                break;
            }
        }
        // Neither watchdog tripped before its time (a host stall makes the silence longer,
        // never shorter).
        let watchdog = Duration::from_nanos(WATCHDOG_NS);
        for (k, at) in left.iter().enumerate() {
            let at = at.unwrap_or_else(|| panic!("drive {k} still enabled after 10 s of silence"));
            assert!(
                at >= watchdog,
                "drive {k} left Operation enabled after {at:?} of silence"
            );
        }
        let b = bus.lock().expect("bus");
        let drive = |k: usize| match &b.devices[k].terminal {
            Terminal::Drive(d) => d,
            _ => unreachable!("two drives"),
        };
        // x: its ESC's watchdog expired: SAFE-OP with the error flag and 0x001B, its status
        // bit cleared and counted; the drive quick-stopped and is without power, no fault.
        let x = &b.devices[0].esc;
        assert_eq!(x.al_status(), 0x14, "SAFE-OP + error");
        assert_eq!(x.al_status_code(), 0x001B, "SyncManager watchdog");
        assert_eq!(x.memory(0x0440, 1)[0] & 1, 0, "watchdog status: expired");
        assert_eq!(x.memory(0x0442, 1)[0], 1, "one expiry counted");
        let sw = drive(0).dictionary().u16(obj::STATUSWORD);
        assert_eq!(sw & 0x4F, 0x40, "x: Switch on disabled: {sw:#06x}");
        assert_eq!(drive(0).dictionary().u16(obj::ERROR_CODE), 0, "x: no fault");
        // y: no ESC watchdog; its command watchdog faulted it (0xFF01), still in OP.
        assert_eq!(b.devices[1].esc.al_status(), 0x08, "y: still OP");
        let sw = drive(1).dictionary().u16(obj::STATUSWORD);
        assert_eq!(sw & 0x4F, 0x08, "y: Fault: {sw:#06x}");
        assert_eq!(
            drive(1).dictionary().u16(obj::ERROR_CODE),
            0xFF01,
            "command watchdog expired"
        );
        // y's fault is announced by a CoE emergency in its send mailbox: 0xFF01, error
        // register 0x01 (ethercrab polls no mailbox: it stays there unread).
        let y = &b.devices[1].esc;
        let m = y.memory(0x1080, 16);
        assert_eq!(m[5] & 0x0F, 3, "CoE");
        assert_eq!(u16::from_le_bytes([m[6], m[7]]) >> 12, 1, "emergency");
        assert_eq!((u16::from_le_bytes([m[8], m[9]]), m[10]), (0xFF01, 0x01));
        assert_eq!(y.memory(0x080D, 1)[0] & 0x08, 0x08, "SM1 full");
        assert_eq!(
            b.devices[0].esc.memory(0x080D, 1)[0] & 0x08,
            0,
            "x did not fault: no emergency"
        );
        for k in 0..2 {
            let axis = drive(k).machine().axes()[0];
            assert_eq!(axis.velocity, 0.0, "drive {k} at rest");
            assert!(
                axis.position > 42.0 && axis.position < 43.0,
                "drive {k} stopped near where the silence began: {}",
                axis.position
            );
        }
    });
    // SAFETY: the MainDevice is not used after this; its loop tells the wire to stop.
    let _ = unsafe { maindevice.release_all() };
    wire.join().expect("the wire thread");
}
