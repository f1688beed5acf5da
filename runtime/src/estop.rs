//! The e-stop as every real-time process sees it in its own cycle (seed 002).
//!
//! [`EstopWatch::poll`] runs at the start of every cycle: it reads `<i>/estop` (triggers from
//! any process, the supervisor or a user's tool; resets from the supervisor) and
//! `<i>/host/state` (the supervisor's heartbeat and latched state), applies the propagation
//! rules of the cell (`propagate_estop`, `propagate_external_estop`) and the process'
//! `network_estop_config`, and tells the task whether to react. Nothing in this path waits
//! for the supervisor: a trigger published by servo reaches iobridge in iobridge's next
//! cycle, whether the supervisor runs or not.

use crate::ipc::{Ipc, IpcError, Pub, Sub};
use iceoryx2::prelude::Node;
use shm_schema::estop::{EstopKind, EstopState, HostStateV1};
use shm_schema::event::code;
use shm_schema::{
    CellConfigV6, EstopOrigin, EstopReaction, EstopV1, EventQueue, EventV1, InstanceName,
    ServiceId, str_of,
};

/// What the task is told about the e-stop in a cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EstopView {
    /// The cell's e-stop is latched (any source, whether this process reacts or not).
    pub latched: bool,
    /// This process must react now: `Some(reaction)` (never `Ignore`).
    pub react: Option<EstopReaction>,
    /// When the e-stop this process reacts to was raised (ns), 0 for none.
    pub since_ns: u64,
    /// The cause, when latched.
    pub cause: Option<EstopV1>,
}

/// A process' watch on the cell's e-stop; see the module documentation.
#[derive(Debug)]
pub struct EstopWatch {
    triggers: Sub<EstopV1>,
    host: Sub<HostStateV1>,
    publisher: Pub<EstopV1>,
    index: u32,
    reaction: EstopReaction,
    propagate_estop: bool,
    propagate_external: bool,
    supervisor_timeout_ns: u64,
    view: EstopView,
    resets: u64,
    raised: bool,
    last_beat: u64,
    last_beat_change_ns: u64,
    supervisor_lost: bool,
    leaving: bool,
    handover: bool,
}

impl EstopWatch {
    /// Opens the e-stop services for process `index` of `cell`.
    pub fn new(
        node: &Node<Ipc>,
        instance: &InstanceName,
        cell: &CellConfigV6,
        index: usize,
        now_ns: u64,
    ) -> Result<Self, IpcError> {
        let reaction = cell
            .processes()
            .get(index)
            .and_then(|p| EstopReaction::from_wire(p.network_estop_config))
            .unwrap_or(EstopReaction::Stop);
        Ok(Self {
            triggers: Sub::new(node, instance, ServiceId::Estop, 64)?,
            host: Sub::new(node, instance, ServiceId::HostState, 1)?,
            publisher: Pub::new(node, instance, ServiceId::Estop)?,
            index: index as u32,
            reaction,
            propagate_estop: cell.propagate_estop != 0,
            propagate_external: cell.propagate_external_estop != 0,
            supervisor_timeout_ns: cell.supervisor_timeout_ns,
            view: EstopView::default(),
            resets: 0,
            raised: false,
            last_beat: 0,
            last_beat_change_ns: now_ns,
            supervisor_lost: false,
            leaving: false,
            handover: false,
        })
    }

    /// Connects the ports (set-up), so the first cycle does not pay for it.
    pub fn connect(&self) {
        self.publisher.update_connections();
    }

    /// The view of the latest [`EstopWatch::poll`].
    pub fn view(&self) -> &EstopView {
        &self.view
    }

    /// True once the supervisor has stopped beating (the process leaves once safe).
    pub fn supervisor_lost(&self) -> bool {
        self.supervisor_lost
    }

    /// True once the process is leaving (a stop request, or the supervisor lost).
    pub fn leaving(&self) -> bool {
        self.leaving || self.supervisor_lost
    }

    /// True while the supervisor replaces a process of the cell: missing samples are not
    /// pending-sequence overruns meanwhile.
    pub fn handover(&self) -> bool {
        self.handover
    }

    /// True when this process raised the latched e-stop.
    pub fn raised(&self) -> bool {
        self.raised
    }

    /// Reads the e-stop services at `now_ns`; returns true when a reset cleared the e-stop
    /// in this call (the runtime restarts its detectors).
    ///
    /// # Real-time
    /// IPC calls and arithmetic.
    pub fn poll(&mut self, now_ns: u64, events: &mut EventQueue) -> bool {
        let mut reset = false;
        while let Some(e) = self.triggers.next() {
            reset |= self.apply(&e);
        }
        if let Some(h) = self.host.latest() {
            self.handover = h.handover != 0;
            if h.beat != self.last_beat {
                self.last_beat = h.beat;
                self.last_beat_change_ns = now_ns;
            }
            if h.resets > self.resets {
                self.resets = h.resets;
                reset |= self.clear();
            }
            // A host state from before the newest reset this process took is stale.
            if h.estop == EstopState::Latched as u32
                && !self.view.latched
                && h.resets >= self.resets
            {
                self.apply(&h.cause);
            }
        }
        if !self.supervisor_lost
            && self.supervisor_timeout_ns > 0
            && now_ns.saturating_sub(self.last_beat_change_ns) > self.supervisor_timeout_ns
        {
            self.supervisor_lost = true;
            let age = now_ns.saturating_sub(self.last_beat_change_ns) as f64 * 1e-9;
            events.push(EventV1::new(
                now_ns,
                code::SUPERVISOR_LOST,
                -1,
                age,
                self.supervisor_timeout_ns as f64 * 1e-9,
                &["no supervisor heartbeat: axes to rest, then exit"],
            ));
            self.raise(
                now_ns,
                EstopOrigin::Host,
                code::SUPERVISOR_LOST,
                &["supervisor lost"],
                events,
            );
        }
        if self.supervisor_lost || self.leaving {
            // Leaving: bring everything to a safe stop whatever the configuration says.
            self.view.react = Some(EstopReaction::Stop);
            if self.view.since_ns == 0 {
                self.view.since_ns = now_ns;
            }
        }
        reset
    }

    /// A stop was requested (SIGTERM): from the next [`EstopWatch::poll`] on, react as to an
    /// e-stop until safe, then leave.
    pub fn leave(&mut self) {
        self.leaving = true;
    }

    /// Raises an e-stop from this process: publishes it and latches it here at once (this
    /// process reacts, whatever the propagation rules say of the others).
    ///
    /// # Real-time
    /// One publish (IPC call).
    pub fn raise(
        &mut self,
        now_ns: u64,
        origin: EstopOrigin,
        cause: u32,
        parts: &[&str],
        events: &mut EventQueue,
    ) {
        let e = EstopV1::trigger(now_ns, origin, self.index, cause, parts);
        if !self.view.latched {
            events.push(EventV1::new(
                now_ns,
                code::ESTOP_RAISED,
                -1,
                origin as u32 as f64,
                cause as f64,
                &[str_of(&e.reason)],
            ));
        }
        self.publisher.send(&e);
        self.raised = true;
        self.apply(&e);
    }

    /// One record; true when it was a reset that cleared the e-stop.
    fn apply(&mut self, e: &EstopV1) -> bool {
        if e.kind == EstopKind::Reset as u32 {
            // A reset carries the number of resets so far in `code`.
            if u64::from(e.code) > self.resets {
                self.resets = u64::from(e.code);
                return self.clear();
            }
            return false;
        }
        if e.kind != EstopKind::Trigger as u32 {
            return false;
        }
        let origin = EstopOrigin::from_wire(e.origin).unwrap_or(EstopOrigin::Host);
        let mine = e.source == self.index;
        let applies = mine || origin.propagates(self.propagate_estop, self.propagate_external);
        if !self.view.latched {
            self.view.latched = true;
            self.view.cause = Some(*e);
        }
        if applies && self.view.react.is_none() && self.reaction != EstopReaction::Ignore {
            self.view.react = Some(self.reaction);
            self.view.since_ns = e.stamp_ns;
        }
        false
    }

    fn clear(&mut self) -> bool {
        let was = self.view.latched;
        self.raised = false;
        if self.leaving || self.supervisor_lost {
            // No reset brings back a process that is leaving.
            self.view.latched = false;
            self.view.cause = None;
            return was;
        }
        self.view = EstopView::default();
        was
    }
}
