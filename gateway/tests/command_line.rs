//! gateway's command lines: the cell's process as the supervisor starts it, and the control
//! room's client refusing a line file it cannot use before it joins anything.

use std::process::Command;

const GATEWAY: &str = env!("CARGO_BIN_EXE_gateway");

#[test]
fn help_names_the_arguments_and_a_wrong_one_is_refused_by_name() {
    integration_tests::check_process_command_line(GATEWAY, "gateway");
}

/// `gateway line ARGS` with `RTC_LINE` unset: its exit code and stderr.
fn line(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(GATEWAY)
        .arg("line")
        .args(args)
        .env_remove("RTC_LINE")
        .output()
        .expect("gateway line");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_line_client_refuses_a_line_file_it_cannot_use_by_name() {
    let (code, err) = line(&["cells"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("no line file: give --line FILE"), "{err}");

    let dir = std::env::temp_dir().join(format!("rtc-gw-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch");
    let clear = dir.join("clear.toml");
    std::fs::write(&clear, "connect = [\"tcp/127.0.0.1:7447\"]\n").expect("write");
    let (code, err) = line(&["--line", clear.to_str().expect("path"), "cells"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("clear.toml: connect \"tcp/127.0.0.1:7447\" is in the clear"),
        "{err}"
    );

    let unknown = dir.join("unknown.toml");
    std::fs::write(&unknown, "conect = []\n").expect("write");
    let (code, err) = line(&["--line", unknown.to_str().expect("path"), "cells"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("unknown field `conect`"), "{err}");

    // A cell's name that could be a wildcard is refused before anything is sent.
    let ok = dir.join("ok.toml");
    std::fs::write(&ok, "connect = []\n").expect("write");
    let (code, err) = line(&["--line", ok.to_str().expect("path"), "pause", "*"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("is not a cell's name on the line"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
