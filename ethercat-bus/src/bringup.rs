//! Start-up of the bus, before the cycle and before anything is enabled: ethercrab scans the
//! line, the SubDevices found are compared with `[[ethercat.subdevice]]` (a missing one, one
//! more, or another identity at a position is refused, naming the position, the expected and
//! the found identity), each drive's process data is mapped by SDO in PRE-OP (the cell's
//! [`cia402::pdo::RX_DEFAULT`] and [`cia402::pdo::TX_DEFAULT`]), its supported modes checked
//! against the axis' mode, its quick stop written from the configuration, every SubDevice's
//! process data watchdog set, Distributed Clocks set up for the SubDevices on SYNC0
//! ([`Dc`]), and the bus taken to SAFE-OP. Then the FMMUs ethercrab configured are read back
//! from the SubDevices: the cycle's own frame uses them, and asks for OP itself
//! ([`crate::frame::CyclicFrame::request_op`]), so that nothing is in OP before the cycle
//! runs.
//!
//! ethercrab's futures are driven here, on this thread, by [`Pump`]: its frames go out of the
//! cell's [`Wire`] and the replies come back into it. Nothing of ethercrab runs once the bus
//! is in SAFE-OP (its own cyclic exchange would allocate a timer per frame).

use crate::frame::{Layout, Slot};
use cia402::pdo::{RX_DEFAULT, TX_DEFAULT, mapping, obj, sync};
use ethercat_wire::{Received, Wire};
use ethercrab::{MainDevice, MainDeviceConfig, PduRx, PduStorage, PduTx, Timeouts};
use shm_schema::ethercat::{MAX_SUBDEVICES, subdevice_flags};
use shm_schema::{AxisConfigV2, EthercatConfigV1, EthercatSubDeviceV1};
use std::future::Future;
use std::pin::pin;
use std::task::{Context, Poll, Waker};
use std::time::{Duration, Instant};

/// How long a SubDevice may take to reach a state asked for (ethercrab's, and the cycle's
/// from SAFE-OP to OP).
pub const STATE_TRANSITION: Duration = Duration::from_secs(10);

const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);
/// Bytes of the process image ethercrab may lay out.
const MAX_PDI: usize = 1100;

/// The line's one group, as scanned (PRE-OP).
type PreOpGroup = ethercrab::SubDeviceGroup<MAX_SUBDEVICES, MAX_PDI>;

static PDU_STORAGE: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

/// ethercrab's frames through the cell's wire.
struct Pump {
    tx: PduTx<'static>,
    rx: PduRx<'static>,
    buf: Vec<u8>,
    /// Each SubDevice's send mailbox (SM1): station address and physical address.
    mailboxes: Vec<(u16, u16)>,
    /// CoE emergencies taken out of replies before ethercrab saw them: station, code,
    /// error register.
    caught: Vec<(u16, u16, u8)>,
}

impl Pump {
    /// Drives `fut` to its end, sending what it queues on `wire` and handing it what comes
    /// back, for at most `limit` (or until `stop` says so).
    fn run<F: Future>(
        &mut self,
        wire: &Wire,
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
                frame
                    .send_blocking(|bytes| {
                        wire.send(bytes)
                            .map(|()| bytes.len())
                            .map_err(|_| ethercrab::error::Error::SendFrame)
                    })
                    .map_err(|e| format!("sending a frame: {e}"))?;
            }
            if let Received::Frame(n) = wire.receive(&mut self.buf)? {
                self.guard(n);
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

impl Pump {
    /// Takes every CoE emergency out of the frame of `n` bytes in `buf` before ethercrab
    /// reads it: a read of a SubDevice's send mailbox that brought one back gets working
    /// counter 0, and the emergency is kept in `caught`. ethercrab 0.7.1 would throw it away
    /// (clearing a full mailbox before an SDO) or, meeting it as an SDO's answer, fail the
    /// SDO or **panic** (`assert_ne!(service, Emergency)`, `mailbox/coe/mod.rs`, whichever
    /// code the emergency carries; `tests/it/emergency.rs` of the emulator pins it). With working
    /// counter 0 its clearing read goes on (it ignores the counter) and an SDO fails
    /// with a working-counter error, which [`Pump::sdo`] tries once more.
    fn guard(&mut self, n: usize) {
        let frame = &mut self.buf[..n];
        if frame.len() < 16 || frame[12..14] != ethercat_wire::ETHERTYPE.to_be_bytes() {
            return;
        }
        let mut at = 16;
        while at + 12 <= frame.len() {
            let cmd = frame[at];
            let station = u16::from_le_bytes([frame[at + 2], frame[at + 3]]);
            let address = u16::from_le_bytes([frame[at + 4], frame[at + 5]]);
            let flags = u16::from_le_bytes([frame[at + 6], frame[at + 7]]);
            let len = usize::from(flags & 0x07FF);
            let wkc_at = at + 10 + len;
            if wkc_at + 2 > frame.len() {
                return;
            }
            let wkc = u16::from_le_bytes([frame[wkc_at], frame[wkc_at + 1]]);
            if cmd == crate::frame::FPRD
                && wkc > 0
                && self.mailboxes.contains(&(station, address))
                && let Some((code, register)) = crate::frame::coe_emergency(&frame[at + 10..wkc_at])
            {
                self.caught.push((station, code, register));
                frame[wkc_at..wkc_at + 2].copy_from_slice(&0u16.to_le_bytes());
            }
            if flags & 0x8000 == 0 {
                return;
            }
            at = wkc_at + 2;
        }
    }

    /// An SDO transfer `make` makes, once more if an emergency came in its place.
    fn sdo<T, F: Future<Output = Result<T, ethercrab::error::Error>>>(
        &mut self,
        wire: &Wire,
        make: impl Fn() -> F,
        limit: Duration,
        stop: &dyn Fn() -> bool,
    ) -> Result<Result<T, ethercrab::error::Error>, String> {
        let before = self.caught.len();
        let first = self.run(wire, make(), limit, stop)?;
        if first.is_err() && self.caught.len() > before {
            return self.run(wire, make(), limit, stop);
        }
        Ok(first)
    }
}

/// The bus' MainDevice: ethercrab, whose frames go through the cell's [`Wire`]. One per
/// process (its frame storage is static); it brings the bus up as often as asked, from the
/// scan (a bus lost and back, [`Master::bring_up`] again).
pub struct Master {
    md: MainDevice<'static>,
    pump: Pump,
}

impl std::fmt::Debug for Master {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Master")
    }
}

impl Master {
    /// The process' MainDevice; an error the second time.
    pub fn new() -> Result<Self, String> {
        let (tx, rx, pdu_loop) = PDU_STORAGE
            .try_split()
            .map_err(|()| "the bus' MainDevice exists once per process".to_string())?;
        // Timeouts with room for a loaded machine; the cycle does not use them.
        let md = MainDevice::new(
            pdu_loop,
            Timeouts {
                pdu: Duration::from_millis(200),
                eeprom: Duration::from_millis(200),
                state_transition: STATE_TRANSITION,
                mailbox_response: Duration::from_secs(2),
                ..Timeouts::default()
            },
            MainDeviceConfig {
                // The FRMWs of the initial drift compensation (ETG recommends 15 000; the
                // cycle's frame carries one every period from then on).
                dc_static_sync_iterations: 1000,
                ..MainDeviceConfig::default()
            },
        );
        Ok(Self {
            md,
            pump: Pump {
                tx,
                rx,
                buf: vec![0; 9216],
                mailboxes: Vec::new(),
                caught: Vec::new(),
            },
        })
    }

    /// Brings the bus of `cfg` on `wire` to SAFE-OP, the drives mapped for `axes`, SYNC0 on the
    /// bus process' `timing`; see the module documentation. Errors name the SubDevice
    /// (position and name) and what is wrong.
    pub fn bring_up(
        &mut self,
        cfg: &EthercatConfigV1,
        axes: &[AxisConfigV2],
        timing: Timing,
        wire: &Wire,
        stop: &dyn Fn() -> bool,
    ) -> Result<Up, BringUpError> {
        self.pump.caught.clear();
        let line = Line {
            cfg,
            axes,
            timing,
            wire,
            stop,
        };
        let mut up = bring_up(&self.md, &mut self.pump, &line);
        if up.is_err() && !self.pump.caught.is_empty() {
            // An emergency in place of an answer ethercrab waited for (its own SDO reads
            // in SAFE-OP's configuration): once more, the emergency read.
            let caught = std::mem::take(&mut self.pump.caught);
            up = bring_up(&self.md, &mut self.pump, &line);
            self.pump.caught.splice(0..0, caught);
        }
        let mut up = up?;
        let stations: Vec<u16> = up.layout.slots[..up.layout.count]
            .iter()
            .map(|s| s.station)
            .collect();
        up.emergencies = self
            .pump
            .caught
            .drain(..)
            .filter_map(|(station, code, register)| {
                Some((stations.iter().position(|s| *s == station)?, code, register))
            })
            .collect();
        Ok(up)
    }
}

/// Why the bus did not come up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BringUpError {
    /// The SubDevices on the wire are not the ones the configuration names, in its order (one
    /// missing, one more, another identity at a position): the configuration is refused.
    Line(Box<Mismatch>),
    /// The SubDevices are the right ones and cannot run as configured (a drive without the
    /// axis' mode, a SubDevice on SYNC0 without Distributed Clocks): refused.
    Refused(String),
    /// Anything else: no link, no answer, a SubDevice that refused a state or an SDO.
    Failed(String),
}

/// The first position where the line as scanned differs from the configuration's
/// `[[ethercat.subdevice]]` list.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mismatch {
    /// The bus' interface.
    pub interface: String,
    /// The position (0: the SubDevice next to the MainDevice).
    pub position: usize,
    /// SubDevices that answered the scan.
    pub found: usize,
    /// SubDevices the configuration names.
    pub named: usize,
    /// What the configuration names there (`None`: nothing, the line is longer than its list).
    pub expected: Option<Expected>,
    /// What is there (`None`: nothing answers, the line is shorter than the list).
    pub there: Option<Found>,
}

/// A configured SubDevice, as the scan should find it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Expected {
    /// Its name in the configuration.
    pub name: String,
    /// The axis it drives, if a drive.
    pub axis: Option<usize>,
    /// Its vendor id.
    pub vendor: u32,
    /// Its product code.
    pub product: u32,
    /// Its revision, when the configuration checks it.
    pub revision: Option<u32>,
}

/// A SubDevice as the scan found it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Found {
    /// Its name as its EEPROM gives it.
    pub name: String,
    /// Its vendor id.
    pub vendor: u32,
    /// Its product code.
    pub product: u32,
    /// Its revision.
    pub revision: u32,
}

impl std::fmt::Display for Expected {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.revision {
            Some(r) => write!(
                f,
                "{} ({})",
                self.name,
                identity(self.vendor, self.product, r)
            ),
            None => write!(
                f,
                "{} (vendor {:#010x}, product {:#010x}, any revision)",
                self.name, self.vendor, self.product
            ),
        }
    }
}

impl std::fmt::Display for Found {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let id = identity(self.vendor, self.product, self.revision);
        write!(f, "{} ({id})", self.name)
    }
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (bus, k) = (&self.interface, self.position);
        match (&self.expected, &self.there) {
            (Some(expected), None) => write!(
                f,
                "the bus on {bus} has {} SubDevice(s): position {k} should be {expected}, and nothing answers there",
                self.found
            ),
            (Some(expected), Some(there)) => write!(
                f,
                "position {k} of the bus on {bus} should be {expected}, and {there} is there"
            ),
            (None, Some(there)) => write!(
                f,
                "the bus on {bus} has {} SubDevice(s) where the configuration names {}: position {k} is {there}, which it does not name",
                self.found, self.named
            ),
            (None, None) => write!(
                f,
                "position {k} of the bus on {bus}: nothing named, nothing there"
            ),
        }
    }
}

impl From<String> for BringUpError {
    fn from(s: String) -> Self {
        Self::Failed(s)
    }
}

impl std::fmt::Display for BringUpError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Line(m) => m.fmt(f),
            Self::Refused(m) | Self::Failed(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for BringUpError {}

/// A SubDevice's identity for messages.
fn identity(vendor: u32, product: u32, revision: u32) -> String {
    format!("vendor {vendor:#010x}, product {product:#010x}, revision {revision:#010x}")
}

/// What the bus is once in SAFE-OP, its process data exchanged once.
#[derive(Debug)]
pub struct Up {
    /// The process image and where each SubDevice's data sits.
    pub layout: Layout,
    /// Each SubDevice's name as its EEPROM gives it.
    pub names: Vec<String>,
    /// CoE emergencies sent during start-up: position, code, error register.
    pub emergencies: Vec<(usize, u16, u8)>,
    /// Distributed Clocks, when SubDevices run on SYNC0.
    pub dc: Option<Dc>,
}

/// The bus process' cycle on the host's clock: it wakes at `k × period_ns + phase_ns` of
/// `CLOCK_MONOTONIC` (the runtime's grid).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Timing {
    /// The drives' period (ns).
    pub period_ns: u64,
    /// The bus process' phase in it (ns).
    pub phase_ns: u64,
}

/// Distributed Clocks as the bus was brought up with them: the first SubDevice with DC is
/// the reference clock; the cycle writes it the host's time plus `epoch_ns` every frame
/// (so the reference, and through the FRMW every DC SubDevice, keeps the host's clock), and
/// SYNC0 comes every period, a SubDevice's shift after each of the bus process' wake-ups.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dc {
    /// The reference clock's position and station address.
    pub reference: usize,
    /// Its station address.
    pub station: u16,
    /// DC system time minus host time (ns, wrapping): a host time `t` is system time
    /// `t.wrapping_add(epoch_ns)`.
    pub epoch_ns: u64,
    /// SYNC0's cycle (the drives' period, ns).
    pub cycle_ns: u64,
    /// A wake-up of the bus process in system time: SYNC0 comes at `wake_ns + shift + k ×
    /// cycle_ns`.
    pub wake_ns: u64,
    /// The SYNC0 shift of the first drive on SYNC0 (else of the first SubDevice on it; ns).
    pub shift_ns: u64,
    /// How long after its SYNC0 that SubDevice latches its inputs (0x1C33:03; ns): the time
    /// the feedback is stamped with.
    pub latch_shift_ns: u64,
    /// SubDevices on SYNC0 (bit k: position k).
    pub on_sync0: u32,
}

impl Dc {
    /// Where an input latch comes for SYNC0 `shift` after the wake-up: at the next wake-up,
    /// just before the bus process sends its frame (0x1C33:03, the input shift).
    pub fn input_shift(period_ns: u64, shift_ns: u64) -> u64 {
        period_ns.saturating_sub(shift_ns) % period_ns.max(1)
    }
}

impl Dc {
    /// For a reference time `r` a frame read: the system time of the last input latch (of
    /// the first SubDevice on SYNC0) at or before `r`, and how long before the next SYNC0 the
    /// frame came (ns); `None` before the first latch.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn around(&self, r: u64) -> Option<(u64, u64)> {
        let cycle = self.cycle_ns.max(1);
        let first = self.wake_ns.wrapping_add(self.shift_ns);
        let into = r.checked_sub(first)? % cycle;
        let latch_first = first.wrapping_add(self.latch_shift_ns);
        let latch = r - r.checked_sub(latch_first)? % cycle;
        Some((latch, cycle - into))
    }

    /// The index of the SYNC0 cycle `r` falls in (0 before the first).
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn cycle_of(&self, r: u64) -> u64 {
        let first = self.wake_ns.wrapping_add(self.shift_ns);
        r.checked_sub(first)
            .map_or(0, |since| since / self.cycle_ns.max(1) + 1)
    }
}

/// What a bring-up works with.
struct Line<'a> {
    cfg: &'a EthercatConfigV1,
    axes: &'a [AxisConfigV2],
    timing: Timing,
    wire: &'a Wire,
    stop: &'a dyn Fn() -> bool,
}

/// How long after the DC set-up SYNC0 starts: room for SAFE-OP's configuration.
const SYNC0_START_DELAY_NS: u64 = 300_000_000;

fn bring_up(
    md: &MainDevice<'static>,
    pump: &mut Pump,
    line: &Line<'_>,
) -> Result<Up, BringUpError> {
    let Line {
        cfg,
        axes,
        wire,
        stop,
        ..
    } = *line;
    let long = Duration::from_secs(30);
    let group = pump
        .run(
            wire,
            md.init_single_group::<MAX_SUBDEVICES, MAX_PDI>(ethercrab::std::ethercat_now),
            long,
            stop,
        )?
        .map_err(|e| format!("scanning the bus on {}: {e}", cfg.interface()))?;

    // The line against the configuration, before anything else is written.
    let want = cfg.subdevices();
    let found: Vec<_> = group
        .iter(md)
        .map(|sd| {
            (
                sd.identity(),
                sd.name().to_string(),
                sd.configured_address(),
            )
        })
        .collect();
    check_line(cfg, want, &found)?;

    // Each SubDevice's send mailbox (SM1 in mailbox mode, written by the SubDevice): its
    // emergencies are taken out of ethercrab's way from here on (`Pump::guard`), and the
    // cycle reads them in OP.
    let mut mailboxes = vec![(0u16, 0u16); found.len()];
    pump.mailboxes.clear();
    for (k, sd) in group.iter(md).enumerate() {
        let control: u8 = pump
            .run(wire, sd.register_read(0x080Cu16), long, stop)?
            .map_err(|e| format!("position {k}: SM1: {e}"))?;
        if control & 0x0F != 0x02 {
            continue; // not a mailbox the SubDevice writes
        }
        let start: u16 = pump
            .run(wire, sd.register_read(0x0808u16), long, stop)?
            .map_err(|e| format!("position {k}: SM1: {e}"))?;
        let len: u16 = pump
            .run(wire, sd.register_read(0x080Au16), long, stop)?
            .map_err(|e| format!("position {k}: SM1: {e}"))?;
        mailboxes[k] = (start, len);
        pump.mailboxes.push((sd.configured_address(), start));
    }

    // PRE-OP: each drive's mapping, modes and quick stop; every SubDevice's watchdog.
    for (k, (sd, w)) in group.iter(md).zip(want).enumerate() {
        let at = |what: &str, e: ethercrab::error::Error| {
            format!("position {k} ({}): {what}: {e}", w.name())
        };
        if let Some(a) = w.axis() {
            let axis = axes.get(a).ok_or_else(|| {
                format!("position {k} ({}): axis {a} is not in the cell", w.name())
            })?;
            let modes: u32 = pump
                .sdo(wire, || sd.sdo_read(obj::SUPPORTED_MODES, 0), long, stop)?
                .map_err(|e| at("reading 0x6502", e))?;
            let bit = u32::try_from(axis.mode - 1)
                .ok()
                .filter(|b| *b < 32)
                .map_or(0, |b| 1u32 << b);
            if modes & bit == 0 {
                return Err(BringUpError::Refused(format!(
                    "position {k} ({}): the drive does not support mode {} (0x6502 = {modes:#010x})",
                    w.name(),
                    axis.mode
                )));
            }
            for (assign, pdo, entries) in [
                (obj::SM2_ASSIGN, obj::RXPDO, &RX_DEFAULT),
                (obj::SM3_ASSIGN, obj::TXPDO, &TX_DEFAULT),
            ] {
                let what = format!("mapping {pdo:#06x}");
                pump.sdo(wire, || sd.sdo_write(assign, 0, 0u8), long, stop)?
                    .map_err(|e| at(&what, e))?;
                pump.sdo(wire, || sd.sdo_write(pdo, 0, 0u8), long, stop)?
                    .map_err(|e| at(&what, e))?;
                for (n, &(index, bits)) in entries.iter().enumerate() {
                    pump.sdo(
                        wire,
                        || sd.sdo_write(pdo, n as u8 + 1, mapping(index, 0, bits)),
                        long,
                        stop,
                    )?
                    .map_err(|e| at(&what, e))?;
                }
                pump.sdo(
                    wire,
                    || sd.sdo_write(pdo, 0, entries.len() as u8),
                    long,
                    stop,
                )?
                .map_err(|e| at(&what, e))?;
                pump.sdo(wire, || sd.sdo_write(assign, 1, pdo), long, stop)?
                    .map_err(|e| at(&what, e))?;
                pump.sdo(wire, || sd.sdo_write(assign, 0, 1u8), long, stop)?
                    .map_err(|e| at(&what, e))?;
            }
            let decel = (axis.quick_stop_deceleration * w.counts_per_unit).round();
            let decel = if decel.is_finite() {
                decel.clamp(0.0, f64::from(u32::MAX)) as u32
            } else {
                0
            };
            pump.sdo(
                wire,
                || sd.sdo_write(obj::QUICK_STOP_DECELERATION, 0, decel),
                long,
                stop,
            )?
            .map_err(|e| at("writing 0x6085", e))?;
            pump.sdo(
                wire,
                || sd.sdo_write(obj::QUICK_STOP_OPTION, 0, axis.quick_stop_option as i16),
                long,
                stop,
            )?
            .map_err(|e| at("writing 0x605A", e))?;
        }
        if cfg.pd_watchdog_ns > 0 {
            // Increments of 100 µs: (divider + 2) × 40 ns.
            let time = u16::try_from(cfg.pd_watchdog_ns / 100_000).unwrap_or(u16::MAX);
            pump.run(wire, sd.register_write(0x0400u16, 2498u16), long, stop)?
                .map_err(|e| at("watchdog divider", e))?;
            pump.run(wire, sd.register_write(0x0420u16, time), long, stop)?
                .map_err(|e| at("watchdog time", e))?;
        }
    }

    let dc = configure_dc(md, pump, line, &group, want, &found)?;

    // SAFE-OP only: OP is asked for by the cycle's own frames (`CyclicFrame::request_op`),
    // so that no SubDevice is ever in OP without the cycle running (its process data
    // watchdog would take it out of OP again in the set-up's gap before the first cycle).
    let group = pump
        .run(wire, group.into_safe_op(md), long, stop)?
        .map_err(|e| format!("bringing the bus on {} to SAFE-OP: {e}", cfg.interface()))?;
    // The process data once, in SAFE-OP (a SubDevice takes them, and ignores its outputs).
    let wkc = pump
        .run(wire, group.tx_rx(md), long, stop)?
        .map_err(|e| format!("exchanging process data on {}: {e}", cfg.interface()))?
        .working_counter;

    // Where ethercrab put each SubDevice's data: its FMMUs, read back.
    let mut fmmus = Vec::new();
    for (k, sd) in group.iter(md).enumerate() {
        let count: u8 = pump
            .run(wire, sd.register_read(0x0004u16), long, stop)?
            .map_err(|e| format!("position {k}: FMMU count: {e}"))?;
        for f in 0..u16::from(count).min(16) {
            let base = 0x0600 + 16 * f;
            let active: u8 = pump
                .run(wire, sd.register_read(base + 0x0C), long, stop)?
                .map_err(|e| format!("position {k}: FMMU {f}: {e}"))?;
            if active & 1 == 0 {
                continue;
            }
            let logical: u32 = pump
                .run(wire, sd.register_read(base), long, stop)?
                .map_err(|e| format!("position {k}: FMMU {f}: {e}"))?;
            let len: u16 = pump
                .run(wire, sd.register_read(base + 4), long, stop)?
                .map_err(|e| format!("position {k}: FMMU {f}: {e}"))?;
            let kind: u8 = pump
                .run(wire, sd.register_read(base + 0x0B), long, stop)?
                .map_err(|e| format!("position {k}: FMMU {f}: {e}"))?;
            fmmus.push((k, logical, len, kind));
        }
    }
    let layout = layout_of(&found.iter().map(|f| f.2).collect::<Vec<_>>(), &fmmus)?;
    if layout.expected_wkc != wkc {
        return Err(BringUpError::Failed(format!(
            "the bus on {} answers with working counter {wkc} where its FMMUs make {}",
            cfg.interface(),
            layout.expected_wkc
        )));
    }
    let mut layout = layout;
    for (slot, mailbox) in layout.slots.iter_mut().zip(&mailboxes) {
        slot.mailbox_in = *mailbox;
    }
    Ok(Up {
        layout,
        names: found.into_iter().map(|f| f.1).collect(),
        emergencies: Vec::new(),
        dc,
    })
}

/// The line as scanned (`found`: identity, name, station address, in wire order) against the
/// configuration's `[[ethercat.subdevice]]` (`want`): refused, naming the position and both
/// identities, unless they are the same SubDevices in the same order.
fn check_line(
    cfg: &EthercatConfigV1,
    want: &[EthercatSubDeviceV1],
    found: &[(ethercrab::SubDeviceIdentity, String, u16)],
) -> Result<(), BringUpError> {
    let at = |position: usize| Mismatch {
        interface: cfg.interface().to_string(),
        position,
        found: found.len(),
        named: want.len(),
        expected: want.get(position).map(|w| Expected {
            name: w.name().to_string(),
            axis: w.axis(),
            vendor: w.vendor,
            product: w.product,
            revision: (w.flags & subdevice_flags::CHECK_REVISION != 0).then_some(w.revision),
        }),
        there: found.get(position).map(|(id, name, _)| Found {
            name: name.clone(),
            vendor: id.vendor_id,
            product: id.product_id,
            revision: id.revision,
        }),
    };
    let differs = |k: usize| {
        let m = at(k);
        match (&m.expected, &m.there) {
            (Some(e), Some(t)) => {
                e.vendor != t.vendor
                    || e.product != t.product
                    || e.revision.is_some_and(|r| r != t.revision)
            }
            (None, None) => false,
            _ => true,
        }
    };
    match (0..want.len().max(found.len())).find(|&k| differs(k)) {
        Some(k) => Err(BringUpError::Line(Box::new(at(k)))),
        None => Ok(()),
    }
}

/// Distributed Clocks for the SubDevices on SYNC0 (the module documentation of `Dc`):
/// each must have DC; the first SubDevice with DC is the reference clock; the host's
/// clock is measured against it (the read with the shortest round trip of eight); a
/// drive gets sync mode 2 and the cycle time in 0x1C32; each SYNC0 starts at a wake-up
/// of the bus process 300 ms on plus its shift, every period (0x0981, 0x0990, 0x09A0:
/// the sequence of ethercrab's `configure_dc_sync`, whose start time would not be on the
/// bus process' grid).
/// `None` when no SubDevice is on SYNC0.
fn configure_dc(
    md: &MainDevice<'static>,
    pump: &mut Pump,
    line: &Line<'_>,
    group: &PreOpGroup,
    want: &[EthercatSubDeviceV1],
    found: &[(ethercrab::SubDeviceIdentity, String, u16)],
) -> Result<Option<Dc>, BringUpError> {
    let Line {
        wire, stop, timing, ..
    } = *line;
    let long = Duration::from_secs(30);
    let on_sync0: Vec<usize> = want
        .iter()
        .enumerate()
        .filter(|(_, w)| w.flags & subdevice_flags::SYNC0 != 0)
        .map(|(k, _)| k)
        .collect();
    // Which SubDevices have DC (ESC features, 0x0008 bit 2): read only when one is on SYNC0.
    let mut has_dc = Vec::with_capacity(found.len());
    for (k, sd) in group
        .iter(md)
        .enumerate()
        .take_while(|_| !on_sync0.is_empty())
    {
        let features: u16 = pump
            .run(wire, sd.register_read(0x0008u16), long, stop)?
            .map_err(|e| format!("position {k}: ESC features: {e}"))?;
        has_dc.push(features & 0x04 != 0);
    }
    if let Some(&k) = on_sync0.iter().find(|&&k| !has_dc[k]) {
        return Err(BringUpError::Refused(format!(
            "position {k} ({}) is configured on SYNC0 (sync = \"dc\", a drive's default) and its ESC has no Distributed Clocks (register 0x0008): write sync = \"frame\" in its [[ethercat.subdevice]]",
            want[k].name()
        )));
    }
    // The feedback is stamped by the first drive on SYNC0 (else the first SubDevice on it).
    let stamped = on_sync0
        .iter()
        .find(|&&k| want[k].axis().is_some())
        .or(on_sync0.first());
    Ok(match (stamped, has_dc.iter().position(|d| *d)) {
        (Some(&first), Some(reference)) => {
            let station = found[reference].2;
            let sd_ref = group
                .iter(md)
                .nth(reference)
                .ok_or_else(|| format!("position {reference}: gone"))?;
            let mut best = (u64::MAX, 0u64);
            for _ in 0..8 {
                let before = runtime::time::now_ns();
                let t: u64 = pump
                    .run(wire, sd_ref.register_read(0x0910u16), long, stop)?
                    .map_err(|e| format!("position {reference}: DC system time: {e}"))?;
                let after = runtime::time::now_ns();
                if after - before < best.0 {
                    best = (
                        after - before,
                        t.wrapping_sub(before + (after - before) / 2),
                    );
                }
            }
            let epoch_ns = best.1;
            let period = timing.period_ns.max(1);
            let now = runtime::time::now_ns() + SYNC0_START_DELAY_NS;
            let wake =
                (now.saturating_sub(timing.phase_ns) / period + 1) * period + timing.phase_ns;
            let shift_of = |k: usize| match want[k].sync0_shift_ns {
                0 => period / 2,
                s => u64::from(s),
            };
            let mut latch_shift = None;
            for &k in &on_sync0 {
                let w = &want[k];
                let sd = group
                    .iter(md)
                    .nth(k)
                    .ok_or_else(|| format!("position {k}: gone"))?;
                let at = |what: &str, e: ethercrab::error::Error| {
                    format!("position {k} ({}): {what}: {e}", w.name())
                };
                if w.axis().is_some() {
                    pump.sdo(
                        wire,
                        || sd.sdo_write(obj::SM2_SYNC, sync::MODE, sync::DC_SYNC0),
                        long,
                        stop,
                    )?
                    .map_err(|e| at("0x1C32:01 (sync mode DC SYNC0)", e))?;
                    pump.sdo(
                        wire,
                        || sd.sdo_write(obj::SM2_SYNC, sync::CYCLE_TIME, period as u32),
                        long,
                        stop,
                    )?
                    .map_err(|e| at("0x1C32:02 (cycle time)", e))?;
                    // The inputs latched at the bus process' wake-up, just before its frame,
                    // rather than at SYNC0 (a period before the frame's command applies).
                    let input_shift = Dc::input_shift(period, shift_of(k));
                    let taken = pump
                        .sdo(
                            wire,
                            || sd.sdo_write(obj::SM3_SYNC, sync::SHIFT_TIME, input_shift as u32),
                            long,
                            stop,
                        )?
                        .inspect_err(|e| {
                            tracing::warn!(
                                "position {k} ({}): 0x1C33:03 (input shift) refused ({e}): its inputs are latched at SYNC0, a period earlier",
                                w.name()
                            );
                        })
                        .is_ok();
                    if k == first {
                        latch_shift = Some(if taken { input_shift } else { 0 });
                    }
                }
                let start = wake.wrapping_add(epoch_ns).wrapping_add(shift_of(k));
                pump.run(wire, sd.register_write(0x0981u16, 0u8), long, stop)?
                    .map_err(|e| at("DC activation", e))?;
                pump.run(wire, sd.register_write(0x0990u16, start), long, stop)?
                    .map_err(|e| at("SYNC0 start time", e))?;
                pump.run(
                    wire,
                    sd.register_write(0x09A0u16, period as u32),
                    long,
                    stop,
                )?
                .map_err(|e| at("SYNC0 cycle time", e))?;
                pump.run(wire, sd.register_write(0x0981u16, 0x03u8), long, stop)?
                    .map_err(|e| at("DC activation", e))?;
            }
            Some(Dc {
                reference,
                station,
                epoch_ns,
                cycle_ns: period,
                wake_ns: wake.wrapping_add(epoch_ns),
                shift_ns: shift_of(first),
                latch_shift_ns: latch_shift.unwrap_or(0),
                on_sync0: on_sync0.iter().fold(0, |m, &k| m | 1 << k),
            })
        }
        _ => None,
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
