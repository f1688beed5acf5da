//! Readiness on `NOTIFY_SOCKET` (`runtime::notify`).

use runtime::notify::ready_on;
use std::os::unix::net::UnixDatagram;

#[test]
fn ready_sends_its_datagram_to_the_socket_named() {
    let dir = std::env::temp_dir().join(format!("rtc-notify-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a directory");
    let path = dir.join("ready.sock");
    let _ = std::fs::remove_file(&path);
    let listener = UnixDatagram::bind(&path).expect("a socket");
    ready_on(path.as_os_str()).expect("said");
    let mut buf = [0u8; 32];
    listener
        .set_read_timeout(Some(std::time::Duration::from_secs(10)))
        .expect("a timeout");
    let n = listener.recv(&mut buf).expect("READY=1");
    assert_eq!(&buf[..n], b"READY=1");
    // A socket nobody binds: the error names it.
    let gone = dir.join("nobody.sock");
    let err = ready_on(gone.as_os_str()).expect_err("nobody there");
    assert!(err.contains(&*gone.to_string_lossy()), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
