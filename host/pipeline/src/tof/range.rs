//! Range from TCSPC histograms by cross-correlation with a reference histogram (thesis §6.2.2,
//! after Griffiths et al. \[62\]: the shift of the scene histogram against a histogram of a white
//! board at a known distance).
//!
//! Per pixel, the central part of the histogram (all but `m` bins at each end, m = the largest
//! shift searched) is made zero-mean and slid along the whole reference:
//!
//! ```text
//! q[k] = Σ_j (h[j+m] − h̄) · r[j+k],   k = 0..2m,   lag n = m − k
//! ```
//!
//! computed for all k at once by FFT (rustfft; one plan per run), and normalised by the spread
//! of the reference under the template, q\[k\]/σ_r(k) (normalised cross-correlation; Lewis, "Fast
//! normalized cross-correlation", 1995, with sliding sums). Every lag sees the same bins of the
//! scene, so there is no overlap bias towards lag 0; the zero-mean template makes q blind to any
//! constant background in either histogram; the normalisation removes the pull of pulse energy
//! entering and leaving the reference window (without it a 350-bin template on a 300-bin pulse
//! period was biased by 2 bins). The integer peak is refined to a fraction of a bin by a
//! least-squares parabola over ±[`PARABOLA_HALF_WIDTH`] lags around it, then polished to the
//! Poisson maximum-likelihood fit h_t ~ Poisson(a·r(t−n) + b) by Fisher scoring, with the
//! reference shifted continuously (cubic convolution). This removes the parabola's sampling bias
//! (0.03 bin) and weights every bin by its noise, which matters when a few thousand photons sit
//! on a background (on the simulated thesis scene: 19.7 mm RMSE for plain correlation). The fit
//! also gives the signal photons a·Σr and the background b per bin, and the lag's standard
//! deviation is the Cramér–Rao bound at the fit:
//!
//! ```text
//! σ_n² = 1 / Σ_t (a·r'(t−n))² / (a·r(t−n) + b)      (+ the reference's own term per pixel)
//! ```
//!
//! The reference is the model of the histogram's shape, so its own photon noise is a timing
//! error common to every pixel: the 16 central pixels of a board at the thesis' counts (~10⁵
//! photons) offset the whole map by about 2 mm (measured on the simulated thesis capture).
//! The score therefore uses the raw reference as the model and a smoothed copy only for the
//! slope r' that weights the bins (an instrument: smoothing cannot move the range, where using
//! the smoothed copy as the model did by +1.3 mm), and a per-pixel reference (a board seen by
//! every pixel) is pooled into one on-axis reference by default: pixel (r, c) sees the board
//! D·(1/cos θ − 1) farther than the axis, is moved back by that delay and added, so the
//! reference has the photons of the whole sensor.
//!
//! Each pixel's estimate is noise-limited (error/σ ≈ 1); with [`RangeConfig::smoothing_radius`]
//! the map is then smoothed within its depth layers by a robust local plane fit
//! ([`super::layer_smoothing`]): 14.7 → 2.8 mm RMSE on the simulated thesis capture.
//!
//! A lag of n bins is a time shift Δt = ±n·bin (forward TCSPC: later photons in later bins;
//! reverse mode, the thesis' SPAD, times from the photon to the next stop, so later photons land
//! in earlier bins), i.e. a radial distance c·Δt/2 beyond the reference's. With the ray angle θ
//! of the pixel (from the ToF camera's field of view; θ = 0 when it is not given), the axial
//! depth is s = (D + cΔt/2)·cos θ for a global reference taken on the optical axis at D, and
//! s = D + (cΔt/2)·cos θ for a per-pixel reference of a board perpendicular to the axis at D.
//!
//! First-photon pile-up: the SPAD keeps only the first photon of each 1 ms exposure, which spans
//! ~3 000 trigger periods, so the timing distribution within a period is distorted only by the
//! photons of that one period, exp(−Λ(t)) with Λ ≲ (mean photons per exposure)/3 000 — far below
//! the noise. The simulator models it exactly and the `pile_up` tests show the range does not
//! move at the thesis' rates (and does at single-period forward-mode rates, which this module does
//! not correct).

use super::histogram::{Histograms, Reference};
use super::layer_smoothing::smooth_within_layers;
use super::{LIGHT_MM_PER_PS, TofError};
use ndarray::{Array2, ArrayView1, Axis};
use rayon::prelude::*;
use rustfft::num_complex::Complex64;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// Lags on each side of the integer peak used by the sub-bin parabola.
pub const PARABOLA_HALF_WIDTH: usize = 6;

/// The likelihood refinement may move the lag this far from the correlation peak (bins);
/// farther, it has left the peak and the correlation's estimate is kept.
const MAX_REFINEMENT_BINS: f64 = 20.0;

/// How bins map to time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TimingMode {
    /// The photon stops the TDC started by the trigger: later photons in later bins.
    Forward,
    /// The photon starts the TDC and a clock stops it (the thesis' SPAD): later photons in
    /// earlier bins.
    Reverse,
}

/// Settings of the range estimation.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RangeConfig {
    /// TDC bin width in picoseconds (thesis: 33).
    pub bin_ps: f64,
    /// Distance of the reference board in mm (thesis: 600).
    pub reference_distance_mm: f64,
    /// Forward or reverse TCSPC.
    pub mode: TimingMode,
    /// Horizontal field of view of the ToF camera in degrees, for each pixel's ray angle;
    /// `None` treats every ray as paraxial (cos θ = 1).
    pub fov_deg: Option<f64>,
    /// Largest distance from the reference searched, mm (either side).
    pub max_shift_mm: f64,
    /// Pixels with fewer signal photons are unreliable (NaN).
    pub min_signal_photons: f64,
    /// Pixels whose histogram correlates less with the shifted reference (Pearson r) are
    /// unreliable (NaN).
    pub min_correlation: f64,
    /// Standard deviation (mm) at which the confidence is 1/2: confidence = σ₀²/(σ₀² + σ²).
    pub confidence_sigma_mm: f64,
    /// σ in bins of the Gaussian that smooths the reference for the coarse correlation and
    /// for the slope that weights the likelihood's bins (its photon noise would otherwise enter
    /// the template's slope); the model of the histogram stays the raw reference, so this
    /// moves no range. Keep it well below the pulse's rise time.
    pub reference_smoothing_bins: f64,
    /// With a per-pixel reference, pool every pixel's histogram into one on-axis reference
    /// (each moved by its known extra distance to the board, module docs) instead of using each
    /// pixel's own: hundreds of times the photons, so no reference noise (the per-pixel way
    /// also calibrates per-pixel timing skew, at the cost of that pixel's photon noise).
    pub pool_reference: bool,
    /// Radius (ToF pixels) of the edge-aware local plane fit that smooths the range within a
    /// depth layer ([`super::layer_smoothing`]); 0 keeps each pixel's own estimate.
    pub smoothing_radius: usize,
}

impl Default for RangeConfig {
    fn default() -> Self {
        Self {
            bin_ps: 33.0,
            reference_distance_mm: 600.0,
            mode: TimingMode::Reverse,
            fov_deg: None,
            max_shift_mm: 750.0,
            min_signal_photons: 50.0,
            min_correlation: 0.3,
            confidence_sigma_mm: 10.0,
            reference_smoothing_bins: 3.0,
            pool_reference: true,
            smoothing_radius: 3,
        }
    }
}

impl RangeConfig {
    /// Checks every setting; the error names the first bad one.
    pub fn validate(&self, bins: usize) -> Result<(), TofError> {
        let bad = |field: &str, reason: String| TofError::Invalid {
            field: field.into(),
            reason,
        };
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.bin_ps) {
            return Err(bad(
                "bin_ps",
                format!("must be positive, got {}", self.bin_ps),
            ));
        }
        if !positive(self.reference_distance_mm) {
            return Err(bad(
                "reference_distance_mm",
                format!("must be positive, got {}", self.reference_distance_mm),
            ));
        }
        if let Some(f) = self.fov_deg
            && !(f.is_finite() && f > 0.0 && f < 170.0)
        {
            return Err(bad("fov_deg", format!("must be in (0, 170), got {f}")));
        }
        if !positive(self.max_shift_mm) {
            return Err(bad(
                "max_shift_mm",
                format!("must be positive, got {}", self.max_shift_mm),
            ));
        }
        let lags = self.max_lag_bins();
        if 2 * lags + 4 * PARABOLA_HALF_WIDTH > bins {
            return Err(bad(
                "max_shift_mm",
                format!(
                    "±{} mm is ±{lags} bins of {} ps, too many for {bins}-bin histograms (at most ±{} mm)",
                    self.max_shift_mm,
                    self.bin_ps,
                    ((bins.saturating_sub(4 * PARABOLA_HALF_WIDTH)) / 2) as f64 * self.bin_mm()
                ),
            ));
        }
        if !(self.min_signal_photons.is_finite() && self.min_signal_photons >= 0.0) {
            return Err(bad("min_signal_photons", "must be ≥ 0".into()));
        }
        if !(self.min_correlation.is_finite() && self.min_correlation < 1.0) {
            return Err(bad("min_correlation", "must be below 1".into()));
        }
        if !(self.reference_smoothing_bins.is_finite()
            && (0.0..=bins as f64 / 8.0).contains(&self.reference_smoothing_bins))
        {
            return Err(bad(
                "reference_smoothing_bins",
                format!("must be 0 to {} bins", bins / 8),
            ));
        }
        if self.smoothing_radius > 16 {
            return Err(bad(
                "smoothing_radius",
                format!("must be 0 to 16 ToF pixels, got {}", self.smoothing_radius),
            ));
        }
        if !positive(self.confidence_sigma_mm) {
            return Err(bad("confidence_sigma_mm", "must be positive".into()));
        }
        Ok(())
    }

    /// Radial distance of one bin, c·bin/2, in mm.
    pub fn bin_mm(&self) -> f64 {
        0.5 * LIGHT_MM_PER_PS * self.bin_ps
    }

    /// The largest lag searched, in bins (at least the parabola's width).
    pub fn max_lag_bins(&self) -> usize {
        ((self.max_shift_mm / self.bin_mm()).ceil() as usize).max(PARABOLA_HALF_WIDTH + 2)
    }
}

/// A range map and its per-pixel quality.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeMap {
    /// Axial depth in mm (distance along the ToF camera's optical axis); NaN where unreliable.
    pub range_mm: Array2<f32>,
    /// Estimated standard deviation of the range in mm (NaN where unreliable).
    pub sigma_mm: Array2<f32>,
    /// Confidence in [0, 1]: σ₀²/(σ₀² + σ²), 0 where unreliable.
    pub confidence: Array2<f32>,
    /// Signal photons (fitted pulse area) per pixel.
    pub signal_photons: Array2<f32>,
    /// Fitted background photons per bin.
    pub background_per_bin: Array2<f32>,
    /// Pearson correlation of the histogram with the shifted reference.
    pub correlation: Array2<f32>,
    /// Pixels whose photons entered each pixel's range (1 without spatial smoothing): one
    /// pixel's share of the information is 1/(samples·σ²), so summing the weights of
    /// neighbouring pixels does not count the same photons twice.
    pub samples: Array2<f32>,
    /// Each pixel's own range before spatial smoothing, mm (NaN where unreliable): independent
    /// from pixel to pixel (each from its own photons), so a fit over many pixels can weight
    /// them by their real covariance (smoothed ranges share photons and their errors are
    /// spatially correlated; the local plane fit also biases curved surfaces).
    pub raw_range_mm: Array2<f32>,
    /// The standard deviation of `raw_range_mm`, mm (Cramér–Rao bound at the fit).
    pub raw_sigma_mm: Array2<f32>,
    /// Why pixels were left out.
    pub rejected: Rejections,
}

/// Counts of unreliable pixels by reason.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct Rejections {
    /// Histograms without a photon.
    pub empty: usize,
    /// Fewer signal photons than the minimum.
    pub few_photons: usize,
    /// Shape does not match the reference (correlation below the minimum).
    pub poor_match: usize,
    /// Correlation peak on the edge of the searched shifts.
    pub out_of_range: usize,
}

impl RangeMap {
    /// Number of pixels with a range.
    pub fn reliable_pixels(&self) -> usize {
        self.range_mm.iter().filter(|v| v.is_finite()).count()
    }
}

/// One pixel's estimate.
#[derive(Debug, Clone, Copy)]
struct PixelRange {
    range_mm: f32,
    sigma_mm: f32,
    confidence: f32,
    signal: f32,
    background: f32,
    correlation: f32,
}

/// Outcome of one pixel.
enum PixelOutcome {
    Range(PixelRange),
    Rejected(Rejected),
}

/// Reason for rejecting a pixel (with its measured quality when there is one).
#[derive(Clone, Copy)]
enum Rejected {
    Empty,
    FewPhotons(f32, f32),
    PoorMatch(f32, f32),
    OutOfRange(f32, f32),
}

/// Estimates the range map of `histograms` against `reference` (module docs).
pub fn estimate_range(
    histograms: &Histograms,
    reference: &Reference,
    config: &RangeConfig,
) -> Result<RangeMap, TofError> {
    histograms.validate()?;
    reference.check_against(histograms)?;
    let bins = histograms.bins();
    config.validate(bins)?;
    let correlator = Correlator::new(bins, config.max_lag_bins());
    let (rows, cols) = histograms.shape();
    let cos_theta = |r: usize, c: usize| match config.fov_deg {
        Some(fov) => {
            let f = cols as f64 / 2.0 / (fov.to_radians() / 2.0).tan();
            let x = (c as f64 + 0.5 - cols as f64 / 2.0) / f;
            let y = (r as f64 + 0.5 - rows as f64 / 2.0) / f;
            1.0 / (1.0 + x * x + y * y).sqrt()
        }
        None => 1.0,
    };
    let global = match reference {
        Reference::Global(r) => Some(ReferenceSpectrum::new(
            &correlator,
            r.view(),
            config.reference_smoothing_bins,
        )?),
        Reference::PerPixel(all) if config.pool_reference => {
            let pooled = pool_reference(all, config, &cos_theta);
            Some(ReferenceSpectrum::new(
                &correlator,
                pooled.view(),
                config.reference_smoothing_bins,
            )?)
        }
        Reference::PerPixel(_) => None,
    };
    let outcomes: Vec<PixelOutcome> = (0..rows * cols)
        .into_par_iter()
        .map_init(
            || correlator.workspace(),
            |ws, i| {
                let (r, c) = (i / cols, i % cols);
                let h = histograms.counts.index_axis(Axis(0), r);
                let h = h.index_axis(Axis(0), c);
                let per_pixel;
                let spectrum = match (&global, reference) {
                    (Some(g), _) => g,
                    (None, Reference::PerPixel(all)) => {
                        let rp = all.index_axis(Axis(0), r);
                        match ReferenceSpectrum::new(
                            &correlator,
                            rp.index_axis(Axis(0), c),
                            config.reference_smoothing_bins,
                        ) {
                            Ok(s) => {
                                per_pixel = s;
                                &per_pixel
                            }
                            Err(_) => return PixelOutcome::Rejected(Rejected::Empty),
                        }
                    }
                    (None, Reference::Global(_)) => {
                        return PixelOutcome::Rejected(Rejected::Empty);
                    }
                };
                let is_global = global.is_some();
                correlator.pixel(ws, h, spectrum, is_global, config, cos_theta(r, c))
            },
        )
        .collect();
    let nan = || Array2::from_elem((rows, cols), f32::NAN);
    let mut map = RangeMap {
        range_mm: nan(),
        sigma_mm: nan(),
        confidence: Array2::zeros((rows, cols)),
        signal_photons: Array2::zeros((rows, cols)),
        background_per_bin: Array2::zeros((rows, cols)),
        correlation: Array2::zeros((rows, cols)),
        samples: Array2::ones((rows, cols)),
        raw_range_mm: nan(),
        raw_sigma_mm: nan(),
        rejected: Rejections::default(),
    };
    for (i, outcome) in outcomes.into_iter().enumerate() {
        let p = (i / cols, i % cols);
        match outcome {
            PixelOutcome::Range(v) => {
                map.range_mm[p] = v.range_mm;
                map.sigma_mm[p] = v.sigma_mm;
                map.confidence[p] = v.confidence;
                map.signal_photons[p] = v.signal;
                map.background_per_bin[p] = v.background;
                map.correlation[p] = v.correlation;
            }
            PixelOutcome::Rejected(reason) => match reason {
                Rejected::Empty => map.rejected.empty += 1,
                Rejected::FewPhotons(s, r) => {
                    map.rejected.few_photons += 1;
                    (map.signal_photons[p], map.correlation[p]) = (s, r);
                }
                Rejected::PoorMatch(s, r) => {
                    map.rejected.poor_match += 1;
                    (map.signal_photons[p], map.correlation[p]) = (s, r);
                }
                Rejected::OutOfRange(s, r) => {
                    map.rejected.out_of_range += 1;
                    (map.signal_photons[p], map.correlation[p]) = (s, r);
                }
            },
        }
    }
    map.raw_range_mm = map.range_mm.clone();
    map.raw_sigma_mm = map.sigma_mm.clone();
    if config.smoothing_radius > 0 {
        let smoothed = smooth_within_layers(&map.range_mm, &map.sigma_mm, config.smoothing_radius);
        let s0 = config.confidence_sigma_mm;
        map.confidence = smoothed.sigma_mm.mapv(|s| {
            if s.is_finite() {
                (s0 * s0 / (s0 * s0 + f64::from(s).powi(2))) as f32
            } else {
                0.0
            }
        });
        map.range_mm = smoothed.range_mm;
        map.sigma_mm = smoothed.sigma_mm;
        map.samples = smoothed.samples;
    }
    if map.reliable_pixels() == 0 {
        let best = map.signal_photons.iter().copied().fold(0.0f32, f32::max);
        let r = &map.rejected;
        return Err(TofError::NoReliableRange {
            reason: format!(
                "{} empty histograms, {} below {} signal photons (best {best:.0}), {} correlating below {}, {} beyond ±{} mm of the reference",
                r.empty,
                r.few_photons,
                config.min_signal_photons,
                r.poor_match,
                config.min_correlation,
                r.out_of_range,
                config.max_shift_mm
            ),
        });
    }
    Ok(map)
}

/// The FFT plans and sizes shared by all pixels.
struct Correlator {
    bins: usize,
    lags: usize,
    size: usize,
    forward: Arc<dyn Fft<f64>>,
    inverse: Arc<dyn Fft<f64>>,
}

/// Per-thread buffers.
struct Workspace {
    template: Vec<Complex64>,
    scratch: Vec<Complex64>,
    shifted: Vec<f64>,
    slope: Vec<f64>,
    weight: Vec<f64>,
    spare: Vec<f64>,
}

/// A reference histogram prepared for correlation: its spectrum, background and samples.
struct ReferenceSpectrum {
    spectrum: Vec<Complex64>,
    /// 1 / (standard deviation × √len) of the reference under the template at each lag index k.
    inverse_spread: Vec<f64>,
    /// The reference counts: the model of the scene's histogram shape.
    samples: Vec<f64>,
    /// The reference smoothed: its slope weights the bins in the likelihood's score (an
    /// instrument: the model stays the raw counts, so smoothing moves no range), and it is
    /// what the coarse correlation slides.
    smoothed: Vec<f64>,
    /// Its background per bin (a low percentile).
    background: f64,
    /// Its mean count per bin.
    mean: f64,
}

impl ReferenceSpectrum {
    /// Fails when the reference has no counts.
    fn new(
        correlator: &Correlator,
        reference: ArrayView1<f32>,
        smoothing_bins: f64,
    ) -> Result<Self, TofError> {
        let raw: Vec<f64> = reference.iter().map(|&v| f64::from(v)).collect();
        if raw.iter().sum::<f64>() <= 0.0 {
            return Err(TofError::NoPhotons("reference".into()));
        }
        let samples = smooth(&raw, smoothing_bins);
        let mut spectrum = vec![Complex64::new(0.0, 0.0); correlator.size];
        for (s, &v) in spectrum.iter_mut().zip(&samples) {
            s.re = v;
        }
        correlator.forward.process(&mut spectrum);
        let background = low_percentile(&samples, 0.1);
        // Sliding sums over the template's length for the normalised correlation.
        let len = correlator.bins - 2 * correlator.lags;
        let (mut s1, mut s2) = (0.0, 0.0);
        for &v in &samples[..len] {
            s1 += v;
            s2 += v * v;
        }
        let mut inverse_spread = Vec::with_capacity(2 * correlator.lags + 1);
        for k in 0..=2 * correlator.lags {
            if k > 0 {
                let (out, inn) = (samples[k - 1], samples[k + len - 1]);
                s1 += inn - out;
                s2 += inn * inn - out * out;
            }
            let spread = (s2 - s1 * s1 / len as f64).max(0.0);
            inverse_spread.push(if spread > 0.0 {
                1.0 / spread.sqrt()
            } else {
                0.0
            });
        }
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        Ok(Self {
            mean,
            spectrum,
            inverse_spread,
            samples: raw,
            smoothed: samples,
            background,
        })
    }

    /// shifted[t] = r(t − lag) of the raw reference and slope[t] = s'(t − lag) of the smoothed
    /// one, by cubic convolution.
    fn shift(&self, lag: f64, shifted: &mut [f64], slope: &mut [f64], spare: &mut [f64]) {
        shift_cubic(&self.samples, lag, shifted, spare);
        shift_cubic(&self.smoothed, lag, spare, slope);
    }
}

impl Correlator {
    fn new(bins: usize, lags: usize) -> Self {
        // Linear correlation of the (bins − 2·lags)-long template with the bins-long reference.
        let size = (2 * bins - 2 * lags).next_power_of_two();
        let mut planner = FftPlanner::new();
        Self {
            bins,
            lags,
            size,
            forward: planner.plan_fft_forward(size),
            inverse: planner.plan_fft_inverse(size),
        }
    }

    fn workspace(&self) -> Workspace {
        let scratch_len = self
            .forward
            .get_inplace_scratch_len()
            .max(self.inverse.get_inplace_scratch_len());
        Workspace {
            template: vec![Complex64::new(0.0, 0.0); self.size],
            scratch: vec![Complex64::new(0.0, 0.0); scratch_len],
            shifted: vec![0.0; self.bins],
            slope: vec![0.0; self.bins],
            weight: vec![0.0; self.bins],
            spare: vec![0.0; self.bins],
        }
    }

    /// The estimate for one histogram `h` (module docs).
    fn pixel(
        &self,
        ws: &mut Workspace,
        h: ArrayView1<f32>,
        reference: &ReferenceSpectrum,
        global_reference: bool,
        config: &RangeConfig,
        cos_theta: f64,
    ) -> PixelOutcome {
        let m = self.lags;
        let len = self.bins - 2 * m;
        let total: f64 = h.iter().map(|&v| f64::from(v)).sum();
        if total <= 0.0 {
            return PixelOutcome::Rejected(Rejected::Empty);
        }
        let central = h.slice(ndarray::s![m..m + len]);
        let mean = central.iter().map(|&v| f64::from(v)).sum::<f64>() / len as f64;
        ws.template.fill(Complex64::new(0.0, 0.0));
        for (t, &v) in ws.template.iter_mut().zip(central.iter()) {
            t.re = f64::from(v) - mean;
        }
        self.forward
            .process_with_scratch(&mut ws.template, &mut ws.scratch);
        // q[k] = Σ_j t[j] r[j + k]  ⇔  Q = conj(T)·R.
        for (t, r) in ws.template.iter_mut().zip(&reference.spectrum) {
            *t = t.conj() * r;
        }
        self.inverse
            .process_with_scratch(&mut ws.template, &mut ws.scratch);
        // Normalised correlation: q[k] over the spread of the reference under the template, so
        // that the reference's energy entering and leaving the window does not pull the peak.
        let q = |k: usize| ws.template[k].re * reference.inverse_spread[k];
        let k0 = (0..=2 * m)
            .max_by(|&a, &b| q(a).total_cmp(&q(b)))
            .unwrap_or(m);
        let coarse = m as f64 - refine_peak(&q, k0, 2 * m);
        // Poisson maximum likelihood of h ~ Poisson(a·r(t − lag) + b) over the central bins by
        // Fisher scoring (Gauss–Newton weighted by 1/mean), r shifted continuously by cubic
        // convolution: removes the parabola's sampling bias and weights bins by their noise.
        let span = m..m + len;
        let mut lag = coarse;
        reference.shift(lag, &mut ws.shifted, &mut ws.slope, &mut ws.spare);
        let (mut a, mut b, mut correlation) =
            fit_scaled(&h, &ws.shifted, &ws.weight[..0], span.clone());
        for _ in 0..12 {
            let floor = 0.02 * (a * reference.mean + b).max(1e-6);
            for t in span.clone() {
                ws.weight[t] = 1.0 / (a * ws.shifted[t] + b).max(floor);
            }
            (a, b, correlation) = fit_scaled(&h, &ws.shifted, &ws.weight, span.clone());
            let (mut score, mut information) = (0.0, 0.0);
            for t in span.clone() {
                let e = f64::from(h[t]) - a * ws.shifted[t] - b;
                // ∂mean/∂lag = −a·r'(t − lag)
                let g = -a * ws.slope[t];
                score += ws.weight[t] * e * g;
                information += ws.weight[t] * g * g;
            }
            if information.is_nan() || information <= 0.0 {
                break;
            }
            let step = (score / information).clamp(-2.0, 2.0);
            lag += step;
            reference.shift(lag, &mut ws.shifted, &mut ws.slope, &mut ws.spare);
            if step.abs() < 1e-4 {
                break;
            }
        }
        if (lag - coarse).abs() > MAX_REFINEMENT_BINS || !lag.is_finite() {
            lag = coarse;
            reference.shift(lag, &mut ws.shifted, &mut ws.slope, &mut ws.spare);
        }
        let signal =
            a * (ws.shifted[span.clone()].iter().sum::<f64>() - len as f64 * reference.background);
        let background = b + a * reference.background;
        let (signal_f, corr_f) = (signal as f32, correlation as f32);
        if k0 == 0 || k0 == 2 * m {
            return PixelOutcome::Rejected(Rejected::OutOfRange(signal_f, corr_f));
        }
        if !(signal >= config.min_signal_photons && a > 0.0) {
            return PixelOutcome::Rejected(Rejected::FewPhotons(signal_f.max(0.0), corr_f));
        }
        if correlation.is_nan() || correlation < config.min_correlation {
            return PixelOutcome::Rejected(Rejected::PoorMatch(signal_f, corr_f));
        }
        // Lag variance: the inverse Fisher information (module docs), plus the reference's own
        // for a per-pixel reference.
        let floor = 0.02 * (a * reference.mean + b).max(1e-6);
        let (mut information, mut reference_information) = (0.0, 0.0);
        for t in span {
            let d = ws.slope[t];
            information += (a * d).powi(2) / (a * ws.shifted[t] + b).max(floor);
            reference_information += d * d / ws.shifted[t].max(0.02 * reference.mean);
        }
        let mut variance = 1.0 / information;
        if !global_reference {
            variance += 1.0 / reference_information;
        }
        let sign = match config.mode {
            TimingMode::Forward => 1.0,
            TimingMode::Reverse => -1.0,
        };
        let radial_shift = sign * lag * config.bin_mm();
        let d_ref = config.reference_distance_mm;
        let range = if global_reference {
            (d_ref + radial_shift) * cos_theta
        } else {
            d_ref + radial_shift * cos_theta
        };
        let sigma = variance.sqrt() * config.bin_mm() * cos_theta;
        let s0 = config.confidence_sigma_mm;
        PixelOutcome::Range(PixelRange {
            range_mm: range as f32,
            sigma_mm: sigma as f32,
            confidence: (s0 * s0 / (s0 * s0 + sigma * sigma)) as f32,
            signal: signal_f,
            background: background as f32,
            correlation: corr_f,
        })
    }
}

/// The per-pixel reference histograms of a board perpendicular to the axis at D summed into
/// one on-axis histogram: pixel (r, c) sees the board D·(1/cos θ − 1) farther than the axis
/// does, so its histogram is moved back by that many bins (cubic convolution) before adding.
fn pool_reference(
    all: &ndarray::Array3<f32>,
    config: &RangeConfig,
    cos_theta: &impl Fn(usize, usize) -> f64,
) -> ndarray::Array1<f32> {
    let (rows, cols, bins) = all.dim();
    let sign = match config.mode {
        TimingMode::Forward => 1.0,
        TimingMode::Reverse => -1.0,
    };
    let mut sum = vec![0.0f64; bins];
    let (mut counts, mut moved, mut slope) = (vec![0.0; bins], vec![0.0; bins], vec![0.0; bins]);
    for r in 0..rows {
        for c in 0..cols {
            for (v, &h) in counts.iter_mut().zip(all.slice(ndarray::s![r, c, ..])) {
                *v = f64::from(h);
            }
            let delay = sign * config.reference_distance_mm * (1.0 / cos_theta(r, c) - 1.0)
                / config.bin_mm();
            // moved[t] = counts(t + delay): the pixel's pulse back at the on-axis time.
            shift_cubic(&counts, -delay, &mut moved, &mut slope);
            sum.iter_mut().zip(&moved).for_each(|(s, m)| *s += m);
        }
    }
    sum.into_iter().map(|v| v.max(0.0) as f32).collect()
}

/// `values` convolved with a unit-area Gaussian of σ = `sigma` samples (edges held).
fn smooth(values: &[f64], sigma: f64) -> Vec<f64> {
    if sigma.is_nan() || sigma <= 0.0 {
        return values.to_vec();
    }
    let half = (3.0 * sigma).ceil() as i64;
    let kernel: Vec<f64> = (-half..=half)
        .map(|j| (-0.5 * (j as f64 / sigma).powi(2)).exp())
        .collect();
    let norm: f64 = kernel.iter().sum();
    let n = values.len() as i64;
    (0..n)
        .map(|i| {
            kernel
                .iter()
                .zip(-half..=half)
                .map(|(w, j)| w * values[(i + j).clamp(0, n - 1) as usize])
                .sum::<f64>()
                / norm
        })
        .collect()
}

/// Vertex of the least-squares parabola through q over ±[`PARABOLA_HALF_WIDTH`] around `k0`
/// (kept within [0, `last`]); `k0` itself when the fit is not a maximum inside that span.
fn refine_peak(q: &impl Fn(usize) -> f64, k0: usize, last: usize) -> f64 {
    let w = PARABOLA_HALF_WIDTH;
    let lo = k0.saturating_sub(w);
    let hi = (k0 + w).min(last);
    if hi - lo < 2 {
        return k0 as f64;
    }
    // Fit q ≈ c0 + c1·x + c2·x² with x = k − k0 (normal equations, 3×3).
    let mut s = [0.0f64; 5];
    let mut t = [0.0f64; 3];
    for k in lo..=hi {
        let x = k as f64 - k0 as f64;
        let v = q(k);
        let mut p = 1.0;
        for (i, si) in s.iter_mut().enumerate() {
            *si += p;
            if i < 3 {
                t[i] += p * v;
            }
            p *= x;
        }
    }
    let m = nalgebra::Matrix3::new(s[0], s[1], s[2], s[1], s[2], s[3], s[2], s[3], s[4]);
    let Some(c) = m.lu().solve(&nalgebra::Vector3::new(t[0], t[1], t[2])) else {
        return k0 as f64;
    };
    if c[2] >= 0.0 {
        return k0 as f64;
    }
    let vertex = -c[1] / (2.0 * c[2]);
    if vertex.abs() > w as f64 {
        return k0 as f64;
    }
    (k0 as f64 + vertex).clamp(0.0, last as f64)
}

/// out[t] = r(t − lag) and slope[t] = r'(t − lag) by cubic convolution (Keys 1981, a = −½;
/// edge values held outside).
fn shift_cubic(r: &[f64], lag: f64, out: &mut [f64], slope: &mut [f64]) {
    let n = r.len() as i64;
    let at = |i: i64| r[i.clamp(0, n - 1) as usize];
    for (t, (o, s)) in out.iter_mut().zip(slope.iter_mut()).enumerate() {
        let x = t as f64 - lag;
        let i = x.floor();
        let f = x - i;
        let i = i as i64;
        let (p0, p1, p2, p3) = (at(i - 1), at(i), at(i + 1), at(i + 2));
        // Catmull–Rom: p(f) = p1 + f·c1 + f²·c2 + f³·c3.
        let c1 = 0.5 * (p2 - p0);
        let c2 = p0 - 2.5 * p1 + 2.0 * p2 - 0.5 * p3;
        let c3 = 0.5 * (p3 - p0) + 1.5 * (p1 - p2);
        *o = p1 + f * (c1 + f * (c2 + f * c3));
        *s = c1 + f * (2.0 * c2 + 3.0 * f * c3);
    }
}

/// Weighted least squares h ≈ a·g + b over `span` (unit weights when `weight` is empty), and
/// the (weighted) Pearson correlation of h and g there.
fn fit_scaled(
    h: &ArrayView1<f32>,
    g: &[f64],
    weight: &[f64],
    span: std::ops::Range<usize>,
) -> (f64, f64, f64) {
    let (mut sw, mut sh, mut sg, mut shh, mut sgg, mut shg) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for t in span {
        let w = weight.get(t).copied().unwrap_or(1.0);
        let (x, y) = (g[t], f64::from(h[t]));
        sw += w;
        sh += w * y;
        sg += w * x;
        shh += w * y * y;
        sgg += w * x * x;
        shg += w * x * y;
    }
    let cov = shg - sh * sg / sw;
    let var_g = sgg - sg * sg / sw;
    let var_h = shh - sh * sh / sw;
    if var_g.is_nan() || var_g <= 0.0 {
        return (0.0, sh / sw, f64::NAN);
    }
    let a = cov / var_g;
    let b = (sh - a * sg) / sw;
    let r = if var_h > 0.0 {
        cov / (var_g * var_h).sqrt()
    } else {
        0.0
    };
    (a, b, r)
}

/// The `p`-quantile (0..1) of `values` by selection.
pub(crate) fn low_percentile(values: &[f64], p: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v = values.to_vec();
    let k = ((v.len() - 1) as f64 * p).round() as usize;
    let (_, x, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    *x
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array1, Array3};

    /// A smooth pulse train sampled on `bins` bins, delayed by `delay` bins (continuous).
    fn train(bins: usize, delay: f64) -> Vec<f64> {
        (0..bins)
            .map(|t| {
                let x = t as f64 - delay;
                // Pulses every 300 bins, 110 wide, edges ~15 bins.
                let phase = x.rem_euclid(300.0);
                let rise = 1.0 / (1.0 + (-(phase - 40.0) / 6.0).exp());
                let fall = 1.0 / (1.0 + ((phase - 150.0) / 8.0).exp());
                rise * fall
            })
            .collect()
    }

    fn config() -> RangeConfig {
        RangeConfig {
            mode: TimingMode::Forward,
            max_shift_mm: 400.0,
            min_signal_photons: 1.0,
            // Exact templates: nothing to smooth (noisy references are the integration tests').
            reference_smoothing_bins: 0.0,
            ..RangeConfig::default()
        }
    }

    /// Noise-free shifted copies of the reference give back their shift to a small fraction
    /// of a bin, for shifts of either sign, with and without a constant background.
    #[test]
    fn recovers_sub_bin_shifts_without_bias() {
        let bins = 512;
        let reference = Array1::from(
            train(bins, 0.0)
                .iter()
                .map(|v| (1000.0 * v) as f32)
                .collect::<Vec<_>>(),
        );
        for (i, &delay) in [-37.3, -0.5, 0.0, 0.25, 12.71, 55.5].iter().enumerate() {
            let background = 5.0 * i as f32;
            let h = Array3::from_shape_vec(
                (1, 1, bins),
                train(bins, delay)
                    .iter()
                    .map(|v| 300.0 * *v as f32 + background)
                    .collect(),
            )
            .unwrap();
            let map = estimate_range(
                &Histograms { counts: h },
                &Reference::Global(reference.clone()),
                &config(),
            )
            .unwrap();
            let expected = 600.0 + delay * config().bin_mm();
            let got = f64::from(map.range_mm[(0, 0)]);
            assert!(
                (got - expected).abs() < 0.005 * config().bin_mm(),
                "delay {delay}: {got} vs {expected}"
            );
            assert!((map.background_per_bin[(0, 0)] - background).abs() < 1.0);
            assert!(map.correlation[(0, 0)] > 0.99);
        }
    }

    #[test]
    fn reverse_mode_flips_the_sign_and_bad_inputs_are_refused() {
        let bins = 256;
        let reference = Array1::from(
            train(bins, 0.0)
                .iter()
                .map(|v| (100.0 * v) as f32)
                .collect::<Vec<_>>(),
        );
        let h = Array3::from_shape_vec(
            (1, 2, bins),
            train(bins, 10.0)
                .iter()
                .chain(train(bins, -10.0).iter())
                .map(|v| 100.0 * *v as f32)
                .collect(),
        )
        .unwrap();
        let histograms = Histograms { counts: h };
        let cfg = RangeConfig {
            mode: TimingMode::Reverse,
            max_shift_mm: 200.0,
            ..config()
        };
        let map = estimate_range(&histograms, &Reference::Global(reference.clone()), &cfg).unwrap();
        assert!((map.range_mm[(0, 0)] - (600.0 - 10.0 * cfg.bin_mm()) as f32).abs() < 0.5);
        assert!((map.range_mm[(0, 1)] - (600.0 + 10.0 * cfg.bin_mm()) as f32).abs() < 0.5);

        let short = Reference::Global(Array1::ones(bins - 1));
        assert!(matches!(
            estimate_range(&histograms, &short, &cfg),
            Err(TofError::Shape { .. })
        ));
        let zeros = Histograms {
            counts: Array3::zeros((1, 2, bins)),
        };
        assert!(matches!(
            estimate_range(&zeros, &Reference::Global(reference.clone()), &cfg),
            Err(TofError::NoPhotons(_))
        ));
        let wide = RangeConfig {
            max_shift_mm: 5000.0,
            ..cfg.clone()
        };
        let err =
            estimate_range(&histograms, &Reference::Global(reference.clone()), &wide).unwrap_err();
        assert!(err.to_string().contains("max_shift_mm"), "{err}");
        let strict = RangeConfig {
            min_signal_photons: 1e9,
            ..cfg
        };
        let err = estimate_range(&histograms, &Reference::Global(reference), &strict).unwrap_err();
        assert!(matches!(err, TofError::NoReliableRange { .. }), "{err}");
    }
}
