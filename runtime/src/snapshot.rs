//! A histogram published without copying all of it in one cycle.
//!
//! A [`LatencyHistogramV1`] is 30 KB. Copied whole into shared memory at each publication,
//! it cost its cycle about 2 µs from cold caches (`cargo bench -p runtime --bench publish`),
//! a periodic spike of the execution time. A [`Snapshot`] loans its sample once and copies a
//! slice of the buckets into it per cycle; a sample the histogram records meanwhile into a
//! bucket already copied is added to the copy as well, and the header (count, sum, minimum,
//! maximum, overflows, stamp) is written last: the sample sent is the histogram exactly as it
//! stood in the cycle that sends it.

use crate::ipc::{InstanceName, Ipc, ServiceId};
use crate::ipc::{IpcError, Node, Pub};
use shm_schema::LatencyHistogramV1;
use shm_schema::latency::{BUCKETS, bucket_of};

// Every byte of the structure is one of the fields written (no padding).
const _: () = assert!(core::mem::size_of::<LatencyHistogramV1>() == 8 * (6 + BUCKETS));

/// At most this many slices per snapshot (a slice of 232 buckets: 1.9 KB).
pub const MAX_SLICES: usize = 16;

/// How often a process publishes its latency histogram (at most; once per cycle if slower).
pub const LATENCY_PUBLISH_INTERVAL_NS: u64 = 100_000_000;

/// A histogram's publisher, one slice per cycle.
#[derive(Debug)]
pub struct Snapshot {
    port: Pub<LatencyHistogramV1>,
    /// Buckets copied per cycle.
    slice: usize,
    /// Buckets copied into the staged sample so far; `None`: no snapshot under way.
    copied: Option<usize>,
    /// The histogram's count when the last slice was copied.
    seen: u64,
    /// When [`Snapshot::step_every`] last began one (ns).
    begun_ns: u64,
}

impl Snapshot {
    /// A publisher of `id` whose snapshot takes `slices` cycles (1..=[`MAX_SLICES`]).
    pub fn new(
        node: &Node<Ipc>,
        instance: &InstanceName,
        id: ServiceId,
        slices: usize,
    ) -> Result<Self, IpcError> {
        Ok(Self {
            port: Pub::new(node, instance, id)?,
            slice: BUCKETS.div_ceil(slices.clamp(1, MAX_SLICES)),
            copied: None,
            seen: 0,
            begun_ns: 0,
        })
    }

    /// Starts a snapshot, unless one is under way.
    pub fn begin(&mut self) {
        if self.copied.is_none() {
            self.copied = Some(0);
        }
    }

    /// Whether a snapshot is under way (begun, not yet sent).
    pub fn copying(&self) -> bool {
        self.copied.is_some()
    }

    /// A cycle's share of a snapshot under way of `h`, whose latest sample is `last` (ns):
    /// the next slice, and the snapshot sent once whole (returns true then).
    ///
    /// # Real-time
    /// A copy of one slice and, at the end, the IPC send (the first slice's loan allocates
    /// once inside iceoryx2).
    pub fn step(&mut self, h: &LatencyHistogramV1, last: u64) -> bool {
        let Some(mut copied) = self.copied else {
            return false;
        };
        let Some(payload) = self.port.staged() else {
            // No sample to fill: the next publication tries again.
            self.copied = None;
            return false;
        };
        let dst = payload.as_mut_ptr();
        // SAFETY: `dst` points to a loaned payload we alone write; every bucket read back
        // (below `copied`) was written by an earlier slice.
        let buckets = unsafe { core::ptr::addr_of_mut!((*dst).buckets) }.cast::<u64>();
        // Wrapping: a histogram started afresh (fewer samples) restarts the copy below.
        match h.count.wrapping_sub(self.seen) {
            0 => {}
            // The one sample recorded since the last slice, in a bucket already copied.
            1 => {
                if let Some(b) = bucket_of(last).filter(|&b| b < copied) {
                    unsafe { *buckets.add(b) += 1 };
                }
            }
            // More than one (a slice missed): start the copy again.
            _ => copied = 0,
        }
        let end = (copied + self.slice).min(BUCKETS);
        // SAFETY: both ranges lie within `buckets` of their structure.
        unsafe {
            core::ptr::copy_nonoverlapping(
                h.buckets.as_ptr().add(copied),
                buckets.add(copied),
                end - copied,
            );
        }
        self.seen = h.count;
        if end < BUCKETS {
            self.copied = Some(end);
            return false;
        }
        // SAFETY: the header's fields written one by one; with the buckets, every byte
        // (the structure has no padding: `repr(C)`, all `u64`).
        unsafe {
            (*dst).count = h.count;
            (*dst).sum_ns = h.sum_ns;
            (*dst).min_ns = h.min_ns;
            (*dst).max_ns = h.max_ns;
            (*dst).overflows = h.overflows;
            (*dst).stamp_ns = h.stamp_ns;
        }
        self.copied = None;
        // SAFETY: every byte written above.
        unsafe { self.port.send_staged() }
    }

    /// [`Snapshot::step`], a snapshot begun at `now_ns` when `interval_ns` have passed since
    /// the last one began (the first at once).
    ///
    /// # Real-time
    /// As [`Snapshot::step`].
    pub fn step_every(
        &mut self,
        now_ns: u64,
        interval_ns: u64,
        h: &LatencyHistogramV1,
        last: u64,
    ) -> bool {
        if self.begun_ns == 0 || now_ns.saturating_sub(self.begun_ns) >= interval_ns {
            self.begin();
            self.begun_ns = now_ns;
        }
        self.step(h, last)
    }

    /// Publishes `h` whole at once (the last publication, out of the cycle).
    pub fn send_whole(&mut self, h: &LatencyHistogramV1) -> bool {
        self.copied = None;
        self.port.send(h)
    }
}

/// A drives process' sense-to-command latency (from the feedback a command was computed from
/// to the command's application): the histogram of every command applied since start and
/// its publisher on `ServiceId::SenseToCommand`, a slice per cycle.
#[derive(Debug)]
pub struct SenseToCommand {
    histogram: Box<LatencyHistogramV1>,
    out: Snapshot,
}

impl SenseToCommand {
    /// The publisher of `instance`'s sense-to-command latency (every drives process has one).
    pub fn new(node: &Node<Ipc>, instance: &InstanceName) -> Result<Self, IpcError> {
        Ok(Self {
            histogram: Box::default(),
            out: Snapshot::new(node, instance, ServiceId::SenseToCommand, MAX_SLICES)?,
        })
    }

    /// A cycle at `now_ns` that applied a command whose latency was `sample_ns` (`None`: no
    /// new command, or one not computed from feedback): recorded, and the histogram's
    /// publication stepped (one begun every `LATENCY_PUBLISH_INTERVAL_NS`).
    ///
    /// # Real-time
    /// A histogram record and [`Snapshot::step_every`].
    pub fn step(&mut self, now_ns: u64, sample_ns: Option<u64>) {
        if let Some(ns) = sample_ns {
            self.histogram.record(ns);
        }
        self.histogram.stamp_ns = now_ns;
        self.out.step_every(
            now_ns,
            LATENCY_PUBLISH_INTERVAL_NS,
            &self.histogram,
            sample_ns.unwrap_or(0),
        );
    }

    /// The last publication, whole, as the process stops at `now_ns`.
    pub fn finish(&mut self, now_ns: u64) {
        self.histogram.stamp_ns = now_ns;
        self.out.send_whole(&self.histogram);
    }
}
