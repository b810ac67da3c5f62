//! The per-pixel matched filter: least squares of every pixel against the fitted waveforms.
//!
//! One pass over the window's frames accumulates, per pixel, the K projections Q·r and |r|²
//! ([`super::basis`]); work is split into row blocks run in parallel with rayon, each block
//! keeping its sums in cache. The inner loops are allocation-free axpy loops over a row.

use super::basis::TemplateBasis;
use super::window::{CodeMap, Region};
use crate::capture::Samples;
use rayon::prelude::*;

/// Rows per parallel task.
const ROWS_PER_TASK: usize = 8;

/// Per-pixel results of one window.
#[derive(Debug, Clone)]
pub struct WindowAmplitudes {
    /// `leds[i][p]`: A_i of pixel p (fraction of full scale).
    pub leds: Vec<Vec<f32>>,
    /// Per-frame noise variance σ² of pixel p (fraction² of full scale).
    pub noise_variance: Vec<f32>,
    /// Largest code value of pixel p over the window.
    pub max_code: Vec<u16>,
}

/// Runs the matched filter over a window: `bases[b]` is the template basis of row band b.
pub fn matched_filter(
    frames: &[Samples],
    region: Region,
    bases: &[TemplateBasis],
    map: &CodeMap,
) -> WindowAmplitudes {
    let width = region.roi.width;
    let height = region.roi.height;
    let k = bases.first().map_or(1, |b| b.columns);
    let stride = (k + 1) * width;
    let mut sums = vec![0.0f32; height * stride];
    let mut max_code = vec![0u16; height * width];
    sums.par_chunks_mut(ROWS_PER_TASK * stride)
        .zip(max_code.par_chunks_mut(ROWS_PER_TASK * width))
        .enumerate()
        .for_each_init(
            || vec![0.0f32; width],
            |values, (block, (block_sums, block_max))| {
                let first_row = block * ROWS_PER_TASK;
                for (r, (row_sums, row_max)) in block_sums
                    .chunks_mut(stride)
                    .zip(block_max.chunks_mut(width))
                    .enumerate()
                {
                    let row = first_row + r;
                    let basis = &bases[region.band_of(row)];
                    for (j, frame) in frames.iter().enumerate() {
                        load_row(frame, row, width, map, values, row_max);
                        for (c, q) in basis.rows.iter().enumerate() {
                            let weight = q[j];
                            let acc = &mut row_sums[c * width..(c + 1) * width];
                            for (a, v) in acc.iter_mut().zip(values.iter()) {
                                *a += weight * v;
                            }
                        }
                        let squares = &mut row_sums[k * width..(k + 1) * width];
                        for (a, v) in squares.iter_mut().zip(values.iter()) {
                            *a += v * v;
                        }
                    }
                }
            },
        );
    finish(&sums, max_code, region, bases, map.scale(), frames.len())
}

/// Converts one row of a frame to accumulation values and updates the row's maxima.
#[inline]
fn load_row(
    frame: &Samples,
    row: usize,
    width: usize,
    map: &CodeMap,
    values: &mut [f32],
    row_max: &mut [u16],
) {
    let range = row * width..(row + 1) * width;
    match (frame, map) {
        (Samples::U8(v), CodeMap::Linear { .. }) => {
            for ((out, m), &c) in values.iter_mut().zip(row_max.iter_mut()).zip(&v[range]) {
                *out = f32::from(c);
                *m = (*m).max(u16::from(c));
            }
        }
        (Samples::U16(v), CodeMap::Linear { .. }) => {
            for ((out, m), &c) in values.iter_mut().zip(row_max.iter_mut()).zip(&v[range]) {
                *out = f32::from(c);
                *m = (*m).max(c);
            }
        }
        (Samples::U8(v), CodeMap::Table(t)) => {
            for ((out, m), &c) in values.iter_mut().zip(row_max.iter_mut()).zip(&v[range]) {
                *out = t[usize::from(c)];
                *m = (*m).max(u16::from(c));
            }
        }
        (Samples::U16(v), CodeMap::Table(t)) => {
            for ((out, m), &c) in values.iter_mut().zip(row_max.iter_mut()).zip(&v[range]) {
                *out = t.get(usize::from(c)).copied().unwrap_or(1.0);
                *m = (*m).max(c);
            }
        }
    }
}

/// Solves every pixel's small least-squares system from its sums.
fn finish(
    sums: &[f32],
    max_code: Vec<u16>,
    region: Region,
    bases: &[TemplateBasis],
    scale: f32,
    frames: usize,
) -> WindowAmplitudes {
    let width = region.roi.width;
    let height = region.roi.height;
    let k = bases.first().map_or(1, |b| b.columns);
    let leds = k - 1;
    let stride = (k + 1) * width;
    let dof = frames.saturating_sub(k).max(1) as f64;
    let scale = f64::from(scale);
    let mut out = vec![0.0f32; height * width * k];
    out.par_chunks_mut(width * k)
        .enumerate()
        .for_each(|(row, row_out)| {
            let basis = &bases[region.band_of(row)];
            let row_sums = &sums[row * stride..(row + 1) * stride];
            let mut projections = [0.0f64; 10];
            let mut coefficients = [0.0f64; 10];
            for col in 0..width {
                let mut explained = 0.0;
                for (c, p) in projections.iter_mut().enumerate().take(k) {
                    *p = f64::from(row_sums[c * width + col]);
                    explained += *p * *p;
                }
                basis.coefficients(&projections[..k], &mut coefficients[..k]);
                let residual = (f64::from(row_sums[k * width + col]) - explained).max(0.0);
                let pixel = &mut row_out[col * k..(col + 1) * k];
                for i in 0..leds {
                    pixel[i] = (coefficients[i + 1] * scale) as f32;
                }
                pixel[leds] = (residual / dof * scale * scale) as f32;
            }
        });
    let mut led_images = vec![vec![0.0f32; height * width]; leds];
    let mut noise_variance = vec![0.0f32; height * width];
    for (p, pixel) in out.chunks(k).enumerate() {
        for (i, image) in led_images.iter_mut().enumerate() {
            image[p] = pixel[i];
        }
        noise_variance[p] = pixel[leds];
    }
    WindowAmplitudes {
        leds: led_images,
        noise_variance,
        max_code,
    }
}
