//! A CiA 402 servo drive behind an ESC (ETG.6010): the objects of the drive profile in a CoE
//! object dictionary, the process data mapped by the MainDevice in PRE-OP (0x1C12/0x1C13 and
//! 0x1600/0x1A00 written by SDO, as a real drive takes them), and behind them the drive and
//! mechanics of `machine-sim` — one physics for the simulated machine and the emulated bus.
//!
//! Units on the wire are the drive's own: position in encoder counts, velocity in counts per
//! second, torque in thousandths of the rated torque; [`Scaling`] converts them to the axis'
//! units for the model, rounded and saturated to the objects' types.
//!
//! The drive runs its model over real elapsed time whenever it is stepped ([`Drive::step`],
//! from every frame and from the emulator's idle ticks). A frame that writes its outputs
//! (SM2) in OP is a new command. Taken out of OP (by its MainDevice, or by its ESC's process
//! data watchdog) it quick-stops; behind that, without a new command for its command
//! watchdog while the power stage is on, it faults as `machine-sim`'s drives do (0xFF01).

use crate::coe::{self, Dictionary};
use crate::esc::{AlState, Esc};
use crate::sii::{Identity, Mailbox, Pdo, PdoEntry, Sii, Sm, SmKind};
use cia402::{State, cw};
use machine_sim::Machine;
use shm_schema::event::EventQueue;
use shm_schema::{AxisConfigV2, CellConfigV6, DriveCommandV2, FaultInjectionV1};

/// The emulator's vendor id: not one ETG assigned to a manufacturer, so that no tool takes
/// an emulated drive for a real one.
pub const VENDOR: u32 = 0xE1A0_0001;
/// The emulated drive's product code.
pub const PRODUCT: u32 = 0x0000_0402;
/// Its revision.
pub const REVISION: u32 = 0x0001_0000;

/// Physical start of the receive mailbox (SM0).
const MBX_OUT: u16 = 0x1000;
/// Physical start of the send mailbox (SM1).
const MBX_IN: u16 = 0x1080;
/// Mailbox size (each way).
const MBX_SIZE: u16 = 128;
/// Physical start of the outputs (SM2).
const OUTPUTS: u16 = 0x1100;
/// Physical start of the inputs (SM3).
const INPUTS: u16 = 0x1180;
/// Entries a PDO mapping object holds.
const MAX_ENTRIES: u8 = 16;

pub use cia402::pdo::{RX_DEFAULT, Scaling, TX_DEFAULT, mapping, obj, sync};

/// SYNC0 events handed to the model at most per frame or idle tick: behind by more (the
/// emulator was not scheduled), the older ones count as missed and are skipped.
const MAX_CATCH_UP: u64 = 64;

/// A drive on SYNC0 (its 0x1C32:01 is 2 and its ESC's SYNC0 active, in SAFE-OP or OP): the
/// outputs a frame brings wait for the next SYNC0; the inputs the next frame reads are
/// latched 0x1C33:03 (the input shift) after each SYNC0.
#[derive(Clone, Debug, Default)]
struct OnSync0 {
    /// SYNC0's first event (system time) as last seen, the next SYNC0 to hand over, and the
    /// next input latch.
    first: u64,
    next: u64,
    next_latch: u64,
    /// Outputs a frame wrote in OP since the last event.
    pending: Option<Vec<u8>>,
    /// The inputs the last event latched.
    latched: Option<Vec<u8>>,
}

/// The objects one way may map: those of its default mapping (an RxPDO the outputs', a
/// TxPDO the inputs'), each with its size in bits.
fn mappable(rxpdo: bool) -> &'static [(u16, u8)] {
    if rxpdo { &RX_DEFAULT } else { &TX_DEFAULT }
}

/// The CoE data type of a mappable object: UNSIGNED16 for the control, status and error
/// words, else INTEGER8, INTEGER16 or INTEGER32 by its size.
fn data_type(index: u16, bits: u8) -> u8 {
    match (index, bits) {
        (obj::CONTROLWORD | obj::STATUSWORD | obj::ERROR_CODE, _) => 6,
        (_, 8) => 2,
        (_, 16) => 3,
        _ => 4,
    }
}

/// The axis of a drive the emulator runs on its own (`--line ek1100,drive`), without a cell
/// to take the mechanics from: a light linear axis in mm starting at 40, its drive closing a
/// stiff position loop (CSP), 1000 counts per mm, a rated torque of 10 effort units.
pub fn standalone() -> (AxisConfigV2, Scaling) {
    (
        AxisConfigV2 {
            start: 40.0,
            inertia: 0.01,
            viscous: 0.02,
            coulomb: 0.05,
            effort_limit: 30.0,
            encoder_resolution: 0.001,
            drive_kp: 40.0,
            drive_ki: 0.0,
            drive_kd: 1.0,
            quick_stop_deceleration: 500.0,
            quick_stop_option: 2,
            ..AxisConfigV2::default()
        },
        Scaling {
            counts_per_unit: 1000.0,
            rated_effort: 10.0,
        },
    )
}

/// One emulated drive: its object dictionary, its mapping and its model.
#[derive(Clone, Debug)]
pub struct Drive {
    name: String,
    dictionary: Dictionary,
    scaling: Scaling,
    machine: Machine,
    command: DriveCommandV2,
    events: EventQueue,
    /// The error code last reported (0x603F), for an emergency when it changes.
    reported_error: u16,
    /// Emergencies not yet handed to the ESC.
    emergencies: Vec<Vec<u8>>,
    /// The next mailbox request is answered by this emergency first (a fault it can be told
    /// to make: the worst moment for a MainDevice).
    emergency_on_request: Option<u16>,
    /// The mailbox counter of the next emergency (1..=7).
    counter: u8,
    /// A fault injection for the model's next cycle (`<i>/drives/inject` in a test cell).
    injection: Option<FaultInjectionV1>,
    /// While it runs on SYNC0.
    sync0: Option<OnSync0>,
    /// SYNC0 events it has taken.
    sync0_events: u64,
}

impl Drive {
    /// A drive named `name` moving axis `axis` (its mechanics, drive gains and quick stop),
    /// its units `scaling`; the command watchdog `watchdog_ns`.
    pub fn new(name: &str, axis: &AxisConfigV2, scaling: Scaling, watchdog_ns: u64) -> Self {
        let mut cell = CellConfigV6 {
            axes: 1,
            machine_substeps: 4,
            drive_command_timeout_ns: watchdog_ns,
            ..Default::default()
        };
        cell.axis[0] = *axis;
        let mut d = Dictionary::default();
        d.constant(obj::DEVICE_TYPE, 0, &0x0002_0192u32.to_le_bytes())
            .constant(obj::NAME, 0, name.as_bytes())
            .constant(obj::IDENTITY, 0, &[4])
            .constant(obj::IDENTITY, 1, &VENDOR.to_le_bytes())
            .constant(obj::IDENTITY, 2, &PRODUCT.to_le_bytes())
            .constant(obj::IDENTITY, 3, &REVISION.to_le_bytes())
            .constant(obj::IDENTITY, 4, &0u32.to_le_bytes())
            .constant(obj::SUPPORTED_MODES, 0, &0x0380u32.to_le_bytes())
            .constant(obj::SM_TYPES, 0, &[4])
            .constant(obj::SM_TYPES, 1, &[1])
            .constant(obj::SM_TYPES, 2, &[2])
            .constant(obj::SM_TYPES, 3, &[3])
            .constant(obj::SM_TYPES, 4, &[4])
            .constant(
                obj::RATED_TORQUE,
                0,
                &((scaling.rated_effort * 1000.0).round().max(0.0) as u32).to_le_bytes(),
            )
            .variable(
                obj::QUICK_STOP_OPTION,
                0,
                &(axis.quick_stop_option as i16).to_le_bytes(),
            )
            .variable(
                obj::QUICK_STOP_DECELERATION,
                0,
                &(scaling.counts(axis.quick_stop_deceleration).max(0) as u32).to_le_bytes(),
            );
        for &(index, bits) in RX_DEFAULT.iter().chain(&TX_DEFAULT) {
            d.variable(index, 0, &vec![0u8; usize::from(bits / 8)]);
        }
        d.set(obj::MODE, 0, &[8]); // CSP until told otherwise
        // Synchronisation (ETG.1020): SM-synchronous until the MainDevice asks for SYNC0;
        // free run, SM event and DC SYNC0 supported, down to 125 µs.
        for index in [obj::SM2_SYNC, obj::SM3_SYNC] {
            d.constant(index, 0, &[0x20])
                .variable(index, sync::MODE, &sync::SM_EVENT.to_le_bytes())
                .variable(index, sync::CYCLE_TIME, &0u32.to_le_bytes())
                .variable(index, sync::SHIFT_TIME, &0u32.to_le_bytes())
                .constant(index, sync::SUPPORTED, &0x0007u16.to_le_bytes())
                .constant(
                    index,
                    sync::MIN_CYCLE_TIME,
                    &(crate::esc::MIN_SYNC0_CYCLE_NS as u32).to_le_bytes(),
                )
                .constant(index, sync::SM_EVENT_MISSED, &0u16.to_le_bytes());
        }
        for (pdo, entries, assign) in [
            (obj::RXPDO, &RX_DEFAULT, obj::SM2_ASSIGN),
            (obj::TXPDO, &TX_DEFAULT, obj::SM3_ASSIGN),
        ] {
            d.variable(pdo, 0, &[entries.len() as u8]);
            for k in 1..=MAX_ENTRIES {
                let e = entries
                    .get(usize::from(k - 1))
                    .map_or(0, |&(i, b)| mapping(i, 0, b));
                d.variable(pdo, k, &e.to_le_bytes());
            }
            d.variable(assign, 0, &[1])
                .variable(assign, 1, &pdo.to_le_bytes());
        }
        let mut drive = Self {
            name: name.into(),
            dictionary: d,
            scaling,
            machine: Machine::new(&cell, 1_000_000),
            command: DriveCommandV2 {
                axes: 1,
                ..Default::default()
            },
            events: EventQueue::default(),
            reported_error: 0,
            emergencies: Vec::new(),
            emergency_on_request: None,
            counter: 1,
            injection: None,
            sync0: None,
            sync0_events: 0,
        };
        // Its first command is its dictionary's: Disable voltage, CSP.
        drive.take_command();
        drive
    }

    /// Its name (0x1008).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Its identity.
    pub fn identity(&self) -> Identity {
        Identity {
            vendor: VENDOR,
            product: PRODUCT,
            revision: REVISION,
            serial: 0,
        }
    }

    /// The object dictionary (for tests and tools).
    pub fn dictionary(&self) -> &Dictionary {
        &self.dictionary
    }

    /// The model (for tests).
    pub fn machine(&self) -> &Machine {
        &self.machine
    }

    /// Answers the next mailbox request with an emergency of `code` first (the answer
    /// follows once it is read): what a drive does when it faults while the MainDevice waits
    /// for an SDO.
    pub fn emergency_on_next_request(&mut self, code: u16) {
        self.emergency_on_request = Some(code);
    }

    /// Sends a CoE emergency of `code` (a fault it can be told to make, whatever its state).
    pub fn send_emergency(&mut self, code: u16) {
        self.push_emergency(code);
    }

    /// Makes its model see fault condition `code` (one of `shm_schema::drive::injected`)
    /// from its next cycle, or clears it (`active` false): `machine-sim`'s injection.
    pub fn inject(&mut self, code: u16, active: bool, seq: u64) {
        self.injection = Some(FaultInjectionV1 {
            seq,
            axis: 0,
            code,
            active: u16::from(active),
        });
    }

    /// The emergencies to send: one per change of its error code to a fault (code, error
    /// register 0x01 generic error, no manufacturer data).
    pub fn emergencies(&mut self) -> Vec<Vec<u8>> {
        std::mem::take(&mut self.emergencies)
    }

    fn push_emergency(&mut self, code: u16) {
        self.emergencies
            .push(coe::emergency(code, 0x01, [0; 5], self.counter));
        self.counter = self.counter % 7 + 1;
    }

    /// Its ESC: a mailbox (SM0, SM1), outputs (SM2) and inputs (SM3) whose lengths follow the
    /// mapping, three FMMUs, DC.
    pub fn esc(&self) -> Esc {
        let pdo = |index: u16, sm: u8, entries: &[(u16, u8)]| Pdo {
            index,
            sm,
            entries: entries
                .iter()
                .map(|&(index, bits)| PdoEntry {
                    index,
                    subindex: 0,
                    bits,
                    data_type: data_type(index, bits),
                })
                .collect(),
        };
        let sm = |start, control, kind| Sm {
            start,
            // Process data: its length is what the mapping makes it (0: not checked
            // against the EEPROM).
            length: if matches!(kind, SmKind::MailboxOut | SmKind::MailboxIn) {
                MBX_SIZE
            } else {
                0
            },
            control,
            enable: true,
            kind,
        };
        let sii = Sii {
            identity: self.identity(),
            alias: 0,
            order: "RTC-EMU-402".into(),
            group: "Drive".into(),
            name: format!("Emulated CiA 402 drive ({})", self.name),
            mailbox: Some(Mailbox {
                receive_offset: MBX_OUT,
                receive_size: MBX_SIZE,
                send_offset: MBX_IN,
                send_size: MBX_SIZE,
                protocols: 0x0004, // CoE
            }),
            fmmus: vec![1, 2, 3],
            sms: vec![
                sm(MBX_OUT, 0x26, SmKind::MailboxOut),
                sm(MBX_IN, 0x22, SmKind::MailboxIn),
                sm(OUTPUTS, 0x64, SmKind::Outputs),
                sm(INPUTS, 0x20, SmKind::Inputs),
            ],
            tx_pdos: vec![pdo(obj::TXPDO, 3, &TX_DEFAULT)],
            rx_pdos: vec![pdo(obj::RXPDO, 2, &RX_DEFAULT)],
        };
        Esc::new(sii, 3, 8, true)
    }

    /// The mailboxes that answer a CoE mailbox request, in order: the emergency it was told
    /// to send first (if any), then the answer (none for a request it ignores). The PDO
    /// assignment and mapping may be written in PRE-OP only (abort 0x0800_0022 otherwise),
    /// and only with objects that can be mapped that way (abort 0x0604_0041).
    pub fn mailbox(
        &mut self,
        request: &[u8],
        capacity: usize,
        al: Option<AlState>,
    ) -> Vec<Vec<u8>> {
        if let Some(code) = self.emergency_on_request.take() {
            self.push_emergency(code);
        }
        let mut out = self.emergencies();
        out.extend(self.answer(request, capacity, al));
        out
    }

    fn answer(&mut self, request: &[u8], capacity: usize, al: Option<AlState>) -> Option<Vec<u8>> {
        if let Some((index, sub, data)) = coe::download_target(request) {
            let mapping_object = matches!(
                index,
                obj::RXPDO | obj::TXPDO | obj::SM2_ASSIGN | obj::SM3_ASSIGN
            );
            let sync_mode = matches!(index, obj::SM2_SYNC | obj::SM3_SYNC) && sub == sync::MODE;
            if (mapping_object || sync_mode) && al != Some(AlState::PreOp) {
                return coe::abort_reply(request, index, sub, coe::abort::STATE);
            }
            if sync_mode
                && !matches!(
                    data.get(..2).map(|b| u16::from_le_bytes([b[0], b[1]])),
                    Some(sync::FREE_RUN | sync::SM_EVENT | sync::DC_SYNC0)
                )
            {
                return coe::abort_reply(request, index, sub, coe::abort::VALUE_RANGE);
            }
            if let Some(code) = self.refuse_mapping(index, sub, data) {
                return coe::abort_reply(request, index, sub, code);
            }
        }
        coe::answer(&mut self.dictionary, request, capacity)
    }

    /// Why a write of `data` to `index`:`sub` makes a mapping this drive cannot serve.
    fn refuse_mapping(&self, index: u16, sub: u8, data: &[u8]) -> Option<u32> {
        let word = |d: &[u8]| {
            d.get(..4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        };
        let byte = |d: &[u8]| d.first().copied();
        match (index, sub) {
            (obj::RXPDO | obj::TXPDO, 0) => {
                (byte(data)? > MAX_ENTRIES).then_some(coe::abort::MAPPING_LENGTH)
            }
            (obj::RXPDO | obj::TXPDO, _) => {
                let e = word(data)?;
                if e == 0 {
                    return None;
                }
                let (i, s, bits) = ((e >> 16) as u16, (e >> 8) as u8, e as u8);
                let ok = s == 0 && mappable(index == obj::RXPDO).contains(&(i, bits));
                (!ok).then_some(coe::abort::NOT_MAPPABLE)
            }
            (obj::SM2_ASSIGN | obj::SM3_ASSIGN, 0) => {
                (byte(data)? > 1).then_some(coe::abort::MAPPING_LENGTH)
            }
            (obj::SM2_ASSIGN | obj::SM3_ASSIGN, 1) => {
                let pdo = if index == obj::SM2_ASSIGN {
                    obj::RXPDO
                } else {
                    obj::TXPDO
                };
                (u16::from_le_bytes([*data.first()?, *data.get(1)?]) != pdo)
                    .then_some(coe::abort::NOT_MAPPABLE)
            }
            _ => None,
        }
    }

    /// The mapped entries of `pdo` (index, bits), as assigned to its SyncManager (none if
    /// the SyncManager has no PDO assigned).
    fn mapped(&self, assign: u16, pdo: u16) -> Vec<(u16, u8)> {
        let value = |i: u16, s: u8| {
            self.dictionary
                .get(i, s)
                .map(|e| e.data.clone())
                .unwrap_or_default()
        };
        if value(assign, 0).first().copied().unwrap_or(0) == 0 {
            return Vec::new();
        }
        let n = value(pdo, 0).first().copied().unwrap_or(0).min(MAX_ENTRIES);
        (1..=n)
            .filter_map(|k| {
                let d = value(pdo, k);
                let e = u32::from_le_bytes(d.get(..4)?.try_into().ok()?);
                (e != 0).then_some(((e >> 16) as u16, e as u8))
            })
            .collect()
    }

    /// Whether the MainDevice asked it to run on SYNC0 (0x1C32:01 = 2).
    pub fn on_sync0(&self) -> bool {
        self.dictionary
            .get(obj::SM2_SYNC, sync::MODE)
            .is_some_and(|e| e.data == sync::DC_SYNC0.to_le_bytes())
    }

    /// SYNC0 events it has taken (its outputs applied, or missed).
    pub fn sync0_events(&self) -> u64 {
        self.sync0_events
    }

    /// How long after SYNC0 it latches its inputs (0x1C33:03, ns).
    pub fn input_shift_ns(&self) -> u32 {
        self.dictionary
            .get(obj::SM3_SYNC, sync::SHIFT_TIME)
            .and_then(|e| e.data.get(..4))
            .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// SYNC0 events in OP that found no new outputs (0x1C32:0B).
    pub fn sm_events_missed(&self) -> u16 {
        self.dictionary
            .get(obj::SM2_SYNC, sync::SM_EVENT_MISSED)
            .and_then(|e| e.data.get(..2))
            .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]))
    }

    /// SYNC0 as it runs it: its ESC's, when it was asked for it and is in SAFE-OP or OP.
    fn sync0_of(&self, esc: &Esc) -> Option<(u64, u64)> {
        let state = esc.al_state();
        let running = matches!(state, Some(AlState::SafeOp | AlState::Op));
        if running && self.on_sync0() {
            esc.sync0()
        } else {
            None
        }
    }

    /// Hands the model every SYNC0 event up to the frame's time `now_ns`: at each, the model
    /// runs up to it, takes the outputs a frame brought since the last (in OP; none: an SM
    /// event missed) and latches its inputs. Off SYNC0, forgets it ran on it.
    fn catch_up(&mut self, esc: &Esc, now_ns: u64) {
        let Some((first, cycle)) = self.sync0_of(esc) else {
            self.sync0 = None;
            return;
        };
        let shift = u64::from(self.input_shift_ns()) % cycle;
        let mut on = match self.sync0.take() {
            Some(s) if s.first == first => s,
            _ => OnSync0 {
                first,
                next: first,
                next_latch: first + shift,
                ..OnSync0::default()
            },
        };
        let system = esc.system_time();
        let op = esc.al_state() == Some(AlState::Op);
        if on.next <= system {
            let due = (system - on.next) / cycle + 1;
            if due > MAX_CATCH_UP {
                let skipped = due - MAX_CATCH_UP;
                on.next += skipped * cycle;
                on.next_latch += skipped * cycle;
                if op {
                    self.count_missed(skipped);
                }
            }
        }
        // SYNC0 (the outputs) and the input latch in the order they come.
        loop {
            let output = on.next <= on.next_latch;
            let t = if output { on.next } else { on.next_latch };
            if t > system {
                break;
            }
            self.step(now_ns.saturating_sub(system - t), op);
            if output {
                self.sync0_events += 1;
                if op {
                    match on.pending.take() {
                        Some(data) => self.take_outputs(&data),
                        None => self.count_missed(1),
                    }
                }
                on.next += cycle;
            } else {
                on.latched = Some(self.packed_inputs(esc));
                on.next_latch += cycle;
            }
        }
        self.sync0 = Some(on);
    }

    fn count_missed(&mut self, n: u64) {
        let missed = u64::from(self.sm_events_missed()) + n;
        let missed = missed.min(u64::from(u16::MAX)) as u16;
        self.dictionary
            .set(obj::SM2_SYNC, sync::SM_EVENT_MISSED, &missed.to_le_bytes());
    }

    /// Its inputs (TxPDO) as the mapping packs them, SM3's length.
    fn packed_inputs(&self, esc: &Esc) -> Vec<u8> {
        let (_, len, _, _) = esc.sm(3);
        let mut buf = Vec::with_capacity(usize::from(len));
        for (index, _) in self.mapped(obj::SM3_ASSIGN, obj::TXPDO) {
            if let Some(e) = self.dictionary.get(index, 0) {
                buf.extend_from_slice(&e.data);
            }
        }
        buf.resize(usize::from(len), 0);
        buf
    }

    /// The outputs (RxPDO) `data` into the dictionary, and the drive's new command.
    fn take_outputs(&mut self, data: &[u8]) {
        let mut at = 0;
        for (index, bits) in self.mapped(obj::SM2_ASSIGN, obj::RXPDO) {
            let n = usize::from(bits / 8);
            if let Some(v) = data.get(at..at + n) {
                self.dictionary.set(index, 0, v);
            }
            at += n;
        }
        self.take_command();
    }

    /// Before a frame at `now_ns`: the model run up to then, and its inputs (TxPDO) packed
    /// into SM3's buffer. SM-synchronous, what the frame reads is where the axis is as the
    /// frame passes (not where it was at the previous frame, a period late); on SYNC0, what
    /// the last SYNC0 latched.
    pub fn inputs(&mut self, esc: &mut Esc, now_ns: u64) {
        self.catch_up(esc, now_ns);
        self.step(now_ns, esc.al_state() == Some(AlState::Op));
        let (start, _, _, on) = esc.sm(3);
        if !on || start != INPUTS {
            return;
        }
        let buf = match self.sync0.as_ref().and_then(|s| s.latched.clone()) {
            Some(latched) => latched,
            None => self.packed_inputs(esc),
        };
        esc.set_memory(INPUTS, &buf);
    }

    /// After a frame: in OP the outputs (RxPDO) from SM2's buffer, if the frame wrote them
    /// (`written`), become the drive's new command (on SYNC0: at the next SYNC0); then the
    /// model steps.
    pub fn outputs(&mut self, esc: &Esc, written: bool, now_ns: u64) {
        let op = esc.al_state() == Some(AlState::Op);
        let (start, len, _, on) = esc.sm(2);
        if op && written && on && start == OUTPUTS {
            let data = esc.memory(OUTPUTS, usize::from(len)).to_vec();
            match self.sync0.as_mut() {
                Some(s) => s.pending = Some(data),
                None => self.take_outputs(&data),
            }
        }
        self.step(now_ns, op);
    }

    /// Between frames: the SYNC0 events up to `now_ns`, and the model runs on.
    pub fn idle(&mut self, esc: &Esc, now_ns: u64) {
        self.catch_up(esc, now_ns);
        self.step(now_ns, esc.al_state() == Some(AlState::Op));
    }

    /// The command in the dictionary, in the model's units.
    fn take_command(&mut self) {
        let s = self.scaling;
        let c = &mut self.command;
        c.seq += 1;
        c.controlword[0] = self.dictionary.u16(obj::CONTROLWORD);
        c.mode[0] = self.dictionary.i8(obj::MODE);
        c.target_position[0] = s.units(self.dictionary.i32(obj::TARGET_POSITION));
        c.target_velocity[0] = s.units(self.dictionary.i32(obj::TARGET_VELOCITY));
        c.target_torque[0] = s.effort(self.dictionary.i16(obj::TARGET_TORQUE));
        c.velocity_offset[0] = s.units(self.dictionary.i32(obj::VELOCITY_OFFSET));
        c.torque_offset[0] = s.effort(self.dictionary.i16(obj::TORQUE_OFFSET));
    }

    /// Runs the model up to `now_ns` (with the newest command if it has not taken it yet)
    /// and puts its feedback in the dictionary. Outside OP (the master left it, or the
    /// SyncManager watchdog took the drive out of it) the drive does what 0x6007 option 3
    /// asks on a lost connection: a powered axis quick-stops along its ramp and is left
    /// without power; an unpowered one stays so (Disable voltage).
    pub fn step(&mut self, now_ns: u64, op: bool) {
        if !op {
            let stopping = matches!(
                self.machine.drives()[0].state(),
                State::OperationEnabled | State::QuickStopActive
            );
            let controlword = if stopping { cw::QUICK_STOP_CMD } else { 0 };
            if self.command.controlword[0] != controlword {
                self.command.controlword[0] = controlword;
                self.command.seq += 1;
            }
        }
        let fb = self.machine.cycle(
            now_ns,
            Some(&self.command),
            self.injection.take().as_ref(),
            &mut self.events,
        );
        self.events.clear();
        let s = self.scaling;
        let d = &mut self.dictionary;
        d.set(obj::STATUSWORD, 0, &fb.statusword[0].to_le_bytes());
        d.set(obj::MODE_DISPLAY, 0, &fb.mode_display[0].to_le_bytes());
        d.set(obj::ERROR_CODE, 0, &fb.error_code[0].to_le_bytes());
        d.set(
            obj::POSITION_ACTUAL,
            0,
            &s.counts(fb.position[0]).to_le_bytes(),
        );
        d.set(
            obj::VELOCITY_ACTUAL,
            0,
            &s.counts(fb.velocity[0]).to_le_bytes(),
        );
        d.set(
            obj::TORQUE_ACTUAL,
            0,
            &s.permille(fb.torque[0]).to_le_bytes(),
        );
        d.set(
            obj::FOLLOWING_ERROR,
            0,
            &s.counts(fb.following_error[0]).to_le_bytes(),
        );
        let error = fb.error_code[0];
        if error != self.reported_error {
            self.reported_error = error;
            if error != 0 {
                self.push_emergency(error);
            }
        }
    }
}
