//! The recorder (`supervisor record`): every service of a running cell into MCAP files, for Foxglove and
//! PlotJuggler (docs/recording.md).
//!
//! An observer like any other: its own node, subscribers with the largest buffers the services
//! allow, nothing the cell waits for. Each message is JSON with a JSON Schema (MCAP's
//! `jsonschema` profile, which both viewers decode), timestamped with the time in the sample
//! itself (`CLOCK_MONOTONIC`, mapped to the Unix epoch once at the start). Per-axis arrays are
//! objects keyed by the axis' name (`/servo/state` → `act_position.x`), the latency histograms
//! are summarised (count, percentiles, maximum). Memory stays bounded: messages go out in
//! compressed chunks; files rotate by size or time. Samples the recorder did not read in time
//! (a subscriber's buffer overflowed) are counted per topic from the gaps in their sequence
//! numbers.

use control_plane::event::Axes;
use mcap::records::MessageHeader;
use runtime::ipc::Payload;
use runtime::ipc::{self, Sub};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value, json};
use shm_schema::estop::HostStateV1;
use shm_schema::latency::LatencyHistogramV1;
use shm_schema::{
    CellConfigV6, CycleStatsV1, DetectorV1, DigitalIoV1, DriveCommandV2, DriveFeedbackV2, EstopV1,
    EventV1, FieldbusImageV1, InstanceName, MAX_AXES, MotionCommandV2, MotionControlV2,
    ProcessName, ProcessStatusV2, ServiceId, ServoStateV3, SetpointV2, str_of,
};
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// How a field becomes JSON, and its JSON Schema.
trait Enc<T> {
    fn enc(v: &T, axes: &[String]) -> Value;
    fn schema(v: &T, axes: &[String]) -> Value;
}

/// A number.
struct Num;
impl<T: Serialize> Enc<T> for Num {
    fn enc(v: &T, _: &[String]) -> Value {
        json!(v)
    }
    fn schema(_: &T, _: &[String]) -> Value {
        json!({"type": "number"})
    }
}

/// A per-axis array: an object keyed by the axes' names (the axes in use only).
struct PerAxis;
impl<T: Serialize> Enc<[T; MAX_AXES]> for PerAxis {
    fn enc(v: &[T; MAX_AXES], axes: &[String]) -> Value {
        Value::Object(
            axes.iter()
                .zip(v.iter())
                .map(|(a, x)| (a.clone(), json!(x)))
                .collect(),
        )
    }
    fn schema(_: &[T; MAX_AXES], axes: &[String]) -> Value {
        let props: Map<String, Value> = axes
            .iter()
            .map(|a| (a.clone(), json!({"type": "number"})))
            .collect();
        json!({"type": "object", "properties": props})
    }
}

/// A fixed array of numbers, whole (the tool's coordinates: named by the kinematics, not by
/// the axes).
struct Array;
impl<T: Serialize, const N: usize> Enc<[T; N]> for Array {
    fn enc(v: &[T; N], _: &[String]) -> Value {
        json!(v.as_slice())
    }
    fn schema(_: &[T; N], _: &[String]) -> Value {
        json!({"type": "array", "items": {"type": "number"}})
    }
}

/// NUL-padded text.
struct Text;
impl<const N: usize> Enc<[u8; N]> for Text {
    fn enc(v: &[u8; N], _: &[String]) -> Value {
        json!(str_of(v))
    }
    fn schema(_: &[u8; N], _: &[String]) -> Value {
        json!({"type": "string"})
    }
}

/// A nested record.
struct Nested;
impl<T: Message> Enc<T> for Nested {
    fn enc(v: &T, axes: &[String]) -> Value {
        v.json(axes)
    }
    fn schema(_: &T, axes: &[String]) -> Value {
        T::schema(axes)
    }
}

/// A payload as a recorded message.
trait Message: Copy + std::fmt::Debug + 'static {
    /// The schema's name.
    const NAME: &'static str;
    fn json(&self, axes: &[String]) -> Value;
    fn schema(axes: &[String]) -> Value;
    /// The time in the sample (ns, `CLOCK_MONOTONIC`), if it has one.
    fn stamp_ns(&self) -> Option<u64> {
        None
    }
    /// (stream, sequence number): numbers that grow by one per sample of a stream.
    fn seq(&self) -> Option<(u64, u64)> {
        None
    }
}

/// Declares the recorded payloads, each with its schema's name, where its time stamp and its
/// sequence number are, and its fields as they are recorded (`Num`, `PerAxis`, `Text`,
/// `Nested`), plus those deliberately not recorded (`not recorded { … }`). Every field of the
/// payload is one or the other: [`coverage`] (checked by a test against the type's size)
/// fails the build's tests when a field is added to a payload and not here.
macro_rules! messages {
    ($( $t:ty, $name:literal, stamp: |$s:ident| $stamp:expr, seq: |$q:ident| $seq:expr,
        { $($f:ident : $k:ident),* $(,)? } $(not recorded { $($skip:ident),* $(,)? })? ; )*) => {
        $(
        impl Message for $t {
            const NAME: &'static str = $name;
            fn json(&self, axes: &[String]) -> Value {
                let mut m = Map::new();
                $( m.insert(stringify!($f).into(), <$k as Enc<_>>::enc(&self.$f, axes)); )*
                Value::Object(m)
            }
            fn schema(axes: &[String]) -> Value {
                let d = <$t>::default();
                let mut props = Map::new();
                $( props.insert(stringify!($f).into(), <$k as Enc<_>>::schema(&d.$f, axes)); )*
                json!({"title": $name, "type": "object", "properties": props})
            }
            fn stamp_ns(&self) -> Option<u64> {
                let $s = self;
                $stamp
            }
            fn seq(&self) -> Option<(u64, u64)> {
                let $q = self;
                $seq
            }
        }
        )*

        /// Per payload declared above: its schema's name, the bytes of the fields it names
        /// (recorded or not), and its size. The two are equal when every field is named (the
        /// payloads have no padding: `shm-schema`'s layout test).
        #[cfg(test)]
        fn coverage() -> Vec<(&'static str, usize, usize)> {
            vec![$({
                let d = <$t>::default();
                let named = 0 $(+ std::mem::size_of_val(&d.$f))*
                    $($(+ std::mem::size_of_val(&d.$skip))*)?;
                ($name, named, std::mem::size_of::<$t>())
            }),*]
        }
    };
}

messages! {
    SetpointV2, "rtc.SetpointV2", stamp: |s| Some(s.stamp_ns), seq: |s| Some((0, s.seq)), {
        seq: Num, stamp_ns: Num, program_id: Num, line: Num, state: Num, fault: Num,
        fault_line: Num, motion_time_s: Num, theoretical_s: Num, segment_time_s: Num,
        path_speed: Num, speed_override: Num, program_speed: Num, hold: Num, space: Num,
        waited_s: Num, commands_taken: Num, queue_free: Num, starved: Num, control_seq: Num,
        position: PerAxis, velocity: PerAxis, acceleration: PerAxis, motion_start_ns: Num,
        motion_end_ns: Num, axes: Num, hold_io: Num, coords: Num, cartesian: Array,
        cartesian_velocity: Array,
    };
    ServoStateV3, "rtc.ServoStateV3", stamp: |s| Some(s.stamp_ns), seq: |s| Some((0, s.seq)), {
        seq: Num, stamp_ns: Num, measured_stamp_ns: Num, setpoint_seq: Num, status: Num,
        power: Num, settled_axes: Num, fault_code: Num, fault_axis: Num, fault_value: Num,
        fault_limit: Num, controlword: PerAxis, statusword: PerAxis, cmd_position: PerAxis,
        cmd_velocity: PerAxis, act_position: PerAxis, act_velocity: PerAxis,
        following_error: PerAxis, effort: PerAxis, peak_program: Num,
        peak_following_error: PerAxis, request_seq: Num, axes: Num, axis_power: PerAxis,
    } not recorded { reserved, reserved2, reserved3 };
    DriveFeedbackV2, "rtc.DriveFeedbackV2", stamp: |s| Some(s.stamp_ns), seq: |s| Some((0, s.seq)), {
        seq: Num, stamp_ns: Num, command_seq: Num, sense_to_command_ns: Num,
        statusword: PerAxis, mode_display: PerAxis, error_code: PerAxis, position: PerAxis,
        velocity: PerAxis, torque: PerAxis, following_error: PerAxis, axes: Num,
    } not recorded { reserved };
    DriveCommandV2, "rtc.DriveCommandV2", stamp: |s| Some(s.stamp_ns), seq: |s| Some((0, s.seq)), {
        seq: Num, stamp_ns: Num, feedback_seq: Num, feedback_stamp_ns: Num, controlword: PerAxis,
        mode: PerAxis, target_position: PerAxis, target_velocity: PerAxis,
        target_torque: PerAxis, velocity_offset: PerAxis, torque_offset: PerAxis, axes: Num,
    } not recorded { reserved };
    DigitalIoV1, "rtc.DigitalIoV1", stamp: |s| Some(s.stamp_ns), seq: |s| Some((0, s.seq)), {
        seq: Num, stamp_ns: Num, values: Num, changed: Num, taken: Num, refused: Num,
        count: Num, outputs_safe: Num,
    };
    // The supervisor's own events and its tools' (`supervisor inject`) share a source and
    // number separately: no loss is counted from theirs.
    EventV1, "rtc.EventV1", stamp: |s| Some(s.stamp_ns), seq: |s| (s.source != shm_schema::event::SOURCE_SUPERVISOR).then_some((u64::from(s.source), s.seq)), {
        seq: Num, stamp_ns: Num, source: Num, severity: Num, code: Num, axis: Num, value: Num,
        limit: Num, text: Text,
    };
    EstopV1, "rtc.EstopV1", stamp: |s| Some(s.stamp_ns), seq: |_s| None, {
        stamp_ns: Num, kind: Num, origin: Num, source: Num, code: Num, reason: Text,
    };
    HostStateV1, "rtc.HostStateV1", stamp: |s| Some(s.stamp_ns), seq: |s| Some((0, s.beat)), {
        stamp_ns: Num, beat: Num, resets: Num, pid: Num, estop: Num, cause: Nested, handover: Num,
    } not recorded { reserved };
    CycleStatsV1, "rtc.CycleStatsV1", stamp: |_s| None, seq: |_s| None, {
        period_ns: Num, cycles: Num, overruns: Num, skipped: Num, wakeup_latency_ns: Num,
        max_wakeup_latency_ns: Num, exec_ns: Num, max_exec_ns: Num, overrun_flag: Num,
    } not recorded { reserved };
    DetectorV1, "rtc.DetectorV1", stamp: |_s| None, seq: |_s| None, {
        level: Num, limit: Num, total: Num,
    };
    ProcessStatusV2, "rtc.ProcessStatusV2", stamp: |s| Some(s.stamp_ns), seq: |s| Some((u64::from(s.pid), s.stats.cycles)), {
        pid: Num, index: Num, state: Num, policy: Num, priority: Num, cpu: Num, fault: Num,
        stamp_ns: Num, stats: Nested, pending_sequence: Nested, transport: Nested,
        thread_offset: Nested, estop: Num, rt_flags: Num, name: Text,
    } not recorded { reserved };
    MotionCommandV2, "rtc.MotionCommandV2", stamp: |_s| None, seq: |_s| None, {
        seq: Num, program_id: Num, line: Num, kind: Num, count: Num, io: Num, value: Num,
        time_s: Num, speed: Num, target: PerAxis,
    };
    MotionControlV2, "rtc.MotionControlV2", stamp: |_s| None, seq: |_s| None, {
        seq: Num, kind: Num, value: Num,
    } not recorded { reserved };
}

/// iobridge's image, decoded: the positions in axis units.
impl Message for FieldbusImageV1 {
    const NAME: &'static str = "rtc.FieldbusImageV1";
    fn json(&self, axes: &[String]) -> Value {
        // Every field, recorded or said not to be (a field added to the payload does not
        // compile here until it is): the image is recorded decoded, its measurement time
        // being `measured_ns` and its positions `position`; `len` (bytes in use) is not.
        let FieldbusImageV1 {
            seq,
            written_ns,
            measured_ns,
            source_seq,
            len: _,
            axes: n,
            image: _,
        } = *self;
        let pos: Map<String, Value> = axes
            .iter()
            .enumerate()
            .take(n as usize)
            .map(|(k, a)| (a.clone(), json!(self.position(k))))
            .collect();
        json!({
            "seq": seq, "written_ns": written_ns, "measured_ns": measured_ns,
            "source_seq": source_seq, "axes": n, "position": pos,
        })
    }
    fn schema(axes: &[String]) -> Value {
        let props: Map<String, Value> = axes
            .iter()
            .map(|a| (a.clone(), json!({"type": ["number", "null"]})))
            .collect();
        let n = json!({"type": "number"});
        json!({"title": Self::NAME, "type": "object", "properties": {
            "seq": n, "written_ns": n, "measured_ns": n, "source_seq": n, "axes": n,
            "position": {"type": "object", "properties": props},
        }})
    }
    fn stamp_ns(&self) -> Option<u64> {
        Some(self.written_ns)
    }
    fn seq(&self) -> Option<(u64, u64)> {
        Some((0, self.seq))
    }
}

/// A latency histogram, summarised (µs).
impl Message for LatencyHistogramV1 {
    const NAME: &'static str = "rtc.LatencySummary";
    fn json(&self, _: &[String]) -> Value {
        let h = self;
        let us = |v: Option<u64>| v.map(|v| v as f64 / 1000.0);
        json!({
            "count": h.count,
            "mean_us": h.mean_ns().map(|v| v / 1000.0),
            "p50_us": us(h.percentile(1, 2)),
            "p99_us": us(h.percentile(99, 100)),
            "p999_us": us(h.percentile(999, 1000)),
            "p9999_us": us(h.percentile(9999, 10000)),
            "max_us": us((h.count > 0).then_some(h.max_ns)),
        })
    }
    fn schema(_: &[String]) -> Value {
        let n = json!({"type": ["number", "null"]});
        json!({"title": Self::NAME, "type": "object", "properties": {
            "count": n, "mean_us": n, "p50_us": n, "p99_us": n, "p999_us": n,
            "p9999_us": n, "max_us": n,
        }})
    }
    fn stamp_ns(&self) -> Option<u64> {
        Some(self.stamp_ns)
    }
}

/// When to start a new file.
#[derive(Clone, Copy, Debug, Default)]
pub struct Rotate {
    /// Once the file reaches this many bytes.
    pub bytes: Option<u64>,
    /// Once the file is this old.
    pub every: Option<Duration>,
}

/// What `supervisor record` is asked to do.
#[derive(Clone, Debug)]
pub struct RecordOptions {
    /// The file (with rotation: `STEM-000.mcap`, `STEM-001.mcap`, … beside it).
    pub out: PathBuf,
    /// Stop after this long; `None`: until a signal or until the cell goes down.
    pub duration: Option<Duration>,
    /// Rotation.
    pub rotate: Rotate,
}

/// `record`'s options on a command line (`supervisor record`, and `gateway line record` for a
/// cell of the line).
#[derive(Clone, Debug, clap::Args)]
pub struct RecordArgs {
    /// The MCAP file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Stop after this many seconds.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Start a new file (OUT-000.mcap, OUT-001.mcap, …) once one reaches this many MB.
    #[arg(long)]
    pub rotate_size: Option<f64>,
    /// Start a new file every this many seconds.
    #[arg(long)]
    pub rotate_time: Option<f64>,
}

impl RecordArgs {
    /// The options, checked: a duration and a rotation size of at least a millisecond and a
    /// thousandth of a MB, a rotation time of at least a second, none above 1e9.
    pub fn options(&self) -> Result<RecordOptions, String> {
        let checked = |name: &str, v: Option<f64>, lo: f64| match v {
            Some(v) if !(v.is_finite() && v >= lo && v <= 1e9) => Err(format!(
                "--{name} {v} must be at least {lo} (and at most 1e9)"
            )),
            v => Ok(v),
        };
        let duration = checked("duration", self.duration, 0.001)?;
        let size_mb = checked("rotate-size", self.rotate_size, 0.001)?;
        let every = checked("rotate-time", self.rotate_time, 1.0)?;
        Ok(RecordOptions {
            out: self.out.clone(),
            duration: duration.map(Duration::from_secs_f64),
            rotate: Rotate {
                bytes: size_mb.map(|mb| (mb * 1e6) as u64),
                every: every.map(Duration::from_secs_f64),
            },
        })
    }

    /// The same options as command-line arguments again.
    pub fn to_args(&self) -> Vec<String> {
        let mut args = vec!["--out".to_string(), self.out.display().to_string()];
        for (flag, v) in [
            ("--duration", self.duration),
            ("--rotate-size", self.rotate_size),
            ("--rotate-time", self.rotate_time),
        ] {
            if let Some(v) = v {
                args.extend([flag.to_string(), v.to_string()]);
            }
        }
        args
    }
}

/// What a recording wrote, per topic: messages written and samples lost.
#[derive(Clone, Debug, Default)]
pub struct Recorded {
    /// The files, in order.
    pub files: Vec<PathBuf>,
    /// (topic, messages, lost).
    pub topics: Vec<(String, u64, u64)>,
    /// Why it ended.
    pub ended: String,
}

impl Recorded {
    /// Messages lost over every topic.
    pub fn lost(&self) -> u64 {
        self.topics.iter().map(|t| t.2).sum()
    }

    /// The summary printed at the end.
    pub fn text(&self) -> String {
        let mut out = format!(
            "recorded {} ({}): {} messages, {} lost\n",
            self.files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            self.ended,
            self.topics.iter().map(|t| t.1).sum::<u64>(),
            self.lost()
        );
        for (t, n, lost) in &self.topics {
            out += &format!("  {t:<28} {n:>9} messages  {lost} lost\n");
        }
        out
    }
}

/// The clock a recording dates its messages by: the cell's.
enum Clock {
    /// A cell on the wall clock: `CLOCK_MONOTONIC`, turned to the Unix epoch by an offset
    /// measured once.
    Wall { offset_ns: i128 },
    /// A cell on the virtual clock: its instants as they are (its time starts at
    /// `runtime::vclock::EPOCH_NS`, one second after the Unix epoch, in every run), so that
    /// two runs are dated alike.
    Virtual(runtime::vclock::Observer),
}

impl std::fmt::Debug for Clock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Wall { offset_ns } => write!(f, "Wall({offset_ns})"),
            Self::Virtual(_) => write!(f, "Virtual"),
        }
    }
}

impl Clock {
    /// The clock of `cell` (`instance`, read through `node`).
    fn of_cell(
        node: &iceoryx2::prelude::Node<ipc::Ipc>,
        instance: &InstanceName,
        cell: &CellConfigV6,
    ) -> Result<Self, String> {
        if cell.clock == shm_schema::CellClock::Virtual as u32 {
            return runtime::vclock::Observer::new(node, instance)
                .map(Self::Virtual)
                .map_err(|e| e.to_string());
        }
        let real = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        Ok(Self::Wall {
            offset_ns: real - runtime::time::wall_ns() as i128,
        })
    }

    /// Now on the cell's clock (ns).
    fn now_ns(&mut self) -> u64 {
        match self {
            Self::Wall { .. } => runtime::time::wall_ns(),
            Self::Virtual(o) => o.now_ns(),
        }
    }

    /// A time of the cell's clock as a log time (ns since the Unix epoch).
    fn log_time(&self, ns: u64) -> u64 {
        match self {
            Self::Wall { offset_ns } => (ns as i128 + offset_ns).max(0) as u64,
            Self::Virtual(_) => ns,
        }
    }
}

/// Where a topic's messages go: `(log time in ns since the Unix epoch, the message's JSON)`.
type Sink<'a> = dyn FnMut(u64, &[u8]) -> Result<(), String> + 'a;

/// Where a source's messages go: `(the topic's index, log time in ns since the Unix epoch,
/// the message's JSON)`.
pub type SourceSink<'a> = dyn FnMut(usize, u64, &[u8]) -> Result<(), String> + 'a;

/// One topic: a subscriber and its counts.
trait Topic {
    fn name(&self) -> &str;
    fn schema_name(&self) -> &'static str;
    fn schema(&self, axes: &[String]) -> Value;
    /// Hands what arrived to `sink`: at most as many samples as the subscriber keeps (all
    /// that can have waited when the call began); what arrives meanwhile waits for the next
    /// call.
    fn drain(
        &mut self,
        sink: &mut Sink<'_>,
        axes: &[String],
        clock: &mut Clock,
    ) -> Result<(), String>;
    fn counts(&self) -> (u64, u64);
    /// When (ns, the cell's clock) the recorder subscribed: no sample it reads was published
    /// before.
    fn subscribed_at(&mut self, ns: u64);
}

struct Chan<T: Message + Payload> {
    sub: Sub<T>,
    topic: String,
    last: HashMap<u64, u64>,
    /// The time of the topic's last message (ns, the cell's clock).
    stamp: Option<u64>,
    /// When the recorder subscribed: no sample it reads was published before.
    since: u64,
    /// The unread samples its subscriber keeps.
    buffer: usize,
    written: u64,
    lost: u64,
}

impl<T: Message + Payload> Topic for Chan<T> {
    fn name(&self) -> &str {
        &self.topic
    }

    fn schema_name(&self) -> &'static str {
        T::NAME
    }

    fn schema(&self, axes: &[String]) -> Value {
        T::schema(axes)
    }

    fn drain(
        &mut self,
        sink: &mut Sink<'_>,
        axes: &[String],
        clock: &mut Clock,
    ) -> Result<(), String> {
        // What was read, in the order of its times: a topic of several publishers (the
        // events) comes from each in turn, in an order that depends on the wall clock; sorted,
        // samples of one instant by their stream and number, every run writes them alike.
        let mut batch: Vec<(u64, (u64, u64), Vec<u8>)> = Vec::new();
        // Bounded: a topic published faster than the recorder reads it (a starved CPU) would
        // hold it here for good, its stop and its other topics waiting.
        for m in std::iter::from_fn(|| self.sub.next()).take(self.buffer) {
            // A number lower than the last (a restarted process) starts the count again.
            if let Some((stream, seq)) = m.seq()
                && let Some(prev) = self.last.insert(stream, seq)
                && seq > prev + 1
            {
                self.lost += seq - prev - 1;
            }
            // A sample without a time of its own: the time it was read; a process' first
            // status (stamped 0, before its first cycle): the topic's previous time, so that
            // the topic stays in time order.
            let stamp = match m.stamp_ns() {
                None => clock.now_ns(),
                Some(0) => self.stamp.unwrap_or(self.since),
                Some(t) => t,
            };
            self.stamp = Some(stamp);
            let data = serde_json::to_vec(&m.json(axes)).map_err(|e| e.to_string())?;
            batch.push((stamp, m.seq().unwrap_or_default(), data));
        }
        batch.sort_by_key(|(stamp, seq, _)| (*stamp, *seq));
        for (stamp, _, data) in batch {
            sink(clock.log_time(stamp), &data)?;
            self.written += 1;
        }
        Ok(())
    }

    fn counts(&self) -> (u64, u64) {
        (self.written, self.lost)
    }

    fn subscribed_at(&mut self, ns: u64) {
        self.since = ns;
    }
}

fn chan<T: Message + Payload>(
    node: &iceoryx2::prelude::Node<ipc::Ipc>,
    instance: &InstanceName,
    id: ServiceId,
    topic: String,
    buffer: usize,
) -> Result<Box<dyn Topic>, String> {
    Ok(Box::new(Chan::<T> {
        sub: Sub::new(node, instance, id, buffer).map_err(|e| format!("{topic}: {e}"))?,
        topic,
        last: HashMap::new(),
        stamp: None,
        since: 0,
        buffer,
        written: 0,
        lost: 0,
    }))
}

/// A recorded topic: its name, and its messages' JSON Schema with that schema's name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TopicInfo {
    /// The topic (`/servo/state`).
    pub topic: String,
    /// The schema's name (`rtc.ServoStateV3`).
    pub schema_name: String,
    /// The JSON Schema of its messages.
    pub schema: Value,
}

/// The MCAP file being written, and the next ones: one channel per topic, in the order of
/// the topics it was created with.
pub struct Writer {
    base: PathBuf,
    rotate: Rotate,
    topics: Vec<TopicInfo>,
    part: u32,
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    /// Channel id per topic, in this file.
    ids: Vec<u16>,
    sequence: u32,
    opened: Instant,
    /// When the file's size was last looked at.
    sized: Instant,
    files: Vec<PathBuf>,
}

impl std::fmt::Debug for Writer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Writer")
            .field("path", &self.path)
            .field("topics", &self.topics.len())
            .finish_non_exhaustive()
    }
}

impl Writer {
    /// Creates the first file (`base`, or `STEM-000.mcap` beside it with rotation).
    pub fn create(base: &Path, rotate: Rotate, topics: Vec<TopicInfo>) -> Result<Self, String> {
        Self::part(base, rotate, topics, 0)
    }

    fn part(
        base: &Path,
        rotate: Rotate,
        topics: Vec<TopicInfo>,
        part: u32,
    ) -> Result<Self, String> {
        let path = if rotate.bytes.is_some() || rotate.every.is_some() {
            let stem = base
                .file_stem()
                .map_or("record".into(), |s| s.to_string_lossy());
            base.with_file_name(format!("{stem}-{part:03}.mcap"))
        } else {
            base.to_path_buf()
        };
        let file = File::create(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Lz4))
            .profile("")
            .create(BufWriter::new(file))
            .map_err(|e| mcap_error(&path, e))?;
        let mut ids = Vec::new();
        let mut schemas: HashMap<&str, u16> = HashMap::new();
        for t in &topics {
            let schema_id = match schemas.get(t.schema_name.as_str()) {
                Some(id) => *id,
                None => {
                    let text = serde_json::to_vec(&t.schema).map_err(|e| e.to_string())?;
                    let id = writer
                        .add_schema(&t.schema_name, "jsonschema", &text)
                        .map_err(|e| mcap_error(&path, e))?;
                    schemas.insert(&t.schema_name, id);
                    id
                }
            };
            ids.push(
                writer
                    .add_channel(schema_id, &t.topic, "json", &BTreeMap::new())
                    .map_err(|e| mcap_error(&path, e))?,
            );
        }
        Ok(Self {
            base: base.to_path_buf(),
            rotate,
            topics,
            part,
            path: path.clone(),
            writer,
            ids,
            sequence: 0,
            opened: Instant::now(),
            sized: Instant::now(),
            files: vec![path],
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The topics, in their channels' order.
    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    /// Writes one message of topic `k` (its index in [`Writer::topics`]) at `log_time` (ns
    /// since the Unix epoch).
    pub fn write(&mut self, k: usize, log_time: u64, data: &[u8]) -> Result<(), String> {
        let channel_id = *self
            .ids
            .get(k)
            .ok_or_else(|| format!("{}: no topic {k}", self.path.display()))?;
        self.sequence = self.sequence.wrapping_add(1);
        self.writer
            .write_to_known_channel(
                &MessageHeader {
                    channel_id,
                    sequence: self.sequence,
                    log_time,
                    publish_time: log_time,
                },
                data,
            )
            .map_err(|e| mcap_error(&self.path, e))
    }

    /// Starts the next file when this one is old enough, or full (its size looked at once a
    /// second): cheap enough to call after every batch of messages.
    pub fn maybe_rotate(&mut self) -> Result<(), String> {
        let look = self.sized.elapsed() >= Duration::from_secs(1);
        if look {
            self.sized = Instant::now();
        }
        let full = look
            && self
                .rotate
                .bytes
                .is_some_and(|b| std::fs::metadata(&self.path).is_ok_and(|m| m.len() >= b));
        let old = self
            .rotate
            .every
            .is_some_and(|t| self.opened.elapsed() >= t);
        if !(full || old) {
            return Ok(());
        }
        let mut next = Self::part(&self.base, self.rotate, self.topics.clone(), self.part + 1)?;
        std::mem::swap(self, &mut next);
        let mut files = std::mem::take(&mut next.files);
        files.append(&mut self.files);
        self.files = files;
        next.writer
            .finish()
            .map(|_| ())
            .map_err(|e| mcap_error(&next.path, e))
    }

    /// Writes the index and the footer; the files written, in order.
    pub fn finish(mut self) -> Result<Vec<PathBuf>, String> {
        self.writer
            .finish()
            .map_err(|e| mcap_error(&self.path, e))?;
        Ok(self.files)
    }
}

/// The topics of a cell: every service (per process: status and latency).
fn topics(
    node: &iceoryx2::prelude::Node<ipc::Ipc>,
    instance: &InstanceName,
    cell: &CellConfigV6,
) -> Result<Vec<Box<dyn Topic>>, String> {
    let big = 1024;
    let mut t: Vec<Box<dyn Topic>> = Vec::new();
    // A service whose subscriber slots are all taken is not recorded: the recorder never
    // takes a place the cell needs, and says which topic it left out.
    let mut add = |c: Result<Box<dyn Topic>, String>| match c {
        Ok(c) => t.push(c),
        Err(e) => tracing::warn!("record: {e}; that topic is not recorded"),
    };
    for c in [
        chan::<SetpointV2>(
            node,
            instance,
            ServiceId::Setpoint,
            "/trajgen/setpoint".into(),
            big,
        ),
        chan::<ServoStateV3>(
            node,
            instance,
            ServiceId::ServoState,
            "/servo/state".into(),
            big,
        ),
        chan::<DriveCommandV2>(
            node,
            instance,
            ServiceId::DriveCommand,
            "/servo/drive_command".into(),
            big,
        ),
        chan::<DriveFeedbackV2>(
            node,
            instance,
            ServiceId::DriveFeedback,
            "/drives/feedback".into(),
            big,
        ),
        chan::<FieldbusImageV1>(
            node,
            instance,
            ServiceId::FieldbusOutput,
            "/iobridge/output".into(),
            big,
        ),
        chan::<DigitalIoV1>(node, instance, ServiceId::IoState, "/io/state".into(), big),
        chan::<MotionCommandV2>(
            node,
            instance,
            ServiceId::MotionCommand,
            "/trajgen/command".into(),
            big,
        ),
        chan::<MotionControlV2>(
            node,
            instance,
            ServiceId::MotionControl,
            "/trajgen/control".into(),
            big,
        ),
        chan::<EventV1>(node, instance, ServiceId::Events, "/events".into(), big),
        chan::<EstopV1>(node, instance, ServiceId::Estop, "/estop".into(), big),
        chan::<HostStateV1>(
            node,
            instance,
            ServiceId::HostState,
            "/host/state".into(),
            big,
        ),
        chan::<LatencyHistogramV1>(
            node,
            instance,
            ServiceId::SenseToCommand,
            "/drives/sense_to_command".into(),
            2,
        ),
    ] {
        add(c);
    }
    for p in cell.processes() {
        let Some(name) = ProcessName::from_field(&p.name) else {
            continue;
        };
        add(chan::<ProcessStatusV2>(
            node,
            instance,
            ServiceId::Status(name),
            format!("/{name}/status"),
            big,
        ));
        add(chan::<LatencyHistogramV1>(
            node,
            instance,
            ServiceId::Latency(name),
            format!("/{name}/latency"),
            2,
        ));
        add(chan::<LatencyHistogramV1>(
            node,
            instance,
            ServiceId::ExecTime(name),
            format!("/{name}/exec_time"),
            2,
        ));
    }
    Ok(t)
}

/// Why a recording did not start or did not finish.
#[derive(Debug)]
pub enum RecordError {
    /// No process of the instance is running.
    NotUp(InstanceName),
    /// Processes of the instance run, but none publishes the cell's configuration.
    NoConfiguration(InstanceName),
    /// Attaching to the cell's shared memory failed.
    Attach(String),
    /// A file could not be created or written (the words name it).
    File(String),
    /// The recorder's own process could not be started.
    Spawn(std::io::Error),
    /// The recorder's process started but did not begin recording (its words, if any).
    NotStarted(String),
    /// The recorder's process failed while recording (a disk full, its file removed): its
    /// exit status; its own error went to stderr.
    Failed(String),
}

impl RecordError {
    /// Whether the user asked for what cannot be (an instance that is not up): the CLI
    /// exits 2, else 1.
    pub fn is_input(&self) -> bool {
        matches!(self, Self::NotUp(_) | Self::NoConfiguration(_))
    }
}

impl std::fmt::Display for RecordError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotUp(i) => write!(f, "instance {i} is not up (`supervisor up --instance {i}`)"),
            Self::NoConfiguration(i) => {
                write!(f, "instance {i} publishes no cell configuration: is it up?")
            }
            Self::Attach(e) | Self::File(e) => f.write_str(e),
            Self::Spawn(e) => write!(f, "record: {e}"),
            Self::NotStarted(why) if why.is_empty() => f.write_str("the recorder did not start"),
            Self::NotStarted(why) => write!(f, "the recorder did not start: {why}"),
            Self::Failed(status) => write!(
                f,
                "the recording failed ({status}; the recorder's error above says why): its file \
                 is incomplete"
            ),
        }
    }
}

impl std::error::Error for RecordError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Spawn(e) => Some(e),
            _ => None,
        }
    }
}

/// Removes what is left of the instance once this observer's node is gone, if the cell is gone
/// too.
struct Leave(InstanceName);

impl Drop for Leave {
    fn drop(&mut self) {
        ipc::cleanup_after_client(&self.0);
    }
}

/// How often (the cell's time) a recorder that takes part in a virtual clock reads: its
/// subscribers keep 1024 samples, 250 ms of a 4 kHz servo.
const RECORD_EVERY: Duration = Duration::from_millis(10);

/// How long without the supervisor's heartbeat before the recording takes the cell for gone.
const GONE: Duration = Duration::from_secs(3);

/// A running cell's services as recorded messages: the recorder's side that reads shared
/// memory, whoever writes the messages (a file here, or the line: the gateway).
pub struct Source {
    // Dropped in this order: the ports, the node, then what is left of a gone cell.
    chans: Vec<Box<dyn Topic>>,
    host: Sub<HostStateV1>,
    clock: Clock,
    _node: iceoryx2::prelude::Node<ipc::Ipc>,
    _leave: Leave,
    axes: Vec<String>,
    heard: Instant,
}

impl std::fmt::Debug for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Source")
            .field("topics", &self.chans.len())
            .field("axes", &self.axes)
            .finish_non_exhaustive()
    }
}

impl Source {
    /// Subscribes to every service of `instance` (a service whose subscriber slots are all
    /// taken is left out, with a warning), under a node named `node_name`.
    pub fn open(instance: &InstanceName, node_name: &str) -> Result<Self, RecordError> {
        ipc::quiet_iceoryx2_log();
        // A listing that fails (out of descriptors) says why, not "not running".
        if ipc::live_node_pids(instance)
            .map_err(|e| RecordError::Attach(e.to_string()))?
            .is_empty()
        {
            return Err(RecordError::NotUp(*instance));
        }
        let attach = |e: ipc::IpcError| RecordError::Attach(e.to_string());
        // Whatever happens from here, the recorder leaves nothing of the instance behind it
        // once the cell is gone (dropped after the node).
        let leave = Leave(*instance);
        let node = ipc::node(instance, node_name).map_err(attach)?;
        let cell_sub =
            Sub::<CellConfigV6>::new(&node, instance, ServiceId::CellConfig, 1).map_err(attach)?;
        let start = Instant::now();
        let cell = loop {
            if let Some(c) = cell_sub.latest() {
                break Box::new(c);
            }
            if start.elapsed() > Duration::from_secs(2) {
                return Err(RecordError::NoConfiguration(*instance));
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        drop(cell_sub);
        let axes: Vec<String> = Axes::of_cell(&cell).axes.into_iter().map(|a| a.0).collect();
        let mut clock = Clock::of_cell(&node, instance, &cell).map_err(RecordError::Attach)?;
        let mut chans = topics(&node, instance, &cell).map_err(RecordError::Attach)?;
        let since = clock.now_ns();
        for c in &mut chans {
            c.subscribed_at(since);
        }
        let host =
            Sub::<HostStateV1>::new(&node, instance, ServiceId::HostState, 1).map_err(attach)?;
        Ok(Self {
            chans,
            host,
            clock,
            _node: node,
            _leave: leave,
            axes,
            heard: Instant::now(),
        })
    }

    /// On a cell on the virtual clock, a part in it for this source's reader (`instance`
    /// its cell): granted every [`RECORD_EVERY`] of the cell's time, after every process due
    /// at the same instant, so that it reads each topic before its subscriber's buffer can
    /// fill. `None` on the wall clock.
    pub fn take_part(
        &self,
        instance: &InstanceName,
    ) -> Result<Option<runtime::vclock::ToolPart>, RecordError> {
        if !matches!(self.clock, Clock::Virtual(_)) {
            return Ok(None);
        }
        runtime::vclock::ToolPart::join(&self._node, instance, RECORD_EVERY.as_nanos() as u64)
            .map(Some)
            .map_err(|e| RecordError::Attach(e.to_string()))
    }

    /// The topics, in the order [`Source::drain`] numbers them.
    pub fn topics(&self) -> Vec<TopicInfo> {
        self.chans
            .iter()
            .map(|c| TopicInfo {
                topic: c.name().to_string(),
                schema_name: c.schema_name().to_string(),
                schema: c.schema(&self.axes),
            })
            .collect()
    }

    /// Hands every message that arrived to `sink(k, log time, JSON)`, `k` its topic's index;
    /// per topic at most what its subscriber keeps (a topic published faster than it is read
    /// leaves the rest for the next call: a call always ends).
    pub fn drain(&mut self, sink: &mut SourceSink<'_>) -> Result<(), String> {
        self.drain_until(sink, &|| false)
    }

    /// [`Source::drain`], ending before the next topic once `stop` says so.
    fn drain_until(
        &mut self,
        sink: &mut SourceSink<'_>,
        stop: &dyn Fn() -> bool,
    ) -> Result<(), String> {
        for (k, c) in self.chans.iter_mut().enumerate() {
            if stop() {
                break;
            }
            c.drain(&mut |t, data| sink(k, t, data), &self.axes, &mut self.clock)?;
        }
        Ok(())
    }

    /// Whether the cell is still there: its supervisor's heartbeat heard within [`GONE`].
    pub fn cell_alive(&mut self) -> bool {
        if self.host.latest().is_some() {
            self.heard = Instant::now();
        }
        self.heard.elapsed() <= GONE
    }

    /// Per topic: (name, messages handed over, samples lost before they were read).
    pub fn counts(&self) -> Vec<(String, u64, u64)> {
        self.chans
            .iter()
            .map(|c| {
                let (n, lost) = c.counts();
                (c.name().to_string(), n, lost)
            })
            .collect()
    }
}

/// Records `instance` until `stop` says so, the duration is over or the cell goes down.
/// `ready` is called once every subscriber is in place.
pub fn record(
    instance: &InstanceName,
    opts: &RecordOptions,
    stop: &dyn Fn() -> bool,
    ready: &mut dyn FnMut(&Path),
) -> Result<Recorded, RecordError> {
    let f = RecordError::File;
    let mut source = Source::open(instance, &format!("recorder-{}", std::process::id()))?;
    let mut out = Writer::create(&opts.out, opts.rotate, source.topics()).map_err(f)?;
    // On the virtual clock the recorder takes part in it: the cell runs on only once it has
    // read every sample (none lost, however fast the clock runs), at the same instants in
    // every run. What came since it subscribed is read first, while the cell runs on (a
    // recorder attaching to a running cell does not hold its clock for it).
    ready(out.path());
    source
        .drain(&mut |k, t, data| out.write(k, t, data))
        .map_err(f)?;
    // A cell that ended meanwhile (its clock stands for good) has no part to give: what it
    // left is read below, and the recording ends as the cell went down.
    let mut part = match source.take_part(instance) {
        Ok(p) => p,
        Err(e) => {
            tracing::warn!("record: {e}; reading on the wall clock's pace");
            None
        }
    };
    // The duration on the cell's clock.
    let began_ns = runtime::time::now_ns();
    let ended = loop {
        // A stop ends the pass: what is left of it is the last drain's.
        source
            .drain_until(&mut |k, t, data| out.write(k, t, data), stop)
            .map_err(f)?;
        if stop() {
            break "stopped".to_string();
        }
        let recorded = Duration::from_nanos(runtime::time::now_ns().saturating_sub(began_ns));
        if opts.duration.is_some_and(|d| recorded >= d) {
            break "its duration is over".to_string();
        }
        if !source.cell_alive() {
            break format!("instance {instance} went down");
        }
        out.maybe_rotate().map_err(f)?;
        match &mut part {
            // A stop or the cell gone: the checks above say which.
            Some(p) => {
                let _ = p.next(&mut || !stop() && source.cell_alive());
            }
            None => std::thread::sleep(Duration::from_millis(5)),
        }
    };
    // What arrived meanwhile (per topic at most what its subscriber keeps: what arrives
    // after the stop does not hold it), then the index and the footer.
    source
        .drain(&mut |k, t, data| out.write(k, t, data))
        .map_err(f)?;
    if let Some(p) = &mut part {
        p.leave();
    }
    Ok(Recorded {
        files: out.finish().map_err(f)?,
        topics: source.counts(),
        ended,
    })
}

/// `e` on the file at `path`, in words: an I/O error's own (mcap's hides it behind "I/O error
/// from writing": a full disk must say "No space left on device").
fn mcap_error(path: &Path, e: mcap::McapError) -> String {
    match e {
        mcap::McapError::Io(io) => format!("{}: {io}", path.display()),
        e => format!("{}: {e}", path.display()),
    }
}

/// `supervisor record` in a process of its own, for `run`, `up` and `exec --wait` with
/// `--record FILE`: an observer, so nothing the cell does waits for it (on the wall clock; on
/// the virtual clock it takes part in the clock, see [`Source::take_part`]). Its start and its
/// stop are steps ([`Background::started`], [`Background::stopped`]) a caller's loop takes
/// between its own; [`Background::start`] and [`Background::stop`] wait for them.
#[derive(Debug)]
pub struct Background {
    child: Option<std::process::Child>,
    /// Its stdout: its first line says it is ready (read on a thread until then), the rest
    /// is its summary.
    out: Option<std::io::BufReader<std::process::ChildStdout>>,
    first_line: Option<FirstLine>,
    spawned: Instant,
    /// When it was asked to end.
    stopping: Option<Instant>,
}

/// Which process group a recorder is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Group {
    /// The caller's: a terminal's Ctrl-C reaches both (a client such as `exec --wait`).
    Callers,
    /// One of its own: it ends only when asked (the supervisor, which stops the cell the
    /// controlled way on Ctrl-C and asks the recorder to end after that).
    Own,
}

/// The thread reading a recorder's first line.
type FirstLine = (
    std::sync::mpsc::Receiver<String>,
    std::thread::JoinHandle<Option<std::io::BufReader<std::process::ChildStdout>>>,
);

/// How long a recorder may take to subscribe to everything.
const START_PATIENCE: Duration = Duration::from_secs(20);
/// How long a recorder may take to finish its file once asked to end; then it is killed (its
/// file then lacks its index: readers that stream still read it).
const STOP_PATIENCE: Duration = Duration::from_secs(10);

impl Background {
    /// Starts recording `instance` into `file`; returns once the recorder subscribes to
    /// everything. `tick` runs every 10 ms meanwhile. The recorder is in the caller's process
    /// group: a terminal's Ctrl-C ends both (it finishes its file).
    pub fn start(
        instance: &InstanceName,
        file: &Path,
        tick: &mut dyn FnMut(),
    ) -> Result<Self, RecordError> {
        let mut me = Self::spawn(instance, file, Group::Callers)?;
        while !me.started()? {
            tick();
            std::thread::sleep(Duration::from_millis(10));
        }
        Ok(me)
    }

    /// Starts the recorder's process in `group`; [`Background::started`] says when it
    /// records.
    pub fn spawn(instance: &InstanceName, file: &Path, group: Group) -> Result<Self, RecordError> {
        use std::io::BufRead;
        use std::os::unix::process::CommandExt;
        let exe = std::env::current_exe().map_err(RecordError::Spawn)?;
        let mut cmd = std::process::Command::new(exe);
        if group == Group::Own {
            cmd.process_group(0);
        }
        let mut child = cmd
            .args(["record", "--instance", instance.as_str(), "--out"])
            .arg(file)
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::piped())
            // The caller's readiness is its own (`READY=1`): not the recorder's to say.
            .env_remove("NOTIFY_SOCKET")
            .spawn()
            .map_err(RecordError::Spawn)?;
        // Its first line on stdout says it is ready (whatever it says: a recorder that cannot
        // start writes its reasons to stderr and exits, closing stdout with no line); read on
        // a thread so that the caller goes on.
        let (tx, rx) = std::sync::mpsc::channel();
        let out = child.stdout.take().map(std::io::BufReader::new);
        let reader = std::thread::spawn(move || {
            let mut out = out;
            let mut line = String::new();
            if let Some(o) = out.as_mut() {
                let _ = o.read_line(&mut line);
            }
            let _ = tx.send(line);
            out
        });
        Ok(Self {
            child: Some(child),
            out: None,
            first_line: Some((rx, reader)),
            spawned: Instant::now(),
            stopping: None,
        })
    }

    /// The recorder's pid, while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(std::process::Child::id)
    }

    /// Whether the recorder subscribed to everything (true from then on); an error, once,
    /// when it could not start (its reasons on stderr), or did not within 20 s (it is then
    /// killed: it has no file worth finishing). Never waits.
    pub fn started(&mut self) -> Result<bool, RecordError> {
        let Some((rx, _)) = &self.first_line else {
            return Ok(true);
        };
        let (line, why) = match rx.try_recv() {
            Ok(line) => (line, ""),
            Err(std::sync::mpsc::TryRecvError::Empty)
                if self.spawned.elapsed() < START_PATIENCE =>
            {
                return Ok(false);
            }
            Err(std::sync::mpsc::TryRecvError::Empty) => {
                (String::new(), "it did not subscribe within 20 s")
            }
            Err(std::sync::mpsc::TryRecvError::Disconnected) => (String::new(), ""),
        };
        let (_, reader) = self.first_line.take().expect("checked");
        if line.is_empty() {
            if let Some(mut child) = self.child.take() {
                let _ = child.kill();
                let _ = child.wait();
            }
            return Err(RecordError::NotStarted(why.to_string()));
        }
        self.out = reader.join().ok().flatten();
        Ok(true)
    }

    /// Ends the recording (SIGTERM: the recorder finishes its file); its summary, or
    /// [`RecordError::Failed`] when the recorder did not end well (it failed while recording,
    /// or had to be killed).
    pub fn stop(&mut self) -> Result<String, RecordError> {
        self.stop_beating(&mut || {})
    }

    /// [`Background::stop`], `tick` running every 10 ms while the recorder finishes its file
    /// (the supervisor's heartbeat: a long recording's index takes a while to write, and the
    /// cell's processes leave after `supervisor_timeout` without a heartbeat).
    pub fn stop_beating(&mut self, tick: &mut dyn FnMut()) -> Result<String, RecordError> {
        loop {
            if let Some(ended) = self.stopped() {
                return ended;
            }
            tick();
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Asks the recorder to end, the first time; then its summary once it has ended (see
    /// [`Background::stop`]), `None` while it finishes its file (killed after 10 s).
    pub fn stopped(&mut self) -> Option<Result<String, RecordError>> {
        use std::io::Read;
        let Some(child) = self.child.as_mut() else {
            return Some(Ok(String::new()));
        };
        let asked = *self.stopping.get_or_insert_with(|| {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(child.id() as i32),
                nix::sys::signal::Signal::SIGTERM,
            );
            Instant::now()
        });
        if child.try_wait().ok().flatten().is_none() {
            if asked.elapsed() < STOP_PATIENCE {
                return None;
            }
            let _ = child.kill();
        }
        let status = child.wait();
        self.child = None;
        let mut text = String::new();
        if let Some(o) = self.out.as_mut() {
            let _ = o.read_to_string(&mut text);
        }
        Some(match status {
            Ok(s) if s.success() => Ok(text),
            Ok(s) => Err(RecordError::Failed(s.to_string())),
            Err(e) => Err(RecordError::Failed(e.to_string())),
        })
    }
}

impl Drop for Background {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The image is recorded by hand (decoded): what it writes is what its schema says, key
    /// for key, and the positions are the image's own.
    #[test]
    fn the_decoded_image_is_what_its_schema_says() {
        let axes = ["x".to_string(), "y".to_string()];
        let mut img = FieldbusImageV1 {
            seq: 7,
            written_ns: 2_000,
            measured_ns: 1_000,
            source_seq: 6,
            len: 16,
            axes: 2,
            image: [0; shm_schema::drive::FIELDBUS_IMAGE_LEN],
        };
        img.image[8..12].copy_from_slice(&12_345i32.to_le_bytes());
        img.image[12..16].copy_from_slice(&shm_schema::drive::IMAGE_INVALID.to_le_bytes());
        let j = img.json(&axes);
        let schema = FieldbusImageV1::schema(&axes);
        let keys = |v: &Value| -> Vec<String> {
            let mut k: Vec<String> = v.as_object().expect("object").keys().cloned().collect();
            k.sort();
            k
        };
        assert_eq!(keys(&j), keys(&schema["properties"]), "{j}");
        assert_eq!(
            keys(&j["position"]),
            keys(&schema["properties"]["position"]["properties"])
        );
        assert_eq!(j["position"]["x"], 12.345);
        assert!(j["position"]["y"].is_null(), "no valid measurement: {j}");
        assert_eq!((j["seq"].as_u64(), j["axes"].as_u64()), (Some(7), Some(2)));
    }

    #[test]
    fn every_field_of_every_recorded_payload_is_recorded_or_said_not_to_be() {
        for (name, named, size) in coverage() {
            assert_eq!(
                named, size,
                "{name}: its fields named in `messages!` cover {named} of its {size} bytes: a \
                 field of the payload is neither recorded nor listed as `not recorded`"
            );
        }
    }
}
