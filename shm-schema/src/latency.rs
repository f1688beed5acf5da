//! A fixed-size latency histogram: records in constant time without allocation, lives in
//! shared memory, and answers percentiles with a bounded relative error.
//!
//! # Buckets
//! Values are nanoseconds. Below 256 ns every value has its own bucket. Above, each power of
//! two `[2^e, 2^(e+1))` is cut into 128 equal buckets of width `2^(e-7)`, so a bucket is never
//! wider than 1/128 of its lowest value (0.8 %): 1 ns wide at 256 ns, 8 ns at 1 µs, 1 µs at
//! 128 µs, 128 µs at 16 ms. The last bucket ends at `2^35` ns (34 s); larger values are
//! counted in [`LatencyHistogramV1::overflows`]. The exact count, sum, minimum and maximum are
//! kept besides the buckets.
//!
//! # Percentiles
//! Nearest rank: the p-th percentile of `n` samples is the sample of rank `ceil(p·n)` in
//! ascending order. The histogram answers the highest value of that sample's bucket, clamped
//! to the exact minimum and maximum, so a reported percentile is never below the true one and
//! at most one bucket width (0.8 %) above it.

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Sub-buckets per power of two, as a power of two.
pub const SUB_BITS: u32 = 7;
const SUB: u64 = 1 << SUB_BITS;
/// Values at or above `1 << MAX_EXP` ns are overflows.
pub const MAX_EXP: u32 = 35;
/// Number of buckets.
pub const BUCKETS: usize = (2 * SUB + (MAX_EXP - SUB_BITS - 1) as u64 * SUB) as usize;

/// Wake-up latency histogram of one loop, published on `<i>/<role>/latency`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("rtc::LatencyHistogramV1")]
pub struct LatencyHistogramV1 {
    /// Samples recorded, overflows included.
    pub count: u64,
    /// Sum of every sample (ns, saturating).
    pub sum_ns: u64,
    /// Smallest sample (ns); 0 when empty.
    pub min_ns: u64,
    /// Largest sample (ns); 0 when empty.
    pub max_ns: u64,
    /// Samples of `2^35` ns or more (in no bucket).
    pub overflows: u64,
    /// When this copy was published (ns, `CLOCK_MONOTONIC`); 0 if never.
    pub stamp_ns: u64,
    /// Counts per bucket; see the module documentation for the bucket bounds.
    pub buckets: [u64; BUCKETS],
}

impl Default for LatencyHistogramV1 {
    fn default() -> Self {
        Self::new()
    }
}

/// The bucket of value `v` (ns), or `None` for an overflow.
#[inline]
pub const fn bucket_of(v: u64) -> Option<usize> {
    if v < 2 * SUB {
        return Some(v as usize);
    }
    let e = 63 - v.leading_zeros();
    if e >= MAX_EXP {
        return None;
    }
    let sub = (v >> (e - SUB_BITS)) - SUB;
    Some((2 * SUB + (e - SUB_BITS - 1) as u64 * SUB + sub) as usize)
}

/// The values bucket `i` holds: `(lowest, highest)` (ns, inclusive).
pub const fn bucket_bounds(i: usize) -> (u64, u64) {
    let i = i as u64;
    if i < 2 * SUB {
        return (i, i);
    }
    let k = i - 2 * SUB;
    let e = k / SUB + SUB_BITS as u64 + 1;
    let width = 1u64 << (e - SUB_BITS as u64);
    let low = (SUB + k % SUB) * width;
    (low, low + width - 1)
}

impl LatencyHistogramV1 {
    /// An empty histogram.
    pub const fn new() -> Self {
        Self {
            count: 0,
            sum_ns: 0,
            min_ns: 0,
            max_ns: 0,
            overflows: 0,
            stamp_ns: 0,
            buckets: [0; BUCKETS],
        }
    }

    /// Records one sample (ns).
    ///
    /// # Real-time
    /// Constant time, a few integer operations; no allocation.
    #[inline]
    pub fn record(&mut self, v: u64) {
        if self.count == 0 || v < self.min_ns {
            self.min_ns = v;
        }
        if v > self.max_ns {
            self.max_ns = v;
        }
        self.count += 1;
        self.sum_ns = self.sum_ns.saturating_add(v);
        match bucket_of(v) {
            Some(i) => self.buckets[i] += 1,
            None => self.overflows += 1,
        }
    }

    /// Adds every sample of `other`.
    pub fn merge(&mut self, other: &Self) {
        if other.count == 0 {
            return;
        }
        if self.count == 0 || other.min_ns < self.min_ns {
            self.min_ns = other.min_ns;
        }
        self.max_ns = self.max_ns.max(other.max_ns);
        self.count += other.count;
        self.sum_ns = self.sum_ns.saturating_add(other.sum_ns);
        self.overflows += other.overflows;
        for (a, b) in self.buckets.iter_mut().zip(other.buckets.iter()) {
            *a += b;
        }
    }

    /// Mean (ns), `None` when empty.
    pub fn mean_ns(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum_ns as f64 / self.count as f64)
    }

    /// The sample of 1-based `rank` in ascending order, to the bucket's highest value
    /// (clamped to the exact minimum and maximum). `None` when empty or `rank` is 0 or
    /// beyond the count. A rank among the overflows answers the maximum.
    pub fn value_at_rank(&self, rank: u64) -> Option<u64> {
        if rank == 0 || rank > self.count {
            return None;
        }
        let mut seen = 0u64;
        for (i, &c) in self.buckets.iter().enumerate() {
            seen += c;
            if seen >= rank {
                let (_, high) = bucket_bounds(i);
                return Some(high.clamp(self.min_ns, self.max_ns));
            }
        }
        Some(self.max_ns)
    }

    /// The `num/den` quantile by nearest rank (`percentile(99, 100)` is p99,
    /// `percentile(9999, 10000)` p99.99, `percentile(1, 2)` the median). `None` when empty.
    pub fn percentile(&self, num: u64, den: u64) -> Option<u64> {
        if den == 0 || num > den {
            return None;
        }
        let n = self.count as u128 * num as u128;
        let rank = n.div_ceil(den as u128).max(1) as u64;
        self.value_at_rank(rank)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_value_falls_in_a_bucket_that_holds_it() {
        let mut v = 0u64;
        let mut prev = None;
        while v < (1u64 << MAX_EXP) {
            let i = bucket_of(v).expect("in range");
            let (lo, hi) = bucket_bounds(i);
            assert!(lo <= v && v <= hi, "{v} in bucket {i} = [{lo}, {hi}]");
            // Relative width bound: never wider than 1/128 of its lowest value (or 1 ns).
            assert!(hi - lo < (lo >> SUB_BITS).max(1), "bucket {i} too wide");
            if let Some(p) = prev {
                assert!(i >= p, "buckets are monotonic");
            }
            prev = Some(i);
            v = v * 17 / 16 + 1;
        }
        assert_eq!(bucket_of((1 << MAX_EXP) - 1), Some(BUCKETS - 1));
        assert_eq!(bucket_of(1 << MAX_EXP), None);
    }

    #[test]
    fn buckets_tile_the_range_without_gaps() {
        let mut next = 0u64;
        for i in 0..BUCKETS {
            let (lo, hi) = bucket_bounds(i);
            assert_eq!(lo, next, "bucket {i} starts where {} ended", i.max(1) - 1);
            assert_eq!(bucket_of(lo), Some(i));
            assert_eq!(bucket_of(hi), Some(i));
            next = hi + 1;
        }
        assert_eq!(next, 1 << MAX_EXP);
    }
}
