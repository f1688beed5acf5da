//! The supervisor's command line itself (what each command does is tested on a running cell
//! by the integration tests, `tests/`).

use std::process::Command;

fn supervisor(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_supervisor"))
        .args(args)
        .output()
        .expect("the supervisor's program");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).to_string(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

/// Every command the README and docs/operations.md teach is listed by `--help` and has a help
/// of its own; an unknown command or option is refused by name with exit 2, and nothing runs.
#[test]
fn every_command_has_help_and_a_wrong_one_is_refused_by_name() {
    let (code, help, _) = supervisor(&["--help"]);
    assert_eq!(code, Some(0));
    let commands = [
        "run",
        "web",
        "record",
        "up",
        "down",
        "exec",
        "speed",
        "check",
        "pause",
        "resume",
        "abort",
        "reset",
        "start",
        "restart",
        "swap",
        "check-config",
        "default-config",
        "status",
        "latency",
        "tune",
        "events",
        "inject",
        "estop",
        "io",
    ];
    for c in commands {
        assert!(
            help.lines().any(|l| l.trim_start().starts_with(c)),
            "`supervisor --help` does not list {c}:\n{help}"
        );
        let (code, text, err) = supervisor(&[c, "--help"]);
        assert_eq!(code, Some(0), "supervisor {c} --help: {err}");
        assert!(
            text.contains("Usage: supervisor"),
            "supervisor {c} --help:\n{text}"
        );
    }
    // The hidden hop of `supervisor latency` is not offered to users.
    assert!(!help.contains("latency-peer"), "{help}");
    let (code, _, err) = supervisor(&["frobnicate"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("frobnicate"), "{err}");
    let (code, _, err) = supervisor(&["status", "--bogus"]);
    assert_eq!(code, Some(2));
    assert!(err.contains("--bogus"), "{err}");
    // `--instance` beside a command's own arguments parses (it once shared `io`'s NAME).
    let none = format!("cli{}", std::process::id());
    for args in [
        &["io", "gripper", "1", "--instance", &none][..],
        &["swap", "trajgen", "--instance", &none],
        &["inject", "--axis", "x", "encoder-loss", "--instance", &none],
    ] {
        let (_, _, err) = supervisor(args);
        assert!(!err.contains("Usage:"), "{args:?} did not parse:\n{err}");
        assert!(
            err.contains(&none),
            "{args:?} did not reach instance {none}:\n{err}"
        );
    }
}
