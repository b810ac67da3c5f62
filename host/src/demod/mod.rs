//! MEB-FDMA demodulation: a captured video → one image per LED (SPEC §3–§4).
//!
//! [`decode`] reads frames in windows (native 8/16-bit, bounded memory), fits every LED's
//! received waveform — shift, exposure and camera/chip rate ratio — once per window from the
//! spatial mean ([`fit`]), then estimates each pixel's on-level A_i by least squares against
//! those waveforms ([`Estimator::Waveform`], a matched filter: unbiased because it models the
//! integration window instead of taking a maximum, and less noisy because it projects on one
//! waveform per LED instead of its whole 2^(i+1)-dimensional subspace). The thesis decoder
//! ([`thesis`], Eqs. 3.25–3.30) is kept as [`Estimator::Thesis`]. Windows are averaged.
//!
//! Per-pixel noise: the residual of the least-squares fit, i.e. the energy in every DFT bin no
//! LED uses (bin 2^N and the bins beyond one carrier frame), as σ per frame sample. The thesis
//! estimator reports the power of bin 2^N instead.

mod basis;
pub mod config;
mod error;
pub mod fit;
mod matched;
pub mod output;
mod report;
mod stats;
#[cfg(test)]
mod synthetic;
#[cfg(test)]
mod tests;
pub mod thesis;
pub mod waveform;
mod window;

pub use config::{DecodeConfig, Estimator, LedCount, Linearize, Roi};
pub use error::DemodError;
pub use report::{DecodeReport, LedReport};

use crate::capture::{FrameFormat, FrameSource, Samples};
use crate::types::LedImages;
use basis::TemplateBasis;
use fit::{FitLimits, WaveformFit, fit_waveforms, refit_shifts, template_columns};
use matched::{CodeLimits, WindowAmplitudes};
use ndarray::Array2;
use rayon::prelude::*;
use stats::PixelStats;
use waveform::ReceivedWaveform;
use window::{CodeMap, Region, read_window};

/// Largest LED count.
pub const MAX_LEDS: usize = 8;
/// Largest LED count `LedCount::Auto` looks for.
const AUTO_MAX_LEDS: usize = 6;
/// Largest decoding window, frames (bounds the cost of the waveform fit).
const MAX_WINDOW_FRAMES: usize = 256;
/// Largest number of pixels the reported median noise is computed from.
const MEDIAN_SAMPLE: usize = 1 << 16;
/// An LED is modulated when its scene-mean on-level exceeds this fraction of the strongest.
const SIGNIFICANT_FRACTION: f64 = 0.03;
/// … and this fraction of full scale.
const SIGNIFICANT_LEVEL: f64 = 1e-3;

/// The result of a decode.
#[derive(Debug, Clone)]
pub struct Decoded {
    /// A_i per LED as a fraction of the input's full scale (SPEC §3).
    pub leds: LedImages,
    /// Per-pixel noise σ of one frame sample, fraction of full scale.
    pub noise: Array2<f32>,
    /// Pixels that reached the white level in some frame.
    pub saturated: Array2<bool>,
    /// Pixels whose brightest frame stays below `underexposed_below`.
    pub underexposed: Array2<bool>,
    /// What the decoder measured.
    pub report: DecodeReport,
}

/// Decodes the frames of `source` into one image per LED; `progress(done, total)` is called
/// after every frame read (total is a best guess when the source does not know its length).
pub fn decode(
    source: &mut dyn FrameSource,
    config: &DecodeConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Decoded, DemodError> {
    let mut format = source.format().clone();
    if let Some(fps) = config.fps {
        if !(fps.is_finite() && fps > 0.0) {
            return Err(DemodError::InvalidConfig(format!(
                "fps {fps} is not positive"
            )));
        }
        format.fps = fps;
    }
    let region = validate(config, &format)?;
    let map = CodeMap::new(&format, config.linearize)?;
    let code_limits = CodeLimits::new(&format, config.underexposed_below);
    for _ in 0..config.start {
        if source.next_frame()?.is_none() {
            return Err(DemodError::TooFewFrames {
                got: 0,
                need: 1,
                leds: requested_leds(config),
            });
        }
    }
    let hint = source
        .frame_count_hint()
        .map(|n| n.saturating_sub(config.start));
    let total = match (config.frames, hint) {
        (Some(f), Some(h)) => Some(f.min(h)),
        (Some(f), None) => Some(f),
        (None, h) => h,
    };
    let sample_bytes = if format.bit_depth > 8 { 2 } else { 1 };
    let frame_bytes = (region.roi.width * region.roi.height * sample_bytes).max(1);
    let budget_frames = (config.window_bytes / frame_bytes).clamp(1, MAX_WINDOW_FRAMES);
    let min_chips = match config.leds {
        LedCount::Fixed(n) => 1usize << (n + 1),
        LedCount::Auto => 4,
    };
    let mut window_len = budget_frames.max(min_chips);
    if let Some(t) = total {
        window_len = window_len.min(t.max(1));
    }
    if let LedCount::Fixed(_) = config.leds
        && window_len > min_chips
    {
        window_len -= window_len % min_chips;
    }
    let progress_total = config.frames.or(hint).unwrap_or(window_len);

    let mut state = Accumulated::default();
    let mut read = 0usize;
    loop {
        let want = match total {
            Some(t) => window_len.min(t - read.min(t)),
            None => window_len,
        };
        if want == 0 {
            break;
        }
        let window = read_window(source, &format, region, &map, want, || {
            read += 1;
            progress(read, progress_total.max(read));
        })?;
        let got = window.frames.len();
        let leds = match state.leds {
            Some(n) => n,
            None => {
                let (n, probe) = choose_led_count(config, &window.mean)?;
                state.leds = Some(n);
                state.detected = probe.as_ref().map(|(d, _)| *d);
                state.probe_fit = probe.map(|(_, fit)| fit);
                n
            }
        };
        let chips = 1usize << (leds + 1);
        if got < chips {
            if state.windows == 0 {
                return Err(DemodError::TooFewFrames {
                    got,
                    need: chips,
                    leds,
                });
            }
            break;
        }
        decode_window(config, region, &map, code_limits, leds, &window, &mut state);
        if got < want {
            break;
        }
    }
    finish(config, &format, region, state)
}

/// LED count named by the config (for errors before detection).
fn requested_leds(config: &DecodeConfig) -> usize {
    match config.leds {
        LedCount::Fixed(n) => n,
        LedCount::Auto => 1,
    }
}

/// Checks the settings against the stream and returns the decoded region.
fn validate(config: &DecodeConfig, format: &FrameFormat) -> Result<Region, DemodError> {
    if let LedCount::Fixed(n) = config.leds
        && !(1..=MAX_LEDS).contains(&n)
    {
        return Err(DemodError::InvalidConfig(format!(
            "LED count {n} is outside 1..={MAX_LEDS}"
        )));
    }
    if let Some(r) = config.rate_ratio
        && !(r.is_finite() && r > 0.0)
    {
        return Err(DemodError::InvalidConfig(format!(
            "rate ratio {r} is not positive"
        )));
    }
    if let Some(e) = config.exposure
        && !(e.is_finite() && e > 0.0 && e <= 1.0)
    {
        return Err(DemodError::InvalidConfig(format!(
            "exposure {e} is outside (0, 1]"
        )));
    }
    if !(config.max_rate_mismatch.is_finite() && (0.0..0.5).contains(&config.max_rate_mismatch)) {
        return Err(DemodError::InvalidConfig(
            "max rate mismatch must be in [0, 0.5)".into(),
        ));
    }
    if !config.underexposed_below.is_finite() {
        return Err(DemodError::InvalidConfig(
            "under-exposure threshold is NaN".into(),
        ));
    }
    let roi = config.roi.unwrap_or(Roi {
        x: 0,
        y: 0,
        width: format.width,
        height: format.height,
    });
    if roi.width == 0
        || roi.height == 0
        || roi.x + roi.width > format.width
        || roi.y + roi.height > format.height
    {
        return Err(DemodError::InvalidConfig(format!(
            "region {}x{}+{}+{} is empty or outside the {}x{} frame",
            roi.width, roi.height, roi.x, roi.y, format.width, format.height
        )));
    }
    if config.row_bands == 0 || config.row_bands > roi.height {
        return Err(DemodError::InvalidConfig(format!(
            "row bands {} must be in 1..={}",
            config.row_bands, roi.height
        )));
    }
    Ok(Region {
        roi,
        bands: config.row_bands,
    })
}

/// Fit limits from the config.
fn limits(config: &DecodeConfig) -> FitLimits {
    FitLimits {
        max_rate_mismatch: config.max_rate_mismatch,
        rate_ratio: config.rate_ratio,
        exposure: config.exposure,
    }
}

/// Number of LEDs to decode, and (detected count, probe fit) when the video could be checked.
fn choose_led_count(
    config: &DecodeConfig,
    mean: &[f64],
) -> Result<(usize, Option<(usize, WaveformFit)>), DemodError> {
    let frames = mean.len();
    let fits = |m: usize| (1usize << (m + 1)) <= frames;
    let probe = match config.leds {
        LedCount::Fixed(n) if !config.check_led_count || !fits(n) => return Ok((n, None)),
        LedCount::Fixed(n) if n < MAX_LEDS && fits(n + 1) => n + 1,
        LedCount::Fixed(n) => n,
        LedCount::Auto => match (1..=AUTO_MAX_LEDS).rev().find(|&m| fits(m)) {
            Some(m) => m,
            None => {
                return Err(DemodError::TooFewFrames {
                    got: frames,
                    need: 4,
                    leds: 1,
                });
            }
        },
    };
    let fit = fit_waveforms(mean, probe, &limits(config));
    let strongest = fit.amplitudes.iter().cloned().fold(0.0, f64::max);
    if strongest < SIGNIFICANT_LEVEL {
        return Err(DemodError::NoModulation);
    }
    let significant = |a: f64| a > SIGNIFICANT_FRACTION * strongest && a > SIGNIFICANT_LEVEL;
    let detected = fit
        .amplitudes
        .iter()
        .rposition(|&a| significant(a))
        .map_or(0, |i| i + 1);
    match config.leds {
        LedCount::Auto => Ok((detected, Some((detected, fit)))),
        LedCount::Fixed(n) => {
            let all_present = fit.amplitudes[..n].iter().all(|&a| significant(a));
            if detected != n || !all_present {
                let detected = if all_present {
                    detected
                } else {
                    detected.min(n - 1)
                };
                return Err(DemodError::LedCountMismatch {
                    requested: n,
                    detected,
                });
            }
            Ok((n, Some((detected, fit))))
        }
    }
}

/// Running sums over windows.
#[derive(Default)]
struct Accumulated {
    leds: Option<usize>,
    detected: Option<usize>,
    probe_fit: Option<WaveformFit>,
    windows: usize,
    frames: usize,
    /// Frame-weighted mean over the windows so far of each LED's A_i.
    mean_leds: Vec<Vec<f32>>,
    /// Frame-weighted mean of the per-frame noise variance.
    mean_variance: Vec<f32>,
    /// Saturated in some window.
    saturated: Vec<bool>,
    /// Under-exposed in every window.
    underexposed: Vec<bool>,
    /// The first window's report statistics, when the kernel gathered them.
    stats: Option<PixelStats>,
    fits: Vec<WaveformFit>,
    variance_factors: Vec<f64>,
}

/// Fits and decodes one window and adds it to the running sums.
fn decode_window(
    config: &DecodeConfig,
    region: Region,
    map: &CodeMap,
    code_limits: CodeLimits,
    leds: usize,
    window: &window::Window,
    state: &mut Accumulated,
) {
    let frames = window.frames.len();
    let limits = limits(config);
    // The first window reuses the count probe's fit when it covered exactly these LEDs' timing.
    let global = match state.probe_fit.take() {
        Some(probe) if state.windows == 0 && probe.amplitudes.len() >= leds => {
            refit_shifts(&window.mean, probe.timing, &probe.shifts[..leds])
        }
        _ => fit_waveforms(&window.mean, leds, &limits),
    };
    let waves: Vec<ReceivedWaveform> = (0..leds).map(ReceivedWaveform::new).collect();
    let bases: Vec<TemplateBasis> = (0..region.bands)
        .map(|band| {
            let shifts = if region.bands > 1 {
                refit_shifts(&window.band_means[band], global.timing, &global.shifts).shifts
            } else {
                global.shifts.clone()
            };
            TemplateBasis::new(&template_columns(&waves, global.timing, &shifts, frames))
        })
        .collect();
    let amplitudes: WindowAmplitudes = match config.estimator {
        Estimator::Waveform => {
            matched::matched_filter(&window.frames, region, &bases, map, code_limits)
        }
        Estimator::Thesis => {
            let chips = 1usize << (leds + 1);
            let used = frames - frames % chips;
            thesis::thesis_window(&window.frames[..used], region, leds, map, code_limits)
        }
    };
    if state.windows == 0 {
        state.variance_factors = (0..leds).map(|i| bases[0].variance_factor(i + 1)).collect();
        state.mean_leds = amplitudes.leds;
        state.mean_variance = amplitudes.noise_variance;
        state.saturated = amplitudes.saturated;
        state.underexposed = amplitudes.underexposed;
        state.stats = amplitudes.stats;
    } else {
        // Running frame-weighted means: m += (x − m)·F / (F_total + F).
        let step = (frames as f64 / (state.frames + frames) as f64) as f32;
        let update = |mean: &mut Vec<f32>, window: &[f32]| {
            mean.par_iter_mut()
                .zip(window)
                .for_each(|(m, &x)| *m += (x - *m) * step);
        };
        for (mean, image) in state.mean_leds.iter_mut().zip(&amplitudes.leds) {
            update(mean, image);
        }
        update(&mut state.mean_variance, &amplitudes.noise_variance);
        state
            .saturated
            .par_iter_mut()
            .zip(&amplitudes.saturated)
            .for_each(|(s, &w)| *s |= w);
        state
            .underexposed
            .par_iter_mut()
            .zip(&amplitudes.underexposed)
            .for_each(|(u, &w)| *u &= w);
    }
    state.windows += 1;
    state.frames += frames;
    state.fits.push(global);
}

/// Turns the running sums into images, masks and the report.
fn finish(
    config: &DecodeConfig,
    format: &FrameFormat,
    region: Region,
    state: Accumulated,
) -> Result<Decoded, DemodError> {
    let (height, width) = (region.roi.height, region.roi.width);
    let leds = state.leds.unwrap_or(0);
    if state.windows == 0 {
        return Err(DemodError::TooFewFrames {
            got: 0,
            need: 1usize << (leds.max(1) + 1),
            leds: leds.max(1),
        });
    }
    let (saturated, underexposed) = (state.saturated, state.underexposed);
    let stats = match state.stats {
        Some(stats) if state.windows == 1 => stats,
        _ => PixelStats::gather(
            &state.mean_leds,
            &state.mean_variance,
            &saturated,
            &underexposed,
        ),
    };
    let mut noise_values = state.mean_variance;
    noise_values
        .par_iter_mut()
        .for_each(|v| *v = v.max(0.0).sqrt());
    let valid = |p: usize| !saturated[p] && !underexposed[p];
    if stats.valid_pixels == 0 {
        return Err(DemodError::NothingToDecode(
            if stats.saturated_pixels >= stats.underexposed_pixels {
                "saturated"
            } else {
                "under-exposed"
            },
        ));
    }
    let valid_count = stats.valid_pixels as f64;
    let noise_power = stats.noise_power / valid_count;
    let median_noise = median_of_valid(&noise_values, valid);
    let per_led = (0..leds)
        .map(|i| {
            let mean_level = stats.level_sums[i] / valid_count;
            let amplitude_noise =
                (noise_power * state.variance_factors[i]).sqrt() / (state.windows as f64).sqrt();
            LedReport {
                led: i + 1,
                phase_chips: state.fits[0].shifts[i],
                mean_level,
                snr_db: 20.0 * (mean_level.abs().max(1e-12) / amplitude_noise.max(1e-12)).log10(),
            }
        })
        .collect();
    let shape_error = |e: ndarray::ShapeError| DemodError::InvalidConfig(e.to_string());
    let images = state
        .mean_leds
        .into_iter()
        .map(|values| Array2::from_shape_vec((height, width), values).map_err(shape_error))
        .collect::<Result<Vec<_>, _>>()?;
    let noise = Array2::from_shape_vec((height, width), noise_values).map_err(shape_error)?;
    let saturated = Array2::from_shape_vec((height, width), saturated).map_err(shape_error)?;
    let underexposed =
        Array2::from_shape_vec((height, width), underexposed).map_err(shape_error)?;
    let n_fits = state.fits.len() as f64;
    let rate_ratio = state.fits.iter().map(|f| f.timing.rate_ratio).sum::<f64>() / n_fits;
    let report = DecodeReport {
        estimator: config.estimator,
        leds,
        detected_leds: state.detected,
        frames_used: state.frames,
        windows: state.windows,
        width,
        height,
        rate_ratio,
        fps: format.fps,
        chip_rate_hz: rate_ratio * format.fps,
        exposure: state.fits.iter().map(|f| f.timing.exposure).sum::<f64>() / n_fits,
        fit_residual: state.fits.iter().map(|f| f.residual_rms).sum::<f64>() / n_fits,
        median_noise,
        saturated_pixels: stats.saturated_pixels,
        underexposed_pixels: stats.underexposed_pixels,
        per_led,
    };
    Ok(Decoded {
        leds: LedImages { images },
        noise,
        saturated,
        underexposed,
        report,
    })
}

/// Median of the valid pixels' values: exact up to [`MEDIAN_SAMPLE`] pixels, else the median
/// of the valid ones among an evenly strided sample of that many (a report statistic,
/// accurate to well under 1 % and independent of the image size).
fn median_of_valid(values: &[f32], valid: impl Fn(usize) -> bool) -> f64 {
    let stride = values.len().div_ceil(MEDIAN_SAMPLE).max(1);
    let mut sample: Vec<f32> = (0..values.len())
        .step_by(stride)
        .filter(|&p| valid(p))
        .map(|p| values[p])
        .collect();
    if sample.is_empty() {
        // Few valid pixels, none on the stride: take them all.
        sample = (0..values.len())
            .filter(|&p| valid(p))
            .map(|p| values[p])
            .collect();
    }
    crate::stats::quantile_in_place(&mut sample, 0.5).map_or(f64::NAN, f64::from)
}

/// Bytes of a frame's samples (for memory budgeting by callers).
pub fn frame_bytes(samples: &Samples) -> usize {
    match samples {
        Samples::U8(v) => v.len(),
        Samples::U16(v) => 2 * v.len(),
    }
}
