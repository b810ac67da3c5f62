//! Nuisance components of a real room: mains flicker and a drifting exposure, found in a window
//! and projected out with the carriers.
//!
//! A room lamp on mains of frequency f_m adds to every pixel a(p)·w(t), w periodic at 2·f_m
//! (any waveform: harmonics at h·2·f_m), a(p) the lamp's light on the pixel. Sampled at F frames
//! of rate fps, harmonic h is a sinusoid at ν_h = h·2·f_m/fps cycles per frame (aliased into
//! [0, ½]); f_m is free within ±0.5 % of 50 or 60 Hz, which over a window of F frames moves the
//! phase by up to 0.005·h·2·f_m·F/fps cycles, so each harmonic is modelled by four columns,
//! cos, sin, τ·cos and τ·sin (τ the centred frame time): the first-order expansion of a
//! sinusoid of slightly unknown frequency and slowly varying amplitude. At an unknown frame rate
//! (image files) the fundamental is scanned over the whole band in cycles per frame, a quarter
//! bin apart (the frequency holding the most energy), and tested the same way. An
//! auto-exposure that drifts multiplies the frame by g(j) ≈ 1 + g₁·τ + g₂·τ²; on the
//! background B(p) that is B(p)·(g(j) − 1), spanned by the Legendre columns τ and τ² − mean.
//!
//! Each pixel then reads r = 1·b + T·a + P·c + noise, P the nuisance columns (orthonormal,
//! orthogonal to the constant) and T the LEDs' templates. By the Frisch–Waugh–Lovell theorem
//! (R. Frisch, F. V. Waugh, "Partial time regressions as compared with individual trends",
//! Econometrica 1933; M. C. Lovell, "Seasonal adjustment of economic time series and multiple
//! regression analysis", J. Am. Stat. Assoc. 1963) the least-squares a of that model are those of
//! r against the projected templates T' = (I − PPᵀ)·T: so every template the decoder forms (seed
//! scores, timing fit, per-pixel filter, quality) is projected ([`Nuisance::project`]), the
//! timing sample is projected once, and the per-pixel filter keeps its size. Where a harmonic
//! coincides with a carrier's line, T' loses that line and the LED's gain rests on its other
//! harmonics (unbiased, noisier).
//!
//! Detection ([`detect`]) tests each candidate against the window's Gram matrix G = XᵀX of
//! the centred pixel sample after removing what the carriers explain: a timing fit's
//! templates and the carriers' strongest harmonics at its rate (the subspace C of
//! [`super::quality`]), G' = (I − CCᵀ)·G·(I − CCᵀ). Without a fit the carriers' weaker lines
//! and any misfit of a scanned rate stand far above the noise (hundreds of noise levels beside
//! the lines in a steady capture), so the decoder tests before a fit only when the LED-count
//! check refused the window. The energy per direction q'ᵀG'q' (q' = (I − CCᵀ)q normalised)
//! of a candidate is compared with the noise energy per direction σ²_G and with nearby
//! control frequencies (or, for the drift, the next two Legendre degrees), which carry the
//! same leakage from the carriers' weaker harmonics and from a misfit: a component counts
//! when its energy per direction exceeds [`DETECTION_RATIO`] times the larger of the two,
//! exceeds the noise by [`DETECTION_SIGMAS`] standard deviations of the noise's energy, and
//! does both in the top and in the bottom half of the sample (a lamp lights the whole view).
//! A false detection costs a little of the carriers' energy (the projection keeps the
//! estimates unbiased), a missed one biases the gains.

use super::waveform::ReceivedWaveform;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Nominal flicker fundamentals: twice the 50 and 60 Hz mains.
pub const FLICKER_FAMILIES_HZ: [f64; 2] = [100.0, 120.0];
/// Largest relative offset of the mains frequency from nominal.
pub const MAINS_TOLERANCE: f64 = 0.005;
/// Steps of the mains-frequency scan across ±[`MAINS_TOLERANCE`].
const MAINS_STEPS: usize = 21;
/// Flicker harmonics tested.
pub const MAX_HARMONICS: usize = 8;
/// A component counts when its energy per direction exceeds this multiple of the noise's and of
/// its controls'.
pub const DETECTION_RATIO: f64 = 4.0;
/// … and when its excess over the noise exceeds this many standard deviations of the noise
/// energy (a white-noise sample's energy per direction spreads by σ²_G·√(2/(P·d))).
pub const DETECTION_SIGMAS: f64 = 10.0;
/// Harmonics landing within this many bins of a lower one are not tested on their own.
const ALIAS_BINS: f64 = 1.5;
/// Control frequencies beside a candidate, in frequency bins (1/F) either side.
const CONTROL_OFFSETS: [f64; 4] = [2.5, 3.5, 4.5, 5.5];
/// A candidate keeping less than this share of its norm outside the carriers' harmonics lies on
/// a carrier line: it cannot be told apart from the carrier.
const SEPARABLE_SHARE: f64 = 0.5;
/// Harmonics of each carrier removed before testing (as [`super::quality`]'s subspaces).
const CARRIER_HARMONICS: usize = 4;

/// Steps per frequency bin (1/F) of the scan for flicker at an unknown frame rate.
const ANY_RATE_STEPS_PER_BIN: usize = 4;

/// Flicker found in a window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Flicker {
    /// Nominal flicker fundamental of the family, Hz (100 for 50 Hz mains, 120 for 60 Hz; 0
    /// when the frame rate is unknown and the flicker was found by its frequency in frames).
    pub nominal_hz: f64,
    /// Best-fitting flicker fundamental, Hz (twice the mains frequency; 0 when the frame rate
    /// is unknown).
    pub frequency_hz: f64,
    /// Where the fundamental lands, cycles per frame (aliased into [0, ½]).
    #[serde(default)]
    pub cycles_per_frame: f64,
    /// Harmonics (multiples of the fundamental) found and projected out.
    pub harmonics: Vec<usize>,
    /// Amplitude of the strongest harmonic, RMS over the sampled pixels, fraction of full scale.
    pub amplitude: f64,
    /// Harmonics that fall on a carrier's line at this camera rate: their flicker cannot be
    /// measured apart from that carrier, and projecting them out costs that carrier's line.
    pub on_carrier_lines: Vec<usize>,
}

/// An exposure drift found in a window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Drift {
    /// Relative change of the frames' gain from the window's first frame to its last.
    pub relative_change: f64,
}

/// What a decode found of the room over its windows (`decode.json`'s `room`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct RoomReport {
    /// Mains flicker per family found, from the window where it was strongest.
    pub flicker: Vec<Flicker>,
    /// Exposure drift: relative gain change over the window, largest over the windows
    /// (`None`: none found).
    pub exposure_drift: Option<f64>,
    /// Windows in which some nuisance component was found and projected out.
    pub windows_modelled: usize,
    /// Frames the camera dropped or repeated, found from the data and re-aligned
    /// ([`super::timing_break`]).
    #[serde(default)]
    pub timing_breaks: Vec<super::timing_break::TimingBreak>,
    /// Frame periods the container's timestamps show missing, frames counted from the first
    /// frame decoded ([`meb_core::capture::clock`]).
    #[serde(default)]
    pub container_gaps: Vec<meb_core::capture::clock::TimestampGap>,
}

impl RoomReport {
    /// Whether nothing of the room was found: no flicker, no drift, no timing break.
    pub fn is_quiet(&self) -> bool {
        self.flicker.is_empty()
            && self.exposure_drift.is_none()
            && self.timing_breaks.is_empty()
            && self.container_gaps.is_empty()
    }

    /// Adds one window's findings.
    pub fn add(&mut self, window: &Nuisance) {
        if window.is_empty() && window.flicker.is_empty() {
            return;
        }
        self.windows_modelled += usize::from(!window.is_empty());
        for found in &window.flicker {
            match self
                .flicker
                .iter_mut()
                .find(|f| f.nominal_hz == found.nominal_hz)
            {
                Some(f) if f.amplitude >= found.amplitude => {}
                Some(f) => *f = found.clone(),
                None => self.flicker.push(found.clone()),
            }
        }
        if let Some(drift) = &window.drift {
            let change = drift.relative_change;
            if self.exposure_drift.is_none_or(|d| change.abs() > d.abs()) {
                self.exposure_drift = Some(change);
            }
        }
    }
}

/// The nuisance components of one window and their orthonormal columns.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Nuisance {
    frames: usize,
    /// Orthonormal columns (F values each), orthogonal to the constant.
    columns: Vec<Vec<f64>>,
    /// Mains flicker found.
    pub flicker: Vec<Flicker>,
    /// Exposure drift found.
    pub drift: Option<Drift>,
    /// The drift's gain g(j) relative to the window's mean (empty without a drift): the
    /// carriers' templates are multiplied by it, A_i·g·t_i being what a drifting camera records.
    gain: Vec<f64>,
}

impl Nuisance {
    /// Whether nothing was found.
    pub fn is_empty(&self) -> bool {
        self.columns.is_empty()
    }

    /// Number of nuisance columns.
    pub fn columns(&self) -> usize {
        self.columns.len()
    }

    /// What was found, in words (`None` when nothing was): the flicker per family with its
    /// frequency and level, and the exposure drift.
    pub fn describe(&self) -> Option<String> {
        let mut parts: Vec<String> = self
            .flicker
            .iter()
            .map(|f| {
                format!(
                    "flicker at {:.1} Hz ({:.1} Hz mains, harmonics {:?}, {:.2} % of full scale)",
                    f.frequency_hz,
                    f.frequency_hz / 2.0,
                    f.harmonics,
                    100.0 * f.amplitude
                )
            })
            .collect();
        if let Some(drift) = &self.drift {
            parts.push(format!(
                "exposure drift ({:+.1} % over the window)",
                100.0 * drift.relative_change
            ));
        }
        (!parts.is_empty()).then(|| parts.join(" and "))
    }

    /// v ← (I − PPᵀ)·v, for a vector of the window's length (others are left alone).
    pub fn project(&self, v: &mut [f64]) {
        if v.len() != self.frames {
            return;
        }
        self.project_only(v);
    }

    /// A carrier template t ← (I − PPᵀ)·(g·t): the drift's gain applied, then projected.
    pub fn project_template(&self, v: &mut [f64]) {
        if v.len() != self.frames {
            return;
        }
        if self.gain.len() == v.len() {
            v.iter_mut().zip(&self.gain).for_each(|(x, g)| *x *= g);
        }
        self.project_only(v);
    }

    /// (I − PPᵀ)·v.
    fn project_only(&self, v: &mut [f64]) {
        for q in &self.columns {
            let d = dot(q, v);
            v.iter_mut().zip(q).for_each(|(x, &y)| *x -= d * y);
        }
    }

    /// (I − PPᵀ)·G·(I − PPᵀ) of an F × F matrix.
    pub fn project_gram(&self, gram: &DMatrix<f64>) -> DMatrix<f64> {
        let m = complement(&self.columns, self.frames);
        &m * gram * &m
    }
}

/// What [`detect`] needs to know about the window.
pub struct Window<'a> {
    /// Centred pixel values, pixel-major (`frames` per pixel).
    pub values: &'a [f64],
    /// Each pixel's mean (the background with the LEDs' mean light), fraction of full scale.
    pub means: &'a [f64],
    /// Gram matrix of the centred values.
    pub gram: &'a DMatrix<f64>,
    /// Frames F.
    pub frames: usize,
    /// σ²_G: noise energy per direction, summed over the pixels.
    pub noise: f64,
}

/// Finds mains flicker and exposure drift in `window` (module docs): `fps` the camera rate
/// (0 when unknown: then flicker of any frequency in frames, scanned over the whole band),
/// `rate` the chips per frame, `leds` the LEDs whose carriers' strongest lines are removed
/// before testing, and `fitted` further columns removed with them (a timing fit's templates).
pub fn detect(
    window: &Window<'_>,
    fps: f64,
    rate: f64,
    leds: usize,
    fitted: &[Vec<f64>],
) -> Nuisance {
    let f = window.frames;
    let pixels = window.means.len();
    if f < 16 || pixels < 2 {
        return Nuisance::default();
    }
    // Mains flicker lies at known frequencies in Hz, which a known frame rate places in
    // frames; a drift is smooth in frames.
    let rate_known = fps.is_finite() && fps > 0.0;
    let mut carriers = carrier_columns(rate, leds, f);
    carriers = orthonormal(
        &fitted
            .iter()
            .filter(|c| c.len() == f)
            .cloned()
            .collect::<Vec<_>>(),
        &[vec![1.0; f]],
    )
    .into_iter()
    .chain(carriers)
    .collect();
    let carriers = orthonormal(&carriers, &[vec![1.0; f]]);
    let m = complement(&carriers, f);
    let whole = Evidence::new(&m, window.gram, window.noise, pixels);
    let mut nuisance = Nuisance {
        frames: f,
        ..Nuisance::default()
    };
    // The halves of the sample (its pixels are in row order: the top and the bottom of the
    // region), formed only when a candidate stands out in the whole sample.
    let mut halves: Option<[Evidence; 2]> = None;
    let mut consistent = |test: &dyn Fn(&Evidence) -> bool| {
        let halves = halves.get_or_insert_with(|| Evidence::halves(&m, window, &whole));
        halves.iter().all(test)
    };
    let mut columns: Vec<Vec<f64>> = Vec::new();
    // The family with more energy at its harmonics is tested first; the other is tested with
    // the first's columns set aside too (at some camera rates harmonics of 100 and 120 Hz
    // alias onto the same frequencies).
    // At an unknown frame rate a lamp's flicker is a periodic component of unknown frequency
    // in frames: its fundamental is scanned over the whole band, in cycles per frame (a rate of
    // one frame per "second"), as one family of nominal 0.
    let (mut families, fps): (Vec<(f64, f64, f64)>, f64) = if rate_known {
        let families = FLICKER_FAMILIES_HZ
            .iter()
            .filter_map(|&nominal| {
                scan_family(nominal, fps, f, &whole).map(|(at, total)| (nominal, at, total))
            })
            .collect();
        (families, fps)
    } else {
        let families = scan_any_rate(f, &whole)
            .map(|(at, total)| (0.0, at, total))
            .into_iter()
            .collect();
        (families, 1.0)
    };
    families.sort_by(|a, b| b.2.total_cmp(&a.2));
    for (nominal, fundamental, _) in families {
        let found = if columns.is_empty() {
            flicker_at(nominal, fundamental, fps, f, &whole, &mut consistent)
        } else {
            let set_aside: Vec<Vec<f64>> = carriers.iter().chain(&columns).cloned().collect();
            let m = complement(&orthonormal(&set_aside, &[vec![1.0; f]]), f);
            let whole = Evidence::new(&m, window.gram, window.noise, pixels);
            let mut halves: Option<[Evidence; 2]> = None;
            let mut consistent = |test: &dyn Fn(&Evidence) -> bool| {
                let halves = halves.get_or_insert_with(|| Evidence::halves(&m, window, &whole));
                halves.iter().all(test)
            };
            flicker_at(nominal, fundamental, fps, f, &whole, &mut consistent)
        };
        if let Some((flicker, found)) = found {
            columns.extend(found);
            nuisance.flicker.push(flicker);
        }
    }
    // Drift: Legendre degrees 1 and 2 against degrees 3 and 4.
    let legendre: Vec<Vec<f64>> = orthonormal(
        &(1..=4)
            .map(|d| (0..f).map(|j| centred_time(j, f).powi(d)).collect())
            .collect::<Vec<_>>(),
        &[vec![1.0; f]],
    );
    if legendre.len() == 4 {
        let test = |e: &Evidence| {
            let (low, _) = e.energy(&legendre[..2]);
            let (control, _) = e.energy(&legendre[2..]);
            e.stands_out(low, control, 2)
        };
        if test(&whole) && consistent(&test) {
            let smooth = drift_series(window, &legendre[..2]);
            nuisance.drift = Some(Drift {
                relative_change: smooth[f - 1] - smooth[0],
            });
            nuisance.gain = smooth.iter().map(|d| 1.0 + d).collect();
            columns.extend(legendre[..2].iter().cloned());
        }
    }
    nuisance.columns = orthonormal(&columns, &[vec![1.0; f]]);
    nuisance
}

/// Whether a test of a candidate holds in each half of the sample too.
type Consistent<'c> = dyn FnMut(&dyn Fn(&Evidence) -> bool) -> bool + 'c;

/// A pixel set's energies with the carriers' lines removed, against which candidates are
/// tested (module docs).
struct Evidence<'a> {
    /// I − CCᵀ, C the carriers' strongest lines.
    carriers: &'a DMatrix<f64>,
    /// (I − CCᵀ)·G·(I − CCᵀ) of the set's Gram matrix G.
    residual: DMatrix<f64>,
    /// σ²_G of the set: noise energy per direction.
    noise: f64,
    /// Pixels in the set.
    pixels: usize,
}

impl<'a> Evidence<'a> {
    fn new(carriers: &'a DMatrix<f64>, gram: &DMatrix<f64>, noise: f64, pixels: usize) -> Self {
        Self {
            carriers,
            residual: carriers * gram * carriers,
            noise: noise.max(f64::MIN_POSITIVE),
            pixels,
        }
    }

    /// The top and bottom halves of the window's sample, each with its share of the noise.
    fn halves(carriers: &'a DMatrix<f64>, window: &Window<'_>, whole: &Self) -> [Self; 2] {
        let f = window.frames;
        let split = whole.pixels / 2;
        let top = DMatrix::from_row_slice(split, f, &window.values[..split * f]);
        let top_gram = top.tr_mul(&top);
        let bottom_gram = window.gram - &top_gram;
        let share = split as f64 / whole.pixels as f64;
        [
            Self::new(carriers, &top_gram, whole.noise * share, split),
            Self::new(
                carriers,
                &bottom_gram,
                whole.noise * (1.0 - share),
                whole.pixels - split,
            ),
        ]
    }

    /// Energy per direction of the span of `columns` with the carriers' lines removed, and
    /// the least share of a column's norm left by that removal.
    fn energy(&self, columns: &[Vec<f64>]) -> (f64, f64) {
        let projected: Vec<Vec<f64>> = columns.iter().map(|c| apply(self.carriers, c)).collect();
        let kept = columns
            .iter()
            .zip(&projected)
            .map(|(c, p)| dot(p, p) / dot(c, c).max(f64::MIN_POSITIVE))
            .fold(1.0f64, f64::min);
        let basis = orthonormal(&projected, &[]);
        if basis.is_empty() {
            return (0.0, 0.0);
        }
        let total: f64 = basis.iter().map(|q| quadratic(&self.residual, q)).sum();
        (total / basis.len() as f64, kept)
    }

    /// Whether energy per direction `energy` over `directions` directions stands out: above
    /// [`DETECTION_RATIO`] times the larger of the noise and the `control` energy, and above
    /// the noise by [`DETECTION_SIGMAS`] of the noise energy's own spread (σ²_G·√(2/(P·d)) for
    /// P pixels of white noise over d directions).
    fn stands_out(&self, energy: f64, control: f64, directions: usize) -> bool {
        let spread = self.noise * (2.0 / (self.pixels * directions.max(1)) as f64).sqrt();
        energy > DETECTION_RATIO * self.noise.max(control)
            && energy - self.noise > DETECTION_SIGMAS * spread
    }

    /// The excess energy per direction above the larger of the noise and `control`.
    fn excess(&self, energy: f64, control: f64) -> f64 {
        (energy - self.noise.max(control)).max(0.0)
    }
}

/// The fundamental (within the mains tolerance of `nominal` Hz) whose two lowest harmonics
/// hold the most energy in `whole`, and that energy. Only the lowest harmonics, where a lamp's
/// flicker is strongest, are summed: at some camera rates a higher harmonic of one family
/// aliases onto the other's fundamental (at 720 fps, 600 Hz lands on 120 Hz), and the family
/// that is there must be tested first.
fn scan_family(nominal: f64, fps: f64, f: usize, whole: &Evidence<'_>) -> Option<(f64, f64)> {
    let bin = 1.0 / f as f64;
    let mut best: Option<(f64, f64)> = None;
    for step in 0..MAINS_STEPS {
        let offset = MAINS_TOLERANCE * (2.0 * step as f64 / (MAINS_STEPS - 1) as f64 - 1.0);
        let fundamental = nominal * (1.0 + offset);
        let total: f64 = harmonics_of(fundamental, fps, bin)
            .into_iter()
            .filter(|&(h, _)| h <= 2)
            .map(|(_, nu)| whole.energy(&pair(nu, f)).0)
            .sum();
        if best.is_none_or(|(_, e)| total > e) {
            best = Some((fundamental, total));
        }
    }
    best
}

/// The frequency in cycles per frame, anywhere a window of `f` frames resolves, that holds the
/// most energy in `whole`, and that energy: the fundamental of a flicker of unknown frequency
/// (a lamp's flicker is strongest there; summing higher harmonics as [`scan_family`] does would
/// favour a subharmonic, whose second harmonic is the flicker's fundamental).
fn scan_any_rate(f: usize, whole: &Evidence<'_>) -> Option<(f64, f64)> {
    let bin = 1.0 / f as f64;
    let step = bin / ANY_RATE_STEPS_PER_BIN as f64;
    let mut best: Option<(f64, f64)> = None;
    let mut fundamental = 1.5 * bin + step;
    while fundamental < 0.5 - 0.5 * bin {
        let total = whole.energy(&pair(fundamental, f)).0;
        if best.is_none_or(|(_, e)| total > e) {
            best = Some((fundamental, total));
        }
        fundamental += step;
    }
    best
}

/// The harmonics h ≤ [`MAX_HARMONICS`] of `fundamental` Hz and where they land (cycles per
/// frame) that a window of bins `bin` resolves, each more than [`ALIAS_BINS`] bins from the
/// lower ones (a harmonic aliased onto a lower one's frequency adds no column of its own).
fn harmonics_of(fundamental: f64, fps: f64, bin: f64) -> Vec<(usize, f64)> {
    let mut found: Vec<(usize, f64)> = Vec::new();
    for h in 1..=MAX_HARMONICS {
        let Some(nu) = usable(alias(h as f64 * fundamental / fps), bin) else {
            continue;
        };
        if found
            .iter()
            .all(|&(_, at)| (at - nu).abs() > ALIAS_BINS * bin)
        {
            found.push((h, nu));
        }
    }
    found
}

/// The flicker of fundamental `fundamental` Hz (family `nominal`; at an unknown frame rate
/// nominal 0, `fps` 1 and the fundamental in cycles per frame), if found: its report and
/// its columns. A harmonic counts when it stands out against its controls in the whole sample
/// and, by `consistent`, in each half of it.
fn flicker_at(
    nominal: f64,
    fundamental: f64,
    fps: f64,
    f: usize,
    whole: &Evidence<'_>,
    consistent: &mut Consistent<'_>,
) -> Option<(Flicker, Vec<Vec<f64>>)> {
    let bin = 1.0 / f as f64;
    let mut harmonics = Vec::new();
    let mut on_lines = Vec::new();
    let mut columns = Vec::new();
    let mut amplitude = 0.0f64;
    // Whether a harmonic clear of the carriers' lines was tested yet.
    let mut tested = false;
    for (h, nu) in harmonics_of(fundamental, fps, bin) {
        let candidate = pair(nu, f);
        let controls: Vec<[Vec<f64>; 2]> = CONTROL_OFFSETS
            .iter()
            .flat_map(|&o| [nu + o * bin, nu - o * bin])
            .filter_map(|c| usable(alias(c), bin))
            .map(|c| pair(c, f))
            .collect();
        let judge = |e: &Evidence| {
            let (energy, _) = e.energy(&candidate);
            let control = median(controls.iter().map(|c| e.energy(c).0).collect());
            (energy, control.unwrap_or(e.noise))
        };
        let (_, share) = whole.energy(&candidate);
        if share < SEPARABLE_SHARE {
            // Its energy cannot be measured apart from the carrier's: projected out below
            // with the family, if the family shows elsewhere.
            on_lines.push((h, nu));
            continue;
        }
        let lowest = !tested;
        tested = true;
        let (energy, control) = judge(whole);
        if whole.stands_out(energy, control, 2)
            && consistent(&|e: &Evidence| {
                let (energy, control) = judge(e);
                e.stands_out(energy, control, 2)
            })
        {
            harmonics.push(h);
            columns.extend(quad(nu, f));
            // Excess energy per direction of the pair = a²·F/4 per pixel (a the amplitude).
            let excess = whole.excess(energy, control);
            amplitude = amplitude.max((4.0 * excess / (whole.pixels as f64 * f as f64)).sqrt());
        } else if lowest {
            // A lamp's flicker is strongest at its lowest harmonics: a family whose lowest
            // measurable harmonic does not stand out is not there (what stands out higher up is
            // leakage from a carrier's weaker lines).
            return None;
        }
    }
    if harmonics.is_empty() {
        return None;
    }
    // The family is present: its harmonics on carrier lines are projected out too (unbiased,
    // at the cost of that carrier's line).
    for &(h, nu) in &on_lines {
        harmonics.push(h);
        columns.extend(quad(nu, f));
    }
    harmonics.sort_unstable();
    let on_lines: Vec<usize> = on_lines.into_iter().map(|(h, _)| h).collect();
    let rate_known = nominal > 0.0;
    Some((
        Flicker {
            nominal_hz: nominal,
            frequency_hz: if rate_known { fundamental } else { 0.0 },
            cycles_per_frame: alias(fundamental / fps),
            harmonics,
            amplitude,
            on_carrier_lines: on_lines,
        },
        columns,
    ))
}

/// The window's relative gain change per frame (mean 0): the pixels' centred values regressed
/// on their means, frame by frame, then on the drift columns.
fn drift_series(window: &Window<'_>, columns: &[Vec<f64>]) -> Vec<f64> {
    let f = window.frames;
    let weight: f64 = window.means.iter().map(|m| m * m).sum();
    if weight <= 0.0 {
        return vec![0.0; f];
    }
    let mut series = vec![0.0; f];
    for (p, &m) in window.means.iter().enumerate() {
        let x = &window.values[p * f..(p + 1) * f];
        series.iter_mut().zip(x).for_each(|(s, v)| *s += m * v);
    }
    series.iter_mut().for_each(|s| *s /= weight);
    let mut smooth = vec![0.0; f];
    for q in columns {
        let c = dot(q, &series);
        smooth.iter_mut().zip(q).for_each(|(s, v)| *s += c * v);
    }
    smooth
}

/// Centred, scaled frame time τ ∈ [−½, ½].
fn centred_time(j: usize, f: usize) -> f64 {
    (j as f64 - (f as f64 - 1.0) / 2.0) / f as f64
}

/// A frequency folded into [0, ½] cycles per frame.
fn alias(nu: f64) -> f64 {
    let x = nu.rem_euclid(1.0);
    if x > 0.5 { 1.0 - x } else { x }
}

/// `nu` unless it sits within 1.5 bins of 0 (a constant or drift, not a flicker the window
/// resolves) or within half a bin of ½ (the sine vanishes).
fn usable(nu: f64, bin: f64) -> Option<f64> {
    (nu > 1.5 * bin && nu < 0.5 - 0.5 * bin).then_some(nu)
}

/// cos and sin at `nu` cycles per frame.
fn pair(nu: f64, f: usize) -> [Vec<f64>; 2] {
    [
        (0..f).map(|j| (TAU * nu * j as f64).cos()).collect(),
        (0..f).map(|j| (TAU * nu * j as f64).sin()).collect(),
    ]
}

/// cos, sin, τ·cos and τ·sin at `nu` cycles per frame (module docs).
fn quad(nu: f64, f: usize) -> Vec<Vec<f64>> {
    let [c, s] = pair(nu, f);
    let tc = c
        .iter()
        .enumerate()
        .map(|(j, v)| centred_time(j, f) * v)
        .collect();
    let ts = s
        .iter()
        .enumerate()
        .map(|(j, v)| centred_time(j, f) * v)
        .collect();
    vec![c, s, tc, ts]
}

/// The carriers' strongest harmonics at rate `rate` for `leds` LEDs, orthonormal and
/// orthogonal to the constant.
fn carrier_columns(rate: f64, leds: usize, f: usize) -> Vec<Vec<f64>> {
    let columns: Vec<Vec<f64>> = (0..leds)
        .flat_map(|i| {
            super::quality::led_subspace(&ReceivedWaveform::new(i), rate, f)
                .into_iter()
                .take(2 * CARRIER_HARMONICS)
        })
        .collect();
    orthonormal(&columns, &[vec![1.0; f]])
}

/// Gram–Schmidt of `columns` against the span of `against` (kept out of the result) and each
/// other; columns that vanish are dropped.
fn orthonormal(columns: &[Vec<f64>], against: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut done: Vec<Vec<f64>> = Vec::new();
    for a in against {
        let mut v = a.clone();
        for q in &done {
            let d = dot(q, &v);
            v.iter_mut().zip(q).for_each(|(x, &y)| *x -= d * y);
        }
        let n = dot(&v, &v).sqrt();
        if n > 1e-12 {
            v.iter_mut().for_each(|x| *x /= n);
            done.push(v);
        }
    }
    let fixed = done.len();
    for c in columns {
        let scale = dot(c, c).sqrt();
        let mut v = c.clone();
        for _ in 0..2 {
            for q in &done {
                let d = dot(q, &v);
                v.iter_mut().zip(q).for_each(|(x, &y)| *x -= d * y);
            }
        }
        let n = dot(&v, &v).sqrt();
        if n > 1e-6 * scale && n > 0.0 {
            v.iter_mut().for_each(|x| *x /= n);
            done.push(v);
        }
    }
    done.split_off(fixed)
}

/// I − QQᵀ (F × F) for orthonormal columns Q.
fn complement(columns: &[Vec<f64>], f: usize) -> DMatrix<f64> {
    let mut m = DMatrix::identity(f, f);
    for q in columns {
        for a in 0..f {
            for b in 0..f {
                m[(a, b)] -= q[a] * q[b];
            }
        }
    }
    m
}

/// M·v.
fn apply(m: &DMatrix<f64>, v: &[f64]) -> Vec<f64> {
    (0..m.nrows())
        .map(|a| (0..m.ncols()).map(|b| m[(a, b)] * v[b]).sum())
        .collect()
}

/// qᵀ·G·q.
fn quadratic(g: &DMatrix<f64>, q: &[f64]) -> f64 {
    dot(q, &apply(g, q))
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn median(mut values: Vec<f64>) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    Some(values[values.len() / 2])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A window of `pixels` pixels: white noise of σ plus `extra(p, j)`.
    fn window_of(
        pixels: usize,
        f: usize,
        sigma: f64,
        extra: impl Fn(usize, usize) -> f64,
    ) -> (Vec<f64>, Vec<f64>, DMatrix<f64>) {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let normal = Normal::new(0.0, sigma).unwrap_or_else(|_| unreachable!());
        let mut values = vec![0.0; pixels * f];
        for p in 0..pixels {
            let x = &mut values[p * f..(p + 1) * f];
            for (j, v) in x.iter_mut().enumerate() {
                *v = extra(p, j) + normal.sample(&mut rng);
            }
            let mean = x.iter().sum::<f64>() / f as f64;
            x.iter_mut().for_each(|v| *v -= mean);
        }
        let m = DMatrix::from_row_slice(pixels, f, &values);
        let gram = m.tr_mul(&m);
        (values, vec![0.2; pixels], gram)
    }

    #[test]
    fn finds_flicker_and_its_family_and_nothing_in_noise() {
        let (pixels, f, sigma) = (400, 128, 0.01);
        let noise = pixels as f64 * sigma * sigma;
        // 100.3 Hz flicker at 960 fps, amplitude 0.01 (the noise's σ) varying over the pixels.
        let (values, means, gram) = window_of(pixels, f, sigma, |p, j| {
            let a = 0.01 * (0.5 + p as f64 / pixels as f64);
            a * (TAU * 100.3 / 960.0 * j as f64 + 0.7).cos()
        });
        let window = Window {
            values: &values,
            means: &means,
            gram: &gram,
            frames: f,
            noise,
        };
        let found = detect(&window, 960.0, 1.0, 4, &[]);
        assert_eq!(found.flicker.len(), 1, "{found:?}");
        assert_eq!(found.flicker[0].nominal_hz, 100.0);
        // The first harmonic is found; the others projected out lie on carrier lines.
        let flicker = &found.flicker[0];
        assert!(flicker.harmonics.contains(&1), "{flicker:?}");
        assert!(
            flicker
                .harmonics
                .iter()
                .all(|h| *h == 1 || flicker.on_carrier_lines.contains(h)),
            "{flicker:?}"
        );
        assert!(found.drift.is_none(), "{found:?}");
        let (values, means, gram) = window_of(pixels, f, sigma, |_, _| 0.0);
        let quiet = Window {
            values: &values,
            means: &means,
            gram: &gram,
            frames: f,
            noise,
        };
        assert!(detect(&quiet, 960.0, 1.0, 4, &[]).is_empty());
    }

    #[test]
    fn finds_flicker_at_an_unknown_frame_rate_by_its_frequency_in_frames() {
        let (pixels, f, sigma) = (400, 128, 0.01);
        let noise = pixels as f64 * sigma * sigma;
        let nu = 100.3 / 960.0;
        let (values, means, gram) = window_of(pixels, f, sigma, |p, j| {
            let a = 0.01 * (0.5 + p as f64 / pixels as f64);
            a * (TAU * nu * j as f64 + 0.7).cos()
        });
        let window = Window {
            values: &values,
            means: &means,
            gram: &gram,
            frames: f,
            noise,
        };
        let found = detect(&window, 0.0, 1.0, 4, &[]);
        assert_eq!(found.flicker.len(), 1, "{found:?}");
        let flicker = &found.flicker[0];
        assert_eq!((flicker.nominal_hz, flicker.frequency_hz), (0.0, 0.0));
        assert!(
            (flicker.cycles_per_frame - nu).abs() < 0.25 / f as f64,
            "{flicker:?}"
        );
        assert!(flicker.harmonics.contains(&1), "{flicker:?}");
        let mut v: Vec<f64> = (0..f).map(|j| (TAU * nu * j as f64 + 0.7).cos()).collect();
        found.project(&mut v);
        assert!(dot(&v, &v) < 1e-3 * f as f64, "{}", dot(&v, &v));
        let (values, means, gram) = window_of(pixels, f, sigma, |_, _| 0.0);
        let quiet = Window {
            values: &values,
            means: &means,
            gram: &gram,
            frames: f,
            noise,
        };
        assert!(detect(&quiet, 0.0, 1.0, 4, &[]).is_empty());
    }

    #[test]
    fn finds_a_drift_and_measures_it() {
        let (pixels, f, sigma) = (400, 128, 0.01);
        let noise = pixels as f64 * sigma * sigma;
        // Gain rising 5 % over the window on a background of 0.2.
        let (values, means, gram) = window_of(pixels, f, sigma, |_, j| {
            0.2 * 0.05 * j as f64 / (f - 1) as f64
        });
        let window = Window {
            values: &values,
            means: &means,
            gram: &gram,
            frames: f,
            noise,
        };
        let found = detect(&window, 960.0, 1.0, 4, &[]);
        let drift = found.drift.clone().unwrap_or_else(|| panic!("{found:?}"));
        assert!((drift.relative_change - 0.05).abs() < 0.005, "{drift:?}");
        assert!(found.flicker.is_empty(), "{found:?}");
        let mut v: Vec<f64> = (0..f).map(|j| centred_time(j, f)).collect();
        found.project(&mut v);
        assert!(dot(&v, &v) < 1e-20);
    }

    #[test]
    fn a_tone_in_one_part_of_the_view_is_not_flicker() {
        // The same 100.3 Hz tone as a lamp's, on the top half of the sample only (a local
        // change, not a lamp lighting the view): it stands out in the whole sample but not in
        // the bottom half, so it is not taken for flicker. On every pixel it is.
        let (pixels, f, sigma) = (400, 128, 0.01);
        let noise = pixels as f64 * sigma * sigma;
        let tone = |j: usize| 0.006 * (TAU * 100.3 / 960.0 * j as f64 + 0.7).cos();
        for (local, expected) in [(true, 0), (false, 1)] {
            let (values, means, gram) = window_of(pixels, f, sigma, |p, j| {
                if local && p >= pixels / 2 {
                    0.0
                } else {
                    tone(j)
                }
            });
            let window = Window {
                values: &values,
                means: &means,
                gram: &gram,
                frames: f,
                noise,
            };
            let found = detect(&window, 960.0, 1.0, 4, &[]);
            assert_eq!(found.flicker.len(), expected, "local {local}: {found:?}");
        }
    }

    #[test]
    fn fitted_templates_are_set_aside_before_testing() {
        // A tone that is one of the fitted templates is the carriers', not the room's.
        let (pixels, f, sigma) = (400, 128, 0.01);
        let noise = pixels as f64 * sigma * sigma;
        let template: Vec<f64> = (0..f)
            .map(|j| (TAU * 100.3 / 960.0 * j as f64 + 0.7).cos())
            .collect();
        let (values, means, gram) = window_of(pixels, f, sigma, |p, j| {
            0.006 * (1.0 + (p % 3) as f64) * template[j]
        });
        let window = Window {
            values: &values,
            means: &means,
            gram: &gram,
            frames: f,
            noise,
        };
        assert_eq!(detect(&window, 960.0, 1.0, 4, &[]).flicker.len(), 1);
        assert!(detect(&window, 960.0, 1.0, 4, &[template]).is_empty());
    }
}
