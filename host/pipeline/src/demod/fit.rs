//! The timing fit: rate ratio ρ, exposure e, shifts Δ_i and rolling-shutter line delay, by
//! least squares over the pixel sample, started from the signal-space seeds.
//!
//! Model (docs/maths/demodulation.md#the-received-signal with the exposure and rolling shutter of
//! [`super::waveform`]): row r of frame j
//! sees LED i's carrier from chip time `(j + λ·r)·ρ + Δ_i` for `e·ρ` chips, λ the line delay in
//! frame periods per row (0 for a global shutter), so pixel p in row r reads
//! `r_j = B_p + Σ_i A_i(p)·u_i(j; r)`. For given timing θ = (ρ, e, λ, Δ) the best B, A of every
//! pixel are linear least squares, so θ maximises the energy the template span explains
//! (variable projection: Golub & Pereyra, SIAM J. Numer. Anal. 1973) and the residual to
//! minimise is `(I − Q_rQ_rᵀ)·X_rᵀ` summed over rows, Q_r an orthonormal basis of the
//! templates at row r. The data enter compressed without loss of signal: a global shutter's
//! signal is the span of the sample's Gram eigenvectors (\[`super::spectrum`\]), scaled by the
//! square roots of their eigenvalues; a rolling shutter's rows each keep their own N leading
//! singular directions (one row of the sample has one set of templates).
//!
//! The refinements from several starting points (the seeds, the exposures tried) and the
//! rows-agree screen of each band are independent and run in parallel; the residual is
//! evaluated in a reused work space (a fit evaluates it hundreds of times).
//!
//! Phases ([`fit_timing`]): (1) each seed of \[`super::seed`\] is refined with λ = 0 and the best
//! kept; (2) unless the line delay is given, row bands of the sample get their own shifts, the
//! shifts' trend across the bands seeds λ, and a band-wise refinement (several exposures, then
//! a grid re-search of each LED's shift, then again least squares) decides whether the rows
//! disagree: when λ explains significantly more than noise would, (3) the fit is redone row by
//! row. λ must earn its place twice: in (2) its cost reduction is measured against the
//! band-wise optimum without it refitted from λ's own solution (so that λ takes no credit for
//! a better exposure, rate or shift it happened to find on the way) and must beat what one
//! extra parameter per band would gain from noise (a χ² threshold); in (3) the row-wise fit is
//! refitted once more without λ from λ's solution, and λ must lower the cost by
//! [`RAMP_SIGNIFICANCE`] noise variances (a likelihood-ratio test: 5σ for one parameter).
//! Otherwise the rows agree and the global-shutter fit stands. The Gauss–Newton covariance
//! σ²·(JᵀJ)⁻¹ at the optimum (inverted with J's columns scaled to unit norm, because ρ, e, Δ_i
//! and λ differ in scale by up to four orders of magnitude) gives the exposure's and λ's
//! standard errors and each LED's gain uncertainty, which the report carries: at ρ ≈ 1 the exposure trades against the shifts' fractional parts along a nearly
//! flat direction and is not determined by the data. (λ's standard error is not the test:
//! its correlation with that flat direction inflates it, and the likelihood ratio is the
//! sharper question.) Finally each carrier's sign is chosen so that the sample's on-levels are positive (a
//! half-period shift negates a carrier, docs/maths/carriers.md#duty-runs-and-half-period-negation).

use super::basis::TemplateBasis;
use super::config::FitLimits;
use super::levenberg::{Freedom, Residuals, Solution, minimise, minimise_within};
use super::sample::PixelSample;
use super::seed::{Start, starts};
use super::spectrum::{SignalSpace, leading_eigenpairs};
use super::waveform::{ReceivedWaveform, Timing};
use nalgebra::DMatrix;
use rayon::prelude::*;
use std::cell::RefCell;

/// Position of ρ, e and λ in the parameter vector; the shifts follow.
const RATE: usize = 0;
/// Position of the exposure.
const EXPOSURE: usize = 1;
/// Position of the line delay.
const LINE_DELAY: usize = 2;
/// Position of the first shift.
const SHIFTS: usize = 3;
/// Shortest exposure the fit allows, frame periods.
const MIN_EXPOSURE: f64 = 0.02;
/// Largest readout time of the region the fit allows, frame periods: |λ|·height.
const MAX_READOUT: f64 = 1.5;
/// Largest number of row bands of the rolling-shutter test.
const TEST_BANDS: usize = 8;
/// Fewest rows per band of the rolling-shutter test.
const ROWS_PER_TEST_BAND: usize = 8;
/// Smallest phase ramp over the region, chips, that counts as a rolling shutter.
const MIN_RAMP_CHIPS: f64 = 0.01;
/// A line delay is kept when it lowers the band-wise cost by this many noise variances (and
/// by more than one extra parameter per band would by noise, see \[`ramp_threshold`\]), and
/// the row-wise cost by as many.
pub const RAMP_SIGNIFICANCE: f64 = 25.0;
/// A standard error is reported as at most this (exposure in frame periods, line delay in
/// frame periods per row): a direction the data do not constrain at all.
const UNDETERMINED_STD: f64 = 1.0;
/// The rows agree (no rolling-shutter search) when letting each band's shifts move lowers
/// the band-wise cost by less than this many noise variances per shift and the bands' shift
/// trend stays below [`MIN_RAMP_CHIPS`].
const AGREEMENT: f64 = 4.0;
/// Least-squares steps of each band's own shifts in that test.
const SCREEN_ITERATIONS: usize = 4;
/// Exposures tried as starting points of the band-wise and row-wise refinements.
const RAMP_EXPOSURES: [f64; 3] = [1.0, 0.5, 0.25];
/// Shift grid step, chips, of the re-search of each LED's shift.
const BACKFIT_STEP: f64 = 0.25;
/// Half-width, chips, of that re-search around the current shift.
const BACKFIT_REACH: f64 = 2.0;
/// Sweeps over the LEDs of that re-search.
const BACKFIT_SWEEPS: usize = 2;
/// Distances, chips, beside a kink of the cost at which a shift is tried
/// ([`Fitter::across_kinks`]).
const KINK_STEPS: [f64; 3] = [0.002, 0.01, 0.04];
/// Most restarts of the least-squares steps from across a kink.
const KINK_ROUNDS: usize = 3;
/// Exposures the row-wise refinement starts from besides the band-wise fit's.
const ROW_EXPOSURES: [f64; 1] = [1.0];
/// A sample row takes part in the row-wise fit when its leading singular value² exceeds the
/// noise-only edge (√pixels + √F)²·σ² by this factor.
const ROW_SIGNAL_FACTOR: f64 = 1.5;

/// The timing of every LED's received waveform.
#[derive(Debug, Clone, PartialEq)]
pub struct TimingModel {
    /// Shared camera timing.
    pub timing: Timing,
    /// λ: rolling-shutter line delay, frame periods per row (0 = global shutter).
    pub line_delay: f64,
    /// Δ_i per LED in chips at region row 0, in `[0, period_i)`.
    pub shifts: Vec<f64>,
}

impl TimingModel {
    /// From a parameter vector [ρ, e, λ, Δ…].
    fn from_params(params: &[f64]) -> Self {
        Self {
            timing: Timing {
                rate_ratio: params[RATE],
                exposure: params[EXPOSURE],
            },
            line_delay: params[LINE_DELAY],
            shifts: params[SHIFTS..].to_vec(),
        }
    }

    /// As a parameter vector [ρ, e, λ, Δ…].
    fn params(&self) -> Vec<f64> {
        let mut p = vec![
            self.timing.rate_ratio,
            self.timing.exposure,
            self.line_delay,
        ];
        p.extend(&self.shifts);
        p
    }

    /// Phase ramp over `rows` rows, chips.
    pub fn ramp_chips(&self, rows: usize) -> f64 {
        self.line_delay * rows as f64 * self.timing.rate_ratio
    }

    /// The K = N+1 template columns `[1, t_0, …]` (t_i = u_i − ½) of region row `row`.
    pub fn columns(&self, waves: &[ReceivedWaveform], row: f64, frames: usize) -> Vec<Vec<f64>> {
        let offset = self.line_delay * row * self.timing.rate_ratio;
        let mut columns = vec![vec![1.0; frames]];
        for (wave, &shift) in waves.iter().zip(&self.shifts) {
            let mut column = vec![0.0; frames];
            self.timing.fill_template(wave, shift + offset, &mut column);
            columns.push(column);
        }
        columns
    }

    /// The least-squares basis of region row `row`.
    pub fn basis(&self, waves: &[ReceivedWaveform], row: f64, frames: usize) -> TemplateBasis {
        TemplateBasis::new(&self.columns(waves, row, frames))
    }
}

/// The fitted timing and how well the data pin it down.
#[derive(Debug, Clone, PartialEq)]
pub struct TimingFit {
    /// The model.
    pub model: TimingModel,
    /// Whether the rows disagree (a line delay was fitted significant, or given non-zero).
    pub rolling: bool,
    /// Relative 1σ uncertainty of each LED's gain caused by the timing's uncertainty.
    pub gain_uncertainty: Vec<f64>,
    /// Noise variance of one pixel sample, fraction² of full scale (σ²_G / pixels).
    pub pixel_noise: f64,
    /// The fitted rate ratio sits at the edge of the searched range.
    pub rate_at_limit: bool,
    /// The fitted line delay sits at the largest one searched.
    pub line_delay_at_limit: bool,
    /// 1σ standard error of the exposure (frame periods) from the fit's covariance; 0 when
    /// given, \[`UNDETERMINED_STD`\] when the data do not constrain it or it ended on a bound.
    pub exposure_std: f64,
    /// 1σ standard error of the line delay (frame periods per row); 0 when given or not fitted.
    pub line_delay_std: f64,
    /// How much the fitted line delay lowers the row-wise cost against the best fit without
    /// one, noise variances (0 when the line delay was given or not fitted).
    pub line_delay_evidence: f64,
    /// Whether the line delay was fitted (not given, not absent).
    pub line_delay_fitted: bool,
}

impl TimingFit {
    /// Whether a fitted line delay lowers the cost by less than [`RAMP_SIGNIFICANCE`] noise
    /// variances: the data do not show it (never for a given or absent line delay).
    pub fn line_delay_undetermined(&self) -> bool {
        self.rolling && self.line_delay_fitted && self.line_delay_evidence < RAMP_SIGNIFICANCE
    }
}

/// The row-wise fit and the evidence for its line delay.
struct RowFit {
    solution: Solution,
    /// Cost reduction of the line delay against the fit without it, noise variances (0 when
    /// the line delay was held).
    evidence: f64,
}

/// A compressed block of sample data sharing one set of templates.
#[derive(Debug, Clone)]
struct FitGroup {
    /// Region row the templates are evaluated at.
    row: f64,
    /// F × k data directions, scaled by their singular values.
    data: DMatrix<f64>,
}

/// The variable-projection residual over groups.
struct Projection<'a> {
    waves: &'a [ReceivedWaveform],
    groups: &'a [FitGroup],
    frames: usize,
}

thread_local! {
    /// Work space of one residual evaluation on this thread: the K × F template rows and the
    /// fitted values of one direction (a fit evaluates the residual hundreds of times, from
    /// several threads, and allocates nothing for it).
    static WORKSPACE: RefCell<(Vec<f64>, Vec<f64>)> = const { RefCell::new((Vec::new(), Vec::new())) };
}

impl<'a> Projection<'a> {
    fn new(waves: &'a [ReceivedWaveform], groups: &'a [FitGroup], frames: usize) -> Self {
        Self {
            waves,
            groups,
            frames,
        }
    }
}

impl Residuals for Projection<'_> {
    fn residuals(&self, params: &[f64], out: &mut Vec<f64>) {
        out.clear();
        // No frames, no residuals (and no zero-length chunks below).
        let Some(f) = std::num::NonZeroUsize::new(self.frames).map(usize::from) else {
            return;
        };
        let k = self.waves.len() + 1;
        WORKSPACE.with_borrow_mut(|(basis, fitted)| {
            basis.resize(k * f, 0.0);
            fitted.resize(f, 0.0);
            let mut projection = [0.0f64; MAX_COLUMNS];
            for group in self.groups {
                fill_columns(params, self.waves, group.row, f, basis);
                orthonormalise(basis, f);
                for d in group.data.as_slice().chunks_exact(f) {
                    for (c, q) in projection.iter_mut().zip(basis.chunks_exact(f)) {
                        *c = q.iter().zip(d).map(|(a, b)| a * b).sum::<f64>();
                    }
                    // Σ_l q_l[j]·c_l in the order l = 0, 1, …, frame by frame.
                    fitted.iter_mut().for_each(|x| *x = 0.0);
                    for (q, &c) in basis.chunks_exact(f).zip(&projection) {
                        fitted.iter_mut().zip(q).for_each(|(x, &v)| *x += v * c);
                    }
                    out.extend(d.iter().zip(fitted.iter()).map(|(&d, &x)| d - x));
                }
            }
        });
    }
}

/// Most template columns K = N + 1.
const MAX_COLUMNS: usize = super::MAX_LEDS + 1;

/// The K = N+1 template rows `[1, t_0, …]` of parameters [ρ, e, λ, Δ…] at region row `row`,
/// written row-major (K × F) into `out` (as [`TimingModel::columns`]).
fn fill_columns(
    params: &[f64],
    waves: &[ReceivedWaveform],
    row: f64,
    frames: usize,
    out: &mut [f64],
) {
    let timing = Timing {
        rate_ratio: params[RATE],
        exposure: params[EXPOSURE],
    };
    let offset = params[LINE_DELAY] * row * timing.rate_ratio;
    let mut rows = out.chunks_exact_mut(frames.max(1));
    if let Some(ones) = rows.next() {
        ones.iter_mut().for_each(|v| *v = 1.0);
    }
    for ((wave, &shift), column) in waves.iter().zip(&params[SHIFTS..]).zip(rows) {
        timing.fill_template(wave, shift + offset, column);
    }
}

/// Modified Gram–Schmidt on the rows (F values each) of `rows`, in place: the Q of
/// [`TemplateBasis::new`] with the same operations in the same order, without R.
fn orthonormalise(rows: &mut [f64], frames: usize) {
    let f = frames.max(1);
    for k in 0..rows.len() / f {
        let (done, rest) = rows.split_at_mut(k * f);
        let v = &mut rest[..f];
        let scale = v.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
        for q in done.chunks_exact(f) {
            let d: f64 = q.iter().zip(v.iter()).map(|(a, b)| a * b).sum();
            v.iter_mut().zip(q).for_each(|(x, &y)| *x -= d * y);
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-7 * scale {
            v.iter_mut().for_each(|x| *x /= norm);
        } else {
            v.iter_mut().for_each(|x| *x = 0.0);
        }
    }
}

/// Fits the timing of `leds` LEDs to the sample (module docs).
pub fn fit_timing(
    sample: &PixelSample,
    space: &SignalSpace,
    leds: usize,
    height: usize,
    limits: &FitLimits,
) -> TimingFit {
    let frames = sample.frames();
    let waves = ReceivedWaveform::set(leds, sample.nuisance());
    let pixel_noise = space.noise / sample.len().max(1) as f64;
    let fitter = Fitter {
        waves: &waves,
        frames,
        height,
        limits,
    };
    let global = fitter.global(space);
    let held = RowFit {
        solution: global,
        evidence: 0.0,
    };
    let (fit, rolling) = match limits.line_delay {
        Some(delay) if delay != 0.0 => {
            let start = fitter.pivot(&held.solution.params, delay, mean_row(sample));
            (fitter.rows(sample, pixel_noise, &start, false), true)
        }
        Some(_) => (held, false),
        None => match fitter.band_fit(sample, &held.solution, pixel_noise) {
            Some(banded) => {
                let rows = fitter.rows(sample, pixel_noise, &banded.params, true);
                if rows.evidence >= RAMP_SIGNIFICANCE {
                    (rows, true)
                } else {
                    (held, false)
                }
            }
            None => (held, false),
        },
    };
    fitter.finish(sample, fit, rolling, pixel_noise)
}

/// Refines an earlier fit of more LEDs (the LED-count check's) for the first `leds` of them,
/// without new seeds.
pub fn refit_timing(
    sample: &PixelSample,
    space: &SignalSpace,
    leds: usize,
    height: usize,
    limits: &FitLimits,
    previous: &TimingFit,
) -> TimingFit {
    let frames = sample.frames();
    let waves = ReceivedWaveform::set(leds, sample.nuisance());
    let pixel_noise = space.noise / sample.len().max(1) as f64;
    let fitter = Fitter {
        waves: &waves,
        frames,
        height,
        limits,
    };
    let mut start = previous.model.params();
    start.truncate(SHIFTS + leds);
    let fit = if previous.rolling {
        fitter.rows(sample, pixel_noise, &start, limits.line_delay.is_none())
    } else {
        let groups = global_groups(space, frames);
        let freedom = fitter.freedom(false);
        let solution = fitter.solve(&groups, &start, &freedom);
        RowFit {
            solution: fitter.across_kinks(&groups, solution, &freedom),
            evidence: 0.0,
        }
    };
    fitter.finish(sample, fit, previous.rolling, pixel_noise)
}

/// The global-shutter data: the signal eigenvectors scaled by √eigenvalue.
fn global_groups(space: &SignalSpace, frames: usize) -> [FitGroup; 1] {
    let rank = space.rank.max(1).min(space.vectors.ncols());
    let data = DMatrix::from_fn(frames, rank, |j, k| {
        space.vectors[(j, k)] * space.values[k].max(0.0).sqrt()
    });
    [FitGroup { row: 0.0, data }]
}

/// The fit's shared settings.
struct Fitter<'a> {
    waves: &'a [ReceivedWaveform],
    frames: usize,
    height: usize,
    limits: &'a FitLimits,
}

impl Fitter<'_> {
    /// The orientation, gain uncertainty, limit checks and packaging of a solution.
    fn finish(
        &self,
        sample: &PixelSample,
        fit: RowFit,
        rolling: bool,
        pixel_noise: f64,
    ) -> TimingFit {
        let RowFit { solution, evidence } = fit;
        let line_delay_fitted =
            rolling && self.limits.line_delay.is_none() && solution.free.contains(&LINE_DELAY);
        let mut model = TimingModel::from_params(&solution.params);
        orient(sample, self.waves, &mut model);
        let reference = if rolling { mean_row(sample) } else { 0.0 };
        let information = ScaledInformation::new(&solution);
        let gain_uncertainty = gain_uncertainty(
            self.waves,
            &model,
            &solution,
            information.as_ref(),
            reference,
            self.frames,
            pixel_noise,
        );
        let rate_at_limit = self.limits.rate_ratio.is_none()
            && (model.timing.rate_ratio - 1.0).abs() > self.limits.max_rate_mismatch;
        let line_delay_at_limit = rolling
            && self.limits.line_delay.is_none()
            && model.line_delay.abs() * self.height as f64 >= MAX_READOUT * (1.0 - 1e-6);
        TimingFit {
            model,
            rolling,
            gain_uncertainty,
            pixel_noise,
            rate_at_limit,
            line_delay_at_limit,
            exposure_std: if exposure_on_bound(&solution) {
                UNDETERMINED_STD
            } else {
                standard_error(&solution, information.as_ref(), EXPOSURE, pixel_noise)
            },
            line_delay_std: standard_error(
                &solution,
                information.as_ref(),
                LINE_DELAY,
                pixel_noise,
            ),
            line_delay_evidence: evidence,
            line_delay_fitted,
        }
    }

    /// Which parameters move: ρ and e unless given, λ when `line_delay`, every shift.
    fn freedom(&self, line_delay: bool) -> Freedom {
        let mismatch = self.limits.max_rate_mismatch + 1.0 / self.frames.max(1) as f64;
        let mut free = vec![
            self.limits.rate_ratio.is_none(),
            self.limits.exposure.is_none(),
            line_delay,
        ];
        let mut bounds = vec![(1.0 - mismatch, 1.0 + mismatch), (MIN_EXPOSURE, 1.0), {
            let most = MAX_READOUT / self.height.max(1) as f64;
            (-most, most)
        }];
        for _ in self.waves {
            free.push(true);
            bounds.push((f64::NEG_INFINITY, f64::INFINITY));
        }
        if let Some(rate) = self.limits.rate_ratio {
            bounds[RATE] = (rate, rate);
        }
        if let Some(exposure) = self.limits.exposure {
            bounds[EXPOSURE] = (exposure, exposure);
        }
        if let Some(delay) = self.limits.line_delay {
            free[LINE_DELAY] = false;
            bounds[LINE_DELAY] = (delay, delay);
        }
        Freedom { free, bounds }
    }

    /// Least squares over `groups` from `start`.
    fn solve(&self, groups: &[FitGroup], start: &[f64], freedom: &Freedom) -> Solution {
        let problem = Projection::new(self.waves, groups, self.frames);
        minimise(&problem, start, freedom)
    }

    /// The lowest-cost refinement of `starts` (refined in parallel; the first of equal costs).
    fn best_of(
        &self,
        groups: &[FitGroup],
        starts: Vec<Vec<f64>>,
        freedom: &Freedom,
    ) -> Option<Solution> {
        let solutions: Vec<Solution> = starts
            .par_iter()
            .map(|start| self.solve(groups, start, freedom))
            .collect();
        let mut best: Option<Solution> = None;
        for solution in solutions {
            if best.as_ref().is_none_or(|b| solution.cost < b.cost) {
                best = Some(solution);
            }
        }
        best
    }

    /// Phase (1): every seed refined with a global shutter; the lowest cost wins.
    fn global(&self, space: &SignalSpace) -> Solution {
        let groups = global_groups(space, self.frames);
        let freedom = self.freedom(false);
        let seeds = starts(space, self.waves, self.frames, self.limits);
        let starts: Vec<Vec<f64>> = seeds
            .into_iter()
            .map(|Start { timing, shifts }| {
                let mut params = vec![timing.rate_ratio, timing.exposure, 0.0];
                params.extend(shifts);
                params
            })
            .collect();
        self.best_of(&groups, starts, &freedom)
            .map(|best| self.across_kinks(&groups, best, &freedom))
            .unwrap_or_else(|| Solution {
                params: {
                    let mut p = vec![self.limits.rate_ratio.unwrap_or(1.0), 1.0, 0.0];
                    p.extend(std::iter::repeat_n(0.0, self.waves.len()));
                    p
                },
                cost: f64::INFINITY,
                information: DMatrix::zeros(0, 0),
                free: Vec::new(),
            })
    }

    /// Restarts the least-squares steps from across the kinks of each LED's shift while that
    /// lowers the cost.
    ///
    /// With the exposure e < 1 chip, the template of a shift Δ whose window [Δ, Δ + e] lies
    /// inside one chip is the same for every such Δ: the cost is flat there, and has a kink
    /// wherever the window's start or end crosses a chip boundary (Δ = n or Δ = n − e). The
    /// steps stop at a kink or on the flat when the optimum lies across it, and the LED's
    /// template then misses the sliver of the neighbouring chip its window holds, which lowers
    /// its gain by 1.5–2 times that sliver's share of the window (neighbouring chips of a
    /// Manchester carrier correlate at −½ to −1). Each shift is therefore tried at
    /// [`KINK_STEPS`] on both sides of every kink within a chip of its window, the others
    /// held, and the steps restart from the lowest of these when it is below the current cost.
    fn across_kinks(&self, groups: &[FitGroup], mut best: Solution, freedom: &Freedom) -> Solution {
        let problem = Projection::new(self.waves, groups, self.frames);
        for _ in 0..KINK_ROUNDS {
            let exposure = best.params[EXPOSURE];
            let trials: Vec<Vec<f64>> = (0..self.waves.len())
                .flat_map(|i| {
                    let shift = best.params[SHIFTS + i];
                    let first = shift.floor() as i64 - 1;
                    let last = (shift + exposure).ceil() as i64 + 1;
                    (first..=last)
                        .flat_map(move |n| [n as f64, n as f64 - exposure])
                        .flat_map(|edge| KINK_STEPS.iter().flat_map(move |s| [edge - s, edge + s]))
                        .map(move |trial| (i, trial))
                })
                .map(|(i, trial)| {
                    let mut params = best.params.clone();
                    params[SHIFTS + i] = trial;
                    params
                })
                .collect();
            let lowest = trials
                .into_par_iter()
                .map(|params| {
                    let mut residual = Vec::new();
                    problem.residuals(&params, &mut residual);
                    (residual.iter().map(|r| r * r).sum::<f64>(), params)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let Some((_, start)) = lowest.filter(|(cost, _)| *cost < best.cost) else {
                break;
            };
            let refined = self.solve(groups, &start, freedom);
            if refined.cost >= best.cost {
                break;
            }
            best = refined;
        }
        best
    }

    /// Parameters with line delay `delay` whose shifts equal `params`' at region row `row`.
    fn pivot(&self, params: &[f64], delay: f64, row: f64) -> Vec<f64> {
        let mut p = params.to_vec();
        p[LINE_DELAY] = delay;
        let offset = delay * row * p[RATE];
        p[SHIFTS..].iter_mut().for_each(|s| *s -= offset);
        p
    }

    /// Phase (2): the band-wise test for a rolling shutter; the band-wise solution when the
    /// rows disagree significantly.
    fn band_fit(
        &self,
        sample: &PixelSample,
        global: &Solution,
        pixel_noise: f64,
    ) -> Option<Solution> {
        let height = self.height;
        let bands = (height / ROWS_PER_TEST_BAND).clamp(1, TEST_BANDS);
        if bands < 2 {
            return None;
        }
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); bands];
        for (p, &row) in sample.rows().iter().enumerate() {
            members[(row * bands / height).min(bands - 1)].push(p);
        }
        let groups: Vec<FitGroup> = members
            .par_iter()
            .filter(|m| m.len() >= 2)
            .filter_map(|m| compress(sample, m, 2 * self.waves.len()))
            .collect();
        if groups.len() < 2 {
            return None;
        }
        // Each band's own shifts (timing held, a few steps), and their trend across the bands.
        let mut shifts_only = self.freedom(false);
        shifts_only.free[RATE] = false;
        shifts_only.free[EXPOSURE] = false;
        let (mut sxy, mut sxx, mut sw, mut swx) = (0.0, 0.0, 0.0, 0.0);
        let mut trend = Vec::new();
        let mut gained = 0.0;
        let screened: Vec<(f64, Solution)> = groups
            .par_iter()
            .map(|group| {
                let single = std::slice::from_ref(group);
                let problem = Projection::new(self.waves, single, self.frames);
                let mut residual = Vec::new();
                problem.residuals(&global.params, &mut residual);
                let before: f64 = residual.iter().map(|r| r * r).sum();
                let solution =
                    minimise_within(&problem, &global.params, &shifts_only, SCREEN_ITERATIONS);
                (before, solution)
            })
            .collect();
        for (group, (before, solution)) in groups.iter().zip(screened) {
            gained += before - solution.cost;
            let weight = group.data.norm_squared();
            for (i, wave) in self.waves.iter().enumerate() {
                let half = wave.period() as f64 / 2.0;
                let offset = (solution.params[SHIFTS + i] - global.params[SHIFTS + i] + half / 2.0)
                    .rem_euclid(half)
                    - half / 2.0;
                trend.push((group.row, offset, weight));
            }
        }
        for &(row, _, w) in &trend {
            sw += w;
            swx += w * row;
        }
        let centre = swx / sw.max(f64::MIN_POSITIVE);
        for &(row, offset, w) in &trend {
            sxy += w * (row - centre) * offset;
            sxx += w * (row - centre) * (row - centre);
        }
        let chips_per_row = if sxx > 0.0 { sxy / sxx } else { 0.0 };
        let shifts = (groups.len() * self.waves.len()) as f64;
        if gained < AGREEMENT * shifts * pixel_noise
            && (chips_per_row * height as f64).abs() < MIN_RAMP_CHIPS
        {
            return None;
        }
        let delay = chips_per_row / global.params[RATE];
        // The band-wise optimum without a line delay: what λ has to improve on.
        let base = self
            .solve(&groups, &global.params, &self.freedom(false))
            .cost;
        let freedom = self.freedom(true);
        let starts = self
            .exposures(global.params[EXPOSURE], &RAMP_EXPOSURES)
            .into_iter()
            .map(|exposure| {
                let mut start = self.pivot(&global.params, delay, centre);
                start[EXPOSURE] = exposure;
                start
            })
            .collect();
        let first = self.best_of(&groups, starts, &freedom)?;
        let searched = self.backfit(&groups, first.params.clone());
        let second = self.solve(&groups, &searched, &freedom);
        let best = if second.cost < first.cost {
            second
        } else {
            first
        };
        let ramp = TimingModel::from_params(&best.params)
            .ramp_chips(height)
            .abs();
        if ramp < MIN_RAMP_CHIPS {
            return None;
        }
        // The same fit without λ, started from λ's solution: what λ itself explains.
        let flat = self
            .solve(
                &groups,
                &self.pivot(&best.params, 0.0, centre),
                &self.freedom(false),
            )
            .cost;
        let base = base.min(flat);
        (base - best.cost > ramp_threshold(groups.len()) * pixel_noise).then_some(best)
    }

    /// The exposures to start a refinement from: `fitted` and `spread` (only the known
    /// exposure when it is given).
    fn exposures(&self, fitted: f64, spread: &[f64]) -> Vec<f64> {
        if self.limits.exposure.is_some() {
            return vec![fitted];
        }
        let mut exposures = vec![fitted];
        for &e in spread {
            if exposures.iter().all(|x| (x - e).abs() > 0.05) {
                exposures.push(e);
            }
        }
        exposures
    }

    /// Re-searches each LED's shift on a grid with the rest held (escapes a shift caught a
    /// chip away, which the least-squares steps cannot cross).
    fn backfit(&self, groups: &[FitGroup], mut params: Vec<f64>) -> Vec<f64> {
        let problem = Projection::new(self.waves, groups, self.frames);
        let mut residual = Vec::new();
        for _ in 0..BACKFIT_SWEEPS {
            for (i, wave) in self.waves.iter().enumerate() {
                let reach = (wave.period() as f64 / 4.0).min(BACKFIT_REACH);
                let steps = (reach / BACKFIT_STEP).round() as i64;
                let centre = params[SHIFTS + i];
                let mut best = (f64::INFINITY, centre);
                for k in -steps..steps {
                    params[SHIFTS + i] = centre + k as f64 * BACKFIT_STEP;
                    problem.residuals(&params, &mut residual);
                    let cost: f64 = residual.iter().map(|r| r * r).sum();
                    if cost < best.0 {
                        best = (cost, params[SHIFTS + i]);
                    }
                }
                params[SHIFTS + i] = best.1;
            }
        }
        params
    }

    /// Phase (3): the row-by-row fit from `start` (several exposures unless the exposure is
    /// given), with the evidence for its line delay when `fit_delay` (module docs).
    fn rows(
        &self,
        sample: &PixelSample,
        pixel_noise: f64,
        start: &[f64],
        fit_delay: bool,
    ) -> RowFit {
        let groups = row_groups(sample, self.waves.len(), pixel_noise);
        let freedom = self.freedom(fit_delay);
        let starts = self
            .exposures(start[EXPOSURE], &ROW_EXPOSURES)
            .into_iter()
            .map(|exposure| {
                let mut params = start.to_vec();
                params[EXPOSURE] = exposure;
                params
            })
            .collect();
        let best = self.best_of(&groups, starts, &freedom);
        let solution = best.unwrap_or_else(|| self.solve(&groups, start, &freedom));
        let evidence = if fit_delay {
            let flat = self.pivot(&solution.params, 0.0, mean_row(sample));
            let without = self.solve(&groups, &flat, &self.freedom(false)).cost;
            (without - solution.cost) / pixel_noise.max(f64::MIN_POSITIVE)
        } else {
            0.0
        };
        RowFit { solution, evidence }
    }
}

/// Noise variances a line delay must explain on `bands` row bands: [`RAMP_SIGNIFICANCE`], and
/// at least the mean plus five standard deviations of the χ² with one degree of freedom per
/// band (what one extra parameter per band would gain from noise alone).
fn ramp_threshold(bands: usize) -> f64 {
    let b = bands as f64;
    RAMP_SIGNIFICANCE.max(b + 5.0 * (2.0 * b).sqrt())
}

/// The Gauss–Newton information JᵀJ of a solution in unit-diagonal form, for its covariance
/// σ²·(JᵀJ)⁻¹. The parameters' scales differ by orders of magnitude (ρ ≈ 1, e ≈ 0.5, Δ_i tens
/// of chips, λ ≈ 1e-3 frame periods per row), so JᵀJ is inverted as D⁻¹·(D⁻¹JᵀJD⁻¹)⁻¹·D⁻¹
/// with D = diag(√(JᵀJ)_kk): Jacobian columns scaled to unit norm, whose Gram matrix has a
/// condition number set by the parameters' correlations alone, not by their units.
struct ScaledInformation {
    /// Eigen-decomposition of D⁻¹·JᵀJ·D⁻¹.
    eigen: nalgebra::SymmetricEigen<f64, nalgebra::Dyn>,
    /// D's diagonal (1 for a column of zeros).
    scale: Vec<f64>,
    /// Eigenvalues at or below this are flat directions the data leave undetermined.
    flat: f64,
}

impl ScaledInformation {
    /// From a solution (None when nothing was fitted).
    fn new(solution: &Solution) -> Option<Self> {
        let n = solution.free.len();
        if n == 0 || solution.information.shape() != (n, n) {
            return None;
        }
        let scale: Vec<f64> = (0..n)
            .map(|k| {
                let d = solution.information[(k, k)].max(0.0).sqrt();
                if d > 0.0 && d.is_finite() { d } else { 1.0 }
            })
            .collect();
        let scaled = DMatrix::from_fn(n, n, |r, c| {
            solution.information[(r, c)] / (scale[r] * scale[c])
        });
        let eigen = scaled.symmetric_eigen();
        let largest = eigen.eigenvalues.iter().fold(0.0f64, |m, &v| m.max(v));
        Some(Self {
            eigen,
            scale,
            flat: 1e-12 * largest,
        })
    }

    /// (JᵀJ)⁻¹ over the determined directions (a pseudo-inverse).
    fn inverse(&self) -> DMatrix<f64> {
        let n = self.scale.len();
        let mut inverse = DMatrix::zeros(n, n);
        for (m, &value) in self.eigen.eigenvalues.iter().enumerate() {
            if value > self.flat {
                let v = self.eigen.eigenvectors.column(m);
                inverse += v * v.transpose() / value;
            }
        }
        DMatrix::from_fn(n, n, |r, c| {
            inverse[(r, c)] / (self.scale[r] * self.scale[c])
        })
    }

    /// ((JᵀJ)⁻¹)_aa for free parameter `a`, None when it loads on a flat direction.
    fn variance(&self, a: usize) -> Option<f64> {
        let mut variance = 0.0;
        for (m, &value) in self.eigen.eigenvalues.iter().enumerate() {
            let loading = self.eigen.eigenvectors[(a, m)];
            if value > self.flat {
                variance += loading * loading / value;
            } else if loading.abs() > 1e-6 {
                return None;
            }
        }
        Some(variance / (self.scale[a] * self.scale[a]))
    }
}

/// 1σ standard error of parameter `k` from the Gauss–Newton covariance σ²·(JᵀJ)⁻¹ of
/// `solution` (0 when `k` was held; [`UNDETERMINED_STD`] at most, and when `k` loads on a
/// direction the data leave flat: a scaled eigenvalue below 1e-12 of the largest, see
/// [`ScaledInformation`]).
fn standard_error(
    solution: &Solution,
    information: Option<&ScaledInformation>,
    k: usize,
    pixel_noise: f64,
) -> f64 {
    let Some(a) = solution.free.iter().position(|&f| f == k) else {
        return 0.0;
    };
    match information.and_then(|i| i.variance(a)) {
        Some(variance) => (variance * pixel_noise).sqrt().min(UNDETERMINED_STD),
        None => UNDETERMINED_STD,
    }
}

/// How close to a bound, frame periods, an exposure counts as on it: the fit stops a hair
/// short of a bound as well as on it (the −20 ppm case below: just under 1.0, shown as 1.000).
const ON_BOUND: f64 = 1e-3;

/// Whether the fitted exposure ended on one of its bounds ([`MIN_EXPOSURE`] or one frame).
/// Its Gauss–Newton standard error says nothing there: the cost's minimum lies outside the
/// box, or at one frame on a kink of the model (a shorter window mixes two chips, a longer
/// one three), where the curvature is that of the kink, not of how far inside the box the
/// data let the exposure move. The −20 ppm hil-like capture with integer shifts (true
/// exposure 0.8, which every exposure in [0.8, 1] fits as well at ρ ≈ 1) ended at 1.0 and
/// reported ±0.002 from that curvature; on a bound the exposure is reported undetermined.
fn exposure_on_bound(solution: &Solution) -> bool {
    let exposure = solution.params[EXPOSURE];
    solution.free.contains(&EXPOSURE)
        && (exposure >= 1.0 - ON_BOUND || exposure <= MIN_EXPOSURE + ON_BOUND)
}

/// The sample's mean region row.
fn mean_row(sample: &PixelSample) -> f64 {
    let rows = sample.rows();
    rows.iter().sum::<usize>() as f64 / rows.len().max(1) as f64
}

/// The `keep` leading singular directions (scaled) of the sample pixels `members`, at their
/// mean row.
fn compress(sample: &PixelSample, members: &[usize], keep: usize) -> Option<FitGroup> {
    let frames = sample.frames();
    let x = DMatrix::from_fn(members.len(), frames, |r, j| sample.pixel(members[r])[j]);
    let row =
        members.iter().map(|&p| sample.rows()[p]).sum::<usize>() as f64 / members.len() as f64;
    let (data, _) = leading_directions(&x, keep)?;
    Some(FitGroup { row, data })
}

/// The `keep` leading right singular vectors of `x` (pixels × F) scaled by their singular
/// values (F × k), and those singular values, descending: from the eigenpairs of the smaller
/// Gram matrix, xᵀx or xxᵀ (for the latter the scaled vectors are xᵀu), which costs a
/// fraction of a full SVD when only a few directions are wanted.
fn leading_directions(x: &DMatrix<f64>, keep: usize) -> Option<(DMatrix<f64>, Vec<f64>)> {
    let (pixels, frames) = x.shape();
    if pixels == 0 || frames == 0 || keep == 0 {
        return None;
    }
    let (values, data) = if pixels >= frames {
        let (values, vectors) = leading_eigenpairs(&x.tr_mul(x), keep.min(frames));
        let singular: Vec<f64> = values.iter().map(|v| v.sqrt()).collect();
        (singular.clone(), scale_columns(vectors, &singular))
    } else {
        let (values, vectors) = leading_eigenpairs(&(x * x.transpose()), keep.min(pixels));
        let singular: Vec<f64> = values.iter().map(|v| v.sqrt()).collect();
        (singular, x.tr_mul(&vectors))
    };
    Some((data, values))
}

/// Columns of `m` times `scale`.
fn scale_columns(mut m: DMatrix<f64>, scale: &[f64]) -> DMatrix<f64> {
    for (mut column, s) in m.column_iter_mut().zip(scale) {
        column *= *s;
    }
    m
}

/// One group per sample row with signal: its N leading directions.
fn row_groups(sample: &PixelSample, leds: usize, pixel_noise: f64) -> Vec<FitGroup> {
    let frames = sample.frames() as f64;
    sample
        .row_runs()
        .into_par_iter()
        .filter_map(|run| {
            let pixels = run.len() as f64;
            let x = sample.matrix(run.clone());
            let (data, values) = leading_directions(&x, leds)?;
            let edge = (pixels.sqrt() + frames.sqrt()).powi(2) * pixel_noise;
            let strongest = values.first().copied().unwrap_or(0.0);
            (strongest * strongest > ROW_SIGNAL_FACTOR * edge).then(|| FitGroup {
                row: sample.rows()[run.start] as f64,
                data,
            })
        })
        .collect()
}

/// Chooses each carrier's sign so that the sample's summed on-levels are positive, and wraps
/// each shift into one period.
fn orient(sample: &PixelSample, waves: &[ReceivedWaveform], model: &mut TimingModel) {
    let frames = sample.frames();
    let mut sums = vec![0.0; waves.len()];
    let mut coefficients = vec![0.0; waves.len() + 1];
    for run in sample.row_runs() {
        let row = sample.rows()[run.start] as f64;
        let mut total = vec![0.0; frames];
        for p in run {
            total
                .iter_mut()
                .zip(sample.pixel(p))
                .for_each(|(t, x)| *t += x);
        }
        let basis = model.basis(waves, row, frames);
        let projections: Vec<f64> = basis
            .rows
            .iter()
            .map(|q| q.iter().zip(&total).map(|(a, b)| a * b).sum())
            .collect();
        basis.coefficients(&projections, &mut coefficients);
        sums.iter_mut()
            .zip(&coefficients[1..])
            .for_each(|(s, c)| *s += c);
    }
    for ((shift, wave), sum) in model.shifts.iter_mut().zip(waves).zip(&sums) {
        let period = wave.period() as f64;
        if *sum < 0.0 {
            *shift += period / 2.0;
        }
        *shift = shift.rem_euclid(period);
    }
}

/// Relative 1σ gain uncertainty of each LED: the timing's covariance σ²·(JᵀJ)⁻¹ carried into
/// the matched filter's coefficients, δg_i = (T⁺·∂T/∂θ_k)_ii·δθ_k, at region row `row`
/// (the covariance over the determined directions, [`ScaledInformation`]).
fn gain_uncertainty(
    waves: &[ReceivedWaveform],
    model: &TimingModel,
    solution: &Solution,
    information: Option<&ScaledInformation>,
    row: f64,
    frames: usize,
    pixel_noise: f64,
) -> Vec<f64> {
    let n = solution.free.len();
    let Some(information) = information.filter(|_| n > 0) else {
        return vec![0.0; waves.len()];
    };
    let covariance = information.inverse() * pixel_noise;
    let params = model.params();
    let basis = model.basis(waves, row, frames);
    let base = model.columns(waves, row, frames);
    let step = 1e-6;
    let mut sensitivity = DMatrix::zeros(waves.len(), n);
    let mut coefficients = vec![0.0; waves.len() + 1];
    for (a, &k) in solution.free.iter().enumerate() {
        let mut shifted = params.clone();
        shifted[k] += step;
        let columns = TimingModel::from_params(&shifted).columns(waves, row, frames);
        for i in 0..waves.len() {
            let derivative: Vec<f64> = columns[i + 1]
                .iter()
                .zip(&base[i + 1])
                .map(|(x, y)| (x - y) / step)
                .collect();
            let projections: Vec<f64> = basis
                .rows
                .iter()
                .map(|q| q.iter().zip(&derivative).map(|(a, b)| a * b).sum())
                .collect();
            basis.coefficients(&projections, &mut coefficients);
            sensitivity[(i, a)] = coefficients[i + 1];
        }
    }
    (0..waves.len())
        .map(|i| {
            let s = sensitivity.row(i);
            (s * &covariance * s.transpose())[(0, 0)].max(0.0).sqrt()
        })
        .collect()
}
