//! Motion in a window: what the still-scene LED model cannot explain, and what frames one code
//! period apart show.
//!
//! The decoder fits every pixel of a window with a still scene: a background plus each LED's
//! received waveform times the pixel's on-level A_i
//! (docs/maths/demodulation.md#the-matched-filter). What that fit leaves over —
//! the energy outside the LED waveforms, reported as the per-pixel noise σ — is sensor noise
//! for a still object, but an object that moves during the window changes its pixels'
//! brightness in ways no carrier does (a silhouette edge sweeping over a pixel is a step, a
//! turning surface a ramp), and that lands in the residual. This is the thesis' proposed
//! frame selection (Ch. 5.4: detect when the object moves, decode where it is still) done on
//! the decoder's own residual instead of frame differences, which the LED modulation itself
//! would trip — except across one code period, which it does not trip:
//!
//! - **Residual outliers.** A pixel counts as moving when its σ exceeds `sigmas` times the σ
//!   typical of still lit pixels at least as bright in the same window (the smallest median σ
//!   of its brightness octile and the brighter ones: shot noise grows with brightness and is
//!   not motion, while half-covered, moving edge pixels crowd the dim octiles). The window's
//!   score is the fraction of lit pixels that move; above `threshold` the window is moving.
//! - **Frames one code period apart.** The carriers repeat every n = 2^(N+1) chips
//!   (docs/maths/carriers.md#the-carrier-table),
//!   so when the window's frames run n·|ρ − 1| ≪ 1 chip off the code, frames j and j + n of a
//!   still pixel differ by noise alone, E[(r_{j+n} − r_j)²] = 2σ², whatever the LEDs do. The
//!   ratio q = mean over lit pixels and pairs of (r_{j+n} − r_j)²/2σ² is 1 for a still scene
//!   and grows with motion, and no timing fit enters it: a wrong fit can neither fake nor hide
//!   it. Above [`PERIOD_MOVING`] the window is moving. A surface turning slowly (the thesis'
//!   ellipsoid at 7.5 rpm) brightens or darkens every pixel a little: no outliers, but q ≈ 4.
//!
//! Both give the motion's energy in the decoder's noise directions (energy per pixel over the
//! noise σ² of one frame sample, as the decoder's verdict counts unexplained modulation,
//! [`crate::demod::quality`]): the outliers' residual excess Σ(F − k)(σ² − σ_ref²) over Σσ_ref²,
//! and for a pixel whose brightness ramps by s per frame, Σ_j (ramp − mean)² = F(F² − 1)s²/12
//! over F decoded frames while (ns)² = 2σ²(q − 1), i.e. F(F² − 1)(q − 1)/(6n²).

use crate::demod::{CodeMap, Decoded, Roi};
use meb_core::capture::Samples;
use serde::{Deserialize, Serialize};

/// Largest number of pixels the score is computed from (an evenly strided sample).
const SAMPLE_PIXELS: usize = 1 << 17;
/// Brightness bins of the noise reference.
const LEVEL_BINS: usize = 8;
/// Period-difference ratio q above which a window is moving: a still window gives 1 (the
/// decoder's σ is unbiased, and a pixel sample of thousands pins the mean to a few percent).
pub const PERIOD_MOVING: f64 = 1.5;
/// Largest slip n·|ρ − 1| of the code over one period, chips, at which frames a period apart
/// still cancel the modulation.
const MAX_PERIOD_SLIP: f64 = 0.02;

/// What to do with windows in which the object moved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MotionPolicy {
    /// Reconstruct every window and record its motion.
    #[default]
    Mark,
    /// Leave moving windows out (recorded as skipped).
    Skip,
    /// Move a moving window later, a few frames at a time, until the object is still in it
    /// (at most up to the next window's start); reconstruct it there.
    Place,
}

/// Motion detection settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MotionConfig {
    /// What to do with moving windows.
    pub policy: MotionPolicy,
    /// A pixel moves when its residual σ exceeds this many times its brightness class's.
    pub sigmas: f32,
    /// A window moves when more than this fraction of its lit pixels move.
    pub threshold: f64,
    /// Pixels brighter (Σ A_i) than this fraction of the 99th percentile count as lit.
    pub lit_fraction: f32,
    /// Frames a [`MotionPolicy::Place`] window moves per try.
    pub place_step: usize,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            policy: MotionPolicy::Mark,
            sigmas: 3.0,
            threshold: 0.02,
            lit_fraction: 0.05,
            place_step: 4,
        }
    }
}

/// The motion measured in one window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotionEstimate {
    /// Fraction of lit pixels whose residual marks them as moving.
    pub score: f64,
    /// Whether the score or the period-difference ratio says the object moved.
    pub moving: bool,
    /// Lit pixels in the sample.
    pub lit_pixels: usize,
    /// Moving pixels in the sample.
    pub moving_pixels: usize,
    /// Period-difference ratio q (1 when still; `None` when the window holds no two frames
    /// one code period apart, or the code slips against the frames).
    #[serde(default)]
    pub period_ratio: Option<f64>,
    /// Motion energy the still-scene model cannot hold, in the decoder's noise directions
    /// (module docs).
    #[serde(default)]
    pub energy: f64,
}

impl MotionEstimate {
    /// No measurement (too few lit pixels).
    fn none(lit_pixels: usize) -> Self {
        Self {
            score: 0.0,
            moving: false,
            lit_pixels,
            moving_pixels: 0,
            period_ratio: None,
            energy: 0.0,
        }
    }
}

/// The camera frames around a decoded window, for the period-difference test.
#[derive(Debug, Clone, Copy)]
pub struct PeriodFrames<'a> {
    /// Consecutive camera frames, whole (not cropped to the decoded region).
    pub frames: &'a [Samples],
    /// Code values to fractions of full scale (the decoder's linearisation).
    pub map: &'a CodeMap,
    /// Frame width in pixels.
    pub width: usize,
    /// The decoded region (`None`: the whole frame).
    pub roi: Option<Roi>,
    /// Code period n = 2^(N+1), frames.
    pub period: usize,
}

impl PeriodFrames<'_> {
    /// Where the decoded region lies in the frame: the frame's width and pixels, and the
    /// region (`None` when the frames hold no pixel).
    fn placement(&self) -> Option<Placement> {
        let pixels = self.frames.first()?.len();
        let height = pixels / self.width.max(1);
        Some(Placement {
            width: self.width,
            pixels,
            region: self.roi.unwrap_or(Roi {
                x: 0,
                y: 0,
                width: self.width,
                height,
            }),
        })
    }
}

/// Where a decoded image lies in its frame.
#[derive(Debug, Clone, Copy)]
struct Placement {
    /// Frame width.
    width: usize,
    /// Frame pixels.
    pixels: usize,
    /// The decoded region.
    region: Roi,
}

/// A lit pixel of the sample: index in the decoded image, brightness Σ A_i, residual σ.
#[derive(Debug, Clone, Copy)]
struct LitPixel {
    index: usize,
    level: f32,
    sigma: f32,
}

/// Measures the motion in a decoded window (module docs); `frames` adds the
/// period-difference test.
pub fn detect_motion(
    decoded: &Decoded,
    frames: Option<&PeriodFrames>,
    config: &MotionConfig,
) -> MotionEstimate {
    let placement = frames.and_then(PeriodFrames::placement);
    let Some(mut samples) = lit_sample(decoded, placement, config.lit_fraction) else {
        return MotionEstimate::none(0);
    };
    let lit = samples.len();
    if lit < LEVEL_BINS * 4 {
        return MotionEstimate::none(lit);
    }
    // Brightness octiles and the median σ of each. Moving pixels (partly covered by a
    // sweeping silhouette) gather in the dim octiles and can make up most of one, while still
    // noise only grows with brightness: each octile's reference is the smallest median of
    // it and every brighter octile.
    samples.sort_unstable_by(|a, b| a.level.total_cmp(&b.level));
    let bins: Vec<&[LitPixel]> = (0..LEVEL_BINS)
        .map(|bin| &samples[bin * lit / LEVEL_BINS..(bin + 1) * lit / LEVEL_BINS])
        .collect();
    let mut medians: Vec<f32> = bins
        .iter()
        .map(|part| meb_core::stats::median(part.iter().map(|s| s.sigma)).unwrap_or(0.0))
        .collect();
    for bin in (0..LEVEL_BINS - 1).rev() {
        medians[bin] = medians[bin].min(medians[bin + 1]);
    }
    let (mut moving, mut excess, mut reference_energy) = (0usize, 0.0f64, 0.0f64);
    for (part, &reference) in bins.iter().zip(&medians) {
        let limit = config.sigmas * reference;
        let reference = f64::from(reference);
        for s in part.iter() {
            reference_energy += reference * reference;
            if s.sigma > limit {
                moving += 1;
                excess += f64::from(s.sigma).powi(2) - reference * reference;
            }
        }
    }
    let report = &decoded.report;
    let frames_used = report.frames_used as f64;
    let dof = (frames_used - (report.leds + 1) as f64).max(0.0);
    let outlier_energy = if reference_energy > 0.0 {
        dof * excess / reference_energy
    } else {
        0.0
    };
    let period = frames.and_then(|f| period_ratio(f, decoded, &samples).map(|q| (q, f.period)));
    let period_energy = period.map_or(0.0, |(q, n)| {
        frames_used * (frames_used * frames_used - 1.0) * (q - 1.0).max(0.0)
            / (6.0 * (n * n) as f64)
    });
    let score = moving as f64 / lit as f64;
    let period_ratio = period.map(|(q, _)| q);
    MotionEstimate {
        score,
        moving: score > config.threshold || period_ratio.is_some_and(|q| q > PERIOD_MOVING),
        lit_pixels: lit,
        moving_pixels: moving,
        period_ratio,
        energy: outlier_energy.max(period_energy),
    }
}

/// The lit pixels of an evenly strided sample of the frame (every k-th pixel in raster order)
/// inside the decoded image, which lies in the frame as `placement` says (`None`: it is the
/// frame); `None` when the decode has no per-pixel noise or its images are not contiguous.
///
/// A region of the frame ([`super::focus`]) takes the frame's sample pixels inside it, and
/// its brightness reference is the frame's: the 99th percentile of the frame's sample with
/// every sample pixel outside the region counted as dimmer than those inside (the region
/// holds the lit pixels). So the region's lit pixels are those the whole frame's decode
/// would have, at a fraction of the cost.
fn lit_sample(
    decoded: &Decoded,
    placement: Option<Placement>,
    lit_fraction: f32,
) -> Option<Vec<LitPixel>> {
    let images = &decoded.leds.images;
    let noise = decoded.noise.as_slice_memory_order()?;
    let planes: Vec<&[f32]> = images
        .iter()
        .filter_map(|im| im.as_slice_memory_order())
        .collect();
    if planes.len() != images.len() || planes.iter().any(|p| p.len() != noise.len()) {
        return None;
    }
    let (rows, cols) = decoded.noise.dim();
    let placement = placement.unwrap_or(Placement {
        width: cols,
        pixels: noise.len(),
        region: Roi {
            x: 0,
            y: 0,
            width: cols,
            height: rows,
        },
    });
    if (placement.region.width, placement.region.height) != (cols, rows) {
        return None;
    }
    let stride = placement.pixels.div_ceil(SAMPLE_PIXELS).max(1);
    let (x, y) = (placement.region.x, placement.region.y);
    let mut inside = 0usize;
    let mut samples = Vec::new();
    for r in 0..rows {
        let start = (r + y) * placement.width + x;
        let first = (stride - start % stride) % stride;
        for c in (first..cols).step_by(stride) {
            inside += 1;
            let p = r * cols + c;
            let level: f32 = planes.iter().map(|plane| plane[p]).sum();
            if level.is_finite() && noise[p].is_finite() {
                samples.push(LitPixel {
                    index: p,
                    level,
                    sigma: noise[p],
                });
            }
        }
    }
    // The frame's sample pixels outside the region rank below every one inside.
    let outside = placement.pixels.div_ceil(stride).saturating_sub(inside);
    let total = samples.len() + outside;
    let rank = ((total.saturating_sub(1)) as f64 * 0.99).round() as usize;
    let mut levels: Vec<f32> = samples.iter().map(|s| s.level).collect();
    let top = meb_core::stats::quantile_in_place(&mut levels, 0.0).map(|lowest| {
        match rank.checked_sub(outside) {
            Some(index) => *levels.select_nth_unstable_by(index, f32::total_cmp).1,
            None => lowest,
        }
    });
    let top = top.unwrap_or(0.0);
    samples.retain(|s| s.level > lit_fraction * top && top > 0.0);
    Some(samples)
}

/// The period-difference ratio q over `lit` pixels (module docs), when the frames hold two
/// or more pairs one code period apart and the code does not slip.
///
/// The noise comes from the same differences, not from the decoder's σ (which the motion
/// inflates): per pixel, the K differences D_j = r_{j+n} − r_j of a brightness that changes
/// smoothly share one mean m (the change over n frames) and scatter about it by noise alone,
/// so the pooled Σ m² / Σ (v/K), v the differences' sample variance, is 1 + K·(ns)²/2σ² and
/// q = 1 + (that − 1)/K.
fn period_ratio(frames: &PeriodFrames, decoded: &Decoded, lit: &[LitPixel]) -> Option<f64> {
    let n = frames.period;
    let slip = n as f64 * (decoded.report.rate_ratio - 1.0).abs();
    let pairs = frames.frames.len().saturating_sub(n);
    if n == 0 || pairs < 2 || slip.is_nan() || slip > MAX_PERIOD_SLIP {
        return None;
    }
    let width = decoded.noise.ncols();
    let (x, y) = frames.roi.map_or((0, 0), |r| (r.x, r.y));
    let scale = f64::from(frames.map.scale());
    let value = |samples: &Samples, i: usize| {
        (i < samples.len()).then(|| f64::from(frames.map.value(samples.code(i) as u16)) * scale)
    };
    let k = pairs as f64;
    let (mut change, mut scatter) = (0.0f64, 0.0f64);
    for pixel in lit {
        let at = (pixel.index / width + y) * frames.width + pixel.index % width + x;
        let (mut sum, mut squares) = (0.0f64, 0.0f64);
        for (a, b) in frames.frames.iter().zip(&frames.frames[n..]) {
            let (Some(a), Some(b)) = (value(a, at), value(b, at)) else {
                return None;
            };
            sum += b - a;
            squares += (b - a).powi(2);
        }
        let mean = sum / k;
        change += mean * mean;
        scatter += (squares - k * mean * mean).max(0.0) / (k - 1.0) / k;
    }
    (scatter > 0.0).then(|| 1.0 + (change / scatter - 1.0) / k)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demod::fixture::decoded;
    use ndarray::Array2;

    /// A lit disc with shot-noise-like σ growing with brightness, on a dark background.
    fn disc() -> (Array2<f32>, Array2<f32>) {
        let levels = Array2::from_shape_fn((64, 64), |(r, c)| {
            let d2 = (r as f32 - 32.0).powi(2) + (c as f32 - 32.0).powi(2);
            if d2 < 400.0 {
                0.1 + 0.5 * (1.0 - d2 / 400.0)
            } else {
                0.0
            }
        });
        let noise = levels.mapv(|l| 0.004 * (1.0 + 2.0 * l) * (1.0 + 0.1 * (l * 97.0).sin()));
        (levels, noise)
    }

    #[test]
    fn a_region_takes_the_whole_frames_lit_sample() {
        // 600×400 frame (a sample pixel every 2nd in raster order) with a bright block.
        let (width, height) = (600, 400);
        let inside = |r: usize, c: usize| (150..250).contains(&r) && (200..330).contains(&c);
        let levels = Array2::from_shape_fn((height, width), |(r, c)| {
            if inside(r, c) {
                0.2 + 0.001 * ((r * 7 + c * 3) % 50) as f32
            } else {
                0.001
            }
        });
        let noise = Array2::from_elem((height, width), 0.002f32);
        let whole = decoded(levels.clone(), noise.clone());
        let region = Roi {
            x: 171,
            y: 120,
            width: 200,
            height: 170,
        };
        let area = ndarray::s![120..290, 171..371];
        let cut = decoded(levels.slice(area).to_owned(), noise.slice(area).to_owned());
        let placement = Placement {
            width,
            pixels: width * height,
            region,
        };
        let frame_pixels = |sample: Vec<LitPixel>, at: Roi, cols: usize| -> Vec<(usize, f32)> {
            sample
                .iter()
                .map(|p| {
                    (
                        (p.index / cols + at.y) * width + p.index % cols + at.x,
                        p.level,
                    )
                })
                .collect()
        };
        let all = Roi {
            x: 0,
            y: 0,
            width,
            height,
        };
        let expected = frame_pixels(lit_sample(&whole, None, 0.05).unwrap(), all, width);
        let got = frame_pixels(
            lit_sample(&cut, Some(placement), 0.05).unwrap(),
            region,
            200,
        );
        assert!(expected.len() > 5000, "{}", expected.len());
        assert_eq!(got, expected);
    }

    #[test]
    fn a_still_window_scores_zero_even_with_brightness_dependent_noise() {
        let (levels, noise) = disc();
        let m = detect_motion(&decoded(levels, noise), None, &MotionConfig::default());
        assert!(m.lit_pixels > 1000);
        assert_eq!(m.moving_pixels, 0);
        assert!(!m.moving);
    }

    #[test]
    fn a_sweeping_edge_marks_the_window_moving() {
        let (levels, mut noise) = disc();
        // An edge crossing a band of lit pixels: residuals ten times the noise there.
        for ((r, c), n) in noise.indexed_iter_mut() {
            let d = ((r as f32 - 32.0).powi(2) + (c as f32 - 32.0).powi(2)).sqrt();
            if (17.0..20.0).contains(&d) {
                *n *= 10.0;
            }
        }
        let m = detect_motion(&decoded(levels, noise), None, &MotionConfig::default());
        assert!(m.moving, "{m:?}");
        assert!(m.score > 0.1 && m.score < 0.5, "{m:?}");
    }

    /// 16-bit frames of the disc whose pixels blink with a period of `period` frames, each
    /// frame's brightness scaled by 1 + `ramp`·j, with Gaussian noise σ = `sigma` (fraction
    /// of full scale).
    fn blinking(period: usize, frames: usize, ramp: f64, sigma: f64) -> Vec<Samples> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let (levels, _) = disc();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, sigma).unwrap();
        (0..frames)
            .map(|j| {
                let on = if (j % period) < period / 2 { 1.0 } else { 0.4 };
                Samples::U16(
                    levels
                        .iter()
                        .map(|&l| {
                            let v = f64::from(l) * on * (1.0 + ramp * j as f64)
                                + noise.sample(&mut rng);
                            (v.clamp(0.0, 1.0) * 65535.0).round() as u16
                        })
                        .collect(),
                )
            })
            .collect()
    }

    #[test]
    fn frames_one_code_period_apart_tell_a_slowly_brightening_object_from_a_still_one() {
        let format = meb_core::capture::FrameFormat {
            width: 64,
            height: 64,
            bit_depth: 16,
            black_level: 0.0,
            white_level: 65535.0,
            fps: 1000.0,
        };
        let map = CodeMap::new(&format, crate::demod::Linearize::None).unwrap();
        let (levels, _) = disc();
        let sigma = 0.004;
        // The decoder's σ, inflated as motion inflates it: the test must not lean on it.
        let decoded = decoded(
            levels.clone(),
            levels.mapv(|l| if l > 0.0 { 0.02 } else { 0.0 }),
        );
        let config = MotionConfig::default();
        let measure = |ramp: f64| {
            let frames = blinking(8, 24, ramp, sigma);
            let period = PeriodFrames {
                frames: &frames,
                map: &map,
                width: 64,
                roi: None,
                period: 8,
            };
            detect_motion(&decoded, Some(&period), &config)
        };
        let still = measure(0.0);
        let q = still.period_ratio.unwrap();
        assert!((q - 1.0).abs() < 0.1, "{still:?}");
        assert!(!still.moving, "{still:?}");
        // 0.4 % brighter per frame: over 8 frames a lit pixel changes by a few σ (q ≈ 2–3).
        let turning = measure(0.004);
        let q = turning.period_ratio.unwrap();
        assert!(q > 1.5 && q < 5.0, "{turning:?}");
        assert!(turning.moving, "{turning:?}");
        assert!(turning.energy > 0.0, "{turning:?}");
        // No two frames a period apart: no ratio, and the residual outliers decide alone.
        let frames = blinking(8, 9, 0.0, sigma);
        let short = PeriodFrames {
            frames: &frames,
            map: &map,
            width: 64,
            roi: None,
            period: 8,
        };
        assert_eq!(
            detect_motion(&decoded, Some(&short), &config).period_ratio,
            None
        );
    }
}
