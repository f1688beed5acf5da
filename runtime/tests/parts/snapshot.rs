use runtime::ipc::{self, Sub};
use runtime::snapshot::*;
use shm_schema::{InstanceName, LatencyHistogramV1, ProcessName, ServiceId};

/// Samples recorded while a snapshot is copied, into buckets copied before and after:
/// what is sent is the histogram as it stood in the cycle that sent it, to the bucket.
#[test]
fn a_snapshot_sent_is_the_histogram_as_it_stood_when_sent() {
    let instance = InstanceName::new(&format!("snap{}", std::process::id())).expect("name");
    {
        let node = ipc::node(&instance, "snapshot").expect("node");
        let id = ServiceId::Latency(ProcessName::new("servo").expect("name"));
        let sub = Sub::<LatencyHistogramV1>::new(&node, &instance, id, 1).expect("sub");
        let mut snap = Snapshot::new(&node, &instance, id, 5).expect("snapshot");
        let mut h = LatencyHistogramV1::new();
        // Low, high and overflowing values, so slices before and after each are hit.
        let mut x: u64 = 12345;
        let mut sample = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            match x >> 60 {
                0 => 1 << 36,
                k => (x >> 30) % (1 << (k + 20)),
            }
        };
        for round in 0..3 {
            // Samples before the snapshot, one per cycle during it (the first with it).
            for _ in 0..100 {
                h.record(sample());
            }
            snap.begin();
            let mut sent = false;
            let mut cycles = 0;
            while !sent {
                let v = sample();
                h.record(v);
                h.stamp_ns = 1000 + cycles;
                sent = snap.step(&h, v);
                cycles += 1;
            }
            assert_eq!(cycles, 5, "round {round}: a slice a cycle");
            let got = sub.latest().expect("a snapshot");
            assert_eq!(got, h, "round {round}");
            assert!(!snap.copying(), "round {round}: done");
        }
    }
    ipc::remove_instance(&instance);
}
