//! Helpers for the integration tests: the real binaries, unique instance names, a watchdog,
//! and the check that an instance left nothing behind.

pub mod load;
pub mod toml;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};
pub use toml::CellToml;

/// The folder holding the workspace's binaries (same profile as the tests). `cargo test
/// --workspace` has built them already (each process crate and the supervisor test their own
/// command line, so cargo builds their binaries with the tests) and the `cargo test --no-run`
/// here finds them fresh; it builds them when a test binary runs on its own. It is the tests'
/// own build, not `cargo build --bins`: without the dev-dependencies some crates would get
/// other features (proptest's regex-syntax, which Zenoh's logging uses too), and every
/// binary would be built again while the tests run.
///
/// Under cargo-nextest, which runs each test in a process of its own, the first test of a run
/// builds and the others find the run's mark (`NEXTEST_RUN_ID`) beside the binaries, under a
/// file lock: one `cargo` for the run, not one for each test (0.45 s each, one at a time on
/// cargo's own lock).
pub fn bin_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let exe = std::env::current_exe().expect("test executable path");
        // target/<profile>/deps/<test> -> target/<profile>
        let dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("target dir")
            .to_path_buf();
        let Some(run) = std::env::var_os("NEXTEST_RUN_ID") else {
            build_bins(&dir);
            return dir;
        };
        let mark = dir.join(".integration-tests-built");
        let file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .read(true)
            .write(true)
            .open(&mark)
            .unwrap_or_else(|e| panic!("{}: {e}", mark.display()));
        file.lock()
            .unwrap_or_else(|e| panic!("lock {}: {e}", mark.display()));
        if std::fs::read(&mark).ok().as_deref() != Some(run.as_encoded_bytes()) {
            build_bins(&dir);
            // A new run: the last one's re-runs go.
            let _ = std::fs::remove_file(dir.join(RERUN_LOG));
            std::fs::write(&mark, run.as_encoded_bytes())
                .unwrap_or_else(|e| panic!("{}: {e}", mark.display()));
        }
        dir
    })
}

/// Under cargo-nextest, the tests [`wall_clock`] ran once more after a failure during a
/// measured stall, in this file of [`bin_dir`]: nextest shows a passing test's output only
/// when asked (`--success-output`), so `tests/run` counts and prints them after the tests.
pub const RERUN_LOG: &str = "rerun.log";

/// `cargo test --no-run --workspace` for the binaries in `dir` (see [`bin_dir`]).
fn build_bins(dir: &Path) {
    let release = dir.file_name().is_some_and(|n| n == "release");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(["test", "--no-run", "--workspace"]);
    // Not the variables cargo set for this test's run: a build script that reads one
    // (ring's reads CARGO_PKG_NAME) would see it changed, and everything above it would
    // be built again.
    for (key, _) in std::env::vars_os() {
        let k = key.to_string_lossy();
        if k.starts_with("CARGO_PKG_")
            || k.starts_with("CARGO_BIN_")
            || k.starts_with("CARGO_MANIFEST_")
            || [
                "CARGO_CRATE_NAME",
                "CARGO_PRIMARY_PACKAGE",
                "CARGO_TARGET_TMPDIR",
                "OUT_DIR",
            ]
            .contains(&k.as_ref())
        {
            cmd.env_remove(&key);
        }
    }
    if release {
        cmd.arg("--release");
    }
    let status = cmd.status().expect("run cargo test --no-run");
    assert!(status.success(), "cargo test --no-run failed");
}

/// Fails the test unless `python3` has iceoryx2's bindings, which the processes written in
/// Python need (from PyPI: `pip install iceoryx2==0.10.0`; `.ci/run` installs them).
pub fn require_python_iceoryx2() {
    needed(
        Command::new("python3").args(["-c", "import iceoryx2"]),
        "this test needs Python's iceoryx2 bindings: pip install iceoryx2==0.10.0",
    );
}

/// `out`, which must show a success: else a panic naming `what` (the command line, or what
/// ran), its exit status and its stderr.
pub fn success(out: Output, what: &str) -> Output {
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs `cmd` to its end; it must succeed ([`success`], naming its command line): its output.
pub fn succeeded(cmd: &mut Command) -> Output {
    let what = format!("{cmd:?}");
    output_of(cmd, what)
}

/// Runs `cmd`, a tool the test needs of the machine, which must succeed: as [`succeeded`],
/// and a failure also says `needs` (what the test needs, and how to get it).
pub fn needed(cmd: &mut Command, needs: &str) -> Output {
    let what = format!("{cmd:?} ({needs})");
    output_of(cmd, what)
}

/// `cmd`'s output, which must show a success ([`success`], naming `what`).
fn output_of(cmd: &mut Command, what: String) -> Output {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e}"));
    success(out, &what)
}

/// [`run_with_watchdog`], and `cmd` must succeed ([`success`], naming its command line): its
/// output.
pub fn succeeded_within(cmd: &mut Command, watchdog: Duration) -> Output {
    let what = format!("{cmd:?}");
    success(run_with_watchdog(cmd, watchdog), &what)
}

/// The stderr of `out`, which must have exited with `code`: else a panic with its exit status
/// and that stderr.
pub fn exited(out: &Output, code: i32) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(code),
        "exit status {}; stderr:\n{err}",
        out.status
    );
    err
}

/// Waits until `child` ends, for at most `watchdog` (then a panic saying `what`); its output
/// (what it wrote on the pipes it was given).
pub fn wait_output(mut child: Child, watchdog: Duration, what: &str) -> Output {
    let start = Instant::now();
    while child.try_wait().expect("wait").is_none() {
        assert!(start.elapsed() < watchdog, "{what} (after {watchdog:?})");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().expect("output")
}

/// A child of a test that never outlives it: dropped while it still runs (the test failed
/// before it stopped the child), it is killed (SIGKILL) and reaped. [`Self::into_child`]
/// hands the child over to a test that waits for it.
#[derive(Debug)]
pub struct Reaped(Option<Child>);

impl Reaped {
    /// Spawns `cmd`, panicking with `what` if it cannot.
    pub fn spawn(cmd: &mut Command, what: &str) -> Self {
        Self(Some(cmd.spawn().unwrap_or_else(|e| panic!("{what}: {e}"))))
    }

    /// The child, no longer killed on drop.
    pub fn into_child(mut self) -> Child {
        self.0.take().expect("the child is still held")
    }
}

impl std::ops::Deref for Reaped {
    type Target = Child;
    fn deref(&self) -> &Child {
        self.0.as_ref().expect("the child is still held")
    }
}

impl std::ops::DerefMut for Reaped {
    fn deref_mut(&mut self) -> &mut Child {
        self.0.as_mut().expect("the child is still held")
    }
}

impl Drop for Reaped {
    fn drop(&mut self) {
        if let Some(child) = self.0.as_mut()
            && child.try_wait().ok().flatten().is_none()
        {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// The first line `child` writes on its stdout (piped), waiting for it (it must write one).
pub fn first_line(child: &mut Child) -> String {
    use std::io::BufRead;
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.as_mut().expect("its stdout piped"))
        .read_line(&mut line)
        .expect("its first line");
    line
}

/// The rows of a `--trace` file (its header passed over): t_s, then cmd and act per axis.
pub fn trace_rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .expect("trace")
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().expect("number")).collect())
        .collect()
}

/// The repository's `examples/` folder.
pub fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// Whether two motion times are the same but for the generator's clock, within 2 ns either
/// way: it counts whole nanoseconds, so a motion ends on the first nanosecond at or after its
/// theoretical end (up to 1 ns later), and each time is a sum of `f64`s besides (a run of the
/// EtherCAT cell started at x = 62.718 predicted 5.8698750010000005 s for 5.869875 s).
pub fn same_motion_time(a: f64, b: f64) -> bool {
    (a - b).abs() < 2e-9
}

/// The default cell's configuration (`examples/gantry-uba.toml`) as text, its Modbus server
/// on any free port (the tests run side by side; only the test of the embedded default itself
/// listens on its 1502), on the virtual clock at real-time pace ([`virtual_cell_toml`]): a
/// test of the cell's logic, which no stall of the host can make late. A test of timing, or
/// of what still dates on the wall clock (the recorder, Foxglove), takes [`wall_cell`].
pub fn default_cell() -> String {
    default_cell_toml().to_string()
}

/// [`default_cell`] to edit.
pub fn default_cell_toml() -> CellToml {
    virtual_cell_toml()
}

/// The default cell on the virtual clock at real-time pace (`[cell] clock = "virtual"`,
/// `pace = 1`, docs/virtual-time.md): a stall of the host delays the cell's time instead of
/// making its processes late.
pub fn virtual_cell_toml() -> CellToml {
    wall_cell_toml()
        .add("cell.clock", "virtual")
        .add("cell.pace", 1.0)
}

/// The default cell as [`default_cell`] has it, on the wall clock: for a test of timing.
pub fn wall_cell() -> String {
    wall_cell_toml().to_string()
}

/// [`wall_cell`] to edit.
pub fn wall_cell_toml() -> CellToml {
    CellToml::example("gantry-uba.toml").set("modbus.listen", "127.0.0.1:0")
}

/// [`wall_cell`] written into a scratch file of `test`.
pub fn wall_cell_file(test: &str) -> PathBuf {
    scratch(test, "wall-cell.toml", &wall_cell())
}

/// The seed's triangle at a fifth of its size, from and back to its start (40, 40): the same
/// three blended corners and the same stop, in a quarter of the time. For the tests that check
/// that a program runs (after a recovery, a swap, with a recorder), not the seed's figure.
pub const SMALL_TRIANGLE: &str =
    "MOVE(40,40,0)\nMOVE(60,40,0)\nMOVE(50,57.2,0)\nMOVE(40,40,0)\nSTOP\nEND\n";

/// [`SMALL_TRIANGLE`] written into a scratch file of `test`.
pub fn small_triangle(test: &str) -> PathBuf {
    scratch(test, "small-triangle.prog", SMALL_TRIANGLE)
}

/// [`default_cell`] written into a scratch file of `test`.
pub fn default_cell_file(test: &str) -> PathBuf {
    scratch(test, "default-cell.toml", &default_cell())
}

/// `cell` with its `iobridge` entry running the Python iobridge written from the documents
/// (`examples/python/iobridge.py`, on stock iceoryx2 bindings).
pub fn with_python_iobridge(cell: CellToml) -> CellToml {
    let script = examples().join("python/iobridge.py");
    let script = script.to_str().expect("utf-8");
    cell.set(
        "process[iobridge].command",
        toml::strings(&[
            "python3",
            script,
            "--instance",
            "{instance}",
            "--name",
            "{name}",
        ]),
    )
}

/// [`wall_cell`] [`with_stall_room`], to edit: a test on the wall clock of something else than
/// the cell's tolerance of the host's stalls.
pub fn wall_cell_with_room() -> CellToml {
    CellToml::parse(&with_stall_room(&wall_cell()))
}

/// `src` (a cell configuration) with room for the host's stalls where a test checks something
/// else than the cell's tolerance of them: a following-error limit of 5 units, a drive
/// watchdog and a feedback timeout of 1.5 s, a setpoint timeout of 0.2 s, a
/// pending-sequence detector that expires only when a process misses every sample for two
/// seconds, a thread-offset detector that expires only when every wake-up is late for a
/// second, a supervisor timeout of 2 s, and a heartbeat timeout of 2 s (the tests run side
/// by side on 2 CPUs, a browser and a recorder among them). On this VM a loaded host stalls
/// a process for 100 ms now and then (`../shared/notes/machine.md`), which the default cell
/// rightly treats as a fault; once in a CI run, one vCPU stopped for 0.95 s (servo, iobridge
/// and modbus, whose timers were on it, woke 0.95 s late; machine and trajgen on the other
/// ran on) and the drives' 0.5 s watchdog cut power to a paused cell; in a loaded run,
/// iobridge skipped 1.1 s of periods and its pending-sequence detector, then at 100 %,
/// expired: the watchdogs allow 1.5 s, the heartbeat and the pending-sequence detector 2 s.
pub fn with_stall_room(src: &str) -> String {
    CellToml::parse(src)
        .set("axis[*].following_error_limit", 5.0)
        .set("drives.command_timeout", 1.5)
        .add("drives.feedback_timeout", 1.5)
        .set("motion.setpoint_timeout", 0.2)
        .set(
            "health_config.pending_sequence_overrun_percent_limit",
            200.0,
        )
        .set(
            "health_config.thread_offset_variance_overrun_percent_limit",
            100.0,
        )
        // An EtherCAT frame lost is a transport overrun: a stall of the emulator's thread
        // alone (one vCPU held by the host) loses frames; 50 in a row at 1 kHz trip it.
        .set("health_config.transport_overrun_percent_limit", 5.0)
        .set("supervisor.supervisor_timeout", 2.0)
        .set("supervisor.heartbeat_timeout", 2.0)
        .to_string()
}

/// The default cell on the wall clock with the machine and servo at `period_us`, their
/// phases scaled (a tenth and two fifths of the period, as 100 µs and 400 µs are of 1 ms), and the thread offset
/// detector's share of the period scaled so that it counts the same wake-up latency (the
/// host's stalls do not shrink with the period).
pub fn cell_at_rate(period_us: u64) -> String {
    at_rate(&wall_cell(), period_us)
}

/// `src` (a cell of the default's shape) with the drives and servo at `period_us`, as
/// [`cell_at_rate`] does.
pub fn at_rate(src: &str, period_us: u64) -> String {
    let p = period_us as i64;
    CellToml::parse(src)
        .set(
            "health_config.thread_offset_variance_percent",
            50.0 * 1000.0 / period_us as f64,
        )
        .set("process[drives].period_us", p)
        .set("process[drives].phase_us", p / 10)
        .set("process[servo].period_us", p)
        .set("process[servo].phase_us", p * 2 / 5)
        .to_string()
}

/// The median of the finite values of `v` (NaN when there are none): the benches' summary.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// The default cell with every axis in CSP: the drives close the loop with their own gains.
pub fn cell_in_csp() -> String {
    let mut cell = default_cell_toml();
    for (axis, [kp, ki, kd]) in [
        ("x", [300.0, 2000.0, 2.5]),
        ("y", [190.0, 1200.0, 1.6]),
        ("theta", [13.0, 80.0, 0.11]),
    ] {
        let mut drive = toml_edit::InlineTable::new();
        drive.insert("mode", "csp".into());
        drive.insert("kp", kp.into());
        drive.insert("ki", ki.into());
        drive.insert("kd", kd.into());
        cell = cell.add(&format!("axis[{axis}].drive"), drive);
    }
    cell.to_string()
}

/// The supervisor binary, as a command to add arguments to.
pub fn supervisor() -> Command {
    Command::new(bin("supervisor"))
}

/// Whether a test of this process failed: its folder ([`test_dir`]) then stays for a look.
static A_TEST_FAILED: AtomicBool = AtomicBool::new(false);

/// This test process' folder for the files its tests make: `rtc-<pid>` in the temporary
/// directory, emptied as it is first asked for (a folder left by an earlier process with
/// this pid is stale: pids come round again) and removed as the process exits, unless a
/// test of [`wall_clock`] failed (then it stays, for a look, until the pid comes round).
pub fn test_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("rtc-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("the tests' folder");
        extern "C" fn remove() {
            if !A_TEST_FAILED.load(Ordering::Relaxed) {
                let _ = std::fs::remove_dir_all(test_dir());
            }
        }
        // SAFETY: `remove` is a plain function that touches only this process' own folder;
        // the test harness exits through `exit`, which runs it.
        unsafe { libc::atexit(remove) };
        dir
    })
}

/// Writes `content` to a file `name` in a scratch folder of `test` (in [`test_dir`]) and
/// returns its path.
pub fn scratch(test: &str, name: &str, content: &str) -> PathBuf {
    let dir = test_dir().join(test);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let p = dir.join(name);
    std::fs::write(&p, content).expect("write");
    p
}

/// A binary of the workspace.
pub fn bin(name: &str) -> PathBuf {
    bin_dir().join(name)
}

/// An instance name unique to this test and process.
pub fn instance(test: &str) -> String {
    let mut s = format!("t{}-{test}", std::process::id());
    s.truncate(32);
    s
}

/// Runs `cmd`, killing it if it takes longer than `watchdog` (a stuck test fails; nothing
/// here bounds how fast anything must be).
pub fn run_with_watchdog(cmd: &mut Command, watchdog: Duration) -> Output {
    use std::io::Read;
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    // Drained while it runs: a child that writes more than a pipe holds must not block.
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut v = Vec::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_end(&mut v);
            }
            v
        })
    };
    let out = drain(
        child
            .stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let err = drain(
        child
            .stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            return Output {
                status,
                stdout: out.join().unwrap_or_default(),
                stderr: err.join().unwrap_or_default(),
            };
        }
        if start.elapsed() > watchdog {
            let stuck = where_stuck(child.id());
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "watchdog: {:?} still running after {watchdog:?}\nstderr:\n{}\n{stuck}",
                cmd,
                String::from_utf8_lossy(&err.join().unwrap_or_default())
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Where process `pid` is stuck, for the message of a watchdog that fails a test: each thread's
/// name, the kernel function it waits in and its kernel stack (readable by root), and, when
/// gdb is installed, every thread's user-space backtrace.
pub fn where_stuck(pid: u32) -> String {
    let mut out = format!("where process {pid} is:\n");
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task"))
        .map(|d| d.flatten().map(|e| e.path()).collect::<Vec<_>>())
        .unwrap_or_default();
    for t in tasks {
        let read = |f: &str| std::fs::read_to_string(t.join(f)).unwrap_or_default();
        out += &format!(
            "thread {} ({}) waits in {}\n{}",
            t.file_name().unwrap_or_default().to_string_lossy(),
            read("comm").trim(),
            read("wchan"),
            read("stack")
        );
    }
    if let Ok(gdb) = Command::new("timeout")
        .args(["30", "gdb", "-p", &pid.to_string(), "-batch", "-ex"])
        .arg("thread apply all bt")
        .stdin(Stdio::null())
        .output()
    {
        let bt = String::from_utf8_lossy(&gdb.stdout);
        out += &bt
            .lines()
            .filter(|l| l.starts_with('#') || l.starts_with("Thread"))
            .collect::<Vec<_>>()
            .join("\n");
    }
    out
}

/// Every iceoryx2 file of `instance` still present: shared memory and the root folder.
pub fn leftovers(instance: &str) -> Vec<String> {
    let mut left = Vec::new();
    let prefix = format!("iox2_{instance}_");
    for e in std::fs::read_dir("/dev/shm")
        .into_iter()
        .flatten()
        .flatten()
    {
        let name = e.file_name().to_string_lossy().to_string();
        if name.starts_with(&prefix) {
            left.push(format!("/dev/shm/{name}"));
        }
    }
    fn walk(p: &Path, out: &mut Vec<String>) {
        for e in std::fs::read_dir(p).into_iter().flatten().flatten() {
            if e.path().is_dir() {
                walk(&e.path(), out);
            } else {
                out.push(e.path().display().to_string());
            }
        }
    }
    walk(
        &PathBuf::from(format!("/tmp/iceoryx2/{instance}")),
        &mut left,
    );
    left
}

/// Asserts that `instance` left nothing behind.
pub fn assert_clean(instance: &str) {
    let left = leftovers(instance);
    assert!(left.is_empty(), "instance {instance} left behind: {left:?}");
}

/// Asserts that no process of `instance` runs, and that it left nothing behind.
pub fn assert_gone(instance: &str) {
    let running = pids_with(&["--instance", instance]);
    assert!(
        running.is_empty(),
        "processes of instance {instance} running: {running:?}"
    );
    assert_clean(instance);
}

/// Pids of processes whose command line has every one of `needles` as a whole argument.
pub fn pids_with(needles: &[&str]) -> Vec<i32> {
    let mut pids = Vec::new();
    for e in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<i32>() else {
            continue;
        };
        let Ok(cmdline) = std::fs::read(e.path().join("cmdline")) else {
            continue;
        };
        // Whole arguments (a program also by its file name): instance `t1-web` is not
        // `t1-web-fivebar`.
        let args: Vec<String> = cmdline
            .split(|b| *b == 0)
            .map(|a| String::from_utf8_lossy(a).into_owned())
            .collect();
        let has = |n: &str| {
            args.iter()
                .any(|a| a == n || std::path::Path::new(a).file_name().is_some_and(|f| f == n))
        };
        if needles.iter().all(|n| has(n)) {
            pids.push(pid);
        }
    }
    pids
}

/// Parses the JSON object `supervisor run --json` prints.
pub fn json_of(out: &Output) -> serde_json::Value {
    let stdout = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(stdout.trim()).unwrap_or_else(|e| {
        panic!(
            "stdout is not JSON ({e}):\n{stdout}\nstderr:\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

/// Stalls of the machine beyond this, in any [`STALL_WINDOW`], are beyond the room any
/// test's configuration gives (the drives' and the heartbeat's watchdogs allow 1.5-2 s, but the
/// following error grows by vmax for every second the axes are not served: 16 mm on the
/// gantry, against 5 mm at most).
pub const STALL_BEYOND_ROOM_MS: f64 = 250.0;

/// The window over which the machine's stalls add up: the axes do not catch up in between.
pub const STALL_WINDOW: Duration = Duration::from_secs(2);

/// A gap of the watch's beat this long or longer is a stall (its beat is 5 ms).
const STALL_GAP: Duration = Duration::from_millis(10);

/// Set (to anything), every test of the real cell prints what its machine watch measured,
/// passed or failed (`WATCH test: …`), and each stall of 100 ms or more with where the time
/// went (`STALL …`): how a leaving process that starved both CPUs for 0.95 s was found.
pub const WATCH_REPORT: &str = "RTC_WATCH_REPORT";

/// The machine's stalls while a test runs, as a real-time process would suffer them: a thread
/// of the test at `SCHED_FIFO` 1 (below every process of a cell, above all ordinary work)
/// wakes every 5 ms; each gap of [`STALL_GAP`] or more is split by the kernel's accounting
/// ([`runtime::stall`]): the share it waited for a CPU (held by real-time work: another test's
/// cell, the host's own threads) or the host took is the machine's. Without the right to
/// `SCHED_FIFO` it runs as ordinary work and measures more generously.
struct MachineWatch {
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<Vec<(Instant, runtime::stall::Stall)>>,
}

impl MachineWatch {
    fn start() -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        let (running, started) = std::sync::mpsc::channel();
        let thread = std::thread::spawn(move || {
            let param = libc::sched_param { sched_priority: 1 };
            // SAFETY: plain system call on the calling thread with a valid parameter block.
            let _ = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
            let mut watch = runtime::stall::StallWatch::new(STALL_GAP);
            let report = std::env::var_os(WATCH_REPORT).is_some();
            let _ = running.send(());
            let mut stalls = Vec::new();
            while !stopped.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(5));
                if let Some(s) = watch.beat() {
                    if report && s.gap >= Duration::from_millis(100) {
                        eprintln!(
                            "STALL of the machine watch: {:.0} ms, {}",
                            s.gap.as_secs_f64() * 1e3,
                            s.cause()
                        );
                    }
                    stalls.push((Instant::now(), s));
                }
            }
            stalls
        });
        // Watching before the test starts: a stall from its first moment is seen.
        let _ = started.recv();
        Self { stop, thread }
    }

    /// The worst [`STALL_WINDOW`] of the run: the machine's share of its stalls (ms), their
    /// number and the longest gap.
    fn worst(self) -> (f64, usize, Duration) {
        self.stop.store(true, Ordering::Relaxed);
        let stalls = self.thread.join().unwrap_or_default();
        let share = |s: &runtime::stall::Stall| s.machine_share().as_secs_f64() * 1e3;
        let mut worst = (0.0, 0, Duration::ZERO);
        let mut first = 0;
        for (k, (end, _)) in stalls.iter().enumerate() {
            while *end - stalls[first].0 > STALL_WINDOW {
                first += 1;
            }
            let window = &stalls[first..=k];
            let total: f64 = window.iter().map(|(_, s)| share(s)).sum();
            if total > worst.0 {
                let longest = window.iter().map(|(_, s)| s.gap).max().unwrap_or_default();
                worst = (total, window.len(), longest);
            }
        }
        worst
    }
}

/// Runs a test of the real cell on the wall clock. A failure while the machine held the
/// test's real-time work off the CPUs beyond [`STALL_BEYOND_ROOM_MS`] in [`STALL_WINDOW`]
/// (measured alongside, see `MachineWatch`) runs the test once more, from the start; the
/// second run's result stands, so a failure is never counted as a pass. Every re-run says
/// why on stderr (`RERUN`, the failure and the figures) and, under nextest, in the run's
/// [`RERUN_LOG`], which `tests/run` counts and prints. A failure without such a stall fails at
/// once. This VM's host stalls both vCPUs now and then, for up to about a second
/// (`../shared/notes/machine.md`); a test whose subject is not timing belongs on the virtual
/// clock, where no stall can make it fail.
pub fn wall_clock(test: impl Fn()) {
    rerun_after_a_stall(test, STALL_BEYOND_ROOM_MS, true);
}

/// The room the default cell's limits give a stall of the host (ms): its axis' following
/// error limit (1 mm) is reached after 62 ms at the gantry's 16 mm/s, its pending-sequence
/// detector expires on about 75 ms without servo's samples.
pub const DEFAULT_CELL_ROOM_MS: f64 = 60.0;

/// [`wall_clock`] for a cell of the default configuration's limits, whose room for a stall
/// is [`DEFAULT_CELL_ROOM_MS`]: a failure during a stall beyond that runs the test once more.
pub fn wall_clock_default_limits(test: impl Fn()) {
    rerun_after_a_stall(test, DEFAULT_CELL_ROOM_MS, true);
}

/// [`wall_clock`] with `room_ms` the stall that is beyond the test's room; `logged`: a re-run
/// goes into [`RERUN_LOG`] (not the self-test's own).
fn rerun_after_a_stall(test: impl Fn(), room_ms: f64, logged: bool) {
    let first = watched(&test);
    let Err((panic, (stalled_ms, stalls, longest))) = first else {
        return;
    };
    if stalled_ms < room_ms {
        A_TEST_FAILED.store(true, Ordering::Relaxed);
        std::panic::resume_unwind(panic);
    }
    // Straight to stderr, past the test harness' capture, and under nextest into the run's
    // RERUN_LOG too: every re-run is seen in the log of the run.
    use std::io::Write;
    let report = format!(
        "RERUN: {}: failed while the machine held real-time work off a CPU {stalled_ms:.0} ms \
         in {} s ({stalls} stalls, the longest {:.0} ms); run once more. The failure:\n{}\n",
        std::thread::current().name().unwrap_or("a test"),
        STALL_WINDOW.as_secs(),
        longest.as_secs_f64() * 1e3,
        panic_text(&panic)
    );
    let _ = std::io::stderr().write_all(report.as_bytes());
    if logged && std::env::var_os("NEXTEST_RUN_ID").is_some() {
        let _ = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(bin_dir().join(RERUN_LOG))
            .and_then(|mut f| f.write_all(report.as_bytes()));
    }
    if let Err((panic, _)) = watched(&test) {
        A_TEST_FAILED.store(true, Ordering::Relaxed);
        std::panic::resume_unwind(panic);
    }
}

/// A failure's panic and the worst stall window of the run (ms, stalls, the longest).
type Watched = (Box<dyn std::any::Any + Send>, (f64, usize, Duration));

/// One run of `test` with the machine watched; a failure with what the watch measured.
fn watched(test: &impl Fn()) -> Result<(), Watched> {
    let watch = MachineWatch::start();
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(test));
    let (stalled_ms, stalls, longest) = watch.worst();
    if std::env::var_os(WATCH_REPORT).is_some() {
        use std::io::Write;
        let _ = writeln!(
            std::io::stderr(),
            "WATCH {}: real-time work held off a CPU {stalled_ms:.0} ms in the worst {} s \
             ({stalls} stalls, the longest {:.0} ms)",
            std::thread::current().name().unwrap_or("a test"),
            STALL_WINDOW.as_secs(),
            longest.as_secs_f64() * 1e3
        );
    }
    result.map_err(|panic| (panic, (stalled_ms, stalls, longest)))
}

/// A panic's message, at most 2000 characters.
fn panic_text(panic: &Box<dyn std::any::Any + Send>) -> String {
    panic
        .downcast_ref::<String>()
        .map(String::as_str)
        .or_else(|| panic.downcast_ref::<&str>().copied())
        .unwrap_or("?")
        .chars()
        .take(2000)
        .collect()
}

/// A Unix datagram socket of the test's own on which a child says `READY=1` once it is ready
/// (`runtime::notify`: systemd's notification protocol): give the child [`Readiness::path`]
/// as `NOTIFY_SOCKET` ([`Readiness::tell`]), spawn it with its stderr piped, then
/// [`Readiness::wait`]. The socket's file goes with it.
#[derive(Debug)]
pub struct Readiness {
    path: PathBuf,
    socket: std::os::unix::net::UnixDatagram,
}

impl Readiness {
    /// A socket in the temporary directory, named after `name`, this process and a counter.
    pub fn new(name: &str) -> Self {
        static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path =
            std::env::temp_dir().join(format!("rtc-ready-{}-{name}-{k}", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let socket = std::os::unix::net::UnixDatagram::bind(&path).expect("a readiness socket");
        socket
            .set_read_timeout(Some(Duration::from_millis(100)))
            .expect("a read timeout");
        Self { path, socket }
    }

    /// `cmd` with `NOTIFY_SOCKET` naming this socket.
    pub fn tell<'a>(&self, cmd: &'a mut Command) -> &'a mut Command {
        cmd.env("NOTIFY_SOCKET", &self.path)
    }

    /// Waits until `child` says `READY=1` here, for at most `watchdog`; a panic then, or as
    /// soon as it ends without having said it.
    pub fn wait(&self, child: &mut std::process::Child, watchdog: Duration) {
        let start = Instant::now();
        let mut buf = [0u8; 64];
        loop {
            if let Ok(n) = self.socket.recv(&mut buf)
                && buf[..n].split(|b| *b == b'\n').any(|l| l == b"READY=1")
            {
                return;
            }
            if let Ok(Some(status)) = child.try_wait() {
                panic!("it ended ({status}) before it said READY=1");
            }
            assert!(
                start.elapsed() < watchdog,
                "it did not say READY=1 in {watchdog:?}"
            );
        }
    }
}

/// Every line `child` (spawned with its stderr piped) writes on its stderr goes on to the
/// test's, after `name: `, for as long as it writes.
pub fn forward_stderr(child: &mut std::process::Child, name: &str) {
    let mut log = std::io::BufReader::new(child.stderr.take().expect("its stderr piped"));
    let name = name.to_string();
    std::thread::spawn(move || {
        use std::io::BufRead;
        let mut text = String::new();
        while log.read_line(&mut text).is_ok_and(|n| n > 0) {
            eprint!("{name}: {text}");
            text.clear();
        }
    });
}

impl Drop for Readiness {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// The `ethercat-emulator` process alone on a line of its own: a network namespace
/// `rtc-ecat-<pid>-<test>` with a veth pair, the emulator on `s0` (with `args`), the
/// MainDevice's end `m0`, and a second pair `s1`-`m1` for a ring (the emulator's `--ring s1`,
/// a MainDevice's second port on `m1`); up once the emulator says it answers (its log goes on
/// to the test's stderr). Dropped: the emulator stopped (SIGTERM, then SIGKILL after 10 s) and
/// the namespace removed. Needs root and iproute2.
#[derive(Debug)]
pub struct EmulatedLine {
    /// The namespace's name.
    pub ns: String,
    emulator: Option<std::process::Child>,
}

/// `ip ARGS` (iproute2), which must succeed: for tests that make network namespaces.
pub fn ip(args: &[&str]) {
    needed(
        Command::new("ip").args(args),
        "this test makes a network namespace: it needs root and iproute2's `ip` (apt-get \
         install iproute2)",
    );
}

impl EmulatedLine {
    /// The line of `test`, the emulator (its program at `emulator`) started with `args`
    /// after `--interface s0`.
    pub fn up(emulator: &Path, test: &str, args: &[&str]) -> Self {
        let ns = format!("rtc-ecat-{}-{test}", std::process::id());
        ip(&["netns", "add", &ns]);
        // Kept first: whatever fails below, the drop removes what was made.
        let mut line = Self {
            ns: ns.clone(),
            emulator: None,
        };
        ip(&[
            "-n", &ns, "link", "add", "m0", "type", "veth", "peer", "name", "s0",
        ]);
        ip(&[
            "-n", &ns, "link", "add", "m1", "type", "veth", "peer", "name", "s1",
        ]);
        for end in ["m0", "s0", "m1", "s1"] {
            ip(&["-n", &ns, "link", "set", end, "up"]);
        }
        let ready = Readiness::new("emulator");
        let emulator = ready
            .tell(
                Command::new("ip")
                    .args(["netns", "exec", &ns])
                    .arg(emulator),
            )
            .args(["--interface", "s0"])
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the emulator");
        let emulator = line.emulator.insert(emulator);
        forward_stderr(emulator, "emulator");
        ready.wait(emulator, Duration::from_secs(120));
        line
    }
}

impl Drop for EmulatedLine {
    fn drop(&mut self) {
        if let Some(mut e) = self.emulator.take() {
            // SAFETY: plain system call; the pid is our own child's, not yet waited for.
            let _ = unsafe { libc::kill(e.id() as libc::pid_t, libc::SIGTERM) };
            let start = Instant::now();
            while matches!(e.try_wait(), Ok(None)) && start.elapsed() < Duration::from_secs(10) {
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = e.kill();
            let _ = e.wait();
        }
        let _ = Command::new("ip").args(["netns", "del", &self.ns]).status();
    }
}

/// The command line of a cell's process (`exe`, its program, named `name`): `--help` names it
/// and its two arguments and exits 0; an unknown argument, a bad `--instance` or `--name` is
/// refused naming the argument, exit 2, before it touches anything of an instance. For each
/// process crate's own test (which makes cargo build the binary with the tests: the
/// integration tests find it built).
pub fn check_process_command_line(exe: &str, name: &str) {
    let run = |args: &[&str]| {
        let out = Command::new(exe)
            .args(args)
            .env("RTC_LOG", "error")
            .output()
            .expect("the process' program");
        let text = String::from_utf8_lossy(&out.stdout).to_string()
            + &String::from_utf8_lossy(&out.stderr);
        (out.status.code(), text)
    };
    let (code, help) = run(&["--help"]);
    assert_eq!(code, Some(0), "{name} --help:\n{help}");
    for word in [name, "--instance", "--name"] {
        assert!(
            help.contains(word),
            "{name} --help does not name {word}:\n{help}"
        );
    }
    for (args, named) in [
        (&["--bogus"][..], "--bogus"),
        (&["--instance", "a/b"], "--instance"),
        (&["--instance"], "--instance"),
        (
            &[
                "--name",
                "a name with spaces that is far too long for a process",
            ],
            "--name",
        ),
    ] {
        let (code, text) = run(args);
        assert_eq!(code, Some(2), "{name} {args:?} was not refused:\n{text}");
        assert!(
            text.contains(named),
            "{name} {args:?}: the error does not name {named}:\n{text}"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every CPU this test may use held at SCHED_FIFO 50 (above the watch) for 400 ms: the
    /// machine stalled. One holder pinned to each CPU, all starting together (unpinned, a
    /// holder could wait behind another on one CPU until that one was done, and the CPUs
    /// would be held one after the other: CI saw it). False without the right to do so.
    fn hold_every_cpu() -> bool {
        let allowed = nix::sched::sched_getaffinity(nix::unistd::Pid::from_raw(0))
            .expect("this thread's CPUs");
        let cpus: Vec<usize> = (0..nix::sched::CpuSet::count())
            .filter(|&c| allowed.is_set(c).unwrap_or(false))
            .collect();
        let together = Arc::new(std::sync::Barrier::new(cpus.len()));
        let hold = move |cpu: usize, together: Arc<std::sync::Barrier>| {
            let mut only = nix::sched::CpuSet::new();
            let pinned = only.set(cpu).is_ok()
                && nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(0), &only).is_ok();
            let param = libc::sched_param { sched_priority: 50 };
            // SAFETY: as in MachineWatch::start.
            let fifo = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } == 0;
            together.wait();
            if !(pinned && fifo) {
                return false;
            }
            let t = Instant::now();
            while t.elapsed() < Duration::from_millis(400) {
                std::hint::spin_loop();
            }
            true
        };
        let holders: Vec<_> = cpus
            .iter()
            .map(|&cpu| {
                let together = together.clone();
                std::thread::spawn(move || hold(cpu, together))
            })
            .collect();
        holders.into_iter().all(|t| t.join().unwrap_or(false))
    }

    /// A failure during a measured stall runs the test once more and the second result
    /// stands: a pass after it passes, a second failure fails; a failure without a stall
    /// fails at once, never run again.
    #[test]
    fn a_stall_then_a_failure_runs_the_test_once_more() {
        use std::sync::atomic::AtomicUsize;
        let runs = AtomicUsize::new(0);
        rerun_after_a_stall(
            || {
                if runs.fetch_add(1, Ordering::Relaxed) == 0 {
                    assert!(!hold_every_cpu(), "a failure while the machine stalled");
                }
            },
            STALL_BEYOND_ROOM_MS,
            false,
        );
        assert_eq!(
            runs.load(Ordering::Relaxed),
            2,
            "a failure during the stall is run once more, then passes"
        );
        let runs = AtomicUsize::new(0);
        let twice = std::panic::catch_unwind(|| {
            rerun_after_a_stall(
                || {
                    runs.fetch_add(1, Ordering::Relaxed);
                    assert!(!hold_every_cpu(), "a failure while the machine stalled");
                },
                STALL_BEYOND_ROOM_MS,
                false,
            )
        });
        assert!(twice.is_err(), "a second failure fails the test");
        assert_eq!(runs.load(Ordering::Relaxed), 2);
        let runs = AtomicUsize::new(0);
        let real = std::panic::catch_unwind(|| {
            rerun_after_a_stall(
                || {
                    runs.fetch_add(1, Ordering::Relaxed);
                    panic!("a real failure");
                },
                STALL_BEYOND_ROOM_MS,
                false,
            )
        });
        assert!(real.is_err(), "a failure without a measured stall fails");
        assert_eq!(runs.load(Ordering::Relaxed), 1, "and is not run again");
        // A failure in this test's own process (the last two, on purpose) keeps its folder.
        A_TEST_FAILED.store(false, Ordering::Relaxed);
    }
}
