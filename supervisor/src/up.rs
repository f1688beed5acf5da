//! `supervisor up`: a cell kept up until `supervisor down`, SIGTERM or SIGINT, with the
//! control channel open to the user's other shells (docs/operations.md).

use crate::cell::{Mode, open_cell};
use crate::config::Config;
use crate::run::{RunError, leftover_error};
use crate::serve::{End, serve};
use runtime::ipc;
use shm_schema::InstanceName;
use std::path::Path;
use std::time::Duration;

/// Brings the cell of `config` up on `instance` and serves it until it is told to go down;
/// then stops every process and removes every resource of the instance. Returns how it
/// ended.
pub fn up(config: Option<&Path>, instance: &str) -> Result<String, RunError> {
    let cfg = Config::load(config).map_err(|e| RunError::Input(e.to_string()))?;
    let instance = InstanceName::new(instance)
        .map_err(|e| RunError::Input(format!("--instance {instance:?}: {e}")))?;
    let (mut cell, mut server) = open_cell(&cfg, instance, Mode::Up)?;
    tracing::info!(
        "instance {instance} up: {} ({} processes: {}); control it with `supervisor <command> --instance {instance}`",
        cfg.cell.name,
        cfg.process.len(),
        cfg.process
            .iter()
            .map(|p| p.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let end = serve(&cfg, &mut cell, &mut server, None);
    let why = match end {
        End::Down => "supervisor down",
        End::Interrupted => "a signal",
        End::Program(_) => "the program",
    };
    tracing::info!("instance {instance}: going down ({why})");
    let problems = cell.stop_children();
    drop(cell);
    // The lock (the control socket) is let go only once the instance is removed: the next
    // supervisor of the instance never meets this one's cleanup.
    let leftovers = ipc::remove_instance_waiting(&instance, Duration::from_secs(1));
    drop(server);
    if let Some((name, problem)) = problems.first() {
        return Err(RunError::failed(format!("{name} {problem}")));
    }
    if let Some(e) = leftover_error(&instance, &leftovers) {
        return Err(e);
    }
    Ok(format!("instance {instance} is down ({why})"))
}
