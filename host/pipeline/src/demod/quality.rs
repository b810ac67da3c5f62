//! How well the fitted timing explains each LED's modulation, and the verdict on a decode.
//!
//! On the pixel sample (centred values x_p, noise energy σ²_G = Σ_p σ_p² per direction, see
//! \[`super::spectrum`\]), for LED i with template t_i
//! (docs/maths/demodulation.md#the-received-signal) at each pixel's row:
//!
//! - signal: S_i = Σ_p (x_p·û_i)² − σ²_G, û_i the unit part of t_i orthogonal to the other
//!   templates, i.e. the energy only LED i explains; `signal_to_noise` = S_i / σ²_G.
//! - unexplained: U_i = Σ_p |Π_i (x_p − P_T x_p)|² − d_i·σ²_G, the energy left in LED i's
//!   subspace after the fit, above what noise alone leaves there. LED i's subspace is spanned
//!   by the strongest harmonics of its carrier at the fitted rate
//!   (docs/maths/demodulation.md#the-subspace-projection at ρ = 1: the DFT
//!   bins of LED i), orthogonalised against the templates (d_i directions). A wrong phase,
//!   rate, exposure or a rolling shutter the model misses leaves LED i's energy there.
//! - gain uncertainty: the timing's statistical uncertainty carried into the LED's gain
//!   ([`super::fit`]).
//! - changing pixels: when an LED leaves modulation unexplained, the sums are split by pixel
//!   (x_p's own share U_p = Σ_i |Π_i x_p|² − d_p·σ², S_p = Σ_i (x_p·û_i)²). A moving scene
//!   (a silhouette sweeping over a pixel, a shadow edge) changes a few pixels abruptly, and
//!   the step lands on the low harmonics that span the slow carriers' subspaces although the
//!   timing is right; a wrong timing leaves a misfit in proportion to every pixel's modulation
//!   (a wrong shift, rate or exposure moves or reshapes the same chip edges everywhere). So a
//!   pixel is set aside as changing when U_p exceeds noise alone by \[`CHANGING_NOISE_SIGMAS`\]
//!   standard deviations (σ²·√(2·d_p)) *and* its share U_p / S_p is \[`CHANGING_SHARE_RATIO`\]
//!   times the sample's median share; at most \[`MAX_CHANGING_SHARE`\] of the sample (beyond it
//!   the misfit is not local and nothing is set aside), and the LEDs' figures are measured
//!   again on the pixels kept. `changing_share` records what was set aside.
//!
//! A decode is implausible when an LED has no signal above noise, leaves a significant part of
//! its modulation unexplained, or has a gain uncertain by more than [`MAX_GAIN_UNCERTAINTY`] (1σ,
//! of the average over the decoding windows, [`judge_gains`]), or when a fitted rolling-shutter line
//! delay is not supported by the data (it lowers the cost by fewer than [`RAMP_SIGNIFICANCE`]
//! noise variances against the fit without it: a line delay can absorb a wrong exposure's
//! misfit, which the unexplained energy alone does not reveal).

use super::fit::{RAMP_SIGNIFICANCE, TimingFit};
use super::sample::PixelSample;
use super::spectrum::SignalSpace;
use super::waveform::ReceivedWaveform;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Below this signal-to-noise an LED's image is noise.
pub const MIN_SIGNAL_TO_NOISE: f64 = 1.0;
/// Unexplained energy, in noise directions, above which the fit is implausible …
pub const MAX_UNEXPLAINED: f64 = 3.0;
/// … when it is also this fraction of the LED's signal.
pub const MAX_UNEXPLAINED_FRACTION: f64 = 1e-3;
/// Largest relative 1σ gain uncertainty of a plausible decode: beyond 1 % the capture cannot
/// give the per-LED gains to the precision photometric stereo needs. (0.33 %, i.e. 1 % at 3σ,
/// refused the thesis rig's own cube at ±0.42 %, whose reconstruction is accurate.)
pub const MAX_GAIN_UNCERTAINTY: f64 = 0.01;
/// A changing pixel's unexplained energy exceeds noise alone by this many standard deviations …
const CHANGING_NOISE_SIGMAS: f64 = 6.0;
/// … and its unexplained share of its modulation is this many times the sample's median.
const CHANGING_SHARE_RATIO: f64 = 10.0;
/// Most of the pixel sample set aside as changing (module docs).
const MAX_CHANGING_SHARE: f64 = 0.2;
/// Harmonics of an LED's carrier spanning its subspace.
const HARMONICS: usize = 4;
/// A subspace direction shorter than this (relative) after orthogonalisation is dropped.
const DIRECTION_TOLERANCE: f64 = 0.1;

/// How well the fit explains one LED.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LedQuality {
    /// Energy only this LED explains, in noise directions (S_i / σ²_G).
    pub signal_to_noise: f64,
    /// Energy left in the LED's subspace beyond noise, in noise directions (U_i / σ²_G).
    pub unexplained: f64,
    /// The same as a fraction of the LED's signal energy.
    pub unexplained_fraction: f64,
    /// Relative 1σ uncertainty of the LED's gain from the timing fit.
    pub gain_uncertainty: f64,
    /// Share of the pixel sample set aside as changing during the window before these
    /// figures were measured (module docs; 0 when nothing was).
    #[serde(default)]
    pub changing_share: f64,
}

impl LedQuality {
    /// Whether the fit leaves more of this LED's modulation unexplained than the verdict
    /// accepts (above [`MAX_UNEXPLAINED`] noise levels and [`MAX_UNEXPLAINED_FRACTION`]).
    pub fn leaves_modulation_unexplained(&self) -> bool {
        self.unexplained > MAX_UNEXPLAINED && self.unexplained_fraction > MAX_UNEXPLAINED_FRACTION
    }
}

/// Whether a decode can be trusted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VerdictStatus {
    /// No verdict was recorded (a `decode.json` of an older version).
    #[default]
    Unchecked,
    /// Every check passed.
    Plausible,
    /// A check failed; the result was not kept.
    Implausible,
    /// A check failed and the result was kept anyway on request.
    Overridden,
}

/// The verdict on a decode (or a reconstruction, [`crate::reconstruct::Support`]), with what
/// looks wrong and what to try.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// The outcome.
    pub status: VerdictStatus,
    /// What looks wrong (empty when plausible).
    pub problems: Vec<String>,
    /// What to try.
    pub advice: Vec<String>,
}

impl Verdict {
    /// A verdict from its problems and advice.
    pub fn from_findings(problems: Vec<String>, advice: Vec<String>) -> Self {
        let status = if problems.is_empty() {
            VerdictStatus::Plausible
        } else {
            VerdictStatus::Implausible
        };
        Self {
            status,
            problems,
            advice,
        }
    }

    /// Whether the result may be used.
    pub fn is_plausible(&self) -> bool {
        self.status == VerdictStatus::Plausible
    }

    /// Combines the verdicts of two windows.
    pub fn merge(mut self, other: &Self) -> Self {
        for p in &other.problems {
            if !self.problems.contains(p) {
                self.problems.push(p.clone());
            }
        }
        for a in &other.advice {
            if !self.advice.contains(a) {
                self.advice.push(a.clone());
            }
        }
        Self::from_findings(self.problems, self.advice)
    }
}

/// What the sample says about a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FitQuality {
    /// Per LED.
    pub leds: Vec<LedQuality>,
    /// Mean least-squares on-level A_i of each LED over the sample's pixels.
    pub levels: Vec<f64>,
    /// RMS residual per frame sample of the sample's pixels (fraction of full scale).
    pub residual_rms: f64,
}

/// Measures each LED's quality (module docs); `gram` is the sample's Gram matrix (used when
/// every row shares one set of templates).
pub fn measure(
    sample: &PixelSample,
    gram: &DMatrix<f64>,
    space: &SignalSpace,
    fit: &TimingFit,
    waves: &[ReceivedWaveform],
) -> FitQuality {
    let frames = sample.frames();
    let model = &fit.model;
    let subspaces: Vec<Vec<Vec<f64>>> = waves
        .iter()
        .map(|w| led_subspace(w, model.timing.rate_ratio, frames))
        .collect();
    let mut sums = Sums::new(waves.len());
    if fit.rolling {
        for run in sample.row_runs() {
            let row = sample.rows()[run.start] as f64;
            let parts = Parts::new(model, waves, &subspaces, row, frames);
            let pixels: Vec<&[f64]> = run.clone().map(|p| sample.pixel(p)).collect();
            parts.add_pixels(&pixels, fit.pixel_noise, &mut sums);
        }
    } else {
        let parts = Parts::new(model, waves, &subspaces, 0.0, frames);
        let mut total = vec![0.0; frames];
        for p in 0..sample.len() {
            total
                .iter_mut()
                .zip(sample.pixel(p))
                .for_each(|(t, x)| *t += x);
        }
        parts.add_gram(gram, &total, sample.len(), fit.pixel_noise, &mut sums);
    }
    let pixels = sample.len().max(1) as f64;
    let dof = frames.saturating_sub(waves.len() + 1).max(1) as f64;
    let mut leds = summarise(&sums, space.noise, fit);
    if leds.iter().any(LedQuality::leaves_modulation_unexplained) {
        let shares = pixel_shares(sample, fit, waves, &subspaces);
        if let Some(kept) = without_changing_pixels(&shares, fit.pixel_noise) {
            let set_aside = shares.len() - kept.pixels;
            leds = summarise(&kept, fit.pixel_noise * kept.pixels as f64, fit);
            for led in &mut leds {
                led.changing_share = set_aside as f64 / shares.len() as f64;
            }
        }
    }
    FitQuality {
        leds,
        levels: sums.levels.iter().map(|s| s / pixels).collect(),
        residual_rms: (sums.residual.max(0.0) / (pixels * dof)).sqrt(),
    }
}

/// Each LED's figures from the `sums` over pixels whose noise energy per direction is `noise`.
fn summarise(sums: &Sums, noise: f64, fit: &TimingFit) -> Vec<LedQuality> {
    let noise = noise.max(f64::MIN_POSITIVE);
    (0..sums.signal.len())
        .map(|i| {
            let s = sums.signal[i] - noise;
            let u = sums.unexplained[i] - sums.expected[i];
            LedQuality {
                signal_to_noise: s / noise,
                unexplained: u / noise,
                unexplained_fraction: if s > 0.0 {
                    u.max(0.0) / s
                } else {
                    f64::INFINITY
                },
                gain_uncertainty: fit.gain_uncertainty.get(i).copied().unwrap_or(0.0),
                changing_share: 0.0,
            }
        })
        .collect()
}

/// One sample pixel's part of the per-LED sums of [`measure`].
#[derive(Debug, Clone, PartialEq)]
struct PixelShare {
    /// (x_p·û_i)² per LED.
    signal: Vec<f64>,
    /// |Π_i x_p|² per LED.
    unexplained: Vec<f64>,
    /// d_i, the directions of LED i's subspace left after the templates, per LED.
    directions: Vec<usize>,
}

/// Every sample pixel's [`PixelShare`] for the fitted timing.
fn pixel_shares(
    sample: &PixelSample,
    fit: &TimingFit,
    waves: &[ReceivedWaveform],
    subspaces: &[Vec<Vec<f64>>],
) -> Vec<PixelShare> {
    let frames = sample.frames();
    let whole = std::iter::once(0..sample.len());
    let runs: Vec<std::ops::Range<usize>> = if fit.rolling {
        sample.row_runs()
    } else {
        whole.collect()
    };
    let mut shares = Vec::with_capacity(sample.len());
    for run in runs {
        let row = if fit.rolling {
            sample.rows()[run.start] as f64
        } else {
            0.0
        };
        let parts = Parts::new(&fit.model, waves, subspaces, row, frames);
        shares.extend(run.map(|p| parts.share(sample.pixel(p))));
    }
    shares
}

/// The per-LED sums over the pixels that are not changing (module docs), or `None` when no
/// pixel is, or more than [`MAX_CHANGING_SHARE`] of them would be.
fn without_changing_pixels(shares: &[PixelShare], pixel_noise: f64) -> Option<Sums> {
    let excess = |p: &PixelShare| {
        let directions: usize = p.directions.iter().sum();
        let unexplained: f64 = p.unexplained.iter().sum();
        (
            unexplained - directions as f64 * pixel_noise,
            pixel_noise * (2.0 * directions as f64).sqrt(),
        )
    };
    let share = |p: &PixelShare| {
        let signal: f64 = p.signal.iter().sum();
        let (over, _) = excess(p);
        if signal > 0.0 {
            over.max(0.0) / signal
        } else {
            f64::INFINITY
        }
    };
    let mut shares_sorted: Vec<f64> = shares.iter().map(share).collect();
    let middle = shares_sorted.len() / 2;
    let (_, median, _) = shares_sorted.select_nth_unstable_by(middle, f64::total_cmp);
    let median = *median;
    let changing: Vec<bool> = shares
        .iter()
        .map(|p| {
            let (over, spread) = excess(p);
            over > CHANGING_NOISE_SIGMAS * spread && share(p) > CHANGING_SHARE_RATIO * median
        })
        .collect();
    let set_aside = changing.iter().filter(|&&c| c).count();
    if set_aside == 0 || set_aside as f64 > MAX_CHANGING_SHARE * shares.len() as f64 {
        return None;
    }
    let leds = shares.first().map_or(0, |p| p.signal.len());
    let mut sums = Sums::new(leds);
    for (p, _) in shares.iter().zip(&changing).filter(|(_, c)| !**c) {
        for i in 0..leds {
            sums.signal[i] += p.signal[i];
            sums.unexplained[i] += p.unexplained[i];
            sums.expected[i] += p.directions[i] as f64 * pixel_noise;
        }
    }
    sums.pixels = shares.len() - set_aside;
    Some(sums)
}

/// Running sums of [`measure`].
#[derive(Debug)]
struct Sums {
    signal: Vec<f64>,
    unexplained: Vec<f64>,
    expected: Vec<f64>,
    levels: Vec<f64>,
    residual: f64,
    /// Pixels summed (set by [`without_changing_pixels`]).
    pixels: usize,
}

impl Sums {
    fn new(leds: usize) -> Self {
        Self {
            signal: vec![0.0; leds],
            unexplained: vec![0.0; leds],
            expected: vec![0.0; leds],
            levels: vec![0.0; leds],
            residual: 0.0,
            pixels: 0,
        }
    }
}

/// The directions [`measure`] projects on for one set of templates.
struct Parts {
    basis: super::basis::TemplateBasis,
    /// Per LED: the unit part of its template no other template explains.
    unique: Vec<Vec<f64>>,
    /// Per LED: its subspace orthogonal to the templates.
    left: Vec<Vec<Vec<f64>>>,
}

impl Parts {
    fn new(
        model: &super::fit::TimingModel,
        waves: &[ReceivedWaveform],
        subspaces: &[Vec<Vec<f64>>],
        row: f64,
        frames: usize,
    ) -> Self {
        let columns = model.columns(waves, row, frames);
        let basis = model.basis(waves, row, frames);
        let unique = (0..waves.len())
            .map(|i| unique_direction(&columns, i + 1))
            .collect();
        let left = subspaces
            .iter()
            .map(|s| orthonormal_complement(s, &basis.rows))
            .collect();
        Self {
            basis,
            unique,
            left,
        }
    }

    /// LED `i`'s signal (x·û_i)² and unexplained energy |Π_i x|² in one pixel `x` (a left
    /// direction is orthogonal to the templates, so bᵀ(x − P_T x) = bᵀx).
    fn energies(&self, i: usize, x: &[f64]) -> (f64, f64) {
        let signal = dot(&self.unique[i], x).powi(2);
        let unexplained = self.left[i].iter().map(|b| dot(b, x).powi(2)).sum::<f64>();
        (signal, unexplained)
    }

    /// One pixel's part of the per-LED sums.
    fn share(&self, x: &[f64]) -> PixelShare {
        let (signal, unexplained) = (0..self.unique.len()).map(|i| self.energies(i, x)).unzip();
        PixelShare {
            signal,
            unexplained,
            directions: self.left.iter().map(Vec::len).collect(),
        }
    }

    /// Adds pixels one by one.
    fn add_pixels(&self, pixels: &[&[f64]], pixel_noise: f64, sums: &mut Sums) {
        let k = self.basis.columns;
        let mut projections = vec![0.0; k];
        let mut coefficients = vec![0.0; k];
        let mut residual = Vec::new();
        for x in pixels {
            residual.clear();
            residual.extend_from_slice(x);
            for (q, b) in self.basis.rows.iter().zip(projections.iter_mut()) {
                *b = dot(q, x);
                residual.iter_mut().zip(q).for_each(|(r, v)| *r -= *b * v);
            }
            self.basis.coefficients(&projections, &mut coefficients);
            sums.levels
                .iter_mut()
                .zip(&coefficients[1..])
                .for_each(|(s, c)| *s += c);
            sums.residual += dot(&residual, &residual);
            for i in 0..self.unique.len() {
                let (signal, unexplained) = self.energies(i, x);
                sums.signal[i] += signal;
                sums.unexplained[i] += unexplained;
            }
        }
        for (e, l) in sums.expected.iter_mut().zip(&self.left) {
            *e += l.len() as f64 * pixels.len() as f64 * pixel_noise;
        }
    }

    /// Adds `pixels` pixels at once from their Gram matrix and summed values.
    fn add_gram(
        &self,
        gram: &DMatrix<f64>,
        total: &[f64],
        pixels: usize,
        pixel_noise: f64,
        sums: &mut Sums,
    ) {
        let energy = |v: &[f64]| {
            let v = DVector::from_column_slice(v);
            (v.transpose() * gram * &v)[(0, 0)]
        };
        let k = self.basis.columns;
        let projections: Vec<f64> = self.basis.rows.iter().map(|q| dot(q, total)).collect();
        let mut coefficients = vec![0.0; k];
        self.basis.coefficients(&projections, &mut coefficients);
        sums.levels
            .iter_mut()
            .zip(&coefficients[1..])
            .for_each(|(s, c)| *s += c);
        let explained: f64 = self.basis.rows.iter().map(|q| energy(q)).sum();
        sums.residual += gram.trace() - explained;
        for (i, (u, left)) in self.unique.iter().zip(&self.left).enumerate() {
            sums.signal[i] += energy(u);
            sums.unexplained[i] += left.iter().map(|b| energy(b)).sum::<f64>();
            sums.expected[i] += left.len() as f64 * pixels as f64 * pixel_noise;
        }
    }
}

/// Each LED's relative 1σ gain uncertainty of the average over windows whose own are
/// `windows` (one entry per window, one value per LED): every window's timing is fitted on its
/// own frames, so their gain errors are independent and the average's is √(Σ u_w²)/W.
pub fn combined_gain_uncertainty(windows: &[Vec<f64>]) -> Vec<f64> {
    let count = windows.len().max(1) as f64;
    let leds = windows.iter().map(Vec::len).max().unwrap_or(0);
    (0..leds)
        .map(|i| {
            let sum: f64 = windows
                .iter()
                .map(|w| w.get(i).copied().unwrap_or(0.0).powi(2))
                .sum();
            sum.sqrt() / count
        })
        .collect()
}

/// The verdict on the LEDs' gains of a decode averaged over windows: implausible when an LED's
/// combined uncertainty ([`combined_gain_uncertainty`]) exceeds [`MAX_GAIN_UNCERTAINTY`].
pub fn judge_gains(combined: &[f64]) -> Verdict {
    let mut problems = Vec::new();
    for (i, &u) in combined.iter().enumerate() {
        if u > MAX_GAIN_UNCERTAINTY {
            problems.push(format!(
                "LED {}'s gain is only determined to ±{:.2} % (1σ) by this capture",
                i + 1,
                100.0 * u
            ));
        }
    }
    let advice = if problems.is_empty() {
        Vec::new()
    } else {
        vec!["decode more frames, expose brighter or with less noise, or give the exposure".into()]
    };
    Verdict::from_findings(problems, advice)
}

/// The verdict for one window's LED qualities and timing fit (the gains are judged over the
/// windows, [`judge_gains`]).
pub fn judge(quality: &[LedQuality], fit: &TimingFit) -> Verdict {
    let mut problems = Vec::new();
    let mut advice = Vec::new();
    let mut advise = |text: &str| {
        if !advice.iter().any(|a: &String| a == text) {
            advice.push(text.to_string());
        }
    };
    for (i, q) in quality.iter().enumerate() {
        let led = i + 1;
        if q.signal_to_noise.is_nan() || q.signal_to_noise < MIN_SIGNAL_TO_NOISE {
            problems.push(format!(
                "LED {led} shows no modulation above noise (signal-to-noise {:.2})",
                q.signal_to_noise
            ));
            advise("check that every LED is on and lights the scene, or decode fewer LEDs");
            continue;
        }
        if q.leaves_modulation_unexplained() {
            problems.push(format!(
                "the fitted waveform leaves {:.2} % of LED {led}'s modulation unexplained \
                 ({:.1} noise levels)",
                100.0 * q.unexplained_fraction,
                q.unexplained
            ));
            advise(
                "give the chip rate / rate ratio, exposure or rolling-shutter line time if known, \
                 and check the code-value linearisation (gamma)",
            );
        }
    }
    if fit.rate_at_limit {
        problems.push("the rate ratio sits at the edge of the searched range".into());
        advise("widen the rate-ratio search or give the chip rate");
    }
    if fit.line_delay_undetermined() {
        problems.push(format!(
            "the fitted rolling-shutter line delay ({:.3e} frame periods per row) explains \
             {:.1} noise variances, fewer than {RAMP_SIGNIFICANCE}: the data do not show one",
            fit.model.line_delay, fit.line_delay_evidence
        ));
        advise("give the rolling-shutter line time (0 for a global shutter)");
    }
    if fit.line_delay_at_limit {
        problems.push(
            "the rolling-shutter line delay sits at the largest one searched (a readout of \
             1.5 frame periods over the region)"
                .into(),
        );
        advise("give the rolling-shutter line time");
    }
    Verdict::from_findings(problems, advice)
}

/// Dot product.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Unit part of `columns[index]` orthogonal to every other column (zero if none is left).
fn unique_direction(columns: &[Vec<f64>], index: usize) -> Vec<f64> {
    let others: Vec<Vec<f64>> = columns
        .iter()
        .enumerate()
        .filter(|(k, _)| *k != index)
        .map(|(_, c)| c.clone())
        .collect();
    let basis = orthonormal_complement(&others, &[]);
    let mut v = columns.get(index).cloned().unwrap_or_default();
    for q in &basis {
        let c = dot(q, &v);
        v.iter_mut().zip(q).for_each(|(x, y)| *x -= c * y);
    }
    let norm = dot(&v, &v).sqrt();
    if norm > 1e-12 {
        v.iter_mut().for_each(|x| *x /= norm);
    } else {
        v.iter_mut().for_each(|x| *x = 0.0);
    }
    v
}

/// Orthonormal basis (modified Gram–Schmidt, twice) of `vectors` made orthogonal to the
/// orthonormal `against`; directions that shrink below [`DIRECTION_TOLERANCE`] are dropped.
fn orthonormal_complement(vectors: &[Vec<f64>], against: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for v in vectors {
        let scale = dot(v, v).sqrt();
        if scale < 1e-12 {
            continue;
        }
        let mut w = v.clone();
        for _ in 0..2 {
            for q in against.iter().chain(basis.iter()) {
                let c = dot(q, &w);
                w.iter_mut().zip(q).for_each(|(x, y)| *x -= c * y);
            }
        }
        let norm = dot(&w, &w).sqrt();
        if norm > DIRECTION_TOLERANCE * scale {
            w.iter_mut().for_each(|x| *x /= norm);
            basis.push(w);
        }
    }
    basis
}

/// The centred cosine and sine columns of LED `wave`'s [`HARMONICS`] strongest harmonics at
/// rate ratio `rate` over `frames` frames (not yet orthonormal).
pub(super) fn led_subspace(wave: &ReceivedWaveform, rate: f64, frames: usize) -> Vec<Vec<f64>> {
    let period = wave.period();
    let chips: Vec<f64> = (0..period).map(|m| wave.chip(m)).collect();
    // |c_m| of the chip-level carrier: |DFT_m| / P · |sinc(m / P)|, m odd (only odd ones
    // exist: a half-period shift negates the carrier).
    let mut strengths: Vec<(f64, usize)> = (1..3 * period)
        .step_by(2)
        .map(|m| {
            let (mut re, mut im) = (0.0, 0.0);
            for (k, s) in chips.iter().enumerate() {
                let angle = -std::f64::consts::TAU * (m * k) as f64 / period as f64;
                re += s * angle.cos();
                im += s * angle.sin();
            }
            let x = std::f64::consts::PI * m as f64 / period as f64;
            (
                (re * re + im * im).sqrt() / period as f64 * (x.sin() / x).abs(),
                m,
            )
        })
        .collect();
    strengths.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut columns = Vec::new();
    for &(_, m) in strengths.iter().take(HARMONICS) {
        let frequency = std::f64::consts::TAU * rate * m as f64 / period as f64;
        for phase in [0.0, std::f64::consts::FRAC_PI_2] {
            let mut column: Vec<f64> = (0..frames)
                .map(|j| (frequency * j as f64 + phase).cos())
                .collect();
            let mean = column.iter().sum::<f64>() / frames.max(1) as f64;
            column.iter_mut().for_each(|v| *v -= mean);
            wave.project(&mut column);
            columns.push(column);
        }
    }
    columns
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pixel of 4 LEDs with modulation `signal` per LED and `unexplained` per LED on top of
    /// noise alone (8 directions per LED, noise 1 per direction).
    fn pixel(signal: f64, unexplained: f64) -> PixelShare {
        PixelShare {
            signal: vec![signal; 4],
            unexplained: vec![8.0 + unexplained; 4],
            directions: vec![8; 4],
        }
    }

    #[test]
    fn a_few_pixels_the_scene_changed_are_set_aside() {
        // 95 pixels the fit explains (noise only), 5 with a large local misfit (an edge).
        let mut shares: Vec<PixelShare> = (0..95).map(|k| pixel(1e3 + k as f64, 0.5)).collect();
        shares.extend((0..5).map(|_| pixel(1e3, 200.0)));
        let kept = without_changing_pixels(&shares, 1.0).expect("the edge pixels are set aside");
        assert_eq!(kept.pixels, 95);
        for i in 0..4 {
            let excess = kept.unexplained[i] - kept.expected[i];
            assert!((excess - 95.0 * 0.5).abs() < 1e-9, "LED {i}: {excess}");
        }
    }

    #[test]
    fn a_misfit_in_proportion_to_the_modulation_is_kept() {
        // A wrong timing: every pixel leaves the same share of its modulation unexplained,
        // bright and dim alike, so nothing is set aside and the misfit stays measured.
        let shares: Vec<PixelShare> = (0..100)
            .map(|k| {
                let signal = 100.0 * (1 + k % 20) as f64;
                pixel(signal, 0.05 * signal)
            })
            .collect();
        assert!(without_changing_pixels(&shares, 1.0).is_none());
    }

    #[test]
    fn a_misfit_on_many_pixels_is_not_set_aside() {
        // 30 % of the sample far off: more than a local change, so nothing is set aside.
        let shares: Vec<PixelShare> = (0..100)
            .map(|k| pixel(1e3, if k % 10 < 3 { 500.0 } else { 0.0 }))
            .collect();
        assert!(without_changing_pixels(&shares, 1.0).is_none());
    }
}
