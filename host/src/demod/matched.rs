//! The per-pixel matched filter: least squares of every pixel against the fitted waveforms.
//!
//! One pass over the window's frames accumulates, per pixel, the K projections Q·r and |r|²
//! ([`super::basis`]). Rows run in parallel with rayon; inside a row, a tile of [`TILE`] pixels
//! keeps its K+1 sums in registers while streaming over the frames (one load and conversion
//! per sample, K+1 multiply-adds), and its least-squares solution is written straight into the
//! output planes. The kernel is monomorphised on K, the sample type and the code map so the
//! inner loop has no branches or allocations.

use super::basis::TemplateBasis;
use super::window::{CodeMap, Region};
use crate::capture::Samples;
use rayon::prelude::*;

/// Pixels accumulated together in registers.
const TILE: usize = 8;

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

/// A sample type the kernel reads.
trait Code: Copy + Send + Sync {
    /// The code value.
    fn code(self) -> u16;
}

impl Code for u8 {
    #[inline(always)]
    fn code(self) -> u16 {
        u16::from(self)
    }
}

impl Code for u16 {
    #[inline(always)]
    fn code(self) -> u16 {
        self
    }
}

/// Shared inputs of one window's kernel.
struct Plan<'a> {
    region: Region,
    bases: &'a [TemplateBasis],
    scale: f64,
    dof: f64,
}

/// Runs the matched filter over a window: `bases[b]` is the template basis of row band b.
pub fn matched_filter(
    frames: &[Samples],
    region: Region,
    bases: &[TemplateBasis],
    map: &CodeMap,
) -> WindowAmplitudes {
    let k = bases.first().map_or(1, |b| b.columns);
    let plan = Plan {
        region,
        bases,
        scale: f64::from(map.scale()),
        dof: frames.len().saturating_sub(k).max(1) as f64,
    };
    let u8_frames: Option<Vec<&[u8]>> = frames
        .iter()
        .map(|f| match f {
            Samples::U8(v) => Some(v.as_slice()),
            Samples::U16(_) => None,
        })
        .collect();
    if let Some(data) = u8_frames {
        return match map {
            CodeMap::Linear { .. } => dispatch(&plan, &data, |c: u8| f32::from(c)),
            CodeMap::Table(t) => dispatch(&plan, &data, |c: u8| {
                t.get(usize::from(c)).copied().unwrap_or(1.0)
            }),
        };
    }
    // 16-bit (or mixed) frames: read everything as 16-bit codes.
    let widened: Vec<std::borrow::Cow<'_, [u16]>> = frames
        .iter()
        .map(|f| match f {
            Samples::U16(v) => std::borrow::Cow::Borrowed(v.as_slice()),
            Samples::U8(v) => std::borrow::Cow::Owned(v.iter().map(|&c| u16::from(c)).collect()),
        })
        .collect();
    let data: Vec<&[u16]> = widened.iter().map(|c| c.as_ref()).collect();
    match map {
        CodeMap::Linear { .. } => dispatch(&plan, &data, |c: u16| f32::from(c)),
        CodeMap::Table(t) => dispatch(&plan, &data, |c: u16| {
            t.get(usize::from(c)).copied().unwrap_or(1.0)
        }),
    }
}

/// Picks the kernel for the model size K.
fn dispatch<T: Code>(
    plan: &Plan<'_>,
    frames: &[&[T]],
    value: impl Fn(T) -> f32 + Sync + Copy,
) -> WindowAmplitudes {
    let k = plan.bases.first().map_or(1, |b| b.columns);
    match k {
        1 => run::<1, T>(plan, frames, value),
        2 => run::<2, T>(plan, frames, value),
        3 => run::<3, T>(plan, frames, value),
        4 => run::<4, T>(plan, frames, value),
        5 => run::<5, T>(plan, frames, value),
        6 => run::<6, T>(plan, frames, value),
        7 => run::<7, T>(plan, frames, value),
        8 => run::<8, T>(plan, frames, value),
        _ => run::<9, T>(plan, frames, value),
    }
}

/// The kernel for K model columns: per-row planes, then one image per LED.
fn run<const K: usize, T: Code>(
    plan: &Plan<'_>,
    frames: &[&[T]],
    value: impl Fn(T) -> f32 + Sync + Copy,
) -> WindowAmplitudes {
    let width = plan.region.roi.width;
    let height = plan.region.roi.height;
    // Q column per frame, one [f32; K] per frame and band.
    let weights: Vec<Vec<[f32; K]>> = plan
        .bases
        .iter()
        .map(|basis| {
            (0..frames.len())
                .map(|j| {
                    let mut w = [0.0f32; K];
                    for (c, q) in basis.rows.iter().enumerate().take(K) {
                        w[c] = q.get(j).copied().unwrap_or(0.0);
                    }
                    w
                })
                .collect()
        })
        .collect();
    let mut planes = vec![0.0f32; height * K * width];
    let mut max_code = vec![0u16; height * width];
    planes
        .par_chunks_mut(K * width)
        .zip(max_code.par_chunks_mut(width))
        .enumerate()
        .for_each(|(row, (row_planes, row_max))| {
            let band = plan.region.band_of(row);
            let rows: Vec<&[T]> = frames
                .iter()
                .map(|f| f.get(row * width..(row + 1) * width).unwrap_or(&[]))
                .collect();
            let mut x = 0;
            while x < width {
                let len = TILE.min(width - x);
                let sums = accumulate::<K, T>(&rows, &weights[band], x, len, value);
                solve::<K>(
                    plan,
                    &plan.bases[band],
                    &sums,
                    x,
                    len,
                    width,
                    row_planes,
                    row_max,
                );
                x += len;
            }
        });
    let plane = |i: usize| -> Vec<f32> {
        planes
            .chunks(K * width)
            .flat_map(|row| row[i * width..(i + 1) * width].iter().copied())
            .collect()
    };
    WindowAmplitudes {
        leds: (0..K - 1).map(plane).collect(),
        noise_variance: plane(K - 1),
        max_code,
    }
}

/// Sums of one tile: projections, squares and maximum code per pixel.
struct TileSums<const K: usize> {
    projections: [[f32; TILE]; K],
    squares: [f32; TILE],
    max_code: [u16; TILE],
}

/// Streams the frames over the tile of `len` pixels starting at column `x`.
#[allow(clippy::needless_range_loop)] // indexed lanes keep the tile in registers
#[inline(always)]
fn accumulate<const K: usize, T: Code>(
    rows: &[&[T]],
    weights: &[[f32; K]],
    x: usize,
    len: usize,
    value: impl Fn(T) -> f32,
) -> TileSums<K> {
    let mut sums = TileSums {
        projections: [[0.0f32; TILE]; K],
        squares: [0.0f32; TILE],
        max_code: [0u16; TILE],
    };
    for (row, w) in rows.iter().zip(weights) {
        let mut v = [0.0f32; TILE];
        if len == TILE
            && let Some(tile) = row.get(x..x + TILE)
        {
            for l in 0..TILE {
                v[l] = value(tile[l]);
                sums.max_code[l] = sums.max_code[l].max(tile[l].code());
            }
        } else {
            for l in 0..len {
                if let Some(&c) = row.get(x + l) {
                    v[l] = value(c);
                    sums.max_code[l] = sums.max_code[l].max(c.code());
                }
            }
        }
        for c in 0..K {
            for l in 0..TILE {
                sums.projections[c][l] += w[c] * v[l];
            }
        }
        for l in 0..TILE {
            sums.squares[l] += v[l] * v[l];
        }
    }
    sums
}

/// Solves the tile's least-squares systems and writes coefficients, noise and maxima.
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
#[inline(always)]
fn solve<const K: usize>(
    plan: &Plan<'_>,
    basis: &TemplateBasis,
    sums: &TileSums<K>,
    x: usize,
    len: usize,
    width: usize,
    row_planes: &mut [f32],
    row_max: &mut [u16],
) {
    let mut projections = [0.0f64; K];
    let mut coefficients = [0.0f64; K];
    for l in 0..len {
        let mut explained = 0.0;
        for (c, p) in projections.iter_mut().enumerate() {
            *p = f64::from(sums.projections[c][l]);
            explained += *p * *p;
        }
        basis.coefficients(&projections, &mut coefficients);
        let residual = (f64::from(sums.squares[l]) - explained).max(0.0);
        let col = x + l;
        for i in 0..K - 1 {
            row_planes[i * width + col] = (coefficients[i + 1] * plan.scale) as f32;
        }
        row_planes[(K - 1) * width + col] = (residual / plan.dof * plan.scale * plan.scale) as f32;
        row_max[col] = sums.max_code[l];
    }
}
