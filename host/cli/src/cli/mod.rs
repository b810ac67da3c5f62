//! One module per `meb` subcommand: argument parsing and printing only.

pub mod calibrate;
pub mod calibrate_camera;
pub mod camera;
pub mod carriers;
pub mod common;
pub mod decode;
pub mod demo;
pub mod device;
pub mod hybrid;
pub mod integrate;
pub mod parse;
pub mod photometric;
pub mod reconstruct;
pub mod rig;
pub mod room_args;
pub mod simulate;
pub mod simulate_tof;
pub mod tof;
pub mod truth;
pub mod video;
