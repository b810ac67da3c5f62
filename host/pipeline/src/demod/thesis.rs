//! The thesis' reference decoder (thesis Eqs. 3.25–3.30,
//! docs/maths/demodulation.md#the-subspace-projection).
//!
//! For LED i the n×n matrix of all cyclic shifts of s_i has rank l_i = 2^(i+1); stabilised
//! Gram–Schmidt turns it into D_i (l_i × n). Per pixel r^(i) = D_iᵀD_i·r and I_i = max_j r^(i)_j,
//! reported as A_i = 2·I_i. [`decoding_matrix`] builds D_i exactly; the per-pixel decoder uses
//! the equivalent masked DFT (LED i's subspace = bins q with q mod 2^N an odd multiple of
//! 2^(N−1−i)), planned once with rustfft. Bin 2^N carries no LED and serves as the noise probe.

use super::window::{CodeMap, Region};
use meb_core::capture::Samples;
use protocol::carriers::chip_is_on;
use rayon::prelude::*;
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// D_i: the orthonormalised cyclic shifts of LED `led`'s carrier in an `leds`-LED table
/// (rows of n = 2^(leds+1) values), by modified Gram–Schmidt.
pub fn decoding_matrix(leds: usize, led: usize) -> Vec<Vec<f64>> {
    let n = 1usize << (leds + 1);
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for shift in 0..n {
        let mut v: Vec<f64> = (0..n)
            .map(|j| {
                if chip_is_on(led, (j + shift) % n) {
                    1.0
                } else {
                    -1.0
                }
            })
            .collect();
        for _ in 0..2 {
            for b in &basis {
                let d: f64 = b.iter().zip(&v).map(|(x, y)| x * y).sum();
                v.iter_mut().zip(b).for_each(|(x, y)| *x -= d * y);
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-9 {
            v.iter_mut().for_each(|x| *x /= norm);
            basis.push(v);
        }
    }
    basis
}

/// I_i = max_j (D_iᵀD_i r)_j with the explicit matrices (reference implementation).
pub fn decode_pixel_with_matrices(r: &[f64], leds: usize) -> Vec<f64> {
    (0..leds)
        .map(|led| {
            let d = decoding_matrix(leds, led);
            let coefficients: Vec<f64> = d
                .iter()
                .map(|row| row.iter().zip(r).map(|(a, b)| a * b).sum())
                .collect();
            (0..r.len())
                .map(|j| {
                    d.iter()
                        .zip(&coefficients)
                        .map(|(row, c)| row[j] * c)
                        .sum::<f64>()
                })
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .collect()
}

/// Whether DFT bin `q` belongs to LED `led`'s subspace in an `leds`-LED table.
pub fn bin_belongs_to(leds: usize, led: usize, q: usize) -> bool {
    let period = 1usize << leds;
    let unit = 1usize << (leds - 1 - led);
    let r = q % period;
    r != 0 && r.is_multiple_of(unit) && !(r / unit).is_multiple_of(2)
}

/// The thesis decoder planned for one LED count.
pub struct ThesisDecoder {
    leds: usize,
    forward: Arc<dyn Fft<f32>>,
    inverse: Arc<dyn Fft<f32>>,
    masks: Vec<Vec<bool>>,
}

impl ThesisDecoder {
    /// Plans the DFTs of length n = 2^(leds+1).
    pub fn new(leds: usize) -> Self {
        let n = 1usize << (leds + 1);
        let mut planner = FftPlanner::new();
        Self {
            leds,
            forward: planner.plan_fft_forward(n),
            inverse: planner.plan_fft_inverse(n),
            masks: (0..leds)
                .map(|led| (0..n).map(|q| bin_belongs_to(leds, led, q)).collect())
                .collect(),
        }
    }

    /// Frame length n.
    pub fn chips(&self) -> usize {
        1 << (self.leds + 1)
    }

    /// Decodes one pixel's n samples: writes I_i to `levels` and returns the noise-probe power
    /// |X[2^N]|²/n (≈ σ² for white noise). `spectrum`, `projection`, `scratch` are n-long buffers.
    pub fn decode_pixel(
        &self,
        spectrum: &mut [Complex32],
        projection: &mut [Complex32],
        scratch: &mut [Complex32],
        levels: &mut [f32],
    ) -> f32 {
        let n = self.chips();
        self.forward.process_with_scratch(spectrum, scratch);
        for (led, mask) in self.masks.iter().enumerate() {
            for ((p, s), &m) in projection.iter_mut().zip(spectrum.iter()).zip(mask) {
                *p = if m { *s } else { Complex32::new(0.0, 0.0) };
            }
            self.inverse.process_with_scratch(projection, scratch);
            levels[led] = projection
                .iter()
                .map(|c| c.re / n as f32)
                .fold(f32::NEG_INFINITY, f32::max);
        }
        spectrum[n / 2].norm_sqr() / n as f32
    }
}

/// Per-pixel thesis decode of a window: blocks of n frames, A_i = 2·I_i averaged over blocks.
/// Returns (`leds[i][p]`, noise variance, max code) like the matched filter.
pub fn thesis_window(
    frames: &[Samples],
    region: Region,
    leds: usize,
    map: &CodeMap,
    limits: super::matched::CodeLimits,
) -> super::matched::WindowAmplitudes {
    let decoder = ThesisDecoder::new(leds);
    let n = decoder.chips();
    let width = region.roi.width;
    let height = region.roi.height;
    let blocks = frames.len() / n;
    let scale = map.scale();
    let k = leds + 2;
    let mut out = vec![0.0f32; height * width * k];
    let scratch_len = decoder
        .forward
        .get_inplace_scratch_len()
        .max(decoder.inverse.get_inplace_scratch_len());
    out.par_chunks_mut(width * k).enumerate().for_each_init(
        || {
            (
                vec![Complex32::new(0.0, 0.0); n],
                vec![Complex32::new(0.0, 0.0); n],
                vec![Complex32::new(0.0, 0.0); scratch_len],
                vec![0.0f32; leds],
            )
        },
        |(spectrum, projection, scratch, levels), (row, row_out)| {
            for col in 0..width {
                let p = row * width + col;
                let pixel = &mut row_out[col * k..(col + 1) * k];
                let mut max_code = 0u16;
                for block in 0..blocks {
                    for (j, s) in spectrum.iter_mut().enumerate() {
                        let code = match &frames[block * n + j] {
                            Samples::U8(v) => u16::from(v[p]),
                            Samples::U16(v) => v[p],
                        };
                        max_code = max_code.max(code);
                        *s = Complex32::new(map.value(code), 0.0);
                    }
                    let noise = decoder.decode_pixel(spectrum, projection, scratch, levels);
                    for i in 0..leds {
                        pixel[i] += 2.0 * levels[i] * scale / blocks as f32;
                    }
                    pixel[leds] += noise * scale * scale / blocks as f32;
                }
                pixel[leds + 1] = f32::from(max_code);
            }
        },
    );
    let mut images = vec![vec![0.0f32; height * width]; leds];
    let mut noise_variance = vec![0.0f32; height * width];
    let mut saturated = vec![false; height * width];
    let mut underexposed = vec![false; height * width];
    for (p, pixel) in out.chunks(k).enumerate() {
        for (i, image) in images.iter_mut().enumerate() {
            image[p] = pixel[i];
        }
        noise_variance[p] = pixel[leds];
        (saturated[p], underexposed[p]) = limits.classify(pixel[leds + 1] as u16);
    }
    super::matched::WindowAmplitudes {
        leds: images,
        noise_variance,
        saturated,
        underexposed,
        stats: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn appendix_a_signal(offset: f64) -> Vec<f64> {
        let s = |led: usize, m: usize| if chip_is_on(led, m % 8) { 1.0 } else { -1.0 };
        let levels = [1.0, 2.0];
        let shifts = [(0usize, 0.3), (1usize, 0.7)];
        (0..8)
            .map(|j| {
                offset
                    + (0..2)
                        .map(|i| {
                            let (k, a) = shifts[i];
                            levels[i] * ((1.0 - a) * s(i, j + k) + a * s(i, j + k + 1))
                        })
                        .sum::<f64>()
            })
            .collect()
    }

    #[test]
    fn appendix_a_signal_matches_spec() {
        let expected = [1.2, -1.8, -2.4, 1.8, -0.4, -0.2, 1.6, 0.2];
        for (a, b) in appendix_a_signal(0.0).iter().zip(expected) {
            assert!((a - b).abs() < 1e-12);
        }
    }

    #[test]
    fn appendix_a_decodes_to_one_and_two_with_any_offset() {
        for offset in [0.0, 3.7, -12.5] {
            let levels = decode_pixel_with_matrices(&appendix_a_signal(offset), 2);
            assert!((levels[0] - 1.0).abs() < 1e-9, "{levels:?}");
            assert!((levels[1] - 2.0).abs() < 1e-9, "{levels:?}");
        }
        // The thesis' printed (time-reversed) vector decodes the same.
        let printed = [0.2, 1.6, -0.2, -0.4, 1.8, -2.4, -1.8, 1.2];
        let levels = decode_pixel_with_matrices(&printed, 2);
        assert!((levels[0] - 1.0).abs() < 1e-9 && (levels[1] - 2.0).abs() < 1e-9);
    }

    #[test]
    fn matrix_ranks_follow_spec() {
        for led in 0..4 {
            assert_eq!(decoding_matrix(4, led).len(), 2 << led);
        }
    }

    #[test]
    fn dft_decoder_equals_gram_schmidt_matrices() {
        let decoder = ThesisDecoder::new(3);
        let n = decoder.chips();
        let r: Vec<f64> = (0..n)
            .map(|j| ((j * 7919) % 13) as f64 * 0.1 - 0.4)
            .collect();
        let reference = decode_pixel_with_matrices(&r, 3);
        let mut spectrum: Vec<Complex32> =
            r.iter().map(|&v| Complex32::new(v as f32, 0.0)).collect();
        let mut projection = vec![Complex32::new(0.0, 0.0); n];
        let mut scratch = vec![
            Complex32::new(0.0, 0.0);
            decoder
                .forward
                .get_inplace_scratch_len()
                .max(decoder.inverse.get_inplace_scratch_len())
        ];
        let mut levels = [0.0f32; 3];
        decoder.decode_pixel(&mut spectrum, &mut projection, &mut scratch, &mut levels);
        for (a, b) in levels.iter().zip(&reference) {
            assert!(
                (f64::from(*a) - b).abs() < 1e-4,
                "{levels:?} vs {reference:?}"
            );
        }
    }
}
