//! A nominal rig that differs from the true one as a rough measurement would: what an
//! installer writes down with a tape measure, and LEDs of one batch whose brightness differs
//! from the data sheet. A capture is rendered with the true rig while the nominal one is
//! handed to the pipeline, so the rig check and the calibration can be tested against truth.
//!
//! Each LED is moved by exactly `position_mm` in a direction drawn uniformly on the sphere
//! (a normalised three-dimensional standard normal vector), and its relative intensity is
//! multiplied by a factor drawn uniformly from [1 − `intensity`, 1 + `intensity`]; the draws
//! come from a ChaCha8 stream of `seed`, so a seed always gives the same nominal rig.

use crate::SimulateError;
use meb_core::rig::Rig;
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// How far a nominal rig lies from the true one (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigError {
    /// Distance in mm by which every LED is moved.
    pub position_mm: f64,
    /// Largest relative change of an LED's intensity, in [0, 1).
    pub intensity: f64,
    /// Seed of the directions and factors.
    pub seed: u64,
}

impl RigError {
    /// `rig` with every LED moved and rescaled as the module docs say; the camera is kept.
    pub fn apply(&self, rig: &Rig) -> Result<Rig, SimulateError> {
        let bad = |field: &str, reason: String| SimulateError::Invalid {
            field: field.to_string(),
            reason,
        };
        if !(self.position_mm.is_finite() && self.position_mm >= 0.0) {
            return Err(bad(
                "perturb_leds_mm",
                format!("must be a distance ≥ 0 mm, got {}", self.position_mm),
            ));
        }
        if !(self.intensity.is_finite() && (0.0..1.0).contains(&self.intensity)) {
            return Err(bad(
                "perturb_intensity",
                format!("must lie in [0, 1), got {}", self.intensity),
            ));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x4e4f_4d49_4e41_4c00);
        let mut nominal = rig.clone();
        for led in &mut nominal.leds {
            let direction = loop {
                let v = Vector3::<f64>::from_fn(|_, _| rng.sample(StandardNormal));
                if v.norm() > 1e-6 {
                    break v.normalize();
                }
            };
            let moved = led.position() + direction * self.position_mm;
            led.position_mm = [moved.x, moved.y, moved.z];
            let factor = 1.0 + self.intensity * rng.random_range(-1.0..=1.0);
            led.intensity *= factor;
        }
        nominal.validate()?;
        Ok(nominal)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_led_moves_by_the_distance_and_stays_within_the_intensity_range() {
        let rig = Rig::preset("thesis-out-of-plane").expect("preset");
        for seed in 0..20 {
            let error = RigError {
                position_mm: 35.0,
                intensity: 0.1,
                seed,
            };
            let nominal = error.apply(&rig).expect("applies");
            assert_eq!(nominal.camera, rig.camera);
            for (n, t) in nominal.leds.iter().zip(&rig.leds) {
                let moved = (n.position() - t.position()).norm();
                assert!((moved - 35.0).abs() < 1e-9, "seed {seed}: moved {moved} mm");
                let ratio = n.intensity / t.intensity;
                assert!((0.9..=1.1).contains(&ratio), "seed {seed}: {ratio}");
            }
            assert_eq!(error.apply(&rig).expect("again"), nominal, "not repeatable");
        }
        let other = RigError {
            position_mm: 35.0,
            intensity: 0.1,
            seed: 1,
        };
        let first = RigError { seed: 0, ..other };
        assert_ne!(other.apply(&rig).ok(), first.apply(&rig).ok());
    }

    #[test]
    fn out_of_range_errors_are_refused() {
        let rig = Rig::preset("thesis-out-of-plane").expect("preset");
        for (position_mm, intensity) in [(-1.0, 0.0), (f64::NAN, 0.0), (1.0, 1.0), (1.0, -0.1)] {
            let error = RigError {
                position_mm,
                intensity,
                seed: 0,
            };
            assert!(error.apply(&rig).is_err(), "{error:?} accepted");
        }
    }
}
