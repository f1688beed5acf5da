//! One-shot commands to a running instance: fault injection into the simulated drives.

use crate::config::{Config, FAULT_NAMES, fault_code};
use runtime::events::EventSink;
use runtime::ipc::{self, Pub};
use shm_schema::event::{SOURCE_SUPERVISOR, code};
use shm_schema::{EventV1, FaultInjectionV1, InstanceName, ServiceId};
use std::time::Duration;

/// `supervisor inject`: raises (or clears) `fault` on `axis` of the running `instance`.
pub fn inject(
    instance: &str,
    config: Option<&std::path::Path>,
    axis: &str,
    fault: &str,
    clear: bool,
) -> Result<String, String> {
    let instance =
        InstanceName::new(instance).map_err(|e| format!("--instance {instance:?}: {e}"))?;
    let cfg = Config::load(config).map_err(|e| e.to_string())?;
    let index = cfg
        .axis
        .iter()
        .position(|a| a.name == axis)
        .ok_or_else(|| {
            let names: Vec<&str> = cfg.axis.iter().map(|a| a.name.as_str()).collect();
            format!("--axis {axis:?}: the cell has axes {}", names.join(", "))
        })?;
    let code_of =
        fault_code(fault).ok_or_else(|| format!("fault {fault:?} is not one of {FAULT_NAMES}"))?;
    ipc::quiet_iceoryx2_log();
    if ipc::live_node_pids(&instance)
        .unwrap_or_default()
        .is_empty()
    {
        return Err(format!("no process of instance {instance} is running"));
    }
    let f = |e: ipc::IpcError| e.to_string();
    let node = ipc::node(&instance, &format!("inject-{}", std::process::id())).map_err(f)?;
    let port =
        Pub::<FaultInjectionV1>::new(&node, &instance, ServiceId::FaultInjection).map_err(f)?;
    let mut events = EventSink::new(&node, &instance, SOURCE_SUPERVISOR).map_err(f)?;
    // Let the drives' subscriber see the new publisher before sending.
    std::thread::sleep(Duration::from_millis(50));
    let sample = FaultInjectionV1 {
        // Unique per sender and increasing: the time.
        seq: runtime::time::now_ns(),
        axis: index as u32,
        code: code_of,
        active: u16::from(!clear),
    };
    if !port.send(&sample) {
        return Err("the drives' injection service refused the sample".into());
    }
    let what = if clear { "cleared" } else { "injected" };
    events.emit(EventV1::new(
        runtime::time::now_ns(),
        code::SUPERVISOR_ACTION,
        index as i32,
        code_of as f64,
        0.0,
        &[what, " ", fault],
    ));
    // Keep the ports until the drives have taken it (their next cycle).
    std::thread::sleep(Duration::from_millis(50));
    drop((port, events));
    drop(node);
    ipc::cleanup_after_client(&instance);
    Ok(format!(
        "{what} {fault} on axis {axis} of instance {instance}"
    ))
}
