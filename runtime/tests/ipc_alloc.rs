//! What the IPC calls of a cycle allocate, in steady state (documented in `runtime::ipc`):
//! `receive` nothing, a publish (`loan_uninit` + `send`) at most once inside iceoryx2, an
//! event's notify and wait nothing.

use runtime::alloc_count::{CountingAllocator, count};
use runtime::ipc::{self, Listener, Notifier, Pub, Sub};
use shm_schema::{InstanceName, ServiceId, SetpointV2};

#[global_allocator]
static A: CountingAllocator = CountingAllocator;

#[test]
fn steady_state_ipc_allocations() {
    let name = format!("ipcalloc{}", std::process::id());
    let instance = InstanceName::new(&name).expect("valid");
    {
        let node = ipc::node(&instance, "alloc-test").expect("node");
        let tx: Pub<SetpointV2> = Pub::new(&node, &instance, ServiceId::Setpoint).expect("pub");
        let rx: Sub<SetpointV2> = Sub::new(&node, &instance, ServiceId::Setpoint, 8).expect("sub");
        let mut sp: SetpointV2 = unsafe { core::mem::zeroed() };
        // Warm-up: the first sends after a connection change allocate.
        for i in 0..100 {
            sp.seq = i;
            assert!(tx.send(&sp));
            rx.latest();
        }
        const N: u64 = 1000;
        let ((), sends) = count(|| {
            for i in 0..N {
                sp.seq = i;
                tx.send(&sp);
            }
        });
        let (got, receives) = count(|| {
            let mut last = None;
            for _ in 0..N {
                last = rx.latest().or(last);
            }
            last
        });
        assert!(got.is_some());
        assert_eq!(receives, 0, "receive allocated");
        assert!(sends <= N, "{sends} allocations in {N} publishes");
        eprintln!("steady state: {sends} allocations in {N} publishes, {receives} in {N} receives");

        // The IPC hop's event: notify, then the listener's wait.
        let ready = Notifier::new(&node, &instance, ServiceId::SetpointReady).expect("notifier");
        let wake = Listener::new(&node, &instance, ServiceId::SetpointReady).expect("listener");
        for _ in 0..100 {
            assert_eq!(ready.notify(), 1);
            assert!(wake.wait());
        }
        let (woken, events) = count(|| {
            let mut woken = 0;
            for _ in 0..N {
                ready.notify();
                woken += wake.wait() as u64;
            }
            woken
        });
        assert_eq!(woken, N, "every notification wakes the listener");
        assert_eq!(events, 0, "notify or wait allocated");
        eprintln!("steady state: {events} allocations in {N} notify + wait");
    }
    let _ = ipc::remove_instance_segment(&instance);
    let _ = std::fs::remove_dir_all(instance.root_dir().as_str());
}
