//! The latency histogram against known samples: exact where buckets are 1 ns wide, within one
//! bucket (≤ 1/128) of the exact nearest-rank percentile elsewhere, never below it.

use shm_schema::LatencyHistogramV1;

/// Exact nearest-rank percentile of sorted samples.
fn exact(sorted: &[u64], num: u64, den: u64) -> u64 {
    let rank = (sorted.len() as u64 * num).div_ceil(den).max(1);
    sorted[rank as usize - 1]
}

fn hist_of(samples: &[u64]) -> Box<LatencyHistogramV1> {
    let mut h = Box::new(LatencyHistogramV1::new());
    for &s in samples {
        h.record(s);
    }
    h
}

const QUANTILES: [(u64, u64); 6] = [
    (1, 2),
    (9, 10),
    (99, 100),
    (999, 1000),
    (9999, 10000),
    (1, 1),
];

#[test]
fn small_values_are_exact() {
    let samples: Vec<u64> = (1..=100).collect();
    let h = hist_of(&samples);
    assert_eq!(h.count, 100);
    assert_eq!((h.min_ns, h.max_ns), (1, 100));
    assert_eq!(h.mean_ns(), Some(50.5));
    assert_eq!(h.percentile(1, 2), Some(50));
    assert_eq!(h.percentile(99, 100), Some(99));
    assert_eq!(h.percentile(999, 1000), Some(100));
    assert_eq!(h.percentile(1, 1), Some(100));
    assert_eq!(h.percentile(0, 1), Some(1), "p0 is the minimum");
}

#[test]
fn an_empty_histogram_has_no_percentiles() {
    let h = LatencyHistogramV1::new();
    assert_eq!(h.percentile(1, 2), None);
    assert_eq!(h.mean_ns(), None);
    assert_eq!(h.value_at_rank(1), None);
}

#[test]
fn a_known_latency_distribution() {
    // 10 000 wake-ups: 9 900 at 5 µs, 90 at 50 µs, 9 at 500 µs, 1 at 5 ms.
    let mut samples = vec![5_000u64; 9_900];
    samples.extend([50_000; 90]);
    samples.extend([500_000; 9]);
    samples.push(5_000_000);
    let h = hist_of(&samples);
    let within = |got: Option<u64>, want: u64| {
        let got = got.expect("non-empty");
        assert!(
            got >= want && got - want <= want / 128,
            "got {got}, want {want}"
        );
    };
    within(h.percentile(1, 2), 5_000);
    within(h.percentile(99, 100), 5_000);
    within(h.percentile(999, 1000), 50_000);
    within(h.percentile(9999, 10000), 500_000);
    assert_eq!(h.percentile(1, 1), Some(5_000_000));
    assert_eq!(h.max_ns, 5_000_000);
}

#[test]
fn random_samples_match_the_exact_percentiles_within_one_bucket() {
    let mut x = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for round in 0..20 {
        // Log-uniform from 1 ns to about 2^(10 + round) ns: covers exact and wide buckets.
        let bits = 10 + round;
        let mut samples: Vec<u64> = (0..5_000)
            .map(|_| {
                let r = next();
                (r >> (64 - bits)) >> (r % bits as u64)
            })
            .collect();
        let h = hist_of(&samples);
        samples.sort_unstable();
        assert_eq!(h.count, samples.len() as u64);
        assert_eq!(h.min_ns, samples[0]);
        assert_eq!(h.max_ns, *samples.last().expect("non-empty"));
        assert_eq!(h.sum_ns, samples.iter().sum::<u64>());
        for (num, den) in QUANTILES {
            let want = exact(&samples, num, den);
            let got = h.percentile(num, den).expect("non-empty");
            assert!(
                got >= want && got - want <= want / 128,
                "round {round}: p{num}/{den} got {got}, exact {want}"
            );
        }
    }
}

#[test]
fn merging_equals_recording_everything_in_one() {
    let a: Vec<u64> = (0..1000).map(|i| i * 977 % 100_000).collect();
    let b: Vec<u64> = (0..700).map(|i| 50 + i * 31_337 % 3_000_000).collect();
    let mut merged = hist_of(&a);
    merged.merge(&hist_of(&b));
    let mut all = a.clone();
    all.extend(&b);
    assert_eq!(*merged, *hist_of(&all));
    let mut into_empty = Box::new(LatencyHistogramV1::new());
    into_empty.merge(&hist_of(&b));
    assert_eq!(*into_empty, *hist_of(&b));
}

#[test]
fn huge_values_are_overflows_answered_by_the_maximum() {
    let mut h = hist_of(&[10, 20, 30]);
    h.record(100_000_000_000); // 100 s
    assert_eq!(h.overflows, 1);
    assert_eq!(h.count, 4);
    assert_eq!(h.percentile(1, 1), Some(100_000_000_000));
    assert_eq!(h.percentile(1, 2), Some(20));
}
