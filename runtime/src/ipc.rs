//! iceoryx2 nodes and typed ports for the services of `shm-schema`.
//!
//! The ports of each payload type are compiled here once ([`Payload`], [`payloads!`](crate::payloads))
//! and reached through a `dyn` table: one indirect call per send or receive, no allocation
//! after they are made.
//!
//! Every port is opened with the service's [`shm_schema::names::Qos`], so any process may
//! create a service first. Every iceoryx2 resource of an instance is isolated by the
//! configuration of [`config_for`]: its own shared-memory file prefix and its own root folder.
//!
//! # Allocation
//! Measured with a counting allocator (see `tests/ipc_alloc.rs` in this crate): in steady
//! state `receive`, `notify` and a listener's wait allocate nothing, a publish (`loan_uninit` +
//! `send`) allocates once inside iceoryx2. The set-up of [`crate::rt`] keeps that allocation on locked, prefaulted heap that
//! malloc never returns to the kernel.

use iceoryx2::node::NodeView;
use iceoryx2::port::listener::Listener as IoxListener;
use iceoryx2::port::notifier::Notifier as IoxNotifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::port::update_connections::UpdateConnections;
pub use iceoryx2::prelude::Node;
use iceoryx2::prelude::*;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::event::PortFactory as EventFactory;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
pub use shm_schema::{InstanceName, ServiceId};
use std::fmt::Debug;
use std::sync::atomic::{AtomicU64, Ordering};

/// The iceoryx2 service flavour of every port: [`RtIpc`].
pub type Ipc = RtIpc;

/// iceoryx2's `ipc::Service` (inter-process, single-threaded ports) with one change: events
/// wake through a process-shared semaphore (a futex in shared memory) instead of a Unix
/// datagram socket.
///
/// Measured with `supervisor latency --test ipc,pipe,unix` on the development VM, the one-way
/// setpoint hop (publish + notify to the listener's wake-up) had a median of 26-28 µs across
/// CPUs with iceoryx2's default event, 13-17 µs with this one, against 9-11 µs for a raw
/// pipe and 17 µs for a raw Unix datagram socket: the default event pays the socket's own
/// cost plus five system calls after every wake-up to drain it.
///
/// Everything else is the type iceoryx2's `ipc::Service` uses, so the publish-subscribe
/// services (all the cell's data) are the same files in the same formats: a process on stock
/// iceoryx2 (the C, C++ and Python bindings) opens them as before
/// (`tests/tests/it/flavour_interop.rs` proves it). Only the event service
/// ([`shm_schema::ServiceId::SetpointReady`]) needs this flavour to be waited on.
#[derive(Debug, Clone)]
pub struct RtIpc {}

mod flavour {
    use super::RtIpc;
    use core::fmt::Debug;
    use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
    use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
    use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
    use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
    use iceoryx2_cal::*;

    impl iceoryx2::service::Service for RtIpc {
        type StaticStorage = static_storage::recommended::Ipc;
        type ConfigSerializer = serialize::recommended::Recommended;
        type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
            dynamic_storage::recommended::PersistentIpc<T>;
        type Bag = bag::recommended::Recommended;
        type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
            dynamic_storage::recommended::Ipc<T>;
        type ServiceNameHasher = hash::recommended::Recommended;
        type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
        type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
        type Connection = zero_copy_connection::recommended::Ipc;
        type Event = event::SemaphoreShmCountingBitSet;
        type Monitoring = monitoring::recommended::Ipc;
        type Reactor = reactor::recommended::Ipc;
        type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> =
            arc_sync_policy::single_threaded::SingleThreaded<T>;
        type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
            dynamic_storage::recommended::Ipc<KeyType>;
        type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
        type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
    }

    impl iceoryx2::service::internal::ServiceInternal<RtIpc> for RtIpc {}
}

/// A failure to set up a node or port, naming what.
#[derive(Debug)]
pub struct IpcError {
    /// What was being set up (a service name, a node).
    pub what: String,
    /// The iceoryx2 error.
    pub reason: String,
}

impl std::fmt::Display for IpcError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.what, self.reason)
    }
}

impl std::error::Error for IpcError {}

fn err(what: impl Into<String>, reason: impl Debug) -> IpcError {
    // Out of descriptors, iceoryx2 says only what it could not make.
    let reason = match crate::fds::shortage() {
        Some(words) => format!("{words} ({reason:?})"),
        None => format!("{reason:?}"),
    };
    IpcError {
        what: what.into(),
        reason,
    }
}

/// The iceoryx2 configuration of `instance`: file prefix `iox2_<instance>_`, root folder
/// `/tmp/iceoryx2/<instance>/`. Built in code, so no `iceoryx2.toml` is looked up.
pub fn config_for(instance: &InstanceName) -> Result<Config, IpcError> {
    let mut cfg = Config::default();
    let prefix = instance.shm_prefix();
    cfg.global.prefix =
        FileName::new(prefix.as_str().as_bytes()).map_err(|e| err("iceoryx2 file prefix", e))?;
    let root = instance.root_dir();
    cfg.global.set_root_path(
        &Path::new(root.as_str().as_bytes()).map_err(|e| err("iceoryx2 root path", e))?,
    );
    // A node dropped does not clean the instance's dead nodes: iceoryx2 0.10 does it
    // blocking, and waits on what a node killed while it attached (an observer's CLI) left
    // half made (`remove_unfinished_shm`): every process of a cell going down waited on it,
    // for many seconds. The supervisor cleans dead nodes itself (`remove_dead_nodes`, before
    // its processes stop and when the instance is removed); a node created still cleans them.
    cfg.global.node.cleanup_dead_nodes_on_destruction = false;
    Ok(cfg)
}

/// Quiets iceoryx2's own log but for its fatal lines: its error lines dump whole structures
/// (4-6 KB for one failure), and every failure comes back to us as an error we say in words
/// ([`IpcError`]).
pub fn quiet_iceoryx2_log() {
    set_log_level(LogLevel::Fatal);
}

/// Creates the node of one process of `instance`. Signal handling is left to
/// [`crate::signals`].
pub fn node(instance: &InstanceName, name: &str) -> Result<Node<Ipc>, IpcError> {
    let cfg = config_for(instance)?;
    let node_name = NodeName::new(name).map_err(|e| err(format!("node name {name:?}"), e))?;
    NodeBuilder::new()
        .name(&node_name)
        .config(&cfg)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Ipc>()
        .map_err(|e| err(format!("iceoryx2 node {name:?} of instance {instance}"), e))
}

/// IPC calls of this process that failed (a loan, a send, a receive), for seed 002's
/// transport detector: none is dropped silently.
static TRANSPORT_ERRORS: AtomicU64 = AtomicU64::new(0);

/// The number of failed IPC calls of this process so far.
///
/// # Real-time
/// One atomic load.
pub fn transport_errors() -> u64 {
    TRANSPORT_ERRORS.load(Ordering::Relaxed)
}

#[inline]
fn transport_error() {
    TRANSPORT_ERRORS.fetch_add(1, Ordering::Relaxed);
}

/// A payload of a service of the cell (a `shm-schema` type). Its ports are built here, in
/// this crate, once: iceoryx2's ports are generic over the payload, and every crate that
/// opened them made its own copy of their code (about 40 % of the code of each crate that
/// used them, and as much of its build). [`Pub`] and [`Sub`] reach the port through a
/// `dyn` table ([`PubPort`], [`SubPort`]) made by [`payloads!`](crate::payloads).
pub trait Payload: Debug + ZeroCopySend + Copy + 'static {
    /// A publisher of `id` carrying this payload.
    fn publisher(
        node: &Node<Ipc>,
        instance: &InstanceName,
        id: ServiceId,
    ) -> Result<Box<dyn PubPort<Self>>, IpcError>;
    /// A subscriber of `id` keeping up to `buffer` unread samples.
    fn subscriber(
        node: &Node<Ipc>,
        instance: &InstanceName,
        id: ServiceId,
        buffer: usize,
    ) -> Result<Box<dyn SubPort<Self>>, IpcError>;
}

/// The publishing side of a port, whatever its payload's type.
pub trait PubPort<T> {
    /// One loan, one copy of `value` into it, one send. False if iceoryx2 refused.
    fn send(&self, value: &T) -> bool;
    /// The payload of a sample loaned and kept until [`PubPort::send_staged`] (loaned by the
    /// first call, the same one after), not initialised: to be written over several calls.
    /// `None` if iceoryx2 refused the loan.
    fn staged(&mut self) -> Option<&mut core::mem::MaybeUninit<T>>;
    /// Sends the staged sample; false if there is none or iceoryx2 refused.
    ///
    /// # Safety
    /// Every byte of the staged payload has been written.
    unsafe fn send_staged(&mut self) -> bool;
    /// Delivers history to subscribers that connected since the last send.
    fn update_connections(&self);
}

/// The receiving side of a port, whatever its payload's type.
pub trait SubPort<T> {
    /// The oldest unread sample.
    fn receive(&self) -> Received<T>;
}

/// What a [`SubPort::receive`] found.
#[derive(Debug)]
pub enum Received<T> {
    /// The oldest unread sample.
    Sample(T),
    /// None unread.
    Empty,
    /// iceoryx2 failed (counted by [`transport_errors`]).
    Failed,
}

/// Implements [`Payload`] for each type given, with its ports compiled in the crate that
/// calls it (this crate for every type of `shm-schema`).
#[macro_export]
macro_rules! payloads {
    ($($t:ty),* $(,)?) => {$(
        impl $crate::ipc::Payload for $t {
            fn publisher(
                node: &$crate::ipc::Node<$crate::ipc::Ipc>,
                instance: &$crate::ipc::InstanceName,
                id: $crate::ipc::ServiceId,
            ) -> Result<Box<dyn $crate::ipc::PubPort<Self>>, $crate::ipc::IpcError> {
                $crate::ipc::publisher::<Self>(node, instance, id)
            }
            fn subscriber(
                node: &$crate::ipc::Node<$crate::ipc::Ipc>,
                instance: &$crate::ipc::InstanceName,
                id: $crate::ipc::ServiceId,
                buffer: usize,
            ) -> Result<Box<dyn $crate::ipc::SubPort<Self>>, $crate::ipc::IpcError> {
                $crate::ipc::subscriber::<Self>(node, instance, id, buffer)
            }
        }
    )*};
}

payloads!(
    shm_schema::CellConfigV6,
    shm_schema::ClockGrantV1,
    shm_schema::ClockReportV1,
    shm_schema::DigitalIoV1,
    shm_schema::DriveCommandV2,
    shm_schema::DriveFeedbackV2,
    shm_schema::EmulatorFaultV1,
    shm_schema::EstopV1,
    shm_schema::EthercatConfigV1,
    shm_schema::EventV1,
    shm_schema::FaultInjectionV1,
    shm_schema::FieldbusImageV1,
    shm_schema::estop::HostStateV1,
    shm_schema::IoWriteV1,
    shm_schema::LatencyHistogramV1,
    shm_schema::MotionCommandV2,
    shm_schema::MotionControlV2,
    shm_schema::ProcessStatusV2,
    shm_schema::ServoRequestV1,
    shm_schema::ServoStateV3,
    shm_schema::SetpointV2,
    shm_schema::TrajgenHandoverV2,
);

fn open<T>(
    node: &Node<Ipc>,
    instance: &InstanceName,
    id: ServiceId,
) -> Result<PubSubFactory<Ipc, T, ()>, IpcError>
where
    T: Debug + ZeroCopySend + Copy + 'static,
{
    let name = instance.service(id);
    let service_name =
        ServiceName::new(name.as_str()).map_err(|e| err(format!("service name {name}"), e))?;
    let q = id.qos();
    node.service_builder(&service_name)
        .publish_subscribe::<T>()
        .max_publishers(q.max_publishers)
        .max_subscribers(q.max_subscribers)
        .history_size(q.history)
        .subscriber_max_buffer_size(q.subscriber_max_buffer)
        .max_nodes(q.max_nodes)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| match e {
            PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                PublishSubscribeOpenError::ExceedsMaxNumberOfNodes,
            ) => slots_taken(&name, q.max_nodes, "processes may open it at once"),
            e => err(format!("service {name}"), e),
        })
}

/// A service's slots all taken (too many observers attached at once), in words.
fn slots_taken(service: &impl std::fmt::Display, max: usize, what: &str) -> IpcError {
    IpcError {
        what: format!("service {service}"),
        reason: format!(
            "all its slots are taken ({max} {what}): close an observer of the cell \
             (a `record`, `web`, `events --follow`, a tool) and try again"
        ),
    }
}

struct PubOf<T: Debug + ZeroCopySend + Copy + 'static> {
    staged: Option<SampleMutUninit<Ipc, core::mem::MaybeUninit<T>, ()>>,
    port: Publisher<Ipc, T, ()>,
    _service: PubSubFactory<Ipc, T, ()>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> PubPort<T> for PubOf<T> {
    fn send(&self, value: &T) -> bool {
        match self.port.loan_uninit() {
            Ok(mut sample) => {
                // One copy, straight into shared memory (`write_payload` takes the value: a
                // copy onto the stack first).
                // SAFETY: `value` is a whole `T`, copied over the whole payload.
                unsafe {
                    core::ptr::copy_nonoverlapping(value, sample.payload_mut().as_mut_ptr(), 1);
                    sample.assume_init().send().is_ok()
                }
            }
            Err(_) => false,
        }
    }

    fn staged(&mut self) -> Option<&mut core::mem::MaybeUninit<T>> {
        if self.staged.is_none() {
            self.staged = Some(self.port.loan_uninit().ok()?);
        }
        self.staged.as_mut().map(|s| s.payload_mut())
    }

    unsafe fn send_staged(&mut self) -> bool {
        // SAFETY: the caller wrote every byte of the payload.
        self.staged
            .take()
            .is_some_and(|s| unsafe { s.assume_init() }.send().is_ok())
    }

    fn update_connections(&self) {
        let _ = self.port.update_connections();
    }
}

/// How many subscribers `<i>/events` has now: for a client that waits until another one
/// has attached (a test's events follower). Opens the service on `node` (its ports stay
/// compiled here, as every payload's).
pub fn events_subscribers(node: &Node<Ipc>, instance: &InstanceName) -> Result<usize, IpcError> {
    Ok(ports::<shm_schema::EventV1>(node, instance, ServiceId::Events)?.1)
}

/// How many publishers `<i>/io/state` has now: a live iobridge (the one a swap replaces, or a
/// foreign one) whose outputs a new iobridge must take over rather than start from 0.
/// Opens the service on `node` (its ports stay compiled here, as every payload's).
pub fn io_state_publishers(node: &Node<Ipc>, instance: &InstanceName) -> Result<usize, IpcError> {
    Ok(ports::<shm_schema::DigitalIoV1>(node, instance, ServiceId::IoState)?.0)
}

/// The publishers and subscribers service `id` has now.
fn ports<T: Debug + ZeroCopySend + Copy + 'static>(
    node: &Node<Ipc>,
    instance: &InstanceName,
    id: ServiceId,
) -> Result<(usize, usize), IpcError> {
    use iceoryx2::service::port_factory::PortFactory;
    let service = open::<T>(node, instance, id)?;
    let config = service.dynamic_config();
    Ok((
        config.number_of_publishers(),
        config.number_of_subscribers(),
    ))
}

/// Opens (or creates) `id` and a publisher on it, for [`Payload::publisher`].
#[doc(hidden)]
pub fn publisher<T: Debug + ZeroCopySend + Copy + 'static>(
    node: &Node<Ipc>,
    instance: &InstanceName,
    id: ServiceId,
) -> Result<Box<dyn PubPort<T>>, IpcError> {
    let service = open::<T>(node, instance, id)?;
    let port = service
        .publisher_builder()
        .max_loaned_samples(2)
        .create()
        .map_err(|e| err(format!("publisher on {}", instance.service(id)), e))?;
    Ok(Box::new(PubOf {
        staged: None,
        port,
        _service: service,
    }))
}

struct SubOf<T: Debug + ZeroCopySend + Copy + 'static> {
    port: Subscriber<Ipc, T, ()>,
    _service: PubSubFactory<Ipc, T, ()>,
}

impl<T: Debug + ZeroCopySend + Copy + 'static> SubPort<T> for SubOf<T> {
    fn receive(&self) -> Received<T> {
        match self.port.receive() {
            Ok(Some(sample)) => Received::Sample(*sample.payload()),
            Ok(None) => Received::Empty,
            Err(_) => Received::Failed,
        }
    }
}

/// Opens (or creates) `id` and a subscriber on it, for [`Payload::subscriber`].
#[doc(hidden)]
pub fn subscriber<T: Debug + ZeroCopySend + Copy + 'static>(
    node: &Node<Ipc>,
    instance: &InstanceName,
    id: ServiceId,
    buffer: usize,
) -> Result<Box<dyn SubPort<T>>, IpcError> {
    let service = open::<T>(node, instance, id)?;
    let port = service
        .subscriber_builder()
        .buffer_size(buffer)
        .create()
        .map_err(|e| match e {
            SubscriberCreateError::ExceedsMaxSupportedSubscribers => slots_taken(
                &instance.service(id),
                id.qos().max_subscribers,
                "subscribers at once",
            ),
            e => err(format!("subscriber on {}", instance.service(id)), e),
        })?;
    Ok(Box::new(SubOf {
        port,
        _service: service,
    }))
}

/// A typed publisher of one service.
pub struct Pub<T: Payload> {
    port: Box<dyn PubPort<T>>,
}

impl<T: Payload> Pub<T> {
    /// Opens (or creates) `id` and a publisher on it.
    pub fn new(node: &Node<Ipc>, instance: &InstanceName, id: ServiceId) -> Result<Self, IpcError> {
        Ok(Self {
            port: T::publisher(node, instance, id)?,
        })
    }

    /// Publishes a copy of `value` straight into shared memory. False if iceoryx2 refused.
    ///
    /// # Real-time
    /// IPC call: one loan and one send; iceoryx2 allocates once per loan (see the module
    /// documentation).
    #[inline]
    pub fn send(&self, value: &T) -> bool {
        let ok = self.port.send(value);
        if !ok {
            transport_error();
        }
        ok
    }

    /// Delivers history to subscribers that connected since the last send.
    pub fn update_connections(&self) {
        self.port.update_connections();
    }

    /// The payload of a sample kept loaned until [`Pub::send_staged`], not initialised, to
    /// be written over several cycles ([`PubPort::staged`]). `None` if iceoryx2 refused.
    ///
    /// # Real-time
    /// IPC call: the first call loans (one allocation inside iceoryx2).
    pub fn staged(&mut self) -> Option<&mut core::mem::MaybeUninit<T>> {
        let p = self.port.staged();
        if p.is_none() {
            transport_error();
        }
        p
    }

    /// Sends the staged sample. False if there is none or iceoryx2 refused.
    ///
    /// # Safety
    /// Every byte of the staged payload has been written.
    ///
    /// # Real-time
    /// IPC call.
    pub unsafe fn send_staged(&mut self) -> bool {
        // SAFETY: the caller's promise.
        let ok = unsafe { self.port.send_staged() };
        if !ok {
            transport_error();
        }
        ok
    }
}

impl<T: Payload> Debug for Pub<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Pub")
    }
}

/// A typed subscriber of one service.
pub struct Sub<T: Payload> {
    port: Box<dyn SubPort<T>>,
}

impl<T: Payload> Sub<T> {
    /// Opens (or creates) `id` and a subscriber on it keeping up to `buffer` unread samples
    /// (older ones are dropped when it is full).
    pub fn new(
        node: &Node<Ipc>,
        instance: &InstanceName,
        id: ServiceId,
        buffer: usize,
    ) -> Result<Self, IpcError> {
        Ok(Self {
            port: T::subscriber(node, instance, id, buffer)?,
        })
    }

    /// Takes every unread sample and returns the newest.
    ///
    /// # Real-time
    /// IPC calls only; no allocation.
    #[inline]
    pub fn latest(&self) -> Option<T> {
        let mut last = None;
        loop {
            match self.port.receive() {
                Received::Sample(v) => last = Some(v),
                Received::Empty => return last,
                Received::Failed => {
                    transport_error();
                    return last;
                }
            }
        }
    }

    /// Takes the oldest unread sample.
    ///
    /// # Real-time
    /// IPC call; no allocation.
    #[inline]
    pub fn next(&self) -> Option<T> {
        match self.port.receive() {
            Received::Sample(v) => Some(v),
            Received::Empty => None,
            Received::Failed => {
                transport_error();
                None
            }
        }
    }
}

impl<T: Payload> Debug for Sub<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Sub")
    }
}

/// Largest event id of an event service: notifications carry no id of their own (0), and a
/// listener's wake-up scans every id up to this one.
const EVENT_ID_MAX: usize = 1;

fn open_event(
    node: &Node<Ipc>,
    instance: &InstanceName,
    id: ServiceId,
) -> Result<EventFactory<Ipc>, IpcError> {
    let name = instance.service(id);
    let service_name =
        ServiceName::new(name.as_str()).map_err(|e| err(format!("service name {name}"), e))?;
    let q = id.qos();
    node.service_builder(&service_name)
        .event()
        .max_notifiers(q.max_publishers)
        .max_listeners(q.max_subscribers)
        .max_nodes(q.max_nodes)
        .event_id_max_value(EVENT_ID_MAX)
        .open_or_create()
        .map_err(|e| err(format!("event service {name}"), e))
}

/// The sending side of an event service: wakes every listener.
pub struct Notifier {
    port: IoxNotifier<Ipc>,
    _service: EventFactory<Ipc>,
}

impl Notifier {
    /// Opens (or creates) the event service `id` and a notifier on it.
    pub fn new(node: &Node<Ipc>, instance: &InstanceName, id: ServiceId) -> Result<Self, IpcError> {
        let service = open_event(node, instance, id)?;
        let port = service
            .notifier_builder()
            .create()
            .map_err(|e| err(format!("notifier on {}", instance.service(id)), e))?;
        Ok(Self {
            port,
            _service: service,
        })
    }

    /// Wakes every listener; returns how many were notified (0 if none or on failure).
    ///
    /// # Real-time
    /// IPC call: one datagram per listener (none without listeners); no allocation in steady
    /// state (the first notify after a listener connects allocates inside iceoryx2).
    #[inline]
    pub fn notify(&self) -> usize {
        self.port.notify().unwrap_or(0)
    }
}

impl Debug for Notifier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Notifier")
    }
}

/// The receiving side of an event service: a blocking wait for a notification.
pub struct Listener {
    port: IoxListener<Ipc>,
    _service: EventFactory<Ipc>,
}

impl Listener {
    /// Opens (or creates) the event service `id` and a listener on it.
    pub fn new(node: &Node<Ipc>, instance: &InstanceName, id: ServiceId) -> Result<Self, IpcError> {
        let service = open_event(node, instance, id)?;
        let port = service
            .listener_builder()
            .create()
            .map_err(|e| err(format!("listener on {}", instance.service(id)), e))?;
        Ok(Self {
            port,
            _service: service,
        })
    }

    /// Blocks until a notification arrives, then takes every pending one. True if at least
    /// one arrived; false when a signal interrupted the wait (see
    /// [`crate::signals::wake_thread`]) or the wait failed.
    ///
    /// # Real-time
    /// The loop's one blocking wait (`sem_wait`, a futex); no allocation.
    #[inline]
    pub fn wait(&self) -> bool {
        matches!(self.port.blocking_wait(|_| {}), Ok(n) if n > 0)
    }
}

impl Debug for Listener {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Listener")
    }
}

/// Removes the resources of every dead node of `instance` (a process that was killed), then
/// the files of nodes that are not alive and that iceoryx2 cannot clean (see
/// [`remove_orphan_node_files`]). Returns how many nodes were cleaned.
pub fn remove_dead_nodes(instance: &InstanceName) -> Result<usize, IpcError> {
    remove_dead_nodes_older_than(instance, std::time::Duration::from_secs(1))
}

/// [`remove_dead_nodes`], taking the unfinished files that are `age` old (not a node or
/// segment being created right now, unless `age` is 0: an instance being removed, whose
/// clients cannot attach any more).
fn remove_dead_nodes_older_than(
    instance: &InstanceName,
    age: std::time::Duration,
) -> Result<usize, IpcError> {
    // First what a node killed while it attached left half made: iceoryx2 would wait on it.
    remove_unfinished_shm(instance, age);
    let cfg = config_for(instance)?;
    let mut dead = Vec::new();
    // The nodes whose files the orphan sweep below must leave alone.
    let mut keep = Vec::new();
    Node::<Ipc>::list(&cfg, |state| {
        match state {
            NodeState::Dead(view) => {
                // A dead node with its details is iceoryx2's to clean: its files tell which
                // ports it held. If this attempt fails (another process is cleaning it right
                // now and holds its cleaner lock), the next one retries; removing its files
                // here would leave its ports registered in the services for good (a
                // restarted process then finds no free publisher slot).
                if view.details().is_some() {
                    keep.push(view.id().value());
                }
                dead.push(view);
            }
            NodeState::Alive(view) => keep.push(view.id().value()),
            // One that cannot be told (another user's) is kept too.
            NodeState::Inaccessible(id) => keep.push(id.value()),
            NodeState::Undefined(_) => {}
        }
        CallbackProgression::Continue
    })
    .map_err(|e| err(format!("listing nodes of instance {instance}"), e))?;
    let mut cleaned = 0;
    for view in dead {
        if view.try_remove_stale_resources().is_ok() {
            cleaned += 1;
        }
    }
    Ok(cleaned + remove_orphan_node_files(instance, &keep, age))
}

/// Removes the files under the instance's `nodes/` folder of every node that is not in `keep`
/// and whose newest file is `age` old (not a node being created right now): what a process
/// killed while it created or removed its node leaves, which iceoryx2 lists as undefined, as
/// dead without details, or not at all. Returns how many nodes' files it removed.
fn remove_orphan_node_files(
    instance: &InstanceName,
    keep: &[u128],
    age: std::time::Duration,
) -> usize {
    use std::collections::BTreeMap;
    let nodes = std::path::PathBuf::from(instance.root_dir().as_str()).join("nodes");
    let prefix = instance.shm_prefix();
    // Per node id: its files. A node is `<prefix><id>.node_monitor…` and a folder `<id>/`.
    let mut by_id: BTreeMap<u128, Vec<std::path::PathBuf>> = BTreeMap::new();
    for e in std::fs::read_dir(&nodes).into_iter().flatten().flatten() {
        let name = e.file_name().to_string_lossy().to_string();
        let id = name
            .strip_prefix(prefix.as_str())
            .and_then(|rest| rest.split('.').next())
            .unwrap_or(&name)
            .parse::<u128>();
        let Ok(id) = id else { continue };
        let mut files = Vec::new();
        if is_real_dir(&e) {
            collect_files(&e.path(), &mut files);
        } else {
            files.push(e.path().display().to_string());
        }
        by_id
            .entry(id)
            .or_default()
            .extend(files.into_iter().map(std::path::PathBuf::from));
    }
    let mut removed = 0;
    for (id, files) in by_id {
        let young = files.iter().any(|f| {
            std::fs::symlink_metadata(f)
                .and_then(|m| m.modified())
                .ok()
                .and_then(|m| m.elapsed().ok())
                .is_none_or(|a| a < age)
        });
        if keep.contains(&id) || young {
            continue;
        }
        for f in &files {
            let _ = std::fs::remove_file(f);
        }
        let _ = std::fs::remove_dir(nodes.join(id.to_string()));
        removed += 1;
    }
    removed
}

/// Process ids of the live nodes of `instance`.
pub fn live_node_pids(instance: &InstanceName) -> Result<Vec<u32>, IpcError> {
    let cfg = config_for(instance)?;
    let mut pids = Vec::new();
    Node::<Ipc>::list(&cfg, |state| {
        if let NodeState::Alive(view) = state
            && let Some(details) = view.details()
        {
            pids.push(details.process_id().value() as u32);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| err(format!("listing nodes of instance {instance}"), e))?;
    Ok(pids)
}

/// The live nodes of `instance`: process id and node name.
pub fn live_nodes(instance: &InstanceName) -> Result<Vec<(u32, String)>, IpcError> {
    let cfg = config_for(instance)?;
    let mut nodes = Vec::new();
    Node::<Ipc>::list(&cfg, |state| {
        if let NodeState::Alive(view) = state
            && let Some(details) = view.details()
        {
            nodes.push((
                details.process_id().value() as u32,
                details.name().to_string(),
            ));
        }
        CallbackProgression::Continue
    })
    .map_err(|e| err(format!("listing nodes of instance {instance}"), e))?;
    Ok(nodes)
}

/// Removes the instance's global management segment (`..._node.<version>.global_mgmt`),
/// which iceoryx2 keeps beyond every node's life on purpose. Only when no node of the
/// instance is alive; the supervisor calls it last. Returns true if it removed it.
pub fn remove_instance_segment(instance: &InstanceName) -> Result<bool, IpcError> {
    if !live_node_pids(instance)?.is_empty() {
        return Ok(false);
    }
    let cfg = config_for(instance)?;
    // SAFETY: no node of this instance's iceoryx2 domain (its own prefix and root folder) is
    // alive, checked just above; the instance refuses to start while one is.
    unsafe { iceoryx2::testing::remove_global_mgmt_segment::<Ipc>(&cfg) }
        .map_err(|e| err(format!("global segment of instance {instance}"), e))
}

/// Removes what a clean shutdown leaves of the instance (dead nodes, the global segment,
/// empty folders) once no node of it is alive, and lists any file that should not be there
/// (empty when everything was cleaned).
pub fn remove_instance(instance: &InstanceName) -> Vec<String> {
    remove_instance_older_than(instance, std::time::Duration::from_secs(1))
}

/// [`remove_instance`], taking what no live node owns once it is `age` old (what is younger
/// may be a node or segment being made right now).
fn remove_instance_older_than(instance: &InstanceName, age: std::time::Duration) -> Vec<String> {
    let _ = remove_dead_nodes_older_than(instance, age);
    let _ = remove_instance_segment(instance);
    let mut left: Vec<String> = shm_files(instance)
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    let root = std::path::PathBuf::from(instance.root_dir().as_str());
    collect_files(&root, &mut left);
    if left.is_empty() {
        remove_empty_dirs(&root);
    }
    left
}

/// The shared-memory files of `instance` in `/dev/shm`: those with its prefix
/// (`iox2_<instance>_`), but not those of another instance whose name extends it
/// (`<instance>_b`, whose root folder exists beside ours).
fn shm_files(instance: &InstanceName) -> Vec<std::path::PathBuf> {
    let prefix = instance.shm_prefix();
    let root = std::path::PathBuf::from(instance.root_dir().as_str());
    let longer: Vec<String> = root
        .parent()
        .and_then(|p| std::fs::read_dir(p).ok())
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| n.starts_with(&format!("{}_", instance.as_str())))
        .map(|n| format!("iox2_{n}_"))
        .collect();
    let mut out = Vec::new();
    if let Ok(dir) = std::fs::read_dir("/dev/shm") {
        for e in dir.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with(prefix.as_str()) && !longer.iter().any(|l| name.starts_with(l)) {
                out.push(e.path());
            }
        }
    }
    out
}

/// Removes every file of `instance`: its root folder and its shared memory. For a supervisor
/// that holds the instance's lock and found no node of it alive: whatever is there was left by
/// processes killed part-way (a service created but not finalized, a node half created or half
/// removed), which iceoryx2 cannot clean up (it refuses to open such a service:
/// `HangsInCreation`, and lists such a node as neither alive nor dead). Returns the files it
/// removed.
pub fn purge_instance(instance: &InstanceName) -> Vec<String> {
    let mut files: Vec<String> = shm_files(instance)
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    let root = std::path::PathBuf::from(instance.root_dir().as_str());
    collect_files(&root, &mut files);
    files.retain(|f| std::fs::remove_file(f).is_ok());
    remove_empty_dirs(&root);
    files
}

/// Removes the services of `instance` whose creation never finished (their creator died
/// before it made the static file read-only: iceoryx2 then refuses them for ever with
/// `HangsInCreation`) and that are older than `age` (not one being created right now). For a
/// supervisor that holds the instance's lock while observers of the instance are alive (so it
/// cannot [`purge_instance`]). Returns the files it removed.
pub fn remove_unfinished_services(
    instance: &InstanceName,
    age: std::time::Duration,
) -> Vec<String> {
    use std::os::unix::fs::PermissionsExt;
    let dir = std::path::PathBuf::from(instance.root_dir().as_str()).join("services");
    let mut removed = Vec::new();
    for e in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
        let Ok(meta) = e.metadata() else { continue };
        // iceoryx2 creates a static file owner read-write and finalizes it owner read-only
        // (iceoryx2-cal's `static_storage::file`: INIT_PERMISSIONS, FINAL_PERMISSIONS).
        let unfinished = meta.is_file() && meta.permissions().mode() & 0o777 == 0o600;
        let old = meta
            .modified()
            .ok()
            .and_then(|m| m.elapsed().ok())
            .is_some_and(|a| a >= age);
        if unfinished && old && std::fs::remove_file(e.path()).is_ok() {
            removed.push(e.path().display().to_string());
        }
    }
    removed
}

/// Removes the shared memory of `instance` that was never finished and is `age` old: a
/// segment of size 0 (created, never sized) or one its owner cannot read (iceoryx2 makes a
/// dynamic storage readable once it is initialized). What a process killed while it created a
/// connection or a port leaves (an observer's CLI killed as it attached): iceoryx2 waits on such
/// a segment before it can remove a dead node's ports, one creation timeout for each, and
/// without end for one of size 0 (`posix_shared_memory::Builder::open_impl`, 0.10), which made
/// a supervisor's own node, dropped as the cell went down, wait for minutes. A live creator
/// finishes one in microseconds. Returns the paths removed.
pub fn remove_unfinished_shm(instance: &InstanceName, age: std::time::Duration) -> Vec<String> {
    use std::os::unix::fs::PermissionsExt;
    let mut removed = Vec::new();
    for path in shm_files(instance) {
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        let unfinished =
            meta.is_file() && (meta.len() == 0 || meta.permissions().mode() & 0o400 == 0);
        let old = meta
            .modified()
            .ok()
            .and_then(|m| m.elapsed().ok())
            .is_some_and(|a| a >= age);
        if unfinished && old && std::fs::remove_file(&path).is_ok() {
            removed.push(path.display().to_string());
        }
    }
    removed
}

/// [`remove_instance`], after waiting up to `patience` for the live nodes of the instance to
/// go (clients such as `supervisor status` or `inject` that are just finishing).
pub fn remove_instance_waiting(
    instance: &InstanceName,
    patience: std::time::Duration,
) -> Vec<String> {
    let start = std::time::Instant::now();
    while start.elapsed() < patience && !live_node_pids(instance).unwrap_or_default().is_empty() {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    // The supervisor holds the instance and no node of it lives: whatever is left goes, however
    // young (a client that failed to attach a moment ago, out of descriptors, left its node's
    // details; one attaching now cannot any more). With clients alive, only what is a second
    // old.
    let age = if live_node_pids(instance).is_ok_and(|p| p.is_empty()) {
        std::time::Duration::ZERO
    } else {
        std::time::Duration::from_secs(1)
    };
    remove_instance_older_than(instance, age)
}

/// For a client of an instance (status, events, inject): once its own node is gone, removes
/// what is left of the instance if no process of it is alive any more (the instance ended
/// while the client ran).
pub fn cleanup_after_client(instance: &InstanceName) {
    if live_node_pids(instance).is_ok_and(|p| p.is_empty()) {
        let _ = remove_instance(instance);
    }
}

/// Whether `e` is a real folder (a symbolic link is never followed: a link planted in the
/// instance's folder must not lead the cleanup elsewhere).
fn is_real_dir(e: &std::fs::DirEntry) -> bool {
    e.file_type().is_ok_and(|t| t.is_dir())
}

fn collect_files(dir: &std::path::Path, out: &mut Vec<String>) {
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            if is_real_dir(&e) {
                collect_files(&e.path(), out);
            } else {
                out.push(e.path().display().to_string());
            }
        }
    }
}

fn remove_empty_dirs(dir: &std::path::Path) {
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            if is_real_dir(&e) {
                remove_empty_dirs(&e.path());
            }
        }
    }
    let _ = std::fs::remove_dir(dir);
}
