//! `gateway`: the cell on a line of cells (`docs/network.md`).
//!
//! As a process of the cell (`gateway --instance NAME`, the `gateway` entry of the process
//! table, switched on by `[network]`), it shows the cell on Zenoh under `rtc/v1/<cell>/`:
//! its presence, its status, its events, a control queryable whose every command is judged by
//! [`gateway::auth::Gate`] before it goes to the cell's control channel, and, while anyone
//! subscribes to it, the recording stream (`recording`).
//!
//! As a control room's client (`gateway line ...`, which `supervisor cells` and `--remote`
//! run), it lists the line's cells, reads, records or commands one of them.
//!
//! # Not real-time
//! The process runs under `SCHED_OTHER` and is not critical. Its cycle only takes the cell's
//! events from shared memory and hands them to the network thread through a bounded queue
//! (an event it cannot hand over is counted, and the count published with the next one);
//! Zenoh's own threads, the status and the commands run beside it, and reach the real-time
//! processes only through the control channel, as `supervisor pause` does.

use cell_config::network::NetworkSettings;
use control_plane::event::Axes;
use control_plane::{Reply, Request, channel};
use gateway::auth::{Gate, Users, now_ms};
use gateway::budget::LogBudget;
use gateway::command::Command;
use gateway::keys::{CellKeys, CellName};
use gateway::link::Link;
use gateway::ros2;
use gateway::wire::{Answer, EventMessage, RefusedBy, StatusMessage};
use runtime::ipc::Sub;
use runtime::process::{self, Context, Cycle, SetupError, Task};
use shm_schema::event::code;
use shm_schema::{EventV1, InstanceName, ServiceId};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

mod client;
mod line_web;
mod recording;
mod survey;
mod viewing;

/// What a stream of the gateway's own thread serves from: the cell's Zenoh session, its
/// instance and its name on the line, and whether the gateway is leaving the line.
#[derive(Clone, Copy, Debug)]
struct OnTheLine<'a> {
    /// The gateway's session.
    session: &'a zenoh::Session,
    /// The cell's instance (its shared memory).
    instance: &'a InstanceName,
    /// The cell's name on the line (its keys).
    name: &'a CellName,
    /// Set when the gateway leaves the line.
    leaving: &'a AtomicBool,
}

impl OnTheLine<'_> {
    /// Whether the stream should end: the gateway leaves the line or the process was asked to
    /// stop.
    fn over(&self) -> bool {
        runtime::signals::stop_requested() || self.leaving.load(Ordering::Relaxed)
    }
}

/// Events queued between the cycle and the network at most.
const EVENT_QUEUE: usize = 1024;

/// How often the network thread asks the supervisor again for `[network]` before it answers.
const ASK_AGAIN: Duration = Duration::from_millis(500);
/// How often the network thread and the events' thread look whether the gateway is leaving.
const LOOK_AGAIN: Duration = Duration::from_millis(50);

/// Commands waiting for the control thread at most.
const CONTROL_QUEUE: usize = 64;

/// How long a command waits for the cell's answer at most.
const PATIENCE: Duration = Duration::from_secs(60);

/// How long a failed join of the line waits before the next.
const JOIN_AGAIN: Duration = Duration::from_secs(2);
/// The commands from the line in the cell's log: at most so many lines in so many ms, then
/// one line saying how many more came (a viewer polling at 1 800 requests a second filled the
/// log with a line each).
const LOG_LINES: u32 = 20;
const LOG_WINDOW_MS: u64 = 10_000;

struct Bridge {
    events: Sub<EventV1>,
    tx: SyncSender<(EventV1, u64)>,
    /// Events not handed over since the last one that was: the queue was full, or the cell
    /// published more than this process' subscriber holds between two cycles (a gap in a
    /// source's numbers).
    lost: u64,
    /// Each source's last event number (the supervisor's and its tools' share theirs: no
    /// gap is counted in them). A source's events before the first one this process saw are
    /// not counted: they cannot be told from those published before it subscribed. Sized in
    /// set-up for every process of the cell and as many foreign sources: the cycle does not
    /// grow it unless more sources than that publish.
    last_seq: std::collections::HashMap<u32, u64>,
    /// This process' source number, for its own note of a loss.
    source: u32,
    /// What the network thread says of the line, to tell the cell as events.
    notes: Receiver<Note>,
}

/// What the network thread tells the cycle.
enum Note {
    /// On the line: where it listens (or connects).
    Joined(String),
    /// Off the line: why (it tries again, or waits for a fixed configuration).
    Failed(String),
}

impl Bridge {
    /// The network thread started (it joins the line) and the cell's events subscribed to.
    /// Set-up only.
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let (tx, rx) = sync_channel(EVENT_QUEUE);
        let (note, notes) = sync_channel(16);
        let instance = ctx.instance;
        let axes = Axes::of_cell(&ctx.cell);
        let kin = forward_kinematics(&ctx.cell);
        std::thread::Builder::new()
            .name("line".into())
            .spawn(move || line(instance, axes, kin, rx, note))
            .map_err(|e| SetupError::from(format!("cannot start the network thread: {e}")))?;
        Ok(Self {
            events: Sub::new(&ctx.node, &ctx.instance, ServiceId::Events, 1024)?,
            tx,
            lost: 0,
            last_seq: std::collections::HashMap::with_capacity(2 * shm_schema::MAX_PROCESSES),
            source: ctx.index as u32,
            notes,
        })
    }
}

impl Task for Bridge {
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        // The line's state as the cell's events (`supervisor status` shows where it listens),
        // as the Modbus server does.
        while let Ok(note) = self.notes.try_recv() {
            let (code, text) = match &note {
                Note::Joined(at) => (code::LISTENING, at.as_str()),
                Note::Failed(why) => (code::LISTEN_FAILED, why.as_str()),
            };
            let now = cx.now_ns();
            cx.events
                .push(EventV1::new(now, code, -1, 0.0, 0.0, &["the line: ", text]));
        }
        while let Some(e) = self.events.next() {
            if e.source != shm_schema::event::SOURCE_SUPERVISOR
                && let Some(prev) = self.last_seq.insert(e.source, e.seq)
                && e.seq > prev + 1
            {
                self.lost += e.seq - prev - 1;
            }
            match self.tx.try_send((e, self.lost)) {
                Ok(()) => self.lost = 0,
                Err(TrySendError::Full(_)) => self.lost += 1,
                // The network thread ended (it said why).
                Err(TrySendError::Disconnected(_)) => {}
            }
        }
        // A loss is said even when no event follows it: a note of the gateway's own, as soon
        // as the queue takes one.
        if self.lost > 0 {
            let mut note = EventV1::new(
                cx.now_ns(),
                code::EVENTS_DROPPED,
                -1,
                self.lost as f64,
                0.0,
                &[
                    "the line: events not forwarded (the cell published them faster than the network took them)",
                ],
            );
            note.source = self.source;
            if self.tx.try_send((note, self.lost)).is_ok() {
                self.lost = 0;
            }
        }
    }
}

fn main() -> ExitCode {
    let mut args = std::env::args_os();
    if args.nth(1).is_some_and(|a| a == "line") {
        return client::main(std::env::args_os().skip(2));
    }
    process::run(
        "gateway",
        "the cell on a line of cells: its presence, status, events and commands on Zenoh",
        Bridge::new,
    )
}

/// The cell's `[network]`, from the supervisor (asked until it answers: it serves its
/// control channel once every process of the cell has started).
fn settings(instance: &InstanceName) -> Option<NetworkSettings> {
    loop {
        match channel::call(instance, &Request::Network) {
            Ok(Reply::Network(Some(n))) => return Some(*n),
            Ok(Reply::Network(None)) => {
                tracing::error!(
                    "the cell has no [network] section: the gateway stays off the network"
                );
                return None;
            }
            Ok(other) => {
                tracing::error!("the supervisor answered [network] with {other:?}");
                return None;
            }
            Err(e) => {
                tracing::debug!("[network] not yet: {e}");
                std::thread::sleep(ASK_AGAIN);
            }
        }
        if runtime::signals::stop_requested() {
            return None;
        }
    }
}

/// The network thread: joins the line and serves the cell on it until the process ends.
fn line(
    instance: InstanceName,
    axes: Axes,
    kin: Option<ForwardKinematics>,
    mut events: Receiver<(EventV1, u64)>,
    note: SyncSender<Note>,
) {
    let off = |why: String| {
        tracing::error!("{why}: the gateway stays off the network");
        let _ = note.try_send(Note::Failed(why));
    };
    let Some(net) = settings(&instance) else {
        return;
    };
    let Some(name) = net.name.clone() else {
        off("[network] came without the cell's name".into());
        return;
    };
    let users = match Users::load(&net.users) {
        Ok(u) => u,
        Err(e) => {
            off(e.to_string());
            return;
        }
    };
    // Its ROS 2 topics, beside its own keys: what its access control lets it publish.
    let also: Vec<String> = (net.ros2.iter())
        .flat_map(|r| {
            let ns = r.namespace_of(&name);
            [
                format!("{}/{ns}/**", r.domain),
                ros2::graph_keys(r.domain, &ns),
            ]
        })
        .collect();
    let link = Link::of(&net, &name, &also);
    loop {
        let session = match link.open() {
            Ok(s) => s,
            Err(e) => {
                tracing::error!("{e}; trying again in {} s", JOIN_AGAIN.as_secs());
                let _ = note.try_send(Note::Failed(e));
                std::thread::sleep(JOIN_AGAIN);
                if runtime::signals::stop_requested() {
                    return;
                }
                continue;
            }
        };
        let at = if net.listen.is_empty() {
            format!("connected to {}", net.connect.join(", "))
        } else {
            net.listen.join(", ")
        };
        let _ = note.try_send(Note::Joined(format!("{name} on {at}")));
        let cell = Cell {
            axes: &axes,
            kin: kin.as_deref(),
        };
        match serve(&session, &instance, &name, &net, &users, &cell, &mut events) {
            Ok(()) => return,
            Err(e) => {
                let why = format!("the gateway left the line: {e}");
                tracing::error!("{why}; joining again in {} s", JOIN_AGAIN.as_secs());
                let _ = note.try_send(Note::Failed(why));
                drop(session);
                std::thread::sleep(JOIN_AGAIN);
            }
        }
    }
}

/// The cell on the line: presence, status, events, control.
fn serve(
    session: &zenoh::Session,
    instance: &InstanceName,
    name: &CellName,
    net: &NetworkSettings,
    users: &Users,
    cell: &Cell<'_>,
    events: &mut Receiver<(EventV1, u64)>,
) -> zenoh::Result<()> {
    let axes = cell.axes;
    let host = nix::unistd::gethostname()
        .ok()
        .and_then(|h| h.into_string().ok())
        .unwrap_or_default();
    let _alive = session.liveliness().declare_token(name.alive()).wait()?;
    // The latest status: what a `get` of the status key and a viewer's `status` command are
    // answered from (neither reaches the supervisor).
    let latest: Latest = Arc::default();
    let status_pub = session
        .declare_publisher(name.status())
        .congestion_control(CongestionControl::Drop)
        .wait()?;
    let for_query = latest.clone();
    let status_key = name.status();
    let _status_queryable = session
        .declare_queryable(name.status())
        .callback(move |q| {
            let bytes = for_query
                .lock()
                .ok()
                .and_then(|g| g.as_ref().map(|m| m.0.clone()));
            if let Some(b) = bytes {
                let _ = q.reply(&status_key, b).wait();
            }
        })
        .wait()?;
    // No event dropped on the way unsaid: the publications wait for a slow subscriber (a
    // dropped last one would go unnoticed, nothing numbered coming after it), on a thread of
    // their own (the status and the ROS 2 topics go on at their period); meanwhile the
    // cycle's queue fills, and what it cannot take is counted and said (`lost`). A link that
    // stays blocked 5 s is closed by Zenoh (`wait_before_close`): that peer has to join again.
    let event_pub = session
        .declare_publisher(name.events())
        .congestion_control(CongestionControl::Block)
        .wait()?;
    // Queries wait for the control thread in a ring: a flood drops the oldest, never blocks
    // Zenoh's own threads.
    let control = session
        .declare_queryable(name.control())
        .with(zenoh::handlers::RingChannel::new(CONTROL_QUEUE))
        .wait()?;
    let mut gate = Gate::new(users.clone(), name.as_str());
    // The commands in the cell's log: the first of a flood, then how many were not logged.
    let mut budget = LogBudget::new(LOG_LINES, LOG_WINDOW_MS);
    let control_instance = *instance;
    let for_control = latest.clone();
    std::thread::Builder::new()
        .name("control".into())
        .spawn(move || {
            while let Ok(q) = control.recv() {
                let answer = answer(&q, &mut gate, &mut budget, &control_instance, &for_control);
                let bytes = serde_json::to_vec(&answer).unwrap_or_default();
                let _ = q.reply(q.key_expr().clone(), bytes).wait();
            }
        })
        .map_err(|e| format!("cannot start the control thread: {e}"))?;
    tracing::info!(
        "on the line as {name} ({} listening, {} connecting)",
        net.listen.join(", "),
        net.connect.join(", ")
    );
    let mut ros = match &net.ros2 {
        Some(r) => Some(RosTopics::declare(session, name, r, cell)?),
        None => None,
    };
    // The recording stream and the web view beside the rest, ended with it.
    let leaving = AtomicBool::new(false);
    std::thread::scope(|scope| {
        type Stream = fn(OnTheLine<'_>) -> zenoh::Result<()>;
        let streams: [(&str, &str, Stream); 2] = [
            ("record", "the recording", recording::serve),
            ("view-line", "the web view", viewing::serve),
        ];
        for (thread, what, serve) in streams {
            let leaving = &leaving;
            let started = std::thread::Builder::new()
                .name(thread.into())
                .spawn_scoped(scope, move || {
                    let line = OnTheLine {
                        session,
                        instance,
                        name,
                        leaving,
                    };
                    if let Err(e) = serve(line) {
                        tracing::error!("{what} on the line ended: {e}");
                    }
                });
            if let Err(e) = started {
                // The threads already started end before the scope does.
                leaving.store(true, Ordering::Relaxed);
                return Err(format!("cannot start {what}'s thread: {e}").into());
            }
        }
        let publishing = std::thread::Builder::new()
            .name("events".into())
            .spawn_scoped(scope, || publish_events(&event_pub, events, axes, &leaving));
        let publishing = match publishing {
            Ok(p) => p,
            Err(e) => {
                leaving.store(true, Ordering::Relaxed);
                return Err(format!("cannot start the events' thread: {e}").into());
            }
        };
        let result = (|| -> zenoh::Result<()> {
            let period = Duration::from_secs_f64(net.status_period);
            let mut next_status = Instant::now();
            loop {
                // The events' thread ends when the cell's events end.
                if runtime::signals::stop_requested() || publishing.is_finished() {
                    return Ok(());
                }
                let wait = next_status.saturating_duration_since(Instant::now());
                if !wait.is_zero() {
                    std::thread::sleep(wait.min(LOOK_AGAIN));
                    continue;
                }
                next_status += period;
                if next_status < Instant::now() {
                    next_status = Instant::now() + period;
                }
                if let Ok(Reply::Status(s)) = channel::call(instance, &Request::Status) {
                    let m = StatusMessage {
                        cell: name.to_string(),
                        host: host.clone(),
                        status: s,
                    };
                    let bytes = serde_json::to_vec(&m).unwrap_or_default();
                    if let Some(r) = &mut ros {
                        r.publish(&m.status)?;
                    }
                    if let Ok(mut g) = latest.lock() {
                        *g = Some((bytes.clone(), m.status));
                    }
                    status_pub.put(bytes).wait()?;
                }
            }
        })();
        leaving.store(true, Ordering::Relaxed);
        // A panic aborts the process: a thread that ended has its result.
        let published = publishing.join().unwrap_or(Ok(()));
        result.and(published)
    })
}

/// The answer to a question on the cell's control key: who asks checked by `gate` (signed,
/// fresh, allowed) before anything is done; the status from the latest one published, any
/// other command asked of the supervisor. Logged within `budget`.
fn answer(
    q: &zenoh::query::Query,
    gate: &mut Gate,
    budget: &mut LogBudget,
    instance: &InstanceName,
    latest: &Latest,
) -> Answer {
    let payload = q
        .payload()
        .map(|p| p.to_bytes().to_vec())
        .unwrap_or_default();
    let signature = q
        .attachment()
        .and_then(|a| a.try_to_string().ok().map(|s| s.to_string()))
        .unwrap_or_default();
    let now = now_ms();
    let verdict = budget.take(now);
    if let Some(n) = verdict.held_before {
        tracing::warn!(
            "{n} more commands from the line not logged (at most {LOG_LINES} in {} s)",
            budget.window_s()
        );
    }
    match gate.admit(&payload, &signature, now) {
        Ok(a) => {
            if verdict.log {
                tracing::info!("{} ({:?}) asks: {}", a.user, a.role, a.command.op());
            }
            match a.command {
                Command::Status {} => latest
                    .lock()
                    .ok()
                    .and_then(|g| g.as_ref().map(|m| m.1.clone()))
                    .map_or_else(
                        || Answer::Failed {
                            reason: "no status of the cell yet".into(),
                        },
                        |status| Answer::Status { status },
                    ),
                ref other => ask(instance, other),
            }
        }
        Err(refusal) => {
            if verdict.log {
                tracing::warn!("a command refused: {refusal}");
            }
            Answer::Refused {
                by: RefusedBy::Gateway,
                reason: refusal.to_string(),
            }
        }
    }
}

/// The cell's events onto the line, numbered, each with the count lost just before it; until
/// the gateway leaves (`leaving`) or the cell's events end.
fn publish_events(
    event_pub: &zenoh::pubsub::Publisher<'_>,
    events: &mut Receiver<(EventV1, u64)>,
    axes: &Axes,
    leaving: &AtomicBool,
) -> zenoh::Result<()> {
    let started_ms = now_ms();
    let t0 = runtime::time::now_ns();
    let mut seq = 0u64;
    while !leaving.load(Ordering::Relaxed) {
        match events.recv_timeout(LOOK_AGAIN) {
            Ok((e, lost)) => {
                seq += 1;
                let m = EventMessage {
                    gateway_started_ms: started_ms,
                    seq,
                    lost,
                    event: control_plane::event::event(&e, axes, t0),
                };
                event_pub
                    .put(serde_json::to_vec(&m).unwrap_or_default())
                    .wait()?;
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => return Ok(()),
        }
    }
    Ok(())
}

/// A cell's forward kinematics, shared with the network thread.
type ForwardKinematics = Arc<dyn kinematics::Kinematics + Send + Sync>;

/// What the network thread knows of the cell: its axes, its forward kinematics.
struct Cell<'a> {
    axes: &'a Axes,
    /// `None` when the cell's kinematics cannot be built (the configuration was checked: not
    /// expected); the tool pose is then not published.
    kin: Option<&'a (dyn kinematics::Kinematics + Send + Sync)>,
}

/// The cell's forward kinematics: `[kinematics]` as trajgen builds it, or the gantry of its
/// axes (whose coordinates are its joints).
fn forward_kinematics(cell: &shm_schema::CellConfigV6) -> Option<ForwardKinematics> {
    let built = match motion_core::generator::Kin::of_cell(cell) {
        Ok(Some(kin)) => Ok(kin.0),
        Ok(None) => kinematics::Gantry::new(cell.axes().len())
            .map(|g| Arc::new(g) as ForwardKinematics)
            .map_err(|e| e.to_string()),
        Err(e) => Err(e.to_string()),
    };
    built
        .inspect_err(|e| tracing::warn!("no tool pose for ROS 2: {e}"))
        .ok()
}

/// The tool pose of `pose` (in `coords`): its position in m (`x`, `y`, `z`; 0 where the
/// kinematics has none) and its turn about z in rad (`theta`; 0 where none).
fn tool_pose(coords: &[kinematics::Coord], pose: &kinematics::Pose) -> ([f64; 3], f64) {
    let mut position = [0.0; 3];
    let mut yaw = 0.0;
    for (c, v) in coords.iter().zip(pose) {
        match c.name {
            "x" => position[0] = v * 1e-3,
            "y" => position[1] = v * 1e-3,
            "z" => position[2] = v * 1e-3,
            "theta" => yaw = v.to_radians(),
            _ => {}
        }
    }
    (position, yaw)
}

/// The cell's ROS 2 topics (`[network.ros2]`): its joint states and tool pose, from each
/// status it publishes.
struct RosTopics<'a> {
    publisher: zenoh::pubsub::Publisher<'static>,
    /// The tool pose's publisher, with the kinematics that gives it.
    pose: Option<(
        zenoh::pubsub::Publisher<'static>,
        &'a (dyn kinematics::Kinematics + Send + Sync),
    )>,
    /// The frame of the message: the namespace.
    frame: String,
    /// Each axis' name and how many m or rad its unit is.
    axes: Vec<(String, f64)>,
    /// The joint states' and the tool pose's GIDs in rmw_zenoh's attachment ([`ros2::gid`]).
    gids: [[u8; 16]; 2],
    seq: i64,
    /// The node and its publishers in ROS 2's graph, for as long as they publish.
    _graph: Vec<zenoh::liveliness::LivelinessToken>,
}

impl<'a> RosTopics<'a> {
    fn declare(
        session: &zenoh::Session,
        name: &CellName,
        r: &cell_config::network::Ros2,
        cell: &Cell<'a>,
    ) -> zenoh::Result<Self> {
        let frame = r.namespace_of(name);
        let declare = |key: String| {
            session
                .declare_publisher(key)
                .congestion_control(CongestionControl::Drop)
                .wait()
        };
        let publisher = declare(ros2::joint_states_key(r.domain, &frame))?;
        let pose = match cell.kin {
            Some(k) => Some((declare(ros2::tool_pose_key(r.domain, &frame))?, k)),
            None => None,
        };
        let zid = session.zid().to_string();
        let joints_token = ros2::publisher_token(
            r.domain,
            &zid,
            1,
            &frame,
            ros2::JOINT_STATES,
            ros2::JOINT_STATE_TYPE,
            ros2::JOINT_STATE_HASH,
        );
        let pose_token = ros2::publisher_token(
            r.domain,
            &zid,
            2,
            &frame,
            ros2::TOOL_POSE,
            ros2::POSE_STAMPED_TYPE,
            ros2::POSE_STAMPED_HASH,
        );
        let gids = [ros2::gid(&joints_token), ros2::gid(&pose_token)];
        let mut graph = vec![ros2::node_token(r.domain, &zid, &frame), joints_token];
        if pose.is_some() {
            graph.push(pose_token);
        }
        let graph = (graph.into_iter())
            .map(|key| session.liveliness().declare_token(key).wait())
            .collect::<zenoh::Result<Vec<_>>>()?;
        tracing::info!(
            "ROS 2: /{frame}/{} (sensor_msgs/msg/JointState) and /{frame}/{} (geometry_msgs/msg/PoseStamped) in domain {}",
            ros2::JOINT_STATES,
            ros2::TOOL_POSE,
            r.domain
        );
        Ok(Self {
            publisher,
            pose,
            frame,
            // The configuration was checked: every unit converts.
            axes: (cell.axes.axes.iter())
                .map(|(n, u)| (n.clone(), cell_config::network::ros_scale(u).unwrap_or(1.0)))
                .collect(),
            gids,
            seq: 0,
            _graph: graph,
        })
    }

    /// The joint states and tool pose of `status`, stamped now (none before servo's first
    /// report).
    fn publish(&mut self, status: &control_plane::status::Status) -> zenoh::Result<()> {
        let Some(servo) = &status.servo else {
            return Ok(());
        };
        let joints: Vec<(&str, f64)> = (self.axes.iter())
            .filter_map(|(n, scale)| Some((n.as_str(), servo.axes.get(n)?.position * scale)))
            .collect();
        // The cell's time: the Unix epoch's on the wall clock; on the virtual clock its own
        // instant (from one second after the epoch, the same in every run).
        let stamp_ns = if runtime::time::is_virtual() {
            runtime::time::now_ns()
        } else {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64)
        };
        self.seq += 1;
        self.publisher
            .put(ros2::joint_state(stamp_ns, &self.frame, &joints))
            .attachment(ros2::attachment(self.seq, stamp_ns as i64, &self.gids[0]))
            .wait()?;
        // The tool pose of the same joints, in the cell's units (mm, deg) for the kinematics.
        let Some((publisher, kin)) = &self.pose else {
            return Ok(());
        };
        let mut q: kinematics::Joints = [0.0; kinematics::MAX_JOINTS];
        for (slot, (n, _)) in q.iter_mut().zip(&self.axes) {
            *slot = servo.axes.get(n).map_or(0.0, |a| a.position);
        }
        let Ok(p) = kin.axes_to_cartesian(&q) else {
            return Ok(());
        };
        let (position, yaw) = tool_pose(kin.coords(), &p);
        publisher
            .put(ros2::pose_stamped(stamp_ns, &self.frame, position, yaw))
            .attachment(ros2::attachment(self.seq, stamp_ns as i64, &self.gids[1]))
            .wait()
    }
}

/// The latest status message, as published and typed.
type Latest = Arc<Mutex<Option<(Vec<u8>, Box<control_plane::status::Status>)>>>;

/// An admitted command, asked of the cell: answered within [`PATIENCE`] (a program's
/// validation included; the remote client waits as long).
fn ask(instance: &InstanceName, command: &Command) -> Answer {
    Answer::of_reply(channel::call_within(
        instance,
        &command.request(),
        Some(PATIENCE),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A gantry at (40 mm, 50 mm, 30 deg): the pose in m, turned 30 degrees about z.
    #[test]
    fn a_tool_pose_is_in_metres_and_radians() {
        let gantry = kinematics::Gantry::new(3).expect("a gantry");
        let kin: &dyn kinematics::Kinematics = &gantry;
        let mut q: kinematics::Joints = [0.0; kinematics::MAX_JOINTS];
        q[..3].copy_from_slice(&[40.0, 50.0, 30.0]);
        let p = kin.axes_to_cartesian(&q).expect("a pose");
        let (position, yaw) = tool_pose(kin.coords(), &p);
        assert!((position[0] - 0.04).abs() < 1e-12 && (position[1] - 0.05).abs() < 1e-12);
        assert_eq!(position[2], 0.0);
        assert!((yaw - std::f64::consts::FRAC_PI_6).abs() < 1e-12, "{yaw}");
    }
}
