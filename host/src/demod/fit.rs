//! Fitting each LED's received waveform to the spatial mean of the frames (SPEC §4, "better
//! estimators").
//!
//! The carriers stay orthogonal under any shift, so the mean over all pixels of a frame
//! sequence is the sum of every LED's waveform with the scene-averaged on-level as its gain.
//! Because the shift Δ_i, the exposure e and the rate ratio ρ are the same for every pixel of a
//! global-shutter frame, they are fitted once here: a coarse grid over ρ (with per-LED best
//! shifts, which decouple by orthogonality), a grid over e, then a joint coordinate search that
//! maximises the variance the K = N+1 column least-squares model explains. The per-pixel
//! amplitudes are then a linear matched filter ([`super::basis`]).

use super::basis::TemplateBasis;
use super::waveform::{ReceivedWaveform, Timing};
use rayon::prelude::*;

/// What the fit may vary.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitLimits {
    /// Largest |ρ − 1| searched when the rate ratio is estimated.
    pub max_rate_mismatch: f64,
    /// A known rate ratio ρ (chips per frame) instead of estimating it.
    pub rate_ratio: Option<f64>,
    /// A known exposure fraction instead of estimating it.
    pub exposure: Option<f64>,
}

impl Default for FitLimits {
    fn default() -> Self {
        Self {
            max_rate_mismatch: 0.06,
            rate_ratio: None,
            exposure: None,
        }
    }
}

/// The fitted received waveforms.
#[derive(Debug, Clone, PartialEq)]
pub struct WaveformFit {
    /// Shared camera timing.
    pub timing: Timing,
    /// Δ_i per LED in chips, in `[0, period_i)`.
    pub shifts: Vec<f64>,
    /// Least-squares on-level of each LED in the mean signal (its scene average).
    pub amplitudes: Vec<f64>,
    /// RMS of the fit residual of the mean signal.
    pub residual_rms: f64,
}

/// Builds the K = N+1 template columns `[1, t_0, …]` over `frames` frames.
pub fn template_columns(
    waves: &[ReceivedWaveform],
    timing: Timing,
    shifts: &[f64],
    frames: usize,
) -> Vec<Vec<f64>> {
    let mut columns = vec![vec![1.0; frames]];
    for (wave, &shift) in waves.iter().zip(shifts) {
        columns.push(
            (0..frames)
                .map(|j| timing.template(wave, shift, j))
                .collect(),
        );
    }
    columns
}

/// Variance of `signal` explained by the joint least-squares model, and its coefficients.
fn explained(
    waves: &[ReceivedWaveform],
    timing: Timing,
    shifts: &[f64],
    signal: &[f64],
) -> (f64, Vec<f64>) {
    let basis = TemplateBasis::new(&template_columns(waves, timing, shifts, signal.len()));
    let projections: Vec<f64> = basis
        .rows
        .iter()
        .map(|q| q.iter().zip(signal).map(|(a, b)| f64::from(*a) * b).sum())
        .collect();
    let mut coefficients = vec![0.0; basis.columns];
    basis.coefficients(&projections, &mut coefficients);
    let explained = projections.iter().skip(1).map(|b| b * b).sum();
    (explained, coefficients)
}

/// Variance of `signal` explained by the joint least-squares model (what [`explained`]
/// returns first), without allocating: modified Gram–Schmidt of the centred templates in
/// `work` (resized to K·F), summing the squared projections of the signal.
fn explained_variance(
    waves: &[ReceivedWaveform],
    timing: Timing,
    shifts: &[f64],
    signal: &[f64],
    work: &mut Vec<f64>,
) -> f64 {
    let f = signal.len();
    work.resize(waves.len() * f, 0.0);
    let mut total = 0.0;
    for (k, (wave, &shift)) in waves.iter().zip(shifts).enumerate() {
        let (done, rest) = work.split_at_mut(k * f);
        let Some(v) = rest.get_mut(..f) else {
            return total;
        };
        timing.fill_template(wave, shift, v);
        let scale = v.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
        // Orthogonal to the constant column: subtract the mean.
        let mean = v.iter().sum::<f64>() / f.max(1) as f64;
        v.iter_mut().for_each(|x| *x -= mean);
        for q in done.chunks_exact(f) {
            let d: f64 = q.iter().zip(v.iter()).map(|(a, b)| a * b).sum();
            v.iter_mut().zip(q).for_each(|(x, y)| *x -= d * y);
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-7 * scale {
            v.iter_mut().for_each(|x| *x /= norm);
            let d: f64 = v.iter().zip(signal).map(|(a, b)| a * b).sum();
            total += d * d;
        } else {
            v.iter_mut().for_each(|x| *x = 0.0);
        }
    }
    total
}

/// Score of one LED alone: squared correlation of its centred template with the centred signal.
fn led_score(
    wave: &ReceivedWaveform,
    timing: Timing,
    shift: f64,
    centred: &[f64],
    template: &mut [f64],
) -> f64 {
    let f = centred.len();
    timing.fill_template(wave, shift, template);
    let mut sum = 0.0;
    let mut template_sum = 0.0;
    let mut template_sq = 0.0;
    for (&t, &m) in template.iter().zip(centred) {
        sum += t * m;
        template_sum += t;
        template_sq += t * t;
    }
    let energy = template_sq - template_sum * template_sum / f as f64;
    if energy <= 1e-12 {
        0.0
    } else {
        sum * sum / energy
    }
}

/// Best shift of one LED on a grid of `steps` per chip. Only the first half period is
/// searched: a half-period shift negates every MEB carrier (s[m + P/2] = −s[m], SPEC §2), which
/// leaves the squared correlation unchanged; [`finish`] picks the sign.
fn best_shift(
    wave: &ReceivedWaveform,
    timing: Timing,
    centred: &[f64],
    steps: usize,
) -> (f64, f64) {
    best_shift_in(
        wave,
        timing,
        centred,
        steps,
        0..(wave.period() / 2 * steps) as i64,
    )
}

/// Best shift `k / steps` for k in `grid` (the first on ties).
fn best_shift_in(
    wave: &ReceivedWaveform,
    timing: Timing,
    centred: &[f64],
    steps: usize,
    grid: std::ops::Range<i64>,
) -> (f64, f64) {
    let mut template = vec![0.0; centred.len()];
    grid.map(|k| {
        let shift = k as f64 / steps as f64;
        (
            shift,
            led_score(wave, timing, shift, centred, &mut template),
        )
    })
    .fold((0.0, f64::NEG_INFINITY), |best, cand| {
        if cand.1 > best.1 { cand } else { best }
    })
}

/// Sum over LEDs of each LED's best grid score, and the shifts: over the whole half period,
/// or within [`NEAR_CHIPS`] of `near[i]`.
fn grid_score(
    waves: &[ReceivedWaveform],
    timing: Timing,
    centred: &[f64],
    steps: usize,
    near: Option<&[f64]>,
) -> (f64, Vec<f64>) {
    let mut total = 0.0;
    let mut shifts = Vec::with_capacity(waves.len());
    for (i, wave) in waves.iter().enumerate() {
        let (shift, score) = match near.and_then(|n| n.get(i)) {
            Some(&centre) => {
                let k = (centre * steps as f64).round() as i64;
                let reach = (NEAR_CHIPS * steps as f64).ceil() as i64;
                best_shift_in(wave, timing, centred, steps, k - reach..k + reach + 1)
            }
            None => best_shift(wave, timing, centred, steps),
        };
        total += score;
        shifts.push(shift);
    }
    (total, shifts)
}

/// The candidate timing with the highest grid score (the first on ties), with its shifts;
/// candidates are scored in parallel.
fn best_timing(
    waves: &[ReceivedWaveform],
    candidates: &[(Timing, Option<Vec<f64>>)],
    centred: &[f64],
    steps: usize,
) -> Option<(Timing, Vec<f64>, f64)> {
    let scored: Vec<(f64, Vec<f64>)> = candidates
        .par_iter()
        .map(|(timing, near)| grid_score(waves, *timing, centred, steps, near.as_deref()))
        .collect();
    let mut best: Option<(usize, f64)> = None;
    for (index, (score, _)) in scored.iter().enumerate() {
        if best.is_none_or(|(_, b)| *score > b) {
            best = Some((index, *score));
        }
    }
    best.and_then(|(index, score)| {
        let (_, shifts) = scored.into_iter().nth(index)?;
        Some((candidates.get(index)?.0, shifts, score))
    })
}

/// Relative gain in explained variance a candidate must bring to be taken: below it, a move
/// only chases rounding (at full exposure with whole-chip shifts the exposure is unobservable
/// and its objective is flat, so ties go to the earlier candidate: the full exposure).
const MIN_GAIN: f64 = 1e-9;

/// Half-width, in chips, of the shift search at the shorter exposures of the coarse grid.
const NEAR_CHIPS: f64 = 1.0;

/// Fits timing and per-LED shifts of `leds` LEDs to the mean signal (one value per frame).
pub fn fit_waveforms(mean: &[f64], leds: usize, limits: &FitLimits) -> WaveformFit {
    let frames = mean.len();
    let waves: Vec<ReceivedWaveform> = (0..leds).map(ReceivedWaveform::new).collect();
    let average = mean.iter().sum::<f64>() / frames.max(1) as f64;
    let centred: Vec<f64> = mean.iter().map(|m| m - average).collect();
    let rate_step = 0.5 / frames.max(1) as f64;

    // Coarse rate ratio with full exposure.
    let mut rate = limits.rate_ratio.unwrap_or(1.0);
    let exposure = limits.exposure.unwrap_or(1.0);
    if limits.rate_ratio.is_none() {
        // Every other grid rate first (a drift of ≤ ½ chip over the window at the true rate
        // keeps its score well above the wrong rates'), then the two between around the best.
        let steps = ((limits.max_rate_mismatch / rate_step).ceil() as i64).min(400);
        let candidates = |ks: &mut dyn Iterator<Item = i64>| -> Vec<(Timing, Option<Vec<f64>>)> {
            ks.map(|k| {
                let timing = Timing {
                    rate_ratio: 1.0 + k as f64 * rate_step,
                    exposure,
                };
                (timing, None)
            })
            .collect()
        };
        let coarse = candidates(&mut (-steps..=steps).filter(|k| k % 2 == 0));
        if let Some((best, _, score)) = best_timing(&waves, &coarse, &centred, 2) {
            rate = best.rate_ratio;
            let k = ((rate - 1.0) / rate_step).round() as i64;
            let fine = candidates(&mut [k - 1, k + 1].into_iter().filter(|k| k.abs() <= steps));
            if let Some((candidate, _, fine_score)) = best_timing(&waves, &fine, &centred, 2)
                && fine_score > score * (1.0 + MIN_GAIN)
            {
                rate = candidate.rate_ratio;
            }
        }
    }
    // Coarse exposure.
    let mut timing = Timing {
        rate_ratio: rate,
        exposure,
    };
    let (best_score, mut shifts) = grid_score(&waves, timing, &centred, 4, None);
    if limits.exposure.is_none() {
        // A shorter exposure keeps the window centred where the full one was: Δ moves by
        // (e₀ − e)·ρ/2, so each LED is searched near that shift only.
        let candidates: Vec<(Timing, Option<Vec<f64>>)> = (1..10)
            .map(|k| {
                let candidate = Timing {
                    exposure: k as f64 * 0.1,
                    ..timing
                };
                let offset = (timing.exposure - candidate.exposure) * rate / 2.0;
                let near = shifts.iter().map(|s| s + offset).collect();
                (candidate, Some(near))
            })
            .collect();
        if let Some((candidate, candidate_shifts, score)) =
            best_timing(&waves, &candidates, &centred, 4)
            && score > best_score * (1.0 + MIN_GAIN)
        {
            shifts = candidate_shifts;
            timing = candidate;
        }
    }
    backfit(&waves, timing, &mut shifts, mean);
    // Joint refinement by coordinate search with shrinking steps.
    let mut work = Vec::new();
    let mut objective = explained_variance(&waves, timing, &shifts, mean, &mut work);
    let mut step_rate = if limits.rate_ratio.is_none() {
        rate_step
    } else {
        0.0
    };
    let mut step_exposure = if limits.exposure.is_none() { 0.05 } else { 0.0 };
    let mut step_shift = 0.125;
    for _ in 0..200 {
        let mut improved = false;
        for parameter in 0..leds + 2 {
            for sign in [-1.0, 1.0] {
                let mut candidate_timing = timing;
                let mut candidate_shifts = shifts.clone();
                match parameter {
                    0 if step_rate > 0.0 => {
                        candidate_timing.rate_ratio += sign * step_rate;
                        // Keep the phase at the middle frame: decouples ρ from the shifts.
                        let pivot = sign * step_rate * frames as f64 / 2.0;
                        candidate_shifts.iter_mut().for_each(|s| *s -= pivot);
                        if (candidate_timing.rate_ratio - 1.0).abs()
                            > limits.max_rate_mismatch + rate_step
                        {
                            continue;
                        }
                    }
                    1 if step_exposure > 0.0 => {
                        candidate_timing.exposure += sign * step_exposure;
                        if !(0.02..=1.0).contains(&candidate_timing.exposure) {
                            continue;
                        }
                    }
                    p if p >= 2 => candidate_shifts[p - 2] += sign * step_shift,
                    _ => continue,
                }
                let value = explained_variance(
                    &waves,
                    candidate_timing,
                    &candidate_shifts,
                    mean,
                    &mut work,
                );
                if value > objective * (1.0 + MIN_GAIN) {
                    objective = value;
                    timing = candidate_timing;
                    shifts = candidate_shifts;
                    improved = true;
                }
            }
        }
        if !improved {
            step_rate *= 0.5;
            step_exposure *= 0.5;
            step_shift *= 0.5;
            if step_shift < 1e-4 {
                break;
            }
        }
    }
    finish(&waves, timing, shifts, mean)
}

/// Re-searches each LED's shift on the grid against the signal minus the other LEDs' fitted
/// contributions (undoes the small cross-talk of the independent coarse search when ρ ≠ 1).
fn backfit(waves: &[ReceivedWaveform], timing: Timing, shifts: &mut [f64], mean: &[f64]) {
    for _ in 0..2 {
        for led in 0..waves.len() {
            let (_, coefficients) = explained(waves, timing, shifts, mean);
            let residual: Vec<f64> = (0..mean.len())
                .map(|j| {
                    mean[j]
                        - waves
                            .iter()
                            .enumerate()
                            .filter(|(k, _)| *k != led)
                            .map(|(k, wave)| {
                                coefficients[k + 1] * timing.template(wave, shifts[k], j)
                            })
                            .sum::<f64>()
                })
                .collect();
            let average = residual.iter().sum::<f64>() / residual.len().max(1) as f64;
            let centred: Vec<f64> = residual.iter().map(|r| r - average).collect();
            shifts[led] = best_shift(&waves[led], timing, &centred, 8).0;
        }
    }
}

/// Refits only the shifts (e.g. per row band of a rolling shutter), starting from `start`.
pub fn refit_shifts(mean: &[f64], timing: Timing, start: &[f64]) -> WaveformFit {
    let waves: Vec<ReceivedWaveform> = (0..start.len()).map(ReceivedWaveform::new).collect();
    let mut shifts = start.to_vec();
    let mut work = Vec::new();
    let mut objective = explained_variance(&waves, timing, &shifts, mean, &mut work);
    let mut step = 0.25;
    while step >= 1e-4 {
        let mut improved = false;
        for led in 0..shifts.len() {
            for sign in [-1.0, 1.0] {
                let mut candidate = shifts.clone();
                candidate[led] += sign * step;
                let value = explained_variance(&waves, timing, &candidate, mean, &mut work);
                if value > objective * (1.0 + MIN_GAIN) {
                    objective = value;
                    shifts = candidate;
                    improved = true;
                }
            }
        }
        if !improved {
            step *= 0.5;
        }
    }
    finish(&waves, timing, shifts, mean)
}

/// Chooses each carrier's sign (a half-period shift negates it) so that the amplitudes are
/// positive, wraps shifts into one period and computes the residual.
fn finish(
    waves: &[ReceivedWaveform],
    timing: Timing,
    mut shifts: Vec<f64>,
    mean: &[f64],
) -> WaveformFit {
    let (_, coefficients) = explained(waves, timing, &shifts, mean);
    for ((shift, wave), c) in shifts.iter_mut().zip(waves).zip(&coefficients[1..]) {
        let period = wave.period() as f64;
        if *c < 0.0 {
            *shift += period / 2.0;
        }
        *shift = shift.rem_euclid(period);
    }
    let columns = template_columns(waves, timing, &shifts, mean.len());
    let (_, coefficients) = explained(waves, timing, &shifts, mean);
    let residual: f64 = (0..mean.len())
        .map(|j| {
            let model: f64 = columns
                .iter()
                .zip(&coefficients)
                .map(|(c, k)| c[j] * k)
                .sum();
            (mean[j] - model).powi(2)
        })
        .sum();
    WaveformFit {
        timing,
        shifts,
        amplitudes: coefficients[1..].to_vec(),
        residual_rms: (residual / mean.len().max(1) as f64).sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn synth(amps: &[f64], shifts: &[f64], timing: Timing, frames: usize) -> Vec<f64> {
        let waves: Vec<ReceivedWaveform> = (0..amps.len()).map(ReceivedWaveform::new).collect();
        (0..frames)
            .map(|j| {
                0.3 + (0..amps.len())
                    .map(|i| amps[i] * timing.template(&waves[i], shifts[i], j))
                    .sum::<f64>()
            })
            .collect()
    }

    #[test]
    fn recovers_amplitudes_rate_and_exposure() {
        let timing = Timing {
            rate_ratio: 1.03,
            exposure: 0.6,
        };
        let amps = [0.2, 0.15, 0.1, 0.12];
        let shifts = [1.3, 5.7, 9.2, 20.45];
        let mean = synth(&amps, &shifts, timing, 64);
        let fit = fit_waveforms(&mean, 4, &FitLimits::default());
        assert!((fit.timing.rate_ratio - 1.03).abs() < 1e-3, "{fit:?}");
        for (a, b) in fit.amplitudes.iter().zip(&amps) {
            assert!((a - b).abs() < 2e-3 * b.max(0.1), "{fit:?}");
        }
        assert!(fit.residual_rms < 1e-4, "{fit:?}");
    }
}
