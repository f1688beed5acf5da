//! What the line says of its cells: who is present (their liveliness tokens) and what each
//! one's status says; read by `gateway line cells` and the line's web view alike.

use gateway::keys::{EVERY_CELL_ALIVE, ROOT, cell_of};
use gateway::wire::StatusMessage;
use std::collections::BTreeMap;
use std::time::Duration;
use zenoh::Wait;
use zenoh::query::QueryTarget;

/// A failure of a line command: its exit code and what to say.
pub(crate) type Failure = (u8, String);

/// How long a `get` waits for the line's answers.
pub(crate) const PATIENCE: Duration = Duration::from_secs(3);

/// A cell as `cells` lists it (`null` where its status did not come).
#[derive(Debug, serde::Serialize)]
pub(crate) struct Row {
    pub(crate) cell: String,
    pub(crate) host: Option<String>,
    /// `enabled`, `disabled` or `fault`.
    pub(crate) state: Option<String>,
    /// The program running, if one is.
    pub(crate) program: Option<String>,
    /// The e-stop latched.
    pub(crate) estop: Option<bool>,
}

impl Row {
    fn of(cell: &str, m: Option<&StatusMessage>) -> Self {
        let s = m.map(|m| &m.status);
        let arm = s.and_then(|s| s.supervisor.arm.as_ref());
        Self {
            cell: cell.into(),
            host: m.map(|m| m.host.clone()),
            state: arm.map(|a| {
                if a.fault_latched {
                    "fault"
                } else if a.enabled {
                    "enabled"
                } else {
                    "disabled"
                }
                .into()
            }),
            program: s.and_then(|s| s.supervisor.job.as_ref().map(|j| j.program.clone())),
            estop: s.and_then(|s| s.estop.as_ref().map(|e| e.latched)),
        }
    }
}

/// The statuses of every cell that answers, by name.
pub(crate) fn statuses(
    session: &zenoh::Session,
    key: &str,
) -> Result<BTreeMap<String, StatusMessage>, Failure> {
    let replies = session
        .get(key)
        .target(QueryTarget::All)
        .timeout(PATIENCE)
        .wait()
        .map_err(|e| (1, format!("cannot ask the line: {e}")))?;
    let mut out = BTreeMap::new();
    while let Ok(reply) = replies.recv() {
        // By the key it came on, not by what it says of itself.
        if let Ok(sample) = reply.result()
            && let Some(cell) = cell_of(sample.key_expr().as_str())
            && let Ok(m) = serde_json::from_slice::<StatusMessage>(&sample.payload().to_bytes())
        {
            out.insert(cell.to_string(), m);
        }
    }
    Ok(out)
}

/// The cells on the line (their presence tokens), each with what its status says.
pub(crate) fn rows(session: &zenoh::Session) -> Result<Vec<Row>, Failure> {
    let tokens = session
        .liveliness()
        .get(EVERY_CELL_ALIVE)
        .timeout(PATIENCE)
        .wait()
        .map_err(|e| (1, format!("cannot ask the line: {e}")))?;
    let mut alive = Vec::new();
    while let Ok(reply) = tokens.recv() {
        if let Ok(sample) = reply.result()
            && let Some(cell) = cell_of(sample.key_expr().as_str())
        {
            alive.push(cell.to_string());
        }
    }
    alive.sort();
    alive.dedup();
    let statuses = statuses(session, &format!("{ROOT}/*/status"))?;
    Ok(alive
        .iter()
        .map(|name| Row::of(name, statuses.get(name)))
        .collect())
}
