//! meb-core: what every stage of MEB-FDMA photometric stereo shares.
//!
//! * [`types`]: the data passed between stages (LED images, normal fields, depth maps,
//!   confidence classes).
//! * [`rig`]: the camera and LED geometry, read from and written to TOML, and the thesis' rigs
//!   as presets.
//! * [`capture`]: frame sources (image sequences, y4m, video files through FFmpeg, raw streams).
//! * [`io`]: the one file layer: atomic output folders, `.npy` arrays, previews, masks.
//! * [`metrics`]: accuracy against ground truth; [`mesh`]: triangle meshes and their raster.
//! * [`datasets`]: readers for public reference data (MATLAB arrays, DiLiGenT).
//! * [`flicker`]: what the carriers do to the eye (IEEE 1789); [`led_waveform`]: the light an
//!   LED emits over time, shared by the simulator and the virtual luminaire; [`mains`]: where
//!   room-light flicker on 50/60 Hz mains falls among the carriers' lines.
//! * [`stop`]: a stop request shared between threads (a live stream ended by an interrupt).
//!
//! Nothing here decodes, reconstructs or simulates: those are `meb-pipeline` and `meb-sim`,
//! which both depend on this crate and never on each other.

#![deny(missing_docs)]

pub mod capture;
pub mod datasets;
pub mod flicker;
pub mod io;
#[cfg(any(test, feature = "testing"))]
pub mod layouts;
pub mod led_waveform;
pub mod mains;
pub mod memory;
pub mod mesh;
pub mod metrics;
pub mod rig;
pub mod stats;
pub mod stop;
pub mod timing;
pub mod types;
