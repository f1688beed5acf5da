//! The per-process runner (`runtime::process::Runner`) driven cycle by cycle in this test,
//! with no supervisor and no other process: what it publishes (status every cycle, the two
//! histograms), an e-stop its task raises, leaving on SIGTERM once the task is safe, and what
//! its cycle allocates.

use runtime::alloc_count::{CountingAllocator, count};
use runtime::ipc::{self, Sub};
use runtime::process::{Context, Cycle, Exit, Flow, Runner, Task};
use runtime::rt::RtReport;
use shm_schema::event::code;
use shm_schema::{
    EstopOrigin, EstopV1, EventV1, InstanceName, LatencyHistogramV1, ProcState, ProcessName,
    ProcessStatusV2, ServiceId, estop_seen,
};

#[global_allocator]
static A: CountingAllocator = CountingAllocator;

/// A task that counts its cycles, raises an e-stop at a given one, and is safe again a few
/// cycles after it reacts.
#[derive(Default)]
struct Probe {
    cycles: u64,
    raise_at: u64,
    reacting: u64,
}

impl Task for Probe {
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        self.cycles += 1;
        if self.cycles == self.raise_at {
            cx.raise_estop(EstopOrigin::Device, code::FOLLOWING_ERROR, &["probe"]);
        }
        if cx.estop.react.is_some() {
            self.reacting += 1;
            cx.set_safe(self.reacting > 5);
        }
    }
}

fn runner(instance: &InstanceName, raise_at: u64) -> Runner<Probe> {
    let name = ProcessName::new("servo").expect("name");
    let mut cell = cell_config::Config::default_cell().to_shm();
    // No supervisor beats in this test, and no health detector (all limits 0: off): a stall
    // of the host (other tests' cells run beside this one) would expire one, whose e-stop
    // would come before the task's.
    cell.supervisor_timeout_ns = 0;
    cell.health = shm_schema::HealthConfigV1::default();
    let node = ipc::node(instance, name.as_str()).expect("node");
    let ctx = Context::of(*instance, name, node, cell).expect("servo is in the default cell");
    let mut r = Runner::new(ctx, |_| {
        Ok(Probe {
            raise_at,
            ..Probe::default()
        })
    })
    .expect("runner");
    r.start(RtReport::default());
    r
}

/// `n` cycles on the runner's own clock; the flow of the last.
fn cycles(r: &mut Runner<Probe>, n: u64) -> Flow {
    let mut flow = Flow::Next;
    for _ in 0..n {
        let wake = r.clock.wait().expect("wake");
        flow = r.cycle(&wake);
        if flow == Flow::Leave {
            break;
        }
    }
    flow
}

#[test]
fn the_runner_publishes_raises_leaves_and_its_cycle_allocates_only_inside_iceoryx2() {
    let instance = InstanceName::new(&format!("runner{}", std::process::id())).expect("name");
    runtime::signals::install().expect("signals");
    // Whatever happens, nothing of the instance stays behind.
    struct Clean(InstanceName);
    impl Drop for Clean {
        fn drop(&mut self) {
            ipc::remove_instance(&self.0);
        }
    }
    let _clean = Clean(instance);
    {
        let observer = ipc::node(&instance, "observer").expect("node");
        let servo = ProcessName::new("servo").expect("name");
        let status: Sub<ProcessStatusV2> =
            Sub::new(&observer, &instance, ServiceId::Status(servo), 1024).expect("status");
        let [latency, exec] = [ServiceId::Latency(servo), ServiceId::ExecTime(servo)].map(|id| {
            Sub::<LatencyHistogramV1>::new(&observer, &instance, id, 2).expect("histogram")
        });
        let events: Sub<EventV1> =
            Sub::new(&observer, &instance, ServiceId::Events, 1024).expect("events");
        let mut r = runner(&instance, 450);

        // Steady state: 100 cycles to warm up, then count what 300 allocate (1 ms each: the
        // default cell's servo period).
        assert_eq!(cycles(&mut r, 100), Flow::Next);
        while events.next().is_some() {}
        let (flow, allocations) = count(|| cycles(&mut r, 300));
        assert_eq!(flow, Flow::Next);
        // 300 statuses, 6 histograms and the events of the window (an overrun burst when the
        // host held a cycle back) were published; iceoryx2 may allocate once per publish
        // (runtime::ipc), nothing else in the cycle may.
        let publishes = 306 + std::iter::from_fn(|| events.next()).count() as u64;
        assert!(
            allocations <= publishes,
            "{allocations} allocations in 300 cycles of {publishes} publishes"
        );
        eprintln!("{allocations} allocations in 300 cycles ({publishes} publishes)");
        let mut last = None;
        let mut seen = 0;
        while let Some(s) = status.next() {
            last = Some(s);
            seen += 1;
        }
        let s = last.expect("a status");
        // The first status says Starting; each cycle's after it, Cyclic.
        assert_eq!(seen, 401, "one status before the cycle, then one per cycle");
        assert_eq!(s.state, ProcState::Cyclic as u32);
        assert_eq!(s.stats.cycles, 400);
        assert_eq!(shm_schema::str_of(&s.name), "servo");
        assert_eq!(s.estop, 0);
        // Both histograms were published (every 100 cycles, half an interval apart), each
        // with the wake-ups so far.
        for sub in [&latency, &exec] {
            let h = sub.latest().expect("a histogram");
            assert!((300..=400).contains(&h.count), "{} samples", h.count);
            // Copied a slice per cycle, yet whole as it stood when sent.
            assert_eq!(h.buckets.iter().sum::<u64>() + h.overflows, h.count);
        }

        // The task raises an e-stop in its 450th cycle: published on the e-stop service, the
        // status says raised, and the runner goes on (the supervisor, absent, would latch it).
        let triggers: Sub<EstopV1> =
            Sub::new(&observer, &instance, ServiceId::Estop, 64).expect("estop");
        assert_eq!(cycles(&mut r, 100), Flow::Next);
        let raised = std::iter::from_fn(|| triggers.next())
            .find(|e| e.code == code::FOLLOWING_ERROR)
            .expect("the task's e-stop");
        assert_eq!(raised.origin, EstopOrigin::Device as u32);
        let s = std::iter::from_fn(|| status.next()).last().expect("status");
        assert_ne!(s.estop & estop_seen::RAISED, 0, "{:#x}", s.estop);
        assert!(
            std::iter::from_fn(|| events.next()).any(|e| e.code == code::ESTOP_RAISED),
            "the e-stop's event"
        );

        // SIGTERM: the runner leaves once its task is safe, and says it stopped.
        nix::sys::signal::raise(nix::sys::signal::Signal::SIGTERM).expect("SIGTERM");
        assert_eq!(
            cycles(&mut r, 5000),
            Flow::Leave,
            "the runner did not leave"
        );
        assert!(r.task().reacting > 5, "it left before its task was safe");
        assert_eq!(r.finish(), Exit::Stopped);
        let s = std::iter::from_fn(|| status.next()).last().expect("status");
        assert_eq!(s.state, ProcState::Stopping as u32);
    }
}
