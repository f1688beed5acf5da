//! A CoE emergency that answers an SDO request: what the emulated drive sends when it faults
//! while a MainDevice waits on its mailbox, and what ethercrab 0.7.1 does with it. Its
//! `mailbox/coe/mod.rs` reads the reply's SDO command bits (the top three bits of byte 8,
//! which in an emergency are the error code's low byte) before it looks at the service:
//! - with a code whose low byte has 0 there (0x2310 over-current, 0xFF01, 0x8611) the parse
//!   fails and the read returns `Wire(InvalidValue)`: the emergency is lost, the read fails;
//! - with one that parses (0x7320, encoder lost: 0x20 is "download") it reaches its
//!   `assert_ne!(service, Emergency)` and **panics**, release builds too.
//!
//! This test pins both for the cell's bus process, which must never let ethercrab's SDO path
//! meet an emergency (docs/ethercat.md); if a new ethercrab behaves otherwise, it fails and
//! says so.

use crate::common::{MAX_PDI, MAX_SUBDEVICES, Storage, main_device};
use ethercat_emulator::bus::Bus;
use ethercat_emulator::drive::{self, Drive, obj};
use ethercat_emulator::terminals::Terminal;
use std::panic::AssertUnwindSafe;
use std::sync::{Arc, Mutex};

static PDU_STORAGE: Storage = Storage::new();

#[test]
fn an_emergency_answering_an_sdo_read_fails_ethercrab_0_7_1s_read_or_panics_it() {
    let (axis, scaling) = drive::standalone();
    let drive = Drive::new("x", &axis, scaling, 300_000_000);
    let bus = Arc::new(Mutex::new(Bus::new([Terminal::Drive(Box::new(drive))])));
    let (maindevice, wire) = main_device(&PDU_STORAGE, bus.clone());
    let group = futures_lite::future::block_on(
        maindevice.init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercrab::std::ethercat_now),
    )
    .expect("ethercrab's init of the emulated drive");
    let sd = group.subdevice(&maindevice, 0).expect("the drive");
    let modes: u32 =
        futures_lite::future::block_on(sd.sdo_read(obj::SUPPORTED_MODES, 0)).expect("0x6502");
    assert_eq!(modes, 0x0380, "an SDO read without an emergency");
    let emergency_next = |code: u16| {
        if let Terminal::Drive(d) = &mut bus.lock().expect("bus").devices[0].terminal {
            d.emergency_on_next_request(code);
        }
    };
    // Over-current: misparsed, an error.
    emergency_next(0x2310);
    let read = futures_lite::future::block_on(sd.sdo_read::<u16>(obj::STATUSWORD, 0));
    assert!(
        format!("{read:?}").contains("InvalidValue"),
        "ethercrab took an emergency of 0x2310 answering an SDO otherwise: {read:?}"
    );
    // Encoder lost: the assertion.
    emergency_next(0x7320);
    let read = std::panic::catch_unwind(AssertUnwindSafe(|| {
        futures_lite::future::block_on(sd.sdo_read::<u16>(obj::STATUSWORD, 0))
    }));
    assert!(
        read.is_err(),
        "ethercrab no longer panics on an emergency of 0x7320 answering an SDO ({:?}): the \
         bus process's guard may be revisited (docs/ethercat.md)",
        read.ok()
    );
    // Each answer came behind its emergency: the drive's mailbox stays consistent, and the
    // next read works (ethercrab clears a full mailbox before it writes).
    let sw: u16 =
        futures_lite::future::block_on(sd.sdo_read(obj::STATUSWORD, 0)).expect("the next SDO read");
    assert_eq!(sw & 0x4F, 0x40, "Switch on disabled: {sw:#06x}");
    // SAFETY: the MainDevice is not used after this; its loop tells the wire to stop.
    let _ = unsafe { maindevice.release_all() };
    wire.join().expect("the wire thread");
}
