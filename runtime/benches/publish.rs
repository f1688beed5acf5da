//! What a cycle pays to publish a latency histogram (30 KB) into shared memory, against a
//! process status (0.3 KB) published the same way, both from cold caches (a process publishes
//! its histograms every 100 ms: by then its other work has evicted them), alternately in the
//! same run; and a cycle's share of a histogram published a slice per cycle
//! (`runtime::snapshot::Snapshot`, as `runtime::process` does: 1/16 of it, the loan or the
//! send included), each slice from cold caches too.
//!
//! `cargo bench -p runtime --bench publish` prints the medians, the 99th percentiles and the
//! ratios.

use runtime::ipc::{self, Pub, Sub};
use runtime::snapshot::{MAX_SLICES, Snapshot};
use shm_schema::{InstanceName, LatencyHistogramV1, ProcessName, ProcessStatusV2, ServiceId};
use std::time::Instant;

const SENDS: usize = 2_000;

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// Touches 16 MB: whatever the caches held is gone.
fn evict(buffer: &mut [u8]) {
    for b in buffer.iter_mut().step_by(64) {
        *b = b.wrapping_add(1);
    }
}

fn main() {
    let instance = InstanceName::new(&format!("pubbench{}", std::process::id())).expect("name");
    let name = ProcessName::new("bench").expect("name");
    {
        let node = ipc::node(&instance, "bench").expect("node");
        let histogram_tx: Pub<LatencyHistogramV1> =
            Pub::new(&node, &instance, ServiceId::Latency(name)).expect("pub");
        let _histogram_rx: Sub<LatencyHistogramV1> =
            Sub::new(&node, &instance, ServiceId::Latency(name), 1).expect("sub");
        let status_tx: Pub<ProcessStatusV2> =
            Pub::new(&node, &instance, ServiceId::Status(name)).expect("pub");
        let _status_rx: Sub<ProcessStatusV2> =
            Sub::new(&node, &instance, ServiceId::Status(name), 1).expect("sub");
        let mut snapshot = Snapshot::new(&node, &instance, ServiceId::ExecTime(name), MAX_SLICES)
            .expect("snapshot");
        let _snapshot_rx: Sub<LatencyHistogramV1> =
            Sub::new(&node, &instance, ServiceId::ExecTime(name), 1).expect("sub");
        let mut h = LatencyHistogramV1::new();
        for k in 0..100_000u64 {
            h.record(5_000 + (k * 7919) % 200_000);
        }
        let mut status = ProcessStatusV2::default();
        let mut buffer = vec![0u8; 16 << 20];
        let (mut hist, mut stat) = (Vec::with_capacity(SENDS), Vec::with_capacity(SENDS));
        let mut slice = Vec::with_capacity(SENDS);
        for k in 0..SENDS {
            h.stamp_ns = k as u64;
            status.stamp_ns = k as u64;
            evict(&mut buffer);
            let t = Instant::now();
            assert!(histogram_tx.send(&h));
            hist.push(t.elapsed().as_secs_f64() * 1e6);
            evict(&mut buffer);
            let t = Instant::now();
            assert!(status_tx.send(&status));
            stat.push(t.elapsed().as_secs_f64() * 1e6);
            snapshot.begin();
            let v = 5_000 + (k as u64 * 7919) % 200_000;
            h.record(v);
            evict(&mut buffer);
            let t = Instant::now();
            snapshot.step(&h, v);
            slice.push(t.elapsed().as_secs_f64() * 1e6);
        }
        let (h50, h99) = (percentile(&mut hist, 0.5), percentile(&mut hist, 0.99));
        let (s50, s99) = (percentile(&mut stat, 0.5), percentile(&mut stat, 0.99));
        let (c50, c99) = (percentile(&mut slice, 0.5), percentile(&mut slice, 0.99));
        println!("publish from cold caches, {SENDS} times each, alternately (µs):");
        println!(
            "  a process status ({} B):       p50 {s50:.2}  p99 {s99:.2}",
            std::mem::size_of::<ProcessStatusV2>()
        );
        println!(
            "  a latency histogram ({} KB):  p50 {h50:.2}  p99 {h99:.2}",
            std::mem::size_of::<LatencyHistogramV1>() / 1024
        );
        println!("  a cycle's slice of one:        p50 {c50:.2}  p99 {c99:.2}");
        println!(
            "  ratio histogram/status:        p50 {:.1}  p99 {:.1}",
            h50 / s50,
            h99 / s99
        );
        println!(
            "  ratio slice/status:            p50 {:.1}  p99 {:.1}",
            c50 / s50,
            c99 / s99
        );
    }
    ipc::cleanup_after_client(&instance);
}
