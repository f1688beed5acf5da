use runtime::rt::*;

/// A process out of its cycle is out of real time: the guard's drop gives the thread back
/// to `SCHED_OTHER` (a leaving process at its priority starved its own log worker, and
/// with it both CPUs, for 0.95 s).
#[test]
fn the_guard_gives_the_thread_back_to_sched_other() {
    std::thread::spawn(|| {
        let (report, guard) = setup(RtRequest {
            priority: 10,
            cpu: None,
        });
        if report.policy != 1 {
            eprintln!("no right to SCHED_FIFO here: nothing to give back");
            return;
        }
        // SAFETY: plain system calls about the calling thread.
        assert_eq!(unsafe { libc::sched_getscheduler(0) }, libc::SCHED_FIFO);
        drop(guard);
        assert_eq!(unsafe { libc::sched_getscheduler(0) }, libc::SCHED_OTHER);
    })
    .join()
    .expect("the thread");
}
