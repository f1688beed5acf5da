//! Start-up of the bus, before the cycle and before anything is enabled: ethercrab scans the
//! line, the SubDevices found are compared with `[[ethercat.subdevice]]` (a missing one, one
//! more, or another identity at a position is refused, naming the position, the expected and
//! the found identity), each drive's process data is mapped by SDO in PRE-OP (the cell's
//! [`cia402::pdo::RX_DEFAULT`] and [`cia402::pdo::TX_DEFAULT`]), its supported modes checked
//! against the axis' mode, its quick stop written from the configuration, every SubDevice's
//! process data watchdog set, and the bus taken through SAFE-OP to OP. Then the FMMUs ethercrab
//! configured are read back from the SubDevices: the cycle's own frame uses them.
//!
//! ethercrab's futures are driven here, on this thread, by [`Pump`]: its frames go out of the
//! cell's [`Wire`] and the replies come back into it. Nothing of ethercrab runs once the bus
//! is in OP (its own cyclic exchange would allocate a timer per frame).

use crate::frame::{Layout, Slot};
use cia402::pdo::{RX_DEFAULT, TX_DEFAULT, mapping, obj};
use ethercat_wire::{Received, Wire};
use ethercrab::{MainDevice, MainDeviceConfig, PduRx, PduStorage, PduTx, Timeouts};
use shm_schema::ethercat::{MAX_SUBDEVICES, subdevice_flags};
use shm_schema::{AxisConfigV2, EthercatConfigV1};
use std::future::Future;
use std::pin::pin;
use std::task::{Context, Poll, Waker};
use std::time::{Duration, Instant};

const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);
/// Bytes of the process image ethercrab may lay out.
const MAX_PDI: usize = 1100;

static PDU_STORAGE: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

/// ethercrab's frames through the cell's wire.
struct Pump<'w> {
    tx: PduTx<'static>,
    rx: PduRx<'static>,
    wire: &'w Wire,
    buf: Vec<u8>,
}

impl Pump<'_> {
    /// Drives `fut` to its end, sending what it queues and handing it what comes back, for at
    /// most `limit` (or until `stop` says so).
    fn run<F: Future>(
        &mut self,
        fut: F,
        limit: Duration,
        stop: &dyn Fn() -> bool,
    ) -> Result<F::Output, String> {
        let mut fut = pin!(fut);
        let mut cx = Context::from_waker(Waker::noop());
        let end = Instant::now() + limit;
        loop {
            if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
                return Ok(v);
            }
            while let Some(frame) = self.tx.next_sendable_frame() {
                let wire = self.wire;
                frame
                    .send_blocking(|bytes| {
                        wire.send(bytes)
                            .map(|()| bytes.len())
                            .map_err(|_| ethercrab::error::Error::SendFrame)
                    })
                    .map_err(|e| format!("sending a frame: {e}"))?;
            }
            if let Received::Frame(n) = self.wire.receive(&mut self.buf)? {
                // Anything that is not a reply of ours is ignored by ethercrab itself.
                let _ = self.rx.receive_frame(&self.buf[..n]);
            }
            if stop() {
                return Err("stopped during start-up".into());
            }
            if Instant::now() > end {
                return Err(format!("no answer within {} s", limit.as_secs_f64()));
            }
        }
    }
}

/// A SubDevice's identity for messages.
fn identity(vendor: u32, product: u32, revision: u32) -> String {
    format!("vendor {vendor:#010x}, product {product:#010x}, revision {revision:#010x}")
}

/// What the bus is once in OP.
#[derive(Debug)]
pub struct Up {
    /// The process image and where each SubDevice's data sits.
    pub layout: Layout,
    /// Each SubDevice's name as its EEPROM gives it.
    pub names: Vec<String>,
}

/// Brings the bus of `cfg` on `wire` to OP, the drives mapped for `axes`; see the module
/// documentation. Errors name the SubDevice (position and name) and what is wrong.
pub fn bring_up(
    cfg: &EthercatConfigV1,
    axes: &[AxisConfigV2],
    wire: &Wire,
    stop: &dyn Fn() -> bool,
) -> Result<Up, String> {
    let (tx, rx, pdu_loop) = PDU_STORAGE
        .try_split()
        .map_err(|()| "the bus can be brought up once per process".to_string())?;
    let mut pump = Pump {
        tx,
        rx,
        wire,
        buf: vec![0; 9216],
    };
    // Timeouts with room for a loaded machine; the cycle does not use them.
    let md = MainDevice::new(
        pdu_loop,
        Timeouts {
            pdu: Duration::from_millis(200),
            eeprom: Duration::from_millis(200),
            state_transition: Duration::from_secs(10),
            mailbox_response: Duration::from_secs(2),
            ..Timeouts::default()
        },
        MainDeviceConfig {
            dc_static_sync_iterations: 0,
            ..MainDeviceConfig::default()
        },
    );
    let long = Duration::from_secs(30);
    let group = pump
        .run(
            md.init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercrab::std::ethercat_now),
            long,
            stop,
        )?
        .map_err(|e| format!("scanning the bus on {}: {e}", cfg.interface()))?;

    // The line against the configuration, before anything else is written.
    let want = cfg.subdevices();
    let found: Vec<_> = group
        .iter(&md)
        .map(|sd| {
            (
                sd.identity(),
                sd.name().to_string(),
                sd.configured_address(),
            )
        })
        .collect();
    for (k, w) in want.iter().enumerate() {
        let expected = if w.flags & subdevice_flags::CHECK_REVISION != 0 {
            format!(
                "{} ({})",
                w.name(),
                identity(w.vendor, w.product, w.revision)
            )
        } else {
            format!(
                "{} (vendor {:#010x}, product {:#010x}, any revision)",
                w.name(),
                w.vendor,
                w.product
            )
        };
        let Some((id, name, _)) = found.get(k) else {
            return Err(format!(
                "the bus on {} has {} SubDevice(s): position {k} should be {expected}, and nothing answers there",
                cfg.interface(),
                found.len()
            ));
        };
        let revision_ok =
            w.flags & subdevice_flags::CHECK_REVISION == 0 || id.revision == w.revision;
        if id.vendor_id != w.vendor || id.product_id != w.product || !revision_ok {
            return Err(format!(
                "position {k} of the bus on {} should be {expected}, and {name} ({}) is there",
                cfg.interface(),
                identity(id.vendor_id, id.product_id, id.revision)
            ));
        }
    }
    if let Some((id, name, _)) = found.get(want.len()) {
        return Err(format!(
            "the bus on {} has {} SubDevice(s) where the configuration names {}: position {} is {name} ({}), which it does not name",
            cfg.interface(),
            found.len(),
            want.len(),
            want.len(),
            identity(id.vendor_id, id.product_id, id.revision)
        ));
    }

    // PRE-OP: each drive's mapping, modes and quick stop; every SubDevice's watchdog.
    for (k, (sd, w)) in group.iter(&md).zip(want).enumerate() {
        let at = |what: &str, e: ethercrab::error::Error| {
            format!("position {k} ({}): {what}: {e}", w.name())
        };
        if let Some(a) = w.axis() {
            let axis = axes.get(a).ok_or_else(|| {
                format!("position {k} ({}): axis {a} is not in the cell", w.name())
            })?;
            let modes: u32 = pump
                .run(sd.sdo_read(obj::SUPPORTED_MODES, 0), long, stop)?
                .map_err(|e| at("reading 0x6502", e))?;
            let bit = u32::try_from(axis.mode - 1)
                .ok()
                .filter(|b| *b < 32)
                .map_or(0, |b| 1u32 << b);
            if modes & bit == 0 {
                return Err(format!(
                    "position {k} ({}): the drive does not support mode {} (0x6502 = {modes:#010x})",
                    w.name(),
                    axis.mode
                ));
            }
            for (assign, pdo, entries) in [
                (obj::SM2_ASSIGN, obj::RXPDO, &RX_DEFAULT),
                (obj::SM3_ASSIGN, obj::TXPDO, &TX_DEFAULT),
            ] {
                let what = format!("mapping {pdo:#06x}");
                pump.run(sd.sdo_write(assign, 0, 0u8), long, stop)?
                    .map_err(|e| at(&what, e))?;
                pump.run(sd.sdo_write(pdo, 0, 0u8), long, stop)?
                    .map_err(|e| at(&what, e))?;
                for (n, &(index, bits)) in entries.iter().enumerate() {
                    pump.run(
                        sd.sdo_write(pdo, n as u8 + 1, mapping(index, 0, bits)),
                        long,
                        stop,
                    )?
                    .map_err(|e| at(&what, e))?;
                }
                pump.run(sd.sdo_write(pdo, 0, entries.len() as u8), long, stop)?
                    .map_err(|e| at(&what, e))?;
                pump.run(sd.sdo_write(assign, 1, pdo), long, stop)?
                    .map_err(|e| at(&what, e))?;
                pump.run(sd.sdo_write(assign, 0, 1u8), long, stop)?
                    .map_err(|e| at(&what, e))?;
            }
            let decel = (axis.quick_stop_deceleration * w.counts_per_unit).round();
            let decel = if decel.is_finite() {
                decel.clamp(0.0, f64::from(u32::MAX)) as u32
            } else {
                0
            };
            pump.run(
                sd.sdo_write(obj::QUICK_STOP_DECELERATION, 0, decel),
                long,
                stop,
            )?
            .map_err(|e| at("writing 0x6085", e))?;
            pump.run(
                sd.sdo_write(obj::QUICK_STOP_OPTION, 0, axis.quick_stop_option as i16),
                long,
                stop,
            )?
            .map_err(|e| at("writing 0x605A", e))?;
        }
        if cfg.pd_watchdog_ns > 0 {
            // Increments of 100 µs: (divider + 2) × 40 ns.
            let time = u16::try_from(cfg.pd_watchdog_ns / 100_000).unwrap_or(u16::MAX);
            pump.run(sd.register_write(0x0400u16, 2498u16), long, stop)?
                .map_err(|e| at("watchdog divider", e))?;
            pump.run(sd.register_write(0x0420u16, time), long, stop)?
                .map_err(|e| at("watchdog time", e))?;
        }
    }

    // SAFE-OP, then OP with the process data running (a drive may wait for valid outputs).
    let group = pump
        .run(group.into_safe_op(&md), long, stop)?
        .map_err(|e| format!("bringing the bus on {} to SAFE-OP: {e}", cfg.interface()))?;
    let group = pump
        .run(group.request_into_op(&md), long, stop)?
        .map_err(|e| format!("bringing the bus on {} to OP: {e}", cfg.interface()))?;
    let end = Instant::now() + long;
    let wkc = loop {
        let r = pump
            .run(group.tx_rx(&md), long, stop)?
            .map_err(|e| format!("exchanging process data on {}: {e}", cfg.interface()))?;
        if r.all_op() {
            break r.working_counter;
        }
        if Instant::now() > end {
            let states: Vec<_> = r.subdevice_states.iter().map(|s| format!("{s}")).collect();
            return Err(format!(
                "the bus on {} did not reach OP within {} s: states {}",
                cfg.interface(),
                long.as_secs(),
                states.join(", ")
            ));
        }
        std::thread::sleep(Duration::from_millis(1));
    };

    // Where ethercrab put each SubDevice's data: its FMMUs, read back.
    let mut fmmus = Vec::new();
    for (k, sd) in group.iter(&md).enumerate() {
        let count: u8 = pump
            .run(sd.register_read(0x0004u16), long, stop)?
            .map_err(|e| format!("position {k}: FMMU count: {e}"))?;
        for f in 0..u16::from(count).min(16) {
            let base = 0x0600 + 16 * f;
            let active: u8 = pump
                .run(sd.register_read(base + 0x0C), long, stop)?
                .map_err(|e| format!("position {k}: FMMU {f}: {e}"))?;
            if active & 1 == 0 {
                continue;
            }
            let logical: u32 = pump
                .run(sd.register_read(base), long, stop)?
                .map_err(|e| format!("position {k}: FMMU {f}: {e}"))?;
            let len: u16 = pump
                .run(sd.register_read(base + 4), long, stop)?
                .map_err(|e| format!("position {k}: FMMU {f}: {e}"))?;
            let kind: u8 = pump
                .run(sd.register_read(base + 0x0B), long, stop)?
                .map_err(|e| format!("position {k}: FMMU {f}: {e}"))?;
            fmmus.push((k, logical, len, kind));
        }
    }
    let layout = layout_of(&found.iter().map(|f| f.2).collect::<Vec<_>>(), &fmmus)?;
    if layout.expected_wkc != wkc {
        return Err(format!(
            "the bus on {} answers with working counter {wkc} where its FMMUs make {}",
            cfg.interface(),
            layout.expected_wkc
        ));
    }
    Ok(Up {
        layout,
        names: found.into_iter().map(|f| f.1).collect(),
    })
}

/// The process image of SubDevices at `stations` with FMMUs `(subdevice, logical address,
/// length, type: 1 read, 2 write)`.
pub fn layout_of(stations: &[u16], fmmus: &[(usize, u32, u16, u8)]) -> Result<Layout, String> {
    let start = fmmus.iter().map(|f| f.1).min().unwrap_or(0);
    let end = fmmus
        .iter()
        .map(|f| f.1 + u32::from(f.2))
        .max()
        .unwrap_or(start);
    let len =
        u16::try_from(end - start).map_err(|_| "the process image is over 64 KiB".to_string())?;
    let mut layout = Layout {
        logical_start: start,
        len,
        slots: [Slot::default(); MAX_SUBDEVICES],
        count: stations.len().min(MAX_SUBDEVICES),
        expected_wkc: 0,
    };
    for (k, &station) in stations.iter().enumerate().take(MAX_SUBDEVICES) {
        let slot = &mut layout.slots[k];
        slot.station = station;
        let mut wkc = 0;
        for &(_, logical, flen, kind) in fmmus.iter().filter(|f| f.0 == k) {
            let span = ((logical - start) as u16, flen);
            match kind {
                1 => {
                    slot.inputs = span;
                    wkc |= 1;
                }
                2 => {
                    slot.outputs = span;
                    wkc |= 2;
                }
                _ => {}
            }
        }
        layout.expected_wkc += wkc;
    }
    Ok(layout)
}
