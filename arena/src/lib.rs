//! The simulated world of the ALMC testbed: the radio medium model ([`radio_medium`]),
//! simulations of cars and the ground station talking over it ([`radio_sim`]), a real-time
//! hub that runs the medium between socket-attached radios ([`hub`]), the world that owns time
//! and runs every car's firmware on a car engine ([`world`], [`engine`]: the soft core's
//! model in virtual time, or QEMU in real time), and experiments played in it
//! ([`experiment`], [`runner`], [`metrics`]) with what they record for people to look at
//! ([`recording`]: `run.mcap` and the live view; [`plot`]; [`report`]).

#![forbid(unsafe_code)]

pub mod camera;
pub mod camera_feed;
pub mod engine;
pub mod experiment;
pub mod hub;
pub mod metrics;
pub mod plot;
pub mod radio_medium;
pub mod radio_sim;
pub mod recording;
pub mod report;
pub mod runner;
pub mod world;
