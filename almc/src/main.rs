//! `almc`: the ALMC user's command-line tool.
//!
//! Each subcommand group lives in its own module; this file only dispatches.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod camera;
mod car;
mod experiment;
mod ground;
mod laws;
mod lbc;
mod lbc_emu;
mod radio;
mod sweep;

#[derive(Debug, Parser)]
#[command(name = "almc", version, about = "ALMC micro-car testbed tool")]
struct Cli {
    #[command(subcommand)]
    command: Group,
}

#[derive(Debug, Subcommand)]
enum Group {
    /// UBC<->LBC protocol: decode and encode messages.
    #[command(subcommand)]
    Lbc(lbc::LbcCommand),
    /// Run an emulated lower board (LBC) behind a socket.
    LbcEmu(lbc_emu::Args),
    /// List the cars heard on the radio (ground station).
    Cars(radio::CarsArgs),
    /// Ground-station radio tools: raw authenticated requests, the simulated radio hub.
    #[command(subcommand)]
    Radio(radio::RadioCommand),
    /// Console of one car's UBC program over the radio: LBC commands, status, maneuvers.
    Car(car::CarArgs),
    /// The registered group-maneuver laws: parameters, options, IDs.
    Laws(laws::LawsArgs),
    /// Camera frames of the cars: snapshots with the on-board detections drawn.
    #[command(subcommand)]
    Camera(camera::CameraCommand),
    /// Experiments with QEMU cars in the simulated arena.
    #[command(subcommand)]
    Experiment(experiment::ExperimentCommand),
    /// Parameter studies: an experiment over a grid of values and seeds, on every core or Slurm.
    #[command(subcommand)]
    Sweep(sweep::SweepCommand),
}

fn main() -> ExitCode {
    match Cli::parse().command {
        Group::Lbc(cmd) => lbc::run(cmd),
        Group::LbcEmu(args) => lbc_emu::run(args),
        Group::Cars(args) => radio::run_cars(args),
        Group::Radio(cmd) => radio::run(cmd),
        Group::Car(args) => car::run(&args),
        Group::Laws(args) => laws::run(&args),
        Group::Experiment(cmd) => experiment::run(cmd),
        Group::Sweep(cmd) => sweep::run(cmd),
        Group::Camera(cmd) => camera::run(cmd),
    }
}
