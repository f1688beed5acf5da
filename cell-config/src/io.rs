//! `[[io]]`: the cell's named digital IO (docs/io.md). Entry `k` is bit `k` of the IO image
//! iobridge publishes (`shm_schema::io`).

use crate::problem::Seg;
use serde::Deserialize;
use shm_schema::{IoConfigV1, IoDirection, MAX_IO, SafeValue, fixed_str, io::IO_NAME_LEN};

/// `direction`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Direction {
    /// Read from the field.
    Input,
    /// Written to the field.
    Output,
}

/// `safe`: 0, 1 or "hold".
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Safe {
    /// 0 or 1.
    Value(i64),
    /// "hold".
    Word(String),
}

/// One `[[io]]` entry.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Io {
    /// Its name in programs (`OUT(gripper, 1)`) and tools: a letter, then letters, digits
    /// and `_`, at most 23 bytes.
    pub name: String,
    /// `"input"` or `"output"`.
    pub direction: Direction,
    /// Outputs: the value an e-stop sets, 0 (default), 1 or `"hold"` (keep it).
    #[serde(default)]
    pub safe: Option<Safe>,
    /// Inputs: an e-stop circuit, normally closed (1 closed; 0 raises the e-stop).
    #[serde(default)]
    pub estop: bool,
    /// Inputs: the value the simulated field gives until a field device drives it (default 1
    /// for an e-stop input, 0 otherwise).
    #[serde(default)]
    pub sim: Option<i64>,
    /// Inputs: the output this input follows in the simulated field (a gripper's position
    /// sensor), after `switch_time`.
    #[serde(default)]
    pub follows: Option<String>,
    /// Inputs that follow an output: the simulated device's switching time (s), 0..=10.
    #[serde(default)]
    pub switch_time: Option<f64>,
    /// The bit of an IO terminal on the EtherCAT bus that carries it (`[ethercat]`); left out,
    /// the entry is the simulated field's or another field device's.
    #[serde(default)]
    pub ethercat: Option<OnBus>,
}

/// Where an `[[io]]` entry sits on the bus: `ethercat = { subdevice = "di", bit = 0 }`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnBus {
    /// The `[[ethercat.subdevice]]` (by name) whose inputs (an input entry) or outputs (an
    /// output entry) hold the bit.
    pub subdevice: String,
    /// The bit of its process data, 0 the lowest of its first byte.
    pub bit: u16,
}

impl Io {
    /// The value an e-stop gives this output.
    pub fn safe_value(&self) -> Option<SafeValue> {
        match &self.safe {
            None | Some(Safe::Value(0)) => Some(SafeValue::Off),
            Some(Safe::Value(1)) => Some(SafeValue::On),
            Some(Safe::Word(w)) if w == "hold" => Some(SafeValue::Hold),
            Some(_) => None,
        }
    }

    /// The simulated field's value of this input.
    pub fn sim_value(&self) -> i64 {
        self.sim.unwrap_or(i64::from(self.estop))
    }
}

/// At most 40 characters of `s`, marked when cut (a name in an error is quoted, not pasted).
fn cut(s: &str) -> String {
    match s.char_indices().nth(40) {
        Some((at, _)) => format!("{}…", &s[..at]),
        None => s.to_string(),
    }
}

/// Checks the IO table: names, directions and the keys each direction takes.
pub(super) fn validate(io: &[Io]) -> Option<(Vec<Seg>, String)> {
    use Seg::{Index as Idx, Key as K};
    if io.len() > MAX_IO {
        return Some((
            vec![K("io")],
            format!("the cell has {} IO entries; at most {MAX_IO}", io.len()),
        ));
    }
    for (k, e) in io.iter().enumerate() {
        let at = |key: &'static str| vec![K("io"), Idx(k), K(key)];
        let name = &e.name;
        let word = name.len() < IO_NAME_LEN
            && name.starts_with(|c: char| c.is_ascii_alphabetic())
            && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !word {
            return Some((
                at("name"),
                format!(
                    "IO name {:?}: a letter, then letters, digits and '_', at most {} bytes",
                    cut(name),
                    IO_NAME_LEN - 1
                ),
            ));
        }
        if io[..k].iter().any(|o| o.name == *name) {
            return Some((at("name"), format!("IO name {name:?} is used twice")));
        }
        let only_inputs = [
            ("estop", e.estop),
            ("sim", e.sim.is_some()),
            ("follows", e.follows.is_some()),
            ("switch_time", e.switch_time.is_some()),
        ];
        match e.direction {
            Direction::Output => {
                if let Some((key, _)) = only_inputs.iter().find(|(_, set)| *set) {
                    return Some((
                        at(key),
                        format!("IO {name}: `{key}` is for inputs; {name} is an output"),
                    ));
                }
                if e.safe_value().is_none() {
                    return Some((
                        at("safe"),
                        format!("IO {name}: safe must be 0, 1 or \"hold\""),
                    ));
                }
            }
            Direction::Input => {
                if e.safe.is_some() {
                    return Some((
                        at("safe"),
                        format!("IO {name}: `safe` is for outputs; {name} is an input"),
                    ));
                }
                if !matches!(e.sim, None | Some(0 | 1)) {
                    return Some((at("sim"), format!("IO {name}: sim must be 0 or 1")));
                }
                if e.estop && e.follows.is_some() {
                    return Some((
                        at("follows"),
                        format!("IO {name}: an e-stop input follows no output"),
                    ));
                }
                if let Some(f) = &e.follows {
                    let target = io.iter().find(|o| o.name == *f);
                    if target.is_none_or(|o| o.direction != Direction::Output) {
                        return Some((
                            at("follows"),
                            format!("IO {name}: follows {f:?}, which is not an output of `[[io]]`"),
                        ));
                    }
                }
                match (e.follows.is_some(), e.switch_time) {
                    (true, Some(t)) if !(t.is_finite() && (0.0..=10.0).contains(&t)) => {
                        return Some((
                            at("switch_time"),
                            format!("IO {name}: switch_time = {t} s must be 0..=10"),
                        ));
                    }
                    (false, Some(_)) => {
                        return Some((
                            at("switch_time"),
                            format!("IO {name}: switch_time needs `follows`"),
                        ));
                    }
                    _ => {}
                }
            }
        }
    }
    None
}

/// The IO table as the cell configuration carries it.
pub(super) fn to_shm(io: &[Io]) -> [IoConfigV1; MAX_IO] {
    let mut out = [IoConfigV1::default(); MAX_IO];
    for (slot, e) in out.iter_mut().zip(io) {
        *slot = IoConfigV1 {
            name: fixed_str(&e.name),
            direction: match e.direction {
                Direction::Input => IoDirection::Input,
                Direction::Output => IoDirection::Output,
            } as u32,
            safe: e.safe_value().unwrap_or(SafeValue::Off) as u32,
            estop: u32::from(e.estop),
            sim: u32::from(e.sim_value() != 0),
            follows: e
                .follows
                .as_ref()
                .and_then(|f| io.iter().position(|o| o.name == *f))
                .map_or(-1, |k| k as i32),
            reserved: 0,
            switch_time_ns: (e.switch_time.unwrap_or(0.0) * 1e9) as u64,
        };
    }
    out
}
