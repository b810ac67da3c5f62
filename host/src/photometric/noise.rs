//! Per-LED noise of decoded LED images.
//!
//! A decoder reports one noise σ per pixel (the level noise of an on-level A_i), but how much of
//! it reaches each LED's image depends on that LED's carrier, phase and the exposure: on a
//! simulated thesis capture (exposure 0.8) the spread of A_i about the truth was 1.4 to 3.5 times
//! the reported σ, by LED. The factor g_i is measured here from the readings themselves: a true
//! on-level is never negative, so a negative A_i can only come from noise on a pixel the LED
//! (nearly) does not light, and for those the mean of (A_i/σ)² over the negative readings is
//! g_i² (a half-normal sample of N(0, g_i²)).
//!
//! g_i is at least 1: σ(p) is the noise of a level estimated from the frames the carrier is on
//! (σ_A = σ_frame·√(2/N), the least an unbiased on-level from half of N frames can have;
//! Cramér–Rao for a mean), and separating the LEDs only adds to it. A smaller measured g_i
//! means the negative readings are not noise: in a noise-free capture they are rounding
//! residue of order 10⁻⁹ against a σ(p) of model residuals, which gave one LED g ≈ 10⁻⁴, a
//! weight 1/g² of 10⁶ times the others' in the solve and a shadow threshold of nothing, and
//! reconstructed 23 % of the object.

use crate::types::LedImages;
use ndarray::Array2;

/// Fewest negative readings from which g_i is measured (otherwise 1).
const MIN_SAMPLES: usize = 200;

/// Noise gain g_i ≥ 1 of every LED image: σ_i(p) = g_i·σ(p) (module docs). Ones without a
/// noise map.
pub fn led_noise_gains(images: &LedImages, noise: Option<&Array2<f32>>) -> Vec<f64> {
    let Some(noise) = noise else {
        return vec![1.0; images.images.len()];
    };
    images
        .images
        .iter()
        .map(|image| {
            let (mut sum, mut count) = (0.0, 0usize);
            for (&a, &s) in image.iter().zip(noise.iter()) {
                if a < 0.0 && s > 0.0 && s.is_finite() {
                    let z = f64::from(a) / f64::from(s);
                    sum += z * z;
                    count += 1;
                }
            }
            if count >= MIN_SAMPLES {
                (sum / count as f64).sqrt().max(1.0)
            } else {
                1.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn gains_come_from_the_negative_readings() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let shape = (60, 80);
        let sigma = Array2::from_shape_fn(shape, |(r, _)| 0.001 + 0.00002 * r as f32);
        // LED 1: noise gain 1, LED 2: gain 3; both dark on the left half, lit on the right.
        let images: Vec<Array2<f32>> = [1.0f32, 3.0]
            .iter()
            .map(|&g| {
                Array2::from_shape_fn(shape, |(r, c)| {
                    let truth = if c < 40 { 0.0 } else { 0.2 };
                    let n = Normal::new(0.0, f64::from(g * sigma[(r, c)])).unwrap();
                    truth + n.sample(&mut rng) as f32
                })
            })
            .collect();
        let gains = led_noise_gains(&LedImages { images }, Some(&sigma));
        assert!((gains[0] - 1.0).abs() < 0.08, "{gains:?}");
        assert!((gains[1] - 3.0).abs() < 0.25, "{gains:?}");
        let none = led_noise_gains(
            &LedImages {
                images: vec![Array2::zeros(shape)],
            },
            None,
        );
        assert_eq!(none, vec![1.0]);
    }

    /// A noise-free capture: the negative readings of an unlit LED are rounding residue, far
    /// below the pixel's σ, which must not make that LED's noise vanish.
    #[test]
    fn rounding_residue_is_not_noise() {
        let shape = (60, 80);
        let sigma = Array2::from_elem(shape, 1e-4f32);
        let images = vec![Array2::from_shape_fn(shape, |(r, c)| {
            if c < 40 {
                if (r + c) % 2 == 0 { -1e-9 } else { 1e-9 }
            } else {
                0.2
            }
        })];
        let gains = led_noise_gains(&LedImages { images }, Some(&sigma));
        assert_eq!(gains, vec![1.0]);
    }
}
