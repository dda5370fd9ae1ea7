//! The program loop inside the program: its state, its console requests and its run at each
//! stream sample (`program::user`).

use super::super::console::{Notice, Refusal, Reply, Tag};
use super::super::group::{lbc_command, neighbours, SendGate};
use super::super::user::{self, ProgramInput, UserProgram};
use super::super::LogSink;
use super::{LogEvent, Owner, Phase, Program};
use radio_mac::{CarMac, IncomingId};

/// The program loop's state (the loop itself is passed to [`Program::poll_with`]).
#[derive(Debug, Default)]
pub(super) struct UserState {
    /// The firmware has a program loop (set at every poll).
    pub(super) present: bool,
    pub(super) running: bool,
    /// Arguments of a start not yet handed to the loop.
    pub(super) start: Option<user::Args>,
    /// A stop not yet told to the loop.
    pub(super) stop: bool,
    /// A STREAM sample arrived since the loop last ran.
    pub(super) sample: bool,
    pub(super) progress: (u8, u8),
    pub(super) gate: SendGate<maneuvers::Command>,
}

impl Program {
    /// `program start`: the loop runs from the next sample with `args`.
    pub(super) fn program_start<S: LogSink + ?Sized>(
        &mut self,
        now: u64,
        id: IncomingId,
        args: user::Args,
        log: &mut S,
    ) -> Option<Refusal> {
        if !self.user.present {
            return Some(Refusal::NoProgram);
        }
        if self.phase != Phase::Running {
            return Some(Refusal::NotReady);
        }
        if !self.drive_enabled {
            return Some(Refusal::DriveDisabled);
        }
        self.stop_maneuvers(now, log);
        self.user.start = Some(args);
        self.user.running = true;
        self.user.progress = (0, 0);
        self.user.gate.reset();
        log.log(now, LogEvent::ProgramStarted);
        self.respond(id, Tag::ProgramStart as u8, &Reply::ProgramStarted);
        None
    }

    /// The program loop: hands it a pending start or stop, and runs it at a new sample
    /// while the car can drive.
    pub(super) fn run_user<U, S>(&mut self, now: u64, program: &mut U, log: &mut S)
    where
        U: UserProgram + ?Sized,
        S: LogSink + ?Sized,
    {
        if core::mem::take(&mut self.user.stop) {
            program.stop();
        }
        if let Some(args) = self.user.start.take() {
            program.start(now, &args);
        }
        let sample = core::mem::take(&mut self.user.sample);
        if !(self.user.running && sample && self.phase == Phase::Running && self.drive_enabled) {
            return;
        }
        let v = &self.vehicle;
        let own = maneuvers::CarPose {
            x: v.x,
            y: v.y,
            heading_mrad: v.heading,
            velocity_mm_s: v.velocity,
        };
        let id = self.mac.as_ref().map_or(0, |m| m.id().get());
        let others = neighbours(now, self.mac.as_ref().map(CarMac::neighbours));
        let step = program.step(&ProgramInput {
            now_us: now,
            id,
            own,
            neighbours: &others,
        });
        self.user.progress = program.progress();
        match step {
            user::Step::Drive(m) => {
                let may_send = !self.owned.iter().any(|(_, o)| matches!(o, Owner::Group));
                if let Some(m) = self.user.gate.offer(now, m, may_send) {
                    if !self.send(now, lbc_command(m), Owner::Group) {
                        self.user.gate.reset();
                    }
                }
            }
            user::Step::Done => {
                self.user.running = false;
                self.send_stop(now);
                log.log(now, LogEvent::ProgramDone);
                self.notice(now, Notice::ManeuverDone);
            }
        }
    }
}
