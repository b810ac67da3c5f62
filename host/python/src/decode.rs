//! `meb.decode`: a capture (a numpy frame stack or any file `meb decode` reads) into one image
//! per LED with [`meb_pipeline::demod::decode`], the decoder of `meb decode`.

use crate::arrays::view;
use crate::errors::{implausible, meb_error};
use crate::frames::{ArraySource, Codes};
use crate::json::to_python;
use meb_core::capture::{FrameFormat, FrameSource, OpenOptions, open};
use meb_core::io::{OutputFolder, Replace};
use meb_pipeline::demod::output::{read_decode_dir, write_decode_dir};
use meb_pipeline::demod::{
    DecodeConfig, Decoded as RustDecoded, DemodError, Estimator, LedCount, Linearize,
    OnImplausible, Roi, VerdictStatus, decode as decode_source,
};
use numpy::{PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Arc;

/// The LED images of a decode, their noise, the pixels that clipped or stayed dark, and the
/// decoder's report with its verdict (the contents of a `meb decode` folder).
#[pyclass(module = "meb", frozen)]
pub struct Decoded {
    /// The decode, shared with the arrays handed out (read-only views).
    pub inner: Arc<RustDecoded>,
}

#[pymethods]
impl Decoded {
    /// LED images A_i (one H×W float32 array per LED, LED 1 first; fraction of full scale).
    #[getter]
    fn images<'py>(slf: Bound<'py, Self>) -> Vec<Bound<'py, PyArray2<f32>>> {
        let inner = slf.get().inner.clone();
        inner
            .leds
            .images
            .iter()
            .map(|image| view(image, slf.clone().into_any()))
            .collect()
    }

    /// Per-pixel noise σ of one frame sample (H×W float32, fraction of full scale).
    #[getter]
    fn noise<'py>(slf: Bound<'py, Self>) -> Bound<'py, PyArray2<f32>> {
        let inner = slf.get().inner.clone();
        view(&inner.noise, slf.into_any())
    }

    /// Pixels that reached the white level in some frame (H×W bool).
    #[getter]
    fn saturated<'py>(slf: Bound<'py, Self>) -> Bound<'py, PyArray2<bool>> {
        let inner = slf.get().inner.clone();
        view(&inner.saturated, slf.into_any())
    }

    /// Pixels whose brightest frame stayed dark (H×W bool).
    #[getter]
    fn underexposed<'py>(slf: Bound<'py, Self>) -> Bound<'py, PyArray2<bool>> {
        let inner = slf.get().inner.clone();
        view(&inner.underexposed, slf.into_any())
    }

    /// The decoder's report (the fields of `decode.json`: timing, per-LED quality, verdict).
    #[getter]
    fn report(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        to_python(py, &self.inner.report)
    }

    /// The quality verdict: `status` (plausible, implausible, overridden), `problems`, `advice`.
    #[getter]
    fn verdict(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        to_python(py, &self.inner.report.verdict)
    }

    /// Number of LED images.
    #[getter]
    fn leds(&self) -> usize {
        self.inner.leds.images.len()
    }

    /// Image (height, width).
    #[getter]
    fn shape(&self) -> (usize, usize) {
        (self.inner.report.height, self.inner.report.width)
    }

    /// Reads a `meb decode` folder.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let decoded = py
            .detach(|| read_decode_dir(&path))
            .map_err(|e| meb_error(Some(&format!("cannot read {}", path.display())), &e))?;
        Ok(Self {
            inner: Arc::new(decoded),
        })
    }

    /// Writes the decode as a `meb decode` folder (led1.npy…, noise.npy, decode.json),
    /// replaced whole and atomically; a non-empty folder that is not an earlier decode is
    /// refused unless `force`.
    #[pyo3(signature = (path, *, force = false))]
    fn save(&self, py: Python<'_>, path: PathBuf, force: bool) -> PyResult<()> {
        let inner = self.inner.clone();
        py.detach(
            move || -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
                let replace = if force {
                    Replace::Anything
                } else {
                    Replace::EarlierOutput
                };
                let folder = OutputFolder::create(&path, "decode", replace)?;
                write_decode_dir(folder.path(), &inner)?;
                folder.commit()?;
                Ok(())
            },
        )
        .map_err(|e| meb_error(Some("cannot write the decode folder"), e.as_ref()))
    }

    fn __repr__(&self) -> String {
        let r = &self.inner.report;
        format!(
            "Decoded({} LEDs, {}x{}, {} frames, verdict {:?})",
            r.leds, r.width, r.height, r.frames_used, r.verdict.status
        )
    }
}

/// The decoder settings of `decode` and of `reconstruct` on a capture.
pub struct DecodeSettings {
    /// LED count, or detect.
    pub leds: LedCount,
    /// The config without the LED count.
    pub config: DecodeConfig,
    /// Camera frame rate (frame arrays: the stream's; files: an override).
    pub fps: Option<f64>,
    /// Bits per sample of a uint16 frame stack.
    pub bit_depth: Option<u8>,
}

/// The LED count from `leds`: an int 1..=8 or "auto".
pub fn led_count(leds: &Bound<'_, PyAny>) -> PyResult<LedCount> {
    if let Ok(text) = leds.extract::<String>() {
        return match text.as_str() {
            "auto" => Ok(LedCount::Auto),
            _ => Err(PyValueError::new_err(format!(
                "leds must be an int (1..=8) or 'auto', got {text:?}"
            ))),
        };
    }
    match leds.extract::<usize>() {
        Ok(n) if (1..=8).contains(&n) => Ok(LedCount::Fixed(n)),
        _ => Err(PyValueError::new_err(format!(
            "leds must be an int (1..=8) or 'auto', got {leds}"
        ))),
    }
}

/// Parses `none`, `srgb` or `gamma:G`.
pub fn linearize(text: &str) -> PyResult<Linearize> {
    match text {
        "none" => Ok(Linearize::None),
        "srgb" => Ok(Linearize::Srgb),
        _ => match text.strip_prefix("gamma:").map(str::parse::<f32>) {
            Some(Ok(g)) if g.is_finite() && g > 0.0 => Ok(Linearize::Gamma(g)),
            _ => Err(PyValueError::new_err(format!(
                "linearize must be 'none', 'srgb' or 'gamma:G' with G > 0, got {text:?}"
            ))),
        },
    }
}

/// Parses the estimator name.
pub fn estimator(text: &str) -> PyResult<Estimator> {
    match text {
        "waveform" => Ok(Estimator::Waveform),
        "thesis" => Ok(Estimator::Thesis),
        _ => Err(PyValueError::new_err(format!(
            "estimator must be 'waveform' or 'thesis', got {text:?}"
        ))),
    }
}

/// The keyword arguments that address a decode error, as the `meb decode` flags do.
fn hint(error: &DemodError) -> Option<String> {
    Some(match error {
        DemodError::LedCountMismatch { detected, .. } => {
            format!("(use leds={detected} or leds='auto'; check_led_count=False skips the check)")
        }
        DemodError::LedsHiddenByClipping { .. } => "(check_led_count=False decodes the pixels \
             that do not clip anyway; the clipped ones are flagged in Decoded.saturated)"
            .into(),
        DemodError::NoModulation => "(check leds, fps and max_rate_mismatch)".into(),
        DemodError::StartBeyondEnd { .. } => "(lower start)".into(),
        _ => return None,
    })
}

/// What the decoder reads: a borrowed frame stack or an opened file.
enum Input<'a> {
    Array(ArraySource<'a>),
    File(Box<dyn FrameSource>),
}

/// Decodes `source` (a frame array or a path) with `settings`; `force` keeps a result the
/// verdict finds implausible (warning), else it raises `ImplausibleError` with the verdict.
pub fn decode_any(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    settings: &DecodeSettings,
    force: bool,
) -> PyResult<RustDecoded> {
    let config = DecodeConfig {
        leds: settings.leds,
        fps: if source.cast::<numpy::PyUntypedArray>().is_ok() {
            None
        } else {
            settings.fps
        },
        on_implausible: OnImplausible::Keep,
        ..settings.config.clone()
    };
    let (decoded, what) = if let Ok(array) = source.cast::<numpy::PyUntypedArray>() {
        let shape = array.shape().to_vec();
        let [count, height, width] = shape[..] else {
            return Err(PyValueError::new_err(format!(
                "frames must be a 3-D array (frames, height, width), got shape {shape:?}"
            )));
        };
        if !array.is_c_contiguous() {
            return Err(PyValueError::new_err(
                "frames must be C-contiguous (meb reads them where they lie and copies \
                 nothing silently: pass np.ascontiguousarray(frames))",
            ));
        }
        let fps = settings.fps.unwrap_or(0.0);
        if !(fps.is_finite() && fps >= 0.0) {
            return Err(PyValueError::new_err(format!(
                "fps must be a positive frame rate, got {fps}"
            )));
        }
        let what = "cannot decode the frames".to_string();
        if let Ok(frames) = array.cast::<numpy::PyArray3<u8>>() {
            if settings.bit_depth.is_some_and(|b| b != 8) {
                return Err(PyValueError::new_err(
                    "bit_depth applies to uint16 frames; uint8 frames are 8-bit",
                ));
            }
            let frames = frames.readonly();
            let codes = frames
                .as_slice()
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            let format = FrameFormat::full_range(width, height, 8, fps);
            let mut input = Input::Array(ArraySource::new(Codes::U8(codes), format, count));
            (py.detach(|| run(&mut input, &config)), what)
        } else if let Ok(frames) = array.cast::<numpy::PyArray3<u16>>() {
            let bits = settings.bit_depth.unwrap_or(16);
            if !matches!(bits, 9..=16) {
                return Err(PyValueError::new_err(format!(
                    "bit_depth of uint16 frames must be 9..=16, got {bits}"
                )));
            }
            let frames = frames.readonly();
            let codes = frames
                .as_slice()
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            let format = FrameFormat::full_range(width, height, bits, fps);
            let mut input = Input::Array(ArraySource::new(Codes::U16(codes), format, count));
            (py.detach(|| run(&mut input, &config)), what)
        } else {
            return Err(PyTypeError::new_err(format!(
                "frames must be uint8 or uint16 code values, got {} (meb converts nothing \
                 silently: scale and pass frames.astype(np.uint16) yourself)",
                array.dtype()
            )));
        }
    } else {
        let path: PathBuf = source.extract().map_err(|_| {
            PyTypeError::new_err(
                "source must be a frame array (frames, height, width) of uint8/uint16, or a \
                 path to a capture",
            )
        })?;
        let options = OpenOptions {
            fps: settings.fps,
            raw: None,
        };
        let opened = py
            .detach(|| open(&path, &options))
            .map_err(|e| meb_error(Some(&format!("cannot open {}", path.display())), &e))?;
        let mut input = Input::File(opened);
        let what = format!("cannot decode {}", path.display());
        (py.detach(|| run(&mut input, &config)), what)
    };
    let decoded = decoded.map_err(|e| match hint(&e) {
        Some(hint) => crate::errors::MebError::new_err(format!("{what}: {e} {hint}")),
        None => meb_error(Some(&what), &e),
    })?;
    judge(py, decoded, force)
}

/// Runs the decoder on `input`.
fn run(input: &mut Input<'_>, config: &DecodeConfig) -> Result<RustDecoded, DemodError> {
    let source: &mut dyn FrameSource = match input {
        Input::Array(source) => source,
        Input::File(source) => source.as_mut(),
    };
    decode_source(source, config, &mut |_, _| {})
}

/// Applies the verdict: a plausible decode passes; an implausible one raises
/// `ImplausibleError` with the decoder's message, unless `force` (then a warning, the verdict
/// recorded as overridden).
fn judge(py: Python<'_>, decoded: RustDecoded, force: bool) -> PyResult<RustDecoded> {
    let verdict = &decoded.report.verdict;
    if verdict.status != VerdictStatus::Overridden {
        return Ok(decoded);
    }
    let problems = verdict.problems.join("; ");
    if force {
        crate::refusals::warn(
            py,
            &format!("kept an implausible decode (force=True): {problems}"),
        )?;
        return Ok(decoded);
    }
    let message = DemodError::Implausible {
        problems,
        advice: verdict.advice.join("; "),
    }
    .to_string();
    let mut report = decoded.report.clone();
    report.verdict.status = VerdictStatus::Implausible;
    Err(implausible(
        py,
        format!("{message} (force=True keeps the result with the verdict recorded)"),
        to_python(py, &report.verdict)?,
        Some(to_python(py, &report)?),
    ))
}

/// Reads the decoder keyword arguments.
#[allow(clippy::too_many_arguments)]
pub fn settings(
    leds: LedCount,
    fps: Option<f64>,
    bit_depth: Option<u8>,
    frames: Option<usize>,
    start: usize,
    estimator_name: &str,
    linearize_name: &str,
    roi: Option<(usize, usize, usize, usize)>,
    rate_ratio: Option<f64>,
    max_rate_mismatch: f64,
    exposure: Option<f64>,
    line_time_us: Option<f64>,
    check_led_count: bool,
) -> PyResult<DecodeSettings> {
    Ok(DecodeSettings {
        leds,
        fps,
        bit_depth,
        config: DecodeConfig {
            leds,
            frames,
            start,
            estimator: estimator(estimator_name)?,
            linearize: linearize(linearize_name)?,
            roi: roi.map(|(x, y, width, height)| Roi {
                x,
                y,
                width,
                height,
            }),
            rate_ratio,
            max_rate_mismatch,
            exposure,
            line_time_s: line_time_us.map(|us| us * 1e-6),
            check_led_count,
            ..DecodeConfig::default()
        },
    })
}

/// Decodes a capture into one image per LED (see the package's `decode`).
#[pyfunction]
#[pyo3(signature = (
    source, leds = None, *, fps = None, bit_depth = None, frames = None, start = 0,
    estimator = "waveform", linearize = "none", roi = None, rate_ratio = None,
    max_rate_mismatch = 0.06, exposure = None, line_time_us = None, check_led_count = true,
    force = false
))]
#[allow(clippy::too_many_arguments)]
pub fn decode(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
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
    force: bool,
) -> PyResult<Decoded> {
    let leds = leds
        .map(led_count)
        .transpose()?
        .unwrap_or(LedCount::Fixed(4));
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
    Ok(Decoded {
        inner: Arc::new(decoded),
    })
}
