//! The cell's Modbus TCP server on the real binaries (docs/fieldbus.md): independent clients
//! (pymodbus from PyPI, Debian's mbpoll, and raw frames written here) read the positions of a
//! running program as its trace has them, write the outputs, the e-stop and the speed
//! override; hostile frames, too many clients and idle ones disturb nothing; a lost server is
//! no e-stop; the register map's document is the code's.

use crate::drives::{WATCHDOG, pid_of};
use crate::up::{Up, arm_enabled, cell, estop_of, latched, process_of};
use control_plane::info::{Life, Origin};
use control_plane::report::RunReport;
use integration_tests::{run_with_watchdog, scratch, trace_rows};
use shm_schema::event::code;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The address the modbus process announced (it listens on port 0: any free one).
fn address(up: &Up) -> SocketAddr {
    let s = up.until_typed("the modbus server listening", |s| {
        process_of(s, "modbus").listening.is_some()
    });
    let a: SocketAddr = process_of(&s, "modbus")
        .listening
        .as_deref()
        .and_then(|a| a.parse().ok())
        .expect("an address");
    // It may listen before iobridge's first image: until then every request is busy.
    let start = Instant::now();
    let mut c = Raw::connect(a);
    while c.registers(4, 0, 1).is_err() {
        assert!(
            start.elapsed() < WATCHDOG,
            "the server never served an image"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    a
}

/// A client of the server at `a` whose first read was answered: connects again while the
/// server closes it (its connections all taken), under the watchdog.
fn served(a: SocketAddr) -> Raw {
    let start = Instant::now();
    loop {
        let mut c = Raw::connect(a);
        if let Some(Ok(_)) = c.ask(&[4, 0, 0, 0, 4]) {
            return c;
        }
        assert!(start.elapsed() < WATCHDOG, "never served");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A Modbus TCP client written from the specification, for frames no library would send.
struct Raw {
    s: TcpStream,
    tid: u16,
}

/// A response PDU, or the exception code.
type Answer = Result<Vec<u8>, u8>;

impl Raw {
    fn connect(a: SocketAddr) -> Self {
        let s = TcpStream::connect(a).expect("connect");
        s.set_read_timeout(Some(Duration::from_secs(20)))
            .expect("timeout");
        Self { s, tid: 0 }
    }

    /// Sends `pdu` to unit 1; the answer, or `None` when the server closed the connection.
    fn ask(&mut self, pdu: &[u8]) -> Option<Answer> {
        self.tid = self.tid.wrapping_add(1);
        let mut frame = Vec::new();
        frame.extend(self.tid.to_be_bytes());
        frame.extend([0, 0]);
        frame.extend((pdu.len() as u16 + 1).to_be_bytes());
        frame.push(1);
        frame.extend(pdu);
        self.s.write_all(&frame).ok()?;
        let mut hdr = [0u8; 7];
        self.s.read_exact(&mut hdr).ok()?;
        assert_eq!(&hdr[..2], &self.tid.to_be_bytes(), "transaction id echoed");
        let len = u16::from_be_bytes([hdr[4], hdr[5]]) as usize;
        let mut body = vec![0u8; len - 1];
        self.s.read_exact(&mut body).ok()?;
        Some(if body[0] & 0x80 != 0 {
            Err(body[1])
        } else {
            Ok(body)
        })
    }

    fn read(&mut self, fc: u8, addr: u16, n: u16) -> Answer {
        let [a, b] = addr.to_be_bytes();
        let [c, d] = n.to_be_bytes();
        self.ask(&[fc, a, b, c, d]).expect("an answer")
    }

    fn registers(&mut self, fc: u8, addr: u16, n: u16) -> Result<Vec<u16>, u8> {
        self.read(fc, addr, n).map(|b| {
            b[2..]
                .chunks(2)
                .map(|w| u16::from_be_bytes([w[0], w[1]]))
                .collect()
        })
    }

    fn bits(&mut self, fc: u8, addr: u16, n: u16) -> Result<Vec<bool>, u8> {
        self.read(fc, addr, n).map(|b| {
            (0..n as usize)
                .map(|k| b[2 + k / 8] >> (k % 8) & 1 == 1)
                .collect()
        })
    }

    fn write_coil(&mut self, addr: u16, on: bool) -> Answer {
        let [a, b] = addr.to_be_bytes();
        self.ask(&[5, a, b, if on { 0xFF } else { 0 }, 0])
            .expect("an answer")
    }

    fn write_register(&mut self, addr: u16, v: u16) -> Answer {
        let [a, b] = addr.to_be_bytes();
        let [c, d] = v.to_be_bytes();
        self.ask(&[6, a, b, c, d]).expect("an answer")
    }

    /// True once the server closed the connection (EOF or reset) within the read timeout.
    fn closed(&mut self) -> bool {
        let mut b = [0u8; 16];
        match self.s.read(&mut b) {
            Ok(0) => true,
            Ok(_) => false,
            Err(e) => matches!(
                e.kind(),
                ErrorKind::ConnectionReset | ErrorKind::ConnectionAborted | ErrorKind::BrokenPipe
            ),
        }
    }
}

/// Exception codes (Modbus application protocol, §7).
const ILLEGAL_FUNCTION: u8 = 1;
const ILLEGAL_ADDRESS: u8 = 2;
const ILLEGAL_VALUE: u8 = 3;
const BUSY: u8 = 6;

/// `mbpoll` reading `n` 32-bit input registers from `addr` (big-endian words): the values.
fn mbpoll_i32(a: SocketAddr, addr: u16, n: u16) -> Vec<i64> {
    let out = run_with_watchdog(
        Command::new("mbpoll").args([
            "-m",
            "tcp",
            "-p",
            &a.port().to_string(),
            "-a",
            "1",
            "-t",
            "3:int",
            "-B",
            "-0",
            "-1",
            "-r",
            &addr.to_string(),
            "-c",
            &n.to_string(),
            &a.ip().to_string(),
        ]),
        WATCHDOG,
    );
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(out.status.success(), "mbpoll: {text}");
    // Lines such as "[32]: 	40000".
    let values: Vec<i64> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix('['))
        .filter_map(|l| l.split(':').nth(1))
        .filter_map(|v| v.split_whitespace().next()?.parse().ok())
        .collect();
    assert_eq!(values.len(), n as usize, "{text}");
    values
}

/// Distance from `p` to the segment `a`-`b` (any dimension).
fn to_segment(p: &[f64], a: &[f64], b: &[f64]) -> f64 {
    let ab: Vec<f64> = a.iter().zip(b).map(|(a, b)| b - a).collect();
    let len2: f64 = ab.iter().map(|v| v * v).sum();
    let t = if len2 > 0.0 {
        (p.iter()
            .zip(a)
            .zip(&ab)
            .map(|((p, a), d)| (p - a) * d)
            .sum::<f64>()
            / len2)
            .clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.iter()
        .zip(a)
        .zip(&ab)
        .map(|((p, a), d)| (p - (a + t * d)).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn pymodbus_and_mbpoll_read_the_positions_of_a_running_program_as_its_trace_has_them() {
    integration_tests::wall_clock(|| {
        let test = "mb-read";
        let up = Up::default_cell(test);
        let a = address(&up);
        // At rest, with mbpoll: each axis' block (position, command, following error, velocity).
        let rest = mbpoll_i32(a, 32, 12);
        assert_eq!(rest[0], 40_000, "x at 40 mm: {rest:?}");
        assert_eq!(rest[4], 40_000, "y at 40 mm: {rest:?}");
        assert_eq!(rest[8], 0, "theta at 0 deg: {rest:?}");
        // pymodbus polls while a small triangle runs.
        // Killed if the test fails before it stops the poller (it polls for 120 s).
        let mut poller = integration_tests::Reaped::spawn(
            Command::new("python3")
                .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("python/modbus_poll.py"))
                .args([&a.ip().to_string(), &a.port().to_string(), "120", "3"])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped()),
            "python3",
        );
        // The motion starts once the poller reads (under load, Python's start alone took
        // seconds and the poller missed the motion).
        let mut said = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(poller.stderr.as_mut().expect("piped")),
            &mut said,
        )
        .expect("the poller's first line");
        assert_eq!(said.trim(), "ready", "the poller: {said}");
        let tr = scratch(test, "trace.csv", "");
        let triangle = integration_tests::small_triangle(test);
        let report = up.report(&triangle, &["--trace", tr.to_str().expect("utf-8")]);
        assert_eq!(report["ok"], true, "{report}");
        let _ = poller.kill();
        let polled = poller
            .into_child()
            .wait_with_output()
            .expect("poller output");
        let stdout = String::from_utf8_lossy(&polled.stdout);
        let stderr = String::from_utf8_lossy(&polled.stderr);
        // The Python client's words are all it says of a Modbus exception: the subject.
        assert!(!stderr.contains("exception"), "{stderr}");
        let rows: Vec<Vec<f64>> = stdout
            .lines()
            .filter(|l| !l.is_empty())
            .map(|l| l.split(',').map(|v| v.parse().expect("number")).collect())
            .collect();
        // image, measured_us, written_us, motion, line, then (position, command, error) per axis.
        let moving: Vec<&Vec<f64>> = rows.iter().filter(|r| r[3] == 1.0).collect();
        let trace = trace_rows(&tr);
        println!(
            "pymodbus: {} images read, {} while moving; trace {} rows",
            rows.len(),
            moving.len(),
            trace.len()
        );
        assert!(moving.len() >= 100, "too few images read while moving");
        for w in rows.windows(2) {
            assert!(w[1][0] > w[0][0], "image numbers increase: {w:?}");
            assert!(w[1][1] >= w[0][1], "measurement times increase: {w:?}");
        }
        let mut ages: Vec<f64> = rows.iter().map(|r| r[2] - r[1]).collect();
        ages.sort_by(f64::total_cmp);
        println!(
            "age of the positions when iobridge wrote them: median {:.0} µs, max {:.0} µs",
            ages[ages.len() / 2],
            ages[ages.len() - 1]
        );
        for r in &rows {
            let age_us = r[2] - r[1];
            assert!(age_us >= 0.0, "measured before written: {r:?}");
            for k in 0..3 {
                let (p, c, e) = (r[5 + 3 * k], r[6 + 3 * k], r[7 + 3 * k]);
                assert!(
                    (c - p - e).abs() <= 0.0015,
                    "following error = command - position within rounding: {r:?}"
                );
            }
        }
        // Every position read while moving lies on the trace's measured path (between two of its
        // rows, 4 ms apart), in the order of the trace.
        let act: Vec<[f64; 3]> = trace.iter().map(|r| [r[4], r[5], r[6]]).collect();
        let mut at = 0usize;
        let mut worst = 0.0f64;
        for r in &moving {
            let p = [r[5], r[8], r[11]];
            let (best, d) = (at..(at + 2000).min(act.len() - 1))
                .map(|i| (i, to_segment(&p, &act[i], &act[i + 1])))
                .fold((at, f64::INFINITY), |b, c| if c.1 < b.1 { c } else { b });
            assert!(
                d <= 0.002,
                "position {p:?} (image {}) is {d:.4} from the trace's path near row {best}",
                r[0]
            );
            worst = worst.max(d);
            at = best;
        }
        println!("largest distance from the trace's path: {worst:.4} (units)");
        // At rest again, mbpoll reads where the trace ends.
        let end = mbpoll_i32(a, 32, 12);
        let last = trace.last().expect("rows");
        for (k, v) in [end[0], end[4], end[8]].into_iter().enumerate() {
            assert!(
                (v as f64 / 1000.0 - last[4 + k]).abs() <= 0.0015,
                "axis {k}: {v} against the trace's {last:?}"
            );
        }
        up.down();
    });
}

#[test]
fn writes_over_modbus_drive_outputs_raise_the_estop_and_set_the_speed_and_a_lost_server_is_no_estop()
 {
    integration_tests::wall_clock(|| {
        let up = Up::default_cell("mb-write");
        let mut c = Raw::connect(address(&up));
        // Coil 1 is the gripper (an output); the sensor that follows it closes 80 ms later.
        assert_eq!(c.write_coil(1, true), Ok(vec![5, 0, 1, 0xFF, 0]));
        up.until_typed("gripper closed", |s| {
            s.io.as_ref().is_some_and(|io| {
                io.entries.get(1).and_then(|e| e.value()) == Some(1)
                    && io.entries.get(2).and_then(|e| e.value()) == Some(1)
            })
        });
        let bits = c.bits(2, 0, 5).expect("discrete inputs");
        assert_eq!(
            bits,
            [true, true, true, false, false],
            "estop_ok, gripper, closed"
        );
        assert_eq!(c.bits(1, 0, 5).expect("coils"), bits);
        // Inputs and addresses past the table are not writable; nothing changes.
        assert_eq!(c.write_coil(0, false), Err(ILLEGAL_ADDRESS));
        assert_eq!(c.write_coil(2, false), Err(ILLEGAL_ADDRESS));
        assert_eq!(c.write_coil(5, true), Err(ILLEGAL_ADDRESS));
        assert_eq!(
            c.registers(4, 0, 57),
            Err(ILLEGAL_ADDRESS),
            "56 input registers"
        );
        assert_eq!(c.registers(4, 0, 0), Err(ILLEGAL_VALUE));
        assert_eq!(c.registers(4, 0, 56).map(|r| r.len()), Ok(56));
        // Functions this server does not implement: a user-defined one, device identification,
        // function 23, 43 with another MEI type or a bad read code, codes of 128 and more:
        // each answered with exception 1 (tokio-modbus' decoder closed the connection on the
        // last four), on the same connection.
        for pdu in [
            &[0x41, 1, 2, 3][..],
            &[0x2B, 0x0E, 1, 0],
            &[0x17, 0, 0, 0, 1, 0, 0, 0, 1, 2, 0, 0],
            &[0x2B, 0x0D, 0],
            &[0x2B, 0x0E, 9, 0],
            &[0x85, 0],
            &[0xFF],
        ] {
            assert_eq!(c.ask(pdu), Some(Err(ILLEGAL_FUNCTION)), "{pdu:x?}");
        }
        assert_eq!(c.registers(4, 0, 1).map(|r| r.len()), Ok(1), "still served");
        // The speed override: 1..=100 %.
        assert_eq!(c.write_register(1, 0), Err(ILLEGAL_VALUE));
        assert_eq!(c.write_register(1, 101), Err(ILLEGAL_VALUE));
        assert_eq!(c.write_register(2, 1), Err(ILLEGAL_ADDRESS));
        assert!(c.write_register(1, 40).is_ok());
        let start = Instant::now();
        while c.registers(3, 1, 1) != Ok(vec![40]) {
            assert!(start.elapsed() < WATCHDOG, "the override never read back");
            std::thread::sleep(Duration::from_millis(20));
        }
        let s = up.status_typed();
        let program = s.program.as_ref().expect("trajgen's program");
        assert_eq!(program.speed_override, 0.4, "{s:?}");
        assert_eq!(s.supervisor.estop, None, "{s:?}");
        // The server is not critical: killed, it restarts without an e-stop.
        let pid = pid_of("modbus", &up.inst);
        nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(pid),
            nix::sys::signal::Signal::SIGKILL,
        )
        .expect("kill");
        let s = up.until_typed("modbus restarted", |s| {
            let m = process_of(s, "modbus");
            m.restarts == 1 && m.life == Life::Running
        });
        assert_eq!(s.supervisor.estop, None, "no e-stop: {s:?}");
        for p in ["drives", "servo", "trajgen", "iobridge"] {
            assert_eq!(process_of(&s, p).restarts, 0, "{p}: {s:?}");
        }
        assert!(arm_enabled(&s), "{s:?}");
        let mut c = Raw::connect(address(&up));
        // The outputs kept their values through it.
        assert_eq!(c.bits(1, 1, 1), Ok(vec![true]));
        // The e-stop register: 0 does nothing, 1 raises the e-stop, named after the client.
        assert!(c.write_register(0, 0).is_ok());
        assert_eq!(c.write_register(0, 2), Err(ILLEGAL_VALUE));
        assert_eq!(c.registers(3, 0, 2), Ok(vec![0, 40]));
        assert!(c.write_register(0, 1).is_ok());
        let s = up.until_typed("e-stop latched", latched);
        let e = estop_of(&s);
        assert_eq!(
            (e.origin, e.code, e.source.as_str()),
            (Origin::External, code::FIELDBUS_WRITE, "modbus"),
            "{s:?}"
        );
        // Named after the client: its address.
        let client = e
            .reason
            .strip_prefix("e-stop asked over Modbus by ")
            .and_then(|a| a.parse::<SocketAddr>().ok());
        assert!(client.is_some_and(|a| a.ip().is_loopback()), "{s:?}");
        up.until_typed("outputs safe", |s| {
            s.io.as_ref().and_then(|io| io.outputs_safe) == Some(true)
        });
        let start = Instant::now();
        while c.registers(3, 0, 1) != Ok(vec![1]) {
            assert!(start.elapsed() < WATCHDOG, "the e-stop never read back");
            std::thread::sleep(Duration::from_millis(20));
        }
        // outputs_safe (input register 29) reaches the server's snapshot with iobridge's image.
        let start = Instant::now();
        while c.registers(4, 29, 1) != Ok(vec![1]) {
            assert!(start.elapsed() < WATCHDOG, "outputs_safe never read 1");
            std::thread::sleep(Duration::from_millis(20));
        }
        assert_eq!(c.write_coil(4, true), Err(BUSY), "outputs held safe");
        up.done(&["reset"]);
        up.until_typed("e-stop clear", |s| !latched(s));
        up.down();
    });
}

#[test]
fn hostile_frames_too_many_clients_and_idle_ones_disturb_nothing() {
    integration_tests::wall_clock(|| {
        let test = "mb-hostile";
        let cfg = cell(
            test,
            &[
                ("modbus.max_connections", 2.into()),
                ("modbus.idle_timeout", 3.0.into()),
                ("modbus.writes", false.into()),
            ],
        );
        let up = Up::start(test, &cfg);
        let a = address(&up);
        // A program runs meanwhile (about 7 s); it must end as if nothing happened.
        let short = scratch(
            test,
            "short.prog",
            "MOVE(90, 40, 0)\nMOVE(40, 40, 0)\nEND\n",
        );
        let job = up.exec_in_background(&short);
        // The two places (the probe of `address` gives its place back once the server has
        // seen it close: until then a second client is one too many).
        let mut c1 = served(a);
        let mut c2 = served(a);
        // A third client is closed at once; so is a flood of them.
        for _ in 0..50 {
            let mut c = Raw::connect(a);
            assert!(c.closed(), "a connection beyond max_connections was served");
        }
        // Writes are off: exception 1, nothing changes.
        assert_eq!(c1.write_coil(1, true), Err(ILLEGAL_FUNCTION));
        assert_eq!(c1.write_register(0, 1), Err(ILLEGAL_FUNCTION));
        // Garbage: a frame longer than any Modbus frame, bytes that are no frame at all, and a
        // write of 16 coils with one data byte (it crashes tokio-modbus 0.17's decoder,
        // slowtec/tokio-modbus#298): each closes its connection at once, long before the idle
        // timeout (3 s), and the server goes on.
        let t = Instant::now();
        c1.s.write_all(&[0, 1, 0, 0, 0xFF, 0xFF, 1, 4])
            .expect("send");
        assert!(c1.closed(), "a 65535-byte frame was not refused");
        c2.s.write_all(&[0xFF; 300]).expect("send");
        assert!(c2.closed(), "garbage was not refused");
        let mut c4 = Raw::connect(a);
        c4.s.write_all(&[0, 1, 0, 0, 0, 8, 1, 0x0F, 0, 0, 0, 16, 1, 0xFF])
            .expect("send");
        assert!(c4.closed(), "a short coil write was not refused");
        let refused_in = t.elapsed();
        // Their places are free again; an idle client is closed after idle_timeout.
        let mut c3 = served(a);
        // The short coil write would have aborted the server without the frame check.
        assert_eq!(
            process_of(&up.status_typed(), "modbus").restarts,
            0,
            "the server crashed"
        );
        println!("three malformed frames refused in {refused_in:?}");
        // Read until the server closes it (or the watchdog ends the wait).
        c3.s.set_read_timeout(Some(WATCHDOG)).expect("timeout");
        assert!(c3.closed(), "an idle client kept its connection");
        // Nothing else noticed.
        let out = job.wait_with_output().expect("exec");
        let report: RunReport = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
            panic!(
                "not a completed run's report ({e}): {}",
                String::from_utf8_lossy(&out.stdout)
            )
        });
        assert!(report.ok, "{report:?}");
        let s = up.status_typed();
        assert_eq!(s.supervisor.estop, None, "{s:?}");
        for p in ["drives", "servo", "trajgen", "iobridge", "modbus"] {
            assert_eq!(process_of(&s, p).restarts, 0, "{p}: {s:?}");
        }
        up.down();
    });
}

#[test]
fn the_register_map_document_is_the_codes() {
    integration_tests::wall_clock(|| {
        let cell = cell_config::Config::default_cell().to_shm();
        let map = modbus::map::markdown(&cell);
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/fieldbus.md");
        let doc = std::fs::read_to_string(&path).unwrap_or_default();
        const BEGIN: &str = "<!-- register map: generated by the test the_register_map_document_is_the_codes; BLESS=1 regenerates -->\n";
        const END: &str = "<!-- end of the register map -->\n";
        let (before, rest) = doc.split_once(BEGIN).unwrap_or((&doc, ""));
        let after = rest.split_once(END).map_or("", |(_, a)| a);
        let want = format!("{before}{BEGIN}{map}{END}{after}");
        if std::env::var_os("BLESS").is_some() {
            std::fs::write(&path, &want).expect("write docs/fieldbus.md");
            return;
        }
        assert!(
            doc == want,
            "docs/fieldbus.md's register map differs from the code: BLESS=1 cargo test -p integration-tests the_register_map"
        );
    });
}
