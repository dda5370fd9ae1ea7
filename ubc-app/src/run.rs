//! Board layer of the program: feeds the two UARTs' interrupt-driven rings and the CLINT time
//! to [`ubc_app::program::Program`], logs its events through defmt and sleeps in WFI until
//! the program's next deadline or a received byte.

use crate::board::{Board, Clock, Uart};
use ubc_app::program::{self, BytePort, Config, LogEvent, LogSink, Program};
use ubc_hal::cpu;

/// Period of the liveness log line, in microseconds.
const STATS_PERIOD_US: u64 = 10_000_000;

struct BoardClock<'a>(&'a Clock);

impl program::Clock for BoardClock<'_> {
    fn now_us(&self) -> u64 {
        self.0.micros()
    }
}

/// A UART as the program's byte port; a missing one (no radio found) takes every byte and
/// never delivers any.
struct Port<'a>(Option<&'a mut Uart>);

impl BytePort for Port<'_> {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        self.0.as_mut().map_or(0, |u| u.read_available(buf))
    }

    fn write(&mut self, bytes: &[u8]) -> usize {
        self.0
            .as_mut()
            .map_or(bytes.len(), |u| u.write_available(bytes))
    }
}

struct Defmt;

impl LogSink for Defmt {
    fn log(&mut self, _now_us: u64, event: LogEvent) {
        // The logger stamps every line with the CLINT time already.
        match event {
            LogEvent::BringUpStarted { attempt } => {
                defmt::info!("lbc bring-up attempt {=u32}", attempt)
            }
            LogEvent::BringUpDone { car_id } => {
                defmt::info!("lbc up: car={=u8}", car_id)
            }
            LogEvent::BringUpFailed { step, retry_in_ms } => defmt::warn!(
                "lbc bring-up failed at step {=u8}, retry in {=u32} ms",
                step,
                retry_in_ms
            ),
            LogEvent::LbcLost => {
                defmt::warn!("lbc link lost: stop, bring up again")
            }
            LogEvent::LbcStateLost => {
                defmt::warn!("lbc refused motion with drive enabled: reset")
            }
            LogEvent::RadioStarted { car_id } => {
                defmt::info!("radio up: car={=u8}", car_id)
            }
            LogEvent::UserLinkLost => defmt::warn!("user link lost: stop"),
            LogEvent::UserLinkRestored => defmt::info!("user link restored"),
            LogEvent::Warnings {
                battery_low,
                over_temperature,
            } => defmt::warn!(
                "warnings: battery_low={=bool} over_temperature={=bool}",
                battery_low,
                over_temperature
            ),
            LogEvent::Console { tag, refused } => match refused {
                Some(code) => defmt::info!("console tag={=u8:#x} refused={=u8:#x}", tag, code),
                None => defmt::debug!("console tag={=u8:#x}", tag),
            },
            LogEvent::ManeuverStarted { points } => {
                defmt::info!("maneuver started: {=u8} points", points)
            }
            LogEvent::ManeuverDone => defmt::info!("maneuver done"),
            LogEvent::ManeuverAborted => defmt::info!("maneuver aborted"),
        }
    }
}

/// Runs the program forever.
pub fn run(board: Board) -> ! {
    let clock = board.clock;
    let mut lbc = board.lbc;
    let mut radio = board.radio.ok();
    let mut program = Program::new(Config::default());
    let mut next_stats = clock.micros() + STATS_PERIOD_US;
    loop {
        program.poll(
            &BoardClock(&clock),
            &mut Port(Some(&mut lbc)),
            &mut Port(radio.as_mut()),
            &mut Defmt,
        );
        let now = clock.micros();
        if now >= next_stats {
            next_stats += STATS_PERIOD_US;
            log_stats(&program, now);
        }
        let due = program.poll_at(now).min(next_stats);
        if due > now {
            clock.set_wakeup(clock.ticks_from_micros(due));
            cpu::idle_unless(|| {
                lbc.rx_len() > 0
                    || radio.as_ref().is_some_and(|r| r.rx_len() > 0)
                    || clock.micros() >= due
            });
        }
    }
}

fn log_stats(program: &Program, now_us: u64) {
    let s = program.status(now_us);
    let l = program.lbc_stats();
    defmt::info!(
        "status phase={=u8} flags={=u8:#x} x={=u16} y={=u16} hd={=u16} v={=i16} stream={=u32} timeouts={=u32} bringups={=u16}",
        s.phase,
        s.flags,
        s.x,
        s.y,
        s.heading_mrad,
        s.velocity_mm_s,
        l.stream_frames,
        l.timeouts,
        s.bringups
    );
}
