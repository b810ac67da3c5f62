//! How well a rig explains a capture: the Lambertian fit's residuals over the lit surface at
//! the reconstructed depth, per LED, and each LED's brightness as the capture shows it.
//!
//! With K ≥ 4 LEDs lighting a pixel, its K readings A_i = ρ·n·L_i(X) over-determine the three
//! unknowns G = ρn: the weighted least-squares fit leaves residuals r_i = A_i − L_i(X)·G in
//! the K − 3 directions L cannot reach. Noise makes them small and random; a wrong LED
//! position or intensity makes them systematic over the whole surface. The check takes every
//! reconstructed pixel that all LEDs light clearly (each reading above [`LIT_SIGMAS`] of its
//! noise and facing the LED), at the point X of its ray at the reconstructed depth, and
//! measures:
//!
//! - the misfit: the median over pixels of the relative residual √(Σ r_i²/Σ A_i²). The median,
//!   because a rig error is systematic over most of the surface while a glossy highlight or a
//!   shadow edge is a small patch. A highlight's tail is not: on a glossy surface it reads
//!   above the model in a wide ring around each highlight, so the caller leaves out the pixels
//!   in an LED's lobe there ([`super::check_decoded_rig`]);
//! - each LED's apparent intensity g_i: the gains that make the readings A_i/g_i most
//!   Lambertian under the rig's light vectors, found by alternating the per-pixel fit of G and
//!   the per-LED gain g_i = median_p A_i/(L_i·G) (a robust form of semi-calibrated photometric
//!   stereo: D. Cho, Y. Matsushita, Y.-W. Tai and I. S. Kweon, "Semi-calibrated photometric
//!   stereo", IEEE Transactions on Pattern Analysis and Machine Intelligence, 2020), scaled
//!   to a geometric mean of 1 (a common factor is the albedo's). A gain far from 1 names the
//!   LED whose intensity the rig misstates;
//! - the misfit left with those gains: what the intensities alone cannot explain (positions,
//!   axes, emission profiles).
//!
//! The misfit is judged against the one noise alone gives (or [`MODEL_FLOOR`], when larger):
//! up to [`DOUBTFUL_MISFIT_RATIO`] times it the rig is consistent, up to [`MAX_MISFIT_RATIO`]
//! doubtful (reported), beyond that inconsistent (refused). The worst LED is the one whose
//! apparent intensity is furthest from 1. The gains are not the LEDs' true intensities when
//! the rig is wrong: the depth they are measured at was reconstructed with the wrong rig
//! (the blobby shape under intensities 1.10 / 0.93 / 1.05 / 0.90 taken for 1 gave apparent
//! intensities 1.025 / 0.979 / 1.108 / 0.899 against the true 1.108 / 0.937 / 1.058 / 0.907),
//! so they name the worst LED but are no calibration.

use crate::demod::quality::Verdict;
use crate::photometric::Lights;
use meb_core::rig::Rig;
use meb_core::types::LedImages;
use nalgebra::{Matrix3, Vector3};
use ndarray::Array2;
use rayon::prelude::*;

/// A reading counts as clearly lit above this many of its noise σ_i.
pub const LIT_SIGMAS: f64 = 5.0;

/// Largest ratio of the misfit to the noise's (or to [`MODEL_FLOOR`], when larger) of a
/// consistent rig. On the blobby shape of seed 4 (out-of-plane rig, 640×360, 64 frames,
/// noise 1 %, gamma 2.2) the misfit with the true rig is 0.84 % against the noise's 1.12 %
/// (ratio 0.75); with every LED 10, 25 and 50 mm off it is 1.73, 4.31 and 8.77 % (1.5, 3.8,
/// 7.8) and with intensities 1.10 / 0.93 / 1.05 / 0.90 taken for 1, 7.6 % (6.1).
pub const MAX_MISFIT_RATIO: f64 = 2.5;

/// Misfit ratio from which a rig is reported as doubtful (on stderr and in the report) but
/// not refused: LEDs about 10 mm off (see [`MAX_MISFIT_RATIO`]).
pub const DOUBTFUL_MISFIT_RATIO: f64 = 1.3;

/// Relative model error a right rig may leave in a capture with almost no noise (quantised,
/// near-field light vectors at a reconstructed depth): the misfit is judged against the
/// larger of this and the noise's.
pub const MODEL_FLOOR: f64 = 0.005;

/// Fewest pixels lit by every LED that the check needs.
pub const MIN_PIXELS: usize = 200;

/// Most pixels the check uses (an even subsample of a larger surface).
const MAX_PIXELS: usize = 40_000;

/// Alternations of the gain fit.
const GAIN_ITERATIONS: usize = 30;

/// What the check found for one LED.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LedCheck {
    /// LED number, from 1.
    pub led: usize,
    /// Apparent intensity relative to the rig's (geometric mean of all LEDs 1).
    pub gain: f64,
    /// Median relative residual |r_i|/A_i with the rig as given.
    pub residual: f64,
    /// Median residual r_i/σ_i with the rig as given, in noise σ (signed: positive when the
    /// LED reads brighter than the fit).
    pub residual_sigmas: f64,
}

/// Whether the rig explains the capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RigFit {
    /// The residuals are those of a right rig.
    Consistent,
    /// The residuals are larger than a right rig's but small: reported, not refused.
    Doubtful,
    /// The rig does not fit the capture.
    Inconsistent,
    /// Too few pixels lit by every LED (or fewer than four LEDs) to judge.
    Unjudged,
}

/// The rig check of a reconstruction (module docs).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RigCheck {
    /// Pixels lit by every LED that were used.
    pub pixels: usize,
    /// Median relative residual √(Σ r_i²/Σ A_i²) with the rig as given.
    pub misfit: f64,
    /// The same with each LED's intensity multiplied by its gain.
    pub misfit_with_gains: f64,
    /// Median relative residual that the noise alone gives.
    pub noise_misfit: f64,
    /// Per LED.
    pub leds: Vec<LedCheck>,
    /// The LED that fits worst (from 1), when judged.
    pub worst_led: Option<usize>,
    /// The outcome.
    pub fit: RigFit,
}

impl RigCheck {
    /// The check as a verdict that names `rig_name` and the worst LED: implausible exactly
    /// when the rig is [`RigFit::Inconsistent`].
    pub fn verdict(&self, rig_name: &str) -> Verdict {
        if self.fit != RigFit::Inconsistent {
            return Verdict::from_findings(Vec::new(), Vec::new());
        }
        Verdict::from_findings(vec![self.describe(rig_name)], vec![self.advice()])
    }

    /// One line: the misfit against a right rig's, and the worst LED.
    pub fn describe(&self, rig_name: &str) -> String {
        match self.fit {
            RigFit::Unjudged => format!(
                "rig {rig_name} not checked: only {} pixels are lit by every LED (at least \
                 {MIN_PIXELS} needed)",
                self.pixels
            ),
            fit => {
                let worst = self.worst_led.filter(|_| fit != RigFit::Consistent);
                let worst = worst.map_or(String::new(), |led| {
                    let g = &self.leds[led - 1];
                    format!(
                        ": LED {led}'s position or intensity does not fit this capture (it \
                         reads {:+.1} % against the others, median residual {:.1} %)",
                        100.0 * (g.gain - 1.0),
                        100.0 * g.residual
                    )
                });
                let judged = match fit {
                    RigFit::Consistent => "fits this capture",
                    RigFit::Doubtful => "fits this capture only roughly",
                    _ => "does not fit this capture",
                };
                format!(
                    "rig {rig_name} {judged}: the Lambertian fit's median residual over {} \
                     pixels lit by every LED is {:.2} % ({:.2} % with fitted intensities; \
                     noise alone {:.2} %, a right rig ≤ {MAX_MISFIT_RATIO}× that){worst}",
                    self.pixels,
                    100.0 * self.misfit,
                    100.0 * self.misfit_with_gains,
                    100.0 * self.noise_misfit.max(MODEL_FLOOR),
                )
            }
        }
    }

    /// What to try for a rig that does not fit.
    pub fn advice(&self) -> String {
        let gains = self
            .leds
            .iter()
            .map(|l| format!("{:.3}", l.gain))
            .collect::<Vec<_>>()
            .join(", ");
        format!(
            "run `meb calibrate lights` with a matte sphere, or measure the LED positions and \
             intensities again (the capture's apparent intensities against the rig's: \
             {gains}); `meb rig check` shows the residuals"
        )
    }
}

/// One pixel's readings, noise and light vectors.
struct Sample {
    a: Vec<f64>,
    sigma: Vec<f64>,
    l: Vec<Vector3<f64>>,
}

/// Checks `rig` against the LED `images` (level `noise` σ(p), per-LED `noise_gains` g_i) at
/// the reconstructed `depth_mm` over the measured pixels `mask` (module docs).
pub fn check_rig(
    images: &LedImages,
    noise: Option<&Array2<f32>>,
    noise_gains: &[f64],
    rig: &Rig,
    depth_mm: &Array2<f32>,
    mask: &Array2<bool>,
) -> RigCheck {
    let k = images.images.len();
    let samples = gather(images, noise, noise_gains, rig, depth_mm, mask);
    let unjudged = |pixels| RigCheck {
        pixels,
        misfit: f64::NAN,
        misfit_with_gains: f64::NAN,
        noise_misfit: f64::NAN,
        leds: Vec::new(),
        worst_led: None,
        fit: RigFit::Unjudged,
    };
    if k < 4 || samples.len() < MIN_PIXELS {
        return unjudged(samples.len());
    }
    let ones = vec![1.0; k];
    let given = residuals(&samples, &ones);
    let gains = fit_gains(&samples);
    let with_gains = residuals(&samples, &gains);
    let misfit = median(given.iter().map(|r| r.relative).collect());
    let misfit_with_gains = median(with_gains.iter().map(|r| r.relative).collect());
    let noise_misfit = median(given.iter().map(|r| r.noise_relative).collect());
    let leds: Vec<LedCheck> = (0..k)
        .map(|i| LedCheck {
            led: i + 1,
            gain: gains[i],
            residual: median(given.iter().map(|r| r.per_led[i].abs()).collect()),
            residual_sigmas: median(given.iter().map(|r| r.per_led_sigmas[i]).collect()),
        })
        .collect();
    let ratio = misfit / noise_misfit.max(MODEL_FLOOR);
    let fit = if ratio.is_nan() || ratio > MAX_MISFIT_RATIO {
        RigFit::Inconsistent
    } else if ratio > DOUBTFUL_MISFIT_RATIO {
        RigFit::Doubtful
    } else {
        RigFit::Consistent
    };
    let mut check = RigCheck {
        pixels: samples.len(),
        misfit,
        misfit_with_gains,
        noise_misfit,
        leds,
        worst_led: None,
        fit,
    };
    check.worst_led = check
        .leds
        .iter()
        .max_by(|a, b| a.gain.ln().abs().total_cmp(&b.gain.ln().abs()))
        .map(|l| l.led);
    check
}

/// The pixels lit by every LED (module docs), evenly subsampled to at most [`MAX_PIXELS`].
fn gather(
    images: &LedImages,
    noise: Option<&Array2<f32>>,
    noise_gains: &[f64],
    rig: &Rig,
    depth_mm: &Array2<f32>,
    mask: &Array2<bool>,
) -> Vec<Sample> {
    let k = images.images.len();
    let candidates: Vec<(usize, usize)> = mask
        .indexed_iter()
        .filter(|&(p, &m)| m && depth_mm.get(p).is_some_and(|z| z.is_finite()))
        .map(|(p, _)| p)
        .collect();
    let stride = candidates.len().div_ceil(MAX_PIXELS).max(1);
    let lights = Lights::near_field(rig, Some(depth_mm));
    candidates
        .par_iter()
        .step_by(stride)
        .filter_map(|&(r, c)| {
            let a: Vec<f64> = images
                .images
                .iter()
                .map(|im| im.get((r, c)).map_or(f64::NAN, |&v| f64::from(v)))
                .collect();
            if a.iter().any(|v| !v.is_finite()) {
                return None;
            }
            let level = noise
                .and_then(|n| n.get((r, c)))
                .map_or(0.0, |&s| f64::from(s));
            let brightest = a.iter().copied().fold(0.0, f64::max);
            let sigma: Vec<f64> = (0..k)
                .map(|i| {
                    let g = noise_gains.get(i).copied().unwrap_or(1.0);
                    if level > 0.0 {
                        g * level
                    } else {
                        // Without a noise map: 1 % of the brightest reading.
                        0.01 * brightest
                    }
                })
                .collect();
            let mut l = vec![Vector3::zeros(); k];
            lights.at(r, c, &mut l);
            let lit = (0..k).all(|i| a[i] > LIT_SIGMAS * sigma[i] && l[i].norm_squared() > 0.0);
            lit.then_some(Sample { a, sigma, l })
        })
        .collect()
}

/// One pixel's residuals under some gains.
struct Residual {
    /// √(Σ r_i²/Σ A_i²).
    relative: f64,
    /// What noise alone gives: √((K − 3)/K · Σ σ_i²/Σ A_i²).
    noise_relative: f64,
    /// r_i/A_i.
    per_led: Vec<f64>,
    /// r_i/σ_i.
    per_led_sigmas: Vec<f64>,
}

/// The weighted least-squares G of readings `a` divided by `gains`, or `None` when the fit
/// is singular or faces away from every LED.
fn fit_g(s: &Sample, gains: &[f64]) -> Option<Vector3<f64>> {
    let (mut m, mut b) = (Matrix3::zeros(), Vector3::zeros());
    for ((l, a), (sigma, gain)) in s.l.iter().zip(&s.a).zip(s.sigma.iter().zip(gains)) {
        let w = 1.0 / (sigma * sigma);
        m += l * l.transpose() * w;
        b += l * (w * a / gain);
    }
    let g = m.cholesky()?.solve(&b);
    g.iter().all(|v| v.is_finite()).then_some(g)
}

/// Every sample's residuals with the LED intensities multiplied by `gains`.
fn residuals(samples: &[Sample], gains: &[f64]) -> Vec<Residual> {
    samples
        .par_iter()
        .filter_map(|s| {
            let g = fit_g(s, gains)?;
            let k = s.a.len();
            let r: Vec<f64> = (0..k).map(|i| s.a[i] - gains[i] * s.l[i].dot(&g)).collect();
            let energy: f64 = s.a.iter().map(|a| a * a).sum();
            let noise: f64 = s.sigma.iter().map(|s| s * s).sum();
            Some(Residual {
                relative: (r.iter().map(|r| r * r).sum::<f64>() / energy).sqrt(),
                noise_relative: ((k - 3) as f64 / k as f64 * noise / energy).sqrt(),
                per_led: (0..k).map(|i| r[i] / s.a[i]).collect(),
                per_led_sigmas: (0..k).map(|i| r[i] / s.sigma[i]).collect(),
            })
        })
        .collect()
}

/// Each LED's apparent intensity relative to the rig's (module docs), geometric mean 1.
fn fit_gains(samples: &[Sample]) -> Vec<f64> {
    let k = samples[0].a.len();
    let mut gains = vec![1.0; k];
    for _ in 0..GAIN_ITERATIONS {
        let fits: Vec<Option<Vector3<f64>>> =
            samples.par_iter().map(|s| fit_g(s, &gains)).collect();
        let next: Vec<f64> = (0..k)
            .map(|i| {
                let ratios: Vec<f64> = samples
                    .iter()
                    .zip(&fits)
                    .filter_map(|(s, g)| {
                        let predicted = s.l[i].dot(g.as_ref()?);
                        (predicted > LIT_SIGMAS * s.sigma[i]).then(|| s.a[i] / predicted)
                    })
                    .collect();
                if ratios.is_empty() {
                    1.0
                } else {
                    median(ratios)
                }
            })
            .collect();
        let log_mean = next.iter().map(|g| g.ln()).sum::<f64>() / k as f64;
        let scale = (-log_mean).exp();
        let moved = next
            .iter()
            .zip(&gains)
            .map(|(n, g)| (n * scale / g - 1.0).abs())
            .fold(0.0, f64::max);
        gains = next.iter().map(|g| g * scale).collect();
        if moved < 1e-5 {
            break;
        }
    }
    gains
}

/// The median (upper for an even count) of `values`; NaN when empty.
fn median(mut values: Vec<f64>) -> f64 {
    values.retain(|v| v.is_finite());
    if values.is_empty() {
        return f64::NAN;
    }
    let middle = values.len() / 2;
    *values.select_nth_unstable_by(middle, f64::total_cmp).1
}
