//! Calibrating a rig from its own captures: each LED's position and relative intensity from
//! captures of a matte sphere of known diameter ([`sphere`] finds it, [`lights`] fits the
//! LEDs on the reconstruction's near-field model), and the camera's intrinsics from photos of
//! a chequerboard ([`camera`]).
//!
//! [`calibrate_lights`] is the one path from decoded sphere captures to a fitted rig: `meb
//! calibrate lights` and the tests call it.

pub mod camera;
pub mod lights;
pub mod sphere;
pub mod sphere_check;

pub use camera::{CameraCalibration, calibrate_camera};
pub use lights::{LedFit, LightFit, SphereCapture, fit_lights};
pub use sphere::{SphereFit, find_sphere};
pub use sphere_check::{SphereCheck, check_sphere};

use crate::demod::Decoded;
use crate::photometric::led_noise_gains;
use crate::reconstruct::{level_noise, usable_led_images};
use meb_core::rig::Rig;
use thiserror::Error;

/// Errors of calibration.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CalibrateError {
    /// The inputs cannot be calibrated from.
    #[error("{0}")]
    Input(String),
    /// No sphere of the given size was found in a capture.
    #[error("no sphere found: {0}")]
    NoSphere(String),
    /// A photo does not show the whole calibration board.
    #[error("{0}")]
    NoBoard(String),
    /// The fitted model does not explain the data.
    #[error("calibration refused: {0}")]
    NoFit(String),
    /// An LED lights too little of the sphere in every capture.
    #[error(
        "LED {led} lights only {lit} of the sphere's pixels in all captures: is it on and \
         connected, and does it face the sphere?"
    )]
    DarkLed {
        /// LED number, from 1.
        led: usize,
        /// Sphere pixels it lights clearly.
        lit: usize,
    },
}

/// What [`calibrate_lights`] found: the sphere in each capture and the fitted LEDs.
#[derive(Debug, Clone)]
pub struct LightCalibration {
    /// The sphere found in each capture (silhouette fits).
    pub spheres: Vec<SphereFit>,
    /// The fitted LEDs, with the rig.
    pub fit: LightFit,
}

/// Calibrates `nominal`'s LEDs from decoded captures of a matte sphere of `diameter_mm`
/// (module docs); the error names the capture (from 1) whose sphere was not found.
pub fn calibrate_lights(
    decoded: &[Decoded],
    nominal: &Rig,
    diameter_mm: f64,
) -> Result<LightCalibration, CalibrateError> {
    if !(diameter_mm.is_finite() && diameter_mm > 0.0) {
        return Err(CalibrateError::Input(format!(
            "the sphere's diameter must be a positive length, got {diameter_mm} mm"
        )));
    }
    if nominal.leds.len() < 3 {
        return Err(CalibrateError::Input(format!(
            "the rig has {} LEDs; at least 3 are needed",
            nominal.leds.len()
        )));
    }
    let mut prepared = Vec::with_capacity(decoded.len());
    for (c, d) in decoded.iter().enumerate() {
        if d.leds.images.len() != nominal.leds.len() {
            return Err(CalibrateError::Input(format!(
                "capture {} has {} LED images but the rig {} LEDs",
                c + 1,
                d.leds.images.len(),
                nominal.leds.len()
            )));
        }
        if d.leds.shape() != Some((nominal.camera.height, nominal.camera.width)) {
            return Err(CalibrateError::Input(format!(
                "capture {}'s images are not of the rig camera's size {}x{}",
                c + 1,
                nominal.camera.width,
                nominal.camera.height
            )));
        }
        let images = usable_led_images(d);
        let noise = level_noise(d);
        // An image brought to full depth carries its scale in its noise (crate::demod::depth).
        let gains: Vec<f64> = led_noise_gains(&images, Some(&noise))
            .into_iter()
            .enumerate()
            .map(|(i, g)| g.max(d.report.modulation.scale(i)))
            .collect();
        let (sphere, region) = find_sphere(&images.images, &noise, nominal, diameter_mm / 2.0)
            .map_err(|e| match e {
                CalibrateError::NoSphere(why) => {
                    CalibrateError::NoSphere(format!("capture {}: {why}", c + 1))
                }
                other => other,
            })?;
        prepared.push((images, noise, gains, sphere, region));
    }
    let captures: Vec<SphereCapture> = prepared
        .iter()
        .map(|(images, noise, gains, sphere, region)| SphereCapture {
            images: &images.images,
            noise,
            noise_gains: gains,
            sphere,
            region,
        })
        .collect();
    let fit = fit_lights(nominal, &captures)?;
    Ok(LightCalibration {
        spheres: prepared.into_iter().map(|p| p.3).collect(),
        fit,
    })
}
