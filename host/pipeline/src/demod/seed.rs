//! Starting points of the timing fit from the signal space, without a joint parametric search.
//!
//! Every LED's received waveform u_i (docs/maths/demodulation.md#the-received-signal: its carrier
//! s_i integrated over the exposure,
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
//! least-squares refinement ([`super::fit`]), and, when the best start leaves an LED outside
//! the signal space, so do the LEDs' shifts where the sample holds the most energy along their
//! templates (a nearly rank-one sample of one flat face: [`strongest_shift_starts`]).

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

/// A local maximum of an LED's shift score reaching this share of its best is tried as a start
/// too (the other LEDs at their best; the refinement keeps the lowest residual). The signal
/// space can hold an LED that lights few of the sample's pixels poorly, and a wrong shift of it
/// then scores higher than the true one: on a 514×311 region around the turning ellipsoid
/// (1280×720, thesis-dynamic, 32-frame windows, carried exposure and rate ratio) LED 3's true
/// shift scored 0.29–0.36 and one 7 chips away 0.37–0.65, and every one of 6 windows was
/// refused as implausible (median σ 0.043 against the true fit's 0.005) while the whole
/// frame's decodes were right. With these starts 12 of 14 decodes of that region and a 700×400
/// one are right; the other two had two LEDs at wrong shifts at once. At 0.75 the true shift
/// was too far below (0.36 against 0.50).
const RIVAL_SHARE: f64 = 0.5;
/// Rival shifts tried per LED.
const RIVALS: usize = 2;
/// An LED whose template at the best start's timing and shift keeps less than this share of
/// its energy in the signal space is not held by it as a direction of its own, and the
/// LEDs' strongest shifts are tried too ([`strongest_shift_starts`]). On a well-lit sphere
/// every LED keeps nearly all of it; on the face-on cube's nearly rank-one sample the weak
/// LEDs kept 0.07 and 0.10. Only then: elsewhere the extra starts would only move the fit
/// along the flat valley of exposure and fractional shifts that ρ ≈ 1 leaves (see
/// [`super::fit`]), and change decodes that were right for no gain.
const WEAK_SCORE: f64 = 0.5;

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

    /// Half of one LED's carrier period, chips: a half-period shift negates a carrier
    /// (docs/maths/carriers.md#duty-runs-and-half-period-negation),
    /// which leaves the score unchanged, so shifts are searched in [0, half).
    fn half_period(&self, led: usize) -> f64 {
        self.waves.get(led).map_or(4, ReceivedWaveform::period) as f64 / 2.0
    }

    /// One LED's score at the shifts k·`step` of its first half period.
    fn shift_grid(&self, led: usize, timing: Timing, step: f64) -> Vec<f64> {
        let mut template = vec![0.0; self.frames];
        let steps = (self.half_period(led) / step).round() as usize;
        (0..steps)
            .map(|k| self.score(led, timing, k as f64 * step, &mut template))
            .collect()
    }

    /// Best shift of one LED in its first half period ([`Self::half_period`]), optionally
    /// refined by golden section.
    fn best_shift(&self, led: usize, timing: Timing, step: f64, refine: bool) -> (f64, f64) {
        let mut best = (f64::NEG_INFINITY, 0.0);
        for (k, s) in self.shift_grid(led, timing, step).into_iter().enumerate() {
            if s > best.0 {
                best = (s, k as f64 * step);
            }
        }
        if refine {
            let mut template = vec![0.0; self.frames];
            let (shift, s) = golden_max(best.1 - step, best.1 + step, |x| {
                self.score(led, timing, x, &mut template)
            });
            if s > best.0 {
                best = (s, shift);
            }
        }
        best
    }

    /// The local maxima of one LED's score over its first half period (circular) other than
    /// the one at `best`, scoring at least [`RIVAL_SHARE`] of `best`'s score, each refined by
    /// golden section: the [`RIVALS`] highest, best first.
    fn rivals(&self, led: usize, timing: Timing, step: f64, best: (f64, f64)) -> Vec<f64> {
        let half = self.half_period(led);
        let grid = self.shift_grid(led, timing, step);
        let steps = grid.len();
        if steps < 3 {
            return Vec::new();
        }
        let mut template = vec![0.0; self.frames];
        let apart = |shift: f64| circular_distance(shift, best.1, half) > 1.5 * step;
        let mut rivals: Vec<(f64, f64)> = (0..steps)
            .filter(|&k| {
                let (before, after) = (grid[(k + steps - 1) % steps], grid[(k + 1) % steps]);
                grid[k] > before && grid[k] >= after && grid[k] >= RIVAL_SHARE * best.0
            })
            .map(|k| k as f64 * step)
            .filter(|&shift| apart(shift))
            .map(|shift| {
                let (x, s) = golden_max(shift - step, shift + step, |x| {
                    self.score(led, timing, x, &mut template)
                });
                (s, x.rem_euclid(half))
            })
            .collect();
        rivals.sort_by(|a, b| b.0.total_cmp(&a.0));
        rivals.into_iter().take(RIVALS).map(|(_, x)| x).collect()
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
    let mut starts: Vec<Start> = peaks
        .into_iter()
        .map(|(_, exposure, shifts)| Start {
            timing: Timing {
                rate_ratio: rate,
                exposure: *exposure,
            },
            shifts: shifts.clone(),
        })
        .collect();
    // The best start with one LED at a rival shift ([`RIVAL_SHARE`]); the refinement keeps the
    // lowest residual.
    if templates.is_none()
        && let Some(best) = starts.first().cloned()
    {
        for (led, &shift) in best.shifts.iter().enumerate() {
            let score = scorer.score(led, best.timing, shift, &mut vec![0.0; frames]);
            for rival in scorer.rivals(led, best.timing, SHIFT_STEP, (score, shift)) {
                let mut shifts = best.shifts.clone();
                shifts[led] = rival;
                starts.push(Start {
                    timing: best.timing,
                    shifts,
                });
            }
        }
    }
    // And, when the best start leaves an LED outside the signal space, the LEDs at their
    // strongest shifts (a sample of nearly rank one).
    let mut column = vec![0.0; frames];
    let weak = starts.first().is_some_and(|best| {
        (0..waves.len()).any(|led| {
            let shift = best.shifts.get(led).copied().unwrap_or(0.0);
            scorer.score(led, best.timing, shift, &mut column) < WEAK_SCORE
        })
    });
    if weak {
        let strongest = strongest_shift_starts(space, waves, frames, &starts);
        starts.extend(strongest);
    }
    starts
}

/// Starts with the LEDs at the shifts where the sample's energy along their templates peaks:
/// for each timing of `starts`, all of them; for the first (best) start, each one alone too.
/// Only starts not in `starts` already.
///
/// The subspace score cannot place an LED whose waveform the signal space does not hold as a
/// direction of its own. The sample's pixels see the LEDs in nearly fixed proportions when
/// they lie on one flat face (a face-on cube), so its signal is nearly rank one, the weighted
/// sum Σ A_i·u_i of the waveforms, and a weak LED's template scores low at every shift. The
/// 75 mm cube face-on at (30, 0, 20) mm (thesis-out-of-plane, 128 frames): two significant
/// eigenvalues (1569 and 1.2, noise 0.025), LEDs 1 and 4 (on-levels 0.03 against 0.18 and
/// 0.19) peaking at 0.07 and 0.10, and LED 4's peak 10 chips from its shift, so every
/// refinement stopped there and the decode was refused (82 % of its modulation unexplained).
/// The energy the sample holds along a template, tᵀGt / tᵀt over the leading directions,
/// does not need that direction: the carriers stay orthogonal under any shift
/// (docs/maths/carriers.md#orthogonality-under-any-shift), so
/// the other LEDs add nothing to it, and it peaks at the LED's own shift however weak. The
/// refinement keeps the lowest residual, so these starts only win where they fit better.
fn strongest_shift_starts(
    space: &SignalSpace,
    waves: &[ReceivedWaveform],
    frames: usize,
    starts: &[Start],
) -> Vec<Start> {
    let energy_basis = space.energy_basis();
    let energy = Scorer::new(energy_basis.as_view(), waves, frames);
    let half = |led: usize| energy.half_period(led);
    let strongest = |timing: Timing| -> Vec<f64> {
        (0..waves.len())
            .map(|led| {
                let (_, shift) = energy.best_shift(led, timing, SHIFT_STEP, true);
                shift.rem_euclid(half(led))
            })
            .collect()
    };
    let same = |a: &Start, b: &Start| {
        a.timing == b.timing
            && a.shifts
                .iter()
                .zip(&b.shifts)
                .enumerate()
                .all(|(led, (&x, &y))| circular_distance(x, y, half(led)) <= 1.5 * SHIFT_STEP)
    };
    let mut new: Vec<Start> = Vec::new();
    let mut timings: Vec<Timing> = Vec::new();
    for (k, start) in starts.iter().enumerate() {
        if timings.contains(&start.timing) {
            continue;
        }
        timings.push(start.timing);
        let shifts = strongest(start.timing);
        if k == 0 {
            for (led, &shift) in shifts.iter().enumerate() {
                let mut moved = start.clone();
                moved.shifts[led] = shift;
                new.push(moved);
            }
        }
        new.push(Start {
            timing: start.timing,
            shifts,
        });
    }
    let mut kept: Vec<Start> = Vec::new();
    for candidate in new {
        if !starts.iter().chain(&kept).any(|s| same(s, &candidate)) {
            kept.push(candidate);
        }
    }
    kept
}

/// Distance between two shifts on a circle of circumference `period`.
fn circular_distance(a: f64, b: f64, period: f64) -> f64 {
    let d = (a - b).rem_euclid(period);
    d.min(period - d)
}

/// The rate ratio whose templates at full exposure the signal space holds best.
/// The rate ratio whose templates the signal space `space` holds best (the seeds' rate scan),
/// within `max_mismatch` of 1.
pub fn scan_rate_of(
    space: &SignalSpace,
    waves: &[ReceivedWaveform],
    frames: usize,
    max_mismatch: f64,
) -> f64 {
    scan_rate(
        &Scorer::new(space.basis(), waves, frames),
        frames,
        max_mismatch,
    )
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// A signal space that holds LED 3's template (of four LEDs, period 16 chips) at two
    /// shifts 6.75 chips apart, as a region's sample can (see [`RIVAL_SHARE`]): whichever the
    /// grid picks, the other is a start too, for the refinement to choose between them.
    #[test]
    fn a_rival_shift_of_an_led_is_tried_as_a_start() {
        let frames = 32;
        let waves: Vec<ReceivedWaveform> = (0..4).map(ReceivedWaveform::new).collect();
        let timing = Timing {
            rate_ratio: 1.0,
            exposure: 1.0,
        };
        let template = |led: usize, shift: f64| {
            let mut t = vec![0.0; frames];
            timing.fill_template(&waves[led], shift, &mut t);
            let mean = t.iter().sum::<f64>() / frames as f64;
            DVector::from_iterator(frames, t.iter().map(|v| v - mean))
        };
        let columns = [
            template(0, 0.25),
            template(1, 2.0),
            template(2, 0.5),
            template(2, 7.25),
            template(3, 1.625),
        ];
        let basis = DMatrix::from_columns(&columns).qr().q();
        let space = SignalSpace {
            vectors: basis,
            values: vec![1.0; columns.len()],
            noise: 0.0,
            rank: columns.len(),
        };
        let limits = FitLimits {
            rate_ratio: Some(1.0),
            exposure: Some(1.0),
            ..FitLimits::default()
        };
        let seeds = starts(&space, &waves, frames, &limits);
        let near = |shift: f64, target: f64| {
            let d = (shift - target).rem_euclid(8.0);
            d.min(8.0 - d) < 0.2
        };
        for target in [0.5, 7.25] {
            assert!(
                seeds.iter().any(|s| near(s.shifts[2], target)),
                "no start has LED 3 at {target} chips: {seeds:?}"
            );
        }
        // Every start keeps the timing it was given.
        assert!(seeds.iter().all(|s| s.timing == timing));
    }
}
