//! meb: synchronisation-free photometric-stereo 3-D imaging with MEB-FDMA LED lighting.
//!
//! Data flows one way: [`capture`] → [`demod`] → [`photometric`] → [`integrate`] → [`export`],
//! each stage a function of typed inputs ([`types`]) plus a config struct. [`simulate`] renders
//! captures with known ground truth and shares no code with the decoder or the reconstruction.
//! [`device`] talks to luminaires over USB serial and runs a virtual one on a pseudo-terminal.

pub mod capture;
pub mod datasets;
pub mod demo;
pub mod demod;
pub mod device;
pub mod export;
pub mod flicker;
pub mod integrate;
#[cfg(test)]
mod layouts;
pub mod led_waveform;
pub mod memory;
pub mod mesh;
pub mod metrics;
pub mod photometric;
pub mod reconstruct;
pub mod regions;
pub mod rig;
pub mod simulate;
pub mod stats;
pub mod timing;
pub mod tof;
pub mod types;
pub mod video;
