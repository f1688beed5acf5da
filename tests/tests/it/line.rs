//! A line of cells on one machine (issue 20): two cells and a control room, each "host" a
//! network namespace of its own, the room joined to each cell by a veth pair it made (no
//! interface of the machine's own is touched). Each cell is its own instance (its own
//! iceoryx2 prefix: no shared memory in common) and Zenoh has no shared-memory transport, so
//! everything the room sees crossed a link. The real binaries: `supervisor up` in each cell's
//! namespace with its `gateway`, `gateway line` in the room's.

use crate::drives::WATCHDOG;
use crate::up::{Up, process_in};
use integration_tests::{ip, run_with_watchdog, scratch};
use serde_json::Value;
use std::f64::consts::PI;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
use toml_edit::{Table, value};

/// The line's users: an operator and a viewer.
const USERS: &str = "[[user]]\nname = \"olga\"\nrole = \"operator\"\nsecret = \"olga-secret-0123456789\"\n\n\
                     [[user]]\nname = \"victor\"\nrole = \"viewer\"\nsecret = \"victor-secret-0123456789\"\n";

/// A link's lease (s): how long a silent cell stays listed.
const LEASE_S: f64 = 3.0;

/// The namespaces of one test: the room and its cells, removed on drop.
struct Hosts {
    room: String,
    cells: Vec<String>,
}

impl Hosts {
    /// The room and `n` cells, cell `k` at 10.77.<k+1>.2, the room's end of its link
    /// `v<k>` at 10.77.<k+1>.1.
    fn new(test: &str, n: usize) -> Self {
        let base = format!("rtc-l{}-{test}", std::process::id());
        let hosts = Self {
            room: format!("{base}-r"),
            cells: (0..n).map(|k| format!("{base}-{k}")).collect(),
        };
        ip(&["netns", "add", &hosts.room]);
        ip(&["-n", &hosts.room, "link", "set", "lo", "up"]);
        for (k, ns) in hosts.cells.iter().enumerate() {
            ip(&["netns", "add", ns]);
            ip(&["-n", ns, "link", "set", "lo", "up"]);
            let v = format!("v{k}");
            ip(&[
                "-n",
                &hosts.room,
                "link",
                "add",
                &v,
                "type",
                "veth",
                "peer",
                "name",
                "eth0",
                "netns",
                ns,
            ]);
            ip(&[
                "-n",
                &hosts.room,
                "addr",
                "add",
                &format!("10.77.{}.1/24", k + 1),
                "dev",
                &v,
            ]);
            ip(&[
                "-n",
                ns,
                "addr",
                "add",
                &format!("10.77.{}.2/24", k + 1),
                "dev",
                "eth0",
            ]);
            ip(&["-n", &hosts.room, "link", "set", &v, "up"]);
            ip(&["-n", ns, "link", "set", "eth0", "up"]);
        }
        hosts
    }

    /// Cell `k`'s link, as the room sees it, brought `state` (`up`, `down`).
    fn link(&self, k: usize, state: &str) {
        ip(&["-n", &self.room, "link", "set", &format!("v{k}"), state]);
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for ns in self.cells.iter().chain([&self.room]) {
            let _ = Command::new("ip").args(["netns", "del", ns]).status();
        }
    }
}

/// A file only its owner may read (the users file, a secret).
fn private(test: &str, name: &str, text: &str) -> PathBuf {
    let p = scratch(test, name, text);
    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o600)).expect("chmod");
    p
}

/// Cell `k` of the line, `press-<k>`: the default cell (on the virtual clock), its gateway
/// listening on its link in the clear.
fn cell_config(test: &str, k: usize, users: &Path) -> PathBuf {
    cell_config_with(test, k, users, "tcp", &[])
}

/// [`cell_config`] listening on a `proto` endpoint, `more` added to `[network]` (its
/// sub-tables).
fn cell_config_with(
    test: &str,
    k: usize,
    users: &Path,
    proto: &str,
    more: &[(&str, Table)],
) -> PathBuf {
    let mut gateway = Table::new();
    gateway.insert("name", value("gateway"));
    gateway.insert(
        "command",
        value(integration_tests::toml::strings(&[
            "gateway",
            "--instance",
            "{instance}",
        ])),
    );
    gateway.insert("period_us", value(20_000));
    gateway.insert("priority", value(0));
    gateway.insert("critical", value(false));
    gateway.insert("network_estop_config", value("ignore"));
    let mut network = Table::new();
    network.insert("name", value(format!("press-{k}")));
    network.insert(
        "listen",
        value(integration_tests::toml::strings(&[&format!(
            "{proto}/10.77.{}.2:7447",
            k + 1
        )])),
    );
    network.insert("plain", value(proto == "tcp"));
    network.insert("users", value(users.display().to_string()));
    network.insert("lease", value(LEASE_S));
    for (key, table) in more {
        network.insert(key, toml_edit::Item::Table(table.clone()));
    }
    integration_tests::default_cell_toml()
        .push("process", gateway)
        .table("network", network)
        .write(test, &format!("cell-{k}.toml"))
}

/// The TOML file `file` with the `lease` of its table `table` (its root for `None`) set to
/// `lease`.
fn with_lease(file: PathBuf, table: Option<&str>, lease: f64) -> PathBuf {
    let text = std::fs::read_to_string(&file).expect("the file");
    let mut doc: toml_edit::DocumentMut = text.parse().expect("TOML");
    let t = match table {
        Some(name) => doc[name].as_table_mut().expect("the table"),
        None => doc.as_table_mut(),
    };
    t.insert("lease", value(lease));
    std::fs::write(&file, doc.to_string()).expect("write");
    file
}

/// A table of `entries`.
fn table(entries: &[(&str, toml_edit::Item)]) -> Table {
    let mut t = Table::new();
    for (k, v) in entries {
        t.insert(k, v.clone());
    }
    t
}

/// The room's line file `file` for `user` (secret `secret`), connecting to `cells` cells.
fn line_file(test: &str, file: &str, user: &str, secret: &str, cells: usize) -> PathBuf {
    let secret_file = private(test, &format!("{file}.secret"), &format!("{secret}\n"));
    let connect: Vec<String> = (0..cells)
        .map(|k| format!("\"tcp/10.77.{}.2:7447\"", k + 1))
        .collect();
    scratch(
        test,
        &format!("{file}.line.toml"),
        &format!(
            "connect = [{}]\nplain = true\nlease = {LEASE_S}\nuser = \"{user}\"\nsecret_file = \"{}\"\n",
            connect.join(", "),
            secret_file.display()
        ),
    )
}

/// `gateway line --line <file> <args>` in the room.
fn room(hosts: &Hosts, file: &Path, args: &[&str]) -> Output {
    let mut cmd = Command::new("ip");
    cmd.args(["netns", "exec", &hosts.room])
        .arg(integration_tests::bin("gateway"))
        .arg("line")
        .arg("--line")
        .arg(file)
        .args(args);
    run_with_watchdog(&mut cmd, WATCHDOG)
}

/// `gateway line --json --line <file> <args>` started in the room, going on (`--watch`,
/// `events`): its stdout piped, its stderr dropped.
fn following(hosts: &Hosts, file: &Path, args: &[&str]) -> std::process::Child {
    Command::new("ip")
        .args(["netns", "exec", &hosts.room])
        .arg(integration_tests::bin("gateway"))
        .args(["line", "--json", "--line"])
        .arg(file)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("gateway line in the room")
}

/// [`room`], which must succeed; its output.
fn ok(hosts: &Hosts, file: &Path, args: &[&str]) -> Output {
    let out = room(hosts, file, args);
    assert!(out.status.success(), "{args:?}: {}", text(&out));
    out
}

fn text(out: &Output) -> String {
    format!(
        "exit {:?}\n{}{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// The cells the room lists, as `cells --json` gives them.
fn cells(hosts: &Hosts, file: &Path) -> Vec<Value> {
    let out = room(hosts, file, &["cells", "--json"]);
    assert!(out.status.success(), "cells: {}", text(&out));
    serde_json::from_slice::<Value>(&out.stdout)
        .unwrap_or_else(|e| panic!("cells --json: {e}: {}", text(&out)))
        .as_array()
        .cloned()
        .unwrap_or_default()
}

fn names(rows: &[Value]) -> Vec<String> {
    rows.iter()
        .filter_map(|r| r["cell"].as_str().map(str::to_string))
        .collect()
}

/// Waits (at most `patience`, a panic then) until the room lists exactly `want`; returns the
/// rows and how long it took.
fn until_listed(
    hosts: &Hosts,
    file: &Path,
    want: &[&str],
    patience: Duration,
) -> (Vec<Value>, Duration) {
    let start = Instant::now();
    loop {
        let rows = cells(hosts, file);
        if names(&rows) == want {
            return (rows, start.elapsed());
        }
        assert!(
            start.elapsed() < patience,
            "the room lists {:?}, not {want:?}, after {patience:?}",
            names(&rows)
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[test]
fn a_line_of_two_cells_is_listed_read_and_commanded_from_the_room_by_operators_only() {
    let test = "line_two";
    let hosts = Hosts::new(test, 2);
    let users = private(test, "users.toml", USERS);
    // press-0 also shows its joint states to ROS 2 (rmw_zenoh), in domain 42.
    let a = Up::start_in(
        &format!("{test}-a"),
        &cell_config_with(
            test,
            0,
            &users,
            "tcp",
            &[("ros2", table(&[("domain", value(42))]))],
        ),
        Some(&hosts.cells[0]),
    );
    let b = Up::start_in(
        &format!("{test}-b"),
        &cell_config(test, 1, &users),
        Some(&hosts.cells[1]),
    );
    let olga = line_file(test, "olga", "olga", "olga-secret-0123456789", 2);
    let victor = line_file(test, "victor", "victor", "victor-secret-0123456789", 2);
    let mallory = line_file(test, "mallory", "olga", "not-olgas-secret-at-all", 2);

    // Both cells listed, with their state.
    let patience = Duration::from_secs(30);
    let (rows, _) = until_listed(&hosts, &victor, &["press-0", "press-1"], patience);
    for r in &rows {
        assert_eq!(r["state"], "enabled", "{r}");
        assert_eq!(r["estop"], false, "{r}");
    }

    // A cell's status crossed the link: its instance, its processes.
    let out = ok(&hosts, &victor, &["status", "press-1", "--json"]);
    let s: Value = serde_json::from_slice(&out.stdout).expect("status JSON");
    assert_eq!(s["instance"], b.inst.as_str());
    // Its gateway says where it is on the line, as the Modbus server says where it listens.
    assert_eq!(
        process_in(&s, "gateway")["listening"],
        "the line: press-1 on tcp/10.77.2.2:7447",
        "{s}"
    );

    // press-0's joint states as a ROS 2 node on rmw_zenoh would receive them, checked by
    // eclipse-zenoh and rosbags in the room (the CDR bytes, the type hash in the key, the
    // attachment): at rest at the default start, x and y 40 mm and theta 0 deg, in m and rad,
    // and the tool pose there.
    let mut ros = Command::new("ip");
    ros.args(["netns", "exec", &hosts.room, "python3"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("python/ros2_joint_states.py"))
        .args(["--connect", "tcp/10.77.1.2:7447", "--domain", "42"])
        .args(["--namespace", "press_0", "--samples", "3", "--pose"]);
    let out = run_with_watchdog(&mut ros, WATCHDOG);
    assert!(out.status.success(), "ROS 2 joint states: {}", text(&out));
    let j: Value = serde_json::from_slice(&out.stdout).expect("the checker's JSON");
    assert_eq!(j["names"], serde_json::json!(["x", "y", "theta"]), "{j}");
    assert_eq!(j["frame"], "press_0", "{j}");
    let status = a.until("at rest", |s| {
        s["servo"]["axes"]["x"]["position"].is_number()
    });
    let at = |axis: &str| {
        status["servo"]["axes"][axis]["position"]
            .as_f64()
            .expect("position")
    };
    for (k, (axis, scale)) in [("x", 1e-3), ("y", 1e-3), ("theta", PI / 180.0)]
        .into_iter()
        .enumerate()
    {
        let want = at(axis) * scale;
        for p in j["positions"].as_array().expect("positions") {
            let got = p[k].as_f64().expect("a position");
            assert!(
                (got - want).abs() < 1e-5,
                "{axis}: {got} against {want}: {j}"
            );
        }
    }
    let seqs: Vec<i64> = (j["seqs"].as_array().expect("seqs").iter())
        .map(|v| v.as_i64().expect("seq"))
        .collect();
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "{j}");
    assert_eq!(
        j["gids"].as_array().map(Vec::len),
        Some(1),
        "one publisher: {j}"
    );
    // The tool pose of the gantry at rest there: (0.04, 0.04, 0) m, not turned; a publisher
    // of its own.
    let pose = &j["pose"];
    assert_eq!(pose["frame"], "press_0", "{j}");
    let near = |v: &Value, want: &[f64]| {
        (v.as_array().expect("numbers").iter())
            .zip(want)
            .all(|(g, w)| (g.as_f64().expect("a number") - w).abs() < 1e-5)
    };
    assert!(
        near(&pose["position"], &[at("x") * 1e-3, at("y") * 1e-3, 0.0]),
        "{j}"
    );
    let half = at("theta").to_radians() / 2.0;
    assert!(
        near(&pose["orientation"], &[0.0, 0.0, half.sin(), half.cos()]),
        "{j}"
    );
    assert_ne!(pose["gid"], j["gids"][0], "{j}");
    // In ROS 2's graph (what `ros2 topic list` reads): the node in press_0's namespace and its
    // two publishers, reliable, keep last 10.
    let graph = &j["graph"];
    assert_eq!(graph["name"], "rtc_gateway", "{graph}");
    for topic in ["joint_states", "tool_pose"] {
        assert_eq!(graph["publishers"][topic]["qos"], "::,10:,:,:,,", "{graph}");
    }
    // Each publisher's messages carry the GID rmw_zenoh gives it: its token's XXH3-128 (the
    // checker compares them; a GID of another making fails it).
    assert_eq!(
        graph["publishers"]["joint_states"]["gid"], j["gids"][0],
        "{j}"
    );
    assert_eq!(graph["publishers"]["tool_pose"]["gid"], pose["gid"], "{j}");

    // A viewer may read, not command: refused by the gateway, with why; the cell untouched.
    let out = room(&hosts, &victor, &["pause", "press-0"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("\"victor\" is a viewer and may not pause"),
        "{}",
        text(&out)
    );
    // A wrong secret is not the operator's.
    let out = room(&hosts, &mallory, &["estop", "press-0"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("the signature is not \"olga\"'s"),
        "{}",
        text(&out)
    );
    assert_eq!(
        a.until("still clear", |s| s["estop"]["latched"] == false)["estop"]["latched"],
        false
    );

    // The operator's commands reach the right cell and are acknowledged: a program on press-0
    // paused, resumed and aborted there; press-1 e-stopped, press-0 not.
    // Long enough (four long moves, aborted below) that a command sent while it moves still
    // finds it moving on a loaded host: the small triangle ended once before a pause came.
    let program = scratch(
        test,
        "long.prog",
        "MOVE(190,140,0)\nMOVE(10,10,0)\nMOVE(190,140,0)\nMOVE(10,10,0)\nEND\n",
    );
    ok(
        &hosts,
        &olga,
        &["exec", "press-0", program.to_str().expect("path")],
    );
    a.until("the program moving", crate::up::moving);
    let out = ok(&hosts, &olga, &["pause", "press-0"]);
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("paused"),
        "{}",
        text(&out)
    );
    a.until("paused", |s| s["supervisor"]["job"]["paused"] == true);
    ok(&hosts, &olga, &["resume", "press-0"]);
    a.until("resumed", |s| s["supervisor"]["job"]["paused"] == false);
    ok(&hosts, &olga, &["abort", "press-0"]);
    a.until("aborted", |s| s["supervisor"]["job"].is_null());

    // A client written from docs/network.md alone (Python, eclipse-zenoh) lists the cells,
    // reads a status and pauses a program; a viewer's pause refused by the gateway.
    let python = |user: &str, args: &[&str]| {
        // The secret line_file wrote beside the users file.
        let secret = users.with_file_name(format!("{user}.secret"));
        let mut cmd = Command::new("ip");
        cmd.args(["netns", "exec", &hosts.room, "python3"])
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("python/line_client.py"))
            .args([
                "--connect",
                "tcp/10.77.1.2:7447",
                "--connect",
                "tcp/10.77.2.2:7447",
            ])
            .args(["--user", user, "--secret-file"])
            .arg(secret)
            .args(args);
        run_with_watchdog(&mut cmd, WATCHDOG)
    };
    let out = python("victor", &["cells"]);
    assert!(out.status.success(), "python cells: {}", text(&out));
    let listed: Value = serde_json::from_slice(&out.stdout).expect("python cells JSON");
    assert_eq!(
        names(listed.as_array().expect("a list")),
        ["press-0", "press-1"]
    );
    let out = python("victor", &["status", "press-1"]);
    assert!(out.status.success(), "python status: {}", text(&out));
    let s: Value = serde_json::from_slice(&out.stdout).expect("python status JSON");
    assert_eq!(s["instance"], b.inst.as_str());
    let out = python("victor", &["pause", "press-0"]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "python viewer pause: {}",
        text(&out)
    );
    ok(
        &hosts,
        &olga,
        &["exec", "press-0", program.to_str().expect("path")],
    );
    a.until("the program moving", crate::up::moving);
    let out = python("olga", &["pause", "press-0"]);
    assert!(out.status.success(), "python pause: {}", text(&out));
    let answer: Value = serde_json::from_slice(&out.stdout).expect("python answer JSON");
    assert_eq!(answer["answer"], "done", "{answer}");
    a.until("paused by python", |s| {
        s["supervisor"]["job"]["paused"] == true
    });
    ok(&hosts, &olga, &["abort", "press-0"]);
    a.until("aborted", |s| s["supervisor"]["job"].is_null());

    // press-1's events as they happen, across its link: its e-stop's among them.
    let mut follow = Command::new("ip");
    follow
        .args(["netns", "exec", &hosts.room])
        .arg(integration_tests::bin("gateway"))
        .args(["line", "--json", "--line"])
        .arg(&victor)
        .args(["events", "press-1", "--seconds", "8"]);
    // It says READY=1 once the cell's gateway knows of its subscription (a round trip).
    let ready = integration_tests::Readiness::new("follower");
    let mut follower = ready
        .tell(&mut follow)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the follower");
    integration_tests::forward_stderr(&mut follower, "follower");
    ready.wait(&mut follower, WATCHDOG);
    ok(
        &hosts,
        &olga,
        &["estop", "press-1", "--reason", "from the room"],
    );
    let s = b.until("the e-stop latched", |s| s["estop"]["latched"] == true);
    assert!(
        s["estop"]["reason"]
            .as_str()
            .is_some_and(|r| r.contains("from the room")),
        "{}",
        s["estop"]
    );
    let followed =
        integration_tests::wait_output(follower, WATCHDOG, "the follower ends (--seconds 8)");
    let lines = String::from_utf8_lossy(&followed.stdout).to_string();
    assert!(
        followed.status.success(),
        "the follower: {}: {lines}",
        followed.status
    );
    assert!(
        lines
            .lines()
            .any(|l| l.contains("\"source\":\"servo\"") && l.contains("\"name\":\"estop-safe\"")),
        "press-1's events in the room: {lines}"
    );
    assert!(
        !lines.contains("\"lost\""),
        "nothing lost on a quiet line: {lines}"
    );
    assert_eq!(
        a.until("press-0 clear", |s| !s.is_null())["estop"]["latched"],
        false
    );

    // A control room's screen, watching the line from here on: the cells as they come and go.
    let mut watcher = following(&hosts, &victor, &["cells", "--watch"]);
    let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::<Value>::new()));
    let lines = std::io::BufReader::new(watcher.stdout.take().expect("piped"));
    let into = seen.clone();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in lines.lines().map_while(Result::ok) {
            if let (Ok(v), Ok(mut seen)) = (serde_json::from_str(&line), into.lock()) {
                seen.push(v);
            }
        }
    });
    // Each cell's comings and goings as the watcher saw them: (alive, when in ms since the
    // epoch).
    let of = |cell: &str| -> Vec<(bool, f64)> {
        seen.lock()
            .expect("seen")
            .iter()
            .filter(|e| e["cell"] == cell)
            .map(|e| (e["alive"] == true, e["time_ms"].as_f64().unwrap_or(0.0)))
            .collect()
    };
    let alive = |cell: &str| of(cell).iter().map(|e| e.0).collect::<Vec<_>>();
    let until_watched = |cell: &str, want: &[bool]| {
        let start = Instant::now();
        while alive(cell) != want {
            assert!(
                start.elapsed() < patience,
                "{cell} as watched: {:?}, not {want:?}",
                of(cell)
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    };
    until_watched("press-0", &[true]);
    until_watched("press-1", &[true]);
    let unix_ms = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64() * 1e3)
    };

    // press-1's gateway killed: it leaves the line, and comes back when the supervisor has
    // started it again (a non-critical process, restarted on failure).
    let s = b.until("the gateway running", |s| {
        process_in(s, "gateway")["pid"].is_u64()
    });
    let pid = process_in(&s, "gateway")["pid"].as_u64().expect("pid") as i32;
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(pid),
        nix::sys::signal::Signal::SIGKILL,
    )
    .expect("kill the gateway");
    let killed_ms = unix_ms();
    b.until("the gateway restarted", |s| {
        process_in(s, "gateway")["restarts"].as_u64() >= Some(1)
            && process_in(s, "gateway")["life"] == "running"
    });
    until_listed(&hosts, &victor, &["press-0", "press-1"], patience);

    // press-0's link cut: the room sees it go within the lease (and some), the cell runs on;
    // the link restored, it comes back.
    hosts.link(0, "down");
    let cut_ms = unix_ms();
    until_listed(&hosts, &victor, &["press-1"], patience);
    // The watcher, whose link to press-0 stays quiet, sees it go once the lease runs out.
    until_watched("press-0", &[true, false]);
    a.until("press-0 running on", |s| {
        process_in(s, "gateway")["life"] == "running"
    });
    hosts.link(0, "up");
    until_listed(&hosts, &victor, &["press-0", "press-1"], patience);
    // The watcher links to each cell again by itself (its retries are seconds apart).
    until_watched("press-1", &[true, false, true]);
    until_watched("press-0", &[true, false, true]);
    let _ = watcher.kill();
    let _ = watcher.wait();
    let (press_0, press_1) = (of("press-0"), of("press-1"));
    eprintln!(
        "the watcher saw press-1 leave {:.2} s after its gateway was killed, press-0 {:.2} s after its link was cut (lease {LEASE_S} s)",
        (press_1[1].1 - killed_ms) / 1e3,
        (press_0[1].1 - cut_ms) / 1e3
    );
    drop((a, b));
}

/// `ip netns exec NS PROGRAM ARGS` in the background, its stdout and stderr piped.
fn spawn_in(ns: &str, program: &str, args: &[&str]) -> std::process::Child {
    Command::new("ip")
        .args(["netns", "exec", ns])
        .arg(integration_tests::bin(program))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{program}: {e}"))
}

/// Asks a recorder to stop (SIGINT, as Ctrl-C), and waits for its summary.
fn stop_recorder(child: std::process::Child, what: &str) -> String {
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGINT,
    )
    .unwrap_or_else(|e| panic!("stop the {what}: {e}"));
    let out = integration_tests::wait_output(child, WATCHDOG, what);
    assert!(out.status.success(), "the {what}: {}", text(&out));
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// Per topic, samples a recorder's summary says it lost (`  /topic   N messages  L lost`).
fn lost_per_topic(summary: &str) -> std::collections::BTreeMap<String, u64> {
    summary
        .lines()
        .filter_map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            match w.as_slice() {
                [topic, _, "messages", lost, "lost"] if topic.starts_with('/') => {
                    Some((topic.to_string(), lost.parse().ok()?))
                }
                _ => None,
            }
        })
        .collect()
}

/// A line of one cell, press-0, up, and the line file of the viewer victor, who sees it
/// listed; the links' lease `lease` (s) on both sides.
fn one_cell_and_a_viewer(test: &str, lease: f64) -> (Hosts, Up, PathBuf) {
    let hosts = Hosts::new(test, 1);
    let users = private(test, "users.toml", USERS);
    let a = Up::start_in(
        &format!("{test}-a"),
        &with_lease(cell_config(test, 0, &users), Some("network"), lease),
        Some(&hosts.cells[0]),
    );
    let victor = with_lease(
        line_file(test, "victor", "victor", "victor-secret-0123456789", 1),
        None,
        lease,
    );
    until_listed(&hosts, &victor, &["press-0"], Duration::from_secs(30));
    (hosts, a, victor)
}

#[test]
fn a_remote_recording_equals_a_local_one_of_the_same_run() {
    // A viewer may record: recording is reading.
    // Two recorders of every service at once: on a loaded host their readers fall behind,
    // and the line's stream goes silent for seconds (lost samples, which the comparison
    // below allows for). A lease of 20 s gives that room: the remote recording takes the
    // cell for gone only after a silence as long.
    let (hosts, a, victor) = one_cell_and_a_viewer("line_rec", 20.0);
    let test = "line_rec";

    // On the cell's host, `supervisor record`; in the room, the same through the line. The
    // local one starts first and stops last: the remote's window lies inside it.
    let local_file = scratch(test, "local.mcap", "");
    let mut local = spawn_in(
        &hosts.cells[0],
        "supervisor",
        &[
            "record",
            "--instance",
            &a.inst,
            "--out",
            local_file.to_str().expect("path"),
        ],
    );
    let said = integration_tests::first_line(&mut local);
    assert!(said.starts_with("recording instance"), "{said}");
    let remote_file = scratch(test, "remote.mcap", "");
    let mut remote = Command::new("ip");
    remote
        .args(["netns", "exec", &hosts.room])
        .arg(integration_tests::bin("supervisor"))
        .args(["record", "--remote", "press-0", "--line"])
        .arg(&victor)
        .arg("--out")
        .arg(&remote_file)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut remote = integration_tests::Reaped::spawn(&mut remote, "the remote recorder");
    let said = integration_tests::first_line(&mut remote);
    assert!(said.starts_with("recording cell press-0 to"), "{said}");

    // A program runs while both record.
    let report = a.report(&integration_tests::small_triangle(test), &[]);
    assert_eq!(report["ok"], true, "{report}");
    let remote_summary = stop_recorder(remote.into_child(), "remote recorder");
    let local_summary = stop_recorder(local, "local recorder");
    println!("local:\n{local_summary}remote:\n{remote_summary}");

    let mut compare = Command::new("python3");
    compare
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("python/mcap_compare.py"))
        .arg(&local_file)
        .arg(&remote_file);
    let out = run_with_watchdog(&mut compare, WATCHDOG);
    assert!(out.status.success(), "mcap_compare: {}", text(&out));
    let c: Value = serde_json::from_slice(&out.stdout).expect("the comparison's JSON");
    // The same channels: topics, schemas and encodings, to the byte.
    assert_eq!(c["channels_local"], c["channels_remote"]);
    assert!(
        c["channels_local"].as_array().map_or(0, Vec::len) >= 20,
        "{}",
        c["channels_local"]
    );
    // The same samples: over the remote's window, each topic's messages are the local's,
    // byte for byte and one unbroken run; a topic either recorder lost samples of (its
    // reader stalled past its buffer: a host stall, which each summary counts) needs only
    // the messages both have in the same order.
    let (lost_l, lost_r) = (
        lost_per_topic(&local_summary),
        lost_per_topic(&remote_summary),
    );
    for (topic, t) in c["topics"].as_object().expect("topics") {
        // The latency summaries are sampled: each reader takes the newest of a process'
        // histogram when it looks (two kept, none numbered), so two readers may take
        // different ones, and each one holds everything before it.
        let sampled = topic.ends_with("/latency")
            || topic.ends_with("/exec_time")
            || topic == "/drives/sense_to_command";
        if sampled {
            continue;
        }
        let remote_n = t["remote"].as_u64().expect("count");
        // A topic several processes publish on (the events, the e-stops, the motion
        // control) reaches each reader in an order of its own across its publishers: the
        // same messages, in any order.
        let several = ["/events", "/estop", "/trajgen/control"].contains(&topic.as_str());
        let matched = t[if several { "contained" } else { "matched" }]
            .as_u64()
            .expect("count");
        let (lost_here, lost_there) = (
            lost_l.get(topic).copied().unwrap_or(0),
            lost_r.get(topic).copied().unwrap_or(0),
        );
        if lost_here + lost_there == 0 {
            assert_eq!(matched, remote_n, "{topic}: {t}");
            assert!(several || t["run"] == true, "{topic}: {t}");
        } else {
            // What the local one lost is all the remote has beyond it.
            assert!(matched + lost_here >= remote_n, "{topic}: {t}");
            println!("{topic}: {lost_here} lost here, {lost_there} there (a reader stalled)");
        }
    }
    for topic in [
        "/trajgen/setpoint",
        "/servo/state",
        "/drives/feedback",
        "/trajgen/command",
    ] {
        assert!(
            c["topics"][topic]["remote"].as_u64() > Some(0),
            "{topic}: {}",
            c["topics"][topic]
        );
    }
    // The program's motion whole in both: every one of its setpoints.
    let programs = c["programs"].as_object().expect("programs");
    let ran = programs.values().collect::<Vec<_>>();
    assert_eq!(ran.len(), 1, "one program ran: {programs:?}");
    let setpoints_lost = lost_l.get("/trajgen/setpoint").copied().unwrap_or(0)
        + lost_r.get("/trajgen/setpoint").copied().unwrap_or(0);
    if setpoints_lost == 0 {
        assert_eq!(ran[0]["local"], ran[0]["remote"], "{programs:?}");
    }
    assert!(ran[0]["local"].as_u64() > Some(100), "{programs:?}");
    // Log times: a sample's own stamp, mapped to the Unix epoch by each recorder's clock; the
    // read time where the sample has none (the program's commands).
    println!(
        "the remote recording: {} topics, its messages the local one's; log times apart by at most {} ns on /servo/state, {} ns on /trajgen/command",
        c["topics"].as_object().map_or(0, |t| t.len()),
        c["topics"]["/servo/state"]["max_log_time_ns"],
        c["topics"]["/trajgen/command"]["max_log_time_ns"],
    );
    drop(a);
}

#[test]
fn an_event_burst_reaches_the_room_whole_or_says_how_many_were_lost() {
    let (hosts, a, victor) = one_cell_and_a_viewer("line_burst", LEASE_S);
    let mut follower = following(&hosts, &victor, &["events", "press-0"]);
    // What the room saw: burst events, and how many it was told were lost.
    let seen = std::sync::Arc::new(std::sync::Mutex::new((0u64, 0u64, false)));
    let lines = std::io::BufReader::new(follower.stdout.take().expect("piped"));
    let into = seen.clone();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in lines.lines().map_while(Result::ok) {
            let Ok(v) = serde_json::from_str::<Value>(&line) else {
                continue;
            };
            let Ok(mut seen) = into.lock() else {
                return;
            };
            // The test's own events, told apart by their value: -1 the warm-up, k the
            // burst's k-th.
            if let Some(n) = v["lost"].as_u64() {
                seen.1 += n;
            } else if v["value"].as_f64().is_some_and(|k| k >= 1.0) {
                seen.0 += 1;
            } else if v["value"].as_f64() == Some(-1.0) {
                seen.2 = true;
            }
        }
    });
    let seen = || *seen.lock().expect("seen");
    let instance = shm_schema::InstanceName::new(&a.inst).expect("instance");
    let node = runtime::ipc::node(&instance, "burst").expect("node");
    let events: runtime::ipc::Pub<shm_schema::EventV1> =
        runtime::ipc::Pub::new(&node, &instance, shm_schema::ServiceId::Events).expect("pub");
    let event = |source: u32, seq: u64, value: f64, text: &str| {
        let mut e = shm_schema::EventV1::new(
            runtime::time::now_ns(),
            shm_schema::event::code::LISTENING,
            -1,
            value,
            0.0,
            &[text],
        );
        e.source = source;
        e.seq = seq;
        e
    };
    // The gateway takes this new publisher's events once it has connected to it, and the
    // room follows once its subscription is known: a warm-up event until one arrives.
    let start = Instant::now();
    let mut seq = 0;
    loop {
        seq += 1;
        events.send(&event(77, seq, -1.0, "warm-up"));
        std::thread::sleep(Duration::from_millis(50));
        if seen().2 {
            break;
        }
        assert!(
            start.elapsed() < WATCHDOG,
            "no warm-up event reached the room"
        );
    }
    // A burst from the same source, its numbers going on: far more at once than the
    // gateway's subscriber holds between two of its cycles (1 024). What iceoryx2 refuses
    // to publish is not the line's to report.
    let mut published = 0u64;
    for k in 1..=5_000u64 {
        if events.send(&event(77, seq + k, k as f64, &format!("burst {k}"))) {
            published += 1;
        }
    }
    const BURST: u64 = 5_000;
    println!("{published} of a burst of {BURST} published");
    // Every event of the burst arrives, or the room is told how many did not.
    let start = Instant::now();
    while seen().0 + seen().1 < published {
        assert!(
            start.elapsed() < WATCHDOG,
            "{} arrived, {} said lost, of {published}",
            seen().0,
            seen().1
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let (arrived, said_lost, _) = seen();
    println!("an event burst of {published}: {arrived} reached the room, {said_lost} said lost");
    assert!(arrived > 0);
    let _ = follower.kill();
    let _ = follower.wait();
    drop(events);
    drop(node);
    runtime::ipc::cleanup_after_client(&instance);
    drop(a);
}

#[test]
fn the_line_s_web_view_lists_its_cells_and_shows_the_one_chosen() {
    let (hosts, a, victor) = one_cell_and_a_viewer("line_web", LEASE_S);
    // In the room, a host with no cell: the line's page.
    let mut web = Command::new("ip");
    web.args(["netns", "exec", &hosts.room])
        .arg(integration_tests::bin("supervisor"))
        .args(["web", "--listen", "127.0.0.1:0", "--line"])
        .arg(&victor)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut web = integration_tests::Reaped::spawn(&mut web, "supervisor web --line");
    let said = integration_tests::first_line(&mut web);
    let base = said
        .trim()
        .strip_prefix("serving the line on ")
        .unwrap_or_else(|| panic!("{said}"))
        .trim_end_matches('/')
        .to_string();
    let mut page = Command::new("ip");
    page.args(["netns", "exec", &hosts.room, "node"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("web/line_page.mjs"))
        .args([base.as_str(), "press-0"]);
    let out = run_with_watchdog(&mut page, WATCHDOG);
    assert!(out.status.success(), "line_page: {}", text(&out));
    let j: Value = serde_json::from_slice(&out.stdout).expect("line_page's JSON");
    // The list: press-0, enabled.
    let list = &j["list"][0];
    assert_eq!(list["kind"], "cells", "{j}");
    assert_eq!(list["cells"][0]["cell"], "press-0", "{j}");
    assert_eq!(list["cells"][0]["state"], "enabled", "{j}");
    // The cell chosen: its description (the gantry's axes), then frames of the cell up, where
    // its status says it stands.
    let view = j["cell"].as_array().expect("messages");
    let hello = view
        .iter()
        .find(|m| m["kind"] == "hello")
        .unwrap_or_else(|| panic!("no hello: {j}"));
    let axes: Vec<&str> = (hello["axes"].as_array().expect("axes").iter())
        .filter_map(|a| a["name"].as_str())
        .collect();
    assert_eq!(axes, ["x", "y", "theta"], "{hello}");
    let status = a.until("at rest", |s| {
        s["servo"]["axes"]["x"]["position"].is_number()
    });
    let frames: Vec<&Value> = view.iter().filter(|m| m["kind"] == "frame").collect();
    assert!(!frames.is_empty(), "{j}");
    for f in &frames {
        assert_eq!(f["up"], true, "{f}");
        for (k, axis) in ["x", "y", "theta"].iter().enumerate() {
            let want = status["servo"]["axes"][axis]["position"]
                .as_f64()
                .expect("position");
            let got = f["joints"][k].as_f64().expect("a joint");
            assert!((got - want).abs() < 1e-3, "{axis}: {got} against {want}");
        }
    }
    // A name that is none is refused; the buttons only on the cell's own view.
    assert_eq!(j["unknown"][0]["refused"], 404, "{j}");
    assert_eq!(j["estop"]["status"], 403, "{j}");
    assert!(
        j["estop"]["text"]
            .as_str()
            .is_some_and(|t| t.contains("supervisor estop --remote press-0")),
        "{j}"
    );
    assert_eq!(a.status()["estop"]["latched"], false);
    // The page itself, in Chromium in the room: the cell's view draws the machine, with a
    // way back to the list; the list links each cell to its view.
    let (mut browser, ready) =
        crate::web::Browser::open_in(Some(&hosts.room), &format!("{base}/?cell=press-0"));
    assert_eq!(ready["errors"], serde_json::json!([]), "{ready}");
    let back = browser.ask("eval document.getElementById('cells').textContent");
    assert!(
        back["value"]
            .as_str()
            .is_some_and(|t| t.contains("every cell of the line")),
        "{back}"
    );
    browser.ask(&format!("goto {base}/"));
    browser.ask("until rtc.cells && rtc.cells.length === 1");
    let link = browser.ask("eval document.querySelector('#cells a').getAttribute('href')");
    assert_eq!(link["value"], "/?cell=press-0", "{link}");
    let bye = browser.ask("quit");
    assert_eq!(bye["errors"], serde_json::json!([]), "{bye}");
    drop(browser);
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(web.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .expect("stop the page");
    let out =
        integration_tests::wait_output(web.into_child(), WATCHDOG, "supervisor web --line stops");
    assert!(out.status.success(), "{}", text(&out));
    drop(a);
}

/// Runs `openssl` with `args` in `dir`; it must succeed.
fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl")
        .current_dir(dir)
        .args(args)
        .output()
        .expect("this test makes certificates with openssl (apt-get install openssl)");
    assert!(out.status.success(), "openssl {args:?}: {}", text(&out));
}

/// In `dir`: a certificate authority `<ca>.pem` (made unless there), and `<name>.pem` and
/// its key signed by it for IP `ip`; the key its owner's alone.
fn certificate(dir: &Path, ca: &str, name: &str, ip: &str) {
    let ec = [
        "-newkey",
        "ec",
        "-pkeyopt",
        "ec_paramgen_curve:P-256",
        "-nodes",
    ];
    let (ca_key, ca_pem) = (format!("{ca}.key"), format!("{ca}.pem"));
    if !dir.join(&ca_pem).exists() {
        let subj = format!("/CN={ca}");
        let mut args = vec!["req", "-x509"];
        args.extend(ec);
        args.extend([
            "-days", "30", "-subj", &subj, "-keyout", &ca_key, "-out", &ca_pem,
        ]);
        openssl(dir, &args);
    }
    let (key, csr, pem) = (
        format!("{name}.key"),
        format!("{name}.csr"),
        format!("{name}.pem"),
    );
    let subj = format!("/CN={name}");
    let mut args = vec!["req"];
    args.extend(ec);
    args.extend(["-subj", &subj, "-keyout", &key, "-out", &csr]);
    openssl(dir, &args);
    let san = dir.join(format!("{name}.san"));
    std::fs::write(&san, format!("subjectAltName=IP:{ip}\n")).expect("san");
    openssl(
        dir,
        &[
            "x509",
            "-req",
            "-in",
            &csr,
            "-CA",
            &ca_pem,
            "-CAkey",
            &ca_key,
            "-CAcreateserial",
            "-days",
            "30",
            "-extfile",
            san.to_str().expect("path"),
            "-out",
            &pem,
        ],
    );
    std::fs::set_permissions(dir.join(&key), std::fs::Permissions::from_mode(0o600))
        .expect("chmod");
}

#[test]
fn a_line_on_mutual_tls_and_passwords_lets_in_only_its_own() {
    let test = "line_tls";
    let hosts = Hosts::new(test, 1);
    let users = private(test, "users.toml", USERS);
    let dir = users.parent().expect("scratch folder").to_path_buf();
    certificate(&dir, "line-ca", "press-0", "10.77.1.2");
    certificate(&dir, "line-ca", "room", "10.77.1.1");
    // A certificate the line's authority never signed.
    certificate(&dir, "other-ca", "stranger", "10.77.1.1");
    private(test, "press-0.password", "press-0-password\n");
    private(test, "passwords", "room:room-password\n");
    let at = |f: &str| dir.join(f).display().to_string();
    let more = [
        (
            "tls",
            table(&[
                ("root_ca", value(at("line-ca.pem"))),
                ("certificate", value(at("press-0.pem"))),
                ("private_key", value(at("press-0.key"))),
            ]),
        ),
        (
            "login",
            table(&[
                ("user", value("press-0")),
                ("password_file", value(at("press-0.password"))),
                ("dictionary_file", value(at("passwords"))),
            ]),
        ),
    ];
    let cfg = cell_config_with(test, 0, &users, "tls", &more);
    let cell = Up::start_in(&format!("{test}-c"), &cfg, Some(&hosts.cells[0]));
    let room_file = |name: &str, cert: &str, password: &str| {
        private(test, &format!("{name}.password"), &format!("{password}\n"));
        scratch(
            test,
            &format!("{name}.line.toml"),
            &format!(
                "connect = [\"tls/10.77.1.2:7447\"]\n\n[tls]\nroot_ca = \"{}\"\n\
                 certificate = \"{}\"\nprivate_key = \"{}\"\n\n\
                 [login]\nuser = \"room\"\npassword_file = \"{}\"\n",
                at("line-ca.pem"),
                at(&format!("{cert}.pem")),
                at(&format!("{cert}.key")),
                at(&format!("{name}.password"))
            ),
        )
    };
    // The line's own: its authority's certificate and the room's password.
    let own = room_file("own", "room", "room-password");
    until_listed(&hosts, &own, &["press-0"], Duration::from_secs(30));
    // Refused at the link, and said so: a certificate of another authority, a wrong password.
    for (name, cert, password) in [
        ("stranger", "stranger", "room-password"),
        ("guesser", "room", "not-the-password"),
    ] {
        let out = room(&hosts, &room_file(name, cert, password), &["cells"]);
        assert_eq!(out.status.code(), Some(1), "{name}: {}", text(&out));
        assert!(
            String::from_utf8_lossy(&out.stderr)
                .contains("no endpoint of the line let this client in"),
            "{name}: {}",
            text(&out)
        );
    }
    // The endpoint in the clear is no way in either.
    let clear = scratch(
        test,
        "clear.line.toml",
        "connect = [\"tcp/10.77.1.2:7447\"]\nplain = true\n",
    );
    let out = room(&hosts, &clear, &["cells"]);
    assert_eq!(out.status.code(), Some(1), "in the clear: {}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("no endpoint of the line let this client in"),
        "in the clear: {}",
        text(&out)
    );

    // A rogue host with the line's authority and the room's password (a compromised host),
    // its certificate naming it press-9, publishes events under press-0's name and its own.
    certificate(&dir, "line-ca", "press-9", "127.0.0.1");
    let mut rogue = Command::new("ip");
    rogue
        .args(["netns", "exec", &hosts.room, "python3"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("python/rogue_cell.py"))
        .args(["--listen", "tls/127.0.0.1:7450", "--ca", &at("line-ca.pem")])
        .args(["--cert", &at("press-9.pem"), "--key", &at("press-9.key")])
        .args(["--dictionary", &at("passwords")])
        .args(["--victim", "press-0", "--own", "press-9"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut rogue = integration_tests::Reaped::spawn(&mut rogue, "the rogue");
    let said = integration_tests::first_line(&mut rogue);
    assert_eq!(said.trim(), "ready", "the rogue: {said}");
    // The room joined to both, without and with the list of its cells (Zenoh's access
    // control: only the cell whose certificate names it may publish under its name).
    let joined = |name: &str, cells: &str| {
        private(test, &format!("{name}.password"), "room-password\n");
        scratch(
            test,
            &format!("{name}.line.toml"),
            &format!(
                "connect = [\"tls/10.77.1.2:7447\", \"tls/127.0.0.1:7450\"]\n{cells}\n[tls]\n\
                 root_ca = \"{}\"\ncertificate = \"{}\"\nprivate_key = \"{}\"\n\n\
                 [login]\nuser = \"room\"\npassword_file = \"{}\"\n",
                at("line-ca.pem"),
                at("room.pem"),
                at("room.key"),
                at(&format!("{name}.password"))
            ),
        )
    };
    let events = |file: &Path, cell: &str| {
        let out = ok(&hosts, file, &["events", cell, "--seconds", "2", "--json"]);
        String::from_utf8_lossy(&out.stdout).to_string()
    };
    // Without it the forgery gets through: the room takes what comes on press-0's key.
    let trusting = joined("trusting", "");
    let seen = events(&trusting, "press-0");
    assert!(
        seen.contains("forged by press-9"),
        "without access control: {seen}"
    );
    // With it, press-9 publishes under its own name, and nothing under press-0's.
    let guarded = joined("guarded", "cells = [\"press-0\", \"press-9\"]");
    let seen = events(&guarded, "press-9");
    assert!(
        seen.contains("press-9's own"),
        "press-9 under its own name: {seen}"
    );
    let seen = events(&guarded, "press-0");
    assert!(!seen.contains("forged"), "with access control: {seen}");
    // press-0 itself is still read: its status crossed the guarded link.
    let out = ok(&hosts, &guarded, &["status", "press-0", "--json"]);
    let s: Value = serde_json::from_slice(&out.stdout).expect("status JSON");
    assert_eq!(s["instance"], cell.inst.as_str(), "{s}");
    // A list of cells without certificates to know them by is refused before anything.
    let bare = scratch(
        test,
        "bare.line.toml",
        "connect = [\"tcp/10.77.1.2:7447\"]\nplain = true\ncells = [\"press-0\"]\n",
    );
    let out = room(&hosts, &bare, &["cells"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr)
            .contains("cells: the access control knows the cells by their certificates"),
        "{}",
        text(&out)
    );
    let _ = rogue.kill();
    let _ = rogue.wait();
}

#[test]
fn a_gateway_whose_users_file_others_may_read_stays_off_the_line_and_says_why() {
    let test = "line_users";
    let hosts = Hosts::new(test, 1);
    // Written as any file is: others may read it.
    let users = scratch(test, "users.toml", USERS);
    let cell = Up::start_in(test, &cell_config(test, 0, &users), Some(&hosts.cells[0]));
    // The cell runs on, its gateway off the line: `status` says why (its `listen-failed`).
    let s = cell.until("the gateway running and off the line", |s| {
        let gateway = process_in(s, "gateway");
        gateway["life"] == "running" && gateway["listen_failed"].is_string()
    });
    let gateway = process_in(&s, "gateway");
    assert!(gateway["listening"].is_null(), "{s}");
    assert!(
        gateway["listen_failed"]
            .as_str()
            .is_some_and(|w| w.starts_with("the line: ")),
        "{s}"
    );
    let room = line_file(test, "victor", "victor", "victor-secret-0123456789", 1);
    let out = self::room(&hosts, &room, &["cells"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    // The log has the whole sentence (the gateway's own line: whole once the cell is down).
    let log = cell.down();
    assert!(
        log.contains("the line: ") && log.contains("others than its owner may read it"),
        "{log}"
    );
}
