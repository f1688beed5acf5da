//! The cell's EtherCAT MainDevice: the drives' process of a cell whose drives are on a bus
//! (`[ethercat]`, `docs/ethercat.md`), in `machine-sim`'s place behind the same two services
//! (`DriveCommandV2` down, `DriveFeedbackV2` up): servo, trajgen and iobridge do not know
//! whether the drives are simulated or real.
//!
//! - [`bringup`]: before the cycle (and again when the bus came back), ethercrab scans the
//!   bus, the line is compared with the configuration, the drives are mapped by SDO,
//!   Distributed Clocks set up for the SubDevices on SYNC0 ([`bringup::Dc`]) and the bus is
//!   taken to SAFE-OP, every CoE emergency kept out of ethercrab's way;
//! - [`frame`]: the cycle's one frame (LRW over the process image, the reference clock's time
//!   written and handed on, the AL status of each SubDevice, the status of each send mailbox,
//!   a full one's content, and the request for OP until every SubDevice is there), built
//!   once: the bus reaches OP with the cycle running, never before it;
//! - [`Drives`]: units both ways (counts, counts/s, thousandths of the rated torque), the
//!   controlword and mode passed through from servo (servo is the master of the CiA 402 state
//!   machine), and what the bus does by itself when servo goes silent: a quick stop, never a
//!   step up.

pub mod bringup;
pub mod frame;

use cia402::pdo::{RxPdo, Scaling, TxPdo};
use cia402::{State, error_code};
use frame::CyclicFrame;
use shm_schema::event::code;
use shm_schema::{
    DriveCommandV2, DriveFeedbackV2, EthercatConfigV1, EventQueue, EventV1, IoDirection, MAX_AXES,
    MAX_IO,
};

/// The controlword the bus sends by itself when servo has gone silent: Quick stop (bits 1 set,
/// 2 clear, 7 clear): a powered drive ramps down by its quick stop and ends without power; an
/// unpowered one stays so.
pub const QUICK_STOP: u16 = 0x0002;

/// One drive on the bus.
#[derive(Clone, Copy, Debug)]
struct Drive {
    /// Its position on the line.
    position: usize,
    /// The axis it moves.
    axis: usize,
    scaling: Scaling,
    /// Its configured mode (sent until servo's first command).
    mode: i8,
    /// The state its last statusword said, for the transition events.
    state: Option<State>,
    error_code: u16,
    /// Its last position, counts (the target while no command says otherwise).
    actual: i32,
}

/// The drives of the bus and their axes.
#[derive(Clone, Debug)]
pub struct Drives {
    drives: [Option<Drive>; MAX_AXES],
    count: usize,
    axes: usize,
    names: [[u8; 16]; MAX_AXES],
    last_command_seq: u64,
}

impl Drives {
    /// The drives of `bus` for a cell of `axes` axes whose modes are `modes`.
    pub fn new(bus: &EthercatConfigV1, axes: usize, modes: &[i8]) -> Self {
        let mut d = Self {
            drives: [None; MAX_AXES],
            count: 0,
            axes: axes.min(MAX_AXES),
            names: [[0; 16]; MAX_AXES],
            last_command_seq: 0,
        };
        for (k, s) in bus.subdevices().iter().enumerate() {
            if let Some(a) = s.axis().filter(|&a| a < d.axes) {
                d.drives[d.count] = Some(Drive {
                    position: k,
                    axis: a,
                    scaling: Scaling {
                        counts_per_unit: s.counts_per_unit,
                        rated_effort: s.rated_effort,
                    },
                    mode: modes.get(a).copied().unwrap_or(8),
                    state: None,
                    error_code: 0,
                    actual: 0,
                });
                d.names[d.count] = s.name;
                d.count += 1;
            }
        }
        d
    }

    /// The outputs of every drive for `command` (`None`: no command yet, Disable voltage;
    /// `silent`: servo has stopped commanding, Quick stop), written into `frame`.
    /// A target that is not finite holds the drive where it is.
    ///
    /// # Real-time
    /// Arithmetic and copies only.
    pub fn write(
        &mut self,
        command: Option<&DriveCommandV2>,
        silent: bool,
        frame: &mut CyclicFrame,
    ) {
        for d in self.drives[..self.count].iter().flatten() {
            let a = d.axis;
            let rx = match command.filter(|_| !silent) {
                Some(c) => {
                    let s = d.scaling;
                    let hold = |v: f64| if v.is_finite() { s.counts(v) } else { d.actual };
                    RxPdo {
                        controlword: c.controlword[a],
                        mode: c.mode[a],
                        target_position: hold(c.target_position[a]),
                        target_velocity: s.counts(c.target_velocity[a]),
                        target_torque: s.permille(c.target_torque[a]),
                        velocity_offset: s.counts(c.velocity_offset[a]),
                        torque_offset: s.permille(c.torque_offset[a]),
                    }
                }
                None => RxPdo {
                    controlword: if silent { QUICK_STOP } else { 0 },
                    mode: d.mode,
                    target_position: d.actual,
                    ..RxPdo::default()
                },
            };
            rx.write(frame.outputs_mut(d.position));
        }
        if let Some(c) = command {
            self.last_command_seq = c.seq;
        }
    }

    /// The feedback of the inputs in `frame`'s last reply; `valid` false (a SubDevice did not
    /// take its data) makes every position, velocity and torque NaN. Queues an event for each
    /// drive's change of state and each new fault.
    ///
    /// # Real-time
    /// Arithmetic and copies only.
    pub fn read(
        &mut self,
        stamp_ns: u64,
        seq: u64,
        valid: bool,
        frame: &CyclicFrame,
        events: &mut EventQueue,
    ) -> DriveFeedbackV2 {
        let mut fb = DriveFeedbackV2 {
            seq,
            stamp_ns,
            command_seq: self.last_command_seq,
            axes: self.axes as u32,
            ..DriveFeedbackV2::default()
        };
        for k in 0..self.count {
            let name = self.names[k];
            let Some(d) = self.drives[k].as_mut() else {
                continue;
            };
            let a = d.axis;
            let tx = TxPdo::read(frame.inputs(d.position)).filter(|_| valid);
            let Some(tx) = tx else {
                fb.position[a] = f64::NAN;
                fb.velocity[a] = f64::NAN;
                fb.torque[a] = f64::NAN;
                fb.following_error[a] = f64::NAN;
                continue;
            };
            let s = d.scaling;
            d.actual = tx.position;
            fb.statusword[a] = tx.statusword;
            fb.mode_display[a] = tx.mode_display;
            fb.error_code[a] = tx.error_code;
            fb.position[a] = s.units(tx.position);
            fb.velocity[a] = s.units(tx.velocity);
            fb.torque[a] = s.effort(tx.torque);
            fb.following_error[a] = s.units(tx.following_error);
            let state = State::from_statusword(tx.statusword);
            let axis_name = shm_schema::str_of(&name);
            if state != d.state {
                d.state = state;
                events.push(EventV1::new(
                    stamp_ns,
                    code::DRIVE_TRANSITION,
                    a as i32,
                    0.0,
                    0.0,
                    &[
                        axis_name,
                        ": ",
                        state.map_or("statusword not a state", State::name),
                    ],
                ));
            }
            if tx.error_code != d.error_code {
                d.error_code = tx.error_code;
                if tx.error_code != 0 {
                    events.push(EventV1::new(
                        stamp_ns,
                        code::DRIVE_FAULT,
                        a as i32,
                        f64::from(tx.error_code),
                        0.0,
                        &[axis_name, ": ", error_code::name(tx.error_code)],
                    ));
                }
            }
        }
        fb
    }

    /// Forgets what the drives said (the bus was brought up again): the next read tells each
    /// drive's state and fault afresh.
    pub fn forget(&mut self) {
        for d in self.drives[..self.count].iter_mut().flatten() {
            d.state = None;
            d.error_code = 0;
        }
    }

    /// Whether any drive's power stage may be on (its last state says so, or is unknown).
    pub fn powered(&self) -> bool {
        self.drives[..self.count].iter().flatten().any(|d| {
            d.state.is_none_or(|s| {
                matches!(
                    s,
                    State::OperationEnabled | State::QuickStopActive | State::FaultReactionActive
                )
            })
        })
    }
}

/// The cell's `[[io]]` entries that are bits of IO terminals on the bus: the inputs read from
/// the terminals' inputs and reported to iobridge as a field device does, the outputs written
/// from iobridge's IO image. iobridge keeps owning the named IO (its safe values, the e-stop
/// circuit); the bus carries the bits.
#[derive(Clone, Copy, Debug)]
pub struct BusIo {
    /// (entry, position, bit) per input entry, then per output entry.
    inputs: [(u8, u8, u16); MAX_IO],
    input_count: usize,
    outputs: [(u8, u8, u16); MAX_IO],
    output_count: usize,
    /// Bits of the input entries.
    mask: u64,
}

impl BusIo {
    /// The entries of `bus` against the cell's IO table `io` and the process image `layout`:
    /// each bit must lie in its SubDevice's inputs (an input entry) or outputs (an output
    /// entry), else the configuration is refused with the entry, the SubDevice and its size.
    pub fn new(
        bus: &EthercatConfigV1,
        io: &[shm_schema::IoConfigV1],
        layout: &frame::Layout,
    ) -> Result<Self, String> {
        let mut m = Self {
            inputs: [(0, 0, 0); MAX_IO],
            input_count: 0,
            outputs: [(0, 0, 0); MAX_IO],
            output_count: 0,
            mask: 0,
        };
        for e in bus.ios() {
            let entry = usize::from(e.entry);
            let position = usize::from(e.position);
            let Some(cfg) = io.get(entry) else {
                return Err(format!("io entry {entry} is not in the cell's IO table"));
            };
            let name = shm_schema::str_of(&cfg.name);
            let sd = bus.subdevices().get(position).map_or("?", |s| s.name());
            let input = IoDirection::from_wire(cfg.direction) == Some(IoDirection::Input);
            let slot = layout
                .slots
                .get(position)
                .filter(|_| position < layout.count);
            let bytes = slot.map_or(0, |s| if input { s.inputs.1 } else { s.outputs.1 });
            if usize::from(e.bit) >= 8 * usize::from(bytes) {
                return Err(format!(
                    "io {name:?}: bit {} of position {position} ({sd}) does not exist: its {} are {} bits",
                    e.bit,
                    if input { "inputs" } else { "outputs" },
                    8 * bytes
                ));
            }
            let at = (entry as u8, position as u8, e.bit);
            if input {
                m.inputs[m.input_count] = at;
                m.input_count += 1;
                m.mask |= 1 << entry;
            } else {
                m.outputs[m.output_count] = at;
                m.output_count += 1;
            }
        }
        Ok(m)
    }

    /// True when the bus carries no IO.
    pub fn is_empty(&self) -> bool {
        self.input_count + self.output_count == 0
    }

    /// The bits of the input entries and their values in `frame`'s last reply.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn read(&self, frame: &CyclicFrame) -> (u64, u64) {
        let mut values = 0;
        for &(entry, position, bit) in &self.inputs[..self.input_count] {
            let bytes = frame.inputs(usize::from(position));
            let byte = bytes.get(usize::from(bit / 8)).copied().unwrap_or(0);
            if byte & (1 << (bit % 8)) != 0 {
                values |= 1 << entry;
            }
        }
        (self.mask, values)
    }

    /// Writes the output entries of `values` (bit `k`: entry `k`) into `frame`.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn write(&self, values: u64, frame: &mut CyclicFrame) {
        for &(entry, position, bit) in &self.outputs[..self.output_count] {
            let bytes = frame.outputs_mut(usize::from(position));
            if let Some(byte) = bytes.get_mut(usize::from(bit / 8)) {
                if values & (1 << entry) != 0 {
                    *byte |= 1 << (bit % 8);
                } else {
                    *byte &= !(1 << (bit % 8));
                }
            }
        }
    }
}
