//! `supervisor up`: a cell kept up until `supervisor down`, SIGTERM or SIGINT, with the
//! control channel open to the user's other shells (docs/operations.md).

use crate::cell::{Mode, open_recorded};
use crate::error::RunError;
use crate::serve::{End, serve};
use cell_config::Config;
use control_plane::Failure;
use control_plane::event::Event;
use shm_schema::InstanceName;
use std::path::Path;

/// Brings the cell of `config` up on `instance` and serves it until it is told to go down;
/// then stops every process and removes every resource of the instance. Returns how it
/// ended, and every event of the cell's life (none when it never came up).
pub fn up(
    config: Option<&Path>,
    instance: &str,
    record: Option<&Path>,
    virtual_time: bool,
) -> (Result<String, RunError>, Vec<Event>) {
    let mut events = Vec::new();
    let ended = up_inner(config, instance, record, virtual_time, &mut events);
    (ended, events)
}

fn up_inner(
    config: Option<&Path>,
    instance: &str,
    record: Option<&Path>,
    virtual_time: bool,
    events: &mut Vec<Event>,
) -> Result<String, RunError> {
    let mut cfg = Config::load(config).map_err(|e| RunError::Input(e.to_string()))?;
    if virtual_time {
        cfg.cell.clock = cell_config::Clock::Virtual;
    }
    let instance = InstanceName::new(instance)
        .map_err(|e| RunError::Input(format!("--instance {instance:?}: {e}")))?;
    // An output that cannot be written is refused before anything starts.
    if let Some(f) = record {
        crate::out::writable(f, "--record").map_err(RunError::Input)?;
    }
    let (mut cell, mut server, recorder) = open_recorded(&cfg, instance, Mode::Up, record)?;
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
    // For a unit of `Type=notify` (or a script): the control channel answers from here on.
    if let Err(e) = runtime::notify::ready() {
        tracing::warn!("cannot say the cell is up: {e}");
    }
    let served = serve(&cfg, &mut cell, &mut server, None, recorder);
    match served.recorded {
        Some(Ok(summary)) => tracing::info!("{}", summary.trim_end()),
        Some(Err(e)) => tracing::error!("{e}"),
        None => {}
    }
    let why = match served.end {
        End::Down => "supervisor down",
        End::Interrupted => "a signal",
        End::Program(_) | End::Tuned(_) => "the program",
        End::Failed(e) => {
            tracing::info!("instance {instance}: going down (it did not come up)");
            *events = cell.close(server).events;
            return Err(*e);
        }
    };
    // A critical process lost for good: the cell ran without it, which `up` says in its exit.
    let lost = cell.lost_for_good();
    tracing::info!("instance {instance}: going down ({why})");
    let closed = cell.close(server);
    *events = closed.events;
    if let Some(e) = closed.problem {
        return Err(e);
    }
    if let Some((process, why)) = lost {
        return Err(RunError::failed(Failure::LostForGood { process, why }));
    }
    Ok(format!("instance {instance} is down ({why})"))
}
