//! Instance names, service names and the quality of service each service is created with.
//!
//! Every service of a cell lives under `<instance>/`, and every iceoryx2 resource of an
//! instance (shared-memory files, node and service folders) is isolated by the iceoryx2
//! configuration built from the same name (see [`InstanceName::shm_prefix`] and
//! [`InstanceName::root_dir`]), so two instances on one machine never meet.

use core::fmt::{self, Write};

/// Longest instance name accepted.
pub const MAX_INSTANCE_LEN: usize = 32;

/// A validated instance name: 1 to 32 of `[A-Za-z0-9_-]`.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct InstanceName {
    bytes: [u8; MAX_INSTANCE_LEN],
    len: u8,
}

/// Why an instance name was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InstanceError {
    /// The name is empty.
    Empty,
    /// The name is longer than [`MAX_INSTANCE_LEN`].
    TooLong {
        /// Length given, in bytes.
        len: usize,
    },
    /// A character outside `[A-Za-z0-9_-]`.
    BadChar {
        /// The character.
        ch: char,
        /// Its byte offset in the name.
        at: usize,
    },
}

impl fmt::Display for InstanceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Empty => write!(f, "instance name is empty"),
            Self::TooLong { len } => {
                write!(
                    f,
                    "instance name is {len} bytes long, at most {MAX_INSTANCE_LEN} allowed"
                )
            }
            Self::BadChar { ch, at } => write!(
                f,
                "instance name has {ch:?} at offset {at}; only letters, digits, '_' and '-' are allowed"
            ),
        }
    }
}

impl core::error::Error for InstanceError {}

impl InstanceName {
    /// Validates `name`.
    pub fn new(name: &str) -> Result<Self, InstanceError> {
        if name.is_empty() {
            return Err(InstanceError::Empty);
        }
        if name.len() > MAX_INSTANCE_LEN {
            return Err(InstanceError::TooLong { len: name.len() });
        }
        if let Some((at, ch)) = name
            .char_indices()
            .find(|&(_, c)| !(c.is_ascii_alphanumeric() || c == '_' || c == '-'))
        {
            return Err(InstanceError::BadChar { ch, at });
        }
        let mut bytes = [0u8; MAX_INSTANCE_LEN];
        bytes[..name.len()].copy_from_slice(name.as_bytes());
        Ok(Self {
            bytes,
            len: name.len() as u8,
        })
    }

    /// The name as text.
    pub fn as_str(&self) -> &str {
        // Only ASCII was accepted in `new`.
        core::str::from_utf8(&self.bytes[..self.len as usize]).unwrap_or("")
    }

    /// The full iceoryx2 service name of `service` in this instance.
    pub fn service(&self, service: ServiceId) -> ServiceNameBuf {
        let mut buf = ServiceNameBuf::default();
        // Cannot overflow: 32 bytes of instance + the longest suffix fit in the buffer.
        let _ = write!(buf, "{}/{}", self.as_str(), service.suffix());
        buf
    }

    /// The file-name prefix of every iceoryx2 file of this instance (`/dev/shm/<prefix>...`).
    pub fn shm_prefix(&self) -> ServiceNameBuf {
        let mut buf = ServiceNameBuf::default();
        let _ = write!(buf, "iox2_{}_", self.as_str());
        buf
    }

    /// The iceoryx2 root folder of this instance (node and service descriptions, sockets).
    pub fn root_dir(&self) -> ServiceNameBuf {
        let mut buf = ServiceNameBuf::default();
        let _ = write!(buf, "/tmp/iceoryx2/{}/", self.as_str());
        buf
    }
}

impl fmt::Debug for InstanceName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

impl fmt::Display for InstanceName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Capacity of a [`ServiceNameBuf`].
pub const SERVICE_NAME_CAP: usize = 96;

/// A service name (or other instance-derived string) built without allocation.
#[derive(Clone, Copy)]
pub struct ServiceNameBuf {
    bytes: [u8; SERVICE_NAME_CAP],
    len: usize,
}

impl Default for ServiceNameBuf {
    fn default() -> Self {
        Self {
            bytes: [0; SERVICE_NAME_CAP],
            len: 0,
        }
    }
}

impl ServiceNameBuf {
    /// The name as text.
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(&self.bytes[..self.len]).unwrap_or("")
    }
}

impl Write for ServiceNameBuf {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len + s.len();
        if end > SERVICE_NAME_CAP {
            return Err(fmt::Error);
        }
        self.bytes[self.len..end].copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

impl fmt::Debug for ServiceNameBuf {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

impl fmt::Display for ServiceNameBuf {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Every service of a cell. All are publish-subscribe but [`ServiceId::SetpointReady`]; `docs/services.md` lists them with
/// their payload layouts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ServiceId {
    /// `<i>/cell/config`: [`crate::CellConfigV6`], published once by the supervisor with
    /// history 1, so a process that starts later still receives it.
    CellConfig,
    /// `<i>/ethercat/config`: [`crate::EthercatConfigV1`], published once by the supervisor
    /// (history 1) when the cell has an EtherCAT bus.
    EthercatConfig,
    /// `<i>/ethercat/emulator/fault`: [`crate::EmulatorFaultV1`], a client to the emulated
    /// bus of a test cell.
    EmulatorFault,
    /// `<i>/trajgen/command`: [`crate::MotionCommandV2`], a client (the supervisor) to trajgen.
    MotionCommand,
    /// `<i>/trajgen/control`: [`crate::MotionControlV2`], a client to trajgen: pause, resume,
    /// abort, taken at once.
    MotionControl,
    /// `<i>/trajgen/handover`: [`crate::TrajgenHandoverV2`], trajgen's paused motion for its
    /// successor (history 1).
    TrajgenHandover,
    /// `<i>/trajgen/setpoint`: [`crate::SetpointV2`], trajgen to servo (and observers).
    Setpoint,
    /// `<i>/servo/state`: [`crate::ServoStateV3`], servo to iobridge (and observers).
    ServoState,
    /// `<i>/servo/request`: [`crate::ServoRequestV1`], a client (the supervisor) to servo:
    /// enable, disable, reset.
    ServoRequest,
    /// `<i>/servo/drive_command`: [`crate::DriveCommandV2`], servo to the drives.
    DriveCommand,
    /// `<i>/drives/feedback`: [`crate::DriveFeedbackV2`], the drives to servo.
    DriveFeedback,
    /// `<i>/drives/inject`: [`crate::FaultInjectionV1`], a client to the simulated drives.
    FaultInjection,
    /// `<i>/drives/sense_to_command`: [`crate::LatencyHistogramV1`] of the sense-to-command
    /// latency the drives measure (sampling the encoders to applying the command computed
    /// from that sample), about every 100 ms and once more on stopping.
    SenseToCommand,
    /// `<i>/events`: [`crate::EventV1`], every process (and the supervisor) to whoever
    /// listens.
    Events,
    /// `<i>/iobridge/output`: [`crate::FieldbusImageV1`], the fieldbus output image.
    FieldbusOutput,
    /// `<i>/<name>/status`: [`crate::ProcessStatusV2`], every real-time process to the
    /// supervisor, every cycle.
    Status(crate::ProcessName),
    /// `<i>/<name>/latency`: [`crate::LatencyHistogramV1`], the wake-up latency histogram of
    /// every real-time process since its start, about every 100 ms and once more on stopping.
    Latency(crate::ProcessName),
    /// `<i>/<name>/exec_time`: [`crate::LatencyHistogramV1`] of the execution time (wake-up
    /// to end of work) of every cycle of a real-time process since its start, published with
    /// the latency histogram.
    ExecTime(crate::ProcessName),
    /// `<i>/estop`: [`crate::EstopV1`], any process, the supervisor and a user's tool to every
    /// process: e-stop triggers and resets, read by every real-time process in its cycle.
    Estop,
    /// `<i>/host/state`: [`crate::estop::HostStateV1`], the supervisor's heartbeat and the
    /// latched e-stop, every supervisor tick, history 1.
    HostState,
    /// `<i>/io/state`: [`crate::DigitalIoV1`], iobridge's image of the named digital IO, every
    /// iobridge cycle, history 1.
    IoState,
    /// `<i>/io/request`: [`crate::IoWriteV1`], output requests from trajgen (`OUT`), the
    /// supervisor's tools and any client to iobridge.
    IoRequest,
    /// `<i>/field/inputs`: [`crate::IoWriteV1`], the inputs as field devices report them (the
    /// simulated machine, a simulated button, a fieldbus driver) to iobridge.
    FieldInputs,
    /// `<i>/trajgen/setpoint` (event service): trajgen notifies it after each setpoint
    /// publish, so a consumer may block until a setpoint arrives instead of polling.
    SetpointReady,
    /// `<i>/clock/grant`: [`crate::ClockGrantV1`], the virtual clock to the process it grants
    /// a cycle (history 1: where the clock stands, for a process about to join).
    ClockGrant,
    /// `<i>/clock/go/<pid>` (event service): the virtual clock wakes process `pid` after its
    /// grant.
    ClockGo(u32),
    /// `<i>/clock/report`: [`crate::ClockReportV1`], every process on the virtual clock to
    /// the clock: a join, a cycle done with the next deadline, a leave.
    ClockReport,
    /// `<i>/clock/report` (event service): notified after each report; the clock waits on it.
    ClockReportReady,
}

/// How a service is created. Every process opens a service with these same values, so it does
/// not matter which process creates it first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Qos {
    /// Publishers allowed at once.
    pub max_publishers: usize,
    /// Subscribers allowed at once.
    pub max_subscribers: usize,
    /// Samples a late subscriber receives on connecting.
    pub history: usize,
    /// Largest receive buffer a subscriber may ask for.
    pub subscriber_max_buffer: usize,
    /// Nodes allowed to open the service at once.
    pub max_nodes: usize,
}

impl ServiceId {
    /// The part of the service name after `<instance>/`.
    pub fn suffix(self) -> ServiceNameBuf {
        let mut buf = ServiceNameBuf::default();
        // Cannot overflow: a process name has at most 15 bytes.
        let _ = match self {
            Self::Status(name) => write!(buf, "{name}/status"),
            Self::Latency(name) => write!(buf, "{name}/latency"),
            Self::ExecTime(name) => write!(buf, "{name}/exec_time"),
            Self::ClockGo(pid) => write!(buf, "clock/go/{pid}"),
            fixed => buf.write_str(fixed.fixed_suffix()),
        };
        buf
    }

    fn fixed_suffix(self) -> &'static str {
        match self {
            Self::CellConfig => "cell/config",
            Self::EthercatConfig => "ethercat/config",
            Self::EmulatorFault => "ethercat/emulator/fault",
            Self::MotionCommand => "trajgen/command",
            Self::MotionControl => "trajgen/control",
            Self::TrajgenHandover => "trajgen/handover",
            Self::Setpoint => "trajgen/setpoint",
            Self::ServoState => "servo/state",
            Self::ServoRequest => "servo/request",
            Self::DriveCommand => "servo/drive_command",
            Self::DriveFeedback => "drives/feedback",
            Self::FaultInjection => "drives/inject",
            Self::SenseToCommand => "drives/sense_to_command",
            Self::Events => "events",
            Self::FieldbusOutput => "iobridge/output",
            Self::Estop => "estop",
            Self::HostState => "host/state",
            Self::IoState => "io/state",
            Self::IoRequest => "io/request",
            Self::FieldInputs => "field/inputs",
            Self::Status(_) | Self::Latency(_) | Self::ExecTime(_) | Self::ClockGo(_) => "",
            Self::SetpointReady => "trajgen/setpoint",
            Self::ClockGrant => "clock/grant",
            Self::ClockReport | Self::ClockReportReady => "clock/report",
        }
    }

    /// Creation parameters of the service.
    pub fn qos(self) -> Qos {
        // Two publishers where a process may be replaced while its predecessor is still
        // being cleaned up; observers (supervisor, recorder, a foreign tool) need subscriber
        // slots beyond the one consumer.
        let base = Qos {
            max_publishers: 2,
            max_subscribers: 8,
            history: 0,
            subscriber_max_buffer: 1024,
            // A table of up to 16 processes, the supervisor and the user's tools.
            max_nodes: 40,
        };
        match self {
            Self::CellConfig | Self::EthercatConfig => Qos {
                history: 1,
                max_publishers: 1,
                max_subscribers: 24,
                ..base
            },
            // Every process writes events, and the supervisor; several tools may read them.
            Self::Events => Qos {
                max_publishers: 32,
                max_subscribers: 16,
                max_nodes: 40,
                ..base
            },
            Self::ServoRequest
            | Self::FaultInjection
            | Self::EmulatorFault
            | Self::MotionControl
            | Self::IoRequest
            | Self::FieldInputs => Qos {
                max_publishers: 8,
                ..base
            },
            // Every process, the supervisor and the user's tools may raise an e-stop.
            Self::Estop => Qos {
                max_publishers: 32,
                max_subscribers: 24,
                max_nodes: 40,
                ..base
            },
            // The successor gets the paused motion at once.
            Self::TrajgenHandover => Qos { history: 1, ..base },
            // A tool gets the IO image at once. Read by the drives, the Modbus server, the
            // supervisor, the next iobridge and the user's tools.
            Self::IoState => Qos {
                history: 1,
                max_subscribers: 16,
                ..base
            },
            // A process started late gets the latched state at once.
            Self::HostState => Qos {
                history: 1,
                max_publishers: 1,
                max_subscribers: 24,
                max_nodes: 32,
                ..base
            },
            // The clock grants one process at a time; a joining process reads where it stands.
            Self::ClockGrant => Qos {
                history: 1,
                max_publishers: 1,
                max_subscribers: 24,
                subscriber_max_buffer: 2,
                max_nodes: 32,
            },
            // Every process of the cell (and a swap's successor beside its predecessor).
            Self::ClockReport | Self::ClockReportReady => Qos {
                max_publishers: 32,
                max_subscribers: 2,
                max_nodes: 40,
                ..base
            },
            // 30 KB a sample: keep few. A late observer gets the newest at once.
            Self::Latency(_) | Self::ExecTime(_) | Self::SenseToCommand => Qos {
                history: 1,
                subscriber_max_buffer: 2,
                max_subscribers: 8,
                ..base
            },
            _ => base,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ProcessName;

    #[test]
    fn instance_names_are_validated() {
        assert_eq!(InstanceName::new(""), Err(InstanceError::Empty));
        assert_eq!(
            InstanceName::new("a/b"),
            Err(InstanceError::BadChar { ch: '/', at: 1 })
        );
        assert!(matches!(
            InstanceName::new(&"x".repeat(33)),
            Err(InstanceError::TooLong { len: 33 })
        ));
        assert_eq!(
            InstanceName::new("gantry-01_a").map(|i| i.as_str().len()),
            Ok(11)
        );
    }

    #[test]
    fn service_names_carry_the_instance() {
        let i = InstanceName::new("t1").expect("valid");
        assert_eq!(
            i.service(ServiceId::Setpoint).as_str(),
            "t1/trajgen/setpoint"
        );
        assert_eq!(
            i.service(ServiceId::Status(ProcessName::new("servo").expect("valid")))
                .as_str(),
            "t1/servo/status"
        );
        assert_eq!(i.shm_prefix().as_str(), "iox2_t1_");
        // The longest instance name still fits every name.
        let long = InstanceName::new(&"z".repeat(MAX_INSTANCE_LEN)).expect("valid");
        for id in [
            ServiceId::DriveCommand,
            ServiceId::Status(ProcessName::new("drives").expect("valid")),
            ServiceId::Latency(ProcessName::new("abcdefghijklmno").expect("valid")),
        ] {
            assert!(long.service(id).as_str().ends_with(id.suffix().as_str()));
        }
        assert!(long.root_dir().as_str().ends_with('/'));
    }
}
