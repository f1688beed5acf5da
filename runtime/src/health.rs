//! Seed 002's health detectors, run by the runtime in every process' cycle.
//!
//! Each detector is a leaky bucket (seed 002, "overrun detector"): every overrun adds one
//! count, one count leaks out per leak time, and the detector expires when the count reaches
//! `percent_limit` % of the process' rate (cycles per second): with a 1 kHz process and
//! `pending_sequence_overrun_percent_limit = 1`, 10 counts. A detector with a start snooze
//! ignores overruns for that long after the process starts and after every reset.
//!
//! What counts, in this framework (`docs/operations.md`):
//! - **pending sequence**: a sample that did not reach its consumer by the consumer's next
//!   cycle: a cycle in which a consumer finds nothing new from a producer whose period has
//!   passed (servo from trajgen and from the drives, the drives from servo, iobridge from
//!   servo; the task reports these), and each period the process itself skipped (its own
//!   outputs missed that many syncs: a stalled iobridge is a gap in the fieldbus image);
//! - **transport**: an IPC call that failed (a loan, a send, a receive; [`crate::ipc`] counts
//!   every one of them), and what a task counts of its own transport (the EtherCAT bus
//!   process: a frame lost, a working counter not the expected one);
//! - **thread offset variance**: a cycle that woke later than `thread_offset_variance_percent`
//!   % of its period after its deadline.

use shm_schema::{DetectorV1, HealthConfigV1};

/// One leaky bucket.
#[derive(Clone, Copy, Debug)]
pub struct LeakyBucket {
    level: f64,
    limit: f64,
    leak_ns: u64,
    last_leak_ns: u64,
    snooze_ns: u64,
    snoozed_until_ns: u64,
    total: u64,
}

impl LeakyBucket {
    /// A bucket expiring at `percent_limit` % of `rate_hz` counts, leaking one count per
    /// `leak_time_s`, snoozed for `snooze_s` from `now_ns`.
    pub fn new(
        percent_limit: f64,
        leak_time_s: f64,
        snooze_s: f64,
        rate_hz: f64,
        now_ns: u64,
    ) -> Self {
        let mut b = Self {
            level: 0.0,
            limit: percent_limit * 0.01 * rate_hz,
            leak_ns: (leak_time_s * 1e9) as u64,
            last_leak_ns: now_ns,
            snooze_ns: (snooze_s * 1e9) as u64,
            snoozed_until_ns: 0,
            total: 0,
        };
        b.restart(now_ns);
        b
    }

    /// Empties the bucket and snoozes it again (after a reset).
    pub fn restart(&mut self, now_ns: u64) {
        self.level = 0.0;
        self.last_leak_ns = now_ns;
        self.snoozed_until_ns = now_ns.saturating_add(self.snooze_ns);
    }

    /// Counts `n` overruns at `now_ns` (after leaking what the time since the last leak
    /// allows); true when the bucket has expired.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn add(&mut self, now_ns: u64, n: u64) -> bool {
        if self.leak_ns > 0 && now_ns > self.last_leak_ns {
            let leaks = (now_ns - self.last_leak_ns) / self.leak_ns;
            if leaks > 0 {
                self.level = (self.level - leaks as f64).max(0.0);
                self.last_leak_ns += leaks * self.leak_ns;
            }
        }
        self.total += n;
        if now_ns < self.snoozed_until_ns {
            return false;
        }
        self.level += n as f64;
        self.expired()
    }

    /// True when the count has reached the limit.
    pub fn expired(&self) -> bool {
        self.level >= self.limit && self.limit > 0.0
    }

    /// The detector as a status reports it (limit 0 while snoozed).
    pub fn report(&self, now_ns: u64) -> DetectorV1 {
        DetectorV1 {
            level: self.level as f32,
            limit: if now_ns < self.snoozed_until_ns {
                0.0
            } else {
                self.limit as f32
            },
            total: self.total,
        }
    }
}

/// Which detector expired.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Detector {
    /// `pending_sequence_overrun`.
    PendingSequence,
    /// `transport_overrun`.
    Transport,
    /// `thread_offset_variance`.
    ThreadOffset,
}

impl Detector {
    /// The seed's name of the detector.
    pub fn name(self) -> &'static str {
        match self {
            Self::PendingSequence => "pending_sequence_overrun",
            Self::Transport => "transport_overrun",
            Self::ThreadOffset => "thread_offset_variance",
        }
    }
}

/// The three detectors of one process.
#[derive(Clone, Copy, Debug)]
pub struct Health {
    /// Pending-sequence overruns.
    pub pending: LeakyBucket,
    /// Transport overruns.
    pub transport: LeakyBucket,
    /// Thread offset variance overruns.
    pub offset: LeakyBucket,
    offset_limit_ns: u64,
}

impl Health {
    /// The detectors of a process of period `period_ns`, configured by `cfg`, started at
    /// `now_ns`.
    pub fn new(cfg: &HealthConfigV1, period_ns: u64, now_ns: u64) -> Self {
        let rate = 1e9 / period_ns.max(1) as f64;
        Self {
            pending: LeakyBucket::new(
                cfg.pending_sequence_overrun_percent_limit,
                cfg.pending_sequence_overrun_leak_time_s,
                cfg.pending_sequence_overrun_start_snooze_s,
                rate,
                now_ns,
            ),
            transport: LeakyBucket::new(
                cfg.transport_overrun_percent_limit,
                cfg.transport_overrun_leak_time_s,
                0.0,
                rate,
                now_ns,
            ),
            offset: LeakyBucket::new(
                cfg.thread_offset_variance_overrun_percent_limit,
                cfg.thread_offset_variance_overrun_leak_time_s,
                cfg.thread_offset_variance_start_snooze_s,
                rate,
                now_ns,
            ),
            offset_limit_ns: (cfg.thread_offset_variance_percent * 0.01 * period_ns as f64) as u64,
        }
    }

    /// Empties and snoozes every detector (after a reset).
    pub fn restart(&mut self, now_ns: u64) {
        self.pending.restart(now_ns);
        self.transport.restart(now_ns);
        self.offset.restart(now_ns);
    }

    /// One cycle's overruns; the first detector that expired, if any.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn cycle(
        &mut self,
        now_ns: u64,
        wakeup_latency_ns: u64,
        pending: u64,
        transport: u64,
    ) -> Option<Detector> {
        let late = u64::from(wakeup_latency_ns > self.offset_limit_ns);
        let p = self.pending.add(now_ns, pending);
        let t = self.transport.add(now_ns, transport);
        let o = self.offset.add(now_ns, late);
        if p {
            Some(Detector::PendingSequence)
        } else if t {
            Some(Detector::Transport)
        } else if o {
            Some(Detector::ThreadOffset)
        } else {
            None
        }
    }

    /// The bucket of detector `d`.
    pub fn bucket(&self, d: Detector) -> &LeakyBucket {
        match d {
            Detector::PendingSequence => &self.pending,
            Detector::Transport => &self.transport,
            Detector::ThreadOffset => &self.offset,
        }
    }

    /// The wake-up latency beyond which a cycle counts as a thread offset overrun (ns).
    pub fn offset_limit_ns(&self) -> u64 {
        self.offset_limit_ns
    }
}

/// A consumer's watch on one producer's samples: how many of the producer's periods passed
/// without a new sample (seed 002's pending sequence overruns on that link).
#[derive(Clone, Copy, Debug, Default)]
pub struct Freshness {
    period_ns: u64,
    /// Producer stamp of the newest sample seen.
    newest_ns: u64,
    /// Periods after `newest_ns` already counted.
    counted: u64,
}

impl Freshness {
    /// A link whose producer publishes every `period_ns`.
    pub fn new(period_ns: u64) -> Self {
        Self {
            period_ns: period_ns.max(1),
            newest_ns: 0,
            counted: 0,
        }
    }

    /// At the consumer's cycle at `now_ns`, with the stamp of the newest sample it has
    /// (`None` before the first): the overruns to count now, one per producer period that
    /// ended more than a period ago without a new sample. The producer's first sample starts
    /// the watch.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn check(&mut self, now_ns: u64, newest_stamp_ns: Option<u64>) -> u64 {
        let Some(stamp) = newest_stamp_ns else {
            return 0;
        };
        if stamp != self.newest_ns {
            self.newest_ns = stamp;
            self.counted = 0;
            return 0;
        }
        // A sample stamped at `stamp` is followed by one stamped `stamp + period`, published
        // before the consumer's cycle after that: late by a whole period when older than two.
        let missed = now_ns.saturating_sub(stamp) / self.period_ns;
        let overdue = missed.saturating_sub(1);
        let new = overdue.saturating_sub(self.counted);
        self.counted = self.counted.max(overdue);
        new
    }
}
