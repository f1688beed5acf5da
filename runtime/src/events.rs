//! Writing events (`shm_schema::event`) on the cell's `<i>/events` service.

use crate::ipc::{Ipc, IpcError, Pub};
use iceoryx2::prelude::Node;
use shm_schema::{EventQueue, EventV1, InstanceName, ServiceId};

/// One process' publisher of events: it numbers them and stamps its source.
#[derive(Debug)]
pub struct EventSink {
    port: Pub<EventV1>,
    source: u32,
    seq: u64,
    dropped_reported: u64,
}

impl EventSink {
    /// Opens `<i>/events` for `source` (a `Role` as `u32`, or
    /// [`shm_schema::event::SOURCE_SUPERVISOR`]).
    pub fn new(node: &Node<Ipc>, instance: &InstanceName, source: u32) -> Result<Self, IpcError> {
        Ok(Self {
            port: Pub::new(node, instance, ServiceId::Events)?,
            source,
            seq: 0,
            dropped_reported: 0,
        })
    }

    /// Connects to the subscribers present now (set-up; iceoryx2 would otherwise do it on
    /// the first publish).
    pub fn connect(&self) {
        self.port.update_connections();
    }

    /// Publishes `e` with the next sequence number and this source.
    ///
    /// # Real-time
    /// One publish (IPC call).
    pub fn emit(&mut self, mut e: EventV1) {
        self.seq += 1;
        e.seq = self.seq;
        e.source = self.source;
        self.port.send(&e);
    }

    /// Publishes every event of `q`, oldest first, and empties it.
    ///
    /// # Real-time
    /// One publish per event (IPC calls).
    pub fn drain(&mut self, q: &mut EventQueue) {
        for e in q.as_slice() {
            self.emit(*e);
        }
        if q.dropped > self.dropped_reported {
            let new = q.dropped - self.dropped_reported;
            self.dropped_reported = q.dropped;
            let stamp = q.as_slice().last().map_or(0, |e| e.stamp_ns);
            self.emit(EventV1::new(
                stamp,
                shm_schema::event::code::EVENTS_DROPPED,
                -1,
                new as f64,
                shm_schema::event::EVENT_QUEUE_CAP as f64,
                &["a cycle queued more events than its queue holds"],
            ));
        }
        q.clear();
    }
}
