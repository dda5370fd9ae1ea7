//! Ground-station sessions: authenticated commands, the station's heartbeat, Hello and
//! SessionOpen (`docs/radio-protocol.md`, sessions).

use super::*;

impl<const N: usize> Endpoint<N> {
    pub(super) fn handle_auth(&mut self, now: u64, frame: Frame) {
        let Frame::AuthCommand {
            dst,
            counter,
            tag,
            ref payload,
            ..
        } = frame
        else {
            return;
        };
        if !self.for_us(dst) {
            return;
        }
        let Some(key) = self.key.as_ref() else {
            self.stats.auth_no_key += 1;
            return;
        };
        // Without a session the epoch of the MAC is unknown: nothing can be verified.
        let Some(mut session) = self.session else {
            if self.hellos_unanswered >= 2 {
                self.stats.auth_bad_mac += 1;
            }
            self.stats.auth_no_session += 1;
            if dst == Address::Broadcast {
                // Every car without a session heard it: answering at once would collide.
                self.hello_later(now);
            } else {
                self.hello(now, HELLO_GAP_US);
            }
            return;
        };
        if !auth::verify(key, session.epoch, &frame) {
            self.stats.auth_bad_mac += 1;
            return;
        }
        let broadcast = dst == Address::Broadcast;
        match session.commands.check(counter) {
            Freshness::Fresh => {
                let ev = Event::Request(Incoming {
                    id: IncomingId {
                        from: Address::Ground,
                        seq: counter as u16,
                        counter: Some(counter),
                        broadcast,
                    },
                    tag,
                    payload: payload.clone(),
                });
                if self.emit(ev) {
                    session.commands.accept(counter);
                    // The last counter of an epoch ends the session; the ground station
                    // continues in its next epoch, which the car joins with a Hello.
                    self.session = (counter != u32::MAX).then_some(session);
                    self.auth_reply = None;
                    self.auth_pending = if broadcast { None } else { Some(counter) };
                }
            }
            Freshness::Repeat => {
                self.stats.auth_repeat += 1;
                if let Some(r) = self.auth_reply.clone().filter(|r| r.seq == counter as u16) {
                    if !broadcast {
                        self.stats.replies_resent += 1;
                        let _ = self.send_reply(Address::Ground, &r);
                    }
                }
            }
            Freshness::Replay => self.stats.auth_replay += 1,
        }
    }

    /// A ground-station heartbeat: it counts (as [`Event::Heartbeat`] from the ground station)
    /// only when it verifies and is fresh in the car's session.
    pub(super) fn handle_beat(&mut self, now: u64, frame: Frame) {
        let Frame::GroundBeat { epoch, beat, .. } = frame else {
            return;
        };
        let Some(key) = self.key.as_ref() else {
            self.stats.auth_no_key += 1;
            return;
        };
        if !matches!(self.own, Address::Car(_)) {
            return;
        }
        if !auth::verify(key, 0, &frame) {
            self.stats.auth_bad_mac += 1;
            return;
        }
        let Some(mut session) = self.session.filter(|s| s.epoch == epoch) else {
            // Our ground station in another session (it restarted, or we did). Every car
            // heard this heartbeat at the same instant.
            self.stats.auth_no_session += 1;
            self.hello_later(now);
            return;
        };
        if session.beats.check(beat) != Freshness::Fresh {
            self.stats.auth_replay += 1;
            return;
        }
        session.beats.accept(beat);
        self.session = (beat != u32::MAX).then_some(session);
        self.emit(Event::Heartbeat {
            from: Address::Ground,
            beat: Heartbeat::default(),
        });
    }

    /// Car: asks the ground station for a session, at most once per `gap`.
    pub(super) fn hello(&mut self, now: u64, gap: u64) {
        let (Some(key), Address::Car(src)) = (self.key.as_ref(), self.own) else {
            return;
        };
        if self.hello_at.is_some_and(|t| crate::sat_sub(now, t) < gap) {
            return;
        }
        let nonce = self.next_nonce;
        let mut frame = Frame::Hello {
            src,
            nonce,
            mac: [0; crate::wire::AUTH_TAG_LEN],
        };
        if auth::sign(key, 0, &mut frame).is_ok() && self.queue_frame(&frame).is_ok() {
            self.next_nonce = nonce.wrapping_add(1);
            self.hello_nonce = Some(nonce);
            self.hello_at = Some(now);
            self.hellos_unanswered = self.hellos_unanswered.saturating_add(1);
            self.stats.hellos_sent += 1;
        }
    }

    /// Car: a Hello after a random delay of up to [`HELLO_REACT_JITTER_US`] (one already
    /// planned stands).
    pub(super) fn hello_later(&mut self, now: u64) {
        if self.hello_soon.is_none() && self.key.is_some() {
            let delay = u64::from(self.random()) % HELLO_REACT_JITTER_US;
            self.hello_soon = Some(now + delay);
        }
    }

    /// Ground station: answers a car's Hello with a session in its epoch. Command counters
    /// from the oldest one still being sent are accepted, heartbeats from the next one.
    pub(super) fn handle_hello(&mut self, now: u64, frame: Frame) {
        let (Frame::Hello { src, nonce, .. }, Some(key)) = (&frame, self.key.as_ref()) else {
            return;
        };
        // `N` tells the roles apart at compile time: a car's firmware carries no station code.
        if N != crate::GROUND_CARS || self.own != Address::Ground {
            return;
        }
        if !auth::verify(key, 0, &frame) {
            self.stats.auth_bad_mac += 1;
            return;
        }
        let Some(n) = self.neighbours.get_mut(Address::Car(*src)) else {
            return;
        };
        if n.session_sent
            .is_some_and(|t| crate::sat_sub(now, t) < SESSION_OPEN_GAP_US)
        {
            return;
        }
        n.session_sent = Some(now);
        let command_min = self
            .pending
            .iter()
            .filter(|p| p.auth)
            .map(|p| p.counter)
            .min()
            .unwrap_or(self.next_command);
        let mut open = Frame::SessionOpen {
            dst: *src,
            nonce: *nonce,
            epoch: self.epoch,
            command_min,
            beat_min: self.next_beat,
            mac: [0; crate::wire::AUTH_TAG_LEN],
        };
        if auth::sign(key, 0, &mut open).is_ok() && self.queue_frame(&open).is_ok() {
            self.stats.sessions_opened += 1;
        }
    }

    /// Car: joins the session of a SessionOpen answering its last Hello.
    pub(super) fn handle_open(&mut self, frame: Frame) {
        let Frame::SessionOpen {
            dst,
            nonce,
            epoch,
            command_min,
            beat_min,
            ..
        } = frame
        else {
            return;
        };
        if self.own != Address::Car(dst) {
            self.stats.not_for_us += 1;
            return;
        }
        let verified = self
            .key
            .as_ref()
            .is_some_and(|k| auth::verify(k, 0, &frame));
        if !verified || self.hello_nonce != Some(nonce) {
            self.stats.sessions_refused += 1;
            return;
        }
        self.hello_nonce = None;
        self.hello_soon = None;
        self.hellos_unanswered = 0;
        let mut session = Session {
            epoch,
            commands: ReplayGuard::from_min(command_min).max(self.guard),
            beats: ReplayGuard::from_min(beat_min),
        };
        if let Some(old) = self.session.filter(|s| s.epoch == epoch) {
            // The same session again (a repeated Hello): never lower its floors.
            session.commands = session.commands.max(old.commands);
            session.beats = session.beats.max(old.beats);
        } else {
            self.auth_reply = None;
            self.auth_pending = None;
        }
        self.session = Some(session);
        self.stats.sessions_opened += 1;
    }
}
