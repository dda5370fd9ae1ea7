//! The simulated world of the ALMC testbed: the radio medium model ([`radio_medium`]),
//! simulations of cars and the ground station talking over it ([`radio_sim`]), and a
//! real-time hub that runs the medium between socket-attached radios ([`hub`]), a world of
//! QEMU cars ([`world`]), and experiments played in it ([`experiment`], [`runner`],
//! [`metrics`], [`plot`]).

#![forbid(unsafe_code)]

pub mod camera;
pub mod camera_feed;
pub mod experiment;
pub mod hub;
pub mod metrics;
pub mod plot;
pub mod radio_medium;
pub mod radio_sim;
pub mod runner;
pub mod world;
