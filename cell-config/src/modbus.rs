//! `[modbus]`: the cell's Modbus TCP server (`docs/fieldbus.md`). The process that serves it
//! is the `modbus` entry of the process table; this section says where it listens, how many
//! connections it serves at once, when an idle one is closed and whether it takes writes.

use crate::problem::Seg;
use serde::Deserialize;
use shm_schema::config::LISTEN_LEN;
use shm_schema::{ModbusConfigV1, fixed_str};
use std::net::SocketAddr;

/// `[modbus]`: every key may be left out, for its default ([`Default`], where each is written
/// once).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModbusSettings {
    /// `IP:port` to listen on. Default `127.0.0.1:1502` (this machine only); `0.0.0.0:502`
    /// opens it to the network; port 0 takes any free port (announced in `supervisor status`).
    pub listen: String,
    /// Connections served at once, 1..=64. Default 8.
    pub max_connections: u32,
    /// A connection that sends no request for this long is closed (s), 0.1..=86400. Default 60.
    pub idle_timeout: f64,
    /// Whether the writable coils and holding registers take writes. Default true.
    pub writes: bool,
}

impl Default for ModbusSettings {
    fn default() -> Self {
        Self {
            listen: "127.0.0.1:1502".into(),
            max_connections: 8,
            idle_timeout: 60.0,
            writes: true,
        }
    }
}

impl ModbusSettings {
    /// As the serving process reads it.
    pub fn to_shm(&self) -> ModbusConfigV1 {
        ModbusConfigV1 {
            listen: fixed_str(&self.listen),
            max_connections: self.max_connections,
            writes: u32::from(self.writes),
            idle_timeout_ns: (self.idle_timeout * 1e9) as u64,
        }
    }
}

/// The first thing wrong in `[modbus]`, with where it is written.
pub(super) fn validate(m: &ModbusSettings) -> Option<(Vec<Seg>, String)> {
    use Seg::Key as K;
    let at = |k: &'static str| vec![K("modbus"), K(k)];
    if m.listen.len() >= LISTEN_LEN || m.listen.parse::<SocketAddr>().is_err() {
        return Some((
            at("listen"),
            format!(
                "modbus listen = {:?} is not an IP:port address (\"127.0.0.1:1502\", \"0.0.0.0:502\", \"[::1]:1502\")",
                m.listen
            ),
        ));
    }
    if !(1..=64).contains(&m.max_connections) {
        return Some((
            at("max_connections"),
            format!(
                "modbus max_connections = {} must be 1..=64",
                m.max_connections
            ),
        ));
    }
    if !(m.idle_timeout.is_finite() && (0.1..=86400.0).contains(&m.idle_timeout)) {
        return Some((
            at("idle_timeout"),
            format!(
                "modbus idle_timeout = {} s must be 0.1..=86400 s",
                m.idle_timeout
            ),
        ));
    }
    None
}
