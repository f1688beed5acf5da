//! The register map: what each Modbus address holds, as data. The server reads it to answer,
//! `docs/fieldbus.md` is generated from it (a test checks the document), and [`Registers`] is
//! one consistent snapshot of the cell built from the samples of one iobridge cycle.
//!
//! Conventions (as most PLCs and HMIs expect them): addresses are 0-based on the wire
//! (`mbpoll -0`, pymodbus); a value of more than one register is big-endian, the high word
//! first; positions are signed thousandths of the axis unit (µm, millidegrees), as in
//! iobridge's image (seed 000), with `i32::MIN` for "no valid measurement".

use shm_schema::drive::{IMAGE_INVALID, milli_units};
use shm_schema::{
    CellConfigV6, DigitalIoV1, EstopV1, FieldbusImageV1, IoDirection, MAX_AXES, ServoStateV3,
    SetpointV2, str_of,
};

/// How a value spreads over registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// One register.
    U16,
    /// Two registers, high word first.
    U32,
    /// Two registers, high word first, two's complement.
    I32,
    /// Four registers, highest word first.
    U64,
}

impl Kind {
    /// Registers it takes.
    pub fn words(self) -> u16 {
        match self {
            Self::U16 => 1,
            Self::U32 | Self::I32 => 2,
            Self::U64 => 4,
        }
    }

    /// Its name in the document.
    pub fn name(self) -> &'static str {
        match self {
            Self::U16 => "u16",
            Self::U32 => "u32",
            Self::I32 => "i32",
            Self::U64 => "u64",
        }
    }
}

/// One value of the map.
#[derive(Clone, Copy, Debug)]
pub struct Field {
    /// First register (0-based), relative to its block.
    pub addr: u16,
    /// Its type.
    pub kind: Kind,
    /// Its name.
    pub name: &'static str,
    /// Its unit, empty for none.
    pub unit: &'static str,
    /// What it is.
    pub meaning: &'static str,
}

const fn f(
    addr: u16,
    kind: Kind,
    name: &'static str,
    unit: &'static str,
    meaning: &'static str,
) -> Field {
    Field {
        addr,
        kind,
        name,
        unit,
        meaning,
    }
}

/// Input registers 0..[`AXIS_BASE`]: the cell as a whole. Reserved registers read 0.
pub const HEADER: &[Field] = &[
    f(
        0,
        Kind::U64,
        "image",
        "",
        "iobridge's image number: +1 per iobridge cycle (the fieldbus cycle counter); it stops when iobridge stops",
    ),
    f(
        4,
        Kind::U64,
        "measured_us",
        "µs",
        "when the positions below were measured by the drives (`CLOCK_MONOTONIC`): seed 000's timestamp of the position",
    ),
    f(
        8,
        Kind::U64,
        "written_us",
        "µs",
        "when iobridge wrote this image (`CLOCK_MONOTONIC`); minus `measured_us`, the age of the positions",
    ),
    f(12, Kind::U16, "axes", "", "axes of the cell (blocks below)"),
    f(
        13,
        Kind::U16,
        "estop",
        "",
        "1 while the cell's e-stop is latched, 0 otherwise",
    ),
    f(
        14,
        Kind::U16,
        "estop_origin",
        "",
        "the latched e-stop's origin: 0 none, 1 device, 2 external (the user, an e-stop input, this fieldbus), 3 host",
    ),
    f(
        15,
        Kind::U16,
        "power",
        "",
        "the drives' power as servo commands it: 0 disabled, 1 enabling, 2 enabled, 3 disabling",
    ),
    f(
        16,
        Kind::U16,
        "servo_status",
        "",
        "servo's status bits (`ServoStateV3.status`): 1 enabled, 2 no setpoint yet, 4 setpoint stale, 8 setpoint jump, 16 fault latched, 64 no feedback, 128 settled, 256 drives initialised",
    ),
    f(
        17,
        Kind::U16,
        "motion",
        "",
        "trajgen's motion: 0 idle, 1 moving, 2 done, 3 fault (aborted, e-stop, refused)",
    ),
    f(
        18,
        Kind::U32,
        "program",
        "",
        "the program's number (+1 per program the supervisor runs), 0 for none",
    ),
    f(20, Kind::U32, "line", "", "the program line being executed"),
    f(
        22,
        Kind::U16,
        "speed_override",
        "%",
        "the live speed override (holding register 1, `supervisor speed`)",
    ),
    f(
        23,
        Kind::U16,
        "hold",
        "",
        "what the program holds for: 0 nothing, 1 a WAIT on an input, 2 a DELAY",
    ),
    f(
        24,
        Kind::U64,
        "io",
        "",
        "the named IO: bit k is entry k of `[[io]]` (the discrete inputs, as one value)",
    ),
    f(28, Kind::U16, "io_count", "", "entries of `[[io]]`"),
    f(
        29,
        Kind::U16,
        "outputs_safe",
        "",
        "1 while iobridge holds the outputs at their safe values (e-stop): coil writes are refused",
    ),
];

/// First register of axis 0's block.
pub const AXIS_BASE: u16 = 32;
/// Registers per axis: axis `k`'s block starts at `AXIS_BASE + k * AXIS_WORDS`.
pub const AXIS_WORDS: u16 = 8;

/// One axis' block of input registers (addresses relative to its start).
pub const AXIS: &[Field] = &[
    f(
        0,
        Kind::I32,
        "position",
        "1/1000 unit",
        "measured position, from iobridge's image (measured at `measured_us`); `i32::MIN`: no valid measurement",
    ),
    f(
        2,
        Kind::I32,
        "command",
        "1/1000 unit",
        "the position servo commanded in the same servo cycle",
    ),
    f(
        4,
        Kind::I32,
        "following_error",
        "1/1000 unit",
        "command minus measured position, servo's",
    ),
    f(
        6,
        Kind::I32,
        "velocity",
        "1/1000 unit/s",
        "measured velocity",
    ),
];

/// Holding registers: the settings a client may write (when `[modbus] writes` is true).
pub const HOLDING: &[Field] = &[
    f(
        0,
        Kind::U16,
        "estop",
        "",
        "reads 1 while the e-stop is latched. Write 1: raises the e-stop (origin external, as `supervisor estop`; the reason names the client). Write 0: accepted, changes nothing (a reset is the operator's: `supervisor reset`). Other values: exception 3",
    ),
    f(
        1,
        Kind::U16,
        "speed_override",
        "%",
        "reads the live speed override. Write 1..=100: the override, as `supervisor speed` (the path speed ramps to it within t_acc); other values: exception 3",
    ),
];

/// Holding register of the e-stop request.
pub const HOLD_ESTOP: u16 = 0;
/// Holding register of the speed override.
pub const HOLD_SPEED: u16 = 1;

/// Registers of input register space used by a cell of `axes` axes.
pub fn input_len(axes: usize) -> u16 {
    AXIS_BASE + AXIS_WORDS * axes.min(MAX_AXES) as u16
}

/// One consistent view of the cell, as the server answers from it.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Registers {
    /// Input registers, `input_len(axes)` of them.
    pub input: Vec<u16>,
    /// The IO values, bit k = entry k.
    pub io: u64,
    /// Bit k set: entry k is an output (a writable coil).
    pub outputs: u64,
    /// Entries of `[[io]]`.
    pub io_count: u16,
    /// iobridge holds the outputs safe (coil writes refused).
    pub outputs_safe: bool,
    /// The e-stop is latched.
    pub estop: bool,
    /// The live speed override (%).
    pub speed_percent: u16,
    /// Whether an image has arrived yet (before: every request is exception 6, busy).
    pub valid: bool,
}

/// The newest sample of each service the map draws on.
#[derive(Clone, Copy, Debug, Default)]
pub struct Samples {
    /// iobridge's image (positions and their time).
    pub image: Option<FieldbusImageV1>,
    /// servo's state of the same cycle as the image (or the newest).
    pub servo: Option<ServoStateV3>,
    /// trajgen's newest setpoint.
    pub setpoint: Option<SetpointV2>,
    /// The latched e-stop's cause, `None` while it is clear.
    pub estop: Option<EstopV1>,
    /// iobridge's IO image.
    pub io: Option<DigitalIoV1>,
}

fn put(regs: &mut [u16], at: u16, kind: Kind, v: u64) {
    let words = kind.words() as usize;
    let at = at as usize;
    for (i, r) in regs[at..at + words].iter_mut().enumerate() {
        *r = (v >> (16 * (words - 1 - i))) as u16;
    }
}

fn field(block: &[Field], name: &str) -> Field {
    *block
        .iter()
        .find(|f| f.name == name)
        .unwrap_or_else(|| unreachable!("no field {name}"))
}

impl Registers {
    /// The registers of `cell` from `s` (set-up and the non-real-time cycle; allocates).
    pub fn build(cell: &CellConfigV6, s: &Samples) -> Self {
        let axes = (cell.axes as usize).min(MAX_AXES);
        let mut input = vec![0u16; input_len(axes) as usize];
        let mut set = |name: &str, v: u64| {
            let fl = field(HEADER, name);
            put(&mut input, fl.addr, fl.kind, v);
        };
        let estop = s.estop.is_some();
        let speed_percent = s.setpoint.map_or(100, |sp| {
            (sp.speed_override * 100.0).round().clamp(0.0, 100.0) as u16
        });
        set("axes", axes as u64);
        set("estop", u64::from(estop));
        set("estop_origin", s.estop.map_or(0, |e| u64::from(e.origin)));
        if let Some(img) = &s.image {
            set("image", img.seq);
            set("measured_us", img.measured_ns / 1000);
            set("written_us", img.written_ns / 1000);
        }
        if let Some(sv) = &s.servo {
            set("power", u64::from(sv.power));
            set("servo_status", u64::from(sv.status & 0xFFFF));
        }
        if let Some(sp) = &s.setpoint {
            set("motion", u64::from(sp.state));
            set("program", u64::from(sp.program_id));
            set("line", u64::from(sp.line));
            set("hold", u64::from(sp.hold));
        }
        set("speed_override", u64::from(speed_percent));
        let io = s.io.map_or(0, |d| d.values);
        set("io", io);
        set("io_count", u64::from(cell.io_count));
        set(
            "outputs_safe",
            u64::from(s.io.is_some_and(|d| d.outputs_safe != 0)),
        );
        for k in 0..axes {
            let base = AXIS_BASE + AXIS_WORDS * k as u16;
            let mut axis = |name: &str, v: i32| {
                let fl = field(AXIS, name);
                put(&mut input, base + fl.addr, fl.kind, u64::from(v as u32));
            };
            let measured = s.image.and_then(|img| img.milli_position(k));
            axis("position", measured.unwrap_or(IMAGE_INVALID));
            if let Some(sv) = &s.servo {
                axis("command", milli_units(sv.cmd_position[k]));
                axis("following_error", milli_units(sv.following_error[k]));
                axis("velocity", milli_units(sv.act_velocity[k]));
            }
        }
        let outputs = cell
            .io()
            .iter()
            .enumerate()
            .filter(|(_, e)| IoDirection::from_wire(e.direction) == Some(IoDirection::Output))
            .fold(0u64, |m, (k, _)| m | 1 << k);
        Self {
            input,
            io,
            outputs,
            io_count: cell.io_count as u16,
            outputs_safe: s.io.is_some_and(|d| d.outputs_safe != 0),
            estop,
            speed_percent,
            valid: s.image.is_some(),
        }
    }
}

/// `docs/fieldbus.md`'s register tables for `cell` (generated; a test compares).
pub fn markdown(cell: &CellConfigV6) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let table = |out: &mut String, fields: &[Field], base: u16| {
        out.push_str(
            "| address | registers | type | name | unit | meaning |\n|---:|---:|---|---|---|---|\n",
        );
        for fl in fields {
            let _ = writeln!(
                out,
                "| {} | {} | {} | `{}` | {} | {} |",
                base + fl.addr,
                fl.kind.words(),
                fl.kind.name(),
                fl.name,
                fl.unit,
                fl.meaning
            );
        }
    };
    out.push_str("### Input registers (function 4): the cell\n\n");
    table(&mut out, HEADER, 0);
    let _ = writeln!(
        out,
        "\nRegisters {}..{} are reserved and read 0.\n",
        HEADER.last().map_or(0, |f| f.addr + f.kind.words()),
        AXIS_BASE - 1
    );
    let _ = writeln!(
        out,
        "### Input registers (function 4): one block of {AXIS_WORDS} per axis\n\nAxis k's block starts at {AXIS_BASE} + {AXIS_WORDS}·k. Offsets in the block:\n"
    );
    table(&mut out, AXIS, 0);
    out.push_str("\nIn this cell (the default configuration):\n\n| axis | unit | position | command | following error | velocity |\n|---|---|---:|---:|---:|---:|\n");
    for (k, a) in cell.axes().iter().enumerate() {
        let base = AXIS_BASE + AXIS_WORDS * k as u16;
        let _ = writeln!(
            out,
            "| {k} `{}` | {} | {} | {} | {} | {} |",
            str_of(&a.name),
            str_of(&a.unit),
            base,
            base + 2,
            base + 4,
            base + 6
        );
    }
    let _ = writeln!(
        out,
        "\nA read past register {} (the last axis' block) is exception 2.\n",
        input_len(cell.axes as usize) - 1
    );
    out.push_str("### Discrete inputs (function 2) and coils (functions 1, 5, 15): the named IO\n\nAddress k is entry k of `[[io]]`, in the order of the configuration. Discrete inputs read every entry; coils read every entry too and take writes to outputs only.\n\n| address | name | direction | coil write |\n|---:|---|---|---|\n");
    for (k, e) in cell.io().iter().enumerate() {
        let output = IoDirection::from_wire(e.direction) == Some(IoDirection::Output);
        let _ = writeln!(
            out,
            "| {k} | `{}` | {} | {} |",
            str_of(&e.name),
            if output { "output" } else { "input" },
            if output {
                "requests the output, as `OUT` and `supervisor io` do"
            } else {
                "exception 2"
            }
        );
    }
    out.push_str(
        "\n### Holding registers (functions 3, 6, 16): the settings a client may write\n\n",
    );
    table(&mut out, HOLDING, 0);
    out.push('\n');
    out
}
