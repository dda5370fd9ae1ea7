//! A car's radio side run in real time on a socket, for testing the hub and the ground
//! station against a peer that follows the slot schedule.

use super::*;

/// What a [`RealtimeCar`] saw.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CarReport {
    /// Its protocol counters.
    pub stats: radio_mac::Stats,
    /// Requests and commands executed, in order: (tag, payload, authenticated).
    pub executed: Vec<(u8, Vec<u8>, bool)>,
    /// State broadcasts heard from other cars, per car ID.
    pub states_heard: Vec<(u8, u32)>,
    /// The connection was made.
    pub connected: bool,
}

/// A car's radio side run in real time on a socket: broadcasts a fixed state in its slot
/// and answers every request or command with the same tag and payload.
#[derive(Debug)]
pub struct RealtimeCar {
    report: Arc<Mutex<CarReport>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl RealtimeCar {
    /// Start a car that connects to `endpoint` (`unix:` or `tcp:`; retried for up to
    /// `connect_within`).
    pub fn spawn(
        endpoint: EndpointSpec,
        config: CarConfig,
        state: CarState,
        connect_within: Duration,
    ) -> io::Result<Self> {
        let report = Arc::new(Mutex::new(CarReport::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let (r, s) = (report.clone(), stop.clone());
        let thread = thread::Builder::new()
            .name(format!("car-{}", config.id.get()))
            .spawn(move || {
                let deadline = Instant::now() + connect_within;
                let Some(stream) = connect_until(&endpoint, deadline, &s) else {
                    return;
                };
                run_car(stream, config, state, &r, &s);
            })?;
        Ok(Self {
            report,
            stop,
            thread: Some(thread),
        })
    }

    /// What the car saw so far.
    pub fn report(&self) -> CarReport {
        self.report
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Stop the car and return what it saw.
    pub fn stop(mut self) -> CarReport {
        self.halt();
        self.report()
    }

    fn halt(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for RealtimeCar {
    fn drop(&mut self) {
        self.halt();
    }
}

fn connect_until(endpoint: &EndpointSpec, deadline: Instant, stop: &AtomicBool) -> Option<Stream> {
    while !stop.load(Ordering::Relaxed) && Instant::now() < deadline {
        let s = match endpoint {
            EndpointSpec::UnixConnect(p) => UnixStream::connect(p).map(Stream::Unix),
            EndpointSpec::TcpConnect(a) => TcpStream::connect(a).map(Stream::Tcp),
            _ => return None,
        };
        if let Ok(s) = s {
            return Some(s);
        }
        thread::sleep(Duration::from_millis(20));
    }
    None
}

fn run_car(
    mut stream: Stream,
    config: CarConfig,
    state: CarState,
    report: &Mutex<CarReport>,
    stop: &AtomicBool,
) {
    if stream.set_nonblocking().is_err() {
        return;
    }
    let started = Instant::now();
    let mut mac = CarMac::new(config);
    mac.set_state(state);
    let mut buf = [0u8; 512];
    let mut out: VecDeque<u8> = VecDeque::new();
    report.lock().unwrap_or_else(|e| e.into_inner()).connected = true;
    while !stop.load(Ordering::Relaxed) {
        let now = started.elapsed().as_micros() as u64;
        match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => mac.push_rx(now, &buf[..n]),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) => {}
            Err(_) => break,
        }
        mac.poll(now);
        let mut executed = Vec::new();
        while let Some(ev) = mac.next_event() {
            if let Event::Request(inc) = ev {
                if !inc.id.broadcast {
                    let _ = mac.reply(inc.id, inc.tag, &inc.payload);
                }
                executed.push((inc.tag, inc.payload.to_vec(), inc.id.counter.is_some()));
            }
        }
        // A peer that stops reading leaves the bytes in the protocol's bounded queue (counted
        // as `tx_queue_full` there) instead of growing this buffer without limit.
        if out.len() < OUT_BACKLOG {
            let n = mac.transmit(&mut buf);
            out.extend(&buf[..n]);
        }
        while !out.is_empty() {
            let (front, _) = out.as_slices();
            match stream.write(front) {
                Ok(0) => break,
                Ok(k) => {
                    out.drain(..k);
                }
                Err(_) => break,
            }
        }
        {
            let mut r = report.lock().unwrap_or_else(|e| e.into_inner());
            r.stats = *mac.stats();
            r.executed.extend(executed);
            r.states_heard = mac
                .neighbours()
                .iter()
                .filter_map(|n| match n.addr {
                    radio_mac::Address::Car(id) => Some((id.get(), n.states_heard)),
                    _ => None,
                })
                .collect();
        }
        thread::sleep(Duration::from_micros(500));
    }
}
