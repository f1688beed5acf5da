//! `supervisor status`'s document composed from what the processes of a running instance
//! publish about themselves (their cycle counts, overruns and wake-up latency percentiles since
//! they started, the servo layer's state: power, settled, a latched fault, every drive's CiA 402
//! state, the drives' sense-to-command latency) with the supervisor's own view ([`Info`]). The
//! supervisor composes it from the newest samples its own ports took ([`Request::Status`]), so
//! a client of `status` opens no port of the cell; [`human`] is its text.
//!
//! [`Request::Status`]: crate::Request::Status

use crate::Info;
use crate::status::{
    AxisStatus, Detector, EstopSeen, EstopStatus, Health, Hold, HoldKind, HoldWord, IoEntry,
    IoStatus, MotionState, Percentiles, Power, ProcState, ProcessStatus, ProgramStatus, SafeValue,
    ServoFault, ServoStatus, Space, Status,
};
use indexmap::IndexMap;
use shm_schema::drive::servo_status as st;
use shm_schema::estop::{EstopState, HostStateV1};
use shm_schema::status::policy_name;
use shm_schema::{
    CellConfigV6, DetectorV1, DigitalIoV1, InstanceName, IoDirection, LatencyHistogramV1,
    ProcessStatusV2, ServoStateV3, SetpointV2, estop_seen, str_of,
};

/// One process as its own ports last said.
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

/// The newest of everything the processes publish that `status` shows.
#[derive(Clone, Debug)]
pub struct Snapshot {
    /// The processes that run and published a status, in the table's order.
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

/// The named digital IO: per entry its name, direction, value (`None` before iobridge's first
/// image), and for an output its safe value, for an input whether it is an e-stop circuit.
pub fn io_status(cell: &CellConfigV6, io: Option<&DigitalIoV1>) -> IoStatus {
    let entries = cell
        .io()
        .iter()
        .enumerate()
        .map(|(k, e)| {
            let name = str_of(&e.name).to_string();
            let value = io.map(|i| u8::from(i.values & (1 << k) != 0));
            match IoDirection::from_wire(e.direction) {
                Some(IoDirection::Output) => IoEntry::Output {
                    name,
                    value,
                    safe: match shm_schema::SafeValue::from_wire(e.safe) {
                        Some(shm_schema::SafeValue::On) => SafeValue::Level(1),
                        Some(shm_schema::SafeValue::Hold) => SafeValue::Hold(HoldWord::Hold),
                        _ => SafeValue::Level(0),
                    },
                },
                _ => IoEntry::Input {
                    name,
                    value,
                    estop: e.estop != 0,
                },
            }
        })
        .collect();
    IoStatus {
        entries,
        outputs_safe: io.map(|i| i.outputs_safe != 0),
        requests_taken: io.map(|i| i.taken),
        writes_refused: io.map(|i| i.refused),
    }
}

fn proc_state(state: u32) -> ProcState {
    match shm_schema::ProcState::from_wire(state) {
        Some(shm_schema::ProcState::Starting) => ProcState::Starting,
        Some(shm_schema::ProcState::Cyclic) => ProcState::Cyclic,
        Some(shm_schema::ProcState::Stopping) => ProcState::Stopping,
        Some(shm_schema::ProcState::Fault) => ProcState::Fault,
        None => ProcState::Unknown,
    }
}

fn drive_state(sw: u16) -> &'static str {
    cia402::State::from_statusword(sw).map_or("?", cia402::State::name)
}

/// Servo's state: the arm and every axis.
fn servo_status(s: &ServoStateV3, cell: Option<&CellConfigV6>) -> ServoStatus {
    let n = (s.axes as usize).min(shm_schema::MAX_AXES);
    let names: Vec<String> = (0..n)
        .map(|i| match cell {
            Some(c) if i < c.axes as usize => str_of(&c.axis[i].name).to_string(),
            _ => format!("axis {i}"),
        })
        .collect();
    let axes: IndexMap<String, AxisStatus> = names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            (
                name.clone(),
                AxisStatus {
                    power: Power::from(s.axis_power[i]),
                    drive_state: drive_state(s.statusword[i]).into(),
                    statusword: s.statusword[i],
                    settled: s.settled_axes & (1 << i) != 0,
                    position: s.act_position[i],
                    following_error: s.following_error[i],
                },
            )
        })
        .collect();
    let fault = (s.status & st::FAULT_LATCHED != 0).then(|| ServoFault {
        code: s.fault_code,
        name: shm_schema::event::info(s.fault_code)
            .map_or("unknown", |i| i.name)
            .into(),
        axis: usize::try_from(s.fault_axis)
            .ok()
            .and_then(|i| names.get(i))
            .cloned(),
        value: s.fault_value,
        limit: s.fault_limit,
    });
    ServoStatus {
        power: Power::from(s.power),
        initialized: s.status & st::INITIALIZED != 0,
        enabled: s.status & st::ENABLED != 0,
        settled: s.status & st::SETTLED != 0,
        fault,
        axes,
    }
}

/// The cell's e-stop: latched or clear, its origin, source and reason.
fn estop_status(snap: &Snapshot) -> Option<EstopStatus> {
    let h = snap.host.as_ref()?;
    let latched = h.estop == EstopState::Latched as u32;
    let names = snap
        .cell
        .as_deref()
        .map(crate::event::Axes::of_cell)
        .unwrap_or_default();
    Some(EstopStatus {
        latched,
        origin: latched.then(|| h.cause.origin.into()),
        source: latched.then(|| names.source_name(h.cause.source)),
        reason: latched.then(|| str_of(&h.cause.reason).to_string()),
        cause: latched.then(|| {
            shm_schema::event::info(h.cause.code)
                .map_or("", |i| i.name)
                .to_string()
        }),
        resets: h.resets,
    })
}

/// trajgen's program: state, line, motion time.
fn program_status(snap: &Snapshot) -> Option<ProgramStatus> {
    let sp = snap.setpoint.as_ref()?;
    let state = match shm_schema::MotionState::from_wire(sp.state) {
        Some(shm_schema::MotionState::Idle) => MotionState::Idle,
        Some(shm_schema::MotionState::Moving) => MotionState::Moving,
        Some(shm_schema::MotionState::Done) => MotionState::Done,
        Some(shm_schema::MotionState::Fault) => MotionState::Fault,
        None => MotionState::Unknown,
    };
    let holds = match sp.hold {
        shm_schema::motion::hold::WAIT => Some(Hold {
            what: HoldKind::Wait,
            input: snap
                .cell
                .as_deref()
                .and_then(|c| c.io().get(sp.hold_io as usize))
                .map(|e| str_of(&e.name).to_string()),
        }),
        shm_schema::motion::hold::DELAY => Some(Hold {
            what: HoldKind::Delay,
            input: None,
        }),
        _ => None,
    };
    Some(ProgramStatus {
        state,
        program_id: sp.program_id,
        line: sp.line,
        motion_time_s: sp.motion_time_s,
        waited_s: sp.waited_s,
        holds,
        path_speed: sp.path_speed,
        speed_override: sp.speed_override,
        program_speed: sp.program_speed,
        space: if sp.space == 0 {
            Space::Cartesian
        } else {
            Space::Joint
        },
        cartesian: sp.cartesian[..(sp.coords as usize).min(sp.cartesian.len())].to_vec(),
        fault: (sp.fault != 0).then(|| shm_schema::motion::trajgen_fault::text(sp.fault).into()),
    })
}

/// Percentiles of a histogram that has samples.
fn percentiles(h: Option<&LatencyHistogramV1>) -> Option<Percentiles> {
    h.filter(|h| h.count > 0).map(Percentiles::of)
}

fn process_status(p: &Seen) -> ProcessStatus {
    let s = &p.status;
    let detector = |d: &DetectorV1| Detector {
        level: d.level,
        limit: d.limit,
        total: d.total,
    };
    ProcessStatus {
        pid: s.pid,
        state: proc_state(s.state),
        estop: EstopSeen {
            latched: s.estop & estop_seen::LATCHED != 0,
            reacting: s.estop & estop_seen::REACTING != 0,
            safe: s.estop & estop_seen::SAFE != 0,
            raised: s.estop & estop_seen::RAISED != 0,
        },
        health: Health {
            pending_sequence_overrun: detector(&s.pending_sequence),
            transport_overrun: detector(&s.transport),
            thread_offset_variance: detector(&s.thread_offset),
        },
        policy: policy_name(s.policy).into(),
        priority: s.priority,
        cpu: s.cpu,
        fault: s.fault,
        period_us: s.stats.period_ns as f64 * 1e-3,
        cycles: s.stats.cycles,
        overruns: s.stats.overruns,
        skipped: s.stats.skipped,
        max_exec_us: s.stats.max_exec_ns as f64 * 1e-3,
        // An empty wake-up histogram still says "published" (all zeros), as it always did.
        wakeup_latency_us: p.latency.as_deref().map(Percentiles::of),
        exec_time_us: percentiles(p.exec_time.as_deref()),
    }
}

/// The document of `supervisor status --json`: what `snap` read, with the supervisor's `info`.
pub fn status(instance: &InstanceName, snap: &Snapshot, info: Info) -> Status {
    Status {
        instance: instance.as_str().to_string(),
        estop: estop_status(snap),
        program: program_status(snap),
        processes: snap
            .processes
            .iter()
            .map(|p| (p.name.clone(), process_status(p)))
            .collect(),
        servo: snap
            .servo
            .as_ref()
            .map(|s| servo_status(s, snap.cell.as_deref())),
        io: snap.cell.as_deref().map(|c| io_status(c, snap.io.as_ref())),
        sense_to_command_us: percentiles(snap.sense_to_command.as_deref()),
        supervisor: info,
    }
}

/// `supervisor status` as text: the supervisor's lines, then the table of the processes, the
/// arm and the IO.
pub fn human(status: &Status) -> String {
    let mut out = status.supervisor.lines();
    out += &format!(
        "instance {}: wake-up latency since each process started (µs)\n\
         process    pid      state     policy       prio    cycles  overruns       p50       p99     p99.9    p99.99       max  exec p99\n",
        status.instance
    );
    for (name, p) in &status.processes {
        out += &format!(
            "{:<9}  {:<7}  {:<8}  {:<11}  {:>4}  {:>8}  {:>8}",
            name,
            p.pid,
            crate::word(&p.state),
            p.policy,
            p.priority,
            p.cycles,
            p.overruns
        );
        match &p.wakeup_latency_us {
            Some(m) => {
                let exec = p
                    .exec_time_us
                    .map_or("-".to_string(), |e| format!("{:.1}", e.p99_us));
                out += &format!(
                    "  {:>8.1}  {:>8.1}  {:>8.1}  {:>8.1}  {:>8.1}  {:>8}\n",
                    m.p50_us, m.p99_us, m.p99_9_us, m.p99_99_us, m.max_us, exec
                );
            }
            None => out += "  (no latency histogram published)\n",
        }
    }
    if let Some(m) = &status.sense_to_command_us {
        out += &format!(
            "sense to command (encoder sample to the drives applying its command): p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs\n",
            m.p50_us, m.p99_us, m.max_us
        );
    }
    if let Some(s) = &status.servo {
        out += &format!(
            "arm: {}{}{}\n",
            crate::word(&s.power),
            if s.settled { ", settled" } else { "" },
            match &s.fault {
                None => String::new(),
                Some(f) => format!(
                    ", e-stop: {} latched{} (value {}, limit {}); reset, then enable",
                    f.name,
                    f.axis
                        .as_deref()
                        .map_or(String::new(), |a| format!(" on axis {a}")),
                    f.value,
                    f.limit
                ),
            }
        );
        for (name, a) in &s.axes {
            out += &format!(
                "  axis {name:<8} {:<10} {:<24} position {:>10.4}  following error {:>8.4}{}\n",
                crate::word(&a.power),
                a.drive_state,
                a.position,
                a.following_error,
                if a.settled { "  settled" } else { "" }
            );
        }
    }
    if let Some(io) = status.io.as_ref().filter(|io| !io.entries.is_empty()) {
        let words: Vec<String> = io
            .entries
            .iter()
            .map(|e| {
                let value = e.value().map_or("?".into(), |v| v.to_string());
                format!("{}={value}", e.name())
            })
            .collect();
        out += &format!(
            "io: {}{}\n",
            words.join("  "),
            if io.outputs_safe == Some(true) {
                "  (outputs held safe by the e-stop)"
            } else {
                ""
            }
        );
    }
    out
}
