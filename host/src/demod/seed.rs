//! Starting points of the timing fit from the signal space, without a joint parametric search.
//!
//! Every LED's received waveform u_i (SPEC §3: its carrier s_i integrated over the exposure,
//! shifted by Δ_i = k_i + α_i and sampled at ρ chips per frame) lies in the window's signal
//! space V (the leading eigenvectors of the sample's Gram matrix, [`super::spectrum`]) whatever
//! the on-levels A_i of the pixels, and a waveform with a wrong shift, exposure or rate does
//! not. So each LED is scored on its own by the fraction of its centred template t that V
//! holds, |Vᵀt|² / |t|² (a subspace-fitting score, as in MUSIC: Schmidt, IEEE Trans. Antennas
//! Propag. 1986): the other LEDs, however bright or spatially alike, do not bias it, unlike
//! a fit to the frame mean, where the LEDs' scene averages mix and a dark background dilutes
//! them. The rate ratio ρ is the grid value (step ½/F, then a golden-section refinement) where
//! the LEDs' best scores at full exposure sum highest; the exposure e is scanned at that rate
//! with each LED's Δ_i refined per exposure. The local maxima of that scan (and a few spread
//! exposures, because at ρ ≈ 1 the exposure barely changes the templates) start the
//! least-squares refinement ([`super::fit`]).

use super::config::{FitLimits, SeedMethod};
use super::spectrum::SignalSpace;
use super::template::rank_one_templates;
use super::waveform::{ReceivedWaveform, Timing};
use nalgebra::DMatrixView;
use rayon::prelude::*;

/// Rate grid step as a fraction of 1/F (a drift of ½ chip over the window at most).
const RATE_STEP: f64 = 0.5;
/// Shift grid step, chips, while scanning the rate.
const RATE_SCAN_SHIFT_STEP: f64 = 0.5;
/// Shift grid step, chips, while scanning the exposure.
const SHIFT_STEP: f64 = 0.25;
/// Golden-section iterations of a rate or shift refinement.
const GOLDEN_ITERATIONS: usize = 12;
/// The exposures scanned, as tenths of the frame period.
const EXPOSURE_TENTHS: std::ops::RangeInclusive<u32> = 1..=10;
/// Exposures always tried as starting points besides the scan's peaks.
const SPREAD_EXPOSURES: [f64; 3] = [1.0, 0.6, 0.3];
/// Scan peaks kept as starting points.
const PEAKS: usize = 3;

/// One starting point of the refinement.
#[derive(Debug, Clone, PartialEq)]
pub struct Start {
    /// Camera timing.
    pub timing: Timing,
    /// Δ_i per LED, chips.
    pub shifts: Vec<f64>,
}

/// Lanes of the signal-space rows: the rank is padded to a multiple of this with zero columns.
const LANES: usize = 4;
/// Largest padded rank: the signal space holds at most 3·N + 2 directions (spectrum).
const MAX_LANES: usize = (3 * super::MAX_LEDS + 2).div_ceil(LANES) * LANES;

/// Scores templates against the signal space.
struct Scorer<'a> {
    /// The signal space V (F × rank) frame-major, each frame's row padded with zeros to
    /// `lanes` values, so that one pass over the frames accumulates every column's dot product
    /// at once (each column still summed frame by frame, in order: the same arithmetic as a
    /// column-by-column dot product, one independent chain per column).
    rows: Vec<f64>,
    /// Row length: the rank rounded up to [`LANES`].
    lanes: usize,
    waves: &'a [ReceivedWaveform],
    frames: usize,
}

impl<'a> Scorer<'a> {
    /// The scorer of `space` (F × rank).
    fn new(space: DMatrixView<'_, f64>, waves: &'a [ReceivedWaveform], frames: usize) -> Self {
        let rank = space.ncols().min(MAX_LANES);
        let lanes = rank.div_ceil(LANES).max(1) * LANES;
        let mut rows = vec![0.0; frames * lanes];
        for (c, column) in space.column_iter().take(rank).enumerate() {
            for (j, &v) in column.iter().enumerate().take(frames) {
                rows[j * lanes + c] = v;
            }
        }
        Self {
            rows,
            lanes,
            waves,
            frames,
        }
    }

    /// |Vᵀt|² / |t|² of LED `led`'s centred template (0 for a flat template).
    fn score(&self, led: usize, timing: Timing, shift: f64, template: &mut [f64]) -> f64 {
        let Some(wave) = self.waves.get(led) else {
            return 0.0;
        };
        timing.fill_template(wave, shift, template);
        let mean = template.iter().sum::<f64>() / self.frames.max(1) as f64;
        let mut energy = 0.0;
        let mut dots = [[0.0f64; LANES]; MAX_LANES / LANES];
        let dots = &mut dots[..self.lanes / LANES];
        for (t, row) in template.iter().zip(self.rows.chunks_exact(self.lanes)) {
            let t = *t - mean;
            energy += t * t;
            for (d, v) in dots.iter_mut().zip(row.as_chunks::<LANES>().0) {
                for (d, &v) in d.iter_mut().zip(v) {
                    *d += v * t;
                }
            }
        }
        if energy < 1e-15 {
            return 0.0;
        }
        let captured: f64 = dots.iter().flatten().map(|d| d.powi(2)).sum();
        captured / energy
    }

    /// Best shift of one LED in its first half period (a half-period shift negates a carrier,
    /// SPEC §2, which leaves the score unchanged), optionally refined by golden section.
    fn best_shift(&self, led: usize, timing: Timing, step: f64, refine: bool) -> (f64, f64) {
        let period = self.waves.get(led).map_or(4, ReceivedWaveform::period) as f64;
        let mut template = vec![0.0; self.frames];
        let steps = (period / 2.0 / step).round() as usize;
        let mut best = (f64::NEG_INFINITY, 0.0);
        for k in 0..steps {
            let shift = k as f64 * step;
            let s = self.score(led, timing, shift, &mut template);
            if s > best.0 {
                best = (s, shift);
            }
        }
        if refine {
            let (shift, s) = golden_max(best.1 - step, best.1 + step, |x| {
                self.score(led, timing, x, &mut template)
            });
            if s > best.0 {
                best = (s, shift);
            }
        }
        best
    }

    /// Sum over LEDs of their best scores, and the shifts.
    fn total(&self, timing: Timing, step: f64, refine: bool) -> (f64, Vec<f64>) {
        let mut total = 0.0;
        let mut shifts = Vec::with_capacity(self.waves.len());
        for led in 0..self.waves.len() {
            let (s, shift) = self.best_shift(led, timing, step, refine);
            total += s;
            shifts.push(shift);
        }
        (total, shifts)
    }
}

/// Maximises `f` on [lo, hi] by golden-section search: (argmax, max).
fn golden_max(mut lo: f64, mut hi: f64, mut f: impl FnMut(f64) -> f64) -> (f64, f64) {
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = hi - ratio * (hi - lo);
    let mut d = lo + ratio * (hi - lo);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..GOLDEN_ITERATIONS {
        if fc > fd {
            hi = d;
            d = c;
            fd = fc;
            c = hi - ratio * (hi - lo);
            fc = f(c);
        } else {
            lo = c;
            c = d;
            fc = fd;
            d = lo + ratio * (hi - lo);
            fd = f(d);
        }
    }
    let middle = 0.5 * (lo + hi);
    (middle, f(middle))
}

/// Starting points for `waves` from the signal space `space` of a window of `frames`: ρ from
/// the rate scan (unless given), then each LED's shift from its rank-1 template
/// ([`super::template`], [`SeedMethod::RankOne`]) or from a grid of shifts
/// ([`SeedMethod::Grid`], also when the window cannot hold the chip templates), at the
/// exposures whose templates the signal space holds best and a few spread ones.
pub fn starts(
    space: &SignalSpace,
    waves: &[ReceivedWaveform],
    frames: usize,
    limits: &FitLimits,
) -> Vec<Start> {
    let scorer = Scorer::new(space.basis(), waves, frames);
    let rate = limits
        .rate_ratio
        .unwrap_or_else(|| scan_rate(&scorer, frames, limits.max_rate_mismatch));
    let exposures: Vec<f64> = match limits.exposure {
        Some(e) => vec![e],
        None => EXPOSURE_TENTHS.rev().map(|k| f64::from(k) / 10.0).collect(),
    };
    let templates = match limits.seeds {
        SeedMethod::RankOne => rank_one_templates(space, waves, rate, frames),
        SeedMethod::Grid => None,
    };
    let scored: Vec<(f64, f64, Vec<f64>)> = exposures
        .par_iter()
        .map(|&exposure| {
            let timing = Timing {
                rate_ratio: rate,
                exposure,
            };
            let (score, shifts) = match &templates {
                Some(templates) => {
                    let mut column = vec![0.0; frames];
                    let shifts: Vec<f64> =
                        templates.iter().map(|t| t.shift(rate, exposure)).collect();
                    let score = shifts
                        .iter()
                        .enumerate()
                        .map(|(led, &shift)| scorer.score(led, timing, shift, &mut column))
                        .sum();
                    (score, shifts)
                }
                None => scorer.total(timing, SHIFT_STEP, true),
            };
            (score, exposure, shifts)
        })
        .collect();
    let mut peaks: Vec<&(f64, f64, Vec<f64>)> = scored
        .iter()
        .enumerate()
        .filter(|(k, (s, _, _))| {
            let left = k.checked_sub(1).map_or(f64::NEG_INFINITY, |l| scored[l].0);
            let right = scored.get(k + 1).map_or(f64::NEG_INFINITY, |r| r.0);
            *s >= left && *s >= right
        })
        .map(|(_, p)| p)
        .collect();
    peaks.sort_by(|a, b| b.0.total_cmp(&a.0));
    peaks.truncate(PEAKS);
    for spread in SPREAD_EXPOSURES {
        let near = |e: f64| (e - spread).abs() < 0.05;
        if !peaks.iter().any(|p| near(p.1))
            && let Some(p) = scored.iter().find(|p| near(p.1))
        {
            peaks.push(p);
        }
    }
    peaks
        .into_iter()
        .map(|(_, exposure, shifts)| Start {
            timing: Timing {
                rate_ratio: rate,
                exposure: *exposure,
            },
            shifts: shifts.clone(),
        })
        .collect()
}

/// The rate ratio whose templates at full exposure the signal space holds best.
fn scan_rate(scorer: &Scorer<'_>, frames: usize, max_mismatch: f64) -> f64 {
    let step = RATE_STEP / frames.max(1) as f64;
    let reach = (max_mismatch / step).floor() as i64;
    let at = |rate: f64, shift_step: f64| {
        let timing = Timing {
            rate_ratio: rate,
            exposure: 1.0,
        };
        scorer.total(timing, shift_step, false).0
    };
    let best = (-reach..=reach)
        .into_par_iter()
        .map(|k| {
            let rate = 1.0 + k as f64 * step;
            (at(rate, RATE_SCAN_SHIFT_STEP), rate)
        })
        .reduce(
            || (f64::NEG_INFINITY, 1.0),
            |a, b| {
                if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }
            },
        );
    golden_max(best.1 - step, best.1 + step, |rate| at(rate, SHIFT_STEP)).0
}
