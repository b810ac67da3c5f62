//! `meb.integrate` and `meb.photometric`: a normal map into depth with
//! [`meb_pipeline::integrate::integrate_surface`] (as `meb integrate`), and LED or light images
//! with known light vectors into normals and albedo with
//! [`meb_pipeline::photometric::estimate_normals`] (as `meb photometric`).

use crate::arrays::{check_finite_in, check_mask, typed};
use crate::errors::meb_error;
use crate::reconstruct::integrator;
use crate::rig::rig_of;
use meb_core::rig::{Intrinsics, Projection};
use meb_core::types::{LedImages, NormalField};
use meb_pipeline::integrate::{IntegrateConfig, SurfaceEvidence, integrate_surface};
use meb_pipeline::photometric::{Lights, PhotometricConfig, estimate_normals};
use nalgebra::Vector3;
use ndarray::{Array2, Axis, Ix2, Ix3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The camera of `integrate`'s arguments for an image of `shape` (rows, columns), with the
/// rules of `meb integrate`'s camera flags: `rig`, or `K` with `distance`, or `pitch`.
fn projection(
    shape: (usize, usize),
    k: Option<[[f64; 3]; 3]>,
    distance: Option<f64>,
    pitch: Option<f64>,
    rig: Option<&Bound<'_, PyAny>>,
) -> PyResult<Projection> {
    let given = [k.is_some(), pitch.is_some(), rig.is_some()];
    if given.iter().filter(|&&g| g).count() > 1 {
        return Err(PyValueError::new_err(
            "give one camera: K (pinhole, with distance), pitch (orthographic) or rig",
        ));
    }
    if let Some(rig) = rig {
        let rig = rig_of(rig)?;
        let camera = &rig.inner.camera;
        if (camera.height, camera.width) != shape {
            return Err(PyValueError::new_err(format!(
                "rig {} has a {}x{} camera but the normals are {}x{} (rows x columns)",
                rig.name, camera.height, camera.width, shape.0, shape.1
            )));
        }
        return match (camera.projection(), distance) {
            (Projection::Perspective { intrinsics, .. }, Some(d)) => perspective(intrinsics, d),
            (projection @ Projection::Perspective { .. }, None) => Ok(projection),
            (_, Some(_)) => Err(PyValueError::new_err(format!(
                "distance applies to a pinhole camera; rig {}'s camera is orthographic",
                rig.name
            ))),
            (projection, None) => Ok(projection),
        };
    }
    if let Some(k) = k {
        let intrinsics = Intrinsics {
            fx: k[0][0],
            fy: k[1][1],
            cx: k[0][2],
            cy: k[1][2],
            k1: 0.0,
            k2: 0.0,
        };
        if !(k.iter().flatten().all(|v| v.is_finite())
            && intrinsics.fx > 0.0
            && intrinsics.fy > 0.0)
        {
            return Err(PyValueError::new_err(
                "K must be a finite 3x3 pinhole matrix with positive focal lengths fx = K[0,0], fy = K[1,1]",
            ));
        }
        let Some(distance) = distance else {
            return Err(PyValueError::new_err(
                "K needs distance: normals fix a perspective surface only up to its scale, so \
                 give the distance (mm) from the camera to the object's outline (any value \
                 gives the right shape up to scale)",
            ));
        };
        return perspective(intrinsics, distance);
    }
    if distance.is_some() {
        return Err(PyValueError::new_err(
            "distance applies to a pinhole camera (K or rig)",
        ));
    }
    match pitch {
        Some(p) if p.is_finite() && p > 0.0 => Ok(Projection::centred(p, (shape.1, shape.0))),
        Some(p) => Err(PyValueError::new_err(format!(
            "pitch must be a positive number of mm per pixel, got {p}"
        ))),
        None => Err(PyValueError::new_err(
            "no camera: give pitch (orthographic, mm per pixel), K with distance (pinhole) or rig",
        )),
    }
}

/// A pinhole projection with its outline `distance_mm` away.
fn perspective(intrinsics: Intrinsics, distance_mm: f64) -> PyResult<Projection> {
    if !(distance_mm.is_finite() && distance_mm > 0.0) {
        return Err(PyValueError::new_err(format!(
            "distance must be a positive number of mm, got {distance_mm}"
        )));
    }
    Ok(Projection::Perspective {
        intrinsics,
        distance_mm,
    })
}

/// Integrates a normal map into depth (see the package's `integrate`).
#[pyfunction]
#[pyo3(signature = (normals, mask, *, K = None, distance = None, pitch = None, rig = None, method = "auto", lambda_ = 0.06))]
#[allow(non_snake_case, clippy::too_many_arguments)]
pub fn integrate<'py>(
    py: Python<'py>,
    normals: &Bound<'py, PyAny>,
    mask: &Bound<'py, PyAny>,
    K: Option<[[f64; 3]; 3]>,
    distance: Option<f64>,
    pitch: Option<f64>,
    rig: Option<&Bound<'py, PyAny>>,
    method: &str,
    lambda_: f64,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let normals = typed::<f32, Ix3>(
        normals,
        "normals",
        "float32",
        "a 3-D array (height, width, 3)",
    )?;
    let shape = normals.shape().to_vec();
    if shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "normals must be (height, width, 3), got shape {shape:?}"
        )));
    }
    let (rows, cols) = (shape[0], shape[1]);
    let mask = typed::<bool, Ix2>(mask, "mask", "bool", "a 2-D array (height, width)")?;
    let mask = mask.readonly();
    check_mask(&mask.as_array(), rows, cols, "the normal map")?;
    let normals = normals.readonly();
    let normals_view = normals.as_array();
    check_finite_in(
        mask.as_array()
            .indexed_iter()
            .filter(|(_, m)| **m)
            .map(|(p, _)| {
                let finite = (0..3).all(|c| normals_view[[p.0, p.1, c]].is_finite());
                (p, finite)
            }),
        "normals",
    )?;
    let projection = projection((rows, cols), K, distance, pitch, rig)?;
    let config = IntegrateConfig {
        integrator: integrator(method)?,
        lambda: lambda_,
        ..IntegrateConfig::default()
    };
    // The library's normal field owns its arrays: one copy in.
    let field = NormalField {
        normals: normals_view.to_owned(),
        albedo: Array2::from_elem((rows, cols), 1.0),
        mask: mask.as_array().to_owned(),
    };
    drop(normals);
    drop(mask);
    let out = py
        .detach(|| {
            let evidence = SurfaceEvidence {
                field: &field,
                planes: &[],
                fill: None,
            };
            integrate_surface(&evidence, &projection, &config, None)
        })
        .map_err(|e| meb_error(Some("cannot integrate the normals"), &e))?;
    Ok(out.depth.depth_mm.into_pyarray(py))
}

/// Normals (H×W×3) and albedo (H×W) as numpy arrays.
type NormalsAndAlbedo<'py> = (Bound<'py, PyArray3<f32>>, Bound<'py, PyArray2<f32>>);

/// Photometric stereo with distant lights (see the package's `photometric`).
#[pyfunction]
#[pyo3(signature = (images, lights, *, mask = None))]
pub fn photometric<'py>(
    py: Python<'py>,
    images: &Bound<'py, PyAny>,
    lights: Vec<[f64; 3]>,
    mask: Option<&Bound<'py, PyAny>>,
) -> PyResult<NormalsAndAlbedo<'py>> {
    let images = typed::<f32, Ix3>(
        images,
        "images",
        "float32",
        "a 3-D array (images, height, width)",
    )?;
    let shape = images.shape().to_vec();
    let (count, rows, cols) = (shape[0], shape[1], shape[2]);
    if count < 3 {
        return Err(PyValueError::new_err(format!(
            "photometric stereo needs at least 3 images, got {count}"
        )));
    }
    if lights.len() != count {
        return Err(PyValueError::new_err(format!(
            "{count} images but {} light vectors (one (x, y, z) row per image)",
            lights.len()
        )));
    }
    if lights.iter().flatten().any(|v| !v.is_finite()) {
        return Err(PyValueError::new_err("lights hold NaN or infinity"));
    }
    let mask = match mask {
        Some(mask) => {
            let mask = typed::<bool, Ix2>(mask, "mask", "bool", "a 2-D array (height, width)")?;
            let mask = mask.readonly();
            check_mask(&mask.as_array(), rows, cols, "the images")?;
            Some(mask.as_array().to_owned())
        }
        None => None,
    };
    let images = images.readonly();
    let view = images.as_array();
    if let Some((index, _)) = view.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        let pixel = index % (rows * cols);
        return Err(PyValueError::new_err(format!(
            "images hold NaN or infinity (image {}, row {}, column {})",
            index / (rows * cols) + 1,
            pixel / cols,
            pixel % cols
        )));
    }
    // The library takes one owned array per image: one copy in.
    let set = LedImages {
        images: view.axis_iter(Axis(0)).map(|im| im.to_owned()).collect(),
    };
    drop(images);
    let lights = Lights::Distant(
        lights
            .iter()
            .map(|l| Vector3::new(l[0], l[1], l[2]))
            .collect(),
    );
    let result = py
        .detach(|| {
            estimate_normals(
                &set,
                &lights,
                mask.as_ref(),
                None,
                &PhotometricConfig::default(),
            )
        })
        .map_err(|e| meb_error(Some("photometric stereo failed"), &e))?;
    let field = result.field;
    Ok((
        field.normals.into_pyarray(py),
        field.albedo.into_pyarray(py),
    ))
}
