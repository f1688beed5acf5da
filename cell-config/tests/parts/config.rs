use cell_config::*;

#[test]
fn the_embedded_default_is_the_gantry_uba_cell() {
    let c = Config::default_cell();
    let names: Vec<_> = c.axis.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["x", "y", "theta"]);
    let prio = |n: &str| c.process_named(n).expect("present").priority;
    assert!(
        prio("trajgen") > prio("servo"),
        "trajgen above servo (seed 003)"
    );
    let shm = c.to_shm();
    assert_eq!(shm.axes, 3);
    assert_eq!(shm_schema::str_of(&shm.axis[2].unit), "deg");
    assert_eq!(shm.period_of("servo"), Some(1_000_000));
    assert_eq!(shm.processes().len(), 5);
}

/// Data-driven: replace `from` by `to` in the default file; the error must read `want`.
fn check(from: &str, to: &str, want: &str) {
    assert!(
        DEFAULT_TOML.contains(from),
        "{from:?} not in the default file"
    );
    let src = DEFAULT_TOML.replacen(from, to, 1);
    let e = Config::parse(&src, "cell.toml").expect_err(to);
    let got = e.to_string();
    assert!(got.starts_with(want), "\n got: {got}\nwant: {want}");
}

/// The default file with each `(from, to)` of `edits` made (at its first place, which must
/// exist): its error, and the error's text.
fn refused(edits: &[(&str, &str)]) -> (ConfigError, String) {
    let mut src = DEFAULT_TOML.to_string();
    for (from, to) in edits {
        assert!(src.contains(from), "{from:?} not in the default file");
        src = src.replacen(from, to, 1);
    }
    let e = Config::parse(&src, "cell.toml").expect_err("refused");
    let text = e.to_string();
    (e, text)
}

#[test]
fn every_problem_is_reported_at_once_in_the_files_order() {
    let (e, text) = refused(&[
        ("stop_timeout = 3.0", "stop_timeout = 1e20"),
        ("priority = 60", "priority = 120"),
        ("vmax = 16.0", "vmax = 0.0"),
        ("t_acc = 0.525", "t_acc = -1.0"),
    ]);
    assert_eq!(e.problems.len(), 4, "{text}");
    let lines: Vec<usize> = e.problems.iter().map(|p| p.line).collect();
    assert!(lines.windows(2).all(|w| w[0] < w[1]), "{text}");
    for needle in [
        "t_acc = -1 s must be positive",
        "vmax = 0 must be positive",
        "priority 120 must be 0..=99",
        "stop_timeout = 100000000000000000000 s must be 0.1..=60 s",
    ] {
        assert!(text.contains(needle), "{needle:?} in\n{text}");
    }
    assert_eq!(text.lines().count(), 4, "one line each:\n{text}");
}

/// `[motion]`'s own keys: each problem at once, not the first one only.
/// The line of the default file's first line that starts with `start`, after `after` such
/// lines.
fn line_starting(start: &str, after: usize) -> usize {
    DEFAULT_TOML
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with(start))
        .nth(after)
        .unwrap_or_else(|| panic!("{start:?} in the default file"))
        .0
        + 1
}

#[test]
fn every_problem_of_the_files_types_is_reported_at_once_each_at_its_line() {
    // Values of the wrong type and unknown keys in three sections and two axes, and a key a
    // process needs taken away: serde alone stops at the first.
    let (e, text) = refused(&[
        ("settle_time = 0.1 ", "settle_time = \"long\" "),
        ("substeps = 4 ", "substepz = 4 "),
        ("vmax = 16.0                   # mm/s", "vmax = \"fast\""),
        ("servo = { kp = 78.0,", "servo = { kp = true,"),
        ("name = \"theta\"", "name = \"theta\"\ncolour = \"red\""),
        (
            "period_us = 1000\nphase_us = 100\npriority = 85",
            "phase_us = 100\npriority = 85",
        ),
    ]);
    let theta = line_starting("name = \"theta\"", 0);
    let want = [
        format!(
            "cell.toml:{}:1: missing field `period_us`",
            line_starting("[[process]]", 0) + 1 // the line `colour` adds above
        ),
        format!(
            "cell.toml:{}:15: invalid type: string \"long\", expected f64",
            line_starting("settle_time", 0)
        ),
        format!(
            "cell.toml:{}:1: unknown field `substepz`",
            line_starting("substeps", 0)
        ),
        format!(
            "cell.toml:{}:8: invalid type: string \"fast\", expected f64",
            line_starting("vmax", 0)
        ),
        format!(
            "cell.toml:{}:16: invalid type: boolean `true`, expected f64",
            line_starting("servo", 1)
        ),
        format!("cell.toml:{}:1: unknown field `colour`", theta + 1),
    ];
    for w in &want {
        assert!(text.contains(w.as_str()), "{w:?} in\n{text}");
    }
    assert_eq!(e.problems.len(), want.len(), "{text}");
    // In the file's order.
    let lines: Vec<usize> = e.problems.iter().map(|p| p.line).collect();
    assert!(lines.is_sorted(), "{text}");
}

#[test]
fn every_syntax_error_the_parser_gets_past_is_reported() {
    let (e, text) = refused(&[
        ("t_acc = 0.525", "t_acc = 0.525.1"),
        ("substeps = 4 ", "substeps = = 4 "),
    ]);
    let lines: Vec<usize> = e.problems.iter().map(|p| p.line).collect();
    assert_eq!(lines[0], line_starting("t_acc", 0), "{text}");
    // `= = 4` is two errors to the parser.
    assert!(
        lines[1..]
            .iter()
            .all(|l| *l == line_starting("substeps", 0)),
        "{text}"
    );
    assert!(lines.len() >= 2, "{text}");
}

#[test]
fn every_problem_of_the_motion_section_is_reported_at_once() {
    let (e, text) = refused(&[
        ("t_acc = 0.525", "t_acc = 0.0"),
        ("settle_time = 0.1 ", "settle_time = -0.1 "),
        ("settle_timeout = 5.0", "settle_timeout = 0.0"),
    ]);
    for needle in [
        "t_acc = 0 s must be positive",
        "settle_time must be 0 s or more",
        "settle_timeout must be positive",
    ] {
        assert!(text.contains(needle), "{needle:?} in\n{text}");
    }
    assert_eq!(e.problems.len(), 3, "{text}");
}

#[test]
fn each_part_of_one_axis_says_its_own_problem_and_a_derived_check_waits_for_them() {
    // Axis x: its unit, its range, a servo gain and its mechanics, each wrong.
    let (e, text) = refused(&[
        ("unit = \"mm\"", "unit = \"millimetre\""),
        ("start = 40.0 ", "start = 400.0"),
        ("kp = 125.0", "kp = -1.0"),
        ("coulomb = 3.0", "coulomb = -3.0"),
    ]);
    for needle in [
        "unit \"millimetre\" must be 1 to 7 bytes",
        "axis x: start 400 lies outside 0 .. 200",
        "axis x: servo kp = -1 must be 0 or more",
        "axis x: sim coulomb = -3 must be 0 or more",
    ] {
        assert!(text.contains(needle), "{needle:?} in\n{text}");
    }
    // None from the limits or the loop's stability, which derive from all of these.
    assert_eq!(e.problems.len(), 4, "{text}");
    // Alone, a gain the loop cannot hold is found by the stability check.
    let (e, text) = refused(&[("kp = 125.0", "kp = 1e9")]);
    assert_eq!(e.problems.len(), 1, "{text}");
    assert!(text.contains("axis x"), "{text}");
}

/// Like [`check`]: the one error is on `line` and says `needle`.
fn check_has(from: &str, to: &str, line: usize, needle: &str) {
    let src = DEFAULT_TOML.replacen(from, to, 1);
    let e = Config::parse(&src, "cell.toml").expect_err(to);
    assert_eq!(e.problems.len(), 1, "{e}");
    assert_eq!(e.problems[0].line, line, "{e}");
    assert!(e.to_string().contains(needle), "{e}");
}

/// `src` edited as TOML by `edit` (a valid configuration made from another: edits by the
/// document's structure, not by its text).
fn edited(src: &str, edit: impl FnOnce(&mut toml_edit::DocumentMut)) -> String {
    let mut doc: toml_edit::DocumentMut = src.parse().expect("a TOML document");
    edit(&mut doc);
    doc.to_string()
}

/// The `[[process]]` entry named `name` of `doc`.
fn process<'a>(doc: &'a mut toml_edit::DocumentMut, name: &str) -> &'a mut toml_edit::Table {
    doc["process"]
        .as_array_of_tables_mut()
        .expect("[[process]]")
        .iter_mut()
        .find(|p| p["name"].as_str() == Some(name))
        .unwrap_or_else(|| panic!("process {name}"))
}

fn line_of(needle: &str) -> usize {
    DEFAULT_TOML
        .lines()
        .position(|l| l.contains(needle))
        .expect("present")
        + 1
}

#[test]
fn the_modbus_settings_and_critical_are_checked_where_they_are_written() {
    // A key left out takes its documented default; an empty section is all defaults.
    let src = edited(DEFAULT_TOML, |d| {
        d["modbus"]
            .as_table_mut()
            .expect("[modbus]")
            .remove("max_connections");
    });
    let c = Config::parse(&src, "cell.toml").expect("max_connections left out");
    assert_eq!(c.modbus.max_connections, 8);
    let d = cell_config::modbus::ModbusSettings::default();
    assert_eq!(
        (
            d.listen.as_str(),
            d.max_connections,
            d.idle_timeout,
            d.writes
        ),
        ("127.0.0.1:1502", 8, 60.0, true),
        "docs/fieldbus.md's defaults"
    );
    let l = line_of("listen = \"127.0.0.1:1502\"");
    check(
        "listen = \"127.0.0.1:1502\"",
        "listen = \"localhost:1502\"",
        &format!("cell.toml:{l}:1: modbus listen = \"localhost:1502\" is not an IP:port address"),
    );
    let m = line_of("max_connections = 8");
    check(
        "max_connections = 8",
        "max_connections = 0",
        &format!("cell.toml:{m}:1: modbus max_connections = 0 must be 1..=64"),
    );
    check("idle_timeout = 60.0", "idle_timeout = 1e20", "cell.toml:");
    let servo = line_of("command = [\"servo\"");
    check(
        "command = [\"servo\", \"--instance\", \"{instance}\"]",
        "command = [\"servo\", \"--instance\", \"{instance}\"]\ncritical = false",
        &format!(
            "cell.toml:{}:1: process servo: critical = false is not allowed",
            servo + 1
        ),
    );
    let c = Config::default_cell();
    let shm = c.to_shm();
    let modbus = shm.process_named("modbus").expect("in the default cell").1;
    assert!(!modbus.critical() && shm.process_named("servo").expect("servo").1.critical());
    assert_eq!(shm_schema::str_of(&shm.modbus.listen), "127.0.0.1:1502");
}

#[test]
fn io_on_the_bus_and_the_drives_entry_are_checked_where_they_are_written() {
    let bus = include_str!("../../../examples/gantry-ethercat.toml");
    let parse = |from: &str, to: &str| {
        assert!(bus.contains(from), "{from:?} not in the EtherCAT example");
        let src = bus.replacen(from, to, 1);
        Config::parse(&src, "cell.toml").expect_err(to).to_string()
    };
    let line = |needle: &str| {
        bus.lines()
            .position(|l| l.contains(needle))
            .expect("present")
            + 1
    };
    let gripper = line("ethercat = { subdevice = \"do\", bit = 0 }");
    let got = parse(
        "ethercat = { subdevice = \"do\", bit = 0 }",
        "ethercat = { subdevice = \"dx\", bit = 0 }",
    );
    assert!(
        got.starts_with(&format!(
            "cell.toml:{gripper}:14: io \"gripper\": subdevice \"dx\" is not in [[ethercat.subdevice]] (EK1100, x, y, theta, di, do)"
        )),
        "{got}"
    );
    let got = parse(
        "ethercat = { subdevice = \"do\", bit = 0 }",
        "ethercat = { subdevice = \"y\", bit = 0 }",
    );
    assert!(got.contains("subdevice \"y\" is a drive"), "{got}");
    let got = parse(
        "ethercat = { subdevice = \"do\", bit = 1 }",
        "ethercat = { subdevice = \"do\", bit = 0 }",
    );
    assert!(
        got.contains("io \"cycle_lamp\": bit 0 of \"do\" already carries io \"gripper\""),
        "{got}"
    );
    // Without [ethercat], no entry may name the bus.
    let at = bus.find("\n[ethercat]\n").expect("the section");
    let got = Config::parse(&bus[..at], "cell.toml")
        .expect_err("io on a bus that is not there")
        .to_string();
    assert!(
        got.contains(
            "io \"estop_ok\": ethercat names a bit of the bus, and the cell has no [ethercat]"
        ),
        "{got}"
    );
    // The drives' entry is called drives; the old name says so.
    let got = parse("name = \"drives\"", "name = \"machine\"");
    assert!(
        got.contains("the drives' process is called \"drives\" (it was \"machine\")"),
        "{got}"
    );
    // The bus' IO as the bus process reads it.
    let c = Config::parse(bus, "cell.toml").expect("the example");
    let shm = c
        .ethercat
        .as_ref()
        .expect("[ethercat]")
        .to_shm(&c.axis, &c.io);
    let ios: Vec<_> = shm
        .ios()
        .iter()
        .map(|m| (m.entry, m.position, m.bit))
        .collect();
    assert_eq!(ios, [(0, 4, 0), (1, 5, 0), (2, 4, 1), (3, 4, 2), (4, 5, 1)]);
    // The drives on SYNC0 by default, the coupler and the terminals not; a shift in
    // seconds, in ns for the bus process.
    let sync0: Vec<_> = shm
        .subdevices()
        .iter()
        .map(|s| {
            (
                s.flags & shm_schema::ethercat::subdevice_flags::SYNC0 != 0,
                s.sync0_shift_ns,
            )
        })
        .collect();
    assert_eq!(
        sync0,
        [
            (false, 0),
            (true, 0),
            (true, 0),
            (true, 0),
            (false, 0),
            (false, 0)
        ]
    );
    // x's drive, position 1.
    let x = "rated_torque = 100.0       # N: 1000 thousandths";
    let src = edited(bus, |d| {
        d["ethercat"]["subdevice"][1]["sync0_shift"] = toml_edit::value(0.0002);
    });
    let c = Config::parse(&src, "cell.toml").expect("a shift of 200 µs");
    let shm = c
        .ethercat
        .as_ref()
        .expect("[ethercat]")
        .to_shm(&c.axis, &c.io);
    assert_eq!(shm.subdevices()[1].sync0_shift_ns, 200_000);
    let got = parse(x, &format!("{x}\nsync0_shift = 0.001"));
    assert!(
        got.contains("ethercat subdevice 1 (\"x\"): sync0_shift = 0.001 s must be more than 0 and less than the drives' period (0.001 s)"),
        "{got}"
    );
    let got = parse(x, &format!("{x}\nsync = \"frame\"\nsync0_shift = 0.0002"));
    assert!(
        got.contains("sync0_shift is for a SubDevice on SYNC0"),
        "{got}"
    );
    let got = parse(x, &format!("{x}\nsync = \"sync0\""));
    assert!(
        got.contains("unknown variant `sync0`, expected `dc` or `frame`"),
        "{got}"
    );
}

#[test]
fn errors_name_file_line_and_reason() {
    let t = line_of("t_acc = 0.525");
    check(
        "t_acc = 0.525",
        "t_acc = -1.0",
        &format!("cell.toml:{t}:1: t_acc = -1 s must be positive"),
    );
    check(
        "t_acc = 0.525",
        "t_acc = 0.525\nspeed = 3",
        &format!("cell.toml:{}:1: unknown field `speed`", t + 1),
    );
    check(
        "t_acc = 0.525",
        "t_acc = \"fast\"",
        &format!("cell.toml:{t}:9: invalid type: string \"fast\""),
    );
    let y_vmax = DEFAULT_TOML
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with("vmax = "))
        .nth(1)
        .expect("y")
        .0
        + 1;
    let src_line = |n: usize| format!("cell.toml:{n}:1: ");
    check(
        "vmax = 16.0\nstart = 40.0\nfollowing_error_limit = 1.0\nin_position = 0.01\nservo = { kp = 78.0",
        "vmax = 0.0\nstart = 40.0\nfollowing_error_limit = 1.0\nin_position = 0.01\nservo = { kp = 78.0",
        &(src_line(y_vmax) + "axis y: vmax = 0 must be positive"),
    );
    let prio = line_of("priority = 70");
    check(
        "priority = 70",
        "priority = 120",
        &(src_line(prio) + "process servo: priority 120 must be 0..=99"),
    );
    check(
        "priority = 70",
        "priority = 70\ncpu = 64",
        &(src_line(prio + 1) + "process servo: cpu 64 does not exist"),
    );
    check(
        "name = \"theta\"",
        "name = \"x\"",
        &(src_line(line_of("name = \"theta\"")) + "axis name \"x\" is used twice"),
    );
    check(
        "start = 0.0",
        "start = 500.0",
        &(src_line(line_of("start = 0.0")) + "axis theta: start 500 lies outside"),
    );
    check(
        "command_timeout = 0.1",
        "command_timeout = 0.001",
        &(src_line(line_of("command_timeout"))
            + "command_timeout = 0.001 s must be at least 3 servo periods"),
    );
    let kp = line_of("kp = 5.45");
    check(
        "kp = 5.45",
        "kp = -5.45",
        &format!("cell.toml:{kp}:11: axis theta: servo kp = -5.45 must be 0 or more"),
    );
    check(
        "name = \"iobridge\"",
        "name = \"servo\"",
        &(src_line(line_of("name = \"iobridge\"")) + "process name \"servo\" is used twice"),
    );
    // Two problems: the name, and so the cell has no trajgen.
    let src = DEFAULT_TOML.replacen("name = \"trajgen\"", "name = \"Trajgen\"", 1);
    let e = Config::parse(&src, "cell.toml").expect_err("Trajgen");
    let text = e.to_string();
    assert_eq!(e.problems.len(), 2, "{text}");
    assert!(
        text.contains(
            &(src_line(line_of("name = \"trajgen\""))
                + "process name \"Trajgen\": a process name is a lower-case letter")
        ) && text.contains("the cell needs a process called \"trajgen\""),
        "{text}"
    );
    check("name = \"trajgen\"", "name = \"planner\"", "cell.toml:");
    check_has(
        "priority = 60",
        "priority = 60\nnetwork_estop_config = \"pause\"",
        line_of("priority = 60") + 1,
        "unknown variant `pause`, expected one of `stop`, `hold`, `ignore`",
    );
    check(
        "stop_timeout = 3.0",
        "stop_timeout = 1e20",
        &(src_line(line_of("stop_timeout = 3.0"))
            + "stop_timeout = 100000000000000000000 s must be 0.1..=60 s"),
    );
    check(
        "thread_offset_variance_percent = 50.0",
        "thread_offset_variance_percent = -1.0",
        &(src_line(line_of("thread_offset_variance_percent"))
            + "thread_offset_variance_percent = -1 must be 0..=1000"),
    );
    check(
        "period_us = 4000\nphase_us = 600",
        "period_us = 4000\nphase_us = 6000",
        &(src_line(line_of("phase_us = 600")) + "process iobridge: phase_us must be smaller"),
    );
}

#[test]
fn a_bad_kinematics_is_refused_with_the_reason() {
    let five_bar = include_str!("../../../examples/five-bar.toml");
    assert!(Config::parse(five_bar, "five-bar.toml").is_ok());
    let refused = |from: &str, to: &str, want: &str| {
        assert!(five_bar.contains(from), "{from:?}");
        let e = Config::parse(&five_bar.replacen(from, to, 1), "f.toml").expect_err(to);
        assert!(e.to_string().contains(want), "\n got: {e}\nwant: {want}");
    };
    refused(
        "type = \"five-bar\"",
        "type = \"delta\"",
        "unknown kinematics type `delta`",
    );
    refused("l2 = 150.0", "l_2 = 150.0", "l_2");
    refused(
        "vmax = [40.0, 40.0]",
        "vmax = [40.0]",
        "vmax has 1 values; the kinematics has 2 Cartesian coordinates",
    );
    refused("vmax = [40.0, 40.0]", "", "needs `vmax`");
    refused(
        "name = \"a1\"\nunit = \"deg\"",
        "name = \"a1\"\nunit = \"mm\"",
        "axis a1: joint 2 of five-bar is rotary in deg",
    );
    // The gantry takes no parameters and its coordinates' speeds are the axes'.
    let gantry = DEFAULT_TOML.replace("[behaviour]", "[kinematics]\nl1 = 3.0\n\n[behaviour]");
    let e = Config::parse(&gantry, "g.toml").expect_err("gantry parameter");
    assert!(
        e.to_string().contains("the gantry has no parameters"),
        "{e}"
    );
}

#[test]
fn a_bad_io_table_is_refused_naming_the_entry_and_key() {
    let at = |needle: &str| format!("cell.toml:{}:1: ", line_of(needle));
    check(
        "safe = \"hold\"",
        "safe = 2",
        &(at("safe = \"hold\"") + "IO gripper: safe must be 0, 1 or \"hold\""),
    );
    check(
        "safe = \"hold\"",
        "safe = \"hold\"\nestop = true",
        &format!(
            "cell.toml:{}:1: IO gripper: `estop` is for inputs; gripper is an output",
            line_of("safe = \"hold\"") + 1
        ),
    );
    check(
        "follows = \"gripper\"",
        "follows = \"part_present\"",
        &(at("follows = \"gripper\"")
            + "IO gripper_closed: follows \"part_present\", which is not an output of `[[io]]`"),
    );
    check(
        "switch_time = 0.08",
        "switch_time = 1e20",
        &(at("switch_time = 0.08")
            + "IO gripper_closed: switch_time = 100000000000000000000 s must be 0..=10"),
    );
    check(
        "name = \"part_present\"",
        "name = \"gripper\"",
        &(at("name = \"part_present\"") + "IO name \"gripper\" is used twice"),
    );
    check(
        "name = \"part_present\"",
        "name = \"part present\"",
        &(at("name = \"part_present\"")
            + "IO name \"part present\": a letter, then letters, digits and '_', at most 23 bytes"),
    );
    check(
        "direction = \"input\"\nestop = true",
        "direction = \"in\"\nestop = true",
        "cell.toml:",
    );
}

#[test]
fn physically_absurd_or_inconsistent_axes_are_refused_with_the_reason() {
    let sim = line_of("inertia = 0.008");
    // The inertia accepted before this check ran the triangle with x = NaN.
    check(
        "inertia = 0.008",
        "inertia = 1e-300",
        &format!(
            "cell.toml:{sim}:9: axis x: sim inertia 1e-300 makes servo's position loop \
             unstable at its 1000 µs period"
        ),
    );
    // Far too much velocity gain for the inertia at this period.
    check(
        "kd = 1.4,",
        "kd = 40.0,",
        &format!(
            "cell.toml:{}:9: axis x: sim inertia 0.008 makes servo's position loop unstable",
            sim
        ),
    );
    let x = line_of("name = \"x\"");
    check_has(
        "in_position = 0.01            # mm",
        "in_position = 0.01\ndrive = { mode = \"position\" }",
        x + 8,
        "unknown variant `position`, expected one of `cst`, `csp`, `csv`",
    );
    check(
        "in_position = 0.01            # mm",
        "in_position = 0.01\nlimits = { velocity = 10.0 }",
        &format!(
            "cell.toml:{}:12: axis x: limits velocity = 10 is below vmax = 16",
            x + 8
        ),
    );
    check(
        "in_position = 0.01            # mm",
        "in_position = 0.01\nlimits = { stop_deceleration = 1000.0 }",
        "cell.toml:",
    );
    check(
        "in_position = 0.01            # mm",
        "in_position = 0.01\ndrive = { mode = \"csp\", kp = 100.0 }",
        "cell.toml:",
    );
    check(
        "substeps = 4 ",
        "substeps = 4\n[[drives.inject]]\naxis = \"z\"\nfault = \"over-current\"\nat = 1.0\n",
        "cell.toml:",
    );
}

#[test]
fn derived_limits_follow_vmax_t_acc_and_the_servo_period() {
    let c = Config::default_cell();
    let x = &c.axis[0];
    assert!((x.velocity_limit() - 17.6).abs() < 1e-12);
    assert!((x.position_step_limit(0.001) - 0.024).abs() < 1e-12);
    assert!((x.velocity_step_limit(0.001, 0.525) - 3.0 * 16.0 / 0.525 * 0.001).abs() < 1e-12);
    assert!((x.stop_deceleration(0.525) - 16.0 / 0.525).abs() < 1e-12);
    let shm = c.to_shm();
    assert_eq!(shm.axis[0].mode, cia402::Mode::Cst as i32);
    assert_eq!(shm.feedback_timeout_ns, 100_000_000);
}

/// Issue 21 item 15, as config.md says: `estop_stop_time` is range-checked (0.01..=60 s;
/// 0 would ask servo for an infinite deceleration) with its key and line named, and
/// `restart_backoff` (0..=60 s) and `restart_limit` (0..=1000) are taken as written, their
/// bounds included, and refused beyond them.
#[test]
fn estop_stop_time_and_the_restart_settings_are_checked_as_config_md_says() {
    let motion = "setpoint_timeout = 0.05";
    let m = line_of(motion) + 1;
    for bad in ["0", "0.0", "0.009", "60.5", "-1.0", "nan"] {
        check(
            motion,
            &format!("{motion}\nestop_stop_time = {bad}"),
            &format!("cell.toml:{m}:1: estop_stop_time = "),
        );
        check_has(
            motion,
            &format!("{motion}\nestop_stop_time = {bad}"),
            m,
            "s must be 0.01..=60 s",
        );
    }
    for v in [0.01, 0.5, 60.0] {
        let src = edited(DEFAULT_TOML, |d| {
            d["motion"]["estop_stop_time"] = toml_edit::value(v);
        });
        let c = Config::parse(&src, "cell.toml").unwrap_or_else(|e| panic!("{v}: {e}"));
        assert_eq!(c.motion.estop_stop_time, v);
    }

    let sup = "supervisor_timeout = 0.5";
    let s = line_of(sup) + 1;
    let with = |k: &str, v: toml_edit::Item| {
        let src = edited(DEFAULT_TOML, |d| d["supervisor"][k] = v.clone());
        Config::parse(&src, "cell.toml").unwrap_or_else(|e| panic!("{k} = {v}: {e}"))
    };
    let d = Config::default_cell().supervisor;
    assert_eq!(
        (d.restart_backoff, d.restart_limit),
        (0.5, 3),
        "the documented defaults"
    );
    for v in [0.0, 2.5, 60.0] {
        assert_eq!(
            with("restart_backoff", toml_edit::value(v))
                .supervisor
                .restart_backoff,
            v
        );
    }
    for v in [0, 7, 1000] {
        assert_eq!(
            with("restart_limit", toml_edit::value(i64::from(v)))
                .supervisor
                .restart_limit,
            v
        );
    }
    for (to, want) in [
        (
            "restart_backoff = 60.5",
            "restart_backoff = 60.5 s must be 0..=60 s",
        ),
        (
            "restart_backoff = -0.5",
            "restart_backoff = -0.5 s must be 0..=60 s",
        ),
        (
            "restart_limit = 1001",
            "restart_limit = 1001 must be 0..=1000",
        ),
    ] {
        check(
            sup,
            &format!("{sup}\n{to}"),
            &format!("cell.toml:{s}:1: {want}"),
        );
    }
}

/// `[supervisor] priority`: 10 by default, 0..=99, and below every real-time process of the
/// table (the loop's work must never delay a cycle); a process under `SCHED_OTHER` (0) does
/// not count.
#[test]
fn the_supervisors_priority_stays_below_every_real_time_process() {
    let s = line_of("priority = 10 ");
    assert_eq!(Config::default_cell().supervisor.priority, 10);
    for (to, want) in [
        (
            "priority = 100",
            "priority = 100 must be 0..=99 (0: SCHED_OTHER)",
        ),
        (
            "priority = -1",
            "priority = -1 must be 0..=99 (0: SCHED_OTHER)",
        ),
        (
            "priority = 60",
            "priority = 60 must be below every real-time process's: process iobridge has 60",
        ),
    ] {
        let e = Config::parse(
            &DEFAULT_TOML.replacen("priority = 10 ", &format!("{to} "), 1),
            "cell.toml",
        )
        .expect_err(to);
        assert_eq!(e.problems.len(), 1, "{e}");
        assert_eq!(e.to_string(), format!("cell.toml:{s}:1: {want}"));
    }
    for v in [0, 1, 59] {
        let src = edited(DEFAULT_TOML, |d| {
            d["supervisor"]["priority"] = toml_edit::value(i64::from(v));
        });
        let c = Config::parse(&src, "cell.toml").unwrap_or_else(|e| panic!("{v}: {e}"));
        assert_eq!(c.supervisor.priority, v);
    }
    // iobridge under SCHED_OTHER: the lowest real-time process is servo, at 70.
    let src = edited(DEFAULT_TOML, |d| {
        process(d, "iobridge")["priority"] = toml_edit::value(0);
        d["supervisor"]["priority"] = toml_edit::value(69);
    });
    Config::parse(&src, "cell.toml").expect("below servo's 70");
}

#[test]
fn a_missing_file_is_named() {
    let e =
        Config::load(Some(std::path::Path::new("/nonexistent/cell.toml"))).expect_err("missing");
    assert!(
        e.to_string()
            .starts_with("/nonexistent/cell.toml: cannot read"),
        "{e}"
    );
}

/// `[network]` and `[network.ros2]`: every problem at its key's line, at once; the same
/// section with sane values parses.
#[test]
fn the_network_and_its_ros2_table_are_checked_where_they_are_written() {
    let gateway = "\n[[process]]\nname = \"gateway\"\ncommand = [\"gateway\", \"--instance\", \"{instance}\"]\nperiod_us = 20000\npriority = 0\ncritical = false\n";
    let network = "\n[network]\nname = \"press-0\"\nlisten = [\"tcp/0.0.0.0:7447\"]\nplain = true\nusers = \"users.toml\"\n";
    let good = format!("{DEFAULT_TOML}{gateway}{network}\n[network.ros2]\ndomain = 42\n");
    let c = Config::parse(&good, "cell.toml").expect("a sane [network.ros2]");
    let r = (c.network.as_ref())
        .and_then(|n| n.ros2.clone())
        .expect("[network.ros2]");
    let name = network::CellName::new("press-0").expect("a name");
    assert_eq!(
        (r.domain, r.namespace_of(&name)),
        (42, "press_0".to_string())
    );

    let bad = format!(
        "{}{gateway}{network}\n[network.ros2]\ndomain = 233\nnamespace = \"2nd-press\"\n",
        DEFAULT_TOML.replacen("unit = \"mm\"", "unit = \"inch\"", 1)
    );
    let e = Config::parse(&bad, "cell.toml").expect_err("three problems");
    let text = e.to_string();
    assert_eq!(e.problems.len(), 3, "{text}");
    let at = |needle: &str| {
        bad.lines()
            .position(|l| l.starts_with(needle))
            .expect("present")
            + 1
    };
    for (line, needle) in [
        (
            at("[network.ros2]"),
            "axis x's unit \"inch\" is none of m, mm, um, rad, deg",
        ),
        (
            at("domain = 233"),
            "network.ros2 domain = 233 must be 0..=232",
        ),
        (
            at("namespace = \"2nd-press\""),
            "namespace \"2nd-press\" is no ROS name: it has a character other than a letter, a digit and '_'",
        ),
    ] {
        let p = (e.problems.iter())
            .find(|p| p.message.contains(needle))
            .unwrap_or_else(|| panic!("{needle:?} in\n{text}"));
        assert_eq!(p.line, line, "{needle:?} at line {line}:\n{text}");
    }
}

#[test]
fn a_key_left_out_takes_the_default_docs_config_md_gives() {
    // The default file without every key that has a default (edited as TOML).
    let mut doc: toml_edit::DocumentMut = DEFAULT_TOML.parse().expect("the default file");
    for key in ["settle_time", "settle_timeout", "setpoint_timeout"] {
        doc["motion"].as_table_mut().expect("[motion]").remove(key);
    }
    doc["drives"]
        .as_table_mut()
        .expect("[drives]")
        .remove("substeps");
    for p in doc["process"]
        .as_array_of_tables_mut()
        .expect("[[process]]")
        .iter_mut()
    {
        p.remove("critical");
        p.remove("restart");
    }
    let c = Config::parse(&doc.to_string(), "cell.toml").expect("valid");
    let m = &c.motion;
    assert_eq!(
        (
            m.settle_time,
            m.settle_timeout,
            m.setpoint_timeout,
            m.estop_stop_time
        ),
        (0.1, 5.0, 0.05, 0.5)
    );
    let d = &c.drives;
    assert_eq!(
        (d.feedback_timeout, d.enable_timeout, d.substeps),
        (0.1, 0.5, 4)
    );
    for p in &c.process {
        assert!(p.critical, "{}", p.name);
        assert_eq!(p.restart, RestartPolicy::OnFailure, "{}", p.name);
    }
    assert_eq!(c.kinematics.kind, "gantry");
    assert_eq!(c.kinematics.vmax, None);
}
