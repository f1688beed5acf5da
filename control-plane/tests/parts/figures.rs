use control_plane::figures::*;
use shm_schema::LatencyHistogramV1;

#[test]
fn latency_bins_keep_every_sample_and_join_up() {
    let mut h = LatencyHistogramV1::new();
    let samples: Vec<u64> = (0..5000u64)
        .map(|i| 12_000 + (i * 7919) % 40_000)
        .chain([150, 2_500_000, 9_000_000])
        .collect();
    for &s in &samples {
        h.record(s);
    }
    let bins = latency_bins(&h);
    let total: u64 = bins.iter().map(|b| b.2).sum();
    assert_eq!(total, samples.len() as u64);
    for s in &samples {
        let us = *s as f64 * 1e-3;
        let n = bins.iter().filter(|b| b.0 <= us && us < b.1).count();
        assert_eq!(n, 1, "sample {us} µs in {n} bins");
    }
    // Ascending, never overlapping; neighbours with samples share their bound.
    for w in bins.windows(2) {
        assert!(w[0].1 <= w[1].0, "{w:?}");
    }
    assert!(bins.windows(2).any(|w| w[0].1 == w[1].0));
    // 1/8 of an octave: 1/8 of the octave's start wide.
    let b = bins.iter().find(|b| b.0 > 16.0).expect("a body bin");
    let octave_us = 2f64.powf((b.0 * 1e3).log2().floor()) * 1e-3;
    assert!((b.1 - b.0 - octave_us / 8.0).abs() < 1e-9, "{b:?}");
}
