//! The `meb` command-line tool: a thin layer over the `meb` library.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

mod cli;

/// Synchronisation-free photometric-stereo 3-D imaging with MEB-FDMA LED lighting.
#[derive(Parser)]
#[command(name = "meb", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the MEB-FDMA chip table, its spectrum and its IEEE 1789 flicker class.
    Carriers(cli::carriers::CarriersArgs),
    /// Talk to meb luminaires over USB serial, or emulate one on a pseudo-terminal.
    Device(cli::device::DeviceArgs),
    /// Render a synthetic MEB-FDMA capture of a scene with ground truth (or the Ch. 7 data set).
    Simulate(Box<cli::simulate::SimulateArgs>),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Carriers(args) => cli::carriers::run(&args),
        Command::Device(args) => cli::device::run(&args),
        Command::Simulate(args) => cli::simulate::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
