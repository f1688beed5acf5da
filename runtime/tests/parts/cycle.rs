use runtime::cycle::*;
use runtime::time::now_ns;

const P: u64 = 1_000_000;

#[test]
fn first_deadline_is_on_the_grid_with_phase() {
    let c = CycleClock::new(P, 250_000, 10 * P + 10);
    assert_eq!(c.next_deadline_ns(), 11 * P + 250_000);
}

#[test]
fn on_time_cycles_follow_the_grid() {
    let mut c = CycleClock::new(P, 0, 0);
    let d = c.next_deadline_ns();
    let w = c.woke(d, true, d + 20_000);
    assert_eq!(w.latency_ns(), 20_000);
    c.finish(&w, d + 100_000);
    assert_eq!(c.next_deadline_ns(), d + P);
    assert_eq!(c.stats().overruns, 0);
    assert_eq!(c.stats().exec_ns, 80_000);
    assert_eq!(c.exec_histogram().count, 1);
    assert_eq!(c.exec_histogram().max_ns, 80_000);
    assert!(!c.woke(d + P, true, d + P).overrun_flag);
    let h = c.histogram();
    assert_eq!((h.count, h.min_ns, h.max_ns), (2, 0, 20_000));
    assert_eq!(h.stamp_ns, d + P);
}

#[test]
fn an_overrun_completes_skips_the_next_period_and_sets_the_flag() {
    let mut c = CycleClock::new(P, 0, 0);
    let d = c.next_deadline_ns();
    let w = c.woke(d, true, d);
    // Work ran 1.5 periods: deadline d+P was missed, d+2P is the next one.
    c.finish(&w, d + P + P / 2);
    assert_eq!(c.stats().overruns, 1);
    assert_eq!(c.stats().skipped, 1);
    assert_eq!(c.next_deadline_ns(), d + 2 * P);
    let w2 = c.woke(d + 2 * P, true, d + 2 * P);
    assert!(w2.overrun_flag);
    assert_eq!(c.stats().overrun_flag, 1);
    c.finish(&w2, d + 2 * P + 10);
    assert!(!c.woke(d + 3 * P, true, d + 3 * P).overrun_flag);
}

#[test]
fn a_long_stall_skips_every_missed_period() {
    let mut c = CycleClock::new(P, 0, 0);
    let d = c.next_deadline_ns();
    let w = c.woke(d, true, d);
    c.finish(&w, d + 4 * P + 1);
    assert_eq!(c.stats().skipped, 4);
    assert_eq!(c.next_deadline_ns(), d + 5 * P);
}

#[test]
fn extra_wake_ups_come_before_the_grid_and_do_not_shift_it() {
    let mut c = CycleClock::new(P, 0, 0);
    let d = c.next_deadline_ns();
    c.request_wake_at(d - 300_000);
    c.request_wake_at(d - 200_000); // the earlier one wins
    assert_eq!(c.upcoming(), (d - 300_000, false));
    let w = c.woke(d - 300_000, false, d - 299_000);
    c.finish(&w, d - 290_000);
    assert_eq!(c.upcoming(), (d, true));
    c.request_wake_at(d + 5); // after the next grid deadline: ignored
    assert_eq!(c.upcoming(), (d, true));
}

#[test]
fn real_wait_sleeps_until_the_deadline() {
    let mut c = CycleClock::new(P, 0, now_ns());
    let w = c.wait().expect("sleep");
    assert!(w.actual_ns >= w.planned_ns);
}
