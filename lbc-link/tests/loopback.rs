//! The UBC client against a minimal LBC built from `CommandParser`, over a wire
//! that can corrupt bytes.

use lbc_link::client::{Client, Event, Failure, Instant};
use lbc_link::lbc::{CommandParser, Incoming};
use lbc_link::{
    Command, EepromAddress, LbcMessage, Position, Reply, StreamFormat, StreamSample,
    SystemVariable, UserRegister, VehicleId, MAX_FRAME_LEN,
};
use proptest::prelude::*;

/// Answers like an LBC with a 64-register EEPROM and a fixed position.
struct FakeLbc {
    parser: CommandParser,
    eeprom: [u16; 64],
    format: StreamFormat,
    out: Vec<u8>,
}

impl FakeLbc {
    fn new() -> Self {
        Self {
            parser: CommandParser::new(),
            eeprom: [0; 64],
            format: StreamFormat::EMPTY,
            out: Vec::new(),
        }
    }

    fn send(&mut self, msg: LbcMessage) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = msg.emit(&mut buf).unwrap();
        self.out.extend_from_slice(&buf[..n]);
    }

    fn receive(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match self.parser.push(b) {
                Some(Incoming::Command(cmd)) => self.execute(cmd),
                Some(Incoming::Respond(msg)) => self.send(msg),
                Some(Incoming::Ignore(_)) | None => {}
            }
        }
    }

    fn execute(&mut self, cmd: Command) {
        let reply = match cmd {
            Command::ReadId => Reply::ReadId(VehicleId::new(7).unwrap()),
            Command::ReadXy => Reply::ReadXy(Position::new(100, 200).unwrap()),
            Command::ReadSf => Reply::ReadSf(self.format),
            Command::UpdSf(f) => {
                self.format = f;
                Reply::Echo(cmd)
            }
            Command::WritEp { address, value } => {
                self.eeprom[usize::from(address.get())] = value;
                Reply::Echo(cmd)
            }
            Command::ReadEp(address) => {
                self.send(LbcMessage::Reply(Reply::Echo(cmd)));
                Reply::ReadEpData {
                    address,
                    value: self.eeprom[usize::from(address.get())],
                }
            }
            other => Reply::Echo(other),
        };
        self.send(LbcMessage::Reply(reply));
    }

    fn stream(&mut self) {
        let sample = StreamSample {
            position: Some(Position::new(100, 200).unwrap()),
            ..StreamSample::default()
        };
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = sample.emit(self.format, &mut buf).unwrap();
        self.out.extend_from_slice(&buf[..n]);
    }
}

/// Runs client and LBC in 1 ms steps; `corrupt(step, byte)` may alter UBC->LBC bytes.
fn run(
    client: &mut Client,
    lbc: &mut FakeLbc,
    steps: u64,
    mut corrupt: impl FnMut(u64, u8) -> u8,
) -> Vec<Event> {
    let mut events = Vec::new();
    for t in 0..steps {
        let now = Instant::from_millis(t);
        let mut buf = [0u8; 64];
        let n = client.transmit(&mut buf);
        let sent: Vec<u8> = buf[..n].iter().map(|&b| corrupt(t, b)).collect();
        lbc.receive(&sent);
        if t % 33 == 32 && lbc.format != StreamFormat::EMPTY {
            lbc.stream();
        }
        let rx = std::mem::take(&mut lbc.out);
        client.poll(now, &rx, |e| events.push(e));
    }
    events
}

fn done_replies(events: &[Event]) -> Vec<Reply> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Done { reply, .. } => Some(*reply),
            _ => None,
        })
        .collect()
}

#[test]
fn eeprom_write_then_read() {
    let mut client = Client::default();
    let mut lbc = FakeLbc::new();
    let t0 = Instant::from_millis(0);
    let reg = UserRegister::new(0x2A).unwrap();
    client
        .send(
            t0,
            Command::WritEp {
                address: reg,
                value: 0x1234,
            },
        )
        .unwrap();
    client.send(t0, Command::ReadEp(reg.into())).unwrap();
    let events = run(&mut client, &mut lbc, 10, |_, b| b);
    assert_eq!(
        done_replies(&events)[1],
        Reply::ReadEpData {
            address: EepromAddress::new(0x2A).unwrap(),
            value: 0x1234
        }
    );
    assert!(client.is_idle());
}

#[test]
fn corrupted_command_is_resent_after_cser() {
    let mut client = Client::default();
    let mut lbc = FakeLbc::new();
    client
        .send(Instant::from_millis(0), Command::ReadId)
        .unwrap();
    // Flip a bit of the checksum byte on the first transmission only.
    let events = run(&mut client, &mut lbc, 10, |t, b| {
        if t == 0 && b == 0x68 {
            0x69
        } else {
            b
        }
    });
    assert_eq!(
        done_replies(&events),
        [Reply::ReadId(VehicleId::new(7).unwrap())]
    );
    let s = client.stats();
    assert_eq!((s.cser, s.retries, s.sent, s.acked), (1, 1, 2, 1));
}

#[test]
fn streaming_after_upd_sf_is_decoded() {
    let mut client = Client::default();
    let mut lbc = FakeLbc::new();
    let format = StreamFormat::EMPTY.with(SystemVariable::Position);
    client
        .send(Instant::from_millis(0), Command::UpdSf(format))
        .unwrap();
    client.send(Instant::from_millis(0), Command::Sten).unwrap();
    let events = run(&mut client, &mut lbc, 100, |_, b| b);
    let samples: Vec<_> = events
        .iter()
        .filter_map(|e| match e {
            Event::Stream(Ok(s)) => Some(s.position),
            _ => None,
        })
        .collect();
    assert_eq!(samples.len(), 3);
    assert!(samples
        .iter()
        .all(|p| *p == Some(Position::new(100, 200).unwrap())));
}

#[test]
fn dead_lbc_times_out() {
    let mut client = Client::default();
    client
        .send(Instant::from_millis(0), Command::ReadXy)
        .unwrap();
    let mut events = Vec::new();
    for t in 0..200 {
        let mut sink = [0u8; 16];
        client.transmit(&mut sink);
        client.poll(Instant::from_millis(t), &[], |e| events.push(e));
    }
    assert!(matches!(
        events[..],
        [Event::Failed {
            failure: Failure::TimedOut,
            command: Command::ReadXy,
            ..
        }]
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// With random single-byte corruption on the way to the LBC, every request
    /// still ends (done or failed) and the client never panics.
    #[test]
    fn every_request_ends_despite_corruption(
        hits in proptest::collection::vec((0u64..12, any::<u8>()), 0..6)
    ) {
        let mut client = Client::default();
        let mut lbc = FakeLbc::new();
        let t0 = Instant::from_millis(0);
        let cmds = [Command::ReadId, Command::ReadXy, Command::Stop, Command::ReadSf];
        for c in cmds {
            client.send(t0, c).unwrap();
        }
        let events = run(&mut client, &mut lbc, 1000, |t, b| {
            hits.iter().find(|(at, _)| *at == t).map_or(b, |(_, v)| *v)
        });
        let ended = events
            .iter()
            .filter(|e| matches!(e, Event::Done { .. } | Event::Failed { .. }))
            .count();
        prop_assert_eq!(ended, cmds.len());
        prop_assert!(client.is_idle());
    }
}
