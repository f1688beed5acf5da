//! The devices behind the ESCs: Beckhoff's EK1100 coupler, EL1008 (8 digital inputs) and
//! EL2008 (8 digital outputs), with the identities and the EEPROM categories of the real
//! terminals' kind (no mailbox: a MainDevice configures them from their SII), and the
//! emulator's CiA 402 drive ([`crate::drive`]).

use crate::drive::Drive;
use crate::esc::{AlState, Esc};
use crate::sii::{Identity, Pdo, PdoEntry, Sii, Sm, SmKind};

/// Beckhoff's vendor id.
pub const BECKHOFF: u32 = 0x0000_0002;

/// A terminal of the line.
#[derive(Clone, Debug)]
pub enum Terminal {
    /// EK1100 EtherCAT coupler: no process data.
    Ek1100,
    /// EL1008: 8 digital inputs; `inputs` is what the field applies (bit k: input k+1).
    El1008 {
        /// The field's levels.
        inputs: u8,
    },
    /// EL2008: 8 digital outputs; `outputs` is what it drives (all off unless OP).
    El2008 {
        /// The driven levels.
        outputs: u8,
    },
    /// A CiA 402 servo drive with its axis.
    Drive(Box<Drive>),
}

/// The physical start of EL1008's input SyncManager.
const EL1008_INPUTS: u16 = 0x1000;
/// The physical start of EL2008's output SyncManager (the ESC's digital output register).
const EL2008_OUTPUTS: u16 = 0x0F00;

impl Terminal {
    /// Its name: the type its EEPROM gives as order number (a drive: its own name).
    pub fn name(&self) -> &str {
        match self {
            Self::Ek1100 => "EK1100",
            Self::El1008 { .. } => "EL1008",
            Self::El2008 { .. } => "EL2008",
            Self::Drive(d) => d.name(),
        }
    }

    /// Its identity.
    pub fn identity(&self) -> Identity {
        let (product, revision) = match self {
            Self::Ek1100 => (0x044C_2C52, 0x0011_0000),
            Self::El1008 { .. } => (0x03F0_3052, 0x0010_0000),
            Self::El2008 { .. } => (0x07D8_3052, 0x0010_0000),
            Self::Drive(d) => return d.identity(),
        };
        Identity {
            vendor: BECKHOFF,
            product,
            revision,
            serial: 0,
        }
    }

    /// Its ESC, with its EEPROM, powered on (INIT).
    pub fn esc(&self) -> Esc {
        if let Self::Drive(d) = self {
            return d.esc();
        }
        let bits = |base: u16, count: u16, pdo: u16, sm: u8| -> Vec<Pdo> {
            (0..count)
                .map(|k| Pdo {
                    index: pdo + k,
                    sm,
                    entries: vec![PdoEntry {
                        index: base + 0x10 * k,
                        subindex: 1,
                        bits: 1,
                        data_type: 1, // BOOL
                    }],
                })
                .collect()
        };
        let (group, description, fmmus, sms, tx, rx) = match self {
            Self::Ek1100 => (
                "SystemBk",
                "EK1100 EtherCAT Coupler (2A E-Bus)",
                vec![],
                vec![],
                vec![],
                vec![],
            ),
            Self::El1008 { .. } => (
                "DigIn",
                "EL1008 8Ch. Dig. Input 24V, 3ms",
                vec![2],
                vec![Sm {
                    start: EL1008_INPUTS,
                    length: 1,
                    control: 0x00,
                    enable: true,
                    kind: SmKind::Inputs,
                }],
                bits(0x6000, 8, 0x1A00, 0),
                vec![],
            ),
            Self::Drive(_) => unreachable!("a drive makes its own ESC"),
            Self::El2008 { .. } => (
                "DigOut",
                "EL2008 8Ch. Dig. Output 24V, 0.5A",
                vec![1],
                vec![Sm {
                    start: EL2008_OUTPUTS,
                    length: 1,
                    control: 0x44,
                    enable: true,
                    kind: SmKind::Outputs,
                }],
                vec![],
                bits(0x7000, 8, 0x1600, 0),
            ),
        };
        let sii = Sii {
            identity: self.identity(),
            alias: 0,
            order: self.name().into(),
            group: group.into(),
            name: description.into(),
            mailbox: None,
            fmmus,
            sms,
            tx_pdos: tx,
            rx_pdos: rx,
        };
        // An EK1100 has Distributed Clocks (the line's reference clock, being the first);
        // the EL1008 and EL2008 have none.
        Esc::new(sii, 8, 8, matches!(self, Self::Ek1100))
    }

    /// Whether the device asked to run on SYNC0 (a drive whose 0x1C32:01 says so).
    pub fn on_sync0(&self) -> bool {
        matches!(self, Self::Drive(d) if d.on_sync0())
    }

    /// The device's mailboxes in answer to a mailbox request in AL state `al`, in order
    /// (only a drive has a mailbox).
    pub fn mailbox(
        &mut self,
        request: &[u8],
        capacity: usize,
        al: Option<AlState>,
    ) -> Vec<Vec<u8>> {
        match self {
            Self::Drive(d) => d.mailbox(request, capacity, al),
            _ => Vec::new(),
        }
    }

    /// The CoE emergencies the device has to send (a drive's).
    pub fn emergencies(&mut self) -> Vec<Vec<u8>> {
        match self {
            Self::Drive(d) => d.emergencies(),
            _ => Vec::new(),
        }
    }

    /// Before a frame at `now_ns`: the device's inputs into its ESC (a drive's as its model
    /// stands at `now_ns`).
    pub fn inputs(&mut self, esc: &mut Esc, now_ns: u64) {
        match self {
            Self::El1008 { inputs } => esc.set_memory(EL1008_INPUTS, &[*inputs]),
            Self::Drive(d) => d.inputs(esc, now_ns),
            _ => {}
        }
    }

    /// After a frame at `now_ns`: the device takes its outputs (a terminal drives them only
    /// in OP; a drive takes a new command when the frame wrote its outputs).
    pub fn outputs(&mut self, esc: &mut Esc, now_ns: u64) {
        let written = esc.take_outputs_written();
        match self {
            Self::El2008 { outputs } => {
                let (_, _, _, enabled) = esc.sm(0);
                *outputs = if esc.al_state() == Some(AlState::Op) && enabled {
                    esc.memory(EL2008_OUTPUTS, 1)[0]
                } else {
                    0
                };
            }
            Self::Drive(d) => d.outputs(esc, written, now_ns),
            _ => {}
        }
    }

    /// Between frames: a drive's model runs on (its watchdog counts the silence).
    pub fn idle(&mut self, esc: &Esc, now_ns: u64) {
        if let Self::Drive(d) = self {
            d.idle(esc, now_ns);
        }
    }
}
