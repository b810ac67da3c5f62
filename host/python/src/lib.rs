//! The `meb` Python package's extension module `meb._meb`: the library's decoder,
//! reconstruction, normal integration, photometric stereo, simulator and luminaire client
//! with numpy arrays in and out.
//!
//! Every function calls the same library functions as the `meb` command (one pipeline):
//! [`meb_pipeline::demod::decode`], [`meb_pipeline::reconstruct::reconstruct`],
//! [`meb_pipeline::integrate::integrate_surface`],
//! [`meb_pipeline::photometric::estimate_normals`], [`meb_sim::SimulatedCapture`] and
//! [`meb_device::client::DeviceClient`]. The interpreter lock is released while they compute.
//! Arrays leave as numpy arrays that share the Rust memory (read-only views owned by the
//! result object) or take it over; arrays come in read where they lie when the library can
//! read a borrowed slice (the frames of `decode`), else copied once into the owned array the
//! library takes, and never converted silently: a wrong dtype or a strided array is refused
//! with what to pass instead. The Python-facing documentation is in `python/meb/__init__.pyi`
//! and docs/howto/python.md.

use pyo3::prelude::*;

mod arrays;
mod decode;
mod device;
mod errors;
mod frames;
mod integrate;
mod json;
mod reconstruct;
mod refusals;
mod rig;
mod simulate;
mod video;

/// The extension module `meb._meb` (re-exported by the `meb` package).
#[pymodule]
fn _meb(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<rig::Rig>()?;
    m.add_class::<decode::Decoded>()?;
    m.add_class::<reconstruct::Reconstruction>()?;
    m.add_class::<simulate::Capture>()?;
    m.add_class::<device::Luminaire>()?;
    m.add_class::<video::Video>()?;
    m.add_class::<video::VideoFrame>()?;
    m.add_function(wrap_pyfunction!(decode::decode, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct::reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(integrate::integrate, m)?)?;
    m.add_function(wrap_pyfunction!(integrate::photometric, m)?)?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(device::list_luminaires, m)?)?;
    m.add_function(wrap_pyfunction!(video::video, m)?)?;
    Ok(())
}
