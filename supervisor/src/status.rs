//! `supervisor status`: what the processes of a running instance report about themselves,
//! their cycle counts, overruns and wake-up latency percentiles since they started, the
//! servo layer's state (power, settled, a latched fault, every drive's CiA 402 state) and the
//! drives' sense-to-command latency.

use latency::report::Summary;
use runtime::ipc::{self, Sub};
use runtime::rt::policy_name;
use serde_json::{Map, Value, json};
use shm_schema::drive::servo_status as st;
use shm_schema::estop::{EstopState, HostStateV1};
use shm_schema::{
    CellConfigV6, DetectorV1, DigitalIoV1, EstopOrigin, InstanceName, IoDirection,
    LatencyHistogramV1, MotionState, Power, ProcState, ProcessName, ProcessStatusV2, SafeValue,
    ServiceId, ServoStateV3, SetpointV2, estop_seen, str_of,
};
use std::time::{Duration, Instant};

/// How long `status` listens for the processes' publications (the latency histogram comes
/// about every 100 ms).
pub const LISTEN: Duration = Duration::from_millis(600);

/// One process as seen by `status`.
#[derive(Clone, Debug)]
pub struct Seen {
    /// Its name.
    pub name: String,
    /// Its latest status.
    pub status: ProcessStatusV2,
    /// Its latest latency histogram, if it publishes one.
    pub latency: Option<Box<LatencyHistogramV1>>,
    /// Its latest execution-time histogram, if it publishes one.
    pub exec_time: Option<Box<LatencyHistogramV1>>,
}

/// Everything `status` read.
#[derive(Clone, Debug)]
pub struct Snapshot {
    /// The processes that published a status.
    pub processes: Vec<Seen>,
    /// Servo's latest state.
    pub servo: Option<ServoStateV3>,
    /// The cell configuration (axis names and units).
    pub cell: Option<Box<CellConfigV6>>,
    /// The drives' sense-to-command latency since they started.
    pub sense_to_command: Option<Box<LatencyHistogramV1>>,
    /// The supervisor's heartbeat and latched e-stop.
    pub host: Option<HostStateV1>,
    /// trajgen's newest setpoint (the running program, its line, its motion time).
    pub setpoint: Option<SetpointV2>,
    /// iobridge's newest image of the named digital IO.
    pub io: Option<DigitalIoV1>,
}

/// Reads the status and latency of every process of `instance`. Errors when nothing of the
/// instance is running.
pub fn read(instance: &InstanceName) -> Result<Snapshot, String> {
    ipc::quiet_iceoryx2_log();
    let live = ipc::live_node_pids(instance).unwrap_or_default();
    if live.is_empty() {
        return Err(format!(
            "no process of instance {instance} is running (start one with `supervisor run --instance {instance} PROGRAM`)"
        ));
    }
    let f = |e: ipc::IpcError| e.to_string();
    let node = ipc::node(instance, &format!("status-{}", std::process::id())).map_err(f)?;
    let cell_sub =
        Sub::<CellConfigV6>::new(&node, instance, ServiceId::CellConfig, 1).map_err(f)?;
    let start = Instant::now();
    let cell = loop {
        if let Some(c) = cell_sub.latest() {
            break Box::new(c);
        }
        if start.elapsed() > LISTEN {
            drop(cell_sub);
            drop(node);
            ipc::cleanup_after_client(instance);
            return Err(format!(
                "instance {instance} has live nodes (pids {live:?}) but publishes no cell configuration"
            ));
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let mut ports = Vec::new();
    let mut seen: Vec<Seen> = Vec::new();
    for (k, p) in cell.processes().iter().enumerate() {
        let Some(name) = ProcessName::from_field(&p.name) else {
            continue;
        };
        let status =
            Sub::<ProcessStatusV2>::new(&node, instance, ServiceId::Status(name), 4).map_err(f)?;
        let latency = Sub::<LatencyHistogramV1>::new(&node, instance, ServiceId::Latency(name), 1)
            .map_err(f)?;
        let exec = Sub::<LatencyHistogramV1>::new(&node, instance, ServiceId::ExecTime(name), 1)
            .map_err(f)?;
        ports.push((k, status, latency, exec));
        seen.push(Seen {
            name: name.to_string(),
            status: ProcessStatusV2::default(),
            latency: None,
            exec_time: None,
        });
    }
    let servo_sub =
        Sub::<ServoStateV3>::new(&node, instance, ServiceId::ServoState, 4).map_err(f)?;
    let sense_sub =
        Sub::<LatencyHistogramV1>::new(&node, instance, ServiceId::SenseToCommand, 1).map_err(f)?;
    let host_sub = Sub::<HostStateV1>::new(&node, instance, ServiceId::HostState, 1).map_err(f)?;
    let setpoint_sub =
        Sub::<SetpointV2>::new(&node, instance, ServiceId::Setpoint, 4).map_err(f)?;
    let io_sub = Sub::<DigitalIoV1>::new(&node, instance, ServiceId::IoState, 1).map_err(f)?;
    let (mut servo, mut sense, mut host, mut setpoint, mut io) = (None, None, None, None, None);
    let mut heard = vec![false; seen.len()];
    let start = Instant::now();
    while start.elapsed() < LISTEN {
        for (k, ((_, status, latency, exec), p)) in ports.iter().zip(seen.iter_mut()).enumerate() {
            if let Some(x) = status.latest() {
                p.status = x;
                heard[k] = true;
            }
            if let Some(x) = latency.latest() {
                p.latency = Some(Box::new(x));
            }
            if let Some(x) = exec.latest() {
                p.exec_time = Some(Box::new(x));
            }
        }
        if let Some(x) = servo_sub.latest() {
            servo = Some(x);
        }
        if let Some(x) = sense_sub.latest() {
            sense = Some(Box::new(x));
        }
        if let Some(x) = host_sub.latest() {
            host = Some(x);
        }
        if let Some(x) = setpoint_sub.latest() {
            setpoint = Some(x);
        }
        if let Some(x) = io_sub.latest() {
            io = Some(x);
        }
        if heard.iter().all(|h| *h)
            && seen
                .iter()
                .all(|p| p.latency.is_some() && p.exec_time.is_some())
            && servo.is_some()
            && sense.is_some()
            && host.is_some()
            && setpoint.is_some()
            && (io.is_some() || cell.io().is_empty())
        {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    drop((host_sub, setpoint_sub, io_sub));
    drop((ports, servo_sub, cell_sub, sense_sub));
    drop(node);
    ipc::cleanup_after_client(instance);
    let out: Vec<Seen> = seen
        .into_iter()
        .zip(heard)
        .filter_map(|(p, h)| h.then_some(p))
        .collect();
    if out.is_empty() {
        return Err(format!(
            "instance {instance} has live nodes (pids {live:?}) but no process published a status within {} ms",
            LISTEN.as_millis()
        ));
    }
    Ok(Snapshot {
        processes: out,
        servo,
        cell: Some(cell),
        sense_to_command: sense,
        host,
        setpoint,
        io,
    })
}

/// The named digital IO: per entry its name, direction, value (null before iobridge's first
/// image), and for an output its safe value, for an input whether it is an e-stop circuit.
pub fn io_json(cell: &CellConfigV6, io: Option<&DigitalIoV1>) -> Value {
    let entries: Vec<Value> = cell
        .io()
        .iter()
        .enumerate()
        .map(|(k, e)| {
            let value = io.map(|i| u8::from(i.values & (1 << k) != 0));
            match IoDirection::from_u32(e.direction) {
                Some(IoDirection::Output) => json!({
                    "name": str_of(&e.name),
                    "direction": "output",
                    "value": value,
                    "safe": match SafeValue::from_u32(e.safe) {
                        Some(SafeValue::On) => json!(1),
                        Some(SafeValue::Hold) => json!("hold"),
                        _ => json!(0),
                    },
                }),
                _ => json!({
                    "name": str_of(&e.name),
                    "direction": "input",
                    "value": value,
                    "estop": e.estop != 0,
                }),
            }
        })
        .collect();
    json!({
        "entries": entries,
        "outputs_safe": io.map(|i| i.outputs_safe != 0),
        "requests_taken": io.map(|i| i.taken),
        "writes_refused": io.map(|i| i.refused),
    })
}

fn state_name(state: u32) -> &'static str {
    match ProcState::from_u32(state) {
        Some(ProcState::Starting) => "starting",
        Some(ProcState::Cyclic) => "cyclic",
        Some(ProcState::Stopping) => "stopping",
        Some(ProcState::Fault) => "fault",
        None => "?",
    }
}

fn power_name(v: u8) -> &'static str {
    Power::from_u8(v).map_or("?", Power::name)
}

fn drive_state(sw: u16) -> &'static str {
    cia402::State::from_statusword(sw).map_or("?", cia402::State::name)
}

/// Servo's state as JSON: the arm and every axis.
fn servo_json(s: &ServoStateV3, cell: Option<&CellConfigV6>) -> Value {
    let n = (s.axes as usize).min(shm_schema::MAX_AXES);
    let names: Vec<String> = (0..n)
        .map(|i| match cell {
            Some(c) if i < c.axes as usize => str_of(&c.axis[i].name).to_string(),
            _ => format!("axis {i}"),
        })
        .collect();
    let mut axes = Map::new();
    for (i, n) in names.iter().enumerate() {
        axes.insert(
            n.clone(),
            json!({
                "power": power_name(s.axis_power[i]),
                "drive_state": drive_state(s.statusword[i]),
                "statusword": s.statusword[i],
                "settled": s.settled_axes & (1 << i) != 0,
                "position": s.act_position[i],
                "following_error": s.following_error[i],
            }),
        );
    }
    let fault = (s.status & st::FAULT_LATCHED != 0).then(|| {
        json!({
            "code": s.fault_code,
            "name": shm_schema::event::info(s.fault_code).map_or("unknown", |i| i.name),
            "axis": names.get(s.fault_axis as usize),
            "value": s.fault_value,
            "limit": s.fault_limit,
        })
    });
    json!({
        "power": power_name(s.power),
        "initialized": s.status & st::INITIALIZED != 0,
        "enabled": s.status & st::ENABLED != 0,
        "settled": s.status & st::SETTLED != 0,
        "fault": fault,
        "axes": axes,
    })
}

/// The cell's e-stop: latched or clear, its origin, source and reason.
fn estop_json(snap: &Snapshot) -> Value {
    let Some(h) = &snap.host else {
        return Value::Null;
    };
    let latched = h.estop == EstopState::Latched as u32;
    let names = snap
        .cell
        .as_deref()
        .map(crate::events::Axes::of_cell)
        .unwrap_or_default();
    json!({
        "latched": latched,
        "origin": latched.then(|| EstopOrigin::from_u32(h.cause.origin).map_or("?", EstopOrigin::name)),
        "source": latched.then(|| names.source_name(h.cause.source)),
        "reason": latched.then(|| str_of(&h.cause.reason).to_string()),
        "cause": latched.then(|| shm_schema::event::info(h.cause.code).map_or("", |i| i.name)),
        "resets": h.resets,
    })
}

/// trajgen's program: state, line, motion time.
fn program_json(snap: &Snapshot) -> Value {
    let Some(sp) = &snap.setpoint else {
        return Value::Null;
    };
    let state = match MotionState::from_u32(sp.state) {
        Some(MotionState::Idle) => "idle",
        Some(MotionState::Moving) => "moving",
        Some(MotionState::Done) => "done",
        Some(MotionState::Fault) => "fault",
        None => "?",
    };
    json!({
        "state": state,
        "program_id": sp.program_id,
        "line": sp.line,
        "motion_time_s": sp.motion_time_s,
        "waited_s": sp.waited_s,
        "holds": match sp.hold {
            shm_schema::motion::hold::WAIT => json!({"for": "wait", "input": snap.cell.as_deref().and_then(|c| c.io().get(sp.hold_io as usize)).map(|e| str_of(&e.name))}),
            shm_schema::motion::hold::DELAY => json!({"for": "delay"}),
            _ => Value::Null,
        },
        "path_speed": sp.path_speed,
        "speed_override": sp.speed_override,
        "program_speed": sp.program_speed,
        "space": if sp.space == 0 { "cartesian" } else { "joint" },
        "cartesian": &sp.cartesian[..(sp.coords as usize).min(sp.cartesian.len())],
        "fault": (sp.fault != 0).then(|| shm_schema::motion::trajgen_fault::text(sp.fault)),
    })
}

/// The JSON object of `supervisor status --json`.
pub fn to_json(instance: &InstanceName, snap: &Snapshot) -> Value {
    let mut procs = Map::new();
    for p in &snap.processes {
        let s = &p.status;
        let detector =
            |d: &DetectorV1| json!({"level": d.level, "limit": d.limit, "total": d.total});
        procs.insert(
            p.name.clone(),
            json!({
                "pid": s.pid,
                "state": state_name(s.state),
                "estop": {
                    "latched": s.estop & estop_seen::LATCHED != 0,
                    "reacting": s.estop & estop_seen::REACTING != 0,
                    "safe": s.estop & estop_seen::SAFE != 0,
                    "raised": s.estop & estop_seen::RAISED != 0,
                },
                "health": {
                    "pending_sequence_overrun": detector(&s.pending_sequence),
                    "transport_overrun": detector(&s.transport),
                    "thread_offset_variance": detector(&s.thread_offset),
                },
                "policy": policy_name(s.policy),
                "priority": s.priority,
                "cpu": s.cpu,
                "fault": s.fault,
                "period_us": s.stats.period_ns as f64 * 1e-3,
                "cycles": s.stats.cycles,
                "overruns": s.stats.overruns,
                "skipped": s.stats.skipped,
                "max_exec_us": s.stats.max_exec_ns as f64 * 1e-3,
                "wakeup_latency_us": p.latency.as_ref().map(|h| Summary::of(h).to_json()),
                "exec_time_us": p.exec_time.as_ref().filter(|h| h.count > 0).map(|h| Summary::of(h).to_json()),
            }),
        );
    }
    json!({
        "instance": instance.as_str(),
        "estop": estop_json(snap),
        "program": program_json(snap),
        "processes": procs,
        "servo": snap.servo.as_ref().map(|s| servo_json(s, snap.cell.as_deref())),
        "io": snap.cell.as_deref().map(|c| io_json(c, snap.io.as_ref())),
        "sense_to_command_us": snap.sense_to_command.as_ref().filter(|h| h.count > 0).map(|h| Summary::of(h).to_json()),
    })
}

/// The supervisor's part of `supervisor status` (its `Info` answer): the e-stop, the
/// program, and per process its life and restarts.
pub fn supervisor_lines(info: &Value) -> String {
    let mut out = format!(
        "supervisor pid {} ({}), e-stop resets {}\n",
        info["pid"],
        info["mode"].as_str().unwrap_or("?"),
        info["resets"]
    );
    match &info["estop"] {
        Value::Null => out += "e-stop: clear\n",
        e => {
            out += &format!(
                "e-stop: LATCHED: {}\n  `supervisor reset`, then `supervisor start`\n",
                e["text"].as_str().unwrap_or("?")
            )
        }
    }
    match &info["job"] {
        Value::Null => {
            out += "program: none";
            if let Some(l) = info["last_job"].as_object() {
                out += &format!(
                    " (last: {} {})",
                    l["program"].as_str().unwrap_or("?"),
                    if l["ok"] == true { "done" } else { "failed" }
                );
            }
            out += "\n";
        }
        j => {
            out += &format!(
                "program: {} line {} motion {:.2} / {:.2} s{}\n",
                j["program"].as_str().unwrap_or("?"),
                j["line"],
                j["motion_time_s"].as_f64().unwrap_or(0.0),
                j["predicted_s"].as_f64().unwrap_or(0.0),
                if j["paused"] == true { " PAUSED" } else { "" }
            )
        }
    }
    if let Some(procs) = info["processes"].as_array() {
        for p in procs {
            out += &format!(
                "  {:<9} {:<10} pid {:<8} restarts {}{}{}{}\n",
                p["name"].as_str().unwrap_or("?"),
                p["life"].as_str().unwrap_or("?"),
                p["pid"],
                p["restarts"],
                if p["critical"] == false {
                    "  not critical"
                } else {
                    ""
                },
                p["listening"]
                    .as_str()
                    .map_or(String::new(), |a| format!("  listening on {a}")),
                p["why"]
                    .as_str()
                    .map_or(String::new(), |w| format!("  ({w})"))
            );
        }
    }
    out
}

/// The table of `supervisor status`.
pub fn human(instance: &InstanceName, snap: &Snapshot) -> String {
    let seen = &snap.processes;
    let mut out = format!(
        "instance {instance}: wake-up latency since each process started (µs)\n\
         process    pid      state     policy       prio    cycles  overruns       p50       p99     p99.9    p99.99       max  exec p99\n"
    );
    for p in seen {
        let s = &p.status;
        out += &format!(
            "{:<9}  {:<7}  {:<8}  {:<11}  {:>4}  {:>8}  {:>8}",
            p.name,
            s.pid,
            state_name(s.state),
            policy_name(s.policy),
            s.priority,
            s.stats.cycles,
            s.stats.overruns
        );
        match &p.latency {
            Some(h) => {
                let m = Summary::of(h);
                let exec = p
                    .exec_time
                    .as_ref()
                    .filter(|h| h.count > 0)
                    .map_or("-".to_string(), |h| format!("{:.1}", Summary::of(h).p99_us));
                out += &format!(
                    "  {:>8.1}  {:>8.1}  {:>8.1}  {:>8.1}  {:>8.1}  {:>8}\n",
                    m.p50_us, m.p99_us, m.p99_9_us, m.p99_99_us, m.max_us, exec
                );
            }
            None => out += "  (no latency histogram published)\n",
        }
    }
    if let Some(h) = snap.sense_to_command.as_ref().filter(|h| h.count > 0) {
        let m = Summary::of(h);
        out += &format!(
            "sense to command (encoder sample to the drives applying its command): p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs\n",
            m.p50_us, m.p99_us, m.max_us
        );
    }
    if let Some(s) = &snap.servo {
        let v = servo_json(s, snap.cell.as_deref());
        out += &format!(
            "arm: {}{}{}\n",
            v["power"].as_str().unwrap_or("?"),
            if s.status & st::SETTLED != 0 {
                ", settled"
            } else {
                ""
            },
            match &v["fault"] {
                Value::Null => String::new(),
                f => format!(
                    ", e-stop: {} latched{} (value {}, limit {}); reset, then enable",
                    f["name"].as_str().unwrap_or("?"),
                    f["axis"]
                        .as_str()
                        .map_or(String::new(), |a| format!(" on axis {a}")),
                    f["value"],
                    f["limit"]
                ),
            }
        );
        if let Some(axes) = v["axes"].as_object() {
            for (name, a) in axes {
                out += &format!(
                    "  axis {name:<8} {:<10} {:<24} position {:>10.4}  following error {:>8.4}{}\n",
                    a["power"].as_str().unwrap_or("?"),
                    a["drive_state"].as_str().unwrap_or("?"),
                    a["position"].as_f64().unwrap_or(f64::NAN),
                    a["following_error"].as_f64().unwrap_or(f64::NAN),
                    if a["settled"] == true {
                        "  settled"
                    } else {
                        ""
                    }
                );
            }
        }
    }
    if let Some(cell) = snap.cell.as_deref().filter(|c| !c.io().is_empty()) {
        let v = io_json(cell, snap.io.as_ref());
        let words: Vec<String> = v["entries"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|e| {
                let value = e["value"].as_u64().map_or("?".into(), |v| v.to_string());
                format!("{}={value}", e["name"].as_str().unwrap_or("?"))
            })
            .collect();
        out += &format!(
            "io: {}{}\n",
            words.join("  "),
            if v["outputs_safe"] == true {
                "  (outputs held safe by the e-stop)"
            } else {
                ""
            }
        );
    }
    out
}
