//! The measuring loop of a timer thread (the cycle runtime's wait, the recorder, the
//! runtime's finish) allocates nothing, proven with a counting allocator.

use latency::measure::{Live, Recorder};
use runtime::alloc_count::{CountingAllocator, count};
use runtime::cycle::CycleClock;
use runtime::time::now_ns;
use std::sync::Arc;

#[global_allocator]
static A: CountingAllocator = CountingAllocator;

#[test]
fn the_timer_loop_allocates_nothing() {
    let live = Arc::new(Live::default());
    let mut rec = Recorder::new(10, live.clone()); // 10 µs range: most samples overflow
    let mut clock = CycleClock::new(100_000, 0, now_ns());
    let ((), allocations) = count(|| {
        for _ in 0..300 {
            let wake = clock.wait().expect("sleep");
            rec.record(wake.latency_ns());
            clock.finish(&wake, now_ns());
        }
    });
    assert_eq!(allocations, 0);
    assert_eq!(clock.histogram().count, 300);
    assert_eq!(live.cycles.load(std::sync::atomic::Ordering::Relaxed), 300);
}
