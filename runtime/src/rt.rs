//! Real-time set-up of a process, done once before its cycle starts.
//!
//! What cyclictest does, in the same order: make malloc real-time safe, lock all memory,
//! prefault the stack and a heap reserve, pin the CPU, switch to `SCHED_FIFO`, hold
//! `/dev/cpu_dma_latency` at 0. Each step that the system refuses (not root, no such file)
//! is warned about once and the process keeps running without it; the result is reported in
//! [`RtReport`] and published in the process status, so nobody mistakes a degraded run for a
//! real-time one.

use shm_schema::status::rt_flags;
use std::fs::File;
use std::io::Write;

/// Stack prefaulted at set-up (bytes). The cycles of this project use a few KiB.
pub const STACK_PREFAULT: usize = 512 * 1024;
/// Heap reserve prefaulted and kept by malloc at set-up (bytes).
pub const HEAP_PREFAULT: usize = 8 * 1024 * 1024;

/// What the process asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RtRequest {
    /// `SCHED_FIFO` priority 1..=99; 0 stays under `SCHED_OTHER`.
    pub priority: i32,
    /// CPU to pin to; `None` for any.
    pub cpu: Option<usize>,
}

/// What the process got.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RtReport {
    /// Policy in effect: 0 `SCHED_OTHER`, 1 `SCHED_FIFO`.
    pub policy: u32,
    /// Priority in effect.
    pub priority: i32,
    /// CPU pinned to, -1 for none.
    pub cpu: i32,
    /// [`rt_flags`] bits of what succeeded.
    pub flags: u32,
}

/// Keeps what must live as long as the cycle: the `/dev/cpu_dma_latency` file; from
/// [`setup`], the calling thread's `SCHED_FIFO` priority, which ends with the guard (dropped
/// on the thread that made it: it is not `Send`).
///
/// A process that leaves its cycle is no longer real-time: what it does then (its last
/// status, its log's flush) must never spin at its priority while a thread under
/// `SCHED_OTHER` is to do the work. tracing-appender's guard waits up to a second for its
/// worker thread by `sched_yield`, which yields to nothing below a `SCHED_FIFO` caller: two
/// processes leaving at once after the supervisor was killed held both CPUs for 0.95 s each
/// time (until the kernel's real-time throttling let the workers run), and every real-time
/// process of every other cell on the machine with them.
#[derive(Debug)]
pub struct RtGuard {
    _dma_latency: Option<File>,
    /// The thread's priority to give back (it was put under `SCHED_FIFO` by [`setup`]).
    fifo: bool,
    _same_thread: std::marker::PhantomData<*const ()>,
}

impl Drop for RtGuard {
    fn drop(&mut self) {
        if self.fifo {
            let param = libc::sched_param { sched_priority: 0 };
            // SAFETY: plain system call with a valid parameter block; 0 is the calling
            // thread, the one `setup` put under SCHED_FIFO.
            let _ = unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &param) };
        }
    }
}

/// Applies `req` to the calling thread and process: [`setup_process`] then [`setup_thread`].
/// The thread's `SCHED_FIFO` priority lasts as long as the guard.
pub fn setup(req: RtRequest) -> (RtReport, RtGuard) {
    let (process, mut guard) = setup_process();
    let thread = setup_thread(req);
    guard.fifo = thread.policy == 1;
    (
        RtReport {
            flags: process.flags | thread.flags,
            ..thread
        },
        guard,
    )
}

/// The process-wide half: real-time-safe malloc, `mlockall`, a prefaulted heap reserve,
/// `/dev/cpu_dma_latency` held at 0 (as long as the guard lives). Reports `MLOCK` and
/// `DMA_LATENCY` in its flags.
pub fn setup_process() -> (RtReport, RtGuard) {
    let mut report = RtReport {
        cpu: -1,
        ..RtReport::default()
    };
    // SAFETY: mallopt only changes allocator tunables.
    unsafe {
        // Never give memory back to the kernel, never serve large blocks by mmap: an
        // allocation after set-up then reuses locked, prefaulted heap.
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, -1);
    }
    // SAFETY: plain system call.
    if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } == 0 {
        report.flags |= rt_flags::MLOCK;
    } else {
        tracing::warn!(
            "mlockall refused ({}): pages may fault in during the cycle",
            std::io::Error::last_os_error()
        );
    }
    prefault_heap();
    let dma = hold_dma_latency_zero();
    if dma.is_some() {
        report.flags |= rt_flags::DMA_LATENCY;
    }
    (
        report,
        RtGuard {
            _dma_latency: dma,
            fifo: false,
            _same_thread: std::marker::PhantomData,
        },
    )
}

/// The calling thread's half: a prefaulted stack, the CPU affinity and `SCHED_FIFO` priority
/// of `req`. Reports `AFFINITY` and `SCHED` in its flags.
pub fn setup_thread(req: RtRequest) -> RtReport {
    let mut report = RtReport {
        cpu: -1,
        ..RtReport::default()
    };
    prefault_stack();
    if let Some(cpu) = req.cpu {
        // SAFETY: the set is zeroed then filled with one valid CPU index.
        let ok = cpu < libc::CPU_SETSIZE as usize
            && unsafe {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                libc::CPU_SET(cpu, &mut set);
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0
            };
        if ok {
            report.cpu = cpu as i32;
            report.flags |= rt_flags::AFFINITY;
        } else {
            tracing::warn!(
                "pinning to CPU {cpu} refused ({}): running on any CPU",
                std::io::Error::last_os_error()
            );
        }
    }
    if req.priority > 0 {
        if let Err(e) = fifo(&mut report, req.priority, 0) {
            tracing::warn!(
                "SCHED_FIFO priority {} refused ({e}): running under SCHED_OTHER, timing will suffer",
                req.priority
            );
        }
    } else {
        report.flags |= rt_flags::SCHED;
    }
    report
}

/// Puts the calling thread under `SCHED_FIFO` at `priority` with `SCHED_RESET_ON_FORK`, for
/// a thread that watches real-time work rather than doing it (the supervisor's loop, which
/// publishes the heartbeat every process of the cell leaves without): ordinary work (a
/// build, a browser) can no longer hold it off a CPU, and whatever it starts (the cell's
/// processes, which set their own priorities, and its own threads: a program's validation,
/// the recorder) starts under `SCHED_OTHER`. Nothing else of [`setup`] (no memory locking,
/// no pinning): a late heartbeat is what this guards against, not a late cycle. The thread
/// goes back to `SCHED_OTHER` when the guard drops. Refused (not root): warned about, and
/// the report says `SCHED_OTHER`; `priority` 0 asks for nothing.
pub fn setup_watching_thread(priority: i32) -> (RtReport, RtGuard) {
    let mut report = RtReport {
        cpu: -1,
        ..RtReport::default()
    };
    if priority > 0
        && let Err(e) = fifo(&mut report, priority, libc::SCHED_RESET_ON_FORK)
    {
        tracing::warn!(
            "SCHED_FIFO priority {priority} refused ({e}): the supervisor's loop runs under \
             SCHED_OTHER, and a loaded machine can hold its heartbeat back"
        );
    }
    let guard = RtGuard {
        _dma_latency: None,
        fifo: report.policy == 1,
        _same_thread: std::marker::PhantomData,
    };
    (report, guard)
}

/// The calling thread under `SCHED_FIFO` at `priority` (with the policy flags `flags`), said
/// in `report`; the system's refusal otherwise.
fn fifo(report: &mut RtReport, priority: i32, flags: libc::c_int) -> std::io::Result<()> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: plain system call with a valid parameter block; 0 is the calling thread.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO | flags, &param) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    report.policy = 1;
    report.priority = priority;
    report.flags |= rt_flags::SCHED;
    Ok(())
}

/// Opens `/dev/cpu_dma_latency` and writes a 32-bit 0: the CPUs stay out of deep idle
/// states while the file is open (halves p99 wake-up latency on this machine).
fn hold_dma_latency_zero() -> Option<File> {
    let open = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/cpu_dma_latency");
    match open.and_then(|mut f| f.write_all(&0i32.to_ne_bytes()).map(|_| f)) {
        Ok(f) => Some(f),
        Err(e) => {
            tracing::warn!("cannot hold /dev/cpu_dma_latency at 0 ({e}): wake-ups will be slower");
            None
        }
    }
}

#[inline(never)]
fn prefault_stack() {
    let mut buf = [0u8; STACK_PREFAULT];
    // Touch one byte per page so every page of the future stack is mapped (and locked).
    for i in (0..STACK_PREFAULT).step_by(4096) {
        buf[i] = 1;
    }
    std::hint::black_box(&buf);
}

fn prefault_heap() {
    let mut v: Vec<u8> = Vec::with_capacity(HEAP_PREFAULT);
    for i in (0..HEAP_PREFAULT).step_by(4096) {
        v.push(0);
        // SAFETY: within capacity; writes one byte per page.
        unsafe { *v.as_mut_ptr().add(i) = 1 };
    }
    std::hint::black_box(&v);
    // Freed into malloc's arena, which keeps it (M_TRIM_THRESHOLD = -1, M_MMAP_MAX = 0).
}

/// Scheduling policy and priority of process `pid` as the kernel reports them
/// (`(policy, priority)`, policy 0 other, 1 FIFO, 2 RR), or `None` if it is gone.
pub fn sched_of(pid: i32) -> Option<(u32, i32)> {
    // SAFETY: plain system calls with a valid parameter block.
    unsafe {
        let policy = libc::sched_getscheduler(pid);
        if policy < 0 {
            return None;
        }
        let mut param = libc::sched_param { sched_priority: 0 };
        if libc::sched_getparam(pid, &mut param) != 0 {
            return None;
        }
        // The policy comes with `SCHED_RESET_ON_FORK` or-ed in where it is set
        // ([`setup_watching_thread`]).
        let p = match policy & !libc::SCHED_RESET_ON_FORK {
            libc::SCHED_FIFO => 1,
            libc::SCHED_RR => 2,
            _ => 0,
        };
        Some((p, param.sched_priority))
    }
}

/// Name of a policy value of [`RtReport::policy`] (the numbers of `ProcessStatusV2::policy`).
pub use shm_schema::status::policy_name;
