use runtime::health::*;
use shm_schema::HealthConfigV1;

const MS: u64 = 1_000_000;

#[test]
fn the_seed_example_expires_at_250_counts_and_leaks_one_per_leak_time() {
    // base_freq_hz 1000, percent_limit 25, leak 0.1 s: expires at 250 counts.
    let mut b = LeakyBucket::new(25.0, 0.1, 0.0, 1000.0, 0);
    for _ in 0..249 {
        assert!(!b.add(0, 1));
    }
    assert!(b.add(0, 1));
    let mut b = LeakyBucket::new(25.0, 0.1, 0.0, 1000.0, 0);
    assert!(!b.add(0, 249));
    // 100 ms later one count has leaked: one more does not expire it.
    assert!(!b.add(100 * MS, 1));
    assert!(b.add(100 * MS, 1));
}

#[test]
fn a_snoozed_detector_counts_nothing_until_the_snooze_ends() {
    let mut b = LeakyBucket::new(1.0, 0.25, 1.0, 1000.0, 0);
    assert!(!b.add(999 * MS, 1000));
    assert_eq!(b.report(999 * MS).limit, 0.0);
    assert_eq!(b.report(999 * MS).total, 1000);
    assert!(!b.add(1000 * MS, 9));
    assert!(b.add(1000 * MS, 1));
    b.restart(2000 * MS);
    assert!(!b.add(2500 * MS, 100));
}

#[test]
fn a_steady_rate_below_the_leak_never_expires() {
    // 3 overruns a second against 4 leaks a second, for an hour.
    let mut b = LeakyBucket::new(1.0, 0.25, 0.0, 1000.0, 0);
    for k in 0..3 * 3600u64 {
        assert!(!b.add(k * 1000 * MS / 3, 1), "expired after {k}");
    }
    // 5 a second expires.
    let mut b = LeakyBucket::new(1.0, 0.25, 0.0, 1000.0, 0);
    assert!((0..5 * 60u64).any(|k| b.add(k * 200 * MS, 1)));
}

#[test]
fn freshness_counts_producer_periods_without_a_sample() {
    let mut f = Freshness::new(4 * MS);
    assert_eq!(f.check(0, None), 0);
    assert_eq!(f.check(MS, Some(0)), 0);
    // Consumer at 1 kHz: the 4 ms producer's next sample is due by 8 ms.
    for t in 2..8 {
        assert_eq!(f.check(t * MS, Some(0)), 0, "at {t} ms");
    }
    assert_eq!(f.check(8 * MS, Some(0)), 1);
    assert_eq!(f.check(9 * MS, Some(0)), 0);
    assert_eq!(f.check(20 * MS, Some(0)), 3);
    assert_eq!(f.check(21 * MS, Some(20 * MS)), 0);
}

#[test]
fn a_late_wakeup_beyond_the_offset_share_counts() {
    let cfg = HealthConfigV1 {
        pending_sequence_overrun_percent_limit: 1.0,
        pending_sequence_overrun_leak_time_s: 0.25,
        transport_overrun_percent_limit: 0.5,
        transport_overrun_leak_time_s: 0.25,
        thread_offset_variance_percent: 10.0,
        thread_offset_variance_overrun_percent_limit: 5.0,
        thread_offset_variance_overrun_leak_time_s: 0.25,
        ..HealthConfigV1::default()
    };
    let mut h = Health::new(&cfg, MS, 0);
    assert_eq!(h.offset_limit_ns(), 100_000);
    for k in 0..49 {
        assert_eq!(h.cycle(k * 1000, 100_001, 0, 0), None);
    }
    assert_eq!(h.cycle(49_000, 100_001, 0, 0), Some(Detector::ThreadOffset));
    // 0.5 % of 1 kHz is 5 counts.
    assert_eq!(h.cycle(50_000, 0, 0, 5), Some(Detector::Transport));
}
