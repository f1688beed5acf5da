use runtime::stall::*;
use std::time::Duration;

#[test]
fn a_gap_over_the_threshold_is_a_stall_with_its_split_and_close_beats_are_none() {
    let mut w = StallWatch::new(Duration::from_millis(50));
    assert_eq!(w.beat(), None, "no gap yet");
    std::thread::sleep(Duration::from_millis(120));
    let s = w.beat().expect("a 120 ms gap is over 50 ms");
    assert!(s.gap >= Duration::from_millis(120), "{s:?}");
    assert!(
        s.waiting_for_cpu.is_some(),
        "the kernel's run delay was read: {s:?}"
    );
    assert!(
        s.host_steal.is_some(),
        "the host's steal time was read: {s:?}"
    );
    assert!(s.cause().contains("waiting for a CPU"), "{}", s.cause());
    for _ in 0..100 {
        assert_eq!(w.beat(), None, "beats close together are no stall");
    }
}
