//! `meb.Rig`: a capture rig (camera, LEDs, optional ToF camera) loaded from its TOML format
//! or a preset, and saved back ([`meb_core::rig::Rig`]).

use crate::errors::meb_error;
use crate::json::to_python;
use meb_core::rig::Rig as RustRig;
use pyo3::prelude::*;
use std::path::PathBuf;

/// A capture rig: the camera and its LEDs in LED order (docs/formats/rig.md).
#[pyclass(module = "meb", frozen)]
#[derive(Clone)]
pub struct Rig {
    /// The rig.
    pub inner: RustRig,
    /// What it was loaded from (a preset name or a file), for messages.
    pub name: String,
}

#[pymethods]
impl Rig {
    /// Loads a rig from a TOML file, or the preset of that name (thesis-in-plane,
    /// thesis-out-of-plane, thesis-dynamic, thesis-hybrid).
    #[staticmethod]
    pub fn load(spec: PathBuf) -> PyResult<Self> {
        let spec = spec.to_string_lossy().into_owned();
        let inner = RustRig::load(&spec)
            .map_err(|e| meb_error(Some(&format!("cannot load rig {spec}")), &e))?;
        Ok(Self { inner, name: spec })
    }

    /// Parses and validates a rig from TOML text.
    #[staticmethod]
    #[pyo3(signature = (text, name = "<string>"))]
    fn from_toml(text: &str, name: &str) -> PyResult<Self> {
        let inner = RustRig::from_toml_str(text, name)
            .map_err(|e| meb_error(Some(&format!("cannot load rig {name}")), &e))?;
        Ok(Self {
            inner,
            name: name.to_string(),
        })
    }

    /// The rig as TOML text (round-trips through `from_toml`).
    fn to_toml(&self) -> String {
        self.inner.to_toml_string()
    }

    /// Writes the rig's TOML to `path`.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        std::fs::write(&path, self.inner.to_toml_string())
            .map_err(|e| meb_error(Some(&format!("cannot write {}", path.display())), &e))
    }

    /// The rig as a dict (the TOML's tables: `camera`, `led` list, `tof_camera`).
    fn to_dict(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        to_python(py, &self.inner)
    }

    /// Number of LEDs.
    #[getter]
    fn leds(&self) -> usize {
        self.inner.leds.len()
    }

    /// Camera image (height, width) in pixels.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        (self.inner.camera.height, self.inner.camera.width)
    }

    /// Camera frame rate, frames per second.
    #[getter]
    fn fps(&self) -> f64 {
        self.inner.camera.fps
    }

    /// Distant light vectors L_i(0), one (x, y, z) row per LED.
    fn light_vectors(&self) -> Vec<[f64; 3]> {
        self.inner
            .distant_light_vectors()
            .iter()
            .map(|v| [v.x, v.y, v.z])
            .collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "Rig({:?}: {} LEDs, camera {}x{} at {} fps)",
            self.name,
            self.inner.leds.len(),
            self.inner.camera.width,
            self.inner.camera.height,
            self.inner.camera.fps
        )
    }

    fn __eq__(&self, other: &Self) -> bool {
        self.inner == other.inner
    }
}

/// A rig from a `Rig` or a preset name / path.
pub fn rig_of(rig: &Bound<'_, PyAny>) -> PyResult<Rig> {
    if let Ok(rig) = rig.cast::<Rig>() {
        return Ok(rig.get().clone());
    }
    let spec: PathBuf = rig.extract().map_err(|_| {
        pyo3::exceptions::PyTypeError::new_err(
            "rig must be a meb.Rig, a preset name or a TOML path",
        )
    })?;
    Rig::load(spec)
}
