//! The simulated world of the ALMC testbed. For now: the radio medium model
//! ([`radio_medium`]) and simulations of cars and the ground station talking over it
//! ([`radio_sim`]).

#![forbid(unsafe_code)]

pub mod radio_medium;
pub mod radio_sim;
