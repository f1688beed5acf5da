//! `[ethercat]`: the cell's EtherCAT bus (`docs/ethercat.md`). The bus process (the drives'
//! entry of the process table runs `ethercat-bus`) owns `interface`, finds the SubDevices of
//! `[[ethercat.subdevice]]` in that order on the wire before anything is enabled, and moves
//! each axis through the drive that names it.

use crate::axis::Axis;
use crate::io::Io;
use crate::problem::Seg;
use serde::Deserialize;
use serde_inline_default::serde_inline_default;
use shm_schema::ethercat::{INTERFACE_LEN, MAX_SUBDEVICES, subdevice_flags};
use shm_schema::{EthercatConfigV1, EthercatIoV1, EthercatSubDeviceV1, MAX_IO, fixed_str};

/// `[ethercat]`.
#[serde_inline_default]
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EthercatSettings {
    /// The network interface the bus runs on (the NIC the SubDevices are cabled to).
    pub interface: String,
    /// The process data watchdog written into every SubDevice (s, 0 leaves each its own;
    /// 0.0001..=6.5535 in steps of 100 µs). Default 0.1: a dead bus process or a pulled cable
    /// takes every output safe within 100 ms.
    #[serde_inline_default(0.1)]
    pub pd_watchdog: f64,
    /// The SubDevices in wire order, the first nearest the MainDevice.
    pub subdevice: Vec<SubDevice>,
}

/// `[[ethercat.subdevice]]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SubDevice {
    /// Its name in events and errors (at most 15 bytes).
    pub name: String,
    /// Vendor ID (ESI `Vendor/Id`).
    pub vendor: u32,
    /// Product code (ESI `Device/Type@ProductCode`).
    pub product: u32,
    /// Revision (ESI `Device/Type@RevisionNo`); any revision when left out.
    pub revision: Option<u32>,
    /// The axis this CiA 402 drive moves; left out for a coupler or an IO terminal.
    pub axis: Option<String>,
    /// A drive's counts (0x6064, 0x607A) per axis unit.
    pub counts_per_unit: Option<f64>,
    /// A drive's rated torque (0x6076) in the axis' effort unit (N, N·m).
    pub rated_torque: Option<f64>,
    /// When it takes its outputs and latches its inputs: on SYNC0 of Distributed Clocks
    /// (`"dc"`, a drive's default) or as the cycle's frame passes (`"frame"`, the default of
    /// other SubDevices).
    pub sync: Option<Sync>,
    /// With `sync = "dc"`: how long after the bus process wakes its SYNC0 comes (s, more than
    /// 0 and less than the drives' period). Default: half the period.
    pub sync0_shift: Option<f64>,
}

/// `sync` of a SubDevice.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Sync {
    /// On SYNC0 of Distributed Clocks, every drives' period.
    Dc,
    /// As the cycle's frame passes (SyncManager-synchronous).
    Frame,
}

impl SubDevice {
    /// Whether it runs on SYNC0: as configured, else if it is a drive.
    pub fn on_sync0(&self) -> bool {
        self.sync.unwrap_or(if self.axis.is_some() {
            Sync::Dc
        } else {
            Sync::Frame
        }) == Sync::Dc
    }
}

impl EthercatSettings {
    /// As the bus process reads it (`axes` resolves each drive's axis to its index, `io` the
    /// entries the bus carries).
    pub fn to_shm(&self, axes: &[Axis], io: &[Io]) -> EthercatConfigV1 {
        let mut c = EthercatConfigV1 {
            interface: fixed_str(&self.interface),
            count: self.subdevice.len().min(MAX_SUBDEVICES) as u32,
            pd_watchdog_ns: (self.pd_watchdog * 1e4).round() as u64 * 100_000,
            ..EthercatConfigV1::default()
        };
        for (slot, s) in c.subdevice.iter_mut().zip(&self.subdevice) {
            *slot = EthercatSubDeviceV1 {
                name: fixed_str(&s.name),
                vendor: s.vendor,
                product: s.product,
                revision: s.revision.unwrap_or(0),
                flags: if s.revision.is_some() {
                    subdevice_flags::CHECK_REVISION
                } else {
                    0
                } | if s.on_sync0() {
                    subdevice_flags::SYNC0
                } else {
                    0
                },
                axis: s
                    .axis
                    .as_ref()
                    .and_then(|a| axes.iter().position(|x| &x.name == a))
                    .map_or(-1, |k| k as i32),
                sync0_shift_ns: s.sync0_shift.map_or(0, |t| {
                    (t * 1e9).round().clamp(1.0, f64::from(u32::MAX)) as u32
                }),
                counts_per_unit: s.counts_per_unit.unwrap_or(0.0),
                rated_effort: s.rated_torque.unwrap_or(0.0),
            };
        }
        let on_bus = io.iter().enumerate().take(MAX_IO).filter_map(|(k, e)| {
            let b = e.ethercat.as_ref()?;
            let position = self.subdevice.iter().position(|s| s.name == b.subdevice)?;
            Some(EthercatIoV1 {
                entry: k as u16,
                position: position as u16,
                bit: b.bit,
                reserved: 0,
            })
        });
        for (slot, m) in c.io.iter_mut().zip(on_bus) {
            *slot = m;
            c.io_count += 1;
        }
        c
    }
}

/// The `[[io]]` entries that name a bit of the bus, in a cell without `[ethercat]`.
pub(super) fn io_without_bus(io: &[Io]) -> Option<(Vec<Seg>, String)> {
    use Seg::{Index as I, Key as K};
    let (k, e) = io.iter().enumerate().find(|(_, e)| e.ethercat.is_some())?;
    Some((
        vec![K("io"), I(k), K("ethercat")],
        format!(
            "io {:?}: ethercat names a bit of the bus, and the cell has no [ethercat]",
            e.name
        ),
    ))
}

/// Everything wrong in `[ethercat]` and in the `[[io]]` entries it carries, each with where
/// it is written.
pub(super) fn validate(
    e: &EthercatSettings,
    axes: &[Axis],
    io: &[Io],
    drives_period: Option<f64>,
) -> Vec<(Vec<Seg>, String)> {
    use Seg::{Index as I, Key as K};
    let mut out = Vec::new();
    let ok_name = |s: &str| {
        !s.is_empty()
            && s.len() < INTERFACE_LEN
            && s.bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"._-@".contains(&b))
    };
    if !ok_name(&e.interface) {
        out.push((
            vec![K("ethercat"), K("interface")],
            format!(
                "ethercat interface = {:?} is not a network interface name (1 to 15 letters, digits, '.', '_', '-', '@')",
                e.interface
            ),
        ));
    }
    if !(e.pd_watchdog == 0.0
        || (e.pd_watchdog.is_finite() && (1e-4..=6.5535).contains(&e.pd_watchdog)))
    {
        out.push((
            vec![K("ethercat"), K("pd_watchdog")],
            format!(
                "ethercat pd_watchdog = {} s must be 0 (each SubDevice's own) or 0.0001..=6.5535 s",
                e.pd_watchdog
            ),
        ));
    }
    if e.subdevice.is_empty() || e.subdevice.len() > MAX_SUBDEVICES {
        out.push((
            vec![K("ethercat"), K("subdevice")],
            format!(
                "ethercat has {} subdevices: 1 to {MAX_SUBDEVICES} are needed, in wire order",
                e.subdevice.len()
            ),
        ));
    }
    let mut moved = vec![None; axes.len()];
    for (k, s) in e.subdevice.iter().enumerate() {
        let at = |key: &'static str| vec![K("ethercat"), K("subdevice"), I(k), K(key)];
        let what = format!("ethercat subdevice {} ({:?})", k, s.name);
        if s.name.is_empty() || s.name.len() >= 16 {
            out.push((at("name"), format!("{what}: name must be 1 to 15 bytes")));
        }
        if let Some(shift) = s.sync0_shift {
            if !s.on_sync0() {
                out.push((
                    at("sync0_shift"),
                    format!("{what}: sync0_shift is for a SubDevice on SYNC0 (sync = \"dc\")"),
                ));
            } else if let Some(period) = drives_period
                && !(shift.is_finite() && shift > 0.0 && shift < period)
            {
                out.push((
                    at("sync0_shift"),
                    format!(
                        "{what}: sync0_shift = {shift} s must be more than 0 and less than the drives' period ({period} s)"
                    ),
                ));
            }
        }
        let Some(axis) = &s.axis else {
            for (key, v) in [
                ("counts_per_unit", s.counts_per_unit),
                ("rated_torque", s.rated_torque),
            ] {
                if v.is_some() {
                    out.push((
                        at(key),
                        format!("{what}: {key} is for a drive (a subdevice with an axis)"),
                    ));
                }
            }
            continue;
        };
        match axes.iter().position(|a| &a.name == axis) {
            None => out.push((
                at("axis"),
                format!(
                    "{what}: axis {axis:?} is not an axis of the cell ({})",
                    axes.iter()
                        .map(|a| a.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
            Some(a) => {
                if let Some(first) = moved[a] {
                    out.push((
                        at("axis"),
                        format!("{what}: axis {axis:?} is already moved by subdevice {first}"),
                    ));
                } else {
                    moved[a] = Some(k);
                }
            }
        }
        for (key, v) in [
            ("counts_per_unit", s.counts_per_unit),
            ("rated_torque", s.rated_torque),
        ] {
            match v {
                None => out.push((
                    vec![K("ethercat"), K("subdevice"), I(k)],
                    format!("{what}: a drive needs {key}"),
                )),
                Some(v) if !(v.is_finite() && v > 0.0) => {
                    out.push((at(key), format!("{what}: {key} = {v} must be positive")));
                }
                Some(_) => {}
            }
        }
    }
    let mut bits = std::collections::HashMap::new();
    for (k, entry) in io.iter().enumerate() {
        let Some(b) = &entry.ethercat else { continue };
        let at = |key: &'static str| vec![K("io"), I(k), K("ethercat"), K(key)];
        let what = format!("io {:?}", entry.name);
        match e.subdevice.iter().position(|s| s.name == b.subdevice) {
            None => out.push((
                at("subdevice"),
                format!(
                    "{what}: subdevice {:?} is not in [[ethercat.subdevice]] ({})",
                    b.subdevice,
                    e.subdevice
                        .iter()
                        .map(|s| s.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )),
            Some(p) if e.subdevice[p].axis.is_some() => out.push((
                at("subdevice"),
                format!(
                    "{what}: subdevice {:?} is a drive (it moves an axis); IO entries sit on IO terminals",
                    b.subdevice
                ),
            )),
            Some(p) => {
                // The bit's range is the SubDevice's process data, known once the bus is up:
                // the bus process checks it before anything is enabled.
                let key = (p, b.bit, std::mem::discriminant(&entry.direction));
                if let Some(first) = bits.insert(key, k) {
                    out.push((
                        at("bit"),
                        format!(
                            "{what}: bit {} of {:?} already carries io {:?}",
                            b.bit, b.subdevice, io[first].name
                        ),
                    ));
                }
            }
        }
        if b.bit >= 2048 {
            out.push((
                at("bit"),
                format!(
                    "{what}: bit {} is beyond any SubDevice's process data",
                    b.bit
                ),
            ));
        }
    }
    if !e.subdevice.is_empty() {
        for (a, m) in axes.iter().zip(&moved) {
            if m.is_none() {
                out.push((
                    vec![K("ethercat"), K("subdevice")],
                    format!(
                        "axis {:?} is moved by no drive of [[ethercat.subdevice]] (each axis needs one)",
                        a.name
                    ),
                ));
            }
        }
    }
    out
}
