//! An in-process wire between ethercrab and the emulated line: ethercrab's frames go straight
//! into the emulator (`PduTx`/`PduRx`) and its replies come straight back, no network.

use ethercat_emulator::bus::Bus;
use ethercrab::{MainDevice, MainDeviceConfig, PduLoop, PduRx, PduStorage, PduTx, Timeouts};
use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::thread::JoinHandle;
use std::time::Duration;

pub const MAX_SUBDEVICES: usize = 8;
pub const MAX_PDU_DATA: usize = PduStorage::element_size(1100);
pub const MAX_FRAMES: usize = 16;
pub const MAX_PDI: usize = 128;

/// The PDU storage one MainDevice uses (a `static` per test: it is split once).
pub type Storage = PduStorage<MAX_FRAMES, MAX_PDU_DATA>;

/// The wire: every frame ethercrab sends passes the emulated line and comes back.
struct Wire {
    tx: PduTx<'static>,
    rx: PduRx<'static>,
    bus: Arc<Mutex<Bus>>,
}

impl Future for Wire {
    type Output = ();

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        let this = &mut *self;
        this.tx.replace_waker(cx.waker());
        while let Some(frame) = this.tx.next_sendable_frame() {
            let mut reply = None;
            let sent = frame.send_blocking(|bytes| {
                let mut f = bytes.to_vec();
                let mut bus = this.bus.lock().expect("bus");
                if bus.handle(&mut f).is_ok() {
                    reply = Some(f);
                }
                Ok(bytes.len())
            });
            assert!(sent.is_ok(), "ethercrab could not send");
            if let Some(r) = reply {
                this.rx
                    .receive_frame(&r)
                    .expect("ethercrab takes the reply");
            }
        }
        if this.tx.should_exit() {
            Poll::Ready(())
        } else {
            Poll::Pending
        }
    }
}

/// A MainDevice on `bus`, through `storage`; the wire's thread (it ends once the MainDevice
/// is released).
pub fn main_device(
    storage: &'static Storage,
    bus: Arc<Mutex<Bus>>,
) -> (MainDevice<'static>, JoinHandle<()>) {
    let (tx, rx, pdu_loop) = storage.try_split().expect("split once");
    let wire = Wire { tx, rx, bus };
    let wire = std::thread::spawn(move || futures_lite::future::block_on(wire));
    (maindevice_on(pdu_loop), wire)
}

/// A MainDevice on `pdu_loop` with timeouts generous for the test machine (a noisy 2-vCPU
/// VM) and no static DC synchronisation.
pub fn maindevice_on(pdu_loop: PduLoop<'static>) -> MainDevice<'static> {
    MainDevice::new(
        pdu_loop,
        Timeouts {
            pdu: Duration::from_millis(500),
            eeprom: Duration::from_millis(500),
            state_transition: Duration::from_secs(10),
            mailbox_response: Duration::from_secs(2),
            ..Timeouts::default()
        },
        MainDeviceConfig {
            dc_static_sync_iterations: 0,
            ..MainDeviceConfig::default()
        },
    )
}
