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

use meb_core::types::LedImages;
use ndarray::Array2;
use rayon::prelude::*;

/// Fewest negative readings from which g_i is measured (otherwise 1).
const MIN_SAMPLES: usize = 200;

/// Noise gain g_i ≥ 1 of every LED image: σ_i(p) = g_i·σ(p) (module docs). Ones without a
/// noise map.
pub fn led_noise_gains(images: &LedImages, noise: Option<&Array2<f32>>) -> Vec<f64> {
    let Some(noise) = noise else {
        return vec![1.0; images.images.len()];
    };
    let sums: Vec<(f64, usize)> = match noise.as_slice() {
        // A contiguous noise map is read as a slice, by pairs of images in parallel.
        Some(sigmas) => images
            .images
            .par_chunks(IMAGES_PER_TASK)
            .flat_map_iter(|images| sums_of(images, noise, sigmas))
            .collect(),
        None => images
            .images
            .iter()
            .map(|image| negative_sum(image, noise))
            .collect(),
    };
    sums.into_iter()
        .map(|(sum, count)| {
            if count >= MIN_SAMPLES {
                (sum / count as f64).sqrt().max(1.0)
            } else {
                1.0
            }
        })
        .collect()
}

/// LED images that share one pass over the noise map.
const IMAGES_PER_TASK: usize = 2;

/// Pixels whose readings are gathered at a time ([`negative_sums`]).
const BLOCK: usize = 1024;

/// [`negative_sum`] of each of `images` against `noise` (read as `sigmas`): by
/// [`negative_sums`] when the images are contiguous too.
fn sums_of(images: &[Array2<f32>], noise: &Array2<f32>, sigmas: &[f32]) -> Vec<(f64, usize)> {
    match images
        .iter()
        .map(|image| image.as_slice())
        .collect::<Option<Vec<_>>>()
    {
        Some(values) => negative_sums(&values, sigmas),
        None => images
            .iter()
            .map(|image| negative_sum(image, noise))
            .collect(),
    }
}

/// Whether reading `a` with noise σ `s` counts: negative, with σ positive and finite (NaN
/// fails every comparison). Written without branches.
fn counts(a: f32, s: f32) -> bool {
    (a < 0.0) & (s > 0.0) & (s < f32::INFINITY)
}

/// Σ (A/σ)² and the count over the readings of `image` that [`counts`], in row-major order.
fn negative_sum(image: &Array2<f32>, noise: &Array2<f32>) -> (f64, usize) {
    let (mut sum, mut count) = (0.0, 0usize);
    for (&a, &s) in image.iter().zip(noise.iter()) {
        if counts(a, s) {
            let z = f64::from(a) / f64::from(s);
            sum += z * z;
            count += 1;
        }
    }
    (sum, count)
}

/// [`negative_sum`] of each of `images` (row-major slices) against the noise map `sigmas`: the
/// same operations in the same order per image, so the same sums, arranged for speed. About
/// half of a dark background's readings are negative, at random, which a branch per reading
/// mispredicts; so block by block each image's counting readings are first gathered without
/// branches, their squares (A/σ)² computed apart (the divisions pipeline), and the images' sums
/// then advanced side by side (each sum waits on its previous addition, not on the others').
fn negative_sums(images: &[&[f32]], sigmas: &[f32]) -> Vec<(f64, usize)> {
    let mut sums = vec![(0.0f64, 0usize); images.len()];
    let mut squares = vec![[0.0f64; BLOCK]; images.len()];
    let mut kept = vec![0usize; images.len()];
    let (mut values, mut noise) = ([0.0f32; BLOCK], [0.0f32; BLOCK]);
    for (block, sigma_block) in sigmas.chunks(BLOCK).enumerate() {
        let start = block * BLOCK;
        // Where every σ of the block is positive and finite, only the signs of readings decide.
        let sigmas_valid = sigma_block
            .iter()
            .fold(true, |valid, &s| valid & (s > 0.0) & (s < f32::INFINITY));
        for ((image, squares), kept) in images.iter().zip(&mut squares).zip(&mut kept) {
            let value_block = image.get(start..).unwrap_or(&[]);
            let (kept_values, kept_sigmas) = (&mut values, &mut noise);
            *kept = if sigmas_valid {
                gather_counting(
                    value_block,
                    sigma_block,
                    |a, _| a < 0.0,
                    kept_values,
                    kept_sigmas,
                )
            } else {
                gather_counting(value_block, sigma_block, counts, kept_values, kept_sigmas)
            };
            for ((square, &a), &s) in squares.iter_mut().zip(&values[..*kept]).zip(&noise) {
                let z = f64::from(a) / f64::from(s);
                *square = z * z;
            }
        }
        let longest = kept.iter().copied().max().unwrap_or(0);
        for j in 0..longest {
            for ((sum, squares), &kept) in sums.iter_mut().zip(&squares).zip(&kept) {
                if j < kept {
                    sum.0 += squares[j];
                }
            }
        }
        for (sum, &kept) in sums.iter_mut().zip(&kept) {
            sum.1 += kept;
        }
    }
    sums
}

/// Copies the readings of `values` (paired with `sigmas`, up to the shorter) that [`counts`]
/// and their σ to the front of `kept_values` and `kept_sigmas`, in order, without a branch per
/// reading; returns how many. `counted` is [`counts`], or a cheaper test equal to it on these
/// readings.
fn gather_counting(
    values: &[f32],
    sigmas: &[f32],
    counted: impl Fn(f32, f32) -> bool,
    kept_values: &mut [f32; BLOCK],
    kept_sigmas: &mut [f32; BLOCK],
) -> usize {
    let mut kept = 0;
    for (&a, &s) in values.iter().zip(sigmas).take(BLOCK) {
        // Always written, kept only when it counts (the next one overwrites it otherwise);
        // `kept` never passes the readings seen, so it stays inside the block.
        kept_values[kept % BLOCK] = a;
        kept_sigmas[kept % BLOCK] = s;
        kept += usize::from(counted(a, s));
    }
    kept
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

    /// The blocked sums are the reading-by-reading ones bit for bit: over several blocks and a
    /// tail, with σ NaN, infinite, zero or negative in the first block and valid after it.
    #[test]
    fn blocked_sums_equal_the_reading_by_reading_sums() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let shape = (37, 101);
        let sigma = Array2::from_shape_fn(shape, |(r, c)| {
            let i = r * shape.1 + c;
            match (i < BLOCK).then_some(i % 97) {
                Some(0) => f32::NAN,
                Some(1) => f32::INFINITY,
                Some(2) => 0.0,
                Some(3) => -0.001,
                _ => 0.001 + 0.0001 * (c % 7) as f32,
            }
        });
        let normal = Normal::new(0.0, 0.002).expect("σ > 0");
        let images: Vec<Array2<f32>> = (0..3)
            .map(|i| {
                Array2::from_shape_fn(shape, |(_, c)| {
                    if c < 20 * i {
                        0.3
                    } else {
                        normal.sample(&mut rng) as f32
                    }
                })
            })
            .collect();
        let values: Vec<&[f32]> = images
            .iter()
            .map(|image| image.as_slice().expect("contiguous"))
            .collect();
        let blocked = negative_sums(&values, sigma.as_slice().expect("contiguous"));
        for (image, (sum, count)) in images.iter().zip(blocked) {
            let (expected_sum, expected_count) = negative_sum(image, &sigma);
            assert!(expected_count > 1000, "{expected_count}");
            assert_eq!(
                (sum.to_bits(), count),
                (expected_sum.to_bits(), expected_count)
            );
        }
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
