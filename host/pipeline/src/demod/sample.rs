//! The pixel sample the timing fit works on: the pixels that carry the most modulation.
//!
//! Every pixel of a window is r_j = B + Σ_i A_i·u_i(j) + noise
//! (docs/maths/demodulation.md#the-received-signal, u_i LED i's on-fraction
//! in frame j). The timing (rate ratio, exposure, shifts Δ_i, line ramp) is the same for every
//! pixel, so it is fitted on a sample: candidate pixels on every k-th row (at least
//! [`CANDIDATE_PIXELS`] of them, so that the pass costs a fixed amount whatever the frame size),
//! ranked by their temporal variance, of which the most variable non-saturated ones are kept.
//! Pixels that no LED reaches (a dark background around a small object) have only the noise's
//! variance and drop out, so a small object in a wide view still drives the fit; a saturated
//! pixel's waveform is clipped and is left out. Each kept pixel's F values are converted to
//! linear fractions of full scale and centred (its mean, the background B, removed).
//!
//! The rows lie on the whole frame's grid ([`RowGrid`]): a region of the frame (a decoding
//! region, or `meb video`'s region around the object) examines the frame's candidate rows that
//! cross it, so the sample of a region holding the modulated pixels is the whole frame's sample
//! and its fit the whole frame's. (Examined on a grid of its own, denser, a region ranks many
//! more of the object's pixels and keeps the most variable few, which on a turning object are
//! its moving silhouette: a window of the turning ellipsoid fitted one LED's shift 7 chips off.)
//! Only a region too small to hold [`MIN_PIXELS`] candidates on the frame's grid is examined on
//! a denser grid of its own.

use super::matched::CodeLimits;
use super::nuisance::Nuisance;
use super::window::CodeMap;
use meb_core::capture::Samples;
use nalgebra::DMatrix;
use rayon::prelude::*;
use std::sync::Arc;

/// Candidate pixels examined per frame (rows are strided above this).
pub const CANDIDATE_PIXELS: usize = 1 << 15;
/// Values (pixels × frames) the sample keeps: 2048 pixels of a 64-frame window.
const SAMPLE_VALUES: usize = 1 << 17;
/// Fewest pixels kept (long windows).
const MIN_PIXELS: usize = 512;
/// Most pixels kept (short windows).
const MAX_PIXELS: usize = 2048;
/// Pixels per block of the parallel Gram accumulation.
const GRAM_BLOCK: usize = 256;

/// The most modulated pixels of a window, centred, in linear fractions of full scale.
#[derive(Debug, Clone)]
pub struct PixelSample {
    frames: usize,
    /// Centred values, pixel-major: `values[p * frames + j]`.
    values: Vec<f64>,
    /// Region row of each pixel, ascending.
    rows: Vec<usize>,
    /// Candidate pixels left out because they clip at full scale in some frame.
    clipped: usize,
    /// Candidate pixels examined, clipped or not.
    examined: usize,
    /// Each pixel's mean before centring, fraction of full scale.
    means: Vec<f64>,
    /// Nuisance components projected out of the values ([`super::nuisance`]).
    nuisance: Option<Arc<Nuisance>>,
}

/// The candidate rows of a region of a frame (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RowGrid {
    /// Every this many frame rows is examined.
    stride: usize,
    /// Frame row of the region's first row.
    top: usize,
}

impl RowGrid {
    /// The grid of a region of `width` × `height` pixels whose first row is row `top` of a
    /// frame of `frame_pixels`.
    pub fn new(frame_pixels: usize, top: usize, width: usize, height: usize) -> Self {
        let frame = Self {
            stride: (frame_pixels / CANDIDATE_PIXELS).max(1),
            top,
        };
        if frame.rows(height).count() * width >= MIN_PIXELS {
            frame
        } else {
            Self {
                stride: (width * height / CANDIDATE_PIXELS).max(1),
                top: 0,
            }
        }
    }

    /// The region rows examined, of a region of `height` rows.
    fn rows(&self, height: usize) -> impl Iterator<Item = usize> + '_ {
        let first = (self.stride - self.top % self.stride) % self.stride;
        (first..height).step_by(self.stride)
    }
}

/// One candidate pixel's temporal statistics.
#[derive(Clone, Copy)]
struct Candidate {
    row: usize,
    col: usize,
    variance: f64,
}

impl PixelSample {
    /// Picks the sample from `frames` (cropped to the region: `width × height` each) on the
    /// candidate rows of `grid`.
    pub fn gather(
        frames: &[Samples],
        (width, height): (usize, usize),
        grid: RowGrid,
        map: &CodeMap,
        limits: CodeLimits,
    ) -> Self {
        let count = frames.len();
        let rows: Vec<usize> = grid.rows(height).collect();
        let per_row: Vec<(Vec<Candidate>, usize)> = rows
            .par_iter()
            .map(|&row| row_candidates(frames, width, row, map, limits))
            .collect();
        let clipped = per_row.iter().map(|(_, clipped)| clipped).sum();
        let examined = clipped + per_row.iter().map(|(row, _)| row.len()).sum::<usize>();
        let mut candidates: Vec<Candidate> = per_row.into_iter().flat_map(|(row, _)| row).collect();
        let keep = (SAMPLE_VALUES / count.max(1)).clamp(MIN_PIXELS, MAX_PIXELS);
        if candidates.len() > keep {
            candidates.select_nth_unstable_by(keep - 1, |a, b| b.variance.total_cmp(&a.variance));
            candidates.truncate(keep);
        }
        candidates.sort_unstable_by_key(|c| (c.row, c.col));
        let mut values = vec![0.0; candidates.len() * count];
        let mut means = vec![0.0; candidates.len()];
        values
            .par_chunks_mut(count.max(1))
            .zip(means.par_iter_mut())
            .zip(&candidates)
            .for_each(|((out, pixel_mean), c)| {
                let at = c.row * width + c.col;
                for (v, frame) in out.iter_mut().zip(frames) {
                    let code = match frame {
                        Samples::U8(s) => s.get(at).map_or(0, |&x| u16::from(x)),
                        Samples::U16(s) => s.get(at).copied().unwrap_or(0),
                    };
                    *v = map.mean_fraction(f64::from(map.value(code)));
                }
                let mean = out.iter().sum::<f64>() / count.max(1) as f64;
                out.iter_mut().for_each(|v| *v -= mean);
                *pixel_mean = mean;
            });
        Self {
            frames: count,
            values,
            rows: candidates.iter().map(|c| c.row).collect(),
            clipped,
            examined,
            means,
            nuisance: None,
        }
    }

    /// A sample from centred values (pixel-major, `frames` per pixel) and their rows.
    #[cfg(test)]
    pub fn from_values(frames: usize, values: Vec<f64>, rows: Vec<usize>) -> Self {
        let means = vec![0.0; rows.len()];
        Self {
            frames,
            values,
            rows,
            clipped: 0,
            examined: 0,
            means,
            nuisance: None,
        }
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// Whether no pixel was kept.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Candidate pixels left out because they clip at full scale in some frame: whatever
    /// lights only those is not in the sample.
    pub fn clipped(&self) -> usize {
        self.clipped
    }

    /// Candidate pixels examined, clipped or not.
    pub fn examined(&self) -> usize {
        self.examined
    }

    /// Frames per pixel (F).
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Region row of each pixel, ascending.
    pub fn rows(&self) -> &[usize] {
        &self.rows
    }

    /// The centred values of pixel `p`.
    pub fn pixel(&self, p: usize) -> &[f64] {
        &self.values[p * self.frames..(p + 1) * self.frames]
    }

    /// Pixels `range` as a matrix (pixels × frames).
    pub fn matrix(&self, range: std::ops::Range<usize>) -> DMatrix<f64> {
        let f = self.frames;
        DMatrix::from_row_slice(range.len(), f, &self.values[range.start * f..range.end * f])
    }

    /// Index ranges of pixels sharing a row, in row order.
    pub fn row_runs(&self) -> Vec<std::ops::Range<usize>> {
        let mut runs = Vec::new();
        let mut start = 0;
        for p in 1..=self.rows.len() {
            if p == self.rows.len() || self.rows[p] != self.rows[start] {
                runs.push(start..p);
                start = p;
            }
        }
        runs
    }

    /// Each pixel's mean before centring, fraction of full scale.
    pub fn means(&self) -> &[f64] {
        &self.means
    }

    /// The centred values, pixel-major.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The nuisance components projected out of the values, if any.
    pub fn nuisance(&self) -> Option<&Arc<Nuisance>> {
        self.nuisance.as_ref()
    }

    /// Projects `nuisance` out of every pixel's values ([`super::nuisance`]).
    pub fn project(&mut self, nuisance: Arc<Nuisance>) {
        let f = self.frames.max(1);
        self.values
            .par_chunks_mut(f)
            .for_each(|x| nuisance.project(x));
        self.nuisance = Some(nuisance);
    }

    /// The Gram matrix G = Σ_p x_p x_pᵀ (F × F) of the centred pixels.
    pub fn gram(&self) -> DMatrix<f64> {
        let f = self.frames;
        let blocks: Vec<std::ops::Range<usize>> = (0..self.len())
            .step_by(GRAM_BLOCK)
            .map(|s| s..(s + GRAM_BLOCK).min(self.len()))
            .collect();
        blocks
            .into_par_iter()
            .map(|range| {
                let x = self.matrix(range);
                x.tr_mul(&x)
            })
            // Summed in order: G does not depend on how the pool split the work.
            .collect::<Vec<_>>()
            .into_iter()
            .fold(DMatrix::zeros(f, f), |a, b| a + b)
    }
}

/// Temporal statistics of the non-saturated pixels of one region row (variance in the
/// code map's accumulation units: only the ranking matters), and how many pixels clip.
fn row_candidates(
    frames: &[Samples],
    width: usize,
    row: usize,
    map: &CodeMap,
    limits: CodeLimits,
) -> (Vec<Candidate>, usize) {
    let range = row * width..(row + 1) * width;
    let mut sums = RowSums::new(width);
    for frame in frames {
        match (frame, map) {
            (Samples::U8(s), CodeMap::Linear { .. }) => {
                sums.add_codes(s.get(range.clone()).unwrap_or(&[]))
            }
            (Samples::U16(s), CodeMap::Linear { .. }) => {
                sums.add_codes(s.get(range.clone()).unwrap_or(&[]))
            }
            (Samples::U8(s), CodeMap::Table(t)) => {
                sums.add_table(s.get(range.clone()).unwrap_or(&[]), t)
            }
            (Samples::U16(s), CodeMap::Table(t)) => {
                sums.add_table(s.get(range.clone()).unwrap_or(&[]), t)
            }
        }
    }
    let n = frames.len().max(1) as f64;
    let candidates: Vec<Candidate> = (0..width)
        .filter(|&col| !limits.classify(sums.max_code[col]).0)
        .map(|col| {
            let (sum, squares) = sums.moments(col);
            let mean = sum / n;
            Candidate {
                row,
                col,
                variance: (squares / n - mean * mean).max(0.0),
            }
        })
        .collect();
    let clipped = width - candidates.len();
    (candidates, clipped)
}

/// Per-pixel running sums of one row: exact integer sums of the codes for a linear map (the
/// loop vectorises), floating-point sums of the looked-up values otherwise.
struct RowSums {
    code_sum: Vec<u64>,
    code_squares: Vec<u64>,
    value_sum: Vec<f64>,
    value_squares: Vec<f64>,
    max_code: Vec<u16>,
}

impl RowSums {
    fn new(width: usize) -> Self {
        Self {
            code_sum: vec![0; width],
            code_squares: vec![0; width],
            value_sum: vec![0.0; width],
            value_squares: vec![0.0; width],
            max_code: vec![0; width],
        }
    }

    /// Adds one frame's codes (linear map: the codes themselves).
    fn add_codes<T: Copy + Into<u16>>(&mut self, codes: &[T]) {
        for (((s, q), m), &c) in self
            .code_sum
            .iter_mut()
            .zip(self.code_squares.iter_mut())
            .zip(self.max_code.iter_mut())
            .zip(codes)
        {
            let code: u16 = c.into();
            let v = u64::from(code);
            *s += v;
            *q += v * v;
            *m = (*m).max(code);
        }
    }

    /// Adds one frame's codes through a look-up table.
    fn add_table<T: Copy + Into<u16>>(&mut self, codes: &[T], table: &[f32]) {
        for (((s, q), m), &c) in self
            .value_sum
            .iter_mut()
            .zip(self.value_squares.iter_mut())
            .zip(self.max_code.iter_mut())
            .zip(codes)
        {
            let code: u16 = c.into();
            let v = f64::from(table.get(usize::from(code)).copied().unwrap_or(1.0));
            *s += v;
            *q += v * v;
            *m = (*m).max(code);
        }
    }

    /// (Σ value, Σ value²) of column `col`, whichever sums were used.
    fn moments(&self, col: usize) -> (f64, f64) {
        (
            self.code_sum[col] as f64 + self.value_sum[col],
            self.code_squares[col] as f64 + self.value_squares[col],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_region_examines_the_frames_candidate_rows_that_cross_it() {
        // 1280×720: every 28th frame row.
        let frame = 1280 * 720;
        let whole: Vec<usize> = RowGrid::new(frame, 0, 1280, 720).rows(720).collect();
        assert_eq!(whole.len(), 720usize.div_ceil(28));
        assert!(whole.iter().all(|r| r % 28 == 0));
        // A region from row 211: the same frame rows, counted from its top.
        let region: Vec<usize> = RowGrid::new(frame, 211, 448, 251).rows(251).collect();
        let expected: Vec<usize> = whole
            .iter()
            .filter(|&&r| (211..211 + 251).contains(&r))
            .map(|r| r - 211)
            .collect();
        assert_eq!(region, expected);
        // Too few candidates on the frame's grid (one row of 40 pixels): a denser grid of its
        // own, every row of the region.
        let small: Vec<usize> = RowGrid::new(frame, 5, 40, 30).rows(30).collect();
        assert_eq!(small, (0..30).collect::<Vec<_>>());
    }
}
