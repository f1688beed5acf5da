//! The periodic cycle: absolute deadlines, the CS9 overrun rule, cycle statistics.
//!
//! Deadlines sit on a grid `k * period + phase` of `CLOCK_MONOTONIC`, shared by every process
//! of a machine, so processes with related periods keep a fixed order within a period (the
//! phases of the configuration) and never drift against each other. The wait is one
//! `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`, as cyclictest's: the timer counts from
//! the deadline, not from the end of the work, so it covers all of the cycle's work
//! (seed 003's second fix).
//!
//! Overruns (seed 000 §4.2): when a cycle's work ends after the next deadline, that late cycle
//! has completed normally, the next period is skipped (as many as were missed), the overrun
//! flag is set for the next cycle and the overrun is counted.
//!
//! In a cell on the virtual clock ([`crate::vclock`]) the wait is the clock's grant instead:
//! the cycle runs at its deadline's virtual instant, never late, and its execution time is
//! measured on the CPU (`CLOCK_MONOTONIC`) but never makes it overrun.
//!
//! A task may ask for one extra wake-up before the next grid deadline
//! ([`CycleClock::request_wake_at`]); trajgen uses it to read its next command at exactly
//! `t = T1 - t_acc` and to end a motion at its exact end time.

use crate::time::{now_ns, wall_ns};
use crate::vclock::Participant;
use shm_schema::{CycleStatsV1, LatencyHistogramV1};

/// One wake-up of the cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Wake {
    /// The deadline the cycle slept until (ns).
    pub planned_ns: u64,
    /// When it actually ran (ns).
    pub actual_ns: u64,
    /// The previous cycle overran (CS9 overrun flag).
    pub overrun_flag: bool,
    /// A grid deadline (false for a requested extra wake-up).
    pub on_grid: bool,
}

impl Wake {
    /// Wake-up latency, actual minus planned (ns).
    pub fn latency_ns(&self) -> u64 {
        self.actual_ns.saturating_sub(self.planned_ns)
    }
}

/// Why a wait returned without a wake-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WaitError {
    /// A signal interrupted the sleep (check [`crate::signals::stop_requested`]).
    Interrupted,
    /// `clock_nanosleep` failed with this errno.
    Os(i32),
}

/// Periodic absolute-deadline clock of one process.
#[derive(Debug)]
pub struct CycleClock {
    period_ns: u64,
    phase_ns: u64,
    next_ns: u64,
    extra_ns: Option<u64>,
    overrun_pending: bool,
    stats: CycleStatsV1,
    // Boxed: 30 KB each, allocated once by `new`, never resized.
    histogram: Box<LatencyHistogramV1>,
    exec_histogram: Box<LatencyHistogramV1>,
    /// On the virtual clock: the process' side of it, and the wall time of the last grant.
    virtual_clock: Option<(Participant, u64)>,
}

impl CycleClock {
    /// A clock whose first deadline is the first grid point at least one period after `now`.
    ///
    /// # Panics
    /// If `period_ns` is 0 (the configuration is validated long before this).
    pub fn new(period_ns: u64, phase_ns: u64, now: u64) -> Self {
        assert!(period_ns > 0, "cycle period must be positive");
        let phase_ns = phase_ns % period_ns;
        let mut clock = Self {
            period_ns,
            phase_ns,
            next_ns: 0,
            extra_ns: None,
            overrun_pending: false,
            stats: CycleStatsV1 {
                period_ns,
                ..CycleStatsV1::default()
            },
            histogram: Box::new(LatencyHistogramV1::new()),
            exec_histogram: Box::new(LatencyHistogramV1::new()),
            virtual_clock: None,
        };
        clock.next_ns = clock.grid_after(now + period_ns);
        clock
    }

    /// Waits on the virtual clock `participant` from now on: joins it with the first deadline.
    pub fn on_virtual_clock(&mut self, mut participant: Participant) {
        participant.join(self.upcoming().0);
        self.virtual_clock = Some((participant, 0));
    }

    /// Leaves the virtual clock, if on it (the process exits).
    pub fn leave(&mut self) {
        if let Some((p, _)) = self.virtual_clock.as_mut() {
            p.leave();
        }
        self.virtual_clock = None;
    }

    /// First grid deadline strictly after `t`.
    fn grid_after(&self, t: u64) -> u64 {
        let base = t.saturating_sub(self.phase_ns);
        (base / self.period_ns + 1) * self.period_ns + self.phase_ns
    }

    /// The next grid deadline (ns).
    pub fn next_deadline_ns(&self) -> u64 {
        self.next_ns
    }

    /// Statistics so far.
    pub fn stats(&self) -> &CycleStatsV1 {
        &self.stats
    }

    /// Wake-up latency of every cycle so far (its `stamp_ns` is the latest wake-up).
    pub fn histogram(&self) -> &LatencyHistogramV1 {
        &self.histogram
    }

    /// Execution time (wake-up to end of work) of every finished cycle so far.
    pub fn exec_histogram(&self) -> &LatencyHistogramV1 {
        &self.exec_histogram
    }

    /// Asks for one extra wake-up at `t` if it falls before the next grid deadline (and after
    /// now). Cleared when it has happened.
    ///
    /// # Real-time
    /// No allocation, no system call.
    pub fn request_wake_at(&mut self, t: u64) {
        if t < self.next_ns {
            self.extra_ns = Some(self.extra_ns.map_or(t, |e| e.min(t)));
        }
    }

    /// The deadline the next [`Self::wait`] sleeps until, and whether it is on the grid.
    pub fn upcoming(&self) -> (u64, bool) {
        match self.extra_ns {
            Some(e) if e < self.next_ns => (e, false),
            _ => (self.next_ns, true),
        }
    }

    /// Blocks until the next deadline.
    ///
    /// # Real-time
    /// The cycle's one blocking wait: one `clock_nanosleep`, one vDSO clock read.
    pub fn wait(&mut self) -> Result<Wake, WaitError> {
        let (deadline, on_grid) = self.upcoming();
        if let Some((p, woke_wall)) = self.virtual_clock.as_mut() {
            let now = p.wait(deadline);
            *woke_wall = wall_ns();
            return Ok(self.woke(deadline, on_grid, now));
        }
        let ts = libc::timespec {
            tv_sec: (deadline / 1_000_000_000) as libc::time_t,
            tv_nsec: (deadline % 1_000_000_000) as libc::c_long,
        };
        // SAFETY: valid timespec; no remaining-time output with TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        match rc {
            0 => Ok(self.woke(deadline, on_grid, now_ns())),
            libc::EINTR => Err(WaitError::Interrupted),
            e => Err(WaitError::Os(e)),
        }
    }

    /// Records a wake-up at `actual` for `deadline` (the bookkeeping half of [`Self::wait`]):
    /// statistics and the latency histogram.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn woke(&mut self, deadline: u64, on_grid: bool, actual: u64) -> Wake {
        let wake = Wake {
            planned_ns: deadline,
            actual_ns: actual,
            overrun_flag: self.overrun_pending,
            on_grid,
        };
        self.overrun_pending = false;
        if on_grid {
            self.next_ns = deadline + self.period_ns;
        }
        if self.extra_ns.is_some_and(|e| e <= deadline) {
            self.extra_ns = None;
        }
        let s = &mut self.stats;
        s.cycles += 1;
        s.wakeup_latency_ns = wake.latency_ns();
        s.max_wakeup_latency_ns = s.max_wakeup_latency_ns.max(s.wakeup_latency_ns);
        s.overrun_flag = wake.overrun_flag as u32;
        self.histogram.record(wake.latency_ns());
        self.histogram.stamp_ns = actual;
        wake
    }

    /// Ends the cycle that started with `wake`, its work finished at `end` (ns): records the
    /// execution time and applies the overrun rule.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn finish(&mut self, wake: &Wake, end: u64) {
        // On the virtual clock the work's time is measured on the CPU, and the cycle ends at
        // its own instant: it is late only when the clock granted it late (a scheduled hold).
        let (exec_ns, end) = match self.virtual_clock {
            Some((_, woke_wall)) => (wall_ns().saturating_sub(woke_wall), wake.actual_ns),
            None => (end.saturating_sub(wake.actual_ns), end),
        };
        let s = &mut self.stats;
        s.exec_ns = exec_ns;
        s.max_exec_ns = s.max_exec_ns.max(s.exec_ns);
        self.exec_histogram.record(s.exec_ns);
        self.exec_histogram.stamp_ns = end;
        if end > self.next_ns {
            // The late cycle completed; skip every period it ran into (CS9: the next cycle
            // is cancelled) and flag it for the next cycle.
            let resume = self.grid_after(end);
            self.stats.overruns += 1;
            self.stats.skipped += (resume - self.next_ns) / self.period_ns;
            self.next_ns = resume;
            self.overrun_pending = true;
        }
    }
}
