//! The `meb` command-line tool: a thin layer over the meb library crates (`meb-core`, `meb-sim`,
//! `meb-pipeline`, `meb-device`).

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
    /// Simulate the thesis' sphere and cube, decode, reconstruct and write a report.
    Demo(cli::demo::DemoArgs),
    /// Integrate a normal map into depth.
    Integrate(cli::integrate::IntegrateArgs),
    /// Photometric stereo on an image set with known lights (or a DiLiGenT folder).
    Photometric(cli::photometric::PhotometricArgs),
    /// Calibrate a rig from its own captures (`meb calibrate lights` with a matte sphere,
    /// `meb calibrate camera` with a chequerboard).
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Print the MEB-FDMA chip table, its spectrum and its IEEE 1789 flicker class.
    Carriers(cli::carriers::CarriersArgs),
    /// Demodulate a capture into one image per LED (led1.npy…, previews, noise, decode.json).
    Decode(Box<cli::decode::DecodeArgs>),
    /// Talk to meb luminaires over USB serial, or emulate one on a pseudo-terminal.
    Device(cli::device::DeviceArgs),
    /// Render a synthetic MEB-FDMA capture of a scene with ground truth (or the Ch. 7 data set).
    Simulate(Box<cli::simulate::SimulateArgs>),
    /// Reconstruct normals, depth and a mesh from a capture or a `meb decode` folder.
    Reconstruct(Box<cli::reconstruct::ReconstructArgs>),
    /// Check a rig against a capture (`meb rig check`).
    Rig(cli::rig::RigArgs),
    /// Time of flight: range maps from SPAD histograms, ToF → camera calibration, object masks.
    Tof(cli::tof::TofArgs),
    /// Make a 3-D video from a long or live capture: a 3-D frame per window of frames.
    Video(Box<cli::video::VideoArgs>),
}

fn main() -> ExitCode {
    // Windows of a video reuse their arrays' pages instead of faulting them in afresh.
    // SAFETY: first thing in `main`: no other thread has started.
    unsafe { meb_core::memory::keep_freed_memory() };
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(args) => cli::demo::run(&args),
        Command::Integrate(args) => cli::integrate::run(&args),
        Command::Photometric(args) => cli::photometric::run(&args),
        Command::Calibrate(args) => cli::calibrate::run(&args),
        Command::Carriers(args) => cli::carriers::run(&args),
        Command::Decode(args) => cli::decode::run(&args),
        Command::Device(args) => cli::device::run(&args),
        Command::Simulate(args) => cli::simulate::run(&args),
        Command::Reconstruct(args) => cli::reconstruct::run(&args),
        Command::Rig(args) => cli::rig::run(&args),
        Command::Tof(args) => cli::tof::run(&args),
        Command::Video(args) => cli::video::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {}", error_chain(&err));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes on one line, "outer: inner: …", leaving out a cause whose text
/// the message before it already contains (libraries that print their source in their own
/// message would otherwise show it twice, as in "entity not found: entity not found").
fn error_chain(err: &anyhow::Error) -> String {
    let mut line = String::new();
    let mut previous = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if text.is_empty() || previous.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
        previous = text;
    }
    line
}
