//! The periodic broadcasts: the slotted state broadcast with its ground frames and send lead,
//! and heartbeats (`docs/radio-protocol.md` section 7).

use super::*;

impl<const N: usize> Endpoint<N> {
    /// Whether every slot of the frame is taken (fresh cars, this one included), so that a
    /// ground station that is around gets ground frames
    /// ([`crate::schedule::GROUND_FRAME_EVERY`]).
    pub(super) fn ground_frames_on(&self, now: u64) -> bool {
        let around = self
            .ground_heard
            .is_some_and(|t| crate::sat_sub(now, t) <= GROUND_AROUND_US);
        (around || self.own == Address::Ground) && self.every_slot_taken(now)
    }

    /// Whether every slot of the frame is taken by a fresh car (this one included).
    fn every_slot_taken(&self, now: u64) -> bool {
        let mut used: u32 = match self.own {
            Address::Car(id) => 1 << crate::schedule::default_slot(id),
            _ => 0,
        };
        for n in self.neighbours.iter() {
            if let (Address::Car(id), false) = (n.addr, n.is_stale(now, self.stale_after_us)) {
                used |= 1 << crate::schedule::default_slot(id);
            }
        }
        used == (1 << crate::schedule::SLOTS) - 1
    }

    pub(super) fn poll_state(&mut self, now: u64) {
        let (Some(state), Address::Car(id)) = (self.state, self.own) else {
            return;
        };
        let stale = self.stale_after_us;
        let Some(s) = self.schedule.as_mut() else {
            return;
        };
        s.expire(now, stale);
        let due = s.next_due(now);
        if due > now {
            return;
        }
        // Looked at only when a broadcast is due (each scans the neighbour table).
        let ground_frames = self.ground_frames_on(now);
        let yields = self
            .schedule
            .as_ref()
            .is_some_and(|s| s.target().is_some_and(|t| s.yields(t)))
            && self.every_slot_taken(now);
        let Some(s) = self.schedule.as_mut() else {
            return;
        };
        let slot = s.own_slot();
        if ground_frames && slot < crate::schedule::GROUND_SLOTS {
            // The frame's number: the reference's count, or this car's own as slot 0's car.
            let start = crate::sat_sub(
                due + s.send_lead_us(),
                u64::from(slot) * u64::from(crate::schedule::SLOT_US),
            );
            let number = match s.reference() {
                Some(_) => s.frame_number(start),
                None => Some(self.state_seq),
            };
            if number.is_some_and(crate::schedule::is_ground_frame) {
                // Silent in the ground station's frame; slot 0's car still counts it.
                s.sent(now);
                if s.reference().is_none() {
                    self.state_seq = self.state_seq.wrapping_add(1);
                }
                self.stats.ground_frames_kept += 1;
                return;
            }
        }
        if yields {
            // The channel ran behind before this slot, and with every slot taken it has no
            // idle time to catch up in: leave this slot free.
            s.sent(now);
            self.stats.states_yielded += 1;
            return;
        }
        s.sent(now);
        let frame = Frame::State {
            src: id,
            seq: self.state_seq,
            state,
        };
        if self.queue_frame(&frame).is_ok() {
            self.state_seq = self.state_seq.wrapping_add(1);
            self.stats.states_sent += 1;
            self.last_state_sent = Some(now);
        }
    }

    /// Start of the slot a heartbeat should go in: a car's own slot; for the ground station
    /// the first slot no fresh car uses. `None`: phase unknown or no free slot.
    pub(super) fn heartbeat_slot_start(&self, now: u64) -> Option<u64> {
        let s = self.schedule.as_ref()?;
        // `N` tells the roles apart at compile time: a car's firmware carries no station code.
        if N != crate::GROUND_CARS || matches!(self.own, Address::Car(_)) {
            return s.slot_start(s.own_slot(), now);
        }
        let mut used = 0u32;
        for n in self.neighbours.iter() {
            if let (Address::Car(id), false) = (n.addr, n.is_stale(now, self.stale_after_us)) {
                used |= 1 << crate::schedule::default_slot(id);
            }
        }
        let free = (0..crate::schedule::SLOTS)
            .filter(|slot| used & (1 << slot) == 0)
            .filter_map(|slot| s.slot_start(slot, now))
            .min();
        // Every slot taken: the next ground frame, which the first cars leave silent.
        free.or_else(|| s.next_ground_frame(now))
    }

    pub(super) fn poll_heartbeat(&mut self, now: u64) {
        let due = *self.next_heartbeat.get_or_insert(now);
        if now < due {
            return;
        }
        // A car broadcasting its state needs no heartbeat.
        if let Some(t) = self.last_state_sent {
            if crate::sat_sub(now, t) < self.heartbeat_us {
                self.next_heartbeat = Some(now + self.heartbeat_us);
                return;
            }
        }
        // Send in a slot of the state schedule, so that the heartbeat does not push a
        // slotted state frame into its neighbour's slot.
        if !self.heartbeat_aligned {
            if let Some(t) = self.heartbeat_slot_start(now) {
                if t > now {
                    self.next_heartbeat = Some(t);
                    self.heartbeat_aligned = true;
                    return;
                }
            }
        }
        self.heartbeat_aligned = false;
        self.next_heartbeat = Some(now + self.heartbeat_us);
        let ground = N == crate::GROUND_CARS && self.own == Address::Ground;
        let frame = if ground {
            // The ground station's heartbeat is authenticated and counted; the counter's
            // last value starts the next epoch.
            let Some(key) = self.key.clone() else {
                return;
            };
            let mut f = Frame::GroundBeat {
                epoch: self.epoch,
                beat: self.next_beat,
                mac: [0; crate::wire::AUTH_TAG_LEN],
            };
            if auth::sign(&key, 0, &mut f).is_err() {
                return;
            }
            f
        } else {
            let uptime = crate::sat_sub(now, self.started.unwrap_or(now)) / 1_000_000;
            Frame::Heartbeat {
                src: self.own,
                beat: Heartbeat {
                    mode: self.mode,
                    neighbours: self.neighbours.fresh_count(now, self.stale_after_us) as u8,
                    uptime_s: uptime as u16,
                },
            }
        };
        if self.queue_frame(&frame).is_ok() {
            self.stats.heartbeats_sent += 1;
            if ground {
                match self.next_beat.checked_add(1) {
                    Some(b) => self.next_beat = b,
                    None => self.next_epoch(),
                }
            }
        }
    }

    /// The state broadcast queued last started on the radio UART at `at` (local time): the
    /// schedule learns how long after its due time the application writes, and makes later
    /// broadcasts due that much earlier ([`crate::schedule::Schedule::written`]).
    pub fn state_written(&mut self, at: u64) {
        if let Some(s) = self.schedule.as_mut() {
            s.written(at);
        }
    }

    /// The schedule's learned send lead in microseconds (0 without a slotted schedule).
    pub fn send_lead_us(&self) -> u64 {
        self.schedule.as_ref().map_or(0, |s| s.send_lead_us())
    }
}
