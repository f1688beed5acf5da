//! Servo's controller and the machine model in one process, in the order the cell runs them:
//! the drives sample and apply the newest command (phase 100 µs), servo reads that sample and
//! commands (phase 400 µs), the drives apply it at their next cycle.

use machine_sim::Machine;
use servo::{Controller, Params as ServoParams};
use shm_schema::drive::servo_status as st;
use shm_schema::{
    CellConfigV6, DriveCommandV2, DriveFeedbackV2, EventQueue, EventV1, FaultInjectionV1,
    RequestKind, ServoRequestV1, ServoStateV3, SetpointV2,
};

pub const MS: u64 = 1_000_000;

pub struct Loop {
    pub machine: Machine,
    pub servo: Controller,
    pub fb: Option<DriveFeedbackV2>,
    pub cmd: Option<DriveCommandV2>,
    pub state: ServoStateV3,
    /// Every event so far.
    pub events: Vec<EventV1>,
    queue: EventQueue,
    /// Time of the next machine cycle (ns).
    pub now: u64,
    pub period: u64,
    /// Servo's phase after the machine's (ns).
    offset: u64,
    request_seq: u64,
}

impl Loop {
    pub fn new(cell: &CellConfigV6) -> Self {
        let proc = |name: &str| *cell.process_named(name).expect("in the table").1;
        let (machine, servo) = (proc("drives"), proc("servo"));
        Self {
            machine: Machine::new(cell, machine.period_ns),
            servo: Controller::new(ServoParams::from_cell(
                cell,
                servo.period_ns,
                cell.period_of("trajgen").expect("trajgen"),
            )),
            fb: None,
            cmd: None,
            state: ServoStateV3::default(),
            events: Vec::new(),
            queue: EventQueue::default(),
            now: 1_000_000_000 + machine.phase_ns,
            period: servo.period_ns,
            offset: servo.phase_ns - machine.phase_ns,
            request_seq: 0,
        }
    }

    /// One period: the machine's cycle, then servo's (with `request` and `setpoint`).
    pub fn step_with(
        &mut self,
        request: Option<RequestKind>,
        setpoint: Option<&SetpointV2>,
        inject: Option<&FaultInjectionV1>,
    ) -> ServoStateV3 {
        let fb = self
            .machine
            .cycle(self.now, self.cmd.as_ref(), inject, &mut self.queue);
        self.fb = Some(fb);
        let r = request.map(|k| {
            self.request_seq += 1;
            ServoRequestV1 {
                seq: self.request_seq,
                kind: k as u32,
                axis: 0,
                value: 0.0,
            }
        });
        let (cmd, state) = self.servo.cycle(
            self.now + self.offset,
            r.as_ref(),
            setpoint,
            self.fb.as_ref(),
            &mut self.queue,
        );
        self.cmd = Some(cmd);
        self.state = state;
        self.events.extend_from_slice(self.queue.as_slice());
        self.queue.clear();
        self.now += self.period;
        state
    }

    /// `cycles` periods in which only the machine runs (servo stalled): it applies the last
    /// command it got.
    pub fn servo_stalls(&mut self, cycles: u64) {
        for _ in 0..cycles {
            let fb = self
                .machine
                .cycle(self.now, self.cmd.as_ref(), None, &mut self.queue);
            self.fb = Some(fb);
            self.now += self.period;
        }
        self.events.extend_from_slice(self.queue.as_slice());
        self.queue.clear();
    }

    /// Servo's cycle alone, at its phase of this period, with `request` and feedback `fb`
    /// (the machine does not run, the time does not advance): its state; its events join the
    /// others.
    pub fn servo_only(
        &mut self,
        request: Option<&ServoRequestV1>,
        fb: Option<&DriveFeedbackV2>,
    ) -> ServoStateV3 {
        let (_, state) =
            self.servo
                .cycle(self.now + self.offset, request, None, fb, &mut self.queue);
        self.events.extend_from_slice(self.queue.as_slice());
        self.queue.clear();
        state
    }

    pub fn step(&mut self) -> ServoStateV3 {
        self.step_with(None, None, None)
    }

    /// Requests `kind` and runs until `done` holds (at most `cycles`); panics otherwise.
    pub fn until(
        &mut self,
        kind: Option<RequestKind>,
        cycles: usize,
        done: impl Fn(&ServoStateV3) -> bool,
    ) -> ServoStateV3 {
        let mut s = self.step_with(kind, None, None);
        for _ in 0..cycles {
            if done(&s) {
                return s;
            }
            s = self.step();
        }
        panic!(
            "not reached in {cycles} cycles: status {:#x}, events {:?}",
            s.status,
            self.codes()
        );
    }

    /// [`Loop::new`] of `cell`, the arm enabled.
    pub fn enabled(cell: &CellConfigV6) -> Self {
        let mut lp = Self::new(cell);
        lp.enable();
        lp
    }

    /// Enables the arm.
    pub fn enable(&mut self) -> ServoStateV3 {
        self.until(None, 10, |s| s.status & st::INITIALIZED != 0);
        self.until(Some(RequestKind::Enable), 50, |s| {
            s.status & st::ENABLED != 0
        })
    }

    /// The codes of every event so far.
    pub fn codes(&self) -> Vec<u32> {
        self.events.iter().map(|e| e.code).collect()
    }
}
