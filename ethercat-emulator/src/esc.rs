//! One EtherCAT SubDevice Controller (ESC): its 64 KiB address space (registers below
//! 0x1000, process RAM above), as the ET1100 datasheet describes the registers a MainDevice
//! uses: identity and features, station address and alias, DL status, AL control and status
//! with the status code, the SII EEPROM interface, FMMUs, SyncManagers, DC.
//!
//! Reads and writes come from the frame's datagrams (`Esc::read`, `Esc::write`,
//! `Esc::logical`); each says whether it was addressed to something the ESC has, which
//! is what the working counter counts. A write reaches only the bytes the MainDevice may
//! write; AL control and SII control act at once (an ESC's AL state machine for devices without
//! a microcontroller, the EEPROM read at its speed, here instantly).

use crate::sii::{Sii, SmKind};

/// Words of the emulated EEPROM (2 KiB: word 0x3E says 16 KiBit).
const EEPROM_WORDS: usize = 1024;

/// SyncManager status bit 3: the mailbox is full.
const SM_FULL: u8 = 0x08;

/// Size of the ESC's address space.
pub const MEMORY: usize = 0x1_0000;
/// Start of the process RAM.
pub const RAM: u16 = 0x1000;

/// Register addresses (ET1100 datasheet, section II).
pub mod reg {
    /// ESC type.
    pub const TYPE: u16 = 0x0000;
    /// FMMUs supported.
    pub const FMMU_COUNT: u16 = 0x0004;
    /// SyncManagers supported.
    pub const SM_COUNT: u16 = 0x0005;
    /// Process RAM in KiB.
    pub const RAM_SIZE: u16 = 0x0006;
    /// Port descriptor.
    pub const PORTS: u16 = 0x0007;
    /// ESC features supported (bit 2: DC, bit 3: DC 64 bit).
    pub const FEATURES: u16 = 0x0008;
    /// Configured station address.
    pub const STATION_ADDRESS: u16 = 0x0010;
    /// Configured station alias.
    pub const STATION_ALIAS: u16 = 0x0012;
    /// DL status.
    pub const DL_STATUS: u16 = 0x0110;
    /// AL control.
    pub const AL_CONTROL: u16 = 0x0120;
    /// AL status.
    pub const AL_STATUS: u16 = 0x0130;
    /// AL status code.
    pub const AL_STATUS_CODE: u16 = 0x0134;
    /// Watchdog divider: the watchdog's increment is (divider + 2) × 40 ns.
    pub const WATCHDOG_DIVIDER: u16 = 0x0400;
    /// Process data watchdog time, in increments (0: off).
    pub const WATCHDOG_TIME_PD: u16 = 0x0420;
    /// Process data watchdog status: bit 0 set while it has not expired.
    pub const WATCHDOG_STATUS_PD: u16 = 0x0440;
    /// Process data watchdog expirations (counter).
    pub const WATCHDOG_COUNTER_PD: u16 = 0x0442;
    /// SII EEPROM configuration (owner).
    pub const SII_CONFIG: u16 = 0x0500;
    /// SII EEPROM control and status.
    pub const SII_CONTROL: u16 = 0x0502;
    /// SII EEPROM word address.
    pub const SII_ADDRESS: u16 = 0x0504;
    /// SII EEPROM data (8 bytes read).
    pub const SII_DATA: u16 = 0x0508;
    /// FMMU 0; 16 bytes each.
    pub const FMMU: u16 = 0x0600;
    /// SyncManager 0; 8 bytes each.
    pub const SM: u16 = 0x0800;
    /// DC receive time of port 0 (a write latches every port's).
    pub const DC_RECEIVE_TIME_PORT0: u16 = 0x0900;
    /// DC system time (a read: the ESC's system time now; a write: compared with it, the
    /// difference into [`DC_TIME_DIFFERENCE`] and the drift control).
    pub const DC_SYSTEM_TIME: u16 = 0x0910;
    /// DC local time of the receive time processing unit, latched with the ports'.
    pub const DC_RECEIVE_TIME_UNIT: u16 = 0x0918;
    /// DC system time offset: system time = local time + offset.
    pub const DC_TIME_OFFSET: u16 = 0x0920;
    /// DC system time delay (from the reference clock to this ESC).
    pub const DC_TIME_DELAY: u16 = 0x0928;
    /// DC system time difference of the last write of the system time: bit 31 set when the
    /// local copy was smaller, bits 0-30 the difference (ns).
    pub const DC_TIME_DIFFERENCE: u16 = 0x092C;
    /// DC activation: bit 0 cyclic operation, bit 1 SYNC0, bit 2 SYNC1.
    pub const DC_ACTIVATION: u16 = 0x0981;
    /// DC start time of the cyclic operation (system time of the first SYNC0).
    pub const DC_START_TIME: u16 = 0x0990;
    /// DC SYNC0 cycle time (ns).
    pub const DC_SYNC0_CYCLE: u16 = 0x09A0;
    /// DC registers end (exclusive).
    pub const DC_END: u16 = 0x0A00;
}

/// AL states (AL control and AL status, low 4 bits).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum AlState {
    /// Init.
    Init = 1,
    /// Pre-operational: mailbox.
    PreOp = 2,
    /// Bootstrap (not supported here).
    Bootstrap = 3,
    /// Safe-operational: inputs.
    SafeOp = 4,
    /// Operational: inputs and outputs.
    Op = 8,
}

impl AlState {
    /// The state of a code.
    pub fn from_code(c: u8) -> Option<Self> {
        Some(match c {
            1 => Self::Init,
            2 => Self::PreOp,
            3 => Self::Bootstrap,
            4 => Self::SafeOp,
            8 => Self::Op,
            _ => return None,
        })
    }
}

/// AL status codes (ETG.1000.6, table "AL status codes") the emulator sets.
pub mod al_code {
    /// No error.
    pub const NONE: u16 = 0x0000;
    /// Invalid requested state change.
    pub const INVALID_STATE_CHANGE: u16 = 0x0011;
    /// Unknown requested state.
    pub const UNKNOWN_STATE: u16 = 0x0012;
    /// Bootstrap not supported.
    pub const NO_BOOTSTRAP: u16 = 0x0013;
    /// Invalid mailbox configuration (PRE-OP).
    pub const INVALID_MAILBOX: u16 = 0x0016;
    /// SyncManager watchdog.
    pub const SM_WATCHDOG: u16 = 0x001B;
    /// Invalid output configuration.
    pub const INVALID_OUTPUTS: u16 = 0x001D;
    /// Invalid input configuration.
    pub const INVALID_INPUTS: u16 = 0x001E;
    /// Invalid DC SYNC configuration (the device runs on SYNC0 and it is not active).
    pub const INVALID_DC_SYNC: u16 = 0x0030;
    /// Invalid DC cycle time (shorter than the device can take).
    pub const INVALID_DC_CYCLE: u16 = 0x0035;
}

/// The shortest SYNC0 cycle a device on SYNC0 takes (ns): 125 µs, 8 kHz.
pub const MIN_SYNC0_CYCLE_NS: u64 = 125_000;

/// How much the drift control moves an ESC's clock at most per write of the system time (ns).
pub const DRIFT_STEP_NS: i64 = 1_000;

/// An ESC's own clock (ET1100 datasheet, "Distributed Clocks"): a local time that runs
/// `drift_ppm` off the host's clock, moved by the drift control, and the system time
/// offset on top.
#[derive(Clone, Copy, Debug, Default)]
struct DcClock {
    /// Host time (ns) from which the quartz' drift counts.
    origin_ns: u64,
    /// How far its quartz is off (parts per million; positive: fast).
    drift_ppm: f64,
    /// What the drift control has added (ns).
    correction_ns: i64,
}

impl DcClock {
    /// Its local time at host time `host_ns`.
    fn local(&self, host_ns: u64) -> u64 {
        let run = host_ns.saturating_sub(self.origin_ns) as f64;
        let drift = (run * self.drift_ppm * 1e-6) as i64;
        host_ns.wrapping_add_signed(drift.wrapping_add(self.correction_ns))
    }
}

/// SII control bits (register 0x0502, as ethercrab's and SOEM's `SiiControl` read them).
mod sii_bit {
    pub const READ_SIZE_8: u16 = 1 << 6;
    pub const READ: u16 = 1 << 8;
    pub const WRITE: u16 = 1 << 9;
    pub const RELOAD: u16 = 1 << 10;
    pub const COMMAND_ERROR: u16 = 1 << 13;
    pub const WRITE_ERROR: u16 = 1 << 14;
    pub const BUSY: u16 = 1 << 15;
    pub const WRITE_ENABLE: u16 = 1;
}

/// One ESC: its memory, its EEPROM and what it has.
#[derive(Clone)]
pub struct Esc {
    mem: Box<[u8]>,
    eeprom: Vec<u16>,
    sii: Sii,
    fmmus: u8,
    sms: u8,
    dc: bool,
    /// A mailbox the MainDevice wrote whole into SM0's area, for the device to answer.
    mailbox_in: Option<Vec<u8>>,
    /// A logical write reached the process RAM since the device last looked.
    outputs_written: bool,
    /// The last write into a SyncManager whose watchdog trigger is on (ns), if any.
    watchdog_trigger_ns: Option<u64>,
    /// The host time (ns, `CLOCK_MONOTONIC`) of the frame being handled: its clock's reads.
    now_ns: u64,
    clock: DcClock,
    /// The system time of the first SYNC0, once SYNC0 was activated.
    sync0_first: Option<u64>,
    /// The device behind it runs on SYNC0 (its 0x1C32:01 says so): SAFE-OP needs SYNC0
    /// active.
    needs_sync0: bool,
}

impl std::fmt::Debug for Esc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Esc")
            .field("device", &self.sii.order)
            .field("station_address", &self.station_address())
            .field("al_status", &self.al_status())
            .finish_non_exhaustive()
    }
}

impl Esc {
    /// An ESC with `fmmus` FMMUs, `sms` SyncManagers, DC or not, and the EEPROM `sii`, in
    /// INIT as after power-on.
    pub fn new(sii: Sii, fmmus: u8, sms: u8, dc: bool) -> Self {
        let mut esc = Self {
            mem: vec![0u8; MEMORY].into_boxed_slice(),
            eeprom: sii.words(),
            sii,
            fmmus: fmmus.min(16),
            sms: sms.min(16),
            dc,
            mailbox_in: None,
            outputs_written: false,
            watchdog_trigger_ns: None,
            now_ns: crate::now_ns(),
            clock: DcClock::default(),
            sync0_first: None,
            needs_sync0: false,
        };
        esc.clock.origin_ns = esc.now_ns;
        esc.power_on();
        esc
    }

    /// Every register to its power-on value: INIT, no address, FMMUs and SyncManagers off.
    pub fn power_on(&mut self) {
        self.mem.fill(0);
        self.mailbox_in = None;
        self.mem[usize::from(reg::TYPE)] = 0x11; // ET1100
        self.mem[usize::from(reg::FMMU_COUNT)] = self.fmmus;
        self.mem[usize::from(reg::SM_COUNT)] = self.sms;
        self.mem[usize::from(reg::RAM_SIZE)] = 8;
        self.mem[usize::from(reg::PORTS)] = 0x0F; // ports 0 and 1: MII
        let features: u16 = if self.dc { 0b1100 } else { 0 };
        self.put16(reg::FEATURES, features);
        self.put16(reg::STATION_ALIAS, self.sii.alias);
        self.put16(reg::AL_STATUS, AlState::Init as u16);
        self.put16(reg::SII_CONTROL, sii_bit::READ_SIZE_8);
        // The ET1100's defaults: an increment of 100 µs, the process data watchdog 100 ms.
        self.put16(reg::WATCHDOG_DIVIDER, 0x09C2);
        self.put16(reg::WATCHDOG_TIME_PD, 1000);
        self.watchdog_trigger_ns = None;
        self.sync0_first = None;
    }

    /// The host time (ns) its clock reads: the time of the frame being handled.
    pub fn set_time(&mut self, now_ns: u64) {
        self.now_ns = now_ns;
    }

    /// Makes its quartz run `ppm` parts per million off the host's clock from now on (a
    /// fault it can be told to make; a real quartz is off by tens of ppm).
    pub fn set_drift(&mut self, ppm: f64) {
        let local = self.clock.local(self.now_ns);
        self.clock = DcClock {
            origin_ns: self.now_ns,
            drift_ppm: ppm,
            correction_ns: local.wrapping_sub(self.now_ns) as i64,
        };
    }

    /// Whether it has Distributed Clocks.
    pub fn has_dc(&self) -> bool {
        self.dc
    }

    /// Its system time at the frame being handled (ns since 2000 as the MainDevice set it up:
    /// local time plus the system time offset).
    pub fn system_time(&self) -> u64 {
        let offset = u64::from_le_bytes(self.bytes(reg::DC_TIME_OFFSET));
        self.clock.local(self.now_ns).wrapping_add(offset)
    }

    /// SYNC0, when active: the system time of its first event and its cycle (ns).
    pub fn sync0(&self) -> Option<(u64, u64)> {
        let cycle = u64::from(u32::from_le_bytes(self.bytes(reg::DC_SYNC0_CYCLE)));
        self.sync0_first
            .filter(|_| self.dc && cycle > 0)
            .map(|first| (first, cycle))
    }

    /// Tells the ESC whether its device runs on SYNC0 (SAFE-OP then needs SYNC0 active).
    pub fn set_needs_sync0(&mut self, on: bool) {
        self.needs_sync0 = on;
    }

    fn bytes<const N: usize>(&self, a: u16) -> [u8; N] {
        let a = usize::from(a);
        self.mem[a..a + N].try_into().unwrap_or([0; N])
    }

    /// A write of the system time: the difference to its own into 0x092C, and the drift
    /// control moves its clock a quarter of the way, at most [`DRIFT_STEP_NS`] (a real ESC
    /// changes its clock's speed, filtered; the effect is the same). `wide`: 64 bits were
    /// written, else the low 32 are compared.
    fn system_time_written(&mut self, wide: bool) {
        let written = u64::from_le_bytes(self.bytes(reg::DC_SYSTEM_TIME));
        let delay = u64::from(u32::from_le_bytes(self.bytes(reg::DC_TIME_DELAY)));
        let received = written.wrapping_add(delay);
        let own = self.system_time();
        let diff = if wide {
            own.wrapping_sub(received) as i64
        } else {
            i64::from((own as u32).wrapping_sub(received as u32) as i32)
        };
        let magnitude = diff.unsigned_abs().min(0x7FFF_FFFF) as u32;
        let register = magnitude | if diff < 0 { 1 << 31 } else { 0 };
        let a = usize::from(reg::DC_TIME_DIFFERENCE);
        self.mem[a..a + 4].copy_from_slice(&register.to_le_bytes());
        self.clock.correction_ns -= (diff / 4).clamp(-DRIFT_STEP_NS, DRIFT_STEP_NS);
    }

    /// DC activation was written: SYNC0 starts at the start time, or is off. A start time
    /// already past waits, as an ET1100 does, until the low 32 bits of the system time meet
    /// it again (about 4.3 s later).
    fn activation_written(&mut self) {
        let activation = self.mem[usize::from(reg::DC_ACTIVATION)];
        if activation & 0x03 != 0x03 {
            self.sync0_first = None;
            return;
        }
        let start = u64::from_le_bytes(self.bytes(reg::DC_START_TIME));
        let now = self.system_time();
        let first = if start >= now {
            start
        } else {
            let wrap = 1u64 << 32;
            start + ((now - start) / wrap + 1) * wrap
        };
        self.sync0_first = Some(first);
    }

    /// The process data watchdog's time (ns; 0: off).
    pub fn watchdog_ns(&self) -> u64 {
        let increment = (u64::from(self.get16(reg::WATCHDOG_DIVIDER)) + 2) * 40;
        increment * u64::from(self.get16(reg::WATCHDOG_TIME_PD))
    }

    /// Drops from OP to SAFE-OP with the error flag and AL status code `code`, as a
    /// SubDevice's own fault would (the MainDevice acknowledges the error to go on); false if
    /// it was not in OP.
    pub fn leave_op(&mut self, code: u16) -> bool {
        if self.al_state() != Some(AlState::Op) {
            return false;
        }
        self.put16(reg::AL_STATUS, AlState::SafeOp as u16 | 0x10);
        self.put16(reg::AL_STATUS_CODE, code);
        true
    }

    /// Another product code in its EEPROM (another device in its place): a MainDevice sees
    /// it at its next scan.
    pub fn set_product(&mut self, product: u32) {
        self.sii.identity.product = product;
        self.eeprom = self.sii.words();
    }

    /// The process data watchdog at `now_ns` (ETG.1000.4 6.3): armed by a write into a
    /// SyncManager buffer whose watchdog trigger is on (control bit 6), it expires when no
    /// such write came for its time. Expired in OP, the digital outputs (0x0F00) go to 0 and
    /// the SubDevice drops to SAFE-OP with the error flag and code 0x001B; its status bit 0
    /// clears and its counter counts. True when it expired now.
    pub fn check_watchdog(&mut self, now_ns: u64) -> bool {
        let limit = self.watchdog_ns();
        let expired = match self.watchdog_trigger_ns {
            Some(t) => limit > 0 && now_ns.saturating_sub(t) > limit,
            None => false,
        };
        let status = usize::from(reg::WATCHDOG_STATUS_PD);
        if !expired {
            self.mem[status] |= u8::from(self.watchdog_trigger_ns.is_some());
            return false;
        }
        self.watchdog_trigger_ns = None;
        self.mem[status] &= !1;
        let counter = usize::from(reg::WATCHDOG_COUNTER_PD);
        self.mem[counter] = self.mem[counter].saturating_add(1);
        self.mem[0x0F00..0x0F08].fill(0);
        if self.al_state() == Some(AlState::Op) {
            self.put16(reg::AL_STATUS, AlState::SafeOp as u16 | 0x10);
            self.put16(reg::AL_STATUS_CODE, al_code::SM_WATCHDOG);
        }
        true
    }

    /// The EEPROM's content.
    pub fn sii(&self) -> &Sii {
        &self.sii
    }

    /// Register 0x0010.
    pub fn station_address(&self) -> u16 {
        self.get16(reg::STATION_ADDRESS)
    }

    /// AL status (state and error bit).
    pub fn al_status(&self) -> u16 {
        self.get16(reg::AL_STATUS)
    }

    /// The AL state (without the error bit).
    pub fn al_state(&self) -> Option<AlState> {
        AlState::from_code((self.al_status() & 0x0F) as u8)
    }

    /// AL status code.
    pub fn al_status_code(&self) -> u16 {
        self.get16(reg::AL_STATUS_CODE)
    }

    /// Sets the DL status (links and loops of ports 0 and 1: the bus knows its position).
    pub fn set_links(&mut self, upstream: bool, downstream: bool) {
        let mut s: u16 = 1 | 2; // PDI operational, watchdog not expired
        if upstream {
            s |= 1 << 4 | 1 << 9; // link port 0, communication on port 0
        } else {
            s |= 1 << 8; // loop closed
        }
        if downstream {
            s |= 1 << 5 | 1 << 11;
        } else {
            s |= 1 << 10;
        }
        s |= 1 << 12 | 1 << 14; // ports 2 and 3: loop closed
        self.put16(reg::DL_STATUS, s);
    }

    /// Whether the ESC has memory at `addr` (an unimplemented area is not counted).
    fn implemented(&self, addr: u16) -> bool {
        let dc = (reg::DC_RECEIVE_TIME_PORT0..reg::DC_END).contains(&addr);
        !dc || self.dc
    }

    /// Whether the MainDevice may write the byte at `addr`.
    fn writable(&self, addr: u16) -> bool {
        match addr {
            0x0010..=0x0011 => true, // station address
            0x0100..=0x0103 => true, // DL control
            0x0120..=0x0121 => true, // AL control
            0x0200..=0x0205 => true, // event masks
            0x0300..=0x0313 => true, // error counters (cleared)
            0x0400..=0x0401 | 0x0410..=0x0411 | 0x0420..=0x0421 => true, // watchdogs
            0x0442..=0x0443 => true, // watchdog counters
            0x0500..=0x050F => true, // SII interface
            0x0600..=0x06FF => true, // FMMUs
            0x0800..=0x087F => !matches!(addr % 8, 5 | 7), // SMs but status, PDI ctrl
            0x0900..=0x09FF => self.dc, // DC
            a if a >= RAM => true,
            _ => false,
        }
    }

    /// A read of `buf.len()` bytes at `addr` into `buf` (ORed in for a broadcast). False if
    /// nothing there is implemented (not counted).
    pub fn read(&mut self, addr: u16, buf: &mut [u8], or: bool) -> bool {
        if !self.implemented(addr) {
            return false;
        }
        let start = usize::from(addr);
        let system = usize::from(reg::DC_SYSTEM_TIME);
        if self.dc && start < system + 8 && system < start + buf.len() {
            let t = self.system_time();
            self.mem[system..system + 8].copy_from_slice(&t.to_le_bytes());
        }
        for (k, b) in buf.iter_mut().enumerate() {
            let v = self.mem.get(start + k).copied().unwrap_or(0);
            *b = if or { *b | v } else { v };
        }
        // Reading the last byte of the send mailbox (SM1) empties it.
        if let Some(last) = self.mailbox_last(1)
            && (start..start + buf.len()).contains(&last)
        {
            self.mem[usize::from(reg::SM + 8 + 5)] &= !SM_FULL;
        }
        true
    }

    /// The address of the last byte of mailbox SyncManager `n`'s area, if the device has a
    /// mailbox and the MainDevice enabled it.
    fn mailbox_last(&self, n: usize) -> Option<usize> {
        self.sii.mailbox?;
        let (start, len, _, on) = self.sm(n);
        let end = usize::from(start) + usize::from(len);
        // An area that runs past the memory is no mailbox.
        (on && len > 0 && end <= MEMORY).then(|| end - 1)
    }

    /// Whether a logical write reached the process data since the last call (the device
    /// takes its outputs once per frame that wrote them).
    pub fn take_outputs_written(&mut self) -> bool {
        std::mem::take(&mut self.outputs_written)
    }

    /// The mailbox the MainDevice wrote, once (for the device to answer).
    pub fn take_mailbox(&mut self) -> Option<Vec<u8>> {
        self.mailbox_in.take()
    }

    /// Puts the device's answer in the send mailbox (SM1) and marks it full; false if SM1 is
    /// not set up or still full (the MainDevice has not read the previous answer).
    pub fn put_mailbox(&mut self, reply: &[u8]) -> bool {
        let (start, len, _, on) = self.sm(1);
        let status = usize::from(reg::SM + 8 + 5);
        let fits = usize::from(start) + usize::from(len) <= MEMORY;
        if !on || !fits || self.mem[status] & SM_FULL != 0 || reply.len() > usize::from(len) {
            return false;
        }
        let s = usize::from(start);
        self.mem[s..s + usize::from(len)].fill(0);
        self.mem[s..s + reply.len()].copy_from_slice(reply);
        self.mem[status] |= SM_FULL;
        true
    }

    /// The size of the send mailbox (SM1) as the MainDevice set it up.
    pub fn mailbox_capacity(&self) -> usize {
        usize::from(self.sm(1).1)
    }

    /// A write of `data` at `addr` (the bytes the MainDevice may write), then what it sets
    /// off. False if nothing there is implemented (not counted).
    pub fn write(&mut self, addr: u16, data: &[u8]) -> bool {
        if !self.implemented(addr) {
            return false;
        }
        let start = usize::from(addr);
        let end = start + data.len();
        for (k, v) in data.iter().enumerate() {
            let a = start + k;
            if a < MEMORY && self.writable(a as u16) {
                self.mem[a] = *v;
            }
        }
        let touches = |r: u16, len: usize| start < usize::from(r) + len && usize::from(r) < end;
        if touches(reg::AL_CONTROL, 2) {
            self.al_control();
        }
        if touches(reg::SII_CONTROL, 2) {
            self.sii_command();
        }
        if touches(0x0300, 0x14) {
            self.mem[0x0300..0x0314].fill(0);
        }
        if self.dc && touches(reg::DC_RECEIVE_TIME_PORT0, 1) {
            self.latch_receive_times();
        }
        if self.dc && touches(reg::DC_SYSTEM_TIME, 1) {
            self.system_time_written(touches(reg::DC_SYSTEM_TIME + 4, 1));
        }
        if self.dc && touches(reg::DC_ACTIVATION, 1) {
            self.activation_written();
        }
        // A write that reaches the last byte of the receive mailbox (SM0) completes it.
        if let Some(last) = self.mailbox_last(0)
            && (start..end).contains(&last)
        {
            let (s0, len, _, _) = self.sm(0);
            let s0 = usize::from(s0);
            self.mailbox_in = Some(self.mem[s0..s0 + usize::from(len)].to_vec());
        }
        true
    }

    /// A logical access (LRD, LWR, LRW) of the datagram at logical address `logical`
    /// through this ESC's active FMMUs; returns the working counter's increment (LRD, LWR: +1
    /// when served; LRW: +1 for a read served, +2 for a write taken).
    pub fn logical(&mut self, logical: u32, data: &mut [u8], read: bool, write: bool) -> u16 {
        let frame_in = data.to_vec();
        let (d0, d1) = (
            u64::from(logical) * 8,
            (u64::from(logical) + data.len() as u64) * 8,
        );
        let (mut read_hit, mut write_hit) = (false, false);
        // The process RAM this access wrote, first and last byte.
        let mut written: Option<(usize, usize)> = None;
        for n in 0..usize::from(self.fmmus) {
            let b = usize::from(reg::FMMU) + 16 * n;
            let f = &self.mem[b..b + 16];
            if f[12] & 1 == 0 {
                continue;
            }
            let log = u64::from(u32::from_le_bytes([f[0], f[1], f[2], f[3]]));
            let len = u64::from(u16::from_le_bytes([f[4], f[5]]));
            if len == 0 {
                continue;
            }
            let (start_bit, end_bit) = (u64::from(f[6] & 7), u64::from(f[7] & 7));
            let phys = u64::from(u16::from_le_bytes([f[8], f[9]])) * 8 + u64::from(f[10] & 7);
            let kind = f[11];
            let l0 = log * 8 + start_bit;
            let l1 = (log + len - 1) * 8 + end_bit + 1;
            let (o0, o1) = (l0.max(d0), l1.min(d1));
            if o0 >= o1 {
                continue;
            }
            let reads = read && kind & 1 != 0;
            let writes = write && kind & 2 != 0;
            for bit in o0..o1 {
                let p = phys + (bit - l0);
                let (pb, pi) = ((p / 8) as usize, (p % 8) as u8);
                let (db, di) = (((bit - d0) / 8) as usize, ((bit - d0) % 8) as u8);
                // Process data lives in the process RAM and the digital output register
                // (0x0F00, which simple output terminals use).
                if !(0x0F00..MEMORY).contains(&pb) {
                    continue;
                }
                if writes {
                    let v = (frame_in[db] >> di) & 1;
                    self.mem[pb] = (self.mem[pb] & !(1 << pi)) | (v << pi);
                    written = Some(written.map_or((pb, pb), |(lo, hi)| (lo.min(pb), hi.max(pb))));
                }
                if reads {
                    let v = (self.mem[pb] >> pi) & 1;
                    data[db] = (data[db] & !(1 << di)) | (v << di);
                }
            }
            read_hit |= reads;
            write_hit |= writes;
        }
        if let Some((lo, hi)) = written {
            self.outputs_written = true;
            if self.triggers_watchdog(lo, hi) {
                self.watchdog_trigger_ns = Some(self.now_ns);
            }
        }
        // LRD and LWR count 1 per SubDevice served; LRW 1 for its read, 2 for its write.
        if read && write {
            u16::from(read_hit) + 2 * u16::from(write_hit)
        } else {
            u16::from(read_hit || write_hit)
        }
    }

    /// Whether the process RAM from `lo` to `hi` (bytes) overlaps the buffer of an enabled
    /// SyncManager whose watchdog trigger is on.
    fn triggers_watchdog(&self, lo: usize, hi: usize) -> bool {
        (0..usize::from(self.sms)).any(|k| {
            let (start, length, control, on) = self.sm(k);
            let (start, end) = (usize::from(start), usize::from(start) + usize::from(length));
            on && control & 0x40 != 0 && lo < end && start <= hi
        })
    }

    /// The process RAM at `addr`, `len` bytes (what a SyncManager's buffer holds).
    pub fn memory(&self, addr: u16, len: usize) -> &[u8] {
        let s = usize::from(addr);
        &self.mem[s.min(MEMORY)..(s + len).min(MEMORY)]
    }

    /// Writes the device's side of the process RAM (its inputs).
    pub fn set_memory(&mut self, addr: u16, data: &[u8]) {
        let s = usize::from(addr);
        let e = (s + data.len()).min(MEMORY);
        self.mem[s..e].copy_from_slice(&data[..e - s]);
    }

    /// SyncManager `n`'s configuration as the MainDevice wrote it: start, length, control,
    /// enabled.
    pub fn sm(&self, n: usize) -> (u16, u16, u8, bool) {
        let b = reg::SM + 8 * n as u16;
        (
            self.get16(b),
            self.get16(b + 2),
            self.mem[usize::from(b + 4)],
            self.mem[usize::from(b + 6)] & 1 != 0,
        )
    }

    fn get16(&self, a: u16) -> u16 {
        let a = usize::from(a);
        u16::from_le_bytes([self.mem[a], self.mem[a + 1]])
    }

    fn put16(&mut self, a: u16, v: u16) {
        let a = usize::from(a);
        self.mem[a..a + 2].copy_from_slice(&v.to_le_bytes());
    }

    /// Every port's receive time and the processing unit's, in local time (the frame
    /// reaches every port of the emulated line at once: no propagation delay).
    fn latch_receive_times(&mut self) {
        let local = self.clock.local(self.now_ns);
        for port in 0..4u16 {
            let a = usize::from(reg::DC_RECEIVE_TIME_PORT0 + 4 * port);
            self.mem[a..a + 4].copy_from_slice(&(local as u32).to_le_bytes());
        }
        let a = usize::from(reg::DC_RECEIVE_TIME_UNIT);
        self.mem[a..a + 8].copy_from_slice(&local.to_le_bytes());
    }

    /// The SyncManagers the EEPROM names of `kind`, checked against what the MainDevice
    /// configured: the same start, at least the length, enabled.
    fn sms_configured(&self, kinds: &[SmKind]) -> bool {
        self.sii.sms.iter().enumerate().all(|(n, want)| {
            if !kinds.contains(&want.kind) || want.length == 0 {
                return true;
            }
            let (start, len, _, on) = self.sm(n);
            start == want.start && len >= want.length && on
        })
    }

    /// AL control was written: the state machine takes the request (ETG.1000.6 table "AL
    /// state transitions").
    fn al_control(&mut self) {
        let control = self.get16(reg::AL_CONTROL);
        let requested = (control & 0x0F) as u8;
        let ack = control & 0x10 != 0;
        let status = self.al_status();
        let current = (status & 0x0F) as u8;
        let error = status & 0x10 != 0;
        if error && !ack {
            return; // an error indication waits for its acknowledgement
        }
        let Some(current) = AlState::from_code(current) else {
            return;
        };
        let outcome = match AlState::from_code(requested) {
            None => Err(al_code::UNKNOWN_STATE),
            Some(AlState::Bootstrap) => Err(al_code::NO_BOOTSTRAP),
            Some(AlState::Init) => Ok(AlState::Init),
            Some(AlState::PreOp) => {
                let mailbox_ok = self.sii.mailbox.is_none()
                    || self.sms_configured(&[SmKind::MailboxOut, SmKind::MailboxIn]);
                if current == AlState::Init && !mailbox_ok {
                    Err(al_code::INVALID_MAILBOX)
                } else {
                    Ok(AlState::PreOp)
                }
            }
            Some(AlState::SafeOp) => match current {
                AlState::Init => Err(al_code::INVALID_STATE_CHANGE),
                AlState::PreOp if !self.sms_configured(&[SmKind::Outputs]) => {
                    Err(al_code::INVALID_OUTPUTS)
                }
                AlState::PreOp if !self.sms_configured(&[SmKind::Inputs]) => {
                    Err(al_code::INVALID_INPUTS)
                }
                AlState::PreOp if self.needs_sync0 && self.sync0().is_none() => {
                    Err(al_code::INVALID_DC_SYNC)
                }
                AlState::PreOp
                    if self.needs_sync0
                        && self.sync0().is_some_and(|(_, c)| c < MIN_SYNC0_CYCLE_NS) =>
                {
                    Err(al_code::INVALID_DC_CYCLE)
                }
                _ => Ok(AlState::SafeOp),
            },
            Some(AlState::Op) => match current {
                AlState::SafeOp | AlState::Op => Ok(AlState::Op),
                _ => Err(al_code::INVALID_STATE_CHANGE),
            },
        };
        match outcome {
            Ok(state) => {
                self.put16(reg::AL_STATUS, state as u16);
                self.put16(reg::AL_STATUS_CODE, al_code::NONE);
            }
            Err(code) => {
                self.put16(reg::AL_STATUS, current as u16 | 0x10);
                self.put16(reg::AL_STATUS_CODE, code);
            }
        }
    }

    /// SII control was written: a read copies 4 words from the word address into SII data; a
    /// write takes one word (with write enable); either completes at once.
    fn sii_command(&mut self) {
        let control = self.get16(reg::SII_CONTROL);
        let address = u32::from_le_bytes([
            self.mem[0x0504],
            self.mem[0x0505],
            self.mem[0x0506],
            self.mem[0x0507],
        ]) as usize;
        let mut status = control & !(sii_bit::READ | sii_bit::WRITE | sii_bit::RELOAD);
        status &= !sii_bit::BUSY;
        status |= sii_bit::READ_SIZE_8;
        let commands = control & (sii_bit::READ | sii_bit::WRITE | sii_bit::RELOAD);
        if commands == 0 {
            // No command: clears the error bits.
            status &= !(sii_bit::COMMAND_ERROR | sii_bit::WRITE_ERROR);
        } else if commands.count_ones() > 1 {
            status |= sii_bit::COMMAND_ERROR;
        } else if commands == sii_bit::READ {
            for k in 0..4 {
                let w = self.eeprom.get(address + k).copied().unwrap_or(0xFFFF);
                let a = usize::from(reg::SII_DATA) + 2 * k;
                self.mem[a..a + 2].copy_from_slice(&w.to_le_bytes());
            }
        } else if commands == sii_bit::WRITE {
            if control & sii_bit::WRITE_ENABLE == 0 {
                status |= sii_bit::WRITE_ERROR;
            } else if address >= EEPROM_WORDS {
                // Beyond the EEPROM (2 KiB, as word 0x3E says): refused, nothing grows.
                status |= sii_bit::COMMAND_ERROR;
            } else {
                let w = self.get16(reg::SII_DATA);
                if address >= self.eeprom.len() {
                    self.eeprom.resize(address + 1, 0xFFFF);
                }
                self.eeprom[address] = w;
            }
        }
        self.put16(reg::SII_CONTROL, status);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terminals::Terminal;

    /// An ESC with FMMU 0 mapping logical 0x100 (1 byte) onto physical `phys`, of `kind`.
    fn mapped(t: Terminal, phys: u16, kind: u8) -> Esc {
        let mut esc = t.esc();
        let mut f = [0u8; 16];
        f[0..4].copy_from_slice(&0x100u32.to_le_bytes());
        f[4..6].copy_from_slice(&1u16.to_le_bytes());
        f[7] = 7;
        f[8..10].copy_from_slice(&phys.to_le_bytes());
        f[11] = kind;
        f[12] = 1;
        assert!(esc.write(reg::FMMU, &f));
        esc
    }

    /// An EL2008 in OP with its outputs mapped, its SyncManager as its EEPROM says.
    fn el2008_in_op() -> Esc {
        let mut esc = mapped(Terminal::El2008 { outputs: 0 }, 0x0F00, 2);
        assert!(esc.write(reg::SM, &[0x00, 0x0F, 1, 0, 0x44, 0, 1, 0]));
        for state in [AlState::PreOp, AlState::SafeOp, AlState::Op] {
            assert!(esc.write(reg::AL_CONTROL, &[state as u8, 0]));
            assert_eq!(esc.al_state(), Some(state), "{:#x}", esc.al_status_code());
        }
        esc
    }

    #[test]
    fn the_process_data_watchdog_takes_the_outputs_down_and_the_subdevice_to_safe_op() {
        let mut esc = el2008_in_op();
        assert_eq!(
            esc.watchdog_ns(),
            100_000_000,
            "the ET1100's default: 100 ms"
        );
        let t0 = crate::now_ns();
        assert!(
            !esc.check_watchdog(t0 + 1_000_000_000),
            "not armed before a write"
        );
        let t = crate::now_ns();
        esc.set_time(t);
        assert_eq!(esc.logical(0x100, &mut [0x3C], false, true), 1);
        assert!(!esc.check_watchdog(t + 90_000_000), "90 ms after the write");
        assert_eq!(esc.memory(reg::WATCHDOG_STATUS_PD, 1)[0] & 1, 1, "running");
        assert_eq!(esc.memory(0x0F00, 1)[0], 0x3C);
        assert!(esc.check_watchdog(t + 110_000_000), "110 ms after it");
        assert_eq!(esc.memory(0x0F00, 1)[0], 0, "outputs off");
        assert_eq!(esc.al_status(), AlState::SafeOp as u16 | 0x10);
        assert_eq!(esc.al_status_code(), al_code::SM_WATCHDOG);
        assert_eq!(esc.memory(reg::WATCHDOG_STATUS_PD, 1)[0] & 1, 0, "expired");
        assert_eq!(esc.memory(reg::WATCHDOG_COUNTER_PD, 1)[0], 1);
        // Its time 0 turns it off.
        let mut esc = el2008_in_op();
        assert!(esc.write(reg::WATCHDOG_TIME_PD, &[0, 0]));
        assert_eq!(esc.logical(0x100, &mut [0x3C], false, true), 1);
        assert!(!esc.check_watchdog(crate::now_ns() + 10_000_000_000));
        assert_eq!(esc.al_state(), Some(AlState::Op));
    }

    #[test]
    fn logical_commands_count_as_the_standard_says() {
        let mut inputs = mapped(Terminal::El1008 { inputs: 0 }, 0x1000, 1);
        inputs.set_memory(0x1000, &[0xA5]);
        let mut outputs = mapped(Terminal::El2008 { outputs: 0 }, 0x0F00, 2);
        let mut d = [0u8];
        assert_eq!(
            inputs.logical(0x100, &mut d, true, false),
            1,
            "LRD of inputs"
        );
        assert_eq!(d[0], 0xA5);
        let mut d = [0x3C];
        assert_eq!(
            outputs.logical(0x100, &mut d, false, true),
            1,
            "LWR of outputs"
        );
        assert_eq!(outputs.memory(0x0F00, 1)[0], 0x3C);
        assert_eq!(
            inputs.logical(0x100, &mut [0], false, true),
            0,
            "LWR of inputs"
        );
        assert_eq!(
            outputs.logical(0x100, &mut [0], true, false),
            0,
            "LRD of outputs"
        );
        assert_eq!(
            inputs.logical(0x100, &mut [0], true, true),
            1,
            "LRW of inputs"
        );
        assert_eq!(
            outputs.logical(0x100, &mut [0x11], true, true),
            2,
            "LRW of outputs"
        );
        assert_eq!(
            inputs.logical(0x101, &mut [0], true, true),
            0,
            "outside the mapping"
        );
    }

    #[test]
    fn a_mailbox_written_whole_is_answered_in_the_send_mailbox_and_emptied_by_reading_it() {
        use crate::coe::{Dictionary, answer};
        use crate::sii::{Identity, Mailbox, Sm};
        let mailbox = Mailbox {
            receive_offset: 0x1000,
            receive_size: 128,
            send_offset: 0x1080,
            send_size: 128,
            protocols: 0x04,
        };
        let sm = |start, control, kind| Sm {
            start,
            length: 128,
            control,
            enable: true,
            kind,
        };
        let sii = Sii {
            identity: Identity {
                vendor: 0x1234,
                product: 1,
                revision: 1,
                serial: 1,
            },
            alias: 0,
            order: "DRIVE".into(),
            group: "Drive".into(),
            name: "a drive".into(),
            mailbox: Some(mailbox),
            fmmus: vec![],
            sms: vec![
                sm(0x1000, 0x26, SmKind::MailboxOut),
                sm(0x1080, 0x22, SmKind::MailboxIn),
            ],
            tx_pdos: vec![],
            rx_pdos: vec![],
        };
        let mut esc = Esc::new(sii, 8, 8, false);
        // PRE-OP is refused until the MainDevice set up both mailbox SyncManagers.
        esc.write(reg::AL_CONTROL, &2u16.to_le_bytes());
        assert_eq!(esc.al_status_code(), al_code::INVALID_MAILBOX);
        for (n, start, control) in [(0u16, 0x1000u16, 0x26u8), (1, 0x1080, 0x22)] {
            let mut r = [0u8; 8];
            r[0..2].copy_from_slice(&start.to_le_bytes());
            r[2..4].copy_from_slice(&128u16.to_le_bytes());
            r[4] = control;
            r[6] = 1;
            esc.write(reg::SM + 8 * n, &r);
        }
        esc.write(reg::AL_CONTROL, &0x12u16.to_le_bytes());
        assert_eq!(esc.al_status(), 2, "PRE-OP");
        let mut dictionary = Dictionary::default();
        dictionary.constant(0x1018, 1, &0x1234u32.to_le_bytes());
        // An SDO upload of 0x1018:01, written in two pieces: only the last completes it.
        let mut request = [0u8; 128];
        request[0..2].copy_from_slice(&10u16.to_le_bytes());
        request[5] = 0x13; // CoE, counter 1
        request[6..8].copy_from_slice(&0x2000u16.to_le_bytes());
        request[8..12].copy_from_slice(&[0x40, 0x18, 0x10, 1]);
        esc.write(0x1000, &request[..64]);
        assert!(
            esc.take_mailbox().is_none(),
            "half a mailbox is not a request"
        );
        esc.write(0x1040, &request[64..]);
        let got = esc.take_mailbox().expect("the whole mailbox");
        let reply = answer(&mut dictionary, &got, esc.mailbox_capacity()).expect("an answer");
        assert!(esc.put_mailbox(&reply));
        assert!(!esc.put_mailbox(&reply), "full until read");
        let mut status = [0u8];
        esc.read(reg::SM + 8 + 5, &mut status, false);
        assert_eq!(status[0] & SM_FULL, SM_FULL);
        let mut out = [0u8; 128];
        esc.read(0x1080, &mut out, false);
        assert_eq!(&out[8..16], &[0x43, 0x18, 0x10, 1, 0x34, 0x12, 0, 0]);
        esc.read(reg::SM + 8 + 5, &mut status, false);
        assert_eq!(status[0] & SM_FULL, 0, "emptied by reading its last byte");
    }

    #[test]
    fn an_eeprom_write_beyond_the_eeprom_is_refused_and_nothing_grows() {
        let mut esc = Terminal::Ek1100.esc();
        // Write enable, write command, address 0x7FFFFFFF, data 0x1234.
        esc.write(reg::SII_DATA, &[0x34, 0x12]);
        esc.write(reg::SII_CONTROL, &[0x01, 0x02, 0xFF, 0xFF, 0xFF, 0x7F]);
        assert_ne!(esc.get16(reg::SII_CONTROL) & sii_bit::COMMAND_ERROR, 0);
        assert!(esc.eeprom.len() <= EEPROM_WORDS);
        // A mailbox SyncManager set past the memory is no mailbox (no panic either).
        let mut sm = [0u8; 8];
        sm[0..2].copy_from_slice(&0xFFF0u16.to_le_bytes());
        sm[2..4].copy_from_slice(&0x20u16.to_le_bytes());
        sm[6] = 1;
        esc.write(reg::SM, &sm);
        esc.write(0xFFF0, &[0; 16]);
        assert!(esc.take_mailbox().is_none());
    }

    #[test]
    fn a_device_on_sync0_goes_to_safe_op_only_with_sync0_active_and_its_start_waits_for_the_wrap() {
        // An EK1100's ESC (it has DC) standing in for a device that asked for SYNC0.
        let mut esc = Terminal::Ek1100.esc();
        esc.set_time(1_000_000_000);
        esc.set_needs_sync0(true);
        let request = |esc: &mut Esc, state: u16| {
            esc.write(reg::AL_CONTROL, &state.to_le_bytes());
            (esc.al_status(), esc.al_status_code())
        };
        assert_eq!(request(&mut esc, 2), (2, 0), "PRE-OP");
        assert_eq!(
            request(&mut esc, 4),
            (0x12, al_code::INVALID_DC_SYNC),
            "SYNC0 not active"
        );
        // The system time now is its local time plus the offset written.
        esc.write(reg::DC_TIME_OFFSET, &5_000_000_000u64.to_le_bytes());
        let now = esc.system_time();
        assert_eq!(now, 6_000_000_000);
        let activate = |esc: &mut Esc, start: u64, cycle: u32| {
            esc.write(reg::DC_ACTIVATION, &[0]);
            esc.write(reg::DC_START_TIME, &start.to_le_bytes());
            esc.write(reg::DC_SYNC0_CYCLE, &cycle.to_le_bytes());
            esc.write(reg::DC_ACTIVATION, &[0x03]);
            esc.sync0()
        };
        assert_eq!(
            activate(&mut esc, now + 100_000_000, 100_000),
            Some((now + 100_000_000, 100_000))
        );
        assert_eq!(
            request(&mut esc, 0x14),
            (0x12, al_code::INVALID_DC_CYCLE),
            "100 µs is under its 125 µs"
        );
        assert_eq!(
            activate(&mut esc, now - 1, 1_000_000),
            Some((now - 1 + (1 << 32), 1_000_000)),
            "a start time already past waits for the low 32 bits to come round again"
        );
        assert_eq!(request(&mut esc, 0x14), (4, 0), "SAFE-OP with SYNC0 active");
        esc.write(reg::DC_ACTIVATION, &[0x01]);
        assert_eq!(esc.sync0(), None, "SYNC0 off");
    }

    #[test]
    fn the_drift_control_moves_the_clock_toward_the_written_time_a_bounded_step_at_a_time() {
        let mut esc = Terminal::Ek1100.esc();
        esc.set_time(1_000_000_000);
        let write = |esc: &mut Esc, t: u64| {
            esc.write(reg::DC_SYSTEM_TIME, &t.to_le_bytes());
            difference(esc)
        };
        // Its own time 40 µs behind the written: the difference says "smaller" (bit 31),
        // and each write takes it a quarter of the way, at most 1 µs.
        assert_eq!(write(&mut esc, 1_000_040_000), 40_000 | 1 << 31);
        assert_eq!(esc.system_time(), 1_000_001_000);
        assert_eq!(write(&mut esc, 1_000_001_002), 2 | 1 << 31, "2 ns smaller");
        assert_eq!(esc.system_time(), 1_000_001_000, "2 / 4 rounds to nothing");
        // A quartz 100 ppm fast: 100 ns a millisecond, caught up by one write a millisecond.
        esc.set_drift(100.0);
        for k in 1..=1000u64 {
            let host = 1_000_000_000 + k * 1_000_000;
            esc.set_time(host);
            write(&mut esc, host + 1_000);
        }
        let off = esc.system_time() as i64 - (2_000_000_000 + 1_000) as i64;
        assert!(off.abs() < 500, "{off} ns off after 1 s");
        // A 32-bit write compares the low 32 bits only.
        esc.set_time(5_000_000_000);
        let own = esc.system_time();
        esc.write(
            reg::DC_SYSTEM_TIME,
            &((own as u32).wrapping_sub(8)).to_le_bytes(),
        );
        assert_eq!(difference(&esc), 8);
    }

    /// The DC system time difference register.
    fn difference(esc: &Esc) -> u32 {
        let b = esc.memory(reg::DC_TIME_DIFFERENCE, 4);
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }

    #[test]
    fn the_al_state_machine_refuses_what_the_standard_refuses() {
        let mut esc = Terminal::El2008 { outputs: 0 }.esc();
        let request = |esc: &mut Esc, state: u16| {
            esc.write(reg::AL_CONTROL, &state.to_le_bytes());
            (esc.al_status(), esc.al_status_code())
        };
        assert_eq!(
            request(&mut esc, 8),
            (0x11, al_code::INVALID_STATE_CHANGE),
            "INIT to OP"
        );
        assert_eq!(
            request(&mut esc, 2),
            (0x11, al_code::INVALID_STATE_CHANGE),
            "unacknowledged"
        );
        assert_eq!(request(&mut esc, 0x12), (2, 0), "acknowledged, to PRE-OP");
        assert_eq!(
            request(&mut esc, 4),
            (0x12, al_code::INVALID_OUTPUTS),
            "SMs not set"
        );
        let mut sm = [0u8; 8];
        sm[0..2].copy_from_slice(&0x0F00u16.to_le_bytes());
        sm[2..4].copy_from_slice(&1u16.to_le_bytes());
        sm[4] = 0x44;
        sm[6] = 1;
        esc.write(reg::SM, &sm);
        assert_eq!(
            request(&mut esc, 0x14),
            (4, 0),
            "SAFE-OP with its SyncManager"
        );
        assert_eq!(request(&mut esc, 8), (8, 0), "OP");
        assert_eq!(
            request(&mut esc, 3),
            (0x18, al_code::NO_BOOTSTRAP),
            "bootstrap"
        );
        assert_eq!(
            request(&mut esc, 0x17),
            (0x18, al_code::UNKNOWN_STATE),
            "state 7"
        );
        assert_eq!(request(&mut esc, 0x11), (1, 0), "INIT");
    }
}
