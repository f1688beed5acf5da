//! `supervisor up` for the tests: a long-running cell in the background and the control CLI
//! against it.

use crate::drives::WATCHDOG;
use control_plane::info::{Info, ProcessInfo};
use control_plane::status::Status;
use control_plane::{Failure, Refusal, Replaced, Reply};
use integration_tests::{
    assert_clean, instance, run_with_watchdog, scratch, supervisor, wait_output,
};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// `supervisor up` in the background, its log in a file; SIGTERM and wait on drop, so a
/// failing test leaves no cell behind.
pub(crate) struct Up {
    pub(crate) inst: String,
    pub(crate) child: Option<Child>,
    log: PathBuf,
    /// Where `up --json` writes how it ended and the cell's events ([`Up::down_events`]);
    /// `None` for an `up` the test started itself.
    ended: Option<PathBuf>,
    /// The command the cell and every command run under (`ip netns exec NS` for an EtherCAT
    /// cell's network namespace, `nsenter` for a mount namespace), if any: program, arguments.
    within: Vec<String>,
}

/// `supervisor`, under the command `within` (program and arguments) if there is one.
fn supervisor_within(within: &[String]) -> Command {
    match within.split_first() {
        Some((program, args)) => {
            let mut c = Command::new(program);
            c.args(args).arg(integration_tests::bin("supervisor"));
            c
        }
        None => supervisor(),
    }
}

impl Up {
    pub(crate) fn start(test: &str, cfg: &Path) -> Self {
        Self::start_in(test, cfg, None)
    }

    /// [`Up::start`] of the default cell on the virtual clock ([`cell`], nothing set).
    pub(crate) fn default_cell(test: &str) -> Self {
        Self::start(test, &cell(test, &[]))
    }

    /// [`Up::default_cell`] on the wall clock: for a test of timing (stalls, overruns).
    pub(crate) fn on_the_wall_clock(test: &str) -> Self {
        Self::start(test, &wall_cell(test, &[]))
    }

    /// [`Up::start`] in network namespace `netns` (every command of the test then runs
    /// there too).
    pub(crate) fn start_in(test: &str, cfg: &Path, netns: Option<&str>) -> Self {
        let within = netns.map_or(vec![], |ns| vec!["ip", "netns", "exec", ns]);
        Self::start_within(test, cfg, &within)
    }

    /// [`Up::start`] under the command `within` (program and arguments: `nsenter -t PID -m`),
    /// as every command of the test then runs.
    pub(crate) fn start_within(test: &str, cfg: &Path, within: &[&str]) -> Self {
        Self::launch(test, cfg, within, &[])
    }

    /// [`Up::start`] with `up --record FILE`.
    pub(crate) fn start_recording(test: &str, cfg: &Path, file: &Path) -> Self {
        Self::launch(test, cfg, &[], &["--record".as_ref(), file.as_os_str()])
    }

    /// `up` of `cfg` under `within` with the arguments `more`, once it said it is ready and
    /// its drives are enabled.
    fn launch(test: &str, cfg: &Path, within: &[&str], more: &[&std::ffi::OsStr]) -> Self {
        let within: Vec<String> = within.iter().map(|a| a.to_string()).collect();
        let inst = instance(test);
        let log = scratch(test, "up.log", "");
        let ended = scratch(test, "up.json", "");
        // `up` says READY=1 once its control channel answers (docs/operations.md).
        let ready = integration_tests::Readiness::new("up");
        let child = ready
            .tell(&mut supervisor_within(&within))
            .args(["up", "--json", "--instance", &inst, "--config"])
            .arg(cfg)
            .args(more)
            .stdout(std::fs::File::create(&ended).expect("up.json"))
            .stderr(std::fs::File::create(&log).expect("log"))
            .spawn()
            .expect("supervisor up");
        let mut up = Self {
            inst,
            child: Some(child),
            log,
            ended: Some(ended),
            within,
        };
        if let Some(child) = up.child.as_mut() {
            ready.wait(child, WATCHDOG);
        }
        up.wait_enabled();
        up
    }

    pub(crate) fn command(&self) -> Command {
        supervisor_within(&self.within)
    }

    /// A `supervisor up` of `inst` started by the caller (its stderr into `log`), once the
    /// drives are enabled.
    pub(crate) fn adopt(inst: String, child: Child, log: PathBuf) -> Self {
        let mut up = Self {
            inst,
            child: Some(child),
            log,
            ended: None,
            within: vec![],
        };
        up.wait_enabled();
        up
    }

    /// Up once the drives are enabled and holding.
    fn wait_enabled(&mut self) {
        self.until_typed("the drives enabled", enabled);
    }

    pub(crate) fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// `supervisor <args> --instance <inst>`, under the watchdog.
    pub(crate) fn ctl(&self, args: &[&str]) -> Output {
        let mut cmd = self.command();
        cmd.args(args).args(["--instance", &self.inst]);
        run_with_watchdog(&mut cmd, WATCHDOG)
    }

    /// `out` of `what`, a command against the cell, which must have succeeded: else a panic
    /// with its exit status, its stdout and stderr, and the cell's log.
    pub(crate) fn succeeded(&self, out: Output, what: &str) -> Output {
        assert!(
            out.status.success(),
            "{what}: {}\n{}\n{}\nlog:\n{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
            self.log()
        );
        out
    }

    /// Like [`Up::ctl`], and it must succeed; its stdout.
    pub(crate) fn ok(&self, args: &[&str]) -> String {
        let out = self.succeeded(self.ctl(args), &format!("{args:?}"));
        String::from_utf8_lossy(&out.stdout).to_string()
    }

    /// Like [`Up::ctl`], and it must exit with `code`; its stderr.
    fn exits(&self, args: &[&str], code: i32) -> String {
        let out = self.ctl(args);
        let err = String::from_utf8_lossy(&out.stderr).to_string();
        assert_eq!(
            out.status.code(),
            Some(code),
            "{args:?}: {}{err}",
            String::from_utf8_lossy(&out.stdout)
        );
        err
    }

    /// Like [`Up::ctl`], and it must be refused (exit 2); its stderr.
    pub(crate) fn refused(&self, args: &[&str]) -> String {
        self.exits(args, 2)
    }

    /// Like [`Up::ctl`], and it must fail (exit 1); its stderr.
    pub(crate) fn fails(&self, args: &[&str]) -> String {
        self.exits(args, 1)
    }

    /// `supervisor <args> --json --instance <inst>`, under the watchdog: the cell's reply,
    /// typed, and the command's stderr. Its exit status must be the reply's (0 done, 2
    /// refused, 1 failed).
    pub(crate) fn reply(&self, args: &[&str]) -> (Reply, String) {
        let mut with_json = args.to_vec();
        with_json.push("--json");
        let out = self.ctl(&with_json);
        let stdout = String::from_utf8_lossy(&out.stdout);
        let err = String::from_utf8_lossy(&out.stderr).to_string();
        let reply: Reply = serde_json::from_str(stdout.trim()).unwrap_or_else(|e| {
            panic!(
                "{args:?} --json: not a Reply ({e}), {}:\n{stdout}{err}\nlog:\n{}",
                out.status,
                self.log()
            )
        });
        let code = match reply {
            Reply::Refused(_) => 2,
            Reply::Failed(_) => 1,
            _ => 0,
        };
        assert_eq!(out.status.code(), Some(code), "{args:?}: {reply:?}\n{err}");
        (reply, err)
    }

    /// [`Up::reply`], which must be a refusal (exit 2): why, as its variant.
    pub(crate) fn refusal(&self, args: &[&str]) -> Refusal {
        match self.reply(args) {
            (Reply::Refused(r), _) => r,
            (other, err) => panic!("{args:?}: not refused: {other:?}\n{err}"),
        }
    }

    /// [`Up::reply`], which must be a failure (exit 1): why, as its variant.
    pub(crate) fn failure(&self, args: &[&str]) -> Failure {
        match self.reply(args) {
            (Reply::Failed(f), _) => f,
            (other, err) => panic!("{args:?}: not failed: {other:?}\n{err}"),
        }
    }

    /// [`Up::reply`], which must be done (exit 0): its line for the user.
    pub(crate) fn done(&self, args: &[&str]) -> String {
        match self.reply(args) {
            (Reply::Done(m), _) => m,
            (other, err) => panic!("{args:?}: not done: {other:?}\n{err}\nlog:\n{}", self.log()),
        }
    }

    /// [`Up::reply`] of a `swap` or a `restart`, which must have replaced the process (exit
    /// 0): the replacement's data.
    pub(crate) fn replaced(&self, args: &[&str]) -> Replaced {
        match self.reply(args) {
            (Reply::Replaced(r), _) => *r,
            (other, err) => panic!(
                "{args:?}: not replaced: {other:?}\n{err}\nlog:\n{}",
                self.log()
            ),
        }
    }

    /// SIGKILLs the cell's process `name` (by the pid `status` gives); its pid.
    pub(crate) fn kill(&self, name: &str) -> i64 {
        let pid = process_of(&self.status_typed(), name)
            .pid
            .unwrap_or_else(|| panic!("{name}'s pid"));
        let pid = i64::from(pid);
        nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(pid as i32),
            nix::sys::signal::Signal::SIGKILL,
        )
        .unwrap_or_else(|e| panic!("kill {name}: {e}"));
        pid
    }

    /// `reset`, then `start`, which must succeed.
    pub(crate) fn reset_and_start(&self) {
        self.ok(&["reset"]);
        self.ok(&["start"]);
    }

    /// `exec PROGRAM --wait --json EXTRA`, under the watchdog.
    pub(crate) fn exec_wait(&self, program: &Path, extra: &[&str]) -> Output {
        let mut args = vec!["exec", program.to_str().expect("utf-8"), "--wait", "--json"];
        args.extend_from_slice(extra);
        self.ctl(&args)
    }

    /// [`Up::exec_wait`], which must succeed: the run's report.
    pub(crate) fn report(&self, program: &Path, extra: &[&str]) -> Value {
        let what = format!("exec {} --wait --json {extra:?}", program.display());
        let out = self.succeeded(self.exec_wait(program, extra), &what);
        serde_json::from_slice(&out.stdout).expect("the run's report")
    }

    /// `status --json`, checked against its type (every key known, none missing: the
    /// document its JSON Schema describes).
    pub(crate) fn status(&self) -> Value {
        let out = self.ok(&["status", "--json"]);
        let typed: Result<control_plane::status::Status, _> = serde_json::from_str(out.trim());
        if let Err(e) = typed {
            panic!("status --json is not the documented Status ({e}):\n{out}");
        }
        serde_json::from_str(out.trim()).expect("status JSON")
    }

    /// `status --json`, typed (every key known, none missing).
    pub(crate) fn status_typed(&self) -> Status {
        let out = self.ok(&["status", "--json"]);
        serde_json::from_str(out.trim())
            .unwrap_or_else(|e| panic!("status --json is not the documented Status ({e}):\n{out}"))
    }

    /// [`Up::until`] on the typed status. A document that is not the documented `Status`
    /// fails at once.
    pub(crate) fn until_typed(&self, what: &str, pred: impl Fn(&Status) -> bool) -> Status {
        let v = self.until(what, |v| pred(&typed(v)));
        typed(&v)
    }

    /// Polls `status --json` until `pred` holds, under the watchdog.
    pub(crate) fn until(&self, what: &str, pred: impl Fn(&Value) -> bool) -> Value {
        poll_status(&self.within, &self.inst, pred).unwrap_or_else(|out| {
            let stuck = match &self.child {
                Some(c) => integration_tests::where_stuck(c.id()),
                None => String::new(),
            };
            panic!(
                "{what}: never happened\nlast status ({}):\n{}{}\nlog:\n{}\n{stuck}\nfiles: {:?}",
                out.status,
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr),
                self.log(),
                integration_tests::leftovers(&self.inst)
            )
        })
    }

    /// Polls the control channel's `Info` (under the watchdog) until a swap of `process`
    /// shows, then asks `req` at once: its answer, given while the swap runs.
    pub(crate) fn during_swap_of(
        &self,
        process: &str,
        req: &control_plane::Request,
    ) -> Result<control_plane::Reply, control_plane::channel::CallError> {
        let instance = shm_schema::InstanceName::new(&self.inst).expect("instance");
        let start = Instant::now();
        loop {
            assert!(start.elapsed() < WATCHDOG, "the swap never showed in Info");
            match control_plane::channel::call(&instance, &control_plane::Request::Info) {
                Ok(control_plane::Reply::Info(info)) if info.swapping.is_some() => {
                    assert_eq!(info.swapping.as_deref(), Some(process), "{info:?}");
                    return control_plane::channel::call(&instance, req);
                }
                Ok(control_plane::Reply::Info(_)) => {}
                other => panic!("Info during a swap: {other:?}"),
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// `supervisor <args> --instance <inst>` in the background, its output piped.
    pub(crate) fn spawn(&self, args: &[&str]) -> Child {
        self.command()
            .args(args)
            .args(["--instance", &self.inst])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("{args:?}: {e}"))
    }

    /// The cell's events from now on, as `supervisor events --follow --json` gives them
    /// (typed), once its subscriber is attached (the events service has one more: an event
    /// published from then on reaches it).
    pub(crate) fn follow_events(&self) -> Events {
        use runtime::ipc;
        let instance = shm_schema::InstanceName::new(&self.inst).expect("instance");
        let node = ipc::node(&instance, &format!("test-{}", std::process::id())).expect("node");
        let count = || ipc::events_subscribers(&node, &instance);
        let before = count().expect("the events service");
        let mut child = self.spawn(&["events", "--follow", "--json"]);
        let lines = std::io::BufReader::new(child.stdout.take().expect("piped"));
        let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let into = seen.clone();
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in lines.lines().map_while(Result::ok) {
                let e: control_plane::event::Event =
                    serde_json::from_str(&line).unwrap_or_else(|e| panic!("{line}: {e}"));
                into.lock().expect("events").push(e);
            }
        });
        let start = Instant::now();
        while count().expect("the events service") <= before {
            assert!(
                start.elapsed() < WATCHDOG,
                "the events follower never attached"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        drop(node);
        Events {
            child,
            seen,
            from: 0,
        }
    }

    /// `exec --wait --json PROGRAM` in the background, its output piped.
    pub(crate) fn exec_in_background(&self, program: impl AsRef<std::ffi::OsStr>) -> Child {
        self.command()
            .args(["exec", "--wait", "--json", "--instance", &self.inst])
            .arg(program)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("exec")
    }

    /// `down`, then the supervisor exits 0 and nothing of the instance is left; its log.
    pub(crate) fn down(mut self) -> String {
        self.ok(&["down"]);
        self.ended("down")
    }

    /// [`Up::down`], and every event of the cell's life as `up --json` gave them as it ended
    /// (those of its going down included).
    pub(crate) fn down_events(self) -> (String, Vec<control_plane::event::Event>) {
        self.events_after(Self::down)
    }

    /// [`Up::terminate`], and every event of the cell's life, as [`Up::down_events`].
    pub(crate) fn terminate_events(self) -> (String, Vec<control_plane::event::Event>) {
        self.events_after(Self::terminate)
    }

    /// Once `up` ended by itself (a `down` or a signal another process sent): it exits 0
    /// and nothing of the instance is left; its log.
    pub(crate) fn wait_ended(mut self) -> String {
        self.ended("its end")
    }

    /// [`Up::wait_ended`], and every event of the cell's life, as [`Up::down_events`].
    pub(crate) fn ended_events(self) -> (String, Vec<control_plane::event::Event>) {
        self.events_after(Self::wait_ended)
    }

    /// `end`'s log of `up`, and every event of the cell's life from `up --json`'s document.
    fn events_after(
        self,
        end: impl FnOnce(Self) -> String,
    ) -> (String, Vec<control_plane::event::Event>) {
        let ended = self.ended.clone();
        let log = end(self);
        let events = read_ended(ended.as_deref(), &log);
        (log, events)
    }

    /// SIGTERM to the supervisor, then it exits 0 and nothing of the instance is left; its
    /// log.
    pub(crate) fn terminate(mut self) -> String {
        let child = self.child.as_ref().expect("running");
        nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(child.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        )
        .expect("SIGTERM");
        self.ended("SIGTERM")
    }

    /// `down`, then `up`'s exit code (whatever it is) and its log; nothing of the instance
    /// may be left.
    pub(crate) fn down_exit(mut self) -> (Option<i32>, String) {
        self.ok(&["down"]);
        let child = self.child.take().expect("running");
        let out = wait_child(child);
        let log = self.log();
        assert_clean(&self.inst);
        (out.code(), log)
    }

    fn ended(&mut self, how: &str) -> String {
        let child = self.child.take().expect("running");
        let out = wait_child(child);
        let log = self.log();
        assert!(out.success(), "{how}: up exited with {out}\n{log}");
        assert_clean(&self.inst);
        log
    }
}

/// The events of `up --json`'s document in `file` (`log`: `up`'s, for the message).
fn read_ended(file: Option<&Path>, log: &str) -> Vec<control_plane::event::Event> {
    let file = file.expect("an up the test started, with --json");
    let text = std::fs::read_to_string(file).expect("up --json's document");
    let doc: control_plane::report::UpEnded = serde_json::from_str(text.trim())
        .unwrap_or_else(|e| panic!("up --json is not the documented UpEnded ({e}): {text}\n{log}"));
    assert!(doc.ok, "{doc:?}\n{log}");
    // A cell that came up has said so (its drives enabled, at the least).
    assert!(!doc.events.is_empty(), "{doc:?}\n{log}");
    doc.events
}

/// The events of `events` that are errors (faults, cuts, refusals).
pub(crate) fn errors(events: &[control_plane::event::Event]) -> Vec<&control_plane::event::Event> {
    events
        .iter()
        .filter(|e| e.severity == control_plane::event::Severity::Error)
        .collect()
}

impl Drop for Up {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(c.id() as i32),
                nix::sys::signal::Signal::SIGTERM,
            );
            let _ = c.wait();
        }
    }
}

pub(crate) fn wait_child(c: Child) -> std::process::ExitStatus {
    wait_output(c, WATCHDOG, "the supervisor did not exit").status
}

/// `status --json` `v` as its type, which it must be.
fn typed(v: &Value) -> Status {
    serde_json::from_value(v.clone())
        .unwrap_or_else(|e| panic!("status --json is not the documented Status ({e}):\n{v}"))
}

/// The supervisor's part of `status --json` `v` as its type, which it must be.
fn info(v: &Value) -> Info {
    serde_json::from_value(v["supervisor"].clone()).unwrap_or_else(|e| {
        panic!("status --json's supervisor is not the documented Info ({e}):\n{v}")
    })
}

/// Polls `supervisor status --json --instance inst` (under the command `within`, if any)
/// until `pred` holds; the last answer when the watchdog ends first.
fn poll_status(
    within: &[String],
    inst: &str,
    pred: impl Fn(&Value) -> bool,
) -> Result<Value, Output> {
    let start = Instant::now();
    loop {
        let mut cmd = supervisor_within(within);
        cmd.args(["status", "--json", "--instance", inst]);
        let out = run_with_watchdog(&mut cmd, WATCHDOG);
        if out.status.success()
            && let Ok(v) =
                serde_json::from_str::<Value>(String::from_utf8_lossy(&out.stdout).trim())
            && pred(&v)
        {
            return Ok(v);
        }
        if start.elapsed() >= WATCHDOG {
            return Err(out);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits, under the watchdog, until a program of instance `inst` (a `supervisor run` the
/// test started itself, in network namespace `netns` if any) has moved the axes for more
/// than a second: for a test that acts mid-motion.
pub(crate) fn until_moving(inst: &str, netns: Option<&str>) {
    let within: Vec<String> = netns.map_or(vec![], |ns| {
        ["ip", "netns", "exec", ns].map(String::from).to_vec()
    });
    if let Err(out) = poll_status(&within, inst, |v| moving_info(&info(v))) {
        panic!(
            "{inst}: never moving\nlast status ({}):\n{}{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// A program has moved the axes for more than a second, in `status --json` `s`.
pub(crate) fn moving(s: &Value) -> bool {
    s["supervisor"]["job"]["motion_time_s"]
        .as_f64()
        .is_some_and(|t| t > 1.0)
}

/// A program has moved the axes for more than a second, in the typed status `s`.
pub(crate) fn moving_typed(s: &Status) -> bool {
    moving_info(&s.supervisor)
}

/// A program has moved the axes for more than a second, in the supervisor's view `i`.
fn moving_info(i: &Info) -> bool {
    i.job
        .as_ref()
        .and_then(|j| j.motion_time_s)
        .is_some_and(|t| t > 1.0)
}

/// The drives enabled and holding, in the typed status `s`.
pub(crate) fn enabled(s: &Status) -> bool {
    s.supervisor.arm.as_ref().is_some_and(|a| a.enabled) && !s.supervisor.enabling
}

/// The supervisor's e-stop is latched, in the typed status `s`.
pub(crate) fn latched(s: &Status) -> bool {
    s.supervisor.estop.is_some()
}

/// The latched e-stop in the typed status `s`, which must be latched.
pub(crate) fn estop_of(s: &Status) -> &control_plane::info::EstopInfo {
    s.supervisor
        .estop
        .as_ref()
        .unwrap_or_else(|| panic!("no e-stop latched: {s:?}"))
}

/// Process `name` in the supervisor's view of the typed status `s`, which must have it.
pub(crate) fn process_of<'a>(s: &'a Status, name: &str) -> &'a ProcessInfo {
    s.supervisor
        .processes
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("no process {name} in {s:?}"))
}

/// The value of IO `name` in the typed status `s`.
pub(crate) fn io_of(s: &Status, name: &str) -> Option<u8> {
    s.io.as_ref()?
        .entries
        .iter()
        .find(|e| e.name() == name)?
        .value()
}

/// Whether the arm is enabled in the typed status `s` (false before servo's first state).
pub(crate) fn arm_enabled(s: &Status) -> bool {
    s.supervisor.arm.as_ref().is_some_and(|a| a.enabled)
}

/// Process `name` in the supervisor's view of `status --json` `s` (null if it has none).
pub(crate) fn process_in<'a>(s: &'a Value, name: &str) -> &'a Value {
    s["supervisor"]["processes"]
        .as_array()
        .and_then(|p| p.iter().find(|p| p["name"] == name))
        .unwrap_or(&Value::Null)
}

/// The default cell on the virtual clock (its default limits: a stall of the host delays the
/// cell's time, it does not make a process late), its Modbus server on any free port (the
/// tests run side by side), and the keys `set` names set to its values
/// (`("modbus.max_connections", 2.into())`).
pub(crate) fn cell(test: &str, set: &[(&str, toml_edit::Value)]) -> PathBuf {
    cell_from(integration_tests::default_cell_toml(), test, set)
}

/// [`cell`] on the wall clock.
pub(crate) fn wall_cell(test: &str, set: &[(&str, toml_edit::Value)]) -> PathBuf {
    cell_from(integration_tests::wall_cell_with_room(), test, set)
}

/// `cell` with the keys `set` names set to its values, written into a scratch file of `test`.
fn cell_from(
    mut cell: integration_tests::CellToml,
    test: &str,
    set: &[(&str, toml_edit::Value)],
) -> PathBuf {
    for (path, value) in set {
        cell = cell.set(path, value.clone());
    }
    cell.write(test, "cell.toml")
}

/// The events of a cell as a follower reads them ([`Up::follow_events`]); on drop it is
/// told to stop (SIGINT: it leaves nothing of itself behind), which must come before the
/// cell goes down.
pub(crate) struct Events {
    child: Child,
    seen: std::sync::Arc<std::sync::Mutex<Vec<control_plane::event::Event>>>,
    /// Where the next [`Events::next`] looks from: the events after the last one it found.
    from: usize,
}

impl Events {
    /// The next event of code `code` (`shm_schema::event::code`) after the last one found,
    /// under the watchdog: decided on its code, never on its words.
    pub(crate) fn next(&mut self, code: u32) -> control_plane::event::Event {
        let start = Instant::now();
        loop {
            {
                let seen = self.seen.lock().expect("events");
                if let Some(k) = (self.from..seen.len()).find(|&k| seen[k].code == code) {
                    self.from = k + 1;
                    return seen[k].clone();
                }
                assert!(
                    start.elapsed() < WATCHDOG,
                    "no event of code {code} after the {} seen: {:?}",
                    self.from,
                    &seen[self.from..]
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Every event of code `code` seen so far, from the first.
    pub(crate) fn all(&self, code: u32) -> Vec<control_plane::event::Event> {
        let seen = self.seen.lock().expect("events");
        seen.iter().filter(|e| e.code == code).cloned().collect()
    }
}

impl Drop for Events {
    fn drop(&mut self) {
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT);
        let _ = self.child.wait();
    }
}
