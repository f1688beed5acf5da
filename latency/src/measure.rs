//! The measurement threads and the order the tests run in.
//!
//! Each test runs alone for the whole duration (the timer threads, then the IPC hop across
//! CPUs, then on one CPU, ...), so one never disturbs another. Every measuring loop follows the
//! cycle rules: set-up first (threads, ports, buffers, the peer process, real-time set-up),
//! then a loop that allocates nothing, takes no lock and makes no system call but its one
//! blocking wait, one clock read and the IPC calls.

use crate::peer;
use runtime::cycle::{CycleClock, WaitError};
use runtime::ipc::{self, Listener, Sub};
use runtime::rt::{self, RtRequest};
use runtime::signals;
use runtime::time::now_ns;
use shm_schema::{InstanceName, LatencyHistogramV1, ServiceId, SetpointV2};
use std::os::fd::{AsRawFd, OwnedFd};
use std::os::unix::net::UnixDatagram;
use std::os::unix::thread::JoinHandleExt;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// What is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Test {
    /// Wake-up latency of the cycle runtime's timer, one thread per CPU.
    Timer,
    /// One-way setpoint hop through iceoryx2 publish + notify and a blocking wait.
    Ipc,
    /// The same hop through a raw pipe: the baseline.
    Pipe,
    /// The same hop through a raw Unix datagram socket (the kernel mechanism under
    /// iceoryx2's notification): a second baseline, to tell the kernel's share from ours.
    Unix,
}

impl Test {
    /// Every test, in the order they run.
    pub const ALL: [Test; 4] = [Test::Timer, Test::Ipc, Test::Pipe, Test::Unix];

    /// The name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Test::Timer => "timer",
            Test::Ipc => "ipc",
            Test::Pipe => "pipe",
            Test::Unix => "unix",
        }
    }

    /// The test called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }

    /// What the test measures, for report headers.
    pub fn describe(self) -> &'static str {
        match self {
            Test::Timer => {
                "wake-up latency of runtime::cycle::CycleClock (clock_nanosleep TIMER_ABSTIME)"
            }
            Test::Ipc => {
                "one-way hop: iceoryx2 publish + notify -> Listener wait in another process"
            }
            Test::Pipe => "one-way hop: write to a pipe -> blocking read in another process",
            Test::Unix => {
                "one-way hop: send on a Unix datagram socket -> blocking read in another process"
            }
        }
    }
}

/// How many timer threads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Threads {
    /// One per CPU the process may run on, thread `i` pinned to the `i`-th.
    Smp,
    /// This many, pinned round-robin over those CPUs.
    Count(usize),
}

/// A latency run.
#[derive(Clone, Debug)]
pub struct Options {
    /// Period of the timer threads and of the hop sender (µs).
    pub interval_us: u64,
    /// Their phase on the grid of `CLOCK_MONOTONIC` (µs, below the interval), as a process'
    /// phase in the cell. A phase of 0 puts every wake-up on a whole millisecond, where the
    /// kernel's own tick (every 1/HZ s, aligned to `CLOCK_MONOTONIC`) fires too.
    pub phase_us: u64,
    /// How long each test runs; `None` until Ctrl-C.
    pub duration: Option<Duration>,
    /// Timer threads.
    pub threads: Threads,
    /// `SCHED_FIFO` priority of every measuring thread and peer (0: `SCHED_OTHER`).
    pub priority: i32,
    /// Range of the 1-µs histogram (cyclictest's `-h US`); larger samples are overflows.
    pub histogram_us: usize,
    /// Tests, run one after the other.
    pub tests: Vec<Test>,
    /// Instance name of the hop's services (and of its iceoryx2 files).
    pub instance: InstanceName,
    /// The program that runs the hop's sender: `<peer_exe> <peer_args...> --transport ...`.
    pub peer_exe: PathBuf,
    /// Arguments before the peer options (the supervisor's hidden subcommand).
    pub peer_args: Vec<String>,
}

/// Live figures of a running series, read by the progress display.
#[derive(Debug)]
pub struct Live {
    /// Samples so far.
    pub cycles: AtomicU64,
    /// Smallest (ns).
    pub min_ns: AtomicU64,
    /// Largest (ns).
    pub max_ns: AtomicU64,
    /// Sum (ns).
    pub sum_ns: AtomicU64,
    /// Latest (ns).
    pub act_ns: AtomicU64,
}

impl Default for Live {
    fn default() -> Self {
        Self {
            cycles: AtomicU64::new(0),
            min_ns: AtomicU64::new(u64::MAX),
            max_ns: AtomicU64::new(0),
            sum_ns: AtomicU64::new(0),
            act_ns: AtomicU64::new(0),
        }
    }
}

/// Overflow cycle numbers kept per series (cyclictest prints them; the rest are counted).
pub const OVERFLOW_CYCLES_KEPT: usize = 1024;

/// The per-sample bookkeeping of a measuring loop besides the latency histogram:
/// cyclictest's 1-µs histogram, overflows, live figures.
#[derive(Debug)]
pub struct Recorder {
    linear: Vec<u64>,
    overflows: u64,
    overflow_cycles: Vec<u64>,
    cycles: u64,
    live: Arc<Live>,
}

impl Recorder {
    /// A recorder with `histogram_us` bins of 1 µs (allocated here, never again).
    pub fn new(histogram_us: usize, live: Arc<Live>) -> Self {
        Self {
            linear: vec![0; histogram_us],
            overflows: 0,
            overflow_cycles: Vec::with_capacity(OVERFLOW_CYCLES_KEPT),
            cycles: 0,
            live,
        }
    }

    /// Records one sample (ns).
    ///
    /// # Real-time
    /// Arithmetic and relaxed atomic stores; the overflow list never grows past its capacity.
    #[inline]
    pub fn record(&mut self, ns: u64) {
        let us = (ns / 1000) as usize;
        match self.linear.get_mut(us) {
            Some(bin) => *bin += 1,
            None => {
                self.overflows += 1;
                if self.overflow_cycles.len() < self.overflow_cycles.capacity() {
                    self.overflow_cycles.push(self.cycles);
                }
            }
        }
        self.cycles += 1;
        let l = &self.live;
        l.cycles.store(self.cycles, Ordering::Relaxed);
        l.act_ns.store(ns, Ordering::Relaxed);
        l.sum_ns.fetch_add(ns, Ordering::Relaxed);
        l.min_ns.fetch_min(ns, Ordering::Relaxed);
        l.max_ns.fetch_max(ns, Ordering::Relaxed);
    }
}

/// The figures of one measuring thread (a timer thread or a hop's receiver).
#[derive(Clone, Debug)]
pub struct Series {
    /// The test.
    pub test: Test,
    /// Index within the test (cyclictest's thread number).
    pub index: usize,
    /// Thread id of the measuring thread.
    pub tid: i32,
    /// CPU the measuring thread ran on (-1: not pinned).
    pub cpu: i32,
    /// CPU of the hop's sender, for hops.
    pub tx_cpu: Option<i32>,
    /// Real-time priority in effect (0: `SCHED_OTHER`).
    pub priority: i32,
    /// Period (µs).
    pub interval_us: u64,
    /// Every sample.
    pub hist: Box<LatencyHistogramV1>,
    /// 1-µs bins up to the histogram range.
    pub linear: Vec<u64>,
    /// Samples beyond the 1-µs range.
    pub overflows: u64,
    /// Sample numbers (from 0) of the first overflows.
    pub overflow_cycles: Vec<u64>,
    /// The latest sample (ns).
    pub act_ns: u64,
    /// `shm_schema::status::rt_flags` of the thread and process set-up.
    pub rt_flags: u32,
}

impl Series {
    /// The figures of the calling measuring thread, once its loop has ended.
    fn of_thread(
        test: Test,
        index: usize,
        interval_us: u64,
        tx_cpu: Option<usize>,
        hist: Box<LatencyHistogramV1>,
        rec: Recorder,
        report: rt::RtReport,
    ) -> Self {
        Self {
            test,
            index,
            tid: gettid(),
            cpu: report.cpu,
            tx_cpu: tx_cpu.map(|c| c as i32),
            priority: report.priority,
            interval_us,
            hist,
            act_ns: rec.live.act_ns.load(Ordering::Relaxed),
            linear: rec.linear,
            overflows: rec.overflows,
            overflow_cycles: rec.overflow_cycles,
            rt_flags: report.flags,
        }
    }

    /// A label like `timer 0` (timer thread 0) or `ipc 0->1` (hop from CPU 0 to CPU 1).
    pub fn label(&self) -> String {
        label(
            self.test,
            self.index,
            self.tx_cpu.map(|tx| (tx as i64, self.cpu as i64)),
        )
    }
}

fn label(test: Test, index: usize, hop: Option<(i64, i64)>) -> String {
    match hop {
        None => format!("{} {index}", test.name()),
        Some((tx, rx)) => format!("{} {tx}->{rx}", test.name()),
    }
}

/// One series being measured, for the progress display.
#[derive(Clone, Debug)]
pub struct Running {
    /// Its label.
    pub label: String,
    /// Its live figures.
    pub live: Arc<Live>,
}

/// Everything a latency run measured.
#[derive(Debug)]
pub struct Results {
    /// Every series, in the order measured.
    pub series: Vec<Series>,
    /// Ctrl-C (or SIGTERM) ended the run early.
    pub interrupted: bool,
    /// Measuring time per test (s).
    pub elapsed_s: Vec<(Test, f64)>,
    /// Process set-up flags (`mlockall`, `/dev/cpu_dma_latency`).
    pub process_flags: u32,
    /// Notes for the report (a test skipped, and why).
    pub notes: Vec<String>,
}

/// The CPUs this process may run on.
pub fn allowed_cpus() -> Vec<usize> {
    // SAFETY: the set is zeroed, then filled by the kernel.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return vec![0];
        }
        (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| libc::CPU_ISSET(c, &set))
            .collect()
    }
}

fn gettid() -> i32 {
    // SAFETY: plain system call without arguments.
    unsafe { libc::gettid() }
}

fn stopped(stop: &AtomicBool) -> bool {
    stop.load(Ordering::Relaxed) || signals::stop_requested()
}

/// Runs every test of `opts` one after the other; `progress` is called about every 100 ms
/// with the series being measured. Ctrl-C (SIGINT) or SIGTERM ends the run early; the
/// figures so far are returned with `interrupted` set. Install [`signals::install`] first.
pub fn run(opts: &Options, progress: impl FnMut(&[Running], f64)) -> Result<Results, String> {
    let outcome = run_tests(opts, progress);
    // Whatever happened, the hop's iceoryx2 files go (its peer and ports are gone by now).
    let left = ipc::remove_instance(&opts.instance);
    let results = outcome?;
    if !left.is_empty() {
        return Err(format!(
            "iceoryx2 resources left behind: {}",
            left.join(", ")
        ));
    }
    Ok(results)
}

fn run_tests(opts: &Options, mut progress: impl FnMut(&[Running], f64)) -> Result<Results, String> {
    let (process_report, _guard) = rt::setup_process();
    let cpus = allowed_cpus();
    let mut results = Results {
        series: Vec::new(),
        interrupted: false,
        elapsed_s: Vec::new(),
        process_flags: process_report.flags,
        notes: Vec::new(),
    };
    for &test in &opts.tests {
        if signals::stop_requested() {
            break;
        }
        let plans: Vec<Plan> = match test {
            Test::Timer => {
                let n = match opts.threads {
                    Threads::Smp => cpus.len(),
                    Threads::Count(n) => n,
                };
                (0..n)
                    .map(|i| Plan::Timer {
                        cpu: cpus[i % cpus.len()],
                    })
                    .collect()
            }
            Test::Ipc | Test::Pipe | Test::Unix => {
                let rx = *cpus.last().unwrap_or(&0);
                let mut p = Vec::new();
                if cpus.len() > 1 {
                    p.push(Plan::Hop { tx: cpus[0], rx });
                } else {
                    results.notes.push(format!(
                        "{}: one CPU only, the cross-CPU hop was skipped",
                        test.name()
                    ));
                }
                p.push(Plan::Hop { tx: rx, rx });
                p
            }
        };
        // The hop plans run one at a time, the timer threads together.
        let groups: Vec<Vec<Plan>> = if test == Test::Timer {
            vec![plans]
        } else {
            plans.into_iter().map(|p| vec![p]).collect()
        };
        let mut elapsed = 0.0;
        for group in groups {
            if signals::stop_requested() {
                break;
            }
            let first = results.series.iter().filter(|s| s.test == test).count();
            let (series, secs) = run_group(opts, test, &group, first, &mut progress)?;
            elapsed += secs;
            results.series.extend(series);
        }
        results.elapsed_s.push((test, elapsed));
    }
    results.interrupted = signals::stop_requested();
    Ok(results)
}

#[derive(Clone, Copy, Debug)]
enum Plan {
    Timer { cpu: usize },
    Hop { tx: usize, rx: usize },
}

fn run_group(
    opts: &Options,
    test: Test,
    group: &[Plan],
    first_index: usize,
    progress: &mut impl FnMut(&[Running], f64),
) -> Result<(Vec<Series>, f64), String> {
    let stop = Arc::new(AtomicBool::new(false));
    let mut handles = Vec::new();
    let mut running = Vec::new();
    for (i, plan) in group.iter().enumerate() {
        let live = Arc::new(Live::default());
        let index = first_index + i;
        let rec = Recorder::new(opts.histogram_us, live.clone());
        let (stop2, opts2, plan2) = (stop.clone(), opts.clone(), *plan);
        let label = match *plan {
            Plan::Timer { .. } => label(test, index, None),
            Plan::Hop { tx, rx } => label(test, index, Some((tx as i64, rx as i64))),
        };
        running.push(Running {
            label: label.clone(),
            live,
        });
        let handle = std::thread::Builder::new()
            .name(label)
            .spawn(move || match plan2 {
                Plan::Timer { cpu } => timer_thread(&opts2, index, cpu, rec, &stop2),
                Plan::Hop { tx, rx } => hop_thread(&opts2, test, index, tx, rx, rec, &stop2),
            })
            .map_err(|e| format!("cannot start a measuring thread: {e}"))?;
        handles.push(handle);
    }
    let start = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(100));
        let done = handles.iter().all(|h| h.is_finished());
        let over = opts.duration.is_some_and(|d| start.elapsed() >= d);
        if over || done || signals::stop_requested() {
            stop.store(true, Ordering::Relaxed);
            break;
        }
        progress(&running, start.elapsed().as_secs_f64());
    }
    let elapsed = start.elapsed().as_secs_f64();
    // A hop's receiver may be blocked in its wait with no sender left: interrupt it until it
    // has seen the stop.
    while !handles.iter().all(|h| h.is_finished()) {
        for h in &handles {
            if !h.is_finished() {
                signals::wake_thread(h.as_pthread_t());
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut out = Vec::new();
    let mut errors = Vec::new();
    for h in handles {
        match h.join() {
            Ok(Ok(s)) => out.push(s),
            Ok(Err(e)) => errors.push(e),
            Err(_) => errors.push("a measuring thread panicked".to_string()),
        }
    }
    if !errors.is_empty() {
        return Err(errors.join("; "));
    }
    Ok((out, elapsed))
}

/// One timer thread: the cycle runtime's clock at the interval and phase, as cyclictest's
/// `clock_nanosleep` loop.
fn timer_thread(
    opts: &Options,
    index: usize,
    cpu: usize,
    mut rec: Recorder,
    stop: &AtomicBool,
) -> Result<Series, String> {
    let report = rt::setup_thread(RtRequest {
        priority: opts.priority,
        cpu: Some(cpu),
    });
    let interval_ns = opts.interval_us * 1000;
    let mut clock = CycleClock::new(interval_ns, opts.phase_us * 1000, now_ns());
    // The measuring loop: the cycle runtime's own wait and bookkeeping, nothing else.
    while !stopped(stop) {
        let wake = match clock.wait() {
            Ok(w) => w,
            Err(WaitError::Interrupted) => continue,
            Err(WaitError::Os(e)) => return Err(format!("clock_nanosleep failed: errno {e}")),
        };
        rec.record(wake.latency_ns());
        clock.finish(&wake, now_ns());
    }
    let hist = Box::new(*clock.histogram());
    Ok(Series::of_thread(
        Test::Timer,
        index,
        opts.interval_us,
        None,
        hist,
        rec,
        report,
    ))
}

/// Stops the peer when dropped, so no error path leaves it running.
struct PeerGuard(Child);

impl Drop for PeerGuard {
    fn drop(&mut self) {
        // SAFETY: plain system call on our own child.
        unsafe { libc::kill(self.0.id() as i32, libc::SIGTERM) };
        let _ = self.0.wait();
    }
}

fn spawn_peer(
    opts: &Options,
    test: Test,
    tx_cpu: usize,
    instance: &InstanceName,
    stdout: Stdio,
) -> Result<PeerGuard, String> {
    let mut cmd = Command::new(&opts.peer_exe);
    cmd.args(&opts.peer_args)
        .args(
            peer::Args {
                transport: test,
                instance: instance.to_string(),
                interval_us: opts.interval_us,
                phase_us: opts.phase_us,
                cpu: tx_cpu,
                priority: opts.priority,
            }
            .to_args(),
        )
        .stdin(Stdio::null())
        .stdout(stdout);
    cmd.spawn().map(PeerGuard).map_err(|e| {
        format!(
            "cannot start the hop's sender {}: {e}",
            opts.peer_exe.display()
        )
    })
}

/// One hop: this thread receives, a peer process sends.
fn hop_thread(
    opts: &Options,
    test: Test,
    index: usize,
    tx_cpu: usize,
    rx_cpu: usize,
    mut rec: Recorder,
    stop: &AtomicBool,
) -> Result<Series, String> {
    let mut hist = Box::new(LatencyHistogramV1::new());
    let report;
    if test == Test::Ipc {
        let instance = &opts.instance;
        let f = |e: ipc::IpcError| e.to_string();
        let node = ipc::node(instance, "latency-rx").map_err(f)?;
        let setpoints =
            Sub::<SetpointV2>::new(&node, instance, ServiceId::Setpoint, 16).map_err(f)?;
        let ready = Listener::new(&node, instance, ServiceId::SetpointReady).map_err(f)?;
        let mut peer = spawn_peer(opts, test, tx_cpu, instance, Stdio::null())?;
        report = rt::setup_thread(RtRequest {
            priority: opts.priority,
            cpu: Some(rx_cpu),
        });
        // A setpoint published after this wake-up's clock read belongs to the next wake-up
        // (its notification is still pending): it waits here.
        let mut early: Option<SetpointV2> = None;
        // The measuring loop: servo's side of the hop. One blocking wait, one clock read,
        // then the samples that arrived before it.
        while !stopped(stop) {
            if !ready.wait() {
                if let Ok(Some(status)) = peer.0.try_wait()
                    && !stopped(stop)
                {
                    return Err(format!("the hop's sender exited early: {status}"));
                }
                continue;
            }
            let now = now_ns();
            while let Some(sp) = early.take().or_else(|| setpoints.next()) {
                if sp.stamp_ns > now {
                    early = Some(sp);
                    break;
                }
                let ns = now - sp.stamp_ns;
                hist.record(ns);
                rec.record(ns);
            }
        }
        drop(peer);
    } else {
        // The sender writes 8-byte stamps to its stdout: a pipe, or one end of a Unix
        // datagram socket pair.
        let (peer, out): (PeerGuard, OwnedFd) = if test == Test::Pipe {
            let mut peer = spawn_peer(opts, test, tx_cpu, &opts.instance, Stdio::piped())?;
            let out = peer.0.stdout.take().ok_or("the hop's sender has no pipe")?;
            (peer, out.into())
        } else {
            let (rx, tx) = UnixDatagram::pair().map_err(|e| format!("socketpair: {e}"))?;
            let tx = Stdio::from(OwnedFd::from(tx));
            (
                spawn_peer(opts, test, tx_cpu, &opts.instance, tx)?,
                rx.into(),
            )
        };
        let fd = out.as_raw_fd();
        report = rt::setup_thread(RtRequest {
            priority: opts.priority,
            cpu: Some(rx_cpu),
        });
        let mut buf = [0u8; 8];
        // The measuring loop: a blocking read of one 8-byte stamp, one clock read.
        while !stopped(stop) {
            // SAFETY: reads at most 8 bytes into an 8-byte buffer from our pipe.
            let n = unsafe { libc::read(fd, buf.as_mut_ptr().cast(), buf.len()) };
            let now = now_ns();
            if n == 8 {
                let ns = now.saturating_sub(u64::from_ne_bytes(buf));
                hist.record(ns);
                rec.record(ns);
            } else if n == 0 {
                if stopped(stop) {
                    break; // Ctrl-C reached the sender too
                }
                return Err("the hop's sender closed its pipe early".into());
            } else if n < 0 && std::io::Error::last_os_error().raw_os_error() != Some(libc::EINTR) {
                return Err(format!("pipe read: {}", std::io::Error::last_os_error()));
            } else if n > 0 {
                // Writes of 8 bytes to a pipe are atomic (< PIPE_BUF): never happens.
                return Err(format!("short read of {n} bytes from the pipe"));
            }
        }
        drop(out);
        drop(peer);
    }
    Ok(Series::of_thread(
        test,
        index,
        opts.interval_us,
        Some(tx_cpu),
        hist,
        rec,
        report,
    ))
}
