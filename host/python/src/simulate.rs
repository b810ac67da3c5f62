//! `meb.simulate`: a synthetic MEB-FDMA capture with its ground truth, rendered in memory by
//! [`meb_sim::SimulatedCapture`] (the simulator of `meb simulate`, which depends on no
//! pipeline code).

use crate::errors::meb_error;
use crate::json::to_python;
use crate::rig::{Rig, rig_of};
use meb_core::capture::Samples;
use meb_sim::{
    GroundPlane, NoiseModel, Scene, SceneObject, SimConfig, SimulatedCapture, Spin, ToneCurve,
};
use nalgebra::{Unit, Vector3};
use ndarray::{Array3, Axis};
use numpy::IntoPyArray;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// A simulated capture: the frames as the camera recorded them (code values) and the ground
/// truth at the truth frame.
#[pyclass(module = "meb", frozen, get_all)]
pub struct Capture {
    /// N×H×W frames: uint8 for 8-bit captures, else uint16 code values.
    pub frames: Py<PyAny>,
    /// Camera frame rate, frames per second.
    pub fps: f64,
    /// Bits per sample.
    pub bit_depth: u8,
    /// H×W float32 surface height z in mm; NaN outside the objects.
    pub depth: Py<PyAny>,
    /// H×W×3 float32 unit normals; NaN outside the objects.
    pub normals: Py<PyAny>,
    /// H×W bool object pixels.
    pub mask: Py<PyAny>,
    /// H×W float32 albedo; NaN outside the objects.
    pub albedo: Py<PyAny>,
    /// What a perfect decoder returns: one H×W float32 image per LED (no background, no noise).
    pub led_images: Vec<Py<PyAny>>,
    /// The capture's facts (`truth.json`): phases, chip rates, gain, noise, seed…
    pub info: Py<PyAny>,
    /// The rig the capture was rendered with.
    pub rig: Py<Rig>,
}

#[pymethods]
impl Capture {
    fn __repr__(&self, py: Python<'_>) -> String {
        let shape = self
            .frames
            .bind(py)
            .getattr("shape")
            .map_or_else(|_| "?".to_string(), |s| s.to_string());
        format!(
            "Capture(frames {shape}, {} fps, {}-bit)",
            self.fps, self.bit_depth
        )
    }
}

/// Three finite numbers.
fn vec3(values: &[f64], name: &str) -> PyResult<Vector3<f64>> {
    match values {
        [x, y, z] if values.iter().all(|v| v.is_finite()) => Ok(Vector3::new(*x, *y, *z)),
        _ => Err(PyValueError::new_err(format!(
            "{name} needs three finite numbers x, y, z"
        ))),
    }
}

/// A positive finite number.
fn positive(value: f64, name: &str) -> PyResult<f64> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(PyValueError::new_err(format!(
            "{name} must be a positive number, got {value}"
        )))
    }
}

/// The objects of a named scene, as `meb simulate --scene` builds them.
fn objects(
    scene: &str,
    size_mm: Option<f64>,
    corner: bool,
    axes_mm: &[f64],
) -> PyResult<Vec<SceneObject>> {
    let size = size_mm.map(|s| positive(s, "size_mm")).transpose()?;
    Ok(match scene {
        "sphere" => vec![SceneObject::sphere(size.unwrap_or(48.0))],
        "cube" => vec![SceneObject::cube(size.unwrap_or(75.0), corner)],
        "ellipsoid" => {
            let axes = vec3(axes_mm, "axes_mm")?;
            for a in axes.iter() {
                positive(*a, "axes_mm")?;
            }
            vec![SceneObject::ellipsoid([axes.x, axes.y, axes.z])]
        }
        "multi" => {
            let mut sphere = SceneObject::sphere(48.0);
            sphere.position_mm = Vector3::new(-40.0, 0.0, 0.0);
            let mut cube = SceneObject::cube(40.0, false);
            cube.position_mm = Vector3::new(45.0, 0.0, -70.0);
            vec![sphere, cube]
        }
        _ => {
            return Err(PyValueError::new_err(format!(
                "scene must be 'sphere', 'cube', 'ellipsoid' or 'multi', got {scene:?} (meshes, \
                 blobby shapes and the hybrid scene: `meb simulate`)"
            )));
        }
    })
}

/// Renders a synthetic capture in memory (see the package's `simulate`).
#[pyfunction]
#[pyo3(signature = (
    rig = None, scene = "sphere", *, size_mm = None, corner = false,
    axes_mm = vec![100.0, 60.0, 60.0], albedo = None, ground_mm = None, ground_albedo = 0.5,
    rpm = 0.0, spin_axis = vec![0.0, 1.0, 0.0], frames = 128, exposure = 1.0,
    line_time_us = 0.0, bit_depth = 8, noise = 0.005, gain = None, peak = None, phases = None,
    seed = 0, camera_size = None, truth_frame = 0
))]
#[allow(clippy::too_many_arguments)]
pub fn simulate(
    py: Python<'_>,
    rig: Option<&Bound<'_, PyAny>>,
    scene: &str,
    size_mm: Option<f64>,
    corner: bool,
    axes_mm: Vec<f64>,
    albedo: Option<f64>,
    ground_mm: Option<f64>,
    ground_albedo: f64,
    rpm: f64,
    spin_axis: Vec<f64>,
    frames: usize,
    exposure: f64,
    line_time_us: f64,
    bit_depth: u8,
    noise: f64,
    gain: Option<f64>,
    peak: Option<f64>,
    phases: Option<Vec<f64>>,
    seed: u64,
    camera_size: Option<(usize, usize)>,
    truth_frame: usize,
) -> PyResult<Capture> {
    let mut rig = match rig {
        Some(rig) => rig_of(rig)?,
        None => Rig::load("thesis-out-of-plane".into())?,
    };
    if let Some((width, height)) = camera_size {
        let camera = &mut rig.inner.camera;
        if camera.intrinsics.is_some() {
            return Err(PyValueError::new_err(
                "camera_size cannot resize a pinhole camera with intrinsics; load a rig of that size instead",
            ));
        }
        if let Some(pitch) = camera.pixel_pitch_mm {
            camera.pixel_pitch_mm = Some(pitch * camera.width as f64 / width as f64);
        }
        camera.width = width;
        camera.height = height;
    }
    if frames == 0 || truth_frame >= frames {
        return Err(PyValueError::new_err(format!(
            "truth_frame {truth_frame} is past the last frame ({frames} frames)"
        )));
    }
    let mut objects = objects(scene, size_mm, corner, &axes_mm)?;
    let spin = if rpm != 0.0 {
        let axis = Unit::try_new(vec3(&spin_axis, "spin_axis")?, 1e-12)
            .ok_or_else(|| PyValueError::new_err("spin_axis must not be zero"))?;
        Some(Spin { axis, rpm })
    } else {
        None
    };
    for object in &mut objects {
        if let Some(albedo) = albedo {
            object.albedo = albedo;
        }
        object.spin = spin.clone();
    }
    let scene = Scene {
        objects,
        ground: ground_mm.map(|z_mm| GroundPlane {
            z_mm,
            albedo: ground_albedo,
        }),
    };
    let config = SimConfig {
        frames,
        exposure,
        line_time_s: line_time_us * 1e-6,
        bit_depth,
        noise: NoiseModel {
            sigma: noise,
            full_well_electrons: None,
        },
        tone: ToneCurve::Linear,
        gain,
        peak: peak.unwrap_or(0.4),
        phases_chips: phases,
        seed,
        ..SimConfig::default()
    };
    let rendered = py.detach(|| -> Result<_, meb_sim::SimulateError> {
        let capture = SimulatedCapture::new(rig.inner.clone(), scene, config)?;
        let (h, w) = (capture.rig().camera.height, capture.rig().camera.width);
        let mut codes8 = (bit_depth == 8).then(|| Array3::<u8>::zeros((frames, h, w)));
        let mut codes16 = (bit_depth != 8).then(|| Array3::<u16>::zeros((frames, h, w)));
        for index in 0..frames {
            let frame = capture.render_frame(index);
            match (&frame.samples, codes8.as_mut(), codes16.as_mut()) {
                (Samples::U8(s), Some(out), _) => out
                    .index_axis_mut(Axis(0), index)
                    .as_slice_mut()
                    .map(|o| o.copy_from_slice(s))
                    .unwrap_or(()),
                (Samples::U16(s), _, Some(out)) => out
                    .index_axis_mut(Axis(0), index)
                    .as_slice_mut()
                    .map(|o| o.copy_from_slice(s))
                    .unwrap_or(()),
                _ => {}
            }
        }
        let truth = capture.truth_at(capture.frame_time(truth_frame));
        Ok((
            codes8,
            codes16,
            truth,
            capture.info().clone(),
            capture.rig().camera.fps,
        ))
    });
    let (codes8, codes16, truth, info, fps) =
        rendered.map_err(|e| meb_error(Some("cannot simulate the capture"), &e))?;
    let frames: Py<PyAny> = match (codes8, codes16) {
        (Some(codes), _) => codes.into_pyarray(py).into_any().unbind(),
        (_, Some(codes)) => codes.into_pyarray(py).into_any().unbind(),
        _ => unreachable!("one of the two code arrays is made"),
    };
    Ok(Capture {
        frames,
        fps,
        bit_depth,
        depth: truth.depth_mm.into_pyarray(py).into_any().unbind(),
        normals: truth.normals.into_pyarray(py).into_any().unbind(),
        mask: truth.mask.into_pyarray(py).into_any().unbind(),
        albedo: truth.albedo.into_pyarray(py).into_any().unbind(),
        led_images: truth
            .led_true
            .images
            .into_iter()
            .map(|im| im.into_pyarray(py).into_any().unbind())
            .collect(),
        info: to_python(py, &info)?,
        rig: Py::new(py, rig)?,
    })
}
