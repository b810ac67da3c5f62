//! `meb.reconstruct`: LED images (a decode, a decode folder or a capture) and a rig →
//! normals, albedo, depth, confidence and mask, with
//! [`meb_pipeline::reconstruct::reconstruct`] and the refusals of `meb reconstruct`.

use crate::arrays::{check_mask, typed, view};
use crate::decode::{Decoded, decode_any, led_count, settings};
use crate::errors::meb_error;
use crate::json::to_python;
use crate::refusals::{check_decode_verdict, check_rig, check_support};
use crate::rig::rig_of;
use meb_pipeline::demod::output::read_decode_dir;
use meb_pipeline::demod::{Decoded as RustDecoded, LedCount};
use meb_pipeline::integrate::Integrator;
use meb_pipeline::photometric::highlights::HighlightShares;
use meb_pipeline::reconstruct::{
    LightModel, ReconstructConfig, Reconstruction as RustReconstruction, Request, Source,
    check_decoded_rig, reconstruct as reconstruct_library,
};
use ndarray::{Array2, Ix2};
use numpy::{PyArray2, PyArray3, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;

/// A reconstruction: normals, albedo, depth, how each pixel's depth is known, the object mask,
/// and a report (the figures of `report.json`'s summary).
#[pyclass(module = "meb", frozen)]
pub struct Reconstruction {
    inner: Arc<Result3d>,
    report: Py<PyAny>,
}

/// The library's reconstruction with its confidence as bytes.
pub struct Result3d {
    /// The library's result.
    pub reconstruction: RustReconstruction,
    /// `confidence.npy`: 0 none, 1 filled, 2 two LEDs, 3 measured.
    pub confidence: Array2<u8>,
}

impl Reconstruction {
    /// Wraps a library result and its report.
    pub fn new(reconstruction: RustReconstruction, report: Py<PyAny>) -> Self {
        let confidence = reconstruction.confidence().mapv(|c| c as u8);
        Self {
            inner: Arc::new(Result3d {
                reconstruction,
                confidence,
            }),
            report,
        }
    }
}

#[pymethods]
impl Reconstruction {
    /// H×W×3 unit normals (x right, y up, z towards the camera); NaN outside the mask.
    #[getter]
    fn normals<'py>(slf: Bound<'py, Self>) -> Bound<'py, PyArray3<f32>> {
        let inner = slf.get().inner.clone();
        view(
            &inner.reconstruction.photometric.field.normals,
            slf.into_any(),
        )
    }

    /// H×W albedo ρ; NaN outside the mask.
    #[getter]
    fn albedo<'py>(slf: Bound<'py, Self>) -> Bound<'py, PyArray2<f32>> {
        let inner = slf.get().inner.clone();
        view(
            &inner.reconstruction.photometric.field.albedo,
            slf.into_any(),
        )
    }

    /// H×W depth z in mm towards the camera (`depth.npy`); NaN where not reconstructed.
    #[getter]
    fn depth<'py>(slf: Bound<'py, Self>) -> Bound<'py, PyArray2<f32>> {
        let inner = slf.get().inner.clone();
        view(
            &inner.reconstruction.integration.depth.depth_mm,
            slf.into_any(),
        )
    }

    /// H×W uint8 (`confidence.npy`): 0 not reconstructed, 1 filled, 2 two LEDs, 3 measured.
    #[getter]
    fn confidence<'py>(slf: Bound<'py, Self>) -> Bound<'py, PyArray2<u8>> {
        let inner = slf.get().inner.clone();
        view(&inner.confidence, slf.into_any())
    }

    /// H×W bool: the pixels whose normal was estimated.
    #[getter]
    fn mask<'py>(slf: Bound<'py, Self>) -> Bound<'py, PyArray2<bool>> {
        let inner = slf.get().inner.clone();
        view(&inner.reconstruction.photometric.field.mask, slf.into_any())
    }

    /// Grid pitch in mm per pixel (on the plane z = 0 for a pinhole camera).
    #[getter]
    fn pitch_mm(&self) -> f64 {
        self.inner.reconstruction.integration.depth.pitch_mm
    }

    /// The report: integrator, light model, pixels, kept share, support verdict, rig check,
    /// highlights, stage timings.
    #[getter]
    fn report(&self, py: Python<'_>) -> Py<PyAny> {
        self.report.clone_ref(py)
    }

    fn __repr__(&self) -> String {
        let (rows, cols) = self.inner.confidence.dim();
        let pixels = self
            .inner
            .reconstruction
            .photometric
            .field
            .mask
            .iter()
            .filter(|&&m| m)
            .count();
        format!("Reconstruction({cols}x{rows}, {pixels} object pixels)")
    }
}

/// Parses an integrator name (`auto`, `least-squares`, `bilateral`, `fast-marching`).
pub fn integrator(name: &str) -> PyResult<Integrator> {
    Ok(match name {
        "auto" => Integrator::Auto,
        "least-squares" => Integrator::LeastSquares,
        "bilateral" => Integrator::Bilateral,
        "fast-marching" => Integrator::FastMarching,
        _ => {
            return Err(PyValueError::new_err(format!(
                "integrator must be 'auto', 'least-squares', 'bilateral' or 'fast-marching', \
                 got {name:?}"
            )));
        }
    })
}

/// The report dict of a reconstruction of `decoded`.
fn report(
    py: Python<'_>,
    decoded: &RustDecoded,
    config: &ReconstructConfig,
    reconstruction: &RustReconstruction,
    rig_check: &meb_pipeline::reconstruct::rig_check::RigCheck,
) -> PyResult<Py<PyAny>> {
    let mask = &reconstruction.photometric.field.mask;
    let record = serde_json::json!({
        "leds": decoded.leds.images.len(),
        "decoded_frames": decoded.report.frames_used,
        "integrator": config.integrate.integrator,
        "light_model": match config.light_model {
            LightModel::Distant => "distant".to_string(),
            LightModel::NearField { refinements } => format!("near-field ({refinements} refinements)"),
        },
        "object_pixels": mask.iter().filter(|&&m| m).count(),
        "kept_fraction": reconstruction.integration.kept_fraction,
        "measured_share": reconstruction.support.measured_share,
        "absolute_depth": reconstruction.support.absolute_depth.describe(),
        "verdict": reconstruction.support.verdict,
        "rig_check": rig_check,
        "highlights": HighlightShares::of(&reconstruction.photometric),
        "clipping": decoded.report.clipping.as_ref().map(|c| c.message.clone()),
        "timings": reconstruction.timings,
        "decode": decoded.report,
    });
    to_python(py, &record)
}

/// Reconstructs a decode with a rig (see the package's `reconstruct`).
#[pyfunction]
#[pyo3(signature = (
    source, rig, *, integrator = "least-squares", mask = None, near_field = true,
    force = false, leds = None, fps = None, bit_depth = None, frames = None, start = 0,
    estimator = "waveform", linearize = "none", roi = None, rate_ratio = None,
    max_rate_mismatch = 0.06, exposure = None, line_time_us = None, check_led_count = true
))]
#[allow(clippy::too_many_arguments)]
pub fn reconstruct(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    rig: &Bound<'_, PyAny>,
    integrator: &str,
    mask: Option<&Bound<'_, PyAny>>,
    near_field: bool,
    force: bool,
    leds: Option<&Bound<'_, PyAny>>,
    fps: Option<f64>,
    bit_depth: Option<u8>,
    frames: Option<usize>,
    start: usize,
    estimator: &str,
    linearize: &str,
    roi: Option<(usize, usize, usize, usize)>,
    rate_ratio: Option<f64>,
    max_rate_mismatch: f64,
    exposure: Option<f64>,
    line_time_us: Option<f64>,
    check_led_count: bool,
) -> PyResult<Reconstruction> {
    let rig = rig_of(rig)?;
    let rig_name = rig.name.clone();
    let rig = rig.inner;
    if rig.leds.len() < 3 {
        return Err(PyValueError::new_err(format!(
            "photometric stereo needs at least 3 LEDs, rig {rig_name} has {}",
            rig.leds.len()
        )));
    }
    let mut config = ReconstructConfig::decoded_capture();
    config.integrate.integrator = self::integrator(integrator)?;
    if !near_field {
        config.light_model = LightModel::Distant;
    }
    // The decode: given, read from a folder, or decoded here.
    let (decoded, what): (Arc<RustDecoded>, String) = if let Ok(decoded) = source.cast::<Decoded>()
    {
        let decoded = decoded.get().inner.clone();
        check_decode_verdict(py, &decoded.report, "the decode", force)?;
        (decoded, "the decode".to_string())
    } else if let Ok(path) = source.extract::<PathBuf>()
        && path.join("decode.json").is_file()
    {
        let decoded = py
            .detach(|| read_decode_dir(&path))
            .map_err(|e| meb_error(Some(&format!("cannot read {}", path.display())), &e))?;
        let what = path.display().to_string();
        check_decode_verdict(py, &decoded.report, &what, force)?;
        (Arc::new(decoded), what)
    } else {
        let leds = leds
            .map(led_count)
            .transpose()?
            .unwrap_or(LedCount::Fixed(rig.leds.len()));
        let settings = settings(
            leds,
            fps,
            bit_depth,
            frames,
            start,
            estimator,
            linearize,
            roi,
            rate_ratio,
            max_rate_mismatch,
            exposure,
            line_time_us,
            check_led_count,
        )?;
        let decoded = decode_any(py, source, &settings, force)?;
        let what = source
            .extract::<PathBuf>()
            .map_or_else(|_| "the frames".to_string(), |p| p.display().to_string());
        (Arc::new(decoded), what)
    };
    let images = decoded.leds.images.len();
    if images != rig.leds.len() {
        return Err(PyValueError::new_err(format!(
            "rig {rig_name} has {} LEDs but {what} has {images} LED images",
            rig.leds.len()
        )));
    }
    let Some(shape) = decoded.leds.shape() else {
        return Err(PyValueError::new_err(format!("{what} holds no LED image")));
    };
    if (rig.camera.height, rig.camera.width) != shape {
        return Err(PyValueError::new_err(format!(
            "rig camera is {}x{} but the images are {}x{} (cropped with roi? use a rig of the \
             crop's size)",
            rig.camera.width, rig.camera.height, shape.1, shape.0
        )));
    }
    let mask = match mask {
        Some(mask) => {
            let mask = typed::<bool, Ix2>(mask, "mask", "bool", "a 2-D array (height, width)")?;
            let mask = mask.readonly();
            check_mask(&mask.as_array(), shape.0, shape.1, "the images")?;
            Some(mask.as_array().to_owned())
        }
        None => None,
    };
    let result = py.detach(|| {
        reconstruct_library(
            Source::Decoded(&decoded),
            &rig,
            &config,
            Request {
                mask: mask.as_ref(),
                ..Request::default()
            },
        )
        .map(|reconstruction| {
            let check = check_decoded_rig(&decoded, &rig, &reconstruction, &config);
            (reconstruction, check)
        })
    });
    let (reconstruction, rig_check) =
        result.map_err(|e| meb_error(Some(&format!("cannot reconstruct {what}")), &e))?;
    let implausible_result = !reconstruction.support.verdict.is_plausible();
    let hint = check_rig(py, &rig_check, &rig_name, force, implausible_result)?;
    check_support(py, &reconstruction, hint, force)?;
    let report = report(py, &decoded, &config, &reconstruction, &rig_check)?;
    Ok(Reconstruction::new(reconstruction, report))
}
