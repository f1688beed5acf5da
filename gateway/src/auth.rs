//! Who may ask a cell what over the network, judged by the cell's gateway itself: the
//! transport's access control refuses silently (the asker hears nothing), so the gateway
//! checks every command and answers a refusal with its reason.
//!
//! A command travels as the JSON of an [`Envelope`] (the user, the cell, the time, a nonce,
//! the [`Command`]), signed with the user's secret: HMAC-SHA256 over the payload's exact
//! bytes, 64 lowercase hex digits, as the query's attachment. The gateway admits it when the
//! user is one of the line's, the signature is theirs, the envelope names this cell, its time
//! is within [`WINDOW_MS`] of the gateway's clock, its nonce was not seen in that window, and
//! the user's role allows the command: a viewer may ask for the status, an operator may also
//! command.
//!
//! The users file (TOML, readable by its owner alone, as an ssh key):
//!
//! ```text
//! [[user]]
//! name = "alice"
//! role = "operator"
//! secret = "at least 16 characters, shared with alice's client alone"
//! ```

use crate::command::Command;
use hmac::{Hmac, Mac};
use serde::{Deserialize, Serialize};
use sha2::Sha256;
use std::collections::{BTreeMap, VecDeque};
use std::fmt;

/// How far a command's time may be from the gateway's clock (ms), either way.
pub const WINDOW_MS: u64 = 30_000;

/// Commands of one user remembered against replay, at most (within [`WINDOW_MS`]): one
/// user's flood refuses that user's commands only. Reads are not remembered (a replayed read
/// changes nothing).
pub const REMEMBERED: usize = 4096;

/// The shortest secret.
pub const MIN_SECRET: usize = 16;

/// What a user may do.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Reads: the status, the events.
    Viewer,
    /// Reads, and commands.
    Operator,
}

/// One user of the line, as the users file has it.
#[derive(Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct UserEntry {
    name: String,
    role: Role,
    secret: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct UsersFile {
    #[serde(default)]
    user: Vec<UserEntry>,
}

/// The line's users, by name.
#[derive(Clone, Default)]
pub struct Users {
    by_name: BTreeMap<String, (Role, Vec<u8>)>,
}

impl fmt::Debug for Users {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Never the secrets.
        f.debug_map()
            .entries(self.by_name.iter().map(|(n, (r, _))| (n, r)))
            .finish()
    }
}

/// A users file that cannot be taken, with where.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UsersError {
    /// The file.
    pub file: String,
    /// What is wrong, with the entry when it is one's.
    pub message: String,
}

impl fmt::Display for UsersError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.file, self.message)
    }
}

impl std::error::Error for UsersError {}

impl Users {
    /// The users of `text`, the content of `file`.
    pub fn parse(text: &str, file: &str) -> Result<Self, UsersError> {
        let err = |message: String| UsersError {
            file: file.into(),
            message,
        };
        let parsed: UsersFile = toml::from_str(text).map_err(|e| err(e.to_string()))?;
        let mut by_name = BTreeMap::new();
        for (k, u) in parsed.user.into_iter().enumerate() {
            if u.name.is_empty() || u.name.len() > 64 || u.name.chars().any(char::is_whitespace) {
                return Err(err(format!(
                    "user {} (entry {}): a name is 1 to 64 characters without spaces",
                    u.name,
                    k + 1
                )));
            }
            if u.secret.len() < MIN_SECRET {
                return Err(err(format!(
                    "user {} (entry {}): the secret is shorter than {MIN_SECRET} characters",
                    u.name,
                    k + 1
                )));
            }
            if by_name
                .insert(u.name.clone(), (u.role, u.secret.into_bytes()))
                .is_some()
            {
                return Err(err(format!(
                    "user {} (entry {}) is named twice",
                    u.name,
                    k + 1
                )));
            }
        }
        Ok(Self { by_name })
    }

    /// The users of the file at `path`, which only its owner may read or write.
    pub fn load(path: &std::path::Path) -> Result<Self, UsersError> {
        use std::os::unix::fs::PermissionsExt;
        let file = path.display().to_string();
        let err = |message: String| UsersError {
            file: file.clone(),
            message,
        };
        let meta = std::fs::metadata(path).map_err(|e| err(format!("cannot read: {e}")))?;
        let mode = meta.permissions().mode();
        if mode & 0o077 != 0 {
            return Err(err(format!(
                "its mode is {:o}: others than its owner may read it (chmod 600)",
                mode & 0o777
            )));
        }
        let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
        Self::parse(&text, &file)
    }

    /// The role of `name`, if a user.
    pub fn role(&self, name: &str) -> Option<Role> {
        self.by_name.get(name).map(|(r, _)| *r)
    }
}

/// What a signed command carries.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Envelope {
    /// Who asks.
    pub user: String,
    /// The cell asked (a command for one cell is never taken by another).
    pub cell: String,
    /// When it was asked: ms since the Unix epoch, the asker's clock.
    pub time_ms: u64,
    /// A number the asker uses once.
    pub nonce: u64,
    /// What is asked.
    pub command: Command,
}

impl Envelope {
    /// The payload as sent (its JSON) and its signature with `secret`.
    pub fn signed(&self, secret: &[u8]) -> (Vec<u8>, String) {
        let payload = serde_json::to_vec(self).expect("an envelope is JSON");
        let signature = sign(secret, &payload);
        (payload, signature)
    }
}

/// Now, in ms since the Unix epoch: an envelope's time, and the gate's clock.
pub fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// The signature of `payload` with `secret`: 64 lowercase hex digits.
pub fn sign(secret: &[u8], payload: &[u8]) -> String {
    let mut mac = <Hmac<Sha256> as Mac>::new_from_slice(secret).expect("HMAC takes any key");
    mac.update(payload);
    mac.finalize()
        .into_bytes()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn unhex(text: &str) -> Option<Vec<u8>> {
    if text.len() != 64 {
        return None;
    }
    (0..64)
        .step_by(2)
        .map(|i| u8::from_str_radix(text.get(i..i + 2)?, 16).ok())
        .collect()
}

/// Why a command was not admitted.
#[derive(Clone, Debug, PartialEq)]
pub enum Refusal {
    /// The payload is not an envelope.
    Malformed(String),
    /// No such user on the line.
    UnknownUser(String),
    /// The signature is not the user's.
    BadSignature(String),
    /// The envelope names another cell.
    OtherCell {
        /// The cell it names.
        named: String,
    },
    /// Its time is too far from the gateway's.
    Stale {
        /// The gateway's clock minus the command's time (ms).
        age_ms: i64,
    },
    /// Its nonce was seen within the window.
    Replayed,
    /// Too many commands of this user within the window to remember them all.
    TooMany,
    /// The user's role does not allow it.
    NotAllowed {
        /// The user.
        user: String,
        /// The user's role.
        role: Role,
        /// The command's `op`.
        op: &'static str,
    },
}

/// A name as a refusal says it: at most 64 characters (a stranger's name is theirs to choose).
fn short(name: &str) -> String {
    match name.char_indices().nth(64) {
        Some((i, _)) => format!("{}...", &name[..i]),
        None => name.into(),
    }
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Malformed(e) => write!(f, "not a command: {e}"),
            Self::UnknownUser(u) => write!(f, "{:?} is not a user of this line", short(u)),
            Self::BadSignature(u) => write!(f, "the signature is not {u:?}'s"),
            Self::OtherCell { named } => write!(f, "the command is for cell {named:?}"),
            Self::Stale { age_ms } => write!(
                f,
                "the command's time is {:.1} s from this cell's clock (at most {} s): a late or replayed command, or clocks apart",
                *age_ms as f64 / 1e3,
                WINDOW_MS / 1000
            ),
            Self::Replayed => f.write_str("this command was taken already (its nonce is used)"),
            Self::TooMany => write!(
                f,
                "more than {REMEMBERED} commands of this user in {} s: refused until the window moves on",
                WINDOW_MS / 1000
            ),
            Self::NotAllowed { user, role, op } => write!(
                f,
                "{user:?} is a {} and may not {op}: only an operator commands",
                match role {
                    Role::Viewer => "viewer",
                    Role::Operator => "operator",
                }
            ),
        }
    }
}

impl std::error::Error for Refusal {}

/// A command admitted: who asked, and what.
#[derive(Clone, Debug, PartialEq)]
pub struct Admitted {
    /// The user.
    pub user: String,
    /// The user's role.
    pub role: Role,
    /// The command.
    pub command: Command,
}

/// The gate of one cell: its users and the nonces of the window.
#[derive(Debug)]
pub struct Gate {
    users: Users,
    cell: String,
    /// (time_ms, user, nonce) of the admitted commands, oldest first.
    seen: VecDeque<(u64, String, u64)>,
}

impl Gate {
    /// The gate of `cell` for `users`.
    pub fn new(users: Users, cell: &str) -> Self {
        Self {
            users,
            cell: cell.into(),
            seen: VecDeque::new(),
        }
    }

    /// Judges `payload` signed `signature`, at `now_ms` (ms since the Unix epoch). Nothing of
    /// an unsigned or wrongly signed payload is kept.
    pub fn admit(
        &mut self,
        payload: &[u8],
        signature: &str,
        now_ms: u64,
    ) -> Result<Admitted, Refusal> {
        let envelope: Envelope =
            serde_json::from_slice(payload).map_err(|e| Refusal::Malformed(e.to_string()))?;
        let Some((role, secret)) = self.users.by_name.get(&envelope.user) else {
            return Err(Refusal::UnknownUser(envelope.user));
        };
        let role = *role;
        let mut mac = <Hmac<Sha256> as Mac>::new_from_slice(secret).expect("any key");
        mac.update(payload);
        let genuine = unhex(signature).is_some_and(|sig| mac.verify_slice(&sig).is_ok());
        if !genuine {
            return Err(Refusal::BadSignature(envelope.user));
        }
        if envelope.cell != self.cell {
            return Err(Refusal::OtherCell {
                named: envelope.cell,
            });
        }
        let age_ms = (i128::from(now_ms) - i128::from(envelope.time_ms))
            .clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64;
        if age_ms.unsigned_abs() > WINDOW_MS {
            return Err(Refusal::Stale { age_ms });
        }
        while self
            .seen
            .front()
            .is_some_and(|(t, _, _)| t.saturating_add(2 * WINDOW_MS) < now_ms)
        {
            self.seen.pop_front();
        }
        if self
            .seen
            .iter()
            .any(|(_, u, n)| *u == envelope.user && *n == envelope.nonce)
        {
            return Err(Refusal::Replayed);
        }
        let changes = envelope.command.changes_the_cell();
        if changes && role != Role::Operator {
            return Err(Refusal::NotAllowed {
                user: envelope.user,
                role,
                op: envelope.command.op(),
            });
        }
        if changes {
            let theirs = self
                .seen
                .iter()
                .filter(|(_, u, _)| *u == envelope.user)
                .count();
            if theirs >= REMEMBERED {
                return Err(Refusal::TooMany);
            }
            self.seen
                .push_back((envelope.time_ms, envelope.user.clone(), envelope.nonce));
        }
        Ok(Admitted {
            user: envelope.user,
            role,
            command: envelope.command,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const USERS: &str = r#"
[[user]]
name = "alice"
role = "operator"
secret = "alice's secret, long enough"

[[user]]
name = "victor"
role = "viewer"
secret = "victor's secret, long enough"
"#;

    fn signed(
        user: &str,
        secret: &str,
        cell: &str,
        time_ms: u64,
        nonce: u64,
        c: Command,
    ) -> (Vec<u8>, String) {
        Envelope {
            user: user.into(),
            cell: cell.into(),
            time_ms,
            nonce,
            command: c,
        }
        .signed(secret.as_bytes())
    }

    #[test]
    fn one_users_flood_refuses_that_user_alone() {
        let users = Users::parse(USERS, "users.toml").expect("users");
        let mut gate = Gate::new(users, "press-1");
        let now = 1_800_000_000_000;
        let alice = "alice's secret, long enough";
        let victor = "victor's secret, long enough";
        // A viewer's reads, any number, remembered by nobody.
        for n in 0..2 * REMEMBERED as u64 {
            let (p, s) = signed("victor", victor, "press-1", now, n, Command::Status {});
            gate.admit(&p, &s, now).expect("a read");
        }
        // An operator's commands: remembered up to the limit, then refused for that user.
        for n in 0..REMEMBERED as u64 {
            let (p, s) = signed("alice", alice, "press-1", now, n, Command::Pause {});
            gate.admit(&p, &s, now).expect("a command");
        }
        let (p, s) = signed("alice", alice, "press-1", now, 1 << 40, Command::Pause {});
        assert_eq!(gate.admit(&p, &s, now), Err(Refusal::TooMany));
        let (p, s) = signed(
            "victor",
            victor,
            "press-1",
            now,
            1 << 40,
            Command::Status {},
        );
        gate.admit(&p, &s, now).expect("victor still reads");
        // The window moves on.
        let later = now + 2 * WINDOW_MS + 1;
        let (p, s) = signed("alice", alice, "press-1", later, 1 << 41, Command::Pause {});
        gate.admit(&p, &s, later).expect("alice again");
    }

    #[test]
    fn an_operator_commands_a_viewer_reads_and_each_refusal_says_why() {
        let users = Users::parse(USERS, "users.toml").expect("users");
        let mut gate = Gate::new(users, "press-1");
        let now = 1_800_000_000_000;
        let alice = "alice's secret, long enough";
        let victor = "victor's secret, long enough";

        let (p, s) = signed("alice", alice, "press-1", now, 1, Command::Pause {});
        let ok = gate.admit(&p, &s, now).expect("alice pauses");
        assert_eq!((ok.role, ok.command), (Role::Operator, Command::Pause {}));
        assert_eq!(gate.admit(&p, &s, now + 5), Err(Refusal::Replayed));

        let (p, s) = signed("victor", victor, "press-1", now, 1, Command::Status {});
        assert_eq!(
            gate.admit(&p, &s, now).expect("victor reads").role,
            Role::Viewer
        );
        let (p, s) = signed("victor", victor, "press-1", now, 2, Command::Pause {});
        let refused = gate.admit(&p, &s, now).expect_err("a viewer may not pause");
        assert!(
            refused.to_string().contains("viewer and may not pause"),
            "{refused}"
        );

        // Signed by the wrong secret, for another cell, late, by nobody, not a command.
        let (p, s) = signed("alice", victor, "press-1", now, 3, Command::Abort {});
        assert_eq!(
            gate.admit(&p, &s, now),
            Err(Refusal::BadSignature("alice".into()))
        );
        assert_eq!(
            gate.admit(&p, "zz", now),
            Err(Refusal::BadSignature("alice".into()))
        );
        let (p, s) = signed("alice", alice, "press-2", now, 4, Command::Abort {});
        assert!(matches!(
            gate.admit(&p, &s, now),
            Err(Refusal::OtherCell { .. })
        ));
        let (p, s) = signed(
            "alice",
            alice,
            "press-1",
            now - 31_000,
            5,
            Command::Abort {},
        );
        assert!(matches!(
            gate.admit(&p, &s, now),
            Err(Refusal::Stale { .. })
        ));
        let (p, s) = signed("mallory", alice, "press-1", now, 6, Command::Abort {});
        assert_eq!(
            gate.admit(&p, &s, now),
            Err(Refusal::UnknownUser("mallory".into()))
        );
        assert!(matches!(
            gate.admit(b"{\"user\": 1}", &s, now),
            Err(Refusal::Malformed(_))
        ));
        // A tampered payload is not the signed one.
        let (mut p, s) = signed(
            "alice",
            alice,
            "press-1",
            now,
            7,
            Command::Speed { percent: 10.0 },
        );
        let at = p.windows(2).position(|w| w == b"10").expect("the percent");
        p[at] = b'9';
        assert_eq!(
            gate.admit(&p, &s, now),
            Err(Refusal::BadSignature("alice".into()))
        );
    }

    #[test]
    fn a_users_file_is_refused_naming_the_entry() {
        for (text, says) in [
            (
                "[[user]]\nname = \"a\"\nrole = \"operator\"\nsecret = \"short\"\n",
                "user a (entry 1): the secret is shorter",
            ),
            (
                "[[user]]\nname = \"a\"\nrole = \"admin\"\nsecret = \"long enough secret\"\n",
                "unknown variant",
            ),
            (
                "[[user]]\nname = \"a\"\nrole = \"viewer\"\nsecret = \"long enough secret\"\n[[user]]\nname = \"a\"\nrole = \"operator\"\nsecret = \"long enough secret\"\n",
                "user a (entry 2) is named twice",
            ),
        ] {
            let e = Users::parse(text, "u.toml").expect_err(text);
            assert!(e.to_string().starts_with("u.toml: "), "{e}");
            assert!(e.to_string().contains(says), "{e}");
        }
        let users = Users::parse(USERS, "users.toml").expect("users");
        assert!(!format!("{users:?}").contains("secret"), "{users:?}");
    }

    #[test]
    fn a_users_file_others_may_read_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        let path = std::env::temp_dir().join(format!("rtc-users-{}.toml", std::process::id()));
        std::fs::write(&path, USERS).expect("write");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).expect("chmod");
        let e = Users::load(&path).expect_err("mode 644");
        assert!(e.to_string().contains("its mode is 644"), "{e}");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).expect("chmod");
        let users = Users::load(&path).expect("mode 600");
        assert_eq!(users.role("victor"), Some(Role::Viewer));
        let _ = std::fs::remove_file(&path);
    }
}
