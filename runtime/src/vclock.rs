//! The cell's virtual clock: a barrier that no process runs ahead of (`docs/virtual-time.md`,
//! the protocol in `shm_schema::clock`).
//!
//! [`Participant`] is a process' side: in a cell on the virtual clock its [`crate::cycle`]
//! waits for a grant instead of sleeping until its deadline. [`Coordinator`] is the clock,
//! owned and stepped by the supervisor's loop ([`Coordinator::advance_to`]): it grants the
//! earliest deadline of every process that takes part, one process at a time, ties in the
//! order of the process table, and moves on only once the process granted has reported its
//! cycle done. Before it moves, every process the supervisor launched has joined (or exited)
//! and every process that left has exited, so a start, a restart, a swap or a stop happens at
//! the same virtual instant in every run. A process that does not report within the clock's
//! wall-time watchdog is left out of the clock and reported ([`Lost`]).

use crate::ipc::{Ipc, IpcError, Listener, Notifier, Pub, Sub};
use crate::time;
use iceoryx2::prelude::Node;
use shm_schema::{ClockGrantV1, ClockReport, ClockReportV1, InstanceName, ServiceId};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Where a cell's virtual clock starts (ns): the same origin in every run, so that two runs
/// stamp everything alike.
pub const EPOCH_NS: u64 = 1_000_000_000;

/// How long the clock waits, on the wall clock, between looks at a process that has not
/// reported yet (whether it still exists).
const LOOK_EVERY: Duration = Duration::from_millis(1);

/// How often (wall time) the clock looks for a report that came without a notification (a
/// process on stock iceoryx2 bindings, which cannot notify the cell's semaphore events) and
/// whether the process it waits for still exists: a thread of the clock notifies its own
/// wait this often. (iceoryx2's timed wait on a semaphore event would spin: it yields
/// thousands of times before it sleeps, a CPU lost per cell on the virtual clock.)
const REPORT_LOOK: Duration = Duration::from_micros(200);

/// [`REPORT_LOOK`] for a clock that keeps a pace.
const PACED_LOOK: Duration = Duration::from_millis(2);

/// How long the clock looks for a granted cycle's report before it blocks (wall time).
const SPIN_FOR: Duration = Duration::from_micros(50);

/// How long (wall time) the clock stands for a process launched to join it: the cell's time
/// does not pass meanwhile, so a slow start costs only wall time (under the test suite's load
/// Python's iobridge took more than 10 s to start, and joined late, at a later instant).
pub const START_PATIENCE: Duration = Duration::from_secs(60);

/// How long (wall time) a process waits at set-up for where the clock stands.
const JOIN_PATIENCE: Duration = Duration::from_secs(10);

/// Why a process could not take part in the virtual clock.
#[derive(Debug)]
pub enum ClockError {
    /// A port of the clock could not be opened.
    Ipc(IpcError),
    /// Nothing on `<i>/clock/grant`: the cell's supervisor runs no virtual clock.
    NoClock(String),
}

impl std::fmt::Display for ClockError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Ipc(e) => write!(f, "the virtual clock: {e}"),
            Self::NoClock(service) => write!(
                f,
                "the cell runs on the virtual clock but nothing is on {service}: is its \
                 supervisor started with --virtual-time?"
            ),
        }
    }
}

impl std::error::Error for ClockError {}

impl From<IpcError> for ClockError {
    fn from(e: IpcError) -> Self {
        Self::Ipc(e)
    }
}

/// Where the clock of `instance` stands (ns), as a process or a tool attaching to the cell
/// reads it, waited for at most `patience`; `None` when nothing came.
pub fn where_it_stands(
    node: &Node<Ipc>,
    instance: &InstanceName,
    patience: Duration,
) -> Result<Option<u64>, IpcError> {
    let grants = Sub::<ClockGrantV1>::new(node, instance, ServiceId::ClockGrant, 2)?;
    Ok(stands(&grants, patience))
}

/// The newest grant's instant on `grants`, waited for at most `patience`: it reaches a new
/// subscriber with the clock's next look at its connections (every millisecond while a
/// launched process has not joined, and every tick).
fn stands(grants: &Sub<ClockGrantV1>, patience: Duration) -> Option<u64> {
    let start = Instant::now();
    loop {
        if let Some(at) = grants.latest() {
            return Some(at.now_ns);
        }
        if start.elapsed() > patience {
            return None;
        }
        std::thread::sleep(LOOK_EVERY);
    }
}

/// The grants of the clock of `instance`, and where it stands (waited for at most
/// [`JOIN_PATIENCE`]).
fn following(
    node: &Node<Ipc>,
    instance: &InstanceName,
) -> Result<(Sub<ClockGrantV1>, u64), ClockError> {
    let grants = Sub::<ClockGrantV1>::new(node, instance, ServiceId::ClockGrant, 2)?;
    let now = stands(&grants, JOIN_PATIENCE)
        .ok_or_else(|| ClockError::NoClock(instance.service(ServiceId::ClockGrant).to_string()))?;
    Ok((grants, now))
}

/// A tool's view of a cell's virtual clock, taking no part in it (a recorder, a web view):
/// where the clock stands, as its newest grant says, to date what the tool reads.
pub struct Observer {
    grants: Sub<ClockGrantV1>,
    last_ns: u64,
}

impl std::fmt::Debug for Observer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Observer")
            .field("last_ns", &self.last_ns)
            .finish_non_exhaustive()
    }
}

impl Observer {
    /// Follows the clock of `instance`; waits (at most [`JOIN_PATIENCE`]) for where it
    /// stands.
    pub fn new(node: &Node<Ipc>, instance: &InstanceName) -> Result<Self, ClockError> {
        let (grants, last_ns) = following(node, instance)?;
        Ok(Self { grants, last_ns })
    }

    /// Where the clock stands now (ns): its newest grant, never earlier than the last seen.
    pub fn now_ns(&mut self) -> u64 {
        if let Some(g) = self.grants.latest() {
            self.last_ns = self.last_ns.max(g.now_ns);
        }
        self.last_ns
    }
}

/// Where a tool that takes part in the clock (the recorder) stands among the processes at an
/// instant: after every process of the table.
pub const AFTER_THE_TABLE: u32 = u32::MAX;

/// A tool's part in the clock, outside the process table (the recorder, which must read every
/// sample before the cell runs on): granted every `period_ns` after every process due at the
/// same instant, and woken every [`TOOL_LOOK`] of wall time to ask whether it should go on
/// (a stop, the cell gone), since no grant comes once the cell is down.
#[derive(Debug)]
pub struct ToolPart {
    part: Participant,
    period_ns: u64,
    next_ns: u64,
    looking: Arc<AtomicU64>,
    look: Option<std::thread::JoinHandle<()>>,
}

/// How often (wall time) a tool that takes part looks whether it should go on.
pub const TOOL_LOOK: Duration = Duration::from_millis(100);

impl ToolPart {
    /// Joins the clock of `instance` at [`AFTER_THE_TABLE`], from the next multiple of
    /// `period_ns` on.
    pub fn join(
        node: &Node<Ipc>,
        instance: &InstanceName,
        period_ns: u64,
    ) -> Result<Self, ClockError> {
        let mut part = Participant::new(node, instance, AFTER_THE_TABLE)?;
        let period_ns = period_ns.max(1);
        let next_ns = (time::now_ns() / period_ns + 1) * period_ns;
        let looking = Arc::new(AtomicU64::new(TOOL_LOOK.as_nanos() as u64));
        let look = look_every(*instance, ServiceId::ClockGo(part.pid), looking.clone())?;
        part.join(next_ns);
        Ok(Self {
            part,
            period_ns,
            next_ns,
            looking,
            look: Some(look),
        })
    }

    /// Stops the thread that wakes the tool, and waits until it has let go of its node.
    fn stop_looking(&mut self) {
        self.looking.store(0, Ordering::Relaxed);
        if let Some(t) = self.look.take() {
            let _ = t.join();
        }
    }

    /// Ends the cycle granted (if any) and waits for the next: its instant, or `None` once
    /// `go_on` (asked every [`TOOL_LOOK`] meanwhile) says to stop.
    pub fn next(&mut self, go_on: &mut dyn FnMut() -> bool) -> Option<u64> {
        let next = self.next_ns;
        let now = self.part.wait_or(next, go_on)?;
        self.next_ns = now + self.period_ns;
        Some(now)
    }

    /// Leaves the clock: the tool exits.
    pub fn leave(&mut self) {
        self.part.leave();
        self.stop_looking();
    }
}

impl Drop for ToolPart {
    fn drop(&mut self) {
        self.stop_looking();
    }
}

/// A process' side of the virtual clock.
pub struct Participant {
    pid: u32,
    /// The process that launched this one (the supervisor), and whether it is gone: then no
    /// grant will come, and the process runs its cycles on the wall clock's pace (its own
    /// heartbeat watch then finds the supervisor lost and brings it to a safe stop).
    parent: u32,
    orphaned: bool,
    index: u32,
    seq: u64,
    owes_report: bool,
    grants: Sub<ClockGrantV1>,
    report: Pub<ClockReportV1>,
    ready: Notifier,
    go: Listener,
}

impl std::fmt::Debug for Participant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Participant")
            .field("pid", &self.pid)
            .field("index", &self.index)
            .field("seq", &self.seq)
            .finish_non_exhaustive()
    }
}

impl Participant {
    /// Opens the clock's ports for the process at `index` of the process table and turns this
    /// process to virtual time, at the instant where the clock stands. Set-up only.
    pub fn new(node: &Node<Ipc>, instance: &InstanceName, index: u32) -> Result<Self, ClockError> {
        let pid = std::process::id();
        // Listening before joining: the clock's first grant finds the listener.
        let go = Listener::new(node, instance, ServiceId::ClockGo(pid))?;
        let report = Pub::<ClockReportV1>::new(node, instance, ServiceId::ClockReport)?;
        let ready = Notifier::new(node, instance, ServiceId::ClockReportReady)?;
        let (grants, now) = following(node, instance)?;
        time::set_virtual_now(now);
        Ok(Self {
            pid,
            parent: std::os::unix::process::parent_id(),
            orphaned: false,
            index,
            seq: 0,
            owes_report: false,
            grants,
            report,
            ready,
            go,
        })
    }

    fn send(&self, kind: ClockReport, next_ns: u64) {
        self.report.send(&ClockReportV1 {
            next_ns,
            seq: self.seq,
            pid: self.pid,
            index: self.index,
            kind: kind as u32,
            reserved: 0,
        });
        self.ready.notify();
    }

    /// Takes part from the deadline `first_ns` on.
    pub fn join(&mut self, first_ns: u64) {
        self.send(ClockReport::Join, first_ns);
    }

    /// Reports the granted cycle done (if one was granted) with the next deadline `next_ns`,
    /// then blocks until the clock grants the next cycle: its virtual instant. When the
    /// supervisor is gone (its parent-death SIGTERM interrupted the wait and this process'
    /// parent changed), no grant comes: the deadline is slept for on the wall clock instead,
    /// time going on from the last grant (the heartbeat's watch then finds the supervisor
    /// lost and the process comes to a safe stop).
    ///
    /// # Real-time
    /// The cycle's one blocking wait (a futex) and the IPC calls; no allocation. Only a wait
    /// a signal interrupted asks the kernel for the parent's pid.
    pub fn wait(&mut self, next_ns: u64) -> u64 {
        if self.owes_report {
            self.send(ClockReport::Done, next_ns);
            self.owes_report = false;
        }
        loop {
            if self.orphaned {
                let wait = next_ns.saturating_sub(time::now_ns());
                std::thread::sleep(Duration::from_nanos(wait));
                time::set_virtual_now(next_ns.max(time::now_ns()));
                return time::now_ns();
            }
            // iceoryx2's timed wait on this event spins and sleeps by steps (its adaptive
            // wait); the blocking one is a futex.
            if !self.go.wait() {
                self.orphaned = std::os::unix::process::parent_id() != self.parent;
                continue;
            }
            if let Some(g) = self.grants.latest()
                && g.pid == self.pid
                && g.seq > self.seq
            {
                self.seq = g.seq;
                self.owes_report = true;
                time::set_virtual_now(g.now_ns);
                return g.now_ns;
            }
        }
    }

    /// [`Self::wait`] for a tool woken now and then by its own thread: `None` once `go_on`,
    /// asked at every wake-up that is not its grant, says to stop.
    fn wait_or(&mut self, next_ns: u64, go_on: &mut dyn FnMut() -> bool) -> Option<u64> {
        if self.owes_report {
            self.send(ClockReport::Done, next_ns);
            self.owes_report = false;
        }
        loop {
            // Woken by the grant, by the tool's own thread or by a signal.
            let _ = self.go.wait();
            if let Some(g) = self.grants.latest()
                && g.pid == self.pid
                && g.seq > self.seq
            {
                self.seq = g.seq;
                self.owes_report = true;
                time::set_virtual_now(g.now_ns);
                return Some(g.now_ns);
            }
            if !go_on() {
                return None;
            }
        }
    }

    /// Leaves the clock (ending a granted cycle): the process exits.
    pub fn leave(&mut self) {
        self.send(ClockReport::Leave, 0);
        self.owes_report = false;
    }
}

/// A process the clock lost.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lost {
    /// Its pid.
    pub pid: u32,
    /// Why.
    pub why: LostWhy,
}

/// Why the clock lost a process.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LostWhy {
    /// Granted a cycle, it did not report it done within the watchdog (wall time).
    NeverDone,
    /// Launched, it did not join within the watchdog (wall time).
    NeverJoined,
}

/// A process held off its cycles from `from_ns` until `until_ns` (a stall on schedule).
#[derive(Clone, Copy, Debug)]
struct Hold {
    index: u32,
    from_ns: u64,
    until_ns: u64,
}

/// A process killed at `at_ns`.
#[derive(Clone, Copy, Debug)]
struct Kill {
    index: u32,
    at_ns: u64,
}

#[derive(Debug)]
struct Part {
    pid: u32,
    index: u32,
    next_ns: u64,
    go: Notifier,
}

/// The clock, stepped by its owner (the supervisor's loop).
#[derive(Debug)]
pub struct Coordinator {
    /// How often (ns) the thread that notifies `ready` does so; 0 stops it (on drop).
    looking: Arc<AtomicU64>,
    instance: InstanceName,
    grant: Pub<ClockGrantV1>,
    reports: Sub<ClockReportV1>,
    ready: Listener,
    now: u64,
    seq: u64,
    parts: Vec<Part>,
    expected: Vec<u32>,
    leaving: Vec<u32>,
    lost: Vec<Lost>,
    watchdog: Duration,
    wall_start: Instant,
    grants: u64,
    holds: Vec<Hold>,
    kills: Vec<Kill>,
    pace: f64,
}

impl Coordinator {
    /// A clock at [`EPOCH_NS`] for `instance`, published before any process starts; this
    /// process (the supervisor) turns to virtual time. `watchdog`: how long (wall time) a
    /// process may take to join or to finish a granted cycle before the clock leaves it out.
    pub fn new(
        node: &Node<Ipc>,
        instance: &InstanceName,
        watchdog: Duration,
    ) -> Result<Self, IpcError> {
        let ready = Listener::new(node, instance, ServiceId::ClockReportReady)?;
        let reports = Sub::<ClockReportV1>::new(node, instance, ServiceId::ClockReport, 64)?;
        let grant = Pub::<ClockGrantV1>::new(node, instance, ServiceId::ClockGrant)?;
        let looking = Arc::new(AtomicU64::new(REPORT_LOOK.as_nanos() as u64));
        // Ends with the clock (the supervisor's instance is removed after it).
        let _ = look_every(*instance, ServiceId::ClockReportReady, looking.clone())?;
        time::set_virtual_now(EPOCH_NS);
        let clock = Self {
            looking,
            instance: *instance,
            grant,
            reports,
            ready,
            now: EPOCH_NS,
            seq: 0,
            parts: Vec::new(),
            expected: Vec::new(),
            leaving: Vec::new(),
            lost: Vec::new(),
            watchdog,
            wall_start: Instant::now(),
            grants: 0,
            holds: Vec::new(),
            kills: Vec::new(),
            pace: 0.0,
        };
        clock.publish_now();
        Ok(clock)
    }

    /// Virtual seconds since the clock started.
    pub fn virtual_s(&self) -> f64 {
        time::secs(self.now - EPOCH_NS)
    }

    /// Wall seconds since the clock started.
    pub fn wall_s(&self) -> f64 {
        self.wall_start.elapsed().as_secs_f64()
    }

    /// Cycles granted so far.
    pub fn grants(&self) -> u64 {
        self.grants
    }

    /// The processes lost since the last call.
    pub fn take_lost(&mut self) -> Vec<Lost> {
        std::mem::take(&mut self.lost)
    }

    /// At most `pace` virtual seconds per wall second from now on (0: as fast as the CPUs
    /// allow): [`Self::advance_to`] then sleeps until the wall clock has caught up with it.
    pub fn set_pace(&mut self, pace: f64) {
        self.pace = if pace.is_finite() && pace > 0.0 {
            pace
        } else {
            0.0
        };
        // At a pace, a look every PACED_LOOK is enough (a polling process still runs in
        // time at its 4 ms period) and saves the wake-ups of the cells beside it.
        let every = if self.pace > 0.0 {
            PACED_LOOK
        } else {
            REPORT_LOOK
        };
        self.looking
            .store(every.as_nanos() as u64, Ordering::Relaxed);
    }

    /// Holds the process at `index` of the table off its cycles from `from_ns` until
    /// `until_ns`: its deadlines in between are granted at `until_ns`, late, as a stall of
    /// the host would let them run.
    pub fn hold(&mut self, index: u32, from_ns: u64, until_ns: u64) {
        self.holds.push(Hold {
            index,
            from_ns,
            until_ns,
        });
    }

    /// Kills (SIGKILL) the process at `index` of the table at `at_ns`, before any cycle of it
    /// at or after that instant.
    pub fn kill_at(&mut self, index: u32, at_ns: u64) {
        self.kills.push(Kill { index, at_ns });
    }

    /// When `p` is granted its next deadline: later if a hold covers it.
    fn effective(&self, p: &Part) -> u64 {
        let mut t = p.next_ns;
        for h in &self.holds {
            if h.index == p.index && t >= h.from_ns && t < h.until_ns {
                t = h.until_ns;
            }
        }
        t
    }

    /// Kills the processes at `index` and waits (wall time, at most the watchdog) until they
    /// have exited; they are out of the clock.
    fn kill(&mut self, index: u32) {
        let pids: Vec<u32> = (self.parts.iter())
            .filter(|p| p.index == index)
            .map(|p| p.pid)
            .collect();
        for pid in pids {
            // SAFETY: plain system call on a pid that took part in the clock.
            unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) };
            let start = Instant::now();
            while !exited(pid) && start.elapsed() < self.watchdog {
                std::thread::sleep(LOOK_EVERY);
            }
            self.parts.retain(|p| p.pid != pid);
        }
    }

    /// Keeps the clock's history delivered to processes that are starting (a grant's
    /// subscriber gets where the clock stands).
    pub fn update_connections(&self) {
        self.grant.update_connections();
    }

    /// Process `pid` was launched: the clock holds until it joins or exits.
    pub fn expect(&mut self, pid: u32) {
        if !self.expected.contains(&pid) {
            self.expected.push(pid);
        }
    }

    fn publish_now(&self) {
        self.grant.send(&ClockGrantV1 {
            now_ns: self.now,
            seq: self.seq,
            pid: 0,
            reserved: 0,
        });
    }

    fn set_now(&mut self, t: u64) {
        self.now = self.now.max(t);
        time::set_virtual_now(self.now);
    }

    /// Grants, in order, every deadline up to and including `t`, then stands at `t`.
    /// Blocks (on the wall clock) until the processes launched have joined and those that
    /// left have exited; a process that takes longer than the watchdog is left out and
    /// reported by [`Self::take_lost`]. `waiting` runs every few milliseconds of wall time
    /// while it waits for a process (the owner keeps its publishers' history delivered to
    /// processes that are starting).
    pub fn advance_to(&mut self, node: &Node<Ipc>, t: u64, waiting: &mut dyn FnMut()) {
        self.settle(node, waiting);
        loop {
            self.absorb(node, None);
            let due = (self.parts.iter().enumerate())
                .map(|(k, p)| (self.effective(p), p.index, p.pid, k))
                .filter(|&(at, ..)| at <= t)
                .min();
            // A kill due before the next grant comes first.
            let horizon = due.map_or(t, |(at, ..)| at);
            if let Some(k) = self.kills.iter().position(|k| k.at_ns <= horizon) {
                let kill = self.kills.remove(k);
                self.set_now(kill.at_ns);
                self.kill(kill.index);
                continue;
            }
            let Some((next, _, _, k)) = due else { break };
            self.set_now(next);
            self.seq += 1;
            self.grants += 1;
            let pid = self.parts[k].pid;
            self.grant.send(&ClockGrantV1 {
                now_ns: self.now,
                seq: self.seq,
                pid,
                reserved: 0,
            });
            self.parts[k].go.notify();
            self.await_report(node, pid, waiting);
            // A process that left is waited for before the clock moves on.
            self.settle(node, waiting);
        }
        self.set_now(t);
        // A tool that subscribed meanwhile gets where the clock stands (its history).
        self.grant.update_connections();
        self.publish_now();
        if self.pace > 0.0 {
            let due = Duration::from_secs_f64(self.virtual_s() / self.pace);
            if let Some(ahead) = due.checked_sub(self.wall_start.elapsed()) {
                std::thread::sleep(ahead);
            }
        }
    }

    /// Takes every report; `awaiting` is the pid whose granted cycle the clock waits for:
    /// true once it reported it done (or left).
    fn absorb(&mut self, node: &Node<Ipc>, awaiting: Option<u32>) -> bool {
        let mut done = false;
        while let Some(r) = self.reports.next() {
            match ClockReport::from_wire(r.kind) {
                Some(ClockReport::Join) => {
                    // A process launched through a wrapper (`sh -c`, a launcher that forks)
                    // joins from a child of the pid launched.
                    let parent = parent_of(r.pid);
                    self.expected.retain(|&p| p != r.pid && Some(p) != parent);
                    if self.parts.iter().any(|p| p.pid == r.pid) {
                        continue;
                    }
                    match Notifier::new(node, &self.instance, ServiceId::ClockGo(r.pid)) {
                        Ok(go) => self.parts.push(Part {
                            pid: r.pid,
                            index: r.index,
                            next_ns: r.next_ns,
                            go,
                        }),
                        Err(e) => {
                            tracing::error!("virtual clock: pid {} cannot be woken: {e}", r.pid);
                        }
                    }
                }
                Some(ClockReport::Done) => {
                    if let Some(p) = self.parts.iter_mut().find(|p| p.pid == r.pid)
                        && r.seq == self.seq
                        && awaiting == Some(r.pid)
                    {
                        p.next_ns = r.next_ns;
                        done = true;
                    }
                }
                Some(ClockReport::Leave) => {
                    self.parts.retain(|p| p.pid != r.pid);
                    self.expected.retain(|&p| p != r.pid);
                    if !self.leaving.contains(&r.pid) {
                        self.leaving.push(r.pid);
                    }
                    if awaiting == Some(r.pid) {
                        done = true;
                    }
                }
                None => {}
            }
        }
        done
    }

    /// Waits until process `pid`, granted a cycle, reports it done or leaves; leaves it out
    /// of the clock if it exits or takes longer than the watchdog.
    fn await_report(&mut self, node: &Node<Ipc>, pid: u32, waiting: &mut dyn FnMut()) {
        let start = Instant::now();
        // A cycle's work takes a few µs: looking for its report for a moment saves the
        // wake-up of a blocking wait (about 10 µs here) on most grants. Only when the clock
        // runs as fast as it can: at a pace, the CPU is worth more (other cells beside it).
        while self.pace == 0.0 && start.elapsed() < SPIN_FOR {
            if self.absorb(node, Some(pid)) {
                return;
            }
            std::hint::spin_loop();
        }
        loop {
            if self.absorb(node, Some(pid)) {
                return;
            }
            // Woken by a report, or by the look every REPORT_LOOK.
            self.ready.wait();
            // A tool attaching meanwhile learns where the clock stands.
            self.grant.update_connections();
            waiting();
            if exited(pid) {
                self.parts.retain(|p| p.pid != pid);
                return;
            }
            if start.elapsed() > self.watchdog {
                self.parts.retain(|p| p.pid != pid);
                self.lost.push(Lost {
                    pid,
                    why: LostWhy::NeverDone,
                });
                return;
            }
        }
    }

    /// Waits until every process launched has joined or exited (for at most
    /// [`START_PATIENCE`], or the watchdog if longer) and every process that left has exited
    /// (for at most the watchdog).
    fn settle(&mut self, node: &Node<Ipc>, waiting: &mut dyn FnMut()) {
        let start = Instant::now();
        loop {
            self.absorb(node, None);
            if self.expected.is_empty() && self.leaving.is_empty() {
                return;
            }
            self.grant.update_connections();
            waiting();
            self.expected.retain(|&p| !exited(p));
            self.leaving.retain(|&p| !exited(p));
            if start.elapsed() > self.watchdog {
                self.leaving.clear();
            }
            if start.elapsed() > self.watchdog.max(START_PATIENCE) {
                for pid in std::mem::take(&mut self.expected) {
                    self.lost.push(Lost {
                        pid,
                        why: LostWhy::NeverJoined,
                    });
                }
            }
            // A sleep, not a timed wait on the event (which would spin): processes start.
            std::thread::sleep(LOOK_EVERY);
        }
    }
}

impl Drop for Coordinator {
    fn drop(&mut self) {
        self.looking.store(0, Ordering::Relaxed);
    }
}

/// A thread (with a node of its own: iceoryx2's ports are single-threaded) that notifies
/// `event` every `on` ns until `on` is 0.
fn look_every(
    instance: InstanceName,
    event: ServiceId,
    on: Arc<AtomicU64>,
) -> Result<std::thread::JoinHandle<()>, IpcError> {
    let (made, ready) = std::sync::mpsc::channel();
    let spawned = std::thread::Builder::new()
        .name("clock-look".into())
        .spawn(move || {
            let name = format!("clock-look-{}", std::process::id());
            let notifier = crate::ipc::node(&instance, &name)
                .and_then(|node| Notifier::new(&node, &instance, event).map(|n| (node, n)));
            let (_node, notifier) = match notifier {
                Ok(n) => {
                    let _ = made.send(Ok(()));
                    n
                }
                Err(e) => {
                    let _ = made.send(Err(e));
                    return;
                }
            };
            loop {
                let every = on.load(Ordering::Relaxed);
                if every == 0 {
                    break;
                }
                std::thread::sleep(Duration::from_nanos(every));
                notifier.notify();
            }
        });
    let thread = spawned.map_err(|e| IpcError {
        what: "the virtual clock's look".into(),
        reason: e.to_string(),
    })?;
    ready.recv().unwrap_or_else(|_| {
        Err(IpcError {
            what: "the virtual clock's look".into(),
            reason: "its thread ended".into(),
        })
    })?;
    Ok(thread)
}

/// The parent of process `pid` (`/proc/<pid>/stat`'s fourth field), if it still exists.
fn parent_of(pid: u32) -> Option<u32> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // After the command's name in parentheses (which may hold anything): state, then ppid.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(1)?.parse().ok()
}

/// Whether process `pid` has exited: a child of this process that exited and is not reaped
/// yet counts (`waitid` without reaping it), another process when no process has the pid.
fn exited(pid: u32) -> bool {
    // SAFETY: a zeroed siginfo_t is valid; waitid writes it.
    let mut info: libc::siginfo_t = unsafe { std::mem::zeroed() };
    // SAFETY: plain system call; WNOWAIT leaves the child waitable for its owner.
    let rc = unsafe {
        libc::waitid(
            libc::P_PID,
            pid as libc::id_t,
            &mut info,
            libc::WEXITED | libc::WNOHANG | libc::WNOWAIT,
        )
    };
    if rc == 0 {
        // SAFETY: waitid filled `info`; si_pid is 0 when the child has not exited.
        return unsafe { info.si_pid() } != 0;
    }
    // Not a child of this process (or already reaped): gone when no process has the pid.
    // SAFETY: signal 0 checks only that the process exists.
    let rc = unsafe { libc::kill(pid as libc::pid_t, 0) };
    rc != 0 && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH)
}
