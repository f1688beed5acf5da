//! A Zenoh session on the line, from a cell's `[network]` section or a control room's line
//! file: the endpoints, discovery, the links' lease, TLS and the links' user/password.
//! Zenoh's shared-memory transport is not built in: what crosses between hosts crosses the
//! network, and a cell's shared memory stays its own.

use cell_config::network::{Login, Mode, NetworkSettings, Tls};
use std::path::Path;
use zenoh::Wait;

/// How to join the line.
#[derive(Clone, Copy, Debug)]
pub struct Link<'a> {
    /// Peer or client.
    pub mode: Mode,
    /// Endpoints to listen on.
    pub listen: &'a [String],
    /// Endpoints to connect to.
    pub connect: &'a [String],
    /// UDP multicast discovery.
    pub multicast: bool,
    /// A silent link is gone after this (s).
    pub lease_s: f64,
    /// The certificates, for `tls/` endpoints.
    pub tls: Option<&'a Tls>,
    /// The links' user and password.
    pub login: Option<&'a Login>,
}

fn json(v: impl serde::Serialize) -> String {
    serde_json::to_string(&v).unwrap_or_default()
}

fn path(p: &Path) -> String {
    json(p.display().to_string())
}

/// The largest message taken from the line (bytes).
pub const MAX_MESSAGE: usize = 4 << 20;

/// `file` is its owner's alone (mode 600), or why not.
fn private(file: &Path) -> Result<(), String> {
    use std::os::unix::fs::MetadataExt;
    let meta = std::fs::metadata(file).map_err(|e| format!("{}: {e}", file.display()))?;
    if meta.mode() & 0o077 != 0 {
        return Err(format!(
            "{}: others may read it (mode {:o}): chmod 600 it",
            file.display(),
            meta.mode() & 0o777
        ));
    }
    Ok(())
}

/// The first line of `file` (a password), which only its owner may read.
pub fn secret_file(file: &Path) -> Result<String, String> {
    private(file)?;
    let text = std::fs::read_to_string(file).map_err(|e| format!("{}: {e}", file.display()))?;
    let line = text.lines().next().unwrap_or("").trim().to_string();
    if line.is_empty() {
        return Err(format!("{}: empty", file.display()));
    }
    Ok(line)
}

impl<'a> Link<'a> {
    /// As a cell's `[network]` section says.
    pub fn of(net: &'a NetworkSettings) -> Self {
        Self {
            mode: net.mode,
            listen: &net.listen,
            connect: &net.connect,
            multicast: net.multicast,
            lease_s: net.lease,
            tls: net.tls.as_ref(),
            login: net.login.as_ref(),
        }
    }

    /// Zenoh's configuration.
    pub fn config(&self) -> Result<zenoh::Config, String> {
        let mut c = zenoh::Config::default();
        let mut set = |key: &str, value: String| {
            c.insert_json5(key, &value)
                .map_err(|e| format!("zenoh {key} = {value}: {e}"))
        };
        set("mode", json(self.mode.as_str()))?;
        set("listen/endpoints", json(self.listen))?;
        set("connect/endpoints", json(self.connect))?;
        set("scouting/multicast/enabled", json(self.multicast))?;
        set(
            "transport/link/tx/lease",
            json((self.lease_s * 1e3).round() as u64),
        )?;
        // Keep-alives four per lease (Zenoh's own ratio).
        set("transport/link/tx/keep_alive", json(4))?;
        // Nothing of the line needs more (a program's text is the largest); a peer's larger
        // message is dropped before it is put together.
        set("transport/link/rx/max_message_size", json(MAX_MESSAGE))?;
        if let Some(t) = self.tls {
            // Its owner's alone, as a secret.
            private(&t.private_key)?;
            set("transport/link/tls/root_ca_certificate", path(&t.root_ca))?;
            set(
                "transport/link/tls/listen_certificate",
                path(&t.certificate),
            )?;
            set(
                "transport/link/tls/listen_private_key",
                path(&t.private_key),
            )?;
            set(
                "transport/link/tls/connect_certificate",
                path(&t.certificate),
            )?;
            set(
                "transport/link/tls/connect_private_key",
                path(&t.private_key),
            )?;
            set("transport/link/tls/enable_mtls", json(t.mutual))?;
        }
        if let Some(l) = self.login {
            set("transport/auth/usrpwd/user", json(&l.user))?;
            set(
                "transport/auth/usrpwd/password",
                json(secret_file(&l.password_file)?),
            )?;
            if let Some(d) = &l.dictionary_file {
                // Zenoh reads it itself; it must be its owner's alone like the password.
                secret_file(d)?;
                set("transport/auth/usrpwd/dictionary_file", path(d))?;
            }
        }
        Ok(c)
    }

    /// A session on the line.
    pub fn open(&self) -> Result<zenoh::Session, String> {
        zenoh::open(self.config()?)
            .wait()
            .map_err(|e| format!("cannot join the line: {e}"))
    }
}
