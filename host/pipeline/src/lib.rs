//! meb-pipeline: from a capture to a surface.
//!
//! Data flows one way: [`demod`] (frames → one image per LED) → [`photometric`] (LED images →
//! normals and albedo) → [`integrate`] (normals → depth), joined by [`reconstruct`], the one
//! path from a decoded capture to a depth map that the CLI, the demo, video and the
//! hardware-in-the-loop tests all call. [`video`] streams windows of long or live captures into
//! 3-D frames; [`tof`] turns time-of-flight histograms into ranges, masks and fused depth.
//! Inputs and outputs are `meb-core`'s types; the simulator (`meb-sim`) is used by tests only.

#![deny(missing_docs)]

pub mod calibrate;
pub mod demod;
pub mod integrate;
pub mod photometric;
pub mod reconstruct;
pub mod regions;
pub mod tof;
pub mod video;
