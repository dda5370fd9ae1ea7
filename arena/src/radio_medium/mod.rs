//! Model of the shared radio channel between the cars' transparent serial radios
//! (Wi.232DTS-like) and the ground station.
//!
//! Each node's module takes bytes from its host UART (115200 8N1, one byte per 86.8 us),
//! gathers them into a packet until an MTU or an inter-byte gap timeout, then sends the
//! packet as a unit after carrier sense with random backoff (the module's own CSMA).
//! A packet is received by every node in range unless another audible transmission
//! overlaps it there (collision), the receiver was itself transmitting, or it is lost by
//! probability or by distance. Received packets leave the module through the receiver's
//! UART at the same byte rate. Both module buffers have capacities; overflows are counted.
//!
//! Sans-IO and deterministic: time is passed in, randomness comes from a seeded ChaCha8.
//! All times are nanoseconds.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, VecDeque};

/// Nanoseconds.
pub type Nanos = u64;

/// One 8N1 byte at 115200 bps: 10 bits / 115200 s.
pub const BYTE_NS_115200: Nanos = 86_806;

/// Index of a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeId(pub usize);

/// Model parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct MediumParams {
    /// Host UART byte time (both directions).
    pub uart_byte_ns: Nanos,
    /// Air time per payload byte.
    pub air_byte_ns: Nanos,
    /// Per-packet air overhead (preamble, sync, header), in byte times.
    pub air_overhead_bytes: u32,
    /// Largest packet the module forms.
    pub mtu: usize,
    /// Inter-byte gap that closes a packet.
    pub gap_timeout_ns: Nanos,
    /// A transmission is sensed only this long after it started (CCA and turnaround latency).
    pub sense_delay_ns: Nanos,
    /// Backoff slot.
    pub backoff_slot_ns: Nanos,
    /// Backoff is uniform in `0..=contention_window` slots after the channel frees.
    pub contention_window: u32,
    /// Busy-channel attempts before a packet is dropped.
    pub max_csma_attempts: u32,
    /// Pause between two packets of one node.
    pub turnaround_ns: Nanos,
    /// Module transmit buffer (bytes waiting to go on air).
    pub tx_buffer: usize,
    /// Module receive buffer (bytes waiting for the host UART).
    pub rx_buffer: usize,
    /// Probability that a receiver misses an intact packet.
    pub loss_probability: f64,
    /// Nodes farther apart than this neither hear nor sense each other, in metres.
    pub range_m: f64,
    /// Loss rises linearly from 0 at this distance to 1 at `range_m`.
    pub fade_start_m: f64,
}

impl Default for MediumParams {
    fn default() -> Self {
        Self {
            uart_byte_ns: BYTE_NS_115200,
            air_byte_ns: BYTE_NS_115200,
            air_overhead_bytes: 4,
            mtu: 64,
            gap_timeout_ns: 3 * BYTE_NS_115200,
            sense_delay_ns: 100_000,
            backoff_slot_ns: 100_000,
            contention_window: 15,
            max_csma_attempts: 64,
            turnaround_ns: 200_000,
            tx_buffer: 256,
            rx_buffer: 256,
            loss_probability: 0.0,
            range_m: 50.0,
            fade_start_m: 40.0,
        }
    }
}

impl MediumParams {
    /// Time from the start of a UART write of `len` bytes on a sender to the last byte
    /// leaving a receiver's UART, when the channel is free (the state-frame pipeline latency).
    pub fn pipeline_latency_ns(&self, len: usize) -> Nanos {
        let n = len as Nanos;
        n * self.uart_byte_ns + self.gap_timeout_ns + self.air_time_ns(len) + n * self.uart_byte_ns
    }

    /// Air time of a packet of `len` bytes.
    pub fn air_time_ns(&self, len: usize) -> Nanos {
        (len as Nanos + Nanos::from(self.air_overhead_bytes)) * self.air_byte_ns
    }
}

/// Channel-wide counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MediumStats {
    /// Packets put on air.
    pub packets_sent: u64,
    /// Packet receptions delivered to a receiver's buffer.
    pub deliveries: u64,
    /// Receptions destroyed by an overlapping transmission.
    pub collisions: u64,
    /// Receptions missed because the receiver was transmitting.
    pub half_duplex: u64,
    /// Receptions lost by probability.
    pub random_losses: u64,
    /// Receptions lost by distance.
    pub distance_losses: u64,
    /// Receptions dropped because the receiver's module buffer was full.
    pub rx_overflows: u64,
    /// Bytes dropped because a sender's module buffer was full.
    pub tx_overflow_bytes: u64,
    /// Carrier-sense deferrals.
    pub csma_defers: u64,
    /// Packets dropped after too many busy attempts.
    pub csma_drops: u64,
}

impl std::ops::AddAssign for MediumStats {
    /// Counts of two channels together.
    fn add_assign(&mut self, other: Self) {
        let MediumStats {
            packets_sent,
            deliveries,
            collisions,
            half_duplex,
            random_losses,
            distance_losses,
            rx_overflows,
            tx_overflow_bytes,
            csma_defers,
            csma_drops,
        } = other;
        self.packets_sent += packets_sent;
        self.deliveries += deliveries;
        self.collisions += collisions;
        self.half_duplex += half_duplex;
        self.random_losses += random_losses;
        self.distance_losses += distance_losses;
        self.rx_overflows += rx_overflows;
        self.tx_overflow_bytes += tx_overflow_bytes;
        self.csma_defers += csma_defers;
        self.csma_drops += csma_drops;
    }
}

#[derive(Debug, Clone)]
struct Transmission {
    src: usize,
    start: Nanos,
    end: Nanos,
    bytes: Vec<u8>,
}

#[derive(Debug, Default)]
struct Node {
    pos: (f64, f64),
    uart_in_free: Nanos,
    open: Vec<u8>,
    open_last: Nanos,
    open_gen: u64,
    queued: VecDeque<Vec<u8>>,
    queued_bytes: usize,
    busy: bool,
    attempts: u32,
    rx_uart_free: Nanos,
    rx: VecDeque<(Nanos, u8)>,
    /// Times at which delivered packets finish leaving the UART.
    rx_marks: VecDeque<Nanos>,
}

#[derive(Debug)]
enum What {
    GapClose { node: usize, gen: u64 },
    Ready { node: usize, packet: Vec<u8> },
    Attempt { node: usize },
    TxEnd { tx: usize },
}

#[derive(Debug)]
struct Scheduled {
    at: Nanos,
    order: u64,
    what: What,
}

impl PartialEq for Scheduled {
    fn eq(&self, o: &Self) -> bool {
        self.at == o.at && self.order == o.order
    }
}
impl Eq for Scheduled {}
impl PartialOrd for Scheduled {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Scheduled {
    fn cmp(&self, o: &Self) -> Ordering {
        // Min-heap on (time, insertion order).
        o.at.cmp(&self.at).then(o.order.cmp(&self.order))
    }
}

/// The shared channel.
#[derive(Debug)]
pub struct RadioMedium {
    params: MediumParams,
    nodes: Vec<Node>,
    rng: ChaCha8Rng,
    queue: BinaryHeap<Scheduled>,
    order: u64,
    now: Nanos,
    /// Transmissions by id; ids of finished ones are reused through `free_air`.
    air: Vec<Option<Transmission>>,
    free_air: Vec<usize>,
    live: Vec<usize>,
    stats: MediumStats,
}

impl RadioMedium {
    /// An empty channel.
    pub fn new(params: MediumParams, seed: u64) -> Self {
        Self {
            params,
            nodes: Vec::new(),
            rng: ChaCha8Rng::seed_from_u64(seed),
            queue: BinaryHeap::new(),
            order: 0,
            now: 0,
            air: Vec::new(),
            free_air: Vec::new(),
            live: Vec::new(),
            stats: MediumStats::default(),
        }
    }

    /// Parameters in use.
    pub fn params(&self) -> &MediumParams {
        &self.params
    }

    /// Counters.
    pub fn stats(&self) -> &MediumStats {
        &self.stats
    }

    /// Current model time.
    pub fn now(&self) -> Nanos {
        self.now
    }

    /// Add a node at `pos` (metres).
    pub fn add_node(&mut self, pos: (f64, f64)) -> NodeId {
        self.nodes.push(Node {
            pos,
            ..Node::default()
        });
        NodeId(self.nodes.len() - 1)
    }

    /// Move a node.
    pub fn set_position(&mut self, node: NodeId, pos: (f64, f64)) {
        if let Some(n) = self.nodes.get_mut(node.0) {
            n.pos = pos;
        }
    }

    fn schedule(&mut self, at: Nanos, what: What) {
        self.order += 1;
        self.queue.push(Scheduled {
            at,
            order: self.order,
            what,
        });
    }

    fn distance(&self, a: usize, b: usize) -> f64 {
        let (p, q) = (self.nodes[a].pos, self.nodes[b].pos);
        ((p.0 - q.0).powi(2) + (p.1 - q.1).powi(2)).sqrt()
    }

    fn hears(&self, a: usize, b: usize) -> bool {
        a != b && self.distance(a, b) <= self.params.range_m
    }

    /// Host writes `bytes` to `node`'s radio UART at `now`. Returns bytes accepted; the rest
    /// overflowed the module's transmit buffer.
    pub fn write(&mut self, node: NodeId, now: Nanos, bytes: &[u8]) -> usize {
        self.step(now);
        let i = node.0;
        if i >= self.nodes.len() || bytes.is_empty() {
            return 0;
        }
        let p = &self.params;
        let (byte_ns, mtu, gap, cap) = (p.uart_byte_ns, p.mtu, p.gap_timeout_ns, p.tx_buffer);
        let n = &mut self.nodes[i];
        let room = cap.saturating_sub(n.queued_bytes + n.open.len());
        let take = bytes.len().min(room);
        let dropped = (bytes.len() - take) as u64;
        let mut t = n.uart_in_free.max(now);
        let mut ready = Vec::new();
        for &b in &bytes[..take] {
            t += byte_ns;
            n.open.push(b);
            n.open_last = t;
            if n.open.len() >= mtu {
                ready.push((t, std::mem::take(&mut n.open)));
            }
        }
        n.uart_in_free = t;
        n.open_gen += 1;
        let gen = n.open_gen;
        let open_pending = !n.open.is_empty();
        let close_at = n.open_last + gap;
        for (at, packet) in ready {
            self.nodes[i].queued_bytes += packet.len();
            self.schedule(at, What::Ready { node: i, packet });
        }
        if open_pending {
            self.schedule(close_at, What::GapClose { node: i, gen });
        }
        self.stats.tx_overflow_bytes += dropped;
        take
    }

    /// Bytes that have left `node`'s radio UART by `now`.
    pub fn read(&mut self, node: NodeId, now: Nanos) -> Vec<u8> {
        self.step(now);
        let mut out = Vec::new();
        if let Some(n) = self.nodes.get_mut(node.0) {
            while let Some(&(t, b)) = n.rx.front() {
                if t > now {
                    break;
                }
                out.push(b);
                n.rx.pop_front();
            }
            while n.rx_marks.front().is_some_and(|t| *t <= now) {
                n.rx_marks.pop_front();
            }
        }
        out
    }

    /// Moves the bytes queued towards `node`'s host that leave its UART by `until` into
    /// `out`, each with its time, without stepping the medium: a byte already queued keeps its
    /// time, and bytes delivered later queue behind it, so `until` may lie ahead of
    /// [`RadioMedium::now`].
    pub fn take_rx(&mut self, node: NodeId, until: Nanos, out: &mut Vec<(Nanos, u8)>) {
        if let Some(n) = self.nodes.get_mut(node.0) {
            while let Some(&(t, b)) = n.rx.front() {
                if t > until {
                    break;
                }
                out.push((t, b));
                n.rx.pop_front();
            }
            while n.rx_marks.front().is_some_and(|t| *t <= until) {
                n.rx_marks.pop_front();
            }
        }
    }

    /// When the last byte now queued towards `node`'s host will have left its UART.
    pub fn rx_idle_at(&self, node: NodeId) -> Option<Nanos> {
        self.nodes.get(node.0)?.rx.back().map(|(t, _)| *t)
    }

    /// Earliest time after [`RadioMedium::now`] at which anything changes: an internal event
    /// or a byte reaching a host.
    pub fn next_event_time(&self) -> Option<Nanos> {
        let internal = self.queue.peek().map(|s| s.at);
        let rx = self
            .nodes
            .iter()
            .filter_map(|n| n.rx.iter().map(|(t, _)| *t).find(|t| *t > self.now))
            .min();
        match (internal, rx) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Earliest time after [`RadioMedium::now`] at which a whole packet finishes arriving at
    /// some host, or an internal event is due.
    /// Drivers that only need frame-level timing can step by this instead of by byte.
    pub fn next_packet_time(&self) -> Option<Nanos> {
        let internal = self.queue.peek().map(|s| s.at);
        let rx = self
            .nodes
            .iter()
            .filter_map(|n| n.rx_marks.iter().copied().find(|t| *t > self.now))
            .min();
        match (internal, rx) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Process every internal event up to `until`.
    pub fn step(&mut self, until: Nanos) {
        while let Some(top) = self.queue.peek() {
            if top.at > until {
                break;
            }
            let Some(ev) = self.queue.pop() else { break };
            self.now = self.now.max(ev.at);
            match ev.what {
                What::GapClose { node, gen } => {
                    let n = &mut self.nodes[node];
                    if n.open_gen == gen && !n.open.is_empty() {
                        let packet = std::mem::take(&mut n.open);
                        n.queued_bytes += packet.len();
                        self.ready(node, packet, ev.at);
                    }
                }
                What::Ready { node, packet } => self.ready(node, packet, ev.at),
                What::Attempt { node } => self.attempt(node, ev.at),
                What::TxEnd { tx } => self.tx_end(tx, ev.at),
            }
        }
        self.now = self.now.max(until);
    }

    fn ready(&mut self, node: usize, packet: Vec<u8>, at: Nanos) {
        let n = &mut self.nodes[node];
        n.queued.push_back(packet);
        if !n.busy {
            n.busy = true;
            n.attempts = 0;
            self.attempt(node, at);
        }
    }

    fn attempt(&mut self, node: usize, at: Nanos) {
        let sense = self.params.sense_delay_ns;
        let mut busy_until = None;
        for &id in &self.live {
            if let Some(tx) = &self.air[id] {
                if tx.end > at && tx.start + sense <= at && self.hears(tx.src, node) {
                    busy_until = Some(busy_until.unwrap_or(0).max(tx.end));
                }
            }
        }
        if let Some(until) = busy_until {
            self.stats.csma_defers += 1;
            let n = &mut self.nodes[node];
            n.attempts += 1;
            if n.attempts >= self.params.max_csma_attempts {
                if let Some(p) = n.queued.pop_front() {
                    n.queued_bytes -= p.len();
                }
                self.stats.csma_drops += 1;
                n.attempts = 0;
                if n.queued.is_empty() {
                    n.busy = false;
                    return;
                }
            }
            let slots = self.rng.random_range(0..=self.params.contention_window);
            let next = until + Nanos::from(slots) * self.params.backoff_slot_ns;
            self.schedule(next, What::Attempt { node });
            return;
        }
        let n = &mut self.nodes[node];
        let Some(bytes) = n.queued.pop_front() else {
            n.busy = false;
            return;
        };
        n.queued_bytes -= bytes.len();
        n.attempts = 0;
        let end = at + self.params.air_time_ns(bytes.len());
        let tx = Transmission {
            src: node,
            start: at,
            end,
            bytes,
        };
        let id = match self.free_air.pop() {
            Some(id) => {
                self.air[id] = Some(tx);
                id
            }
            None => {
                self.air.push(Some(tx));
                self.air.len() - 1
            }
        };
        self.live.push(id);
        self.stats.packets_sent += 1;
        self.schedule(end, What::TxEnd { tx: id });
    }

    fn tx_end(&mut self, id: usize, at: Nanos) {
        let Some(tx) = self.air[id].clone() else {
            return;
        };
        for r in 0..self.nodes.len() {
            if r == tx.src || !self.hears(tx.src, r) {
                continue;
            }
            let mut half_duplex = false;
            let mut collided = false;
            for &other in &self.live {
                if other == id {
                    continue;
                }
                let Some(o) = &self.air[other] else { continue };
                if o.start >= tx.end || o.end <= tx.start {
                    continue;
                }
                if o.src == r {
                    half_duplex = true;
                } else if self.hears(o.src, r) {
                    collided = true;
                }
            }
            if half_duplex {
                self.stats.half_duplex += 1;
                continue;
            }
            if collided {
                self.stats.collisions += 1;
                continue;
            }
            let d = self.distance(tx.src, r);
            let p = &self.params;
            let fade = if d <= p.fade_start_m || p.range_m <= p.fade_start_m {
                0.0
            } else {
                ((d - p.fade_start_m) / (p.range_m - p.fade_start_m)).clamp(0.0, 1.0)
            };
            let loss = self.params.loss_probability;
            if fade > 0.0 && self.rng.random::<f64>() < fade {
                self.stats.distance_losses += 1;
                continue;
            }
            if loss > 0.0 && self.rng.random::<f64>() < loss {
                self.stats.random_losses += 1;
                continue;
            }
            let byte_ns = self.params.uart_byte_ns;
            let cap = self.params.rx_buffer;
            let n = &mut self.nodes[r];
            let backlog = n.rx.iter().filter(|(t, _)| *t > at).count();
            if backlog + tx.bytes.len() > cap {
                self.stats.rx_overflows += 1;
                continue;
            }
            let mut t = n.rx_uart_free.max(at);
            for &b in &tx.bytes {
                t += byte_ns;
                n.rx.push_back((t, b));
            }
            n.rx_uart_free = t;
            n.rx_marks.push_back(t);
            self.stats.deliveries += 1;
        }
        // Keep transmissions that may still overlap a packet in flight.
        let horizon = at.saturating_sub(self.params.air_time_ns(self.params.mtu));
        // Their end events have all been handled, so their ids can be reused.
        let air = &mut self.air;
        let free = &mut self.free_air;
        self.live.retain(|&l| match &air[l] {
            Some(t) if t.end >= horizon => true,
            _ => {
                air[l] = None;
                free.push(l);
                false
            }
        });
        let n = &mut self.nodes[tx.src];
        if n.queued.is_empty() {
            n.busy = false;
        } else {
            let next = at + self.params.turnaround_ns;
            self.schedule(next, What::Attempt { node: tx.src });
        }
    }
}

#[cfg(test)]
mod tests;
