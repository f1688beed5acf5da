//! The byte layout of every shared payload, as `docs/payload-layouts.md` documents it for
//! processes in other languages. The test fails if a field is missing from the listing (a gap
//! or a short total), if the type has padding, or if the document differs; regenerate it with
//! `BLESS=1 cargo test -p shm-schema --test layout`.

use core::mem::{offset_of, size_of};
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use shm_schema::estop::HostStateV1;
use shm_schema::*;

struct Layout {
    name: &'static str,
    type_name: &'static str,
    size: usize,
    fields: Vec<(usize, usize, &'static str, &'static str)>,
}

macro_rules! layout {
    ($t:ty { $($f:ident : $c:literal = $s:expr),* $(,)? }) => {{
        Layout {
            name: stringify!($t),
            // SAFETY: type_name has no preconditions; it is unsafe only to implement.
            type_name: unsafe { <$t as ZeroCopySend>::type_name() },
            size: size_of::<$t>(),
            fields: vec![$((offset_of!($t, $f), $s, stringify!($f), $c)),*],
        }
    }};
}

const A: usize = MAX_AXES;

fn layouts() -> Vec<Layout> {
    vec![
        layout!(CellConfigV6 {
            axes: "uint32_t" = 4,
            machine_substeps: "uint32_t" = 4,
            t_acc_s: "double" = 8,
            drive_command_timeout_ns: "uint64_t" = 8,
            setpoint_timeout_ns: "uint64_t" = 8,
            feedback_timeout_ns: "uint64_t" = 8,
            enable_timeout_ns: "uint64_t" = 8,
            settle_time_ns: "uint64_t" = 8,
            estop_stop_time_ns: "uint64_t" = 8,
            supervisor_timeout_ns: "uint64_t" = 8,
            propagate_estop: "uint32_t" = 4,
            propagate_external_estop: "uint32_t" = 4,
            process_count: "uint32_t" = 4,
            clock: "uint32_t" = 4,
            health: "HealthConfigV1" = size_of::<HealthConfigV1>(),
            process: "ProcessConfigV2[16]" = MAX_PROCESSES * size_of::<ProcessConfigV2>(),
            axis: "AxisConfigV2[8]" = A * size_of::<AxisConfigV2>(),
            inject: "ConfiguredFaultV1[4]" = 4 * size_of::<ConfiguredFaultV1>(),
            io_count: "uint32_t" = 4,
            reserved2: "uint32_t" = 4,
            io: "IoConfigV1[64]" = MAX_IO * size_of::<IoConfigV1>(),
            kinematics: "KinematicsConfigV1" = size_of::<KinematicsConfigV1>(),
            modbus: "ModbusConfigV1" = size_of::<ModbusConfigV1>(),
        }),
        layout!(EthercatConfigV1 {
            interface: "char[16]" = 16,
            count: "uint32_t" = 4,
            io_count: "uint32_t" = 4,
            pd_watchdog_ns: "uint64_t" = 8,
            subdevice: "EthercatSubDeviceV1[32]" = 32 * size_of::<EthercatSubDeviceV1>(),
            io: "EthercatIoV1[64]" = 64 * size_of::<EthercatIoV1>(),
        }),
        layout!(EthercatIoV1 {
            entry: "uint16_t" = 2,
            position: "uint16_t" = 2,
            bit: "uint16_t" = 2,
            reserved: "uint16_t" = 2,
        }),
        layout!(EmulatorFaultV1 {
            seq: "uint64_t" = 8,
            kind: "uint32_t" = 4,
            position: "uint32_t" = 4,
            code: "uint32_t" = 4,
            bit: "uint32_t" = 4,
        }),
        layout!(EthercatSubDeviceV1 {
            name: "char[16]" = 16,
            vendor: "uint32_t" = 4,
            product: "uint32_t" = 4,
            revision: "uint32_t" = 4,
            flags: "uint32_t" = 4,
            axis: "int32_t" = 4,
            sync0_shift_ns: "uint32_t" = 4,
            counts_per_unit: "double" = 8,
            rated_effort: "double" = 8,
        }),
        layout!(ModbusConfigV1 {
            listen: "char[64]" = 64,
            max_connections: "uint32_t" = 4,
            writes: "uint32_t" = 4,
            idle_timeout_ns: "uint64_t" = 8,
        }),
        layout!(KinematicsConfigV1 {
            type_name: "char[24]" = 24,
            param_count: "uint32_t" = 4,
            coords: "uint32_t" = 4,
            params: "KinParamV1[8]" = 8 * size_of::<KinParamV1>(),
            coord_vmax: "double[8]" = 8 * A,
        }),
        layout!(KinParamV1 {
            name: "char[16]" = 16,
            value: "double" = 8,
        }),
        layout!(IoConfigV1 {
            name: "char[24]" = 24,
            direction: "uint32_t" = 4,
            safe: "uint32_t" = 4,
            estop: "uint32_t" = 4,
            sim: "uint32_t" = 4,
            follows: "int32_t" = 4,
            reserved: "uint32_t" = 4,
            switch_time_ns: "uint64_t" = 8,
        }),
        layout!(IoWriteV1 {
            stamp_ns: "uint64_t" = 8,
            mask: "uint64_t" = 8,
            values: "uint64_t" = 8,
            source: "uint32_t" = 4,
            line: "uint32_t" = 4,
        }),
        layout!(DigitalIoV1 {
            seq: "uint64_t" = 8,
            stamp_ns: "uint64_t" = 8,
            values: "uint64_t" = 8,
            changed: "uint64_t" = 8,
            taken: "uint64_t" = 8,
            refused: "uint64_t" = 8,
            count: "uint32_t" = 4,
            outputs_safe: "uint32_t" = 4,
        }),
        layout!(ProcessConfigV2 {
            name: "char[16]" = 16,
            period_ns: "uint64_t" = 8,
            phase_ns: "uint64_t" = 8,
            priority: "int32_t" = 4,
            cpu: "int32_t" = 4,
            network_estop_config: "uint32_t" = 4,
            flags: "uint32_t" = 4,
        }),
        layout!(HealthConfigV1 {
            pending_sequence_overrun_percent_limit: "double" = 8,
            pending_sequence_overrun_leak_time_s: "double" = 8,
            pending_sequence_overrun_start_snooze_s: "double" = 8,
            transport_overrun_percent_limit: "double" = 8,
            transport_overrun_leak_time_s: "double" = 8,
            thread_offset_variance_percent: "double" = 8,
            thread_offset_variance_overrun_percent_limit: "double" = 8,
            thread_offset_variance_overrun_leak_time_s: "double" = 8,
            thread_offset_variance_start_snooze_s: "double" = 8,
        }),
        layout!(AxisConfigV2 {
            name: "char[16]" = 16,
            unit: "char[8]" = 8,
            min: "double" = 8,
            max: "double" = 8,
            vmax: "double" = 8,
            start: "double" = 8,
            following_error_limit: "double" = 8,
            in_position: "double" = 8,
            settle_velocity: "double" = 8,
            velocity_limit: "double" = 8,
            position_step_limit: "double" = 8,
            velocity_step_limit: "double" = 8,
            stop_deceleration: "double" = 8,
            kp: "double" = 8,
            ki: "double" = 8,
            kd: "double" = 8,
            kvff: "double" = 8,
            kaff: "double" = 8,
            integral_limit: "double" = 8,
            mode: "int32_t" = 4,
            quick_stop_option: "int32_t" = 4,
            drive_kp: "double" = 8,
            drive_ki: "double" = 8,
            drive_kd: "double" = 8,
            quick_stop_deceleration: "double" = 8,
            inertia: "double" = 8,
            viscous: "double" = 8,
            coulomb: "double" = 8,
            effort_limit: "double" = 8,
            encoder_resolution: "double" = 8,
        }),
        layout!(ConfiguredFaultV1 {
            at_ns: "uint64_t" = 8,
            duration_ns: "uint64_t" = 8,
            axis: "uint32_t" = 4,
            code: "uint32_t" = 4,
        }),
        layout!(MotionCommandV2 {
            seq: "uint64_t" = 8,
            program_id: "uint32_t" = 4,
            line: "uint32_t" = 4,
            kind: "uint32_t" = 4,
            count: "uint32_t" = 4,
            io: "uint32_t" = 4,
            value: "uint32_t" = 4,
            time_s: "double" = 8,
            speed: "double" = 8,
            target: "double[8]" = 8 * A,
        }),
        layout!(MotionControlV2 {
            seq: "uint64_t" = 8,
            kind: "uint32_t" = 4,
            reserved: "uint32_t" = 4,
            value: "double" = 8,
        }),
        layout!(TrajgenHandoverV2 {
            stamp_ns: "uint64_t" = 8,
            command_seq: "uint64_t" = 8,
            motion_start_ns: "uint64_t" = 8,
            program_id: "uint32_t" = 4,
            line: "uint32_t" = 4,
            valid: "uint32_t" = 4,
            starved: "uint32_t" = 4,
            local_s: "double" = 8,
            lost_s: "double" = 8,
            theoretical_s: "double" = 8,
            t1_s: "double" = 8,
            t_acc_s: "double" = 8,
            a: "double[8]" = 8 * A,
            b: "double[8]" = 8 * A,
            c: "double[8]" = 8 * A,
            speed_override: "double" = 8,
            program_speed: "double" = 8,
            waited_s: "double" = 8,
            space: "uint32_t" = 4,
            reserved: "uint32_t" = 4,
        }),
        layout!(SetpointV2 {
            seq: "uint64_t" = 8,
            stamp_ns: "uint64_t" = 8,
            motion_start_ns: "uint64_t" = 8,
            motion_end_ns: "uint64_t" = 8,
            motion_time_s: "double" = 8,
            theoretical_s: "double" = 8,
            segment_time_s: "double" = 8,
            program_id: "uint32_t" = 4,
            line: "uint32_t" = 4,
            state: "uint32_t" = 4,
            axes: "uint32_t" = 4,
            fault: "uint32_t" = 4,
            fault_line: "uint32_t" = 4,
            commands_taken: "uint64_t" = 8,
            queue_free: "uint32_t" = 4,
            starved: "uint32_t" = 4,
            path_speed: "double" = 8,
            control_seq: "uint64_t" = 8,
            speed_override: "double" = 8,
            program_speed: "double" = 8,
            hold: "uint32_t" = 4,
            hold_io: "uint32_t" = 4,
            space: "uint32_t" = 4,
            coords: "uint32_t" = 4,
            waited_s: "double" = 8,
            position: "double[8]" = 8 * A,
            velocity: "double[8]" = 8 * A,
            acceleration: "double[8]" = 8 * A,
            cartesian: "double[8]" = 8 * A,
            cartesian_velocity: "double[8]" = 8 * A,
        }),
        layout!(ServoStateV3 {
            seq: "uint64_t" = 8,
            stamp_ns: "uint64_t" = 8,
            measured_stamp_ns: "uint64_t" = 8,
            setpoint_seq: "uint64_t" = 8,
            request_seq: "uint64_t" = 8,
            status: "uint32_t" = 4,
            axes: "uint32_t" = 4,
            power: "uint8_t" = 1,
            axis_power: "uint8_t[8]" = A,
            reserved: "uint8_t[7]" = 7,
            settled_axes: "uint32_t" = 4,
            fault_code: "uint32_t" = 4,
            fault_axis: "int32_t" = 4,
            reserved2: "uint32_t" = 4,
            fault_value: "double" = 8,
            fault_limit: "double" = 8,
            controlword: "uint16_t[8]" = 2 * A,
            statusword: "uint16_t[8]" = 2 * A,
            cmd_position: "double[8]" = 8 * A,
            cmd_velocity: "double[8]" = 8 * A,
            act_position: "double[8]" = 8 * A,
            act_velocity: "double[8]" = 8 * A,
            following_error: "double[8]" = 8 * A,
            effort: "double[8]" = 8 * A,
            peak_program: "uint32_t" = 4,
            reserved3: "uint32_t" = 4,
            peak_following_error: "double[8]" = 8 * A,
        }),
        layout!(ServoRequestV1 {
            seq: "uint64_t" = 8,
            kind: "uint32_t" = 4,
            axis: "uint32_t" = 4,
            value: "double" = 8,
        }),
        layout!(DriveCommandV2 {
            seq: "uint64_t" = 8,
            stamp_ns: "uint64_t" = 8,
            feedback_seq: "uint64_t" = 8,
            feedback_stamp_ns: "uint64_t" = 8,
            axes: "uint32_t" = 4,
            reserved: "uint32_t" = 4,
            controlword: "uint16_t[8]" = 2 * A,
            mode: "int8_t[8]" = A,
            target_position: "double[8]" = 8 * A,
            target_velocity: "double[8]" = 8 * A,
            target_torque: "double[8]" = 8 * A,
            velocity_offset: "double[8]" = 8 * A,
            torque_offset: "double[8]" = 8 * A,
        }),
        layout!(DriveFeedbackV2 {
            seq: "uint64_t" = 8,
            stamp_ns: "uint64_t" = 8,
            command_seq: "uint64_t" = 8,
            sense_to_command_ns: "uint64_t" = 8,
            axes: "uint32_t" = 4,
            reserved: "uint32_t" = 4,
            statusword: "uint16_t[8]" = 2 * A,
            mode_display: "int8_t[8]" = A,
            error_code: "uint16_t[8]" = 2 * A,
            position: "double[8]" = 8 * A,
            velocity: "double[8]" = 8 * A,
            torque: "double[8]" = 8 * A,
            following_error: "double[8]" = 8 * A,
        }),
        layout!(FaultInjectionV1 {
            seq: "uint64_t" = 8,
            axis: "uint32_t" = 4,
            code: "uint16_t" = 2,
            active: "uint16_t" = 2,
        }),
        layout!(EventV1 {
            seq: "uint64_t" = 8,
            stamp_ns: "uint64_t" = 8,
            value: "double" = 8,
            limit: "double" = 8,
            source: "uint32_t" = 4,
            severity: "uint32_t" = 4,
            code: "uint32_t" = 4,
            axis: "int32_t" = 4,
            text: "char[64]" = 64,
        }),
        layout!(FieldbusImageV1 {
            seq: "uint64_t" = 8,
            written_ns: "uint64_t" = 8,
            measured_ns: "uint64_t" = 8,
            source_seq: "uint64_t" = 8,
            len: "uint32_t" = 4,
            axes: "uint32_t" = 4,
            image: "uint8_t[64]" = 64,
        }),
        layout!(EstopV1 {
            stamp_ns: "uint64_t" = 8,
            kind: "uint32_t" = 4,
            origin: "uint32_t" = 4,
            source: "uint32_t" = 4,
            code: "uint32_t" = 4,
            reason: "char[64]" = 64,
        }),
        layout!(ClockGrantV1 {
            now_ns: "uint64_t" = 8,
            seq: "uint64_t" = 8,
            pid: "uint32_t" = 4,
            reserved: "uint32_t" = 4,
        }),
        layout!(ClockReportV1 {
            next_ns: "uint64_t" = 8,
            seq: "uint64_t" = 8,
            pid: "uint32_t" = 4,
            index: "uint32_t" = 4,
            kind: "uint32_t" = 4,
            reserved: "uint32_t" = 4,
        }),
        layout!(HostStateV1 {
            stamp_ns: "uint64_t" = 8,
            beat: "uint64_t" = 8,
            resets: "uint64_t" = 8,
            pid: "uint32_t" = 4,
            estop: "uint32_t" = 4,
            cause: "EstopV1" = size_of::<EstopV1>(),
            handover: "uint32_t" = 4,
            reserved: "uint32_t" = 4,
        }),
        layout!(ProcessStatusV2 {
            pid: "uint32_t" = 4,
            index: "uint32_t" = 4,
            state: "uint32_t" = 4,
            policy: "uint32_t" = 4,
            priority: "int32_t" = 4,
            cpu: "int32_t" = 4,
            rt_flags: "uint32_t" = 4,
            fault: "uint32_t" = 4,
            stamp_ns: "uint64_t" = 8,
            stats: "CycleStatsV1" = size_of::<CycleStatsV1>(),
            name: "char[16]" = 16,
            pending_sequence: "DetectorV1" = size_of::<DetectorV1>(),
            transport: "DetectorV1" = size_of::<DetectorV1>(),
            thread_offset: "DetectorV1" = size_of::<DetectorV1>(),
            estop: "uint32_t" = 4,
            reserved: "uint32_t" = 4,
        }),
        layout!(DetectorV1 {
            level: "float" = 4,
            limit: "float" = 4,
            total: "uint64_t" = 8,
        }),
        layout!(LatencyHistogramV1 {
            count: "uint64_t" = 8,
            sum_ns: "uint64_t" = 8,
            min_ns: "uint64_t" = 8,
            max_ns: "uint64_t" = 8,
            overflows: "uint64_t" = 8,
            stamp_ns: "uint64_t" = 8,
            buckets: "uint64_t[3712]" = 8 * shm_schema::latency::BUCKETS,
        }),
        layout!(CycleStatsV1 {
            period_ns: "uint64_t" = 8,
            cycles: "uint64_t" = 8,
            overruns: "uint64_t" = 8,
            skipped: "uint64_t" = 8,
            wakeup_latency_ns: "uint64_t" = 8,
            max_wakeup_latency_ns: "uint64_t" = 8,
            exec_ns: "uint64_t" = 8,
            max_exec_ns: "uint64_t" = 8,
            overrun_flag: "uint32_t" = 4,
            reserved: "uint32_t" = 4,
        }),
    ]
}

fn render() -> String {
    let mut s = String::from(
        "# Payload byte layouts\n\nGenerated by `shm-schema/tests/layout.rs` from the Rust \
         definitions (`BLESS=1 cargo test -p shm-schema --test layout`); do not edit by hand. \
         All types are `#[repr(C)]`, little-endian on this platform, 8-byte aligned, without \
         padding. `MAX_AXES` = 8. Units and meanings: the field documentation in `shm-schema/src`.\n",
    );
    for l in layouts() {
        s += &format!(
            "\n## {}\n\niceoryx2 type name `{}`, {} bytes.\n\n| offset | size | field | C type |\n|---:|---:|---|---|\n",
            l.name, l.type_name, l.size
        );
        for (off, size, name, c) in &l.fields {
            s += &format!("| {off} | {size} | `{name}` | `{c}` |\n");
        }
    }
    s
}

#[test]
fn every_field_is_listed_without_gaps_or_padding() {
    for l in layouts() {
        let mut at = 0;
        for (off, size, name, _) in &l.fields {
            assert_eq!(
                *off, at,
                "{}: field {name} at {off}, expected {at} (a field is missing or padded)",
                l.name
            );
            at += size;
        }
        assert_eq!(
            at, l.size,
            "{}: listed fields cover {at} of {} bytes",
            l.name, l.size
        );
        assert!(
            l.type_name.starts_with("rtc::")
                && l.type_name
                    .rsplit_once('V')
                    .is_some_and(|(_, v)| v.parse::<u32>().is_ok()),
            "{}",
            l.type_name
        );
    }
}

#[test]
fn the_layout_document_is_current() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/payload-layouts.md");
    let want = render();
    if std::env::var_os("BLESS").is_some() {
        std::fs::write(path, &want).expect("write docs/payload-layouts.md");
    }
    let have = std::fs::read_to_string(path).unwrap_or_default();
    assert!(
        have == want,
        "docs/payload-layouts.md is stale: run BLESS=1 cargo test -p shm-schema --test layout"
    );
}
