//! The project's iceoryx2 flavour (`runtime::ipc::RtIpc`) differs from iceoryx2's stock
//! `ipc::Service` only in its event mechanism, so a process on stock iceoryx2 (what the C, C++
//! and Python bindings use) still opens every publish-subscribe service of a cell: it receives
//! our samples and we receive its samples.

use iceoryx2::prelude::*;
use runtime::ipc::{self, Pub, Sub};
use shm_schema::{InstanceName, ServiceId, SetpointV2};

#[test]
fn a_stock_iceoryx2_process_reads_and_writes_our_publish_subscribe_services() {
    let instance = InstanceName::new(&format!("flavour{}", std::process::id())).expect("valid");
    {
        let ours = ipc::node(&instance, "ours").expect("node");
        let tx: Pub<SetpointV2> = Pub::new(&ours, &instance, ServiceId::Setpoint).expect("pub");
        let rx: Sub<SetpointV2> = Sub::new(&ours, &instance, ServiceId::Setpoint, 8).expect("sub");

        // The stock flavour, with the same per-instance configuration and the same QoS.
        let cfg = ipc::config_for(&instance).expect("config");
        let stock = NodeBuilder::new()
            .config(&cfg)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<iceoryx2::service::ipc::Service>()
            .expect("stock node");
        let name = instance.service(ServiceId::Setpoint);
        let q = ServiceId::Setpoint.qos();
        let service = stock
            .service_builder(&ServiceName::new(name.as_str()).expect("name"))
            .publish_subscribe::<SetpointV2>()
            .max_publishers(q.max_publishers)
            .max_subscribers(q.max_subscribers)
            .history_size(q.history)
            .subscriber_max_buffer_size(q.subscriber_max_buffer)
            .max_nodes(q.max_nodes)
            .enable_safe_overflow(true)
            .open()
            .expect("the stock flavour opens our service");
        let stock_rx = service
            .subscriber_builder()
            .create()
            .expect("stock subscriber");
        let stock_tx = service
            .publisher_builder()
            .create()
            .expect("stock publisher");

        let sp = SetpointV2 {
            seq: 42,
            ..SetpointV2::default()
        };
        assert!(tx.send(&sp));
        let got = stock_rx.receive().expect("receive").expect("a sample");
        assert_eq!(got.payload().seq, 42);
        drop(got);

        let sample = stock_tx.loan_uninit().expect("loan");
        sample
            .write_payload(SetpointV2 {
                seq: 43,
                ..SetpointV2::default()
            })
            .send()
            .expect("send");
        let seqs: Vec<u64> = std::iter::from_fn(|| rx.next()).map(|s| s.seq).collect();
        assert_eq!(
            seqs,
            vec![42, 43],
            "ours receives its own and the stock sample"
        );
    }
    let left = ipc::remove_instance(&instance);
    assert!(left.is_empty(), "{left:?}");
}
