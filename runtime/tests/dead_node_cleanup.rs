//! A killed process's node while another process is cleaning it: `remove_dead_nodes` must
//! leave its files (the record of which ports it held) to the cleaner and to its own next
//! call, never sweep them as orphans. Swept, the dead node's ports stay registered in the
//! services for good and a restarted process finds no free slot (a publisher of a service
//! with two slots: `ExceedsMaxSupportedPublishers`).
//!
//! The processes are this test binary run again (`HELPER` says as what): one holds a node and
//! a publisher until it is SIGKILLed; one takes the dead node's cleaner lock (a write lock on
//! its `_owner_lock` file, as iceoryx2's cleaner does) and holds it.

use runtime::ipc::{self, Pub};
use shm_schema::{InstanceName, ServiceId, TrajgenHandoverV2};
use std::io::{BufRead, BufReader};
use std::os::fd::AsRawFd;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

const HELPER: &str = "RTC_DEAD_NODE_HELPER";

/// Runs this binary's `helper` test as `role` with `arg`; returns once it printed "ready".
fn spawn_helper(role: &str, arg: &str) -> Child {
    let mut child = Command::new(std::env::current_exe().expect("test binary"))
        .args(["--exact", "helper", "--include-ignored", "--nocapture"])
        .env(HELPER, format!("{role} {arg}"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("helper");
    let out = child.stdout.take().expect("stdout");
    let ready = BufReader::new(out)
        .lines()
        .map_while(Result::ok)
        .any(|l| l == "ready");
    assert!(ready, "helper {role} did not get ready");
    child
}

/// The helpers: `node <instance>` holds a node and a handover publisher; `lock <file>` holds
/// a write lock on the file. Both until killed. Run only by [`spawn_helper`].
#[test]
#[ignore = "a helper process of the test below, not a test"]
fn helper() {
    let Ok(what) = std::env::var(HELPER) else {
        return;
    };
    let (role, arg) = what.split_once(' ').expect("role and argument");
    let mut keep: Vec<Box<dyn std::any::Any>> = Vec::new();
    match role {
        "node" => {
            let instance = InstanceName::new(arg).expect("instance");
            let node = ipc::node(&instance, "victim").expect("node");
            let port: Pub<TrajgenHandoverV2> =
                Pub::new(&node, &instance, ServiceId::TrajgenHandover).expect("publisher");
            keep.push(Box::new(port));
            keep.push(Box::new(node));
        }
        "lock" => {
            let file = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(arg)
                .expect("owner lock file");
            let lock = libc::flock {
                l_type: libc::F_WRLCK as libc::c_short,
                l_whence: libc::SEEK_SET as libc::c_short,
                l_start: 0,
                l_len: 0,
                l_pid: 0,
            };
            // SAFETY: a valid descriptor and a valid flock.
            let rc = unsafe { libc::fcntl(file.as_raw_fd(), libc::F_SETLK, &lock) };
            assert_eq!(rc, 0, "lock {arg}");
            keep.push(Box::new(file));
        }
        _ => panic!("unknown helper {role}"),
    }
    println!("ready");
    loop {
        std::thread::sleep(Duration::from_secs(1));
    }
}

fn kill(mut child: Child) {
    let _ = child.kill();
    let _ = child.wait();
}

#[test]
fn a_dead_node_another_process_is_cleaning_keeps_its_files_until_it_is_cleaned() {
    let name = format!("deadclean{}", std::process::id());
    let instance = InstanceName::new(&name).expect("valid");
    let nodes = std::path::PathBuf::from(instance.root_dir().as_str()).join("nodes");
    // The handover service has two publisher slots: ours and the victim's.
    let node = ipc::node(&instance, "survivor").expect("node");
    let ours: Pub<TrajgenHandoverV2> =
        Pub::new(&node, &instance, ServiceId::TrajgenHandover).expect("our publisher");
    kill(spawn_helper("node", &name));
    // Its node's files are over a second old before anything looks at them (the orphan sweep
    // spares younger ones).
    std::thread::sleep(Duration::from_millis(1200));
    let own_id = node.id().value().to_string();
    let victim_lock = std::fs::read_dir(&nodes)
        .expect("nodes folder")
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            let n = p.file_name().map(|n| n.to_string_lossy().to_string());
            n.is_some_and(|n| n.ends_with(".node_monitor_owner_lock") && !n.contains(&own_id))
        })
        .expect("the dead node's owner lock file");
    let cleaner = spawn_helper("lock", victim_lock.to_str().expect("utf-8"));

    // Another process is cleaning it: this call cannot, and must keep its files.
    let _ = ipc::remove_dead_nodes(&instance);
    assert!(
        victim_lock.exists(),
        "the files of a dead node another process is cleaning were swept"
    );
    let second: Result<Pub<TrajgenHandoverV2>, _> =
        Pub::new(&node, &instance, ServiceId::TrajgenHandover);
    assert!(
        second.is_err(),
        "the dead node's publisher slot should still be taken while it is being cleaned"
    );

    // The cleaner went away (it crashed: its lock is released); the next call cleans the
    // dead node, and its slot is free again.
    kill(cleaner);
    assert!(ipc::remove_dead_nodes(&instance).expect("cleanup") >= 1);
    let again: Pub<TrajgenHandoverV2> = Pub::new(&node, &instance, ServiceId::TrajgenHandover)
        .expect("the dead node's slot is free once it is cleaned");
    drop((again, ours, node));
    let left = ipc::remove_instance(&instance);
    assert!(left.is_empty(), "left behind: {left:?}");
}
