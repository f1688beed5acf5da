//! The virtual clock between a clock and one process (here two threads with a node each): the
//! process is granted exactly its deadlines, in order, a scheduled hold grants them late, and
//! a cycle's wait allocates at most once, inside iceoryx2 (its report's publish).

use runtime::alloc_count::{CountingAllocator, count};
use runtime::ipc;
use runtime::vclock::{Coordinator, EPOCH_NS, Participant};
use shm_schema::InstanceName;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

#[global_allocator]
static A: CountingAllocator = CountingAllocator;

const MS: u64 = 1_000_000;

#[test]
fn a_process_is_granted_its_deadlines_in_order_and_its_wait_allocates_at_most_once() {
    let name = format!("vclock{}", std::process::id());
    let instance = InstanceName::new(&name).expect("valid");
    // The instance's files go whether the test passes or not.
    struct Removed(InstanceName);
    impl Drop for Removed {
        fn drop(&mut self) {
            ipc::remove_instance(&self.0);
        }
    }
    let _removed = Removed(instance);
    {
        let done = Arc::new(AtomicBool::new(false));
        let stop = done.clone();
        let (ready, started) = std::sync::mpsc::channel();
        // The clock's ports are single-threaded: made on its own thread.
        let ticking = std::thread::spawn(move || {
            let node = ipc::node(&instance, "clock").expect("node");
            // Its watchdog short: the process that leaves at the end never exits (it is this
            // one), and the clock waits that long for it.
            let mut clock =
                Coordinator::new(&node, &instance, Duration::from_millis(500)).expect("clock");
            // The process' deadlines from 50 ms on are held until 58.5 ms.
            clock.hold(0, EPOCH_NS + 50 * MS, EPOCH_NS + 58 * MS + MS / 2);
            // The process about to join: the clock stands still until it has.
            clock.expect(std::process::id());
            ready.send(()).expect("the test waits");
            let mut t = EPOCH_NS;
            while !stop.load(Ordering::Relaxed) {
                t += 10 * MS;
                clock.advance_to(&node, t, &mut || {});
            }
            clock.grants()
        });
        started.recv().expect("the clock started");
        let node = ipc::node(&instance, "process").expect("node");
        let mut me = Participant::new(&node, &instance, 0).expect("participant");
        assert_eq!(runtime::time::now_ns(), EPOCH_NS, "where the clock stands");
        me.join(EPOCH_NS + MS);
        let mut next = EPOCH_NS + MS;
        let mut granted = Vec::new();
        for _ in 0..100 {
            let now = me.wait(next);
            granted.push(now);
            next = now.max(next) + MS;
        }
        const N: u64 = 500;
        let ((), allocations) = count(|| {
            for _ in 0..N {
                let now = me.wait(next);
                next = now.max(next) + MS;
            }
        });
        me.leave();
        done.store(true, Ordering::Relaxed);
        let grants = ticking.join().expect("the clock's thread");
        // Its deadlines, each granted at its own instant, but those the hold covered: granted
        // at its end (the process' own overrun rule would then skip what it ran into).
        let expected: Vec<u64> = (1..=100)
            .map(|k| EPOCH_NS + k * MS)
            .map(|t| {
                if (EPOCH_NS + 50 * MS..EPOCH_NS + 58 * MS + MS / 2).contains(&t) {
                    EPOCH_NS + 58 * MS + MS / 2
                } else {
                    t
                }
            })
            .collect();
        assert_eq!(granted[..49], expected[..49]);
        assert_eq!(granted[49], EPOCH_NS + 58 * MS + MS / 2, "{granted:?}");
        assert!(grants >= 600, "{grants} grants");
        assert!(
            allocations <= N,
            "{allocations} allocations in {N} waits on the clock"
        );
        eprintln!("steady state: {allocations} allocations in {N} waits on the clock");
    }
}
