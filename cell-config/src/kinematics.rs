//! `[kinematics]`: which kinematics the cell has, its parameters, and the Cartesian speed
//! limits of `MOVE` (`docs/kinematics.md`). Without the section the cell is a gantry: its
//! Cartesian coordinates are its axes.

use crate::axis::Axis;
use crate::problem::Seg;
use kinematics::{JointKind, Kinematics, MAX_COORDS};
use serde::Deserialize;
use shm_schema::config::MAX_KIN_PARAMS;
use shm_schema::{KinParamV1, KinematicsConfigV1, MAX_AXES, fixed_str};
use std::collections::BTreeMap;

/// `[kinematics]`; a key not given is its [`Default`]'s.
#[derive(Clone, Debug, Deserialize)]
#[serde(default)]
pub struct KinematicsSettings {
    /// Its name in the registry: `"gantry"` (the default), `"scara"`, `"five-bar"`, or a
    /// user's own.
    #[serde(rename = "type")]
    pub kind: String,
    /// Largest velocity per Cartesian coordinate (unit/s), for `MOVE`'s segment times.
    /// Required unless the cell is a gantry (whose coordinates have their axes' vmax).
    pub vmax: Option<Vec<f64>>,
    /// The kinematics' own parameters (`l1 = 200.0`), numbers.
    #[serde(flatten)]
    pub params: BTreeMap<String, toml::Value>,
}

impl Default for KinematicsSettings {
    fn default() -> Self {
        Self {
            kind: "gantry".into(),
            vmax: None,
            params: BTreeMap::new(),
        }
    }
}

impl KinematicsSettings {
    /// True for the gantry: the Cartesian coordinates are the axes.
    pub fn is_gantry(&self) -> bool {
        self.kind == "gantry"
    }

    /// The parameters as numbers (the first one that is not, with its key).
    fn numbers(&self) -> Result<Vec<(&str, f64)>, (String, String)> {
        self.params
            .iter()
            .map(|(k, v)| match v {
                toml::Value::Float(f) if f.is_finite() => Ok((k.as_str(), *f)),
                toml::Value::Integer(i) => Ok((k.as_str(), *i as f64)),
                other => Err((
                    k.clone(),
                    format!("kinematics parameter {k} = {other} must be a finite number"),
                )),
            })
            .collect()
    }

    /// The kinematics, built from the registry (set-up; allocates).
    pub fn build(&self) -> Result<Option<kinematics::Boxed>, String> {
        if self.is_gantry() {
            return Ok(None);
        }
        let params = self.numbers().map_err(|(_, m)| m)?;
        kinematics::build(&self.kind, &kinematics::Params(&params))
            .map(Some)
            .map_err(|e| e.to_string())
    }

    /// The Cartesian coordinates a program's `MOVE` names: (name, unit).
    pub fn coords(&self, axes: &[Axis]) -> Vec<(String, String)> {
        match self.build() {
            Ok(Some(k)) => k
                .coords()
                .iter()
                .map(|c| (c.name.to_string(), c.unit.symbol().to_string()))
                .collect(),
            _ => axes
                .iter()
                .map(|a| (a.name.clone(), a.unit.clone()))
                .collect(),
        }
    }

    /// As the cell configuration carries it.
    pub(super) fn to_shm(&self, axes: &[Axis]) -> KinematicsConfigV1 {
        let mut c = KinematicsConfigV1::default();
        if self.is_gantry() {
            c.type_name = fixed_str("gantry");
            return c;
        }
        c.type_name = fixed_str(&self.kind);
        let numbers = self.numbers().unwrap_or_default();
        for (slot, (k, v)) in c.params.iter_mut().zip(&numbers) {
            *slot = KinParamV1 {
                name: fixed_str(k),
                value: *v,
            };
        }
        c.param_count = numbers.len().min(MAX_KIN_PARAMS) as u32;
        let coords = self.coords(axes);
        c.coords = coords.len() as u32;
        for (slot, v) in c.coord_vmax.iter_mut().zip(self.vmax.iter().flatten()) {
            *slot = *v;
        }
        c
    }
}

/// Checks `[kinematics]` against the axes: a known type with valid parameters, one axis per
/// joint with the joint's unit, and a positive vmax per Cartesian coordinate.
pub(super) fn validate(k: &KinematicsSettings, axes: &[Axis]) -> Option<(Vec<Seg>, String)> {
    use Seg::Key as K;
    let at = |key: &'static str| vec![K("kinematics"), K(key)];
    if k.is_gantry() {
        if !k.params.is_empty() {
            let key = k.params.keys().next().cloned().unwrap_or_default();
            return Some((
                vec![K("kinematics")],
                format!("the gantry has no parameters (found `{key}`)"),
            ));
        }
        if axes.len() > 3 {
            return Some((
                vec![K("axis")],
                format!(
                    "a gantry cell has 1 to 3 axes (x, y, theta); this one has {}: choose a `[kinematics]` type",
                    axes.len()
                ),
            ));
        }
        if k.vmax.is_some() {
            return Some((
                at("vmax"),
                "the gantry's Cartesian speeds are its axes' vmax: `vmax` is for other kinematics"
                    .into(),
            ));
        }
        return None;
    }
    if k.params.len() > MAX_KIN_PARAMS {
        return Some((
            vec![K("kinematics")],
            format!("at most {MAX_KIN_PARAMS} kinematics parameters"),
        ));
    }
    if let Err((_, m)) = k.numbers() {
        return Some((vec![K("kinematics")], m));
    }
    let built = match k.build() {
        Ok(Some(b)) => b,
        Ok(None) => return None,
        Err(m) => return Some((at("type"), m)),
    };
    if built.joints() != axes.len() {
        return Some((
            vec![K("axis")],
            format!(
                "kinematics {} has {} joints; the cell has {} axes (one `[[axis]]` per joint, in order)",
                k.kind,
                built.joints(),
                axes.len()
            ),
        ));
    }
    for (i, a) in axes.iter().enumerate() {
        let j = built.joint(i);
        let unit = match j.kind {
            JointKind::Rotary => "deg",
            JointKind::Linear => "mm",
        };
        if a.unit != unit {
            return Some((
                vec![K("axis")],
                format!(
                    "axis {}: joint {} of {} is {} in {unit}; the axis says {:?}",
                    a.name,
                    i + 1,
                    k.kind,
                    if unit == "deg" { "rotary" } else { "linear" },
                    a.unit
                ),
            ));
        }
    }
    let coords = built.coords().len().min(MAX_COORDS).min(MAX_AXES);
    if k.vmax.is_none() {
        return Some((
            vec![K("kinematics")],
            format!(
                "kinematics {} needs `vmax`, one Cartesian speed limit per coordinate ({})",
                k.kind,
                built
                    .coords()
                    .iter()
                    .map(|c| c.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    }
    vmax_ok(k, coords, &at)
}

fn vmax_ok(
    k: &KinematicsSettings,
    coords: usize,
    at: &dyn Fn(&'static str) -> Vec<Seg>,
) -> Option<(Vec<Seg>, String)> {
    let v = k.vmax.as_ref()?;
    if v.len() != coords {
        return Some((
            at("vmax"),
            format!(
                "vmax has {} values; the kinematics has {coords} Cartesian coordinates",
                v.len()
            ),
        ));
    }
    if let Some(x) = v.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
        return Some((at("vmax"), format!("vmax {x} must be a positive number")));
    }
    None
}
