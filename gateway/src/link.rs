//! A Zenoh session on the line, from a cell's `[network]` section or a control room's line
//! file: the endpoints, discovery, the links' lease, TLS and the links' user/password.
//! Zenoh's shared-memory transport is not built in: what crosses between hosts crosses the
//! network, and a cell's shared memory stays its own.

use cell_config::network::{CellName, Login, Mode, NetworkSettings, Tls};
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
    /// Zenoh's access control on this node.
    pub access: Access<'a>,
}

/// Zenoh's access control on a node of the line: what it lets in and out, message by message
/// and key by key, beside the gateway's own judgement of who commands (Zenoh drops what it
/// refuses without a word; the gateway answers why).
#[derive(Clone, Copy, Debug)]
pub enum Access<'a> {
    /// A cell's gateway, `name` on the line: it takes from the line only questions and
    /// subscriptions (a cell reads nobody's publications), and sends publications, answers,
    /// queryables and its presence under `rtc/v1/<name>/` only, and under `also` (its ROS 2
    /// topics).
    Cell {
        /// The cell's name on the line.
        name: &'a CellName,
        /// Key expressions it may publish under besides its own.
        also: &'a [String],
    },
    /// A control room that knows its line's cells: only the cell whose certificate's common
    /// name is `C` may publish, answer or be present under `rtc/v1/C/`; everything else from
    /// the line is dropped (needs TLS: the certificates are the cells' identities).
    Room {
        /// The line's cells, their certificates' common names.
        cells: &'a [CellName],
    },
    /// None: what comes on a key is taken for the key's cell (the links' TLS and passwords
    /// decide who may join).
    Open,
}

/// What asks (questions, subscriptions, presence asked), and what answers or publishes.
const ASKING: [&str; 4] = [
    "declare_subscriber",
    "query",
    "liveliness_query",
    "declare_liveliness_subscriber",
];
const SPEAKING: [&str; 5] = [
    "put",
    "delete",
    "reply",
    "declare_queryable",
    "liveliness_token",
];

impl Access<'_> {
    /// Zenoh's `access_control` section: everything denied but what the rules allow.
    pub fn zenoh(&self) -> Option<serde_json::Value> {
        use serde_json::json;
        let rule = |id: &str, messages: &[&str], flows: &[&str], keys: Vec<String>| json!({"id": id, "messages": messages, "flows": flows, "permission": "allow", "key_exprs": keys});
        let (rules, subjects, policies) = match self {
            Self::Open => return None,
            Self::Cell { name, also } => {
                let mut own = vec![format!("{}/{name}/**", crate::keys::ROOT)];
                own.extend(also.iter().cloned());
                (
                    vec![
                        rule("asked", &ASKING, &["ingress", "egress"], vec!["**".into()]),
                        rule("own", &SPEAKING, &["egress"], own),
                    ],
                    vec![json!({"id": "anyone"})],
                    vec![json!({"rules": ["asked", "own"], "subjects": ["anyone"]})],
                )
            }
            Self::Room { cells } => {
                let mut rules = vec![rule("asks", &ASKING, &["egress"], vec!["**".into()])];
                let mut subjects = vec![json!({"id": "anyone"})];
                let mut policies = vec![json!({"rules": ["asks"], "subjects": ["anyone"]})];
                for c in *cells {
                    let id = format!("cell-{c}");
                    rules.push(rule(
                        &id,
                        &SPEAKING,
                        &["ingress"],
                        vec![format!("{}/{c}/**", crate::keys::ROOT)],
                    ));
                    subjects.push(json!({"id": id, "cert_common_names": [c.as_str()]}));
                    policies.push(json!({"rules": [id], "subjects": [id]}));
                }
                (rules, subjects, policies)
            }
        };
        Some(json!({
            "enabled": true,
            "default_permission": "deny",
            "rules": rules,
            "subjects": subjects,
            "policies": policies,
        }))
    }
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
    /// As a cell's `[network]` section says, with the cell's access control (`also`: the
    /// keys it publishes under besides its own, its ROS 2 topics).
    pub fn of(net: &'a NetworkSettings, name: &'a CellName, also: &'a [String]) -> Self {
        Self {
            mode: net.mode,
            listen: &net.listen,
            connect: &net.connect,
            multicast: net.multicast,
            lease_s: net.lease,
            tls: net.tls.as_ref(),
            login: net.login.as_ref(),
            access: Access::Cell { name, also },
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
        if let Some(acl) = self.access.zenoh() {
            set("access_control", acl.to_string())?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn session(listen: &[String], connect: &[String], access: Access<'_>) -> zenoh::Session {
        Link {
            mode: Mode::Peer,
            listen,
            connect,
            multicast: false,
            lease_s: 3.0,
            tls: None,
            login: None,
            access,
        }
        .open()
        .expect("a session")
    }

    /// What `from` puts on `key` reaches a subscriber of everything on the other end.
    fn arrives(
        from: &zenoh::Session,
        to: &zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
        key: &str,
    ) -> bool {
        from.put(key, "x").wait().expect("put");
        let mut seen = false;
        while let Ok(Some(s)) = to.recv_timeout(Duration::from_millis(500)) {
            seen |= s.key_expr().as_str() == key;
        }
        seen
    }

    #[test]
    fn a_cell_publishes_under_its_own_name_and_its_ros_topics_only() {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free port")
            .port();
        let at = [format!("tcp/127.0.0.1:{port}")];
        let room = session(&at, &[], Access::Open);
        let everything = room.declare_subscriber("**").wait().expect("subscriber");
        let name = CellName::new("press-0").expect("name");
        let also = ["42/press_0/**".to_string()];
        let cell = session(
            &[],
            &at,
            Access::Cell {
                name: &name,
                also: &also,
            },
        );
        // Linked, and its subscribers known to the cell.
        let start = std::time::Instant::now();
        while !arrives(&cell, &everything, "rtc/v1/press-0/status") {
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "the cell's own key never arrived"
            );
        }
        assert!(arrives(&cell, &everything, "42/press_0/joint_states/x"));
        assert!(
            !arrives(&cell, &everything, "rtc/v1/press-1/status"),
            "another cell's key"
        );
        assert!(
            !arrives(&cell, &everything, "43/press_0/joint_states/x"),
            "another domain"
        );
    }
}
