//! `supervisor web` in a real headless Chromium (Debian's `chromium`, driven by
//! `playwright-core` from npm: tests/web/drive.mjs): the page loads with no network but the
//! supervisor's, draws the robot where the cell says it is and follows a running program,
//! its e-stop button stops the cell, reset and start bring it back, and the page goes on
//! across the cell going down and coming up again. A screenshot is saved.

use crate::drives::WATCHDOG;
use crate::up::{Up, cell, moving};
use integration_tests::{exited, leftovers, scratch, supervisor};
use serde_json::Value;
use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, ChildStdout, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// The page in Chromium, one command and one JSON answer at a time.
pub(crate) struct Browser {
    child: Child,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
}

impl Browser {
    fn open(url: &str) -> (Self, Value) {
        Self::open_in(None, url)
    }

    /// The page at `url` in Chromium, run in network namespace `ns` when given; with the
    /// driver's first answer (ready, and the page's errors so far).
    pub(crate) fn open_in(ns: Option<&str>, url: &str) -> (Self, Value) {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("web");
        assert!(
            dir.join("node_modules/playwright-core").exists(),
            "playwright-core is not installed: `npm ci --prefix tests/web` (.ci/run does it)"
        );
        let mut child = match ns {
            Some(ns) => {
                let mut c = Command::new("ip");
                c.args(["netns", "exec", ns, "node"]);
                c
            }
            None => Command::new("node"),
        };
        let mut child = child
            .arg(dir.join("drive.mjs"))
            .arg(url)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("node");
        let stdin = child.stdin.take().expect("stdin");
        let stdout = BufReader::new(child.stdout.take().expect("stdout"));
        let mut b = Self {
            child,
            stdin,
            stdout,
        };
        let ready = b.answer();
        (b, ready)
    }

    fn answer(&mut self) -> Value {
        let mut line = String::new();
        self.stdout.read_line(&mut line).expect("read");
        assert!(!line.is_empty(), "the browser driver ended");
        serde_json::from_str(&line).expect("JSON from the driver")
    }

    pub(crate) fn ask(&mut self, cmd: &str) -> Value {
        writeln!(self.stdin, "{cmd}").expect("write");
        let a = self.answer();
        assert!(a["error"].is_null(), "{cmd}: {a}");
        a
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A `supervisor web`, stopped as a user stops it (SIGTERM: it lets go of the instance)
/// when dropped, so a failing test leaves no server behind either.
pub(crate) struct View(Child);

impl View {
    /// SIGTERM (unless it has ended), then its exit status once it has ended; killed if it is
    /// still running after the watchdog.
    fn stop(&mut self) -> std::io::Result<ExitStatus> {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(self.0.id() as i32),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
        let start = Instant::now();
        while matches!(self.0.try_wait(), Ok(None)) && start.elapsed() < WATCHDOG {
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.0.kill();
        self.0.wait()
    }
}

impl Drop for View {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

/// `supervisor web` of `inst` on a free loopback port, with `extra` arguments, its stderr to
/// `stderr`: the server and its address (`host:port`).
pub(crate) fn serve(inst: &str, extra: &[&str], stderr: Stdio) -> (View, String) {
    let mut web = supervisor()
        .args(["web", "--instance", inst, "--listen", "127.0.0.1:0"])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .expect("supervisor web");
    let line = integration_tests::first_line(&mut web);
    // "serving instance … on http://127.0.0.1:port/"
    let addr = line
        .split("http://")
        .nth(1)
        .and_then(|a| a.trim_end().strip_suffix('/'))
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_string();
    (View(web), addr)
}

/// The page at `addr` in Chromium ([`Browser::open`]), which must open without an error.
fn page(addr: &str) -> Browser {
    let (page, ready) = Browser::open(&format!("http://{addr}/"));
    assert_eq!(ready["errors"], serde_json::json!([]), "{ready}");
    page
}

/// Runs `program` on `up` and, once it moves, asks the page for `sample` (`sample N 5`: what
/// the page drew over N seconds, and on until 5 samples saw the program moving): the samples
/// taken while the program moved.
fn samples_while_moving(up: &Up, page: &mut Browser, program: &Path, sample: &str) -> Vec<Value> {
    up.ok(&["exec", program.to_str().expect("utf-8")]);
    up.until("moving", moving);
    let a = page.ask(sample);
    let samples: Vec<Value> = a["samples"]
        .as_array()
        .expect("samples")
        .iter()
        .filter(|s| s["state"] == 1)
        .cloned()
        .collect();
    assert!(samples.len() >= 5, "too few samples while moving: {a}");
    samples
}

#[test]
fn the_page_draws_the_running_cell_its_estop_button_stops_it_and_it_outlives_the_cell() {
    integration_tests::wall_clock(|| {
        let test = "web";
        let cfg = cell(test, &[]);
        let up = Up::start(test, &cfg);
        let inst = up.inst.clone();
        let (mut web, addr) = serve(&inst, &[], Stdio::inherit());
        let mut page = page(&addr);
        // A program: x from 40 to 140 mm and back; the drawn tool follows the measured position.
        let short = scratch(
            test,
            "short.prog",
            "MOVE(140, 40, 0)\nMOVE(40, 40, 0)\nEND\n",
        );
        let samples = samples_while_moving(&up, &mut page, &short, "sample 3 5");
        let xs: Vec<f64> = samples
            .iter()
            .map(|s| s["drawn"][0].as_f64().expect("drawn x"))
            .collect();
        for s in &samples {
            // Gantry: the tool is drawn at the measured joints (x, y).
            let (d, j) = (&s["drawn"], &s["joints"]);
            assert_eq!(d[0], j[0], "{s}");
            assert_eq!(d[1], j[1], "{s}");
        }
        for w in xs.windows(2) {
            assert!(w[1] >= w[0] - 1e-9, "x goes out to 140 mm: {xs:?}");
        }
        let moved = xs[xs.len() - 1] - xs[0];
        println!("drawn x moved {moved:.2} mm in {} samples", xs.len());
        assert!(
            moved > 1.0,
            "the drawn tool did not follow the program: {xs:?}"
        );
        // The path plot: the commanded tool (trajgen's own) along y = 40 mm from x = 40 to 140
        // (the program moves x only), the measured one within the following-error limit of
        // this cell (5 mm, room for the host's stalls: beyond it the cell faults) of that
        // segment; both drawn.
        let a = page.ask("until rtc.path.commanded.length > 10 && rtc.plotted.path > 0");
        assert!(a["held"].is_string(), "{a}");
        // Measured and commanded are the same motion, not two drawings: they go as far, once
        // the measured tool had time to get where the command was (a host stall can hold servo
        // back while trajgen runs on the other CPU: waited for, up to the driver's 60 s).
        let a = page.ask(
            "until (() => { const r = (p) => Math.max(...p.map(q => q[0])); \
         return Math.abs(r(rtc.path.measured) - r(rtc.path.commanded)) < 5; })()",
        );
        assert!(a["held"].is_string(), "{a}");
        let v =
        page.ask("eval ({path: rtc.path, latency: rtc.latency, plotted: rtc.plotted})")["value"]
            .clone();
        let points = |k: &str| -> Vec<(f64, f64)> {
            v["path"][k]
                .as_array()
                .expect("points")
                .iter()
                .map(|p| (p[0].as_f64().expect("x"), p[1].as_f64().expect("y")))
                .collect()
        };
        let (commanded, measured) = (points("commanded"), points("measured"));
        assert!(commanded.len() > 10 && measured.len() > 10, "{v}");
        for c in &commanded {
            assert!(
                (c.1 - 40.0).abs() < 1e-9 && (40.0..=140.0).contains(&c.0),
                "commanded {c:?}"
            );
        }
        for m in &measured {
            assert!(
                (m.1 - 40.0).abs() < 5.0 && (35.0..=145.0).contains(&m.0),
                "measured {m:?}"
            );
        }
        let reach = |p: &[(f64, f64)]| p.iter().map(|p| p.0).fold(f64::MIN, f64::max);
        println!(
            "path plot: {} points, x {:.1} .. {:.1} mm; reach: measured {:.2}, commanded {:.2} mm",
            commanded.len(),
            commanded.first().expect("a point").0,
            commanded.last().expect("a point").0,
            reach(&measured),
            reach(&commanded)
        );
        // The latency histograms: one per process of the cell, each with its samples.
        let status = up.status();
        let names: Vec<&String> = status["processes"]
            .as_object()
            .expect("processes")
            .keys()
            .collect();
        assert!(names.len() >= 4, "{status}");
        let hists = v["latency"].as_array().expect("latency histograms");
        for name in &names {
            let h = hists
                .iter()
                .find(|h| h["name"].as_str() == Some(name.as_str()))
                .unwrap_or_else(|| panic!("no histogram of {name}: {v}"));
            let in_bins: u64 = h["bins"]
                .as_array()
                .expect("bins")
                .iter()
                .map(|b| b[2].as_u64().expect("count"))
                .sum();
            // Every sample in a bin, or beyond the histogram's range (counted apart).
            let samples = h["samples"].as_u64().expect("samples");
            let beyond = h["overflows"].as_u64().expect("overflows");
            assert!(in_bins > 0 && in_bins + beyond == samples, "{name}: {h}");
        }
        assert_eq!(
            v["plotted"]["hist"].as_u64(),
            Some(hists.len() as u64),
            "{v}"
        );
        let shot = scratch(test, "web.png", "");
        page.ask(&format!("shot {}", shot.display()));
        assert!(
            std::fs::metadata(&shot).is_ok_and(|m| m.len() > 10_000),
            "screenshot"
        );
        println!("screenshot: {}", shot.display());
        // The e-stop button stops the cell, through the CLI's path.
        page.ask("click estop");
        let a = page.ask("until rtc.estop");
        assert!(a["banner"].as_str().unwrap_or("").contains("E-STOP"), "{a}");
        let s = up.until("e-stop latched", |s| !s["supervisor"]["estop"].is_null());
        let reason = s["supervisor"]["estop"]["reason"].as_str().unwrap_or("");
        assert!(reason.contains("web view"), "{s}");
        up.until("the job ended", |s| s["supervisor"]["job"].is_null());
        // Reset and start from the page.
        page.ask("click reset");
        page.ask("until !rtc.estop");
        page.ask("click start");
        page.ask("until rtc.last && rtc.last.enabled === true");
        // The cell goes down: the page says so; the web server lets go of the instance.
        up.ok(&["down"]);
        drop(up);
        page.ask("until !rtc.up");
        let start = Instant::now();
        while !leftovers(&inst).is_empty() {
            assert!(start.elapsed() < WATCHDOG, "left: {:?}", leftovers(&inst));
            std::thread::sleep(Duration::from_millis(100));
        }
        // It comes up again: the same page draws it again.
        let up = Up::start(test, &cfg);
        let frames = page.ask("until rtc.up && rtc.last && rtc.last.joints")["held"].clone();
        assert!(frames.is_string());
        let bye = page.ask("quit");
        assert_eq!(bye["errors"], serde_json::json!([]), "{bye}");
        drop(page);
        let status = web.stop().expect("web");
        assert!(status.success(), "web exited with {status}");
        up.down();
    });
}

/// Seed 004's five-bar (examples/five-bar.toml) in the page: its builder draws it without an
/// error, the tool it draws is the forward kinematics of the measured joints (computed here
/// with the `kinematics` crate, not the page's), and the commanded path stays in the
/// program's triangle.
#[test]
fn the_page_draws_the_five_bar_through_its_kinematics() {
    integration_tests::wall_clock(|| {
        let test = "web-fivebar";
        let src = std::fs::read_to_string(integration_tests::examples().join("five-bar.toml"))
            .expect("examples/five-bar.toml");
        let cfg = scratch(test, "cell.toml", &integration_tests::with_stall_room(&src));
        // The five-bar's parameters as the file gives them (`[kinematics]`: key = number).
        let doc: toml_edit::DocumentMut = src.parse().expect("five-bar.toml is TOML");
        let params: Vec<(String, f64)> = doc["kinematics"]
            .as_table()
            .expect("[kinematics]")
            .iter()
            .filter_map(|(k, v)| {
                let v = v.as_float().or_else(|| v.as_integer().map(|i| i as f64))?;
                Some((k.to_string(), v))
            })
            .collect();
        let params: Vec<(&str, f64)> = params.iter().map(|(k, v)| (k.as_str(), *v)).collect();
        assert_eq!(params.len(), 6, "{params:?}");
        let kin =
            kinematics::build("five-bar", &kinematics::Params(&params)).expect("the five-bar");
        let up = Up::start(test, &cfg);
        let (web, addr) = serve(&up.inst, &[], Stdio::inherit());
        let mut page = page(&addr);
        let hello = page.ask("eval rtc.hello.kinematics")["value"].clone();
        assert_eq!(hello, "five-bar");
        let prog = integration_tests::examples().join("five-bar.prog");
        let samples = samples_while_moving(&up, &mut page, &prog, "sample 2 5");
        for s in &samples {
            let q: Vec<f64> = s["joints"]
                .as_array()
                .expect("joints")
                .iter()
                .map(|v| v.as_f64().expect("joint"))
                .collect();
            let mut joints = [0.0; kinematics::MAX_JOINTS];
            joints[..q.len()].copy_from_slice(&q);
            let p = kin.axes_to_cartesian(&joints).expect("forward");
            for k in 0..2 {
                let drawn = s["drawn"][k].as_f64().expect("drawn");
                assert!((drawn - p[k]).abs() < 1e-6, "{s}: forward {p:?}");
            }
        }
        let a = page.ask("until rtc.path.commanded.length > 10 && rtc.plotted.path > 0");
        assert!(a["held"].is_string(), "{a}");
        let path = page.ask("eval rtc.path.commanded")["value"].clone();
        for p in path.as_array().expect("points") {
            let (x, y) = (p[0].as_f64().expect("x"), p[1].as_f64().expect("y"));
            // Start (-200, -150) and the corners P1..P3: the blend stays within their hull's box.
            assert!(
                (-236.0..=-159.0).contains(&x) && (-191.0..=-109.0).contains(&y),
                "({x}, {y})"
            );
        }
        let shot = scratch(test, "five-bar.png", "");
        page.ask(&format!("shot {}", shot.display()));
        println!("screenshot: {}", shot.display());
        let bye = page.ask("quit");
        assert_eq!(bye["errors"], serde_json::json!([]), "{bye}");
        drop(page);
        // The observer leaves first: `down` checks that nothing of the instance is left.
        drop(web);
        up.down();
    });
}

#[test]
fn web_refuses_a_network_address_without_a_token() {
    integration_tests::wall_clock(|| {
        let out = supervisor()
            .args(["web", "--instance", "nobody", "--listen", "0.0.0.0:0"])
            .output()
            .expect("web");
        assert!(exited(&out, 2).contains("--token"));
    });
}
