//! Events as people read them: one line per event for the terminal, one JSON object per
//! event for reports, and `supervisor events --follow`.

use control_plane::event::{Axes, event, line};
use runtime::ipc::{self, Sub};
use runtime::signals;
use shm_schema::{CellConfigV6, EventV1, InstanceName, ServiceId};
use std::time::Duration;

/// `supervisor events --instance NAME [--follow] [--json]`: prints the events of a running
/// instance as they happen (with `--follow`, until Ctrl-C; without, for `listen`).
pub fn follow(instance: &InstanceName, forever: bool, json: bool) -> Result<(), String> {
    ipc::quiet_iceoryx2_log();
    // A listing that fails (out of descriptors) says why, not "not running".
    if ipc::live_node_pids(instance)
        .map_err(|e| e.to_string())?
        .is_empty()
    {
        return Err(format!("no process of instance {instance} is running"));
    }
    signals::install().map_err(|e| format!("cannot install signal handlers: {e}"))?;
    let f = |e: ipc::IpcError| e.to_string();
    let node = ipc::node(instance, &format!("events-{}", std::process::id())).map_err(f)?;
    let config = Sub::<CellConfigV6>::new(&node, instance, ServiceId::CellConfig, 1).map_err(f)?;
    let events = Sub::<EventV1>::new(&node, instance, ServiceId::Events, 1024).map_err(f)?;
    let mut axes = Axes::default();
    let t0 = runtime::time::now_ns();
    let listen = Duration::from_millis(500);
    let start = std::time::Instant::now();
    while forever || start.elapsed() < listen {
        if signals::stop_requested() {
            break;
        }
        if let Some(c) = config.latest() {
            axes = Axes::of_cell(&c);
        }
        while let Some(e) = events.next() {
            if json {
                let doc = serde_json::to_string(&event(&e, &axes, t0));
                println!("{}", doc.unwrap_or_default());
            } else {
                println!("{}", line(&e, &axes, t0));
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    drop((config, events));
    drop(node);
    ipc::cleanup_after_client(instance);
    Ok(())
}
