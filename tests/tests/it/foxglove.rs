//! Foxglove live (`supervisor foxglove`) checked by the protocol's reference client, npm
//! `@foxglove/ws-protocol` (tests/web/foxglove_client.mjs): the channels it advertises are the
//! MCAP recorder's, topic by topic and schema by schema, their messages arrive with the
//! samples' time stamps, and what may not connect is refused with its reason.

use crate::drives::WATCHDOG;
use crate::up::Up;
use integration_tests::{
    exited, first_line, run_with_watchdog, scratch, succeeded_within, supervisor,
};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};

/// `node foxglove_client.mjs URL SECONDS ARGS`: its JSON.
fn client(url: &str, seconds: &str, args: &[&str]) -> Value {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("web");
    assert!(
        dir.join("node_modules/@foxglove/ws-protocol").exists(),
        "@foxglove/ws-protocol is not installed: `npm ci --prefix tests/web` (.ci/run does it)"
    );
    let out = succeeded_within(
        Command::new("node")
            .arg(dir.join("foxglove_client.mjs"))
            .args([url, seconds])
            .args(args),
        WATCHDOG,
    );
    serde_json::from_slice(&out.stdout).expect("the client's JSON")
}

#[test]
fn foxglove_sees_the_recorders_channels_live_and_only_from_where_it_may() {
    integration_tests::wall_clock(|| {
        let test = "foxglove";
        let up = Up::default_cell(test);
        // Killed if the test fails before it stops the server.
        let mut server = integration_tests::Reaped::spawn(
            supervisor()
                .args([
                    "foxglove",
                    "--instance",
                    &up.inst,
                    "--listen",
                    "127.0.0.1:0",
                ])
                .stdout(Stdio::piped())
                .stderr(Stdio::null()),
            "supervisor foxglove",
        );
        let said = first_line(&mut server);
        let url = said
            .trim()
            .rsplit(' ')
            .next()
            .filter(|u| u.starts_with("ws://"))
            .unwrap_or_else(|| panic!("no address in {said:?}"))
            .to_string();

        // The reference client: every channel advertised and subscribed, until servo's state
        // has come 101 times (60 s at most).
        let seen = client(&url, "60", &["--until", "/servo/state:101"]);
        assert_eq!(seen["protocol"], "foxglove.websocket.v1", "{seen}");
        assert_eq!(
            seen["serverInfo"]["capabilities"],
            serde_json::json!([]),
            "{seen}"
        );
        let channels = seen["channels"].as_array().expect("channels");
        // The recorder's channels, from a recording of the same cell read by PyPI's reader.
        let mcap = scratch(test, "cell.mcap", "");
        succeeded_within(
            supervisor()
                .args([
                    "record",
                    "--instance",
                    &up.inst,
                    "--duration",
                    "0.5",
                    "--out",
                ])
                .arg(&mcap),
            WATCHDOG,
        );
        let read = succeeded_within(
            Command::new("python3")
                .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("python/mcap_read.py"))
                .arg(&mcap),
            WATCHDOG,
        );
        let recorded: Value = serde_json::from_slice(&read.stdout).expect("mcap_read's JSON");
        let mut advertised: Vec<Value> = channels
            .iter()
            .map(|c| {
                serde_json::json!([
                    c["topic"],
                    c["schemaName"],
                    c["schemaEncoding"],
                    c["encoding"],
                    c["schema"]
                ])
            })
            .collect();
        advertised.sort_by_key(|c| c.to_string());
        let mut in_file = recorded["channels"].as_array().expect("channels").clone();
        in_file.sort_by_key(|c| c.to_string());
        assert_eq!(
            advertised, in_file,
            "the recorder's channels, schemas to the byte"
        );
        assert!(advertised.len() >= 20, "{advertised:?}");
        // Live: servo's state, with its own time stamp (the cell's clock: a virtual cell's
        // starts one second after the epoch) and the axes by name.
        let n = seen["counts"]["/servo/state"].as_u64().unwrap_or(0);
        assert!(n > 100, "{}", seen["counts"]);
        let first = &seen["first"]["/servo/state"];
        assert!(first["message"]["act_position"]["x"].is_number(), "{first}");
        let stamp: u64 = first["timestamp"]
            .as_str()
            .and_then(|t| t.parse().ok())
            .expect("a stamp");
        let epoch = runtime::vclock::EPOCH_NS;
        assert!(
            (epoch..epoch + 3_600_000_000_000).contains(&stamp),
            "{stamp}: not within the cell's first hour"
        );
        println!(
            "foxglove: {} channels, {n} /servo/state messages",
            advertised.len()
        );

        // Foxglove's own page may connect; a page of another site may not, nor a client that
        // does not speak the protocol.
        let app = client(
            &url,
            "60",
            &[
                "--origin",
                "https://app.foxglove.dev",
                "--until",
                "advertised",
            ],
        );
        assert!(
            app["refused"].is_null() && !app["channels"].as_array().expect("channels").is_empty(),
            "{app}"
        );
        let evil = client(
            &url,
            "60",
            &["--origin", "https://evil.example", "--until", "advertised"],
        );
        let why = evil["refused"].as_str().unwrap_or_default();
        assert!(
            why.starts_with("403") && why.contains("\"https://evil.example\" may not connect"),
            "{evil}"
        );
        let other = client(&url, "60", &["--protocol", "chat", "--until", "advertised"]);
        let why = other["refused"].as_str().unwrap_or_default();
        assert!(
            why.contains("ask for the subprotocol foxglove.websocket.v1"),
            "{other}"
        );

        // Beyond loopback only with a token.
        let open = run_with_watchdog(
            supervisor().args(["foxglove", "--instance", &up.inst, "--listen", "0.0.0.0:0"]),
            WATCHDOG,
        );
        assert!(
            exited(&open, 2).contains("shows the cell to the network: give --token"),
            "{open:?}"
        );

        nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(server.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        )
        .expect("stop the server");
        let out = integration_tests::wait_output(
            server.into_child(),
            WATCHDOG,
            "supervisor foxglove stops",
        );
        assert!(out.status.success(), "{out:?}");
        up.down();
    });
}
