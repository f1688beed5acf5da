//! The one definition of everything that crosses a process boundary.
//!
//! Every payload here is `#[repr(C)]`, `Copy`, fixed size (arrays of [`MAX_AXES`]), free of
//! pointers, and carries an explicit versioned iceoryx2 `type_name` (`"rtc::SetpointV2"`), so a
//! process written in another language can join by copying the layout from
//! `docs/services.md`. Changing a field means a new type name (`...V2`), never an edit in place:
//! iceoryx2 checks the type name and size of a service, not its field layout.
//!
//! Service names are built here from an instance name (see [`names`]); no process spells a
//! service name itself.
//!
//! Units, everywhere: positions in the axis unit (mm for linear axes, degrees for rotary
//! ones), velocities in unit/s, efforts in N (linear) or N·m (rotary), times in nanoseconds of
//! `CLOCK_MONOTONIC` when the field name ends in `_ns`, seconds when it ends in `_s`.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

/// Defines an enum that crosses a process boundary as its integer (a `u32` or `u8` field of a
/// payload), its variants written once: the enum with `#[repr]` and its values, `ALL` (every
/// variant, in order) and `from_wire` (the variant of a wire value, `None` for a value this
/// version does not know). Variants written `Name = value as "name"` give the enum a `name()`
/// too: how reports, events and the configuration spell it.
macro_rules! wire_enum {
    (
        $(#[$attr:meta])*
        pub enum $name:ident: $repr:ident {
            $($(#[$vattr:meta])* $variant:ident = $value:literal as $text:literal,)+
        }
    ) => {
        wire_enum! {
            $(#[$attr])*
            pub enum $name: $repr {
                $($(#[$vattr])* $variant = $value,)+
            }
        }

        impl $name {
            /// Its name in lower case: how reports, events and the configuration spell it.
            pub fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $text,)+
                }
            }
        }

        // A name written twice, empty or not in lower case does not compile.
        const _: () = assert!(
            $crate::distinct_lower_case(&[$($text),+]),
            concat!(stringify!($name), ": a name twice, empty or not in lower case")
        );
    };
    (
        $(#[$attr:meta])*
        pub enum $name:ident: $repr:ident {
            $($(#[$vattr:meta])* $variant:ident = $value:literal,)+
        }
    ) => {
        $(#[$attr])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        #[repr($repr)]
        pub enum $name {
            $($(#[$vattr])* $variant = $value,)+
        }

        impl $name {
            /// Every variant, in their order.
            pub const ALL: &'static [Self] = &[$(Self::$variant),+];

            /// Decodes the wire value; `None` for a value this version does not know.
            pub fn from_wire(v: $repr) -> Option<Self> {
                match v {
                    $($value => Some(Self::$variant),)+
                    _ => None,
                }
            }
        }
    };
}

/// Whether `names` are all different, none empty and none with an upper-case ASCII letter:
/// what [`wire_enum!`]'s names must be, checked as the enum compiles.
#[doc(hidden)]
pub const fn distinct_lower_case(names: &[&str]) -> bool {
    let mut k = 0;
    while k < names.len() {
        let a = names[k].as_bytes();
        if a.is_empty() {
            return false;
        }
        let mut i = 0;
        while i < a.len() {
            if a[i].is_ascii_uppercase() {
                return false;
            }
            i += 1;
        }
        let mut j = 0;
        while j < k {
            if same_bytes(a, names[j].as_bytes()) {
                return false;
            }
            j += 1;
        }
        k += 1;
    }
    true
}

const fn same_bytes(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

pub mod clock;
pub mod config;
pub mod drive;
pub mod estop;
pub mod ethercat;
pub mod event;
pub mod io;
pub mod latency;
pub mod motion;
pub mod names;
pub mod status;

pub use clock::{CellClock, ClockGrantV1, ClockReport, ClockReportV1};
pub use config::{
    AxisConfigV2, CellConfigV6, ConfiguredFaultV1, EstopReaction, HealthConfigV1, KinParamV1,
    KinematicsConfigV1, ModbusConfigV1, ProcessConfigV2, process_flags,
};
pub use drive::{
    DriveCommandV2, DriveFeedbackV2, FaultInjectionV1, FieldbusImageV1, Power, RequestKind,
    ServoRequestV1, ServoStateV3,
};
pub use estop::{EstopKind, EstopOrigin, EstopV1};
pub use ethercat::{EmulatorFaultV1, EthercatConfigV1, EthercatIoV1, EthercatSubDeviceV1};
pub use event::{EventQueue, EventV1, Severity};
pub use io::{DigitalIoV1, IoConfigV1, IoDirection, IoWriteV1, MAX_IO, SafeValue};
pub use latency::LatencyHistogramV1;
pub use motion::{
    CommandKind, ControlKind, MotionCommandV2, MotionControlV2, MotionState, SetpointV2,
    TrajgenHandoverV2,
};
pub use names::{InstanceError, InstanceName, ServiceId, ServiceNameBuf};
pub use status::{
    CycleStatsV1, DetectorV1, MAX_PROCESSES, ProcState, ProcessName, ProcessStatusV2, estop_seen,
};

/// Capacity of every per-axis array in a shared payload. A cell uses the first `axes` entries.
pub const MAX_AXES: usize = 8;

/// Copies `s` into a fixed, NUL-padded byte field (truncating at `N - 1` bytes so the field
/// always ends in NUL, as C expects).
pub fn fixed_str<const N: usize>(s: &str) -> [u8; N] {
    let mut out = [0u8; N];
    let n = s.len().min(N.saturating_sub(1));
    out[..n].copy_from_slice(&s.as_bytes()[..n]);
    out
}

/// `v` bounded to `[lo, hi]` without `f64::clamp`'s panic on crossed or NaN bounds (a real-time
/// process must not abort on a bad value): NaN bounds are ignored, crossed ones give `hi`.
#[inline]
pub fn bound(v: f64, lo: f64, hi: f64) -> f64 {
    v.max(lo).min(hi)
}

/// Reads a NUL-padded byte field back as text; invalid UTF-8 reads as `"?"`.
pub fn str_of(bytes: &[u8]) -> &str {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    core::str::from_utf8(&bytes[..end]).unwrap_or("?")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bound_never_panics() {
        assert_eq!(bound(5.0, -1.0, 1.0), 1.0);
        assert_eq!(bound(-5.0, -1.0, 1.0), -1.0);
        assert_eq!(bound(0.5, f64::NAN, 1.0), 0.5);
        assert_eq!(bound(0.5, 1.0, -1.0), -1.0);
        assert!(bound(f64::NAN, -1.0, 1.0).is_finite());
    }

    #[test]
    fn fixed_strings_round_trip_and_truncate() {
        let f: [u8; 8] = fixed_str("theta");
        assert_eq!(str_of(&f), "theta");
        let g: [u8; 4] = fixed_str("abcdef");
        assert_eq!(str_of(&g), "abc");
        assert_eq!(g[3], 0);
    }

    #[test]
    fn every_wire_enum_decodes_its_own_values_and_nothing_else() {
        macro_rules! check {
            ($($t:ty),+) => {$(
                for v in <$t>::ALL {
                    assert_eq!(<$t>::from_wire(*v as _), Some(*v), "{v:?}");
                }
                let known = |w| <$t>::ALL.iter().any(|v| *v as i64 == w);
                for w in (0..=255).filter(|w| !known(*w)) {
                    assert_eq!(<$t>::from_wire(w as _), None, "{} {w}", stringify!($t));
                }
            )+};
        }
        check!(
            Power,
            RequestKind,
            estop::EstopKind,
            EstopOrigin,
            estop::EstopState,
            EstopReaction,
            Severity,
            IoDirection,
            SafeValue,
            CommandKind,
            ControlKind,
            MotionState,
            ProcState
        );
        assert_eq!(CommandKind::ALL.len(), 8);
    }

    #[test]
    fn a_named_wire_enums_names_must_be_distinct_non_empty_and_lower_case() {
        // What each named enum is checked with as it compiles.
        assert!(distinct_lower_case(&["stop", "hold", "ignore"]));
        assert!(!distinct_lower_case(&["stop", "hold", "stop"]));
        assert!(!distinct_lower_case(&["stop", ""]));
        assert!(!distinct_lower_case(&["stop", "Hold"]));
        assert!(!distinct_lower_case(&["holds", "hold", "hold"]));
        let named = [
            Power::ALL
                .iter()
                .map(|v| v.name())
                .collect::<std::vec::Vec<_>>(),
            EstopOrigin::ALL.iter().map(|v| v.name()).collect(),
            EstopReaction::ALL.iter().map(|v| v.name()).collect(),
            Severity::ALL.iter().map(|v| v.name()).collect(),
        ];
        assert_eq!(named[0], ["disabled", "enabling", "enabled", "disabling"]);
        assert_eq!(named[1], ["device", "external", "host"]);
        assert_eq!(named[2], ["stop", "hold", "ignore"]);
        assert_eq!(named[3], ["info", "warning", "error"]);
    }
}
