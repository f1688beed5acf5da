//! `[network]`: the cell on a line of cells (`docs/network.md`). The section switches the
//! cell's gateway on: the `gateway` entry of the process table, a non-real-time process that
//! shows the cell on Zenoh under `rtc/v1/<name>/` and takes the commands of the line's
//! operators. Without the section nothing of the cell is on the network.
//!
//! Nothing is open by default: the users file is required (every command is signed by one of
//! its users; a viewer may only read), and an endpoint in the clear (`tcp/`) must be allowed
//! in so many words (`plain = true`), else only `tls/` endpoints are taken.

use crate::problem::Seg;
use serde::{Deserialize, Serialize};
use serde_inline_default::serde_inline_default;
use std::fmt;
use std::path::PathBuf;

/// `[network]`.
#[serde_inline_default]
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NetworkSettings {
    /// The cell's name on the line: one key chunk of `rtc/v1/<name>/` ([`CellName`]).
    /// Default: `[cell] name`, lower-cased, other characters as `-`.
    #[serde(default)]
    pub name: Option<CellName>,
    /// Zenoh's mode: `peer` (default; finds and is found by the line's other peers) or
    /// `client` (through a router).
    #[serde(default)]
    pub mode: Mode,
    /// Zenoh endpoints to listen on (`tls/0.0.0.0:7447`). Default none.
    #[serde(default)]
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to (a router, the control room). Default none.
    #[serde(default)]
    pub connect: Vec<String>,
    /// Find the line's peers by UDP multicast on the local network. Default false: the
    /// endpoints above only.
    #[serde(default)]
    pub multicast: bool,
    /// Whether `tcp/` endpoints (in the clear) are allowed. Default false.
    #[serde(default)]
    pub plain: bool,
    /// The line's users, their roles and secrets (TOML, `[[user]] name role secret`; a file
    /// only its owner may read): who may see the cell and who may command it.
    pub users: PathBuf,
    /// The status is published at most this often (s), 0.02..=10. Default 0.2.
    #[serde_inline_default(0.2)]
    pub status_period: f64,
    /// A peer silent this long is gone (s): the lease of Zenoh's links, 1..=60. Default 3.
    #[serde_inline_default(3.0)]
    pub lease: f64,
    /// `[network.tls]`: the certificates for `tls/` endpoints.
    #[serde(default)]
    pub tls: Option<Tls>,
    /// `[network.login]`: Zenoh's user/password authentication of the link.
    #[serde(default)]
    pub login: Option<Login>,
    /// `[network.ros2]`: the cell's joint states for ROS 2 (rmw_zenoh) too.
    #[serde(default)]
    pub ros2: Option<Ros2>,
}

/// `[network.ros2]`: the gateway publishes the cell's joint states as a
/// `sensor_msgs/msg/JointState` on `/<namespace>/joint_states`, the way ROS 2 Jazzy reads it
/// through rmw_zenoh, at the status period. The axes' units must be ROS's (m or rad) or
/// convert to them (mm, deg).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Ros2 {
    /// The ROS domain (`ROS_DOMAIN_ID`), 0..=232. Default 0.
    #[serde(default)]
    pub domain: u32,
    /// The namespace of the cell's topics (a ROS name: letters, digits and `_`, starting with
    /// a letter). Default: the cell's name on the line with `-` as `_`.
    #[serde(default)]
    pub namespace: Option<String>,
}

impl Ros2 {
    /// The largest ROS domain.
    pub const MAX_DOMAIN: u32 = 232;

    /// The namespace of the cell's topics: as given, or from its name on the line.
    pub fn namespace_of(&self, cell: &CellName) -> String {
        match &self.namespace {
            Some(n) => n.clone(),
            None => cell.as_str().replace('-', "_"),
        }
    }
}

/// What is wrong with `n` as a ROS namespace (one token of a ROS name), if anything.
pub fn ros_name_problem(n: &str) -> Option<&'static str> {
    if n.is_empty() {
        Some("it is empty")
    } else if !n.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') {
        Some("it has a character other than a letter, a digit and '_'")
    } else if !n.as_bytes()[0].is_ascii_alphabetic() {
        Some("it does not start with a letter")
    } else if n.contains("__") || n.ends_with('_') {
        Some("it has '__' or ends with '_'")
    } else {
        None
    }
}

/// How many of ROS's units (m, rad) one of the cell's `unit` is, if it converts.
pub fn ros_scale(unit: &str) -> Option<f64> {
    match unit {
        "m" | "rad" => Some(1.0),
        "mm" => Some(1e-3),
        "um" | "µm" => Some(1e-6),
        "deg" => Some(std::f64::consts::PI / 180.0),
        _ => None,
    }
}

/// Zenoh's mode.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// A peer of the line.
    #[default]
    Peer,
    /// A client of a router.
    Client,
}

impl Mode {
    /// As Zenoh's configuration writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Peer => "peer",
            Mode::Client => "client",
        }
    }
}

/// `[network.tls]`.
#[serde_inline_default]
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Tls {
    /// The certificate authority the line's certificates are signed by (PEM).
    pub root_ca: PathBuf,
    /// This cell's certificate (PEM).
    pub certificate: PathBuf,
    /// Its private key (PEM; a file only its owner may read).
    pub private_key: PathBuf,
    /// Peers must show a certificate of the same authority too. Default true.
    #[serde_inline_default(true)]
    pub mutual: bool,
}

/// `[network.login]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Login {
    /// The Zenoh user this cell connects as.
    pub user: String,
    /// A file holding its password (one line; only its owner may read it).
    pub password_file: PathBuf,
    /// The users and passwords this cell accepts on its own endpoints (`user:password` a
    /// line; only its owner may read it). Default: none accepted but its own.
    #[serde(default)]
    pub dictionary_file: Option<PathBuf>,
}

impl NetworkSettings {
    /// The cell's name on the line, from `name` or the cell's own (`[cell] name`).
    pub fn line_name(&self, cell_name: &str) -> Result<CellName, BadName> {
        match &self.name {
            Some(n) => Ok(n.clone()),
            None => {
                let n: String = cell_name
                    .chars()
                    .map(|c| match c.to_ascii_lowercase() {
                        c if c.is_ascii_alphanumeric() || c == '_' => c,
                        _ => '-',
                    })
                    .collect();
                CellName::new(n.trim_matches(|c| c == '-' || c == '_'))
            }
        }
    }
}

/// A cell's name on the line.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Deserialize, Serialize)]
#[serde(try_from = "String", into = "String")]
pub struct CellName(String);

/// Why a name is not a cell's name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BadName {
    /// The name as given.
    pub name: String,
    /// What is wrong with it.
    pub why: &'static str,
}

impl fmt::Display for BadName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:?} is not a cell's name on the line: {} (1 to 32 of a-z, 0-9, '-', '_', starting with a letter or a digit)",
            self.name, self.why
        )
    }
}

impl std::error::Error for BadName {}

impl CellName {
    /// The longest name.
    pub const MAX_LEN: usize = 32;

    /// `name`, checked.
    pub fn new(name: &str) -> Result<Self, BadName> {
        let bad = |why| {
            Err(BadName {
                name: name.into(),
                why,
            })
        };
        if name.is_empty() {
            return bad("it is empty");
        }
        if name.len() > Self::MAX_LEN {
            return bad("it is longer than 32 characters");
        }
        if !name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'_')
        {
            return bad("it has a character other than a-z, 0-9, '-' and '_'");
        }
        if !name.as_bytes()[0].is_ascii_alphanumeric() {
            return bad("it starts with '-' or '_'");
        }
        Ok(Self(name.into()))
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for CellName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl TryFrom<String> for CellName {
    type Error = BadName;
    fn try_from(name: String) -> Result<Self, BadName> {
        Self::new(&name)
    }
}

impl From<CellName> for String {
    fn from(name: CellName) -> String {
        name.0
    }
}

/// What is wrong with endpoint `e` of `key` (`listen`, `connect`), if anything: a `tls/`
/// endpoint without certificates (in table `tls_table`), a `tcp/` one not allowed by `plain`,
/// anything else, or no port. Shared by `[network]` and a control room's line file.
pub fn endpoint_problem(
    key: &str,
    e: &str,
    plain: bool,
    tls: bool,
    tls_table: &str,
) -> Option<String> {
    let (proto, addr) = e.split_once('/').unwrap_or(("", e));
    let problem = match proto {
        "tls" if !tls => Some(format!(
            "{key} {e:?} is a tls/ endpoint: {tls_table} must give its certificates"
        )),
        "tcp" if !plain => Some(format!(
            "{key} {e:?} is in the clear: use tls/, or allow it with plain = true"
        )),
        "tls" | "tcp" => None,
        _ => Some(format!(
            "{key} {e:?} is not an endpoint (\"tls/HOST:PORT\", or \"tcp/HOST:PORT\" with plain = true)"
        )),
    };
    problem.or_else(|| {
        addr.rsplit_once(':')
            .and_then(|(_, p)| p.parse::<u16>().ok())
            .is_none()
            .then(|| format!("{key} {e:?} has no port (\"{proto}/HOST:PORT\")"))
    })
}

/// What is wrong with a link's lease (s), if anything: 1..=60.
pub fn lease_problem(lease: f64) -> Option<String> {
    (!(lease.is_finite() && (1.0..=60.0).contains(&lease)))
        .then(|| format!("lease = {lease} s must be 1..=60 s"))
}

/// Every problem of `[network]`, each at its key; `gateway` says whether the process table
/// has the gateway that serves it; `axes` are the cell's (name, unit).
pub(super) fn validate(
    n: &NetworkSettings,
    cell_name: &str,
    axes: &[(&str, &str)],
    gateway: bool,
) -> Vec<(Vec<Seg>, String)> {
    use Seg::Key as K;
    let at = |k: &'static str| vec![K("network"), K(k)];
    let mut found = Vec::new();
    // A name given is checked as it is parsed.
    if let Err(e) = n.line_name(cell_name) {
        found.push((
            vec![K("network")],
            format!("{e}: [cell] name is no name on the line, give [network] name"),
        ));
    }
    if !gateway {
        found.push((
            vec![K("network")],
            "[network] needs the process that serves it: a [[process]] named \"gateway\" (command = [\"gateway\", \"--instance\", \"{instance}\"], critical = false)".into(),
        ));
    }
    if n.listen.is_empty() && n.connect.is_empty() && !n.multicast {
        found.push((
            vec![K("network")],
            "[network] has no way onto the line: give listen or connect endpoints, or multicast = true".into(),
        ));
    }
    for (key, endpoints) in [("listen", &n.listen), ("connect", &n.connect)] {
        for e in endpoints {
            let problem = endpoint_problem(key, e, n.plain, n.tls.is_some(), "[network.tls]");
            found.extend(problem.map(|p| (at(key), format!("network {p}"))));
        }
    }
    if !(n.status_period.is_finite() && (0.02..=10.0).contains(&n.status_period)) {
        found.push((
            at("status_period"),
            format!(
                "network status_period = {} s must be 0.02..=10 s",
                n.status_period
            ),
        ));
    }
    if let Some(p) = lease_problem(n.lease) {
        found.push((at("lease"), format!("network {p}")));
    }
    if let Some(r) = &n.ros2 {
        let at = |k: &'static str| vec![K("network"), K("ros2"), K(k)];
        if r.domain > Ros2::MAX_DOMAIN {
            found.push((
                at("domain"),
                format!(
                    "network.ros2 domain = {} must be 0..={}",
                    r.domain,
                    Ros2::MAX_DOMAIN
                ),
            ));
        }
        if let Ok(cell) = n.line_name(cell_name) {
            let ns = r.namespace_of(&cell);
            if let Some(why) = ros_name_problem(&ns) {
                found.push((
                    at("namespace"),
                    format!("network.ros2 namespace {ns:?} is no ROS name: {why}"),
                ));
            }
        }
        for (axis, unit) in axes {
            if ros_scale(unit).is_none() {
                found.push((
                    vec![K("network"), K("ros2")],
                    format!(
                        "[network.ros2] needs ROS's units: axis {axis}'s unit {unit:?} is none of m, mm, um, rad, deg"
                    ),
                ));
            }
        }
    }
    found
}
