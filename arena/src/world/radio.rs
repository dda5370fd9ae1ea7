//! The world's radio channels. A radio module is set to one channel; modules on different
//! channels neither hear nor disturb each other, so each channel in use is a radio medium of
//! its own, with a ground station of its own (a real ground station would have one radio per
//! channel). One channel carries at most 16 cars in its state schedule: a fleet larger than
//! that spreads over channels, a group per channel.

use super::ground::Ground;
use super::{metres, CarSpec, NodeCounters};
use crate::radio_medium::{MediumParams, NodeId, RadioMedium};

/// One radio channel of the world.
#[derive(Debug)]
pub(super) struct Channel {
    /// The channel's number.
    pub number: u8,
    /// Its medium.
    pub medium: RadioMedium,
    /// The ground station's node on it.
    pub ground_node: NodeId,
    /// Its ground station.
    pub ground: Ground,
    /// Index of its ground station in the world's node counters.
    pub counter: usize,
}

/// The channels in use, each car's channel index and node, and the node counters
/// (`ground`, then every car, then the other channels' ground stations as `ground<N>`).
pub(super) struct Radio {
    pub channels: Vec<Channel>,
    pub channel_of: Vec<usize>,
    pub nodes: Vec<NodeId>,
    pub counters: Vec<NodeCounters>,
}

/// Seed of channel number `n`'s random sources (the lowest channel keeps the world's seed, so
/// a world on one channel runs as it always has).
fn channel_seed(seed: u64, first: u8, n: u8) -> u64 {
    if n == first {
        seed
    } else {
        seed ^ (u64::from(n) + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15)
    }
}

/// Sets up the radio channels the cars use.
pub(super) fn channels(
    cars: &[CarSpec],
    ids: &[u8],
    params: &MediumParams,
    key: [u8; 16],
    seed: u64,
) -> Radio {
    let mut numbers: Vec<u8> = cars.iter().map(|c| c.radio_channel).collect();
    numbers.sort_unstable();
    numbers.dedup();
    let first = numbers.first().copied().unwrap_or(0);
    let mut channels: Vec<Channel> = numbers
        .iter()
        .map(|&n| {
            let mut medium = RadioMedium::new(params.clone(), channel_seed(seed, first, n));
            let ground_node = medium.add_node((0.75, -0.2));
            Channel {
                number: n,
                medium,
                ground_node,
                ground: Ground::new(ids, key, channel_seed(seed, first, n)),
                counter: 0,
            }
        })
        .collect();
    let mut counters = vec![NodeCounters {
        name: "ground".into(),
        ..NodeCounters::default()
    }];
    let mut channel_of = Vec::with_capacity(cars.len());
    let mut nodes = Vec::with_capacity(cars.len());
    for c in cars {
        let ch = numbers
            .iter()
            .position(|&n| n == c.radio_channel)
            .unwrap_or(0);
        channel_of.push(ch);
        nodes.push(channels[ch].medium.add_node(metres(&c.start)));
        counters.push(NodeCounters {
            name: format!("car{}", c.id),
            ..NodeCounters::default()
        });
    }
    for ch in channels.iter_mut().skip(1) {
        ch.counter = counters.len();
        counters.push(NodeCounters {
            name: format!("ground{}", ch.number),
            ..NodeCounters::default()
        });
    }
    Radio {
        channels,
        channel_of,
        nodes,
        counters,
    }
}
