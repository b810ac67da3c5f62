//! MEB-FDMA demodulation: a captured video → one image per LED
//! (docs/maths/demodulation.md#demodulation).
//!
//! Every pixel p of a window of F frames reads (docs/maths/demodulation.md#the-received-signal)
//!
//! ```text
//! r_j(p) = B(p) + Σ_i A_i(p)·u_i(j) + noise,   u_i(j) = ½ + ½·g_i(j·ρ + Δ_i),
//! ```
//!
//! u_i LED i's on-fraction in frame j: its carrier s_i (period 2^(i+2) chips inside the
//! n = 2^(N+1)-chip table) box-averaged over the exposure e·ρ chips (g_i, [`waveform`]),
//! shifted by Δ_i = k_i + α_i chips and sampled at ρ chips per frame; a rolling shutter adds
//! λ·r frame periods to row r's start. The timing (ρ, e, Δ_i, λ) is the same for every pixel,
//! so it is estimated once per window from the pixels that carry modulation, and each pixel's
//! A_i is then a linear least-squares fit against the N received waveforms (a matched
//! filter, [`Estimator::Waveform`]): unbiased, because it models the integration instead of
//! taking a maximum, and far less noisy than the thesis' subspace maximum, which is kept as
//! [`Estimator::Thesis`] (Eqs. 3.25–3.30, [`thesis`]).
//!
//! The timing estimate is global, not a local search on the frame mean:
//!
//! 1. \[`sample`\]: the window's most modulated pixels (strided candidates ranked by temporal
//!    variance), so a small object in a wide, dark view drives the estimate rather than the
//!    unlit background. X is that sample, centred (pixels × F).
//! 2. \[`spectrum`\]: the leading eigenvectors V of G = XᵀX span every LED's waveform, because
//!    X = A·Tᵀ + noise with T = [u_0 … u_{N−1}] (F × N); per LED this is the rank-1 structure
//!    of docs/maths/demodulation.md#the-subspace-projection: the projection of the window onto LED
//!    i's subspace is, across pixels,
//!    A_i(p)·(projected u_i)ᵀ. The eigenvalues beyond the signal give the noise energy σ²_G.
//!    Randomised subspace iteration keeps it cheap.
//! 3. \[`seed`\]: each LED's waveform is found in V on its own — the fraction |Vᵀt|²/|t|² of a
//!    candidate template t that V holds is 1 for the true (ρ, e, Δ_i) and does not depend on
//!    the A_i, so neither other LEDs nor a dark background bias it, and the scale and sign
//!    ambiguity of singular vectors never arises (templates are scored, not read off V).
//!    ρ comes from a one-dimensional scan, e from a scan at that ρ with Δ_i refined per LED
//!    on a grid of shifts ([`SeedMethod::Grid`], the default). [`SeedMethod::RankOne`]
//!    instead reads each LED's template off the window as the leading eigenvector of its
//!    block of the signal space's coordinates in the LEDs' chip templates (\[`template`\]),
//!    which gives Δ_i in closed form — exact at ρ = 1, a seed the refinement must correct
//!    away from it.
//! 4. [`fit`]: those seeds start a least-squares refinement of (ρ, e, Δ_i) on the sample
//!    (variable projection), which pins the templates' amplitude — and with it each LED's
//!    gain — to the physics of the integration; a rolling shutter is detected when row bands
//!    disagree and fitted as a per-row phase ramp (λ, or given). The per-pixel filter then uses
//!    one basis per row band narrow enough that the ramp moves the phase < 0.004 chip inside.
//! 5. [`quality`]: the energy each LED's template explains against what noise alone would
//!    give, the energy left unexplained in its subspace, and the uncertainty the timing's noise
//!    puts on its gain; an implausible decode is refused (or kept with the verdict recorded,
//!    [`OnImplausible`]).
//!
//! The LED-count check fits one LED more than requested (or the most the window allows, for
//! [`LedCount::Auto`]) and counts the LEDs with signal above noise. Long captures are decoded
//! in windows of bounded memory (\[`window`\]), each with its own timing fit, and averaged.
//! [`WindowDecoder`] is that per-window core: template estimate + matched filter on a window of
//! frames, returning per-LED images, noise and fit quality.
//!
//! Per-pixel noise: the residual of the per-pixel least-squares fit, as σ per frame sample.
//! The thesis estimator reports the power of DFT bin 2^N instead.

mod basis;
pub mod clipping;
pub mod compression;
pub mod config;
pub mod depth;
mod error;
pub mod fit;
#[cfg(test)]
pub(crate) mod fixture;
mod levenberg;
mod matched;
pub mod nuisance;
pub mod output;
pub mod quality;
mod report;
mod sample;
mod seed;
mod spectrum;
mod stats;
#[cfg(test)]
pub(crate) mod synthetic;
mod template;
#[cfg(test)]
mod tests;
pub mod thesis;
pub mod timing_break;
pub mod waveform;
mod window;

pub use config::{DecodeConfig, Estimator, LedCount, Linearize, OnImplausible, Roi, SeedMethod};
pub use depth::{ModulationDepths, ModulationReport};
pub use error::DemodError;
pub use matched::WindowAmplitudes;
pub use quality::{FitQuality, LedQuality, Verdict, VerdictStatus};
pub use report::{DecodeReport, LedReport};
pub use window::CodeMap;

use config::FitLimits;
use fit::{TimingFit, fit_timing, refit_timing};
pub(crate) use matched::CodeLimits;
use meb_core::capture::clock::TimestampGap;
use meb_core::capture::{FrameFormat, FrameSource, Samples};
use meb_core::types::LedImages;
use nalgebra::DMatrix;
use ndarray::Array2;
use rayon::prelude::*;
use sample::{PixelSample, RowGrid};
use spectrum::{SignalSpace, Spectrum};
use stats::PixelStats;
use waveform::ReceivedWaveform;
use window::{Region, read_window};

/// Largest LED count.
pub const MAX_LEDS: usize = 8;
/// Largest LED count `LedCount::Auto` looks for.
const AUTO_MAX_LEDS: usize = 6;
/// Largest decoding window, frames (bounds the cost of the timing fit).
const MAX_WINDOW_FRAMES: usize = 256;
/// Largest number of pixels the reported median noise is computed from.
const MEDIAN_SAMPLE: usize = 1 << 16;
/// Fewer LEDs than requested are put down to clipping, not to their absence, when the clipped
/// candidate pixels number at least this share of the sample's pixels: enough to hold a
/// face of their own. The 75 mm cube corner-on (thesis-out-of-plane rig, default gain): the
/// top face, the only one LEDs 1 and 2 reach, clips whenever three LEDs are on, and the
/// unclipped pixels show LEDs 3 and 4 alone; a specular highlight is a few pixels.
const HIDING_CLIPPED_SHARE: f64 = 0.1;
/// An LED counts as present when its mean on-level exceeds this fraction of the strongest's.
const SIGNIFICANT_FRACTION: f64 = 0.03;
/// Largest phase change, chips, of the rolling-shutter ramp inside one row band.
const BAND_PHASE_STEP: f64 = 0.004;

/// The result of a decode.
#[derive(Debug, Clone)]
pub struct Decoded {
    /// A_i per LED as a fraction of the input's full scale
    /// (docs/maths/demodulation.md#the-received-signal).
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
    let format = stream_format(source.format(), config)?;
    let decoder = WindowDecoder::new(&format, config)?;
    skip_start(source, config.start)?;
    if config.start > 0 && source.frame_count_hint() == Some(0) {
        // The start skipped exactly every frame.
        return Err(DemodError::StartBeyondEnd {
            start: config.start,
            available: config.start,
        });
    }
    let plan = WindowPlan::new(config, &format, decoder.roi, source.frame_count_hint());
    // The container's gaps, counted from the first frame decoded.
    let gaps: Vec<TimestampGap> = source
        .timestamp_gaps()
        .into_iter()
        .filter(|g| g.frame > config.start)
        .map(|g| TimestampGap {
            frame: g.frame - config.start,
            ..g
        })
        .collect();
    let mut state = Accumulated::default();
    let mut read = 0usize;
    loop {
        let want = plan.next_window(read);
        if want == 0 {
            break;
        }
        let window = read_window(source, &format, decoder.roi, want, || {
            read += 1;
            progress(read, plan.progress_total.max(read));
        })?;
        let got = window.frames.len();
        let added = add_window(&decoder, &window.frames, config, &mut state);
        let added = match (added, source.lossy_compression()) {
            (Err(e), _) if gaps.iter().any(|g| g.frame < read) => {
                Err(timing_break::explain_gaps(e, &gaps))
            }
            (Err(e), Some(compression)) => Err(compression::explain(e, &compression)),
            (Err(e), None) if format.fps <= 0.0 => Err(without_frame_rate(e)),
            (added, _) => added,
        };
        if !added? || got < want {
            break;
        }
    }
    let gaps: Vec<TimestampGap> = gaps.into_iter().filter(|g| g.frame < read).collect();
    let explain = |e: DemodError| {
        if gaps.is_empty() {
            e
        } else {
            timing_break::explain_gaps(e, &gaps)
        }
    };
    let mut decoded = finish(config, &format, decoder.roi, state).map_err(explain)?;
    decoded.report.room.container_gaps = gaps.clone();
    // The compression is judged on the swing the video carries, before the depths scale it.
    if let Some(compression) = source.lossy_compression() {
        compression::check(&mut decoded.report, &format, &compression);
    }
    apply_verdict(
        to_full_depth(decoded, &config.depths)?,
        config.on_implausible,
    )
    .map_err(explain)
}

/// The error an LED count mismatch of a capture without a frame rate is reported as: without
/// the rate, room-light flicker is looked for only as one periodic component of unknown
/// frequency in frames, so flicker that escaped that search shows as an extra component, and
/// the frame rate is what to give first.
fn without_frame_rate(error: DemodError) -> DemodError {
    match error {
        DemodError::LedCountMismatch {
            requested,
            detected,
        } if detected > requested => DemodError::Implausible {
            problems: format!(
                "{requested} LEDs requested and the video shows {detected} modulated \
                 components; its frame rate is unknown (image files carry none), so flicker of \
                 room lights on the mains, the usual cause, could be looked for only by its \
                 frequency in frames"
            ),
            advice: format!(
                "give the camera's frame rate (--fps, or fps= in Python) so mains flicker is \
                 found and projected out; decode {detected} LEDs only if the luminaire really \
                 plays that many"
            ),
        },
        other => other,
    }
}

/// Decodes `frames` already in memory (each of `format`'s size) as one window with `config`,
/// as [`decode`] decodes a source of those frames in one window; the frame range settings
/// (`start`, `frames`) are ignored. The frames are read where they lie (copied only when
/// `config.roi` cuts them): `meb video` decodes each window of its stream this way. More
/// frames than one window holds (256) are copied into a source and cut into windows by
/// [`decode`].
pub fn decode_frames(
    frames: &[Samples],
    format: &FrameFormat,
    config: &DecodeConfig,
) -> Result<Decoded, DemodError> {
    if frames.len() > MAX_WINDOW_FRAMES {
        // More than one window holds: cut into windows as `decode` cuts a source of them.
        let owned = frames
            .iter()
            .enumerate()
            .map(|(index, samples)| meb_core::capture::Frame {
                index,
                samples: samples.clone(),
            })
            .collect();
        let mut source = meb_core::capture::memory::MemorySource::new(format.clone(), owned)?;
        let config = DecodeConfig {
            start: 0,
            frames: None,
            window_bytes: usize::MAX,
            ..config.clone()
        };
        return decode(&mut source, &config, &mut |_, _| {});
    }
    let format = stream_format(format, config)?;
    let decoder = WindowDecoder::new(&format, config)?;
    if let Some((index, frame)) = frames
        .iter()
        .enumerate()
        .find(|(_, f)| f.len() != format.pixels())
    {
        return Err(meb_core::capture::CaptureError::Other(format!(
            "frame {index} has {} samples, expected {}x{}",
            frame.len(),
            format.width,
            format.height
        ))
        .into());
    }
    let cropped: std::borrow::Cow<'_, [Samples]> = if decoder.roi.x == 0
        && decoder.roi.y == 0
        && (decoder.roi.width, decoder.roi.height) == (format.width, format.height)
    {
        std::borrow::Cow::Borrowed(frames)
    } else {
        std::borrow::Cow::Owned(
            frames
                .par_iter()
                .map(|f| window::cut(f, format.width, decoder.roi))
                .collect(),
        )
    };
    let mut state = Accumulated::default();
    let config = DecodeConfig {
        start: 0,
        ..config.clone()
    };
    add_window(&decoder, &cropped, &config, &mut state)?;
    let decoded = finish(&config, &format, decoder.roi, state)?;
    apply_verdict(
        to_full_depth(decoded, &config.depths)?,
        config.on_implausible,
    )
}

/// `decoded` with each LED image (and its mean level) divided by 1 − ℓ_i, LED i's off chips'
/// share of its on light, as `depths` gives them ([`depth`]); the scales in its report.
fn to_full_depth(mut decoded: Decoded, depths: &ModulationDepths) -> Result<Decoded, DemodError> {
    let report = &mut decoded.report;
    let modulation = depth::resolve(depths, report.leds, report.chip_rate_hz)?;
    for (i, image) in decoded.leds.images.iter_mut().enumerate() {
        let scale = modulation.scale(i);
        if scale != 1.0 {
            image.mapv_inplace(|v| v * scale as f32);
        }
        if let Some(led) = report.per_led.get_mut(i) {
            led.mean_level *= scale;
        }
    }
    report.modulation = modulation;
    Ok(decoded)
}

/// Adds one window of `frames` (cropped to the decoder's region) to `state`: `Ok(false)` when
/// it holds too few frames for one carrier period after an earlier window (the stream's end),
/// an error when it is the first. A window refused because the camera dropped or repeated a
/// frame in it ([`timing_break`]) is re-aligned: decoded without the repeated frame, or as the
/// pieces either side of the dropped one that hold a carrier period each.
fn add_window(
    decoder: &WindowDecoder,
    frames: &[Samples],
    config: &DecodeConfig,
    state: &mut Accumulated,
) -> Result<bool, DemodError> {
    let prepared = prepare_window(decoder, frames, config, state);
    let refused = match &prepared {
        Ok(Prepared::Window { decoded, .. }) => !decoded.verdict.is_plausible(),
        Err(DemodError::LedCountMismatch { .. } | DemodError::Implausible { .. }) => true,
        _ => false,
    };
    let leds = state.leds.or(match config.leds {
        LedCount::Fixed(n) => Some(n),
        LedCount::Auto => None,
    });
    // Every window long enough for two carrier periods is searched, not only a refused one: a
    // frame dropped or repeated a few frames from an end is absorbed by a plausible but wrong
    // timing (a rate ratio and exposure off), leaving no misfit the verdict can see.
    let found = leds.and_then(|leds| match &prepared {
        _ if refused => decoder.find_break(frames, leds, None),
        Ok(Prepared::Window { decoded, .. }) if frames.len() >= 1 << (leds + 2) => {
            decoder.find_break(frames, leds, Some(&decoded.fit.model))
        }
        _ => None,
    });
    if let Some(leds) = leds
        && let Some(found) = found
    {
        let offset = state.offset;
        let need = 1usize << (leds + 1);
        // Each piece is cut to whole carrier periods, as the window plan cuts windows, keeping
        // the frames farthest from the break.
        let whole = |n: usize| n - n % need;
        let pieces: Vec<Vec<Samples>> = match found.kind {
            timing_break::BreakKind::Repeated => {
                let joined: Vec<Samples> = frames[..found.frame]
                    .iter()
                    .chain(&frames[found.frame + 1..])
                    .cloned()
                    .collect();
                let keep = whole(joined.len());
                if found.frame < joined.len() / 2 {
                    vec![joined[joined.len() - keep..].to_vec()]
                } else {
                    vec![joined[..keep].to_vec()]
                }
            }
            timing_break::BreakKind::Dropped => {
                let (before, after) = frames.split_at(found.frame);
                vec![
                    before[..whole(before.len())].to_vec(),
                    after[after.len() - whole(after.len())..].to_vec(),
                ]
            }
        };
        let mut added = 0;
        for piece in pieces.iter().filter(|p| !p.is_empty()) {
            if let Ok(Prepared::Window {
                decoded,
                counted,
                found,
                ..
            }) = prepare_window(decoder, piece, config, state)
                && decoded.verdict.is_plausible()
            {
                state.commit(*decoded, counted, found.as_ref());
                added += piece.len();
            }
        }
        let at = timing_break::TimingBreak {
            frame: offset + found.frame,
            ..found
        };
        if added > 0 {
            state.offset = offset + frames.len();
            state.room.timing_breaks.push(at);
            return Ok(true);
        }
        let problem = format!(
            "the camera's frame timing breaks in the capture ({}): every carrier's phase jumps \
             at once there, and the frames either side could not be decoded on their own",
            at.describe()
        );
        let advice = format!(
            "record again with the camera's frame rate fixed (no dropped or repeated frames; on \
             a phone, a shorter clip or a lower resolution), or decode a range of at least \
             {need} frames clear of the break (--start, --frames)"
        );
        match prepared {
            Ok(Prepared::Window {
                mut decoded,
                counted,
                found,
                ..
            }) => {
                decoded.verdict.problems.insert(0, problem);
                decoded.verdict.advice.insert(0, advice);
                state.offset += frames.len();
                state.commit(*decoded, counted, found.as_ref());
                return Ok(true);
            }
            _ => {
                return Err(DemodError::Implausible {
                    problems: problem,
                    advice,
                });
            }
        }
    }
    state.offset += frames.len();
    match prepared? {
        Prepared::Short => Ok(false),
        Prepared::Window {
            decoded,
            counted,
            found,
            ..
        } => {
            state.commit(*decoded, counted, found.as_ref());
            Ok(true)
        }
    }
}

/// A window prepared by [`prepare_window`].
enum Prepared {
    /// Too few frames for one carrier period after an earlier window (the stream's end).
    Short,
    /// The window decoded.
    Window {
        /// The decode.
        decoded: Box<WindowDecode>,
        /// The LED count and the modulated LEDs seen, when this window's check set them.
        counted: Option<(usize, Option<usize>)>,
        /// The room's nuisance components found and projected out.
        found: Option<nuisance::Nuisance>,
    },
}

/// Decodes one window of `frames` as [`add_window`] adds it, without adding it to `state`.
fn prepare_window(
    decoder: &WindowDecoder,
    frames: &[Samples],
    config: &DecodeConfig,
    state: &Accumulated,
) -> Result<Prepared, DemodError> {
    let got = frames.len();
    let mut sample = decoder.sample(frames);
    // Whether the room's components were looked for in a fit of this window.
    let mut looked = false;
    let mut counted = None;
    let (leds, seed) = match state.leds {
        Some(n) => (n, None),
        None => {
            let checked = decoder.count_leds(&sample, config.leds, config.check_led_count);
            let count = match &checked {
                // The check's fit shows what the carriers leave; an unchecked count is
                // looked at after the decode's fit.
                Ok(LedCountCheck { fit: None, .. }) => checked?,
                Ok(LedCountCheck { fit: Some(fit), .. }) => {
                    looked = true;
                    match decoder.with_nuisance(
                        &sample,
                        Some(&fit.timing),
                        fit.timing.model.shifts.len(),
                    ) {
                        Some(projected) => {
                            sample = projected;
                            decoder.count_leds(&sample, config.leds, config.check_led_count)?
                        }
                        None => checked?,
                    }
                }
                Err(_) => match decoder.with_nuisance(&sample, None, decoder.nuisance_leds) {
                    Some(projected) => {
                        sample = projected;
                        decoder.count_leds(&sample, config.leds, config.check_led_count)?
                    }
                    None => checked?,
                },
            };
            counted = Some((count.leds, count.detected));
            (count.leds, count.fit)
        }
    };
    if got < 1usize << (leds + 1) {
        if state.windows == 0 && got == 0 && config.start > 0 {
            // The start skipped exactly every frame.
            return Err(DemodError::StartBeyondEnd {
                start: config.start,
                available: config.start,
            });
        }
        if state.windows == 0 {
            return Err(DemodError::TooFewFrames {
                got,
                need: 1 << (leds + 1),
                leds,
            });
        }
        return Ok(Prepared::Short);
    }
    let mut decoded = decoder.decode(frames, &sample, leds, seed.as_ref());
    if !looked
        && sample.found.is_none()
        && let Some(projected) = decoder.with_nuisance(&sample, Some(&decoded.fit), leds)
    {
        decoded = decoder.decode(frames, &projected, leds, None);
        sample = projected;
    }
    Ok(Prepared::Window {
        decoded: Box::new(decoded),
        counted,
        found: sample.found,
    })
}

/// The stream's format with the configured frame-rate override.
fn stream_format(format: &FrameFormat, config: &DecodeConfig) -> Result<FrameFormat, DemodError> {
    let mut format = format.clone();
    if let Some(fps) = config.fps {
        if !(fps.is_finite() && fps > 0.0) {
            return Err(DemodError::InvalidConfig(format!(
                "frame rate {fps} is not positive"
            )));
        }
        format.fps = fps;
    }
    Ok(format)
}

/// Skips the first `start` frames.
fn skip_start(source: &mut dyn FrameSource, start: usize) -> Result<(), DemodError> {
    for skipped in 0..start {
        if source.next_frame()?.is_none() {
            return Err(DemodError::StartBeyondEnd {
                start,
                available: skipped,
            });
        }
    }
    Ok(())
}

/// How a capture is cut into windows.
#[derive(Debug, Clone, Copy)]
struct WindowPlan {
    /// Frames per window.
    length: usize,
    /// Frames to decode in total, when known.
    total: Option<usize>,
    /// Total reported to the progress callback.
    progress_total: usize,
}

impl WindowPlan {
    /// Windows for `config` over a stream of `remaining` frames (after the start), within the
    /// memory budget.
    fn new(
        config: &DecodeConfig,
        format: &FrameFormat,
        roi: Roi,
        remaining: Option<usize>,
    ) -> Self {
        let total = match (config.frames, remaining) {
            (Some(f), Some(h)) => Some(f.min(h)),
            (Some(f), None) => Some(f),
            (None, h) => h,
        };
        let sample_bytes = if format.bit_depth > 8 { 2 } else { 1 };
        let frame_bytes = (roi.width * roi.height * sample_bytes).max(1);
        let budget_frames = (config.window_bytes / frame_bytes).clamp(1, MAX_WINDOW_FRAMES);
        let min_chips = match config.leds {
            LedCount::Fixed(n) => 1usize << (n + 1),
            LedCount::Auto => 4,
        };
        let mut length = budget_frames.max(min_chips);
        if let Some(t) = total {
            length = length.min(t.max(1));
        }
        if let LedCount::Fixed(_) = config.leds
            && length > min_chips
        {
            length -= length % min_chips;
        }
        Self {
            length,
            total,
            progress_total: total.unwrap_or(length),
        }
    }

    /// Frames of the next window after `read` frames (0 at the end).
    fn next_window(&self, read: usize) -> usize {
        match self.total {
            Some(t) => self.length.min(t.saturating_sub(read)),
            None => self.length,
        }
    }
}

/// Checks the settings against the stream and returns the decoded region.
fn validate(config: &DecodeConfig, format: &FrameFormat) -> Result<Roi, DemodError> {
    let invalid = |text: String| Err(DemodError::InvalidConfig(text));
    if let LedCount::Fixed(n) = config.leds
        && !(1..=MAX_LEDS).contains(&n)
    {
        return invalid(format!("LED count {n} is outside 1..={MAX_LEDS}"));
    }
    depth::check(
        &config.depths,
        match config.leds {
            LedCount::Fixed(n) => Some(n),
            LedCount::Auto => None,
        },
    )?;
    if let Some(r) = config.rate_ratio
        && !(r.is_finite() && r > 0.0)
    {
        return invalid(format!("rate ratio {r} is not positive"));
    }
    if let Some(e) = config.exposure
        && !(e.is_finite() && e > 0.0 && e <= 1.0)
    {
        return invalid(format!("exposure {e} is outside (0, 1]"));
    }
    if let Some(t) = config.line_time_s
        && !(t.is_finite() && t.abs() * format.fps < 1.0)
    {
        return invalid(format!(
            "line time {t} s is not shorter than a frame period at {} fps",
            format.fps
        ));
    }
    if !(config.max_rate_mismatch.is_finite() && (0.0..0.5).contains(&config.max_rate_mismatch)) {
        return invalid("the rate-ratio search range must be in [0, 0.5)".into());
    }
    if !config.underexposed_below.is_finite() {
        return invalid("under-exposure threshold is NaN".into());
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
        return invalid(format!(
            "region {}x{}+{}+{} is empty or outside the {}x{} frame",
            roi.width, roi.height, roi.x, roi.y, format.width, format.height
        ));
    }
    Ok(roi)
}

/// A window's pixel sample, its Gram matrix and that matrix's leading eigenpairs: the timing
/// fit's input, shared by the LED-count check and the decode.
#[derive(Debug, Clone)]
pub struct WindowSample {
    sample: PixelSample,
    gram: DMatrix<f64>,
    spectrum: Spectrum,
    /// The room's nuisance components found in the window (`None`: not looked for).
    found: Option<nuisance::Nuisance>,
}

impl WindowSample {
    /// The room's nuisance components found in the window, when they were looked for.
    pub fn nuisance(&self) -> Option<&nuisance::Nuisance> {
        self.found.as_ref()
    }
}

/// The outcome of the LED-count check.
#[derive(Debug, Clone)]
pub struct LedCountCheck {
    /// LEDs to decode.
    pub leds: usize,
    /// Modulated LEDs seen in the window (when checked).
    pub detected: Option<usize>,
    /// The check's timing fit (of as many LEDs or more) and its quality, a starting point for
    /// the decode's.
    pub fit: Option<CheckedFit>,
}

/// A timing fit and what the window's sample says about it.
#[derive(Debug, Clone)]
pub struct CheckedFit {
    /// The fit.
    pub timing: TimingFit,
    /// Its quality over the fitted LEDs.
    pub quality: FitQuality,
}

/// One window decoded.
#[derive(Debug, Clone)]
pub struct WindowDecode {
    /// Frames in the window.
    pub frames: usize,
    /// Per-pixel on-levels, noise and masks.
    pub amplitudes: WindowAmplitudes,
    /// The timing of the received waveforms.
    pub fit: TimingFit,
    /// How well it explains the window.
    pub quality: FitQuality,
    /// The window's verdict.
    pub verdict: Verdict,
    /// The room's cause and the mains advice a refusal of this window names (first and last).
    pub room_advice: (Option<String>, Option<String>),
    /// Row bands of the per-pixel fit.
    pub bands: usize,
    /// var(A_i) / σ² of the per-pixel fit, per LED (first band).
    pub variance_factors: Vec<f64>,
}

/// The per-window decoder: planned once per stream, run on every window.
#[derive(Debug, Clone)]
pub struct WindowDecoder {
    roi: Roi,
    /// Pixels of the whole frame (the pixel sample's rows lie on its grid).
    frame_pixels: usize,
    map: CodeMap,
    code_limits: CodeLimits,
    fit_limits: FitLimits,
    estimator: Estimator,
    /// Most LEDs a window's signal space is analysed for (the count check's probe).
    spectrum_leds: usize,
    /// LEDs whose carriers are set aside when looking for room nuisances.
    nuisance_leds: usize,
    /// Camera frame rate (places the mains flicker in the window).
    fps: f64,
    /// Largest rate mismatch searched, and a given rate ratio.
    rate: (f64, Option<f64>),
}

impl WindowDecoder {
    /// Plans the decoder for a stream of `format` (frame-rate override applied) and `config`.
    pub fn new(format: &FrameFormat, config: &DecodeConfig) -> Result<Self, DemodError> {
        let roi = validate(config, format)?;
        Ok(Self {
            roi,
            frame_pixels: format.pixels(),
            map: CodeMap::new(format, config.linearize)?,
            code_limits: CodeLimits::new(format, config.underexposed_below),
            fit_limits: FitLimits {
                max_rate_mismatch: config.max_rate_mismatch,
                rate_ratio: config.rate_ratio,
                exposure: config.exposure,
                line_delay: config.line_time_s.map(|t| t * format.fps),
                seeds: config.seeds,
            },
            estimator: config.estimator,
            spectrum_leds: match config.leds {
                LedCount::Fixed(n) if config.check_led_count => (n + 1).min(MAX_LEDS),
                LedCount::Fixed(n) => n,
                LedCount::Auto => AUTO_MAX_LEDS,
            },
            nuisance_leds: match config.leds {
                LedCount::Fixed(n) => n,
                LedCount::Auto => AUTO_MAX_LEDS,
            },
            fps: format.fps,
            rate: (config.max_rate_mismatch, config.rate_ratio),
        })
    }

    /// What to try when room-light flicker on 50 or 60 Hz mains falls on a carrier line of
    /// `leds` LEDs at rate ratio `rate` (where the decoder cannot tell it from the carrier,
    /// [`meb_core::mains`]); `None` when it falls clear of them.
    fn mains_advice(&self, leds: usize, rate: f64) -> Option<String> {
        let chip_rate = rate * self.fps;
        let window = MAX_WINDOW_FRAMES.min(1 << (leds + 3));
        let clashes = meb_core::mains::clashes(leds as u8, chip_rate, self.fps, window);
        let first = clashes.first()?;
        let clear = meb_core::mains::clear_chip_rates(leds as u8, self.fps, window, self.rate.0, 3);
        let rates = if clear.is_empty() {
            "a camera frame rate that `meb carriers` shows clear".to_string()
        } else {
            clear
                .iter()
                .map(|r| format!("a chip rate of {r:.1} Hz"))
                .collect::<Vec<_>>()
                .join(" or ")
        };
        Some(format!(
            "if a room light on the mains is on: its flicker at {:.0} Hz ({} Hz mains) falls on \
             LED {}'s carrier line at this chip rate ({chip_rate:.1} Hz, camera {} fps), where it \
             cannot be told from the carrier; switch it off, or use {rates} (`meb carriers \
             --rate {chip_rate:.1} --fps {}`)",
            first.family_hz * first.harmonic as f64,
            first.family_hz / 2.0,
            first.led,
            self.fps,
            self.fps
        ))
    }

    /// The decoded region.
    pub fn roi(&self) -> Roi {
        self.roi
    }

    /// Picks the pixel sample of a window of frames cropped to the region (no nuisance
    /// component projected out: [`WindowDecoder::with_nuisance`]).
    pub fn sample(&self, frames: &[Samples]) -> WindowSample {
        self.raw_sample(frames)
    }

    /// The room's nuisance components ([`nuisance`]) in `raw`, a sample with none projected
    /// out, and the sample with them projected out; `None` when none is found. They are
    /// looked for in what `fit` leaves unexplained (its templates and the carriers' strongest
    /// lines removed) or, without a fit (the LED-count check refused the window), beside the
    /// carriers' lines at the rate the seeds' scan finds for `leds` LEDs.
    pub fn with_nuisance(
        &self,
        raw: &WindowSample,
        fit: Option<&TimingFit>,
        leds: usize,
    ) -> Option<WindowSample> {
        let frames = raw.sample.frames();
        if raw.sample.is_empty() || raw.found.is_some() || frames < 1 << (leds.min(2) + 1) {
            return None;
        }
        let (rate, leds, fitted) = match fit {
            Some(fit) => {
                let leds = fit.model.shifts.len();
                let waves = ReceivedWaveform::set(leds, None);
                let rows = raw.sample.rows();
                let rows: Vec<f64> = match (fit.rolling, rows.first(), rows.last()) {
                    (true, Some(&top), Some(&bottom)) => {
                        vec![top as f64, (top + bottom) as f64 / 2.0, bottom as f64]
                    }
                    _ => vec![0.0],
                };
                let fitted = rows
                    .iter()
                    .flat_map(|&row| fit.model.columns(&waves, row, frames).split_off(1))
                    .collect();
                (fit.model.timing.rate_ratio, leds, fitted)
            }
            None => {
                let rate = self.rate.1.unwrap_or_else(|| {
                    let space = SignalSpace::from_spectrum(&raw.spectrum, &raw.gram, leds);
                    let waves = ReceivedWaveform::set(leds, None);
                    seed::scan_rate_of(&space, &waves, frames, self.rate.0)
                });
                (rate, leds, Vec::new())
            }
        };
        let noise = SignalSpace::from_spectrum(&raw.spectrum, &raw.gram, self.spectrum_leds).noise;
        let window = nuisance::Window {
            values: raw.sample.values(),
            means: raw.sample.means(),
            gram: &raw.gram,
            frames,
            noise,
        };
        let found = nuisance::detect(&window, self.fps, rate, leds, &fitted);
        if found.is_empty() {
            return None;
        }
        let found = std::sync::Arc::new(found);
        let mut sample = raw.sample.clone();
        let gram = found.project_gram(&raw.gram);
        sample.project(std::sync::Arc::clone(&found));
        let spectrum = Spectrum::projected(&gram, self.spectrum_leds, found.columns());
        Some(WindowSample {
            sample,
            gram,
            spectrum,
            found: Some((*found).clone()),
        })
    }

    /// A frame dropped or repeated inside the window of `frames` (cropped to the region) of
    /// `leds` LEDs ([`timing_break`]), found with the timing fitted to each half of the window;
    /// `None` when the halves are too short for a fit or no break explains the window.
    pub fn find_break(
        &self,
        frames: &[Samples],
        leds: usize,
        single: Option<&fit::TimingModel>,
    ) -> Option<timing_break::TimingBreak> {
        let f = frames.len();
        let half = f / 2;
        if leds == 0 || leds > MAX_LEDS || half < 1 << (leds + 1) {
            return None;
        }
        let whole = self.raw_sample(frames);
        if whole.sample.is_empty() {
            return None;
        }
        let waves = ReceivedWaveform::set(leds, None);
        let fits: Vec<(TimingFit, usize, bool)> = [(0, half, true), (half, f, false)]
            .into_par_iter()
            .filter_map(|(start, end, before)| {
                let part = self.raw_sample(&frames[start..end]);
                if part.sample.is_empty() {
                    return None;
                }
                let space = SignalSpace::from_spectrum(&part.spectrum, &part.gram, leds);
                let fit = fit_timing(
                    &part.sample,
                    &space,
                    leds,
                    self.roi.height,
                    &self.fit_limits,
                );
                Some((fit, start, before))
            })
            .collect();
        let pixels = whole.sample.len();
        // σ²_G of the whole sample from the halves' fits (the window's own spectrum counts the
        // signal a break spreads beyond the leading directions as noise).
        let noise = fits
            .iter()
            .map(|(fit, _, _)| fit.pixel_noise)
            .fold(f64::INFINITY, f64::min)
            * pixels as f64;
        if !noise.is_finite() {
            return None;
        }
        let rows = whole.sample.rows();
        let values = whole.sample.values();
        let count = if fits.iter().any(|(fit, _, _)| fit.rolling) {
            3
        } else {
            1
        };
        let bands: Vec<timing_break::Band> = (0..count)
            .map(|b| (b * pixels / count, (b + 1) * pixels / count))
            .filter(|(a, z)| z > a)
            .map(|(a, z)| {
                let m = DMatrix::from_row_slice(z - a, f, &values[a * f..z * f]);
                let row = rows[a..z].iter().map(|&r| r as f64).sum::<f64>() / (z - a) as f64;
                timing_break::Band {
                    gram: m.tr_mul(&m),
                    row,
                }
            })
            .collect();
        let halves: Vec<timing_break::HalfFit<'_>> = fits
            .iter()
            .map(|(fit, start, before)| timing_break::HalfFit {
                model: &fit.model,
                start: *start,
                before: *before,
            })
            .collect();
        timing_break::find(&bands, &halves, single, &waves, f, noise)
    }

    /// The pixel sample without nuisance components.
    fn raw_sample(&self, frames: &[Samples]) -> WindowSample {
        let grid = RowGrid::new(
            self.frame_pixels,
            self.roi.y,
            self.roi.width,
            self.roi.height,
        );
        let sample = PixelSample::gather(
            frames,
            (self.roi.width, self.roi.height),
            grid,
            &self.map,
            self.code_limits,
        );
        let gram = sample.gram();
        let spectrum = Spectrum::new(&gram, self.spectrum_leds);
        WindowSample {
            sample,
            gram,
            spectrum,
            found: None,
        }
    }

    /// The LED count to decode (module docs): with `check`, a fit of one LED more than a
    /// fixed count (or of the most the window allows for `Auto`) counts the LEDs whose signal
    /// stands above noise.
    pub fn count_leds(
        &self,
        window: &WindowSample,
        request: LedCount,
        check: bool,
    ) -> Result<LedCountCheck, DemodError> {
        let frames = window.sample.frames();
        let fits = |m: usize| (1usize << (m + 1)) <= frames;
        let unchecked = |leds| LedCountCheck {
            leds,
            detected: None,
            fit: None,
        };
        let probe = match request {
            LedCount::Fixed(n) if !check || !fits(n) => return Ok(unchecked(n)),
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
        if window.sample.is_empty() {
            return Err(DemodError::NothingToDecode("saturated"));
        }
        let waves = ReceivedWaveform::set(probe, window.sample.nuisance());
        let space = SignalSpace::from_spectrum(&window.spectrum, &window.gram, probe);
        let fit = fit_timing(
            &window.sample,
            &space,
            probe,
            self.roi.height,
            &self.fit_limits,
        );
        let quality = quality::measure(&window.sample, &window.gram, &space, &fit, &waves);
        let strongest = quality.levels.iter().cloned().fold(0.0, f64::max);
        let present: Vec<bool> = quality
            .leds
            .iter()
            .zip(&quality.levels)
            .map(|(q, &level)| {
                q.signal_to_noise >= quality::MIN_SIGNAL_TO_NOISE
                    && level > SIGNIFICANT_FRACTION * strongest
            })
            .collect();
        let detected = present.iter().rposition(|&p| p).map_or(0, |i| i + 1);
        if detected == 0 {
            return Err(DemodError::NoModulation);
        }
        let leds = match request {
            LedCount::Auto => detected,
            LedCount::Fixed(n) => {
                let all_present = present.iter().take(n).all(|&p| p);
                if detected != n || !all_present {
                    let detected = if all_present {
                        detected
                    } else {
                        detected.min(n - 1)
                    };
                    let sample = &window.sample;
                    if detected < n
                        && sample.clipped() as f64 >= HIDING_CLIPPED_SHARE * sample.len() as f64
                    {
                        return Err(DemodError::LedsHiddenByClipping {
                            requested: n,
                            detected,
                            clipped_percent: 100.0 * sample.clipped() as f64
                                / sample.examined().max(1) as f64,
                        });
                    }
                    if detected > n
                        && let Some(found) = window.sample.nuisance()
                        && let Some(cause) = found.describe()
                    {
                        // The room's components were found and projected out, and the window
                        // still shows more: name what was found rather than advise more LEDs.
                        return Err(DemodError::Implausible {
                            problems: format!(
                                "{n} LEDs requested and the video shows {detected} modulated \
                                 components after the room's {cause} was projected out"
                            ),
                            advice: format!(
                                "switch the room light off or run it from a steady supply, and \
                                 lock the camera's exposure; or use a chip rate `meb carriers \
                                 --fps {}` lists clear of the flicker",
                                self.fps
                            ),
                        });
                    }
                    return Err(DemodError::LedCountMismatch {
                        requested: n,
                        detected,
                    });
                }
                n
            }
        };
        Ok(LedCountCheck {
            leds,
            detected: Some(detected),
            fit: Some(CheckedFit {
                timing: fit,
                quality,
            }),
        })
    }

    /// Decodes one window of `leds` LEDs (frames cropped to the region); `seed` is an earlier
    /// fit of this window (of at least as many LEDs) to refine instead of starting afresh, or,
    /// of as many LEDs, to use as it is (with its quality: the same fit of the same sample).
    pub fn decode(
        &self,
        frames: &[Samples],
        window: &WindowSample,
        leds: usize,
        seed: Option<&CheckedFit>,
    ) -> WindowDecode {
        let count = frames.len();
        let height = self.roi.height;
        let waves = ReceivedWaveform::set(leds, window.sample.nuisance());
        let space = SignalSpace::from_spectrum(&window.spectrum, &window.gram, leds);
        let (fit, quality) = match seed {
            Some(same) if same.timing.model.shifts.len() == leds => {
                (same.timing.clone(), same.quality.clone())
            }
            _ => {
                let fit = match seed {
                    Some(more) if more.timing.model.shifts.len() > leds => refit_timing(
                        &window.sample,
                        &space,
                        leds,
                        height,
                        &self.fit_limits,
                        &more.timing,
                    ),
                    _ => fit_timing(&window.sample, &space, leds, height, &self.fit_limits),
                };
                let quality = quality::measure(&window.sample, &window.gram, &space, &fit, &waves);
                (fit, quality)
            }
        };
        let mut verdict = quality::judge(&quality.leds, &fit);
        // What the room adds to the advice of a refusal (this window's, or the gains' over the
        // windows, `finish`): its cause first, the mains advice last.
        let room_advice = (
            window
                .sample
                .nuisance()
                .and_then(|n| n.describe())
                .map(|cause| {
                    format!(
                        "the window holds the room's {cause}, projected out: switch the room \
                     light off or run it from a steady supply, and lock the camera's exposure"
                    )
                }),
            self.mains_advice(leds, fit.model.timing.rate_ratio),
        );
        if !verdict.is_plausible() {
            if let Some(advice) = &room_advice.0 {
                verdict.advice.insert(0, advice.clone());
            }
            if let Some(advice) = &room_advice.1 {
                verdict.advice.push(advice.clone());
            }
        }
        let bands = if fit.rolling {
            let ramp = fit.model.ramp_chips(height).abs();
            ((ramp / BAND_PHASE_STEP).ceil() as usize).clamp(1, height)
        } else {
            1
        };
        let region = Region {
            roi: self.roi,
            bands,
        };
        let bases: Vec<basis::TemplateBasis> = (0..bands)
            .map(|b| fit.model.basis(&waves, region.band_centre(b), count))
            .collect();
        let amplitudes = match self.estimator {
            Estimator::Waveform => {
                matched::matched_filter(frames, region, &bases, &self.map, self.code_limits)
            }
            Estimator::Thesis => {
                let chips = 1usize << (leds + 1);
                let used = count - count % chips;
                thesis::thesis_window(&frames[..used], region, leds, &self.map, self.code_limits)
            }
        };
        let variance_factors = bases
            .first()
            .map(|b| (0..leds).map(|i| b.variance_factor(i + 1)).collect())
            .unwrap_or_default();
        WindowDecode {
            frames: count,
            amplitudes,
            fit,
            quality,
            verdict,
            room_advice,
            bands,
            variance_factors,
        }
    }
}

/// Running sums over windows.
#[derive(Default)]
struct Accumulated {
    leds: Option<usize>,
    detected: Option<usize>,
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
    /// Each window's fit, quality and bands.
    fits: Vec<(TimingFit, FitQuality, usize)>,
    /// The verdict over the windows so far.
    verdict: Option<Verdict>,
    /// The room advice of the windows so far ([`WindowDecode::room_advice`]), each once.
    room_advice: (Vec<String>, Vec<String>),
    variance_factors: Vec<f64>,
    /// The room's nuisance components and timing breaks found so far.
    room: nuisance::RoomReport,
    /// Frames of the stream's windows seen so far (decoded or not).
    offset: usize,
}

impl Accumulated {
    /// Adds one decoded window with the LED count its check set and the room's components
    /// found in it.
    fn commit(
        &mut self,
        window: WindowDecode,
        counted: Option<(usize, Option<usize>)>,
        found: Option<&nuisance::Nuisance>,
    ) {
        if let Some((leds, detected)) = counted {
            self.leds = Some(leds);
            self.detected = detected;
        }
        if let Some(found) = found {
            self.room.add(found);
        }
        self.add(window);
    }

    /// Adds one decoded window.
    fn add(&mut self, window: WindowDecode) {
        let count = window.frames;
        let amplitudes = window.amplitudes;
        if self.windows == 0 {
            self.variance_factors = window.variance_factors;
            self.mean_leds = amplitudes.leds;
            self.mean_variance = amplitudes.noise_variance;
            self.saturated = amplitudes.saturated;
            self.underexposed = amplitudes.underexposed;
            self.stats = amplitudes.stats;
        } else {
            // Running frame-weighted means: m += (x − m)·F / (F_total + F).
            let step = (count as f64 / (self.frames + count) as f64) as f32;
            let update = |mean: &mut Vec<f32>, window: &[f32]| {
                mean.par_iter_mut()
                    .zip(window)
                    .for_each(|(m, &x)| *m += (x - *m) * step);
            };
            for (mean, image) in self.mean_leds.iter_mut().zip(&amplitudes.leds) {
                update(mean, image);
            }
            update(&mut self.mean_variance, &amplitudes.noise_variance);
            self.saturated
                .par_iter_mut()
                .zip(&amplitudes.saturated)
                .for_each(|(s, &w)| *s |= w);
            self.underexposed
                .par_iter_mut()
                .zip(&amplitudes.underexposed)
                .for_each(|(u, &w)| *u &= w);
        }
        self.verdict = Some(match self.verdict.take() {
            Some(v) => v.merge(&window.verdict),
            None => window.verdict,
        });
        for (list, advice) in [
            (&mut self.room_advice.0, window.room_advice.0),
            (&mut self.room_advice.1, window.room_advice.1),
        ] {
            if let Some(advice) = advice.filter(|a| !list.contains(a)) {
                list.push(advice);
            }
        }
        self.windows += 1;
        self.frames += count;
        self.fits.push((window.fit, window.quality, window.bands));
    }
}

/// Turns the running sums into images, masks and the report.
fn finish(
    config: &DecodeConfig,
    format: &FrameFormat,
    roi: Roi,
    state: Accumulated,
) -> Result<Decoded, DemodError> {
    let (height, width) = (roi.height, roi.width);
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
    let (first_fit, first_quality, _) = &state.fits[0];
    let gain_uncertainty = quality::combined_gain_uncertainty(
        &state
            .fits
            .iter()
            .map(|(_, q, _)| q.leds.iter().map(|l| l.gain_uncertainty).collect())
            .collect::<Vec<_>>(),
    );
    let per_led = (0..leds)
        .map(|i| {
            let mean_level = stats.level_sums[i] / valid_count;
            let amplitude_noise =
                (noise_power * state.variance_factors[i]).sqrt() / (state.windows as f64).sqrt();
            LedReport {
                led: i + 1,
                phase_chips: first_fit.model.shifts[i],
                mean_level,
                snr_db: 20.0 * (mean_level.abs().max(1e-12) / amplitude_noise.max(1e-12)).log10(),
                quality: LedQuality {
                    gain_uncertainty: gain_uncertainty.get(i).copied().unwrap_or(0.0),
                    ..first_quality.leds[i].clone()
                },
            }
        })
        .collect();
    let images = state
        .mean_leds
        .into_iter()
        .map(|values| Array2::from_shape_vec((height, width), values))
        .collect::<Result<Vec<_>, _>>()?;
    let noise = Array2::from_shape_vec((height, width), noise_values)?;
    let saturated = Array2::from_shape_vec((height, width), saturated)?;
    let underexposed = Array2::from_shape_vec((height, width), underexposed)?;
    let windows = state.fits.len() as f64;
    let mean = |f: &dyn Fn(&(TimingFit, FitQuality, usize)) -> f64| {
        state.fits.iter().map(f).sum::<f64>() / windows
    };
    let largest = |f: &dyn Fn(&(TimingFit, FitQuality, usize)) -> f64| {
        state.fits.iter().map(f).fold(0.0f64, f64::max)
    };
    let rate_ratio = mean(&|(fit, _, _)| fit.model.timing.rate_ratio);
    let line_delay = mean(&|(fit, _, _)| fit.model.line_delay);
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
        exposure: mean(&|(fit, _, _)| fit.model.timing.exposure),
        exposure_std: largest(&|(fit, _, _)| fit.exposure_std),
        line_time_us: if format.fps > 0.0 {
            line_delay / format.fps * 1e6
        } else {
            0.0
        },
        line_delay_frames: line_delay,
        line_delay_std_frames: largest(&|(fit, _, _)| fit.line_delay_std),
        line_delay_evidence: state
            .fits
            .iter()
            .map(|(fit, _, _)| fit.line_delay_evidence)
            .reduce(f64::min)
            .unwrap_or(0.0),
        row_bands: state.fits.iter().map(|(_, _, b)| *b).max().unwrap_or(1),
        fit_residual: mean(&|(_, quality, _)| quality.residual_rms),
        median_noise,
        saturated_pixels: stats.saturated_pixels,
        underexposed_pixels: stats.underexposed_pixels,
        clipping: clipping::ClippingAdvice::of(&images, &noise, &saturated, &underexposed),
        per_led,
        verdict: state
            .verdict
            .unwrap_or_else(|| Verdict::from_findings(Vec::new(), Vec::new()))
            .merge(&{
                let mut gains = quality::judge_gains(&gain_uncertainty);
                if !gains.is_plausible() {
                    let (first, last) = &state.room_advice;
                    gains.advice.splice(0..0, first.iter().cloned());
                    gains.advice.extend(last.iter().cloned());
                }
                gains
            }),
        room: state.room,
        compression: None,
        modulation: ModulationReport::default(),
    };
    Ok(Decoded {
        leds: LedImages { images },
        noise,
        saturated,
        underexposed,
        report,
    })
}

/// Refuses an implausible decode, or keeps it with the verdict marked overridden.
fn apply_verdict(mut decoded: Decoded, policy: OnImplausible) -> Result<Decoded, DemodError> {
    let verdict = &mut decoded.report.verdict;
    if verdict.is_plausible() {
        return Ok(decoded);
    }
    match policy {
        OnImplausible::Refuse => Err(DemodError::Implausible {
            problems: verdict.problems.join("; "),
            advice: verdict.advice.join("; "),
        }),
        OnImplausible::Keep => {
            verdict.status = VerdictStatus::Overridden;
            Ok(decoded)
        }
    }
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
    meb_core::stats::quantile_in_place(&mut sample, 0.5).map_or(f64::NAN, f64::from)
}

/// Bytes of a frame's samples (for memory budgeting by callers).
pub fn frame_bytes(samples: &Samples) -> usize {
    match samples {
        Samples::U8(v) => v.len(),
        Samples::U16(v) => 2 * v.len(),
    }
}
