//! The `meb` command-line tool's library: the demo (a simulated capture of the thesis' rig,
//! decoded, reconstructed and scored), the report (`report.json`, `report.html` with its
//! three.js view, previews and surface meshes) and the live view of `meb video --live`. The
//! commands themselves are in the binary.

#![deny(missing_docs)]

pub mod demo;
pub mod export;
pub mod live;
