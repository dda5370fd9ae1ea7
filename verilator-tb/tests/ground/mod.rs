//! A radio-mac ground station for the firmware tests: it acknowledges the car's notices, sends
//! console requests to one car and collects their replies. On the SoC it sits on the radio UART
//! through [`GroundPeer`]; next to QEMU the test feeds it the radio bytes itself.

use radio_mac::RequestHandle;
use radio_mac::{Address, CarId, Event, GroundConfig, GroundStation, Incoming, Key};
use std::cell::RefCell;
use std::rc::Rc;
use ubc_app::program::console::{Reply, Request, Tag};
use ubc_app::program::DEFAULT_KEY;
use verilator_tb::cosim::SerialPeer;

/// The ground station of one car.
pub struct Ground {
    gs: GroundStation,
    car: CarId,
    /// Deaf and silent until the first request (what the car sends meanwhile is dropped).
    listening: bool,
    /// Console replies by request; `None` when the radio gave up.
    answers: Vec<(RequestHandle, Option<Reply>)>,
}

impl Ground {
    /// A ground station (testbed key) for car `car`; with `wait_for_first_request` it stays deaf
    /// and silent until [`Ground::request`] is first called.
    pub fn new(car: u8, wait_for_first_request: bool) -> Self {
        Self {
            gs: GroundStation::new(GroundConfig::new(Key::new(DEFAULT_KEY), 1)),
            car: CarId::new(car).expect("car id"),
            listening: !wait_for_first_request,
            answers: Vec::new(),
        }
    }

    /// Bytes heard on the radio at `now_us`.
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) {
        if self.listening {
            self.gs.push_rx(now_us, bytes);
        }
    }

    /// Advances to `now_us`: acknowledges notices, records replies, appends what it sends.
    pub fn advance(&mut self, now_us: u64, out: &mut Vec<u8>) {
        if !self.listening {
            return;
        }
        self.gs.poll(now_us);
        while let Some(ev) = self.gs.next_event() {
            match ev {
                Event::Request(Incoming { id, tag, .. }) if tag == Tag::Notice as u8 => {
                    let _ = self.gs.reply(id, tag, &[]);
                }
                Event::Reply {
                    handle,
                    tag,
                    payload,
                    ..
                } => {
                    let reply = Reply::decode(tag, &payload)
                        .unwrap_or_else(|e| panic!("console reply does not decode: {e:?}"));
                    self.answers.push((handle, Some(reply)));
                }
                Event::Failed { handle, .. } => self.answers.push((handle, None)),
                _ => {}
            }
        }
        let mut buf = [0u8; 256];
        loop {
            let n = self.gs.transmit(&mut buf);
            if n == 0 {
                break;
            }
            out.extend_from_slice(&buf[..n]);
        }
    }

    /// Sends a console request to the car at `now_us`.
    pub fn request(&mut self, now_us: u64, req: &Request) -> RequestHandle {
        self.listening = true;
        let mut buf = [0u8; 64];
        let n = req.encode(&mut buf).expect("encode");
        self.gs
            .command(now_us, Address::Car(self.car), req.tag() as u8, &buf[..n])
            .expect("ground command")
    }

    /// The answer to `h` once it came; panics if the radio gave up on it.
    pub fn answer(&mut self, h: RequestHandle) -> Option<Reply> {
        let i = self.answers.iter().position(|(x, _)| *x == h)?;
        match self.answers.swap_remove(i).1 {
            Some(r) => Some(r),
            None => panic!("the radio gave up on a console request"),
        }
    }
}

/// The SoC's radio peer: a [`Ground`] shared with the test's script.
pub struct GroundPeer(pub Rc<RefCell<Ground>>);

impl SerialPeer for GroundPeer {
    fn receive(&mut self, t_us: u64, byte: u8) {
        self.0.borrow_mut().receive(t_us, &[byte]);
    }

    fn advance(&mut self, now_us: u64, out: &mut Vec<(u64, u8)>) {
        let mut bytes = Vec::new();
        self.0.borrow_mut().advance(now_us, &mut bytes);
        out.extend(bytes.into_iter().map(|b| (now_us, b)));
    }
}
