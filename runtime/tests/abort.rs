//! `runtime::abort_on_panic`: the release profile unwinds (one build of the dependencies for
//! the binaries and the test harnesses), and every binary of the cell still dies of a panic,
//! by SIGABRT, even one in a thread whose `join` would have caught it.

use std::os::unix::process::ExitStatusExt;
use std::process::Command;

const CHILD: &str = "RTC_ABORT_ON_PANIC_CHILD";

#[test]
fn a_panic_in_any_thread_aborts_the_process() {
    if std::env::var_os(CHILD).is_some() {
        runtime::abort_on_panic();
        let joined = std::thread::spawn(|| panic!("a thread's panic")).join();
        // Unwinding would have come back here with the panic caught.
        println!("survived: {}", joined.is_err());
        std::process::exit(0);
    }
    let out = Command::new(std::env::current_exe().expect("the test binary"))
        .args([
            "--exact",
            "a_panic_in_any_thread_aborts_the_process",
            "--nocapture",
        ])
        .env(CHILD, "1")
        .output()
        .expect("the child");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.signal(),
        Some(libc::SIGABRT),
        "{:?}\n{stdout}\n{stderr}",
        out.status
    );
    assert!(!stdout.contains("survived"), "{stdout}");
    assert!(
        stderr.contains("a thread's panic"),
        "the message first: {stderr}"
    );
}
