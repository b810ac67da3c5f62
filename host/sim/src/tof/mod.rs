//! The time-of-flight side of a hybrid capture (thesis Ch. 6): a SPAD camera of its own pose
//! and resolution ([`meb_core::rig::TofCamera`]) with a co-located pulsed LED array, recording
//! reverse-mode TCSPC histograms, and chequerboard images in both cameras for calibration.
//!
//! Emitter: trains of `pulses` electrical pulses `width` wide, `spacing` apart, one train per
//! trigger period; the LED's optical response is a first-order low-pass (time constant τ), so
//! each optical pulse rises as 1 − e^(−t/τ) and decays as e^(−t/τ); SPAD timing jitter is
//! Gaussian. A pixel's footprint is sampled by k×k rays; a ray hitting a surface at radial
//! distance ρ with albedo a and incidence cosine cos i adds
//!
//! ```text
//! μ = μ_ref · a · cos i · (D_ref/ρ)²      signal photons per exposure, delayed by 2ρ/c
//! ```
//!
//! (μ_ref: a white board facing the camera at the reference distance), so edges give mixed
//! pixels. Background photons (ambient light, dark counts) are uniform over the gate.
//!
//! Detection (reverse mode, thesis §6.2.2): the SPAD is armed during a gate of `bins` TDC bins
//! each trigger period; the first photon of each exposure (many trigger periods) starts the TDC
//! and the next stop (the gate's end) stops it, so its code counts bins from the photon to the
//! gate's end. With per-period expected counts Λ_b per bin (in time order), L_b = Σ_{j<b} Λ_j,
//! Λ = Σ_b Λ_b and P periods per exposure, the first photon of an exposure falls in bin b with
//! probability
//!
//! ```text
//! q_b = (1 − e^(−P·Λ)) · (e^(−L_b) − e^(−L_b − Λ_b)) / (1 − e^(−Λ))
//! ```
//!
//! (pile-up exact); a histogram of F exposures is multinomial(F; q), drawn by sequential
//! binomials. Shapes are ray-cast exactly (analytic shapes only; meshes are refused).
//!
//! [`chequerboard`] renders calibration boards in both cameras; [`scene`] holds the thesis'
//! three-object hybrid scene. Like the rest of `simulate`, this never uses the code under test
//! (`tof`).

pub mod chequerboard;
pub mod scene;

pub use chequerboard::Chequerboard;
pub use scene::{HybridScene, thesis_hybrid_scene};

use super::SimulateError;
use super::scene::{Scene, Shape, intersect_analytic};
use meb_core::rig::{Camera, PixelRay, TofCamera};
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::{Array1, Array2, Array3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Binomial, Distribution};
use rayon::prelude::*;

/// Speed of light in mm per nanosecond.
const LIGHT_MM_PER_NS: f64 = 299.792_458;

/// How the TDC maps a photon's time to a bin.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum TdcMode {
    /// Bin = time from the gate's start (later photons, higher bins).
    Forward,
    /// Bin = time from the photon to the gate's end (later photons, lower bins; the thesis').
    Reverse,
}

/// The emitter's pulse train (thesis §6.5: 10 pulses of 11.3 ns, 30 ns apart, every 320 ns).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PulseTrain {
    /// Pulses per train.
    pub pulses: usize,
    /// Electrical pulse width, ns.
    pub width_ns: f64,
    /// Pulse start-to-start spacing, ns.
    pub spacing_ns: f64,
    /// Trigger (train) period, ns.
    pub period_ns: f64,
    /// LED optical time constant τ, ns (10–90 % rise time ≈ 2.2 τ).
    pub led_time_constant_ns: f64,
    /// SPAD + TDC timing jitter σ, ps.
    pub jitter_ps: f64,
}

impl Default for PulseTrain {
    fn default() -> Self {
        Self {
            pulses: 10,
            width_ns: 11.3,
            spacing_ns: 30.0,
            period_ns: 320.0,
            led_time_constant_ns: 1.0,
            jitter_ps: 50.0,
        }
    }
}

/// Settings of a simulated SPAD capture.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TofSimConfig {
    /// Exposures (TCSPC frames) per histogram (thesis: 10 000 of 1 ms).
    pub frames: usize,
    /// Exposure time, ms.
    pub exposure_ms: f64,
    /// TDC bins per histogram.
    pub bins: usize,
    /// TDC bin width, ps (thesis: 33).
    pub bin_ps: f64,
    /// Gate opening after the trigger, ns.
    pub gate_start_ns: f64,
    /// Forward or reverse TCSPC.
    pub mode: TdcMode,
    /// The emitter.
    pub pulse: PulseTrain,
    /// Mean signal photons per exposure inside the gate from a white board facing the camera
    /// at the reference distance.
    pub signal_photons_at_reference: f64,
    /// Mean background photons per exposure over the whole gate.
    pub background_photons: f64,
    /// Distance of the reference board, mm (thesis: 600).
    pub reference_distance_mm: f64,
    /// Rays per pixel side (k×k rays sample each pixel's footprint).
    pub supersampling: usize,
    /// Model the first-photon selection exactly (`false`: ideal histograms ∝ the photon rate,
    /// the same expected number of detections).
    pub pile_up: bool,
    /// Seed of the photon noise.
    pub seed: u64,
}

impl Default for TofSimConfig {
    fn default() -> Self {
        Self {
            frames: 10_000,
            exposure_ms: 1.0,
            bins: 1024,
            bin_ps: 33.0,
            gate_start_ns: 100.0,
            mode: TdcMode::Reverse,
            pulse: PulseTrain::default(),
            signal_photons_at_reference: 1.0,
            background_photons: 0.1,
            reference_distance_mm: 600.0,
            supersampling: 3,
            pile_up: true,
            seed: 0,
        }
    }
}

impl TofSimConfig {
    /// Checks every setting; names the first bad one.
    pub fn validate(&self) -> Result<(), SimulateError> {
        let bad = |field: &str, reason: &str| {
            Err(SimulateError::Invalid {
                field: format!("tof.{field}"),
                reason: reason.into(),
            })
        };
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let p = &self.pulse;
        if self.frames == 0 || self.frames > 100_000_000 {
            return bad("frames", "must be 1 to 10⁸");
        }
        if !(4..=65_536).contains(&self.bins) {
            return bad("bins", "must be 4 to 65 536");
        }
        if !positive(self.bin_ps) || !positive(self.exposure_ms) {
            return bad("bin_ps/exposure_ms", "must be positive");
        }
        if !(self.gate_start_ns.is_finite() && self.gate_start_ns >= 0.0) {
            return bad("gate_start_ns", "must be ≥ 0");
        }
        if p.pulses == 0
            || !positive(p.width_ns)
            || !positive(p.spacing_ns)
            || !positive(p.period_ns)
        {
            return bad(
                "pulse",
                "pulse count, width, spacing and period must be positive",
            );
        }
        if !(positive(p.led_time_constant_ns) && p.jitter_ps.is_finite() && p.jitter_ps >= 0.0) {
            return bad("pulse", "LED time constant must be positive and jitter ≥ 0");
        }
        if self.gate_start_ns + self.bins as f64 * self.bin_ps * 1e-3 > p.period_ns {
            return bad("bins", "the gate must end within one trigger period");
        }
        if !(self.signal_photons_at_reference.is_finite()
            && self.signal_photons_at_reference >= 0.0
            && self.background_photons.is_finite()
            && self.background_photons >= 0.0)
        {
            return bad("photons", "photon rates must be ≥ 0");
        }
        if !positive(self.reference_distance_mm) {
            return bad("reference_distance_mm", "must be positive");
        }
        if !(1..=8).contains(&self.supersampling) {
            return bad("supersampling", "must be 1 to 8");
        }
        Ok(())
    }

    /// Trigger periods per exposure.
    fn periods(&self) -> f64 {
        (self.exposure_ms * 1e6 / self.pulse.period_ns).max(1.0)
    }
}

/// A simulated SPAD capture of a scene and of the reference board, with the truth.
#[derive(Debug, Clone)]
pub struct TofCapture {
    /// H×W×bins photon counts of the scene.
    pub histograms: Array3<u32>,
    /// H×W×bins photon counts of the reference board (perpendicular to the axis at D_ref).
    pub reference_pixels: Array3<u32>,
    /// Reference histogram: the sum of the board's central 4×4 pixels (on the optical axis).
    pub reference: Array1<u32>,
    /// Axial depth (mm) of the surface hit by each pixel's central ray; NaN where none.
    pub truth_range_mm: Array2<f32>,
    /// Object group hit by the central ray (−1: background or nothing).
    pub truth_label: Array2<i32>,
    /// Whether the pixel's rays all hit one surface within 5 mm of axial depth.
    pub pure: Array2<bool>,
    /// Expected signal photons per exposure (before detection) per pixel.
    pub signal_photons: Array2<f32>,
}

/// What one ray hits.
#[derive(Debug, Clone, Copy)]
struct RayHit {
    /// Distance along the unit-axial-depth ray (= axial depth).
    axial: f64,
    normal: Vector3<f64>,
    albedo: f64,
    label: i32,
}

/// A ray's hit: (t, unit normal, albedo, label).
pub type Hit = (f64, Vector3<f64>, f64, i32);

/// The front-most hit of the ray `origin + t·direction` (t > 0): (t, unit normal, albedo,
/// label), t in units of `direction`. Object k carries label `groups[k]` (several analytic
/// objects may form one, e.g. a head of ellipsoids); the ground plane is label −1.
pub fn cast_ray(
    scene: &Scene,
    groups: &[usize],
    origin: &Vector3<f64>,
    direction: &Vector3<f64>,
) -> Result<Option<Hit>, SimulateError> {
    // Rotate the scene so the ray runs along −z through the origin: then the front-most hit is
    // the largest z of the orthographic ray caster.
    let unit = direction.normalize();
    let q = UnitQuaternion::rotation_between(&unit, &-Vector3::z()).unwrap_or_else(|| {
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    });
    let mut best: Option<(f64, Vector3<f64>, f64, i32)> = None;
    // In the SPAD-aligned frame the pixel's ray is the z axis through the origin.
    let axis = PixelRay {
        base: Vector3::zeros(),
        slope: Vector3::z(),
    };
    for (k, object) in scene.objects.iter().enumerate() {
        if matches!(object.shape, Shape::Mesh(_)) {
            return Err(SimulateError::Invalid {
                field: "scene".into(),
                reason:
                    "the ToF simulator ray-casts analytic shapes only (sphere, ellipsoid, cuboid)"
                        .into(),
            });
        }
        let centre = q * (object.position_mm - origin);
        let rotation = q * object.rotation;
        if let Some((z, n)) = intersect_analytic(&object.shape, &centre, &rotation, &axis)
            && z < 0.0
        {
            let t = -z;
            if best.is_none_or(|b| t < b.0) {
                let label = groups.get(k).map_or(k as i32, |&g| g as i32);
                best = Some((t, q.inverse() * n, object.albedo, label));
            }
        }
    }
    if let Some(g) = &scene.ground
        && unit.z.abs() > 1e-12
    {
        let t = (g.z_mm - origin.z) / unit.z;
        if t > 0.0 && best.is_none_or(|b| t < b.0) {
            best = Some((t, Vector3::z(), g.albedo, -1));
        }
    }
    Ok(best.map(|(t, n, a, l)| (t / direction.norm(), n, a, l)))
}

/// Per-pixel object group seen by the PS camera (−1: ground or nothing).
pub fn camera_labels(scene: &Scene, groups: &[usize], camera: &Camera) -> Array2<i32> {
    Array2::from_shape_fn((camera.height, camera.width), |(r, c)| {
        let ray = camera.ray(r as f64, c as f64);
        let mut best = (f64::NEG_INFINITY, -1);
        if let Some(g) = &scene.ground {
            best = (g.z_mm, -1);
        }
        for (k, o) in scene.objects.iter().enumerate() {
            if let Some((z, _)) = intersect_analytic(&o.shape, &o.position_mm, &o.rotation, &ray)
                && z > best.0
            {
                best = (z, groups.get(k).map_or(k as i32, |&g| g as i32));
            }
        }
        best.1
    })
}

/// The optical pulse train's cumulative photon fraction G(t) (normalised to 1 over one train),
/// tabulated finely, jitter included.
struct TrainProfile {
    start_ns: f64,
    step_ns: f64,
    cumulative: Vec<f64>,
}

impl TrainProfile {
    fn new(pulse: &PulseTrain) -> Self {
        let tau = pulse.led_time_constant_ns;
        let sigma = pulse.jitter_ps * 1e-3;
        let step = 0.002;
        let start = -6.0 * sigma - step;
        let end = (pulse.pulses - 1) as f64 * pulse.spacing_ns
            + pulse.width_ns
            + 30.0 * tau
            + 6.0 * sigma;
        let n = ((end - start) / step).ceil() as usize + 1;
        // One optical pulse: rect(width) ⊗ e^(−t/τ)/τ.
        let single = |t: f64| {
            if t <= 0.0 {
                0.0
            } else if t <= pulse.width_ns {
                1.0 - (-t / tau).exp()
            } else {
                (1.0 - (-pulse.width_ns / tau).exp()) * (-(t - pulse.width_ns) / tau).exp()
            }
        };
        let power: Vec<f64> = (0..n)
            .map(|i| {
                let t = start + i as f64 * step;
                (0..pulse.pulses)
                    .map(|k| single(t - k as f64 * pulse.spacing_ns))
                    .sum()
            })
            .collect();
        let smoothed = if sigma > 0.0 {
            let half = (4.0 * sigma / step).ceil() as isize;
            let kernel: Vec<f64> = (-half..=half)
                .map(|j| (-0.5 * (j as f64 * step / sigma).powi(2)).exp())
                .collect();
            let norm: f64 = kernel.iter().sum();
            (0..n as isize)
                .map(|i| {
                    kernel
                        .iter()
                        .enumerate()
                        .map(|(k, w)| {
                            let j = i + k as isize - half;
                            if (0..n as isize).contains(&j) {
                                w * power[j as usize]
                            } else {
                                0.0
                            }
                        })
                        .sum::<f64>()
                        / norm
                })
                .collect()
        } else {
            power
        };
        let mut cumulative = Vec::with_capacity(n);
        let mut sum = 0.0;
        for p in &smoothed {
            cumulative.push(sum);
            sum += p * step;
        }
        if sum > 0.0 {
            cumulative.iter_mut().for_each(|c| *c /= sum);
        }
        Self {
            start_ns: start,
            step_ns: step,
            cumulative,
        }
    }

    /// G(t) by linear interpolation (0 before the train, 1 after).
    fn at(&self, t_ns: f64) -> f64 {
        let x = (t_ns - self.start_ns) / self.step_ns;
        if x <= 0.0 {
            return 0.0;
        }
        let i = x.floor() as usize;
        if i + 1 >= self.cumulative.len() {
            return 1.0;
        }
        let f = x - i as f64;
        self.cumulative[i] * (1.0 - f) + self.cumulative[i + 1] * f
    }
}

/// Expected photons per exposure in each gate bin (time order) for one pixel's hits.
fn expected_counts(
    hits: &[(f64, f64)],
    profile: &TrainProfile,
    config: &TofSimConfig,
    gate_fraction_at_reference: f64,
    out: &mut [f64],
) {
    let bin_ns = config.bin_ps * 1e-3;
    let background = config.background_photons / config.bins as f64;
    out.fill(background);
    for &(mu, radial_mm) in hits {
        if mu <= 0.0 {
            continue;
        }
        let delay = 2.0 * radial_mm / LIGHT_MM_PER_NS;
        let scale = mu / gate_fraction_at_reference;
        let mut previous = profile.at(config.gate_start_ns - delay);
        for (b, o) in out.iter_mut().enumerate() {
            let next = profile.at(config.gate_start_ns + (b + 1) as f64 * bin_ns - delay);
            *o += scale * (next - previous);
            previous = next;
        }
    }
}

/// Draws a histogram of `frames` exposures from per-exposure expected counts per bin (time
/// order), with or without first-photon pile-up (module docs), into TDC code order.
fn draw_histogram(
    expected: &[f64],
    config: &TofSimConfig,
    rng: &mut ChaCha8Rng,
    probabilities: &mut [f64],
    out: &mut [u32],
) {
    let periods = config.periods();
    let total: f64 = expected.iter().sum();
    if config.pile_up {
        let lambda = total / periods;
        let detect = 1.0 - (-periods * lambda).exp();
        let norm = -(-lambda).exp_m1();
        let mut cumulative = 0.0f64;
        for (p, &m) in probabilities.iter_mut().zip(expected) {
            let l = m / periods;
            // e^(−L) − e^(−L−l) = e^(−L)·(1 − e^(−l))
            *p = if norm > 0.0 {
                detect * (-cumulative).exp() * -(-l).exp_m1() / norm
            } else {
                0.0
            };
            cumulative += l;
        }
    } else {
        // Same expected number of detections, shape ∝ the photon rate.
        let detect = 1.0 - (-total).exp();
        for (p, &m) in probabilities.iter_mut().zip(expected) {
            *p = if total > 0.0 { detect * m / total } else { 0.0 };
        }
    }
    let mut remaining = config.frames as u64;
    let mut mass = 1.0f64;
    let bins = out.len();
    for (b, &p) in probabilities.iter().enumerate() {
        let code = match config.mode {
            TdcMode::Forward => b,
            TdcMode::Reverse => bins - 1 - b,
        };
        let k = if remaining == 0 || p <= 0.0 || mass <= 0.0 {
            0
        } else {
            let share = (p / mass).clamp(0.0, 1.0);
            Binomial::new(remaining, share).map_or(0, |d| d.sample(rng))
        };
        out[code] = k as u32;
        remaining -= k;
        mass -= p;
    }
}

/// Renders histograms of `scene` (object `k` in group `groups[k]`) and of the reference board.
pub fn render_tof(
    scene: &Scene,
    groups: &[usize],
    camera: &TofCamera,
    config: &TofSimConfig,
) -> Result<TofCapture, SimulateError> {
    config.validate()?;
    let (rows, cols, bins) = (camera.height, camera.width, config.bins);
    let profile = TrainProfile::new(&config.pulse);
    let bin_ns = config.bin_ps * 1e-3;
    let reference_delay = 2.0 * config.reference_distance_mm / LIGHT_MM_PER_NS;
    let gate_fraction = profile.at(config.gate_start_ns + bins as f64 * bin_ns - reference_delay)
        - profile.at(config.gate_start_ns - reference_delay);
    if gate_fraction <= 1e-6 {
        return Err(SimulateError::Invalid {
            field: "tof.gate_start_ns".into(),
            reason: "the gate sees no light from the reference distance".into(),
        });
    }
    let k = config.supersampling;
    let origin = Vector3::from(camera.position_mm);
    type PixelResult = (Vec<u32>, Vec<u32>, f32, i32, bool, f32);
    let pixels: Vec<Result<PixelResult, SimulateError>> = (0..rows * cols)
        .into_par_iter()
        .map_init(
            || (vec![0.0; bins], vec![0.0; bins]),
            |(expected, probabilities), i| {
                let (r, c) = (i / cols, i % cols);
                let mut hits = Vec::with_capacity(k * k);
                let mut depths = Vec::with_capacity(k * k);
                let mut labels = Vec::with_capacity(k * k);
                for a in 0..k {
                    for b in 0..k {
                        let rr = r as f64 - 0.5 + (a as f64 + 0.5) / k as f64;
                        let cc = c as f64 - 0.5 + (b as f64 + 0.5) / k as f64;
                        let d = camera.ray(rr, cc);
                        if let Some(hit) = cast_ray(scene, groups, &origin, &d)?.map(
                            |(axial, normal, albedo, label)| RayHit {
                                axial,
                                normal,
                                albedo,
                                label,
                            },
                        ) {
                            let radial = hit.axial * d.norm();
                            let cos_i = hit.normal.dot(&-d.normalize()).max(0.0);
                            let mu = config.signal_photons_at_reference
                                * hit.albedo
                                * cos_i
                                * (config.reference_distance_mm / radial).powi(2)
                                / (k * k) as f64;
                            hits.push((mu, radial));
                            depths.push(hit.axial);
                            labels.push(hit.label);
                        } else {
                            labels.push(i32::MIN);
                        }
                    }
                }
                let centre = camera.ray(r as f64, c as f64);
                let truth = cast_ray(scene, groups, &origin, &centre)?;
                let (truth_range, truth_label) =
                    truth.map_or((f32::NAN, -1), |h| (h.0 as f32, h.3));
                let pure = labels.iter().all(|&l| l == labels[0] && l != i32::MIN)
                    && depths.iter().fold(f64::NEG_INFINITY, |m, &d| m.max(d))
                        - depths.iter().fold(f64::INFINITY, |m, &d| m.min(d))
                        < 5.0;
                let signal: f64 = hits.iter().map(|h| h.0).sum();
                expected_counts(&hits, &profile, config, gate_fraction, expected);
                let mut rng = ChaCha8Rng::seed_from_u64(seed_for(config.seed, 1, i));
                let mut scene_counts = vec![0u32; bins];
                draw_histogram(expected, config, &mut rng, probabilities, &mut scene_counts);
                // The reference board: perpendicular to the axis at D_ref, albedo 1.
                let d = camera.ray(r as f64, c as f64);
                let cos_theta = 1.0 / d.norm();
                let radial = config.reference_distance_mm / cos_theta;
                let mu = config.signal_photons_at_reference * cos_theta.powi(3);
                expected_counts(&[(mu, radial)], &profile, config, gate_fraction, expected);
                let mut rng = ChaCha8Rng::seed_from_u64(seed_for(config.seed, 2, i));
                let mut reference_counts = vec![0u32; bins];
                draw_histogram(
                    expected,
                    config,
                    &mut rng,
                    probabilities,
                    &mut reference_counts,
                );
                Ok((
                    scene_counts,
                    reference_counts,
                    truth_range,
                    truth_label,
                    pure,
                    signal as f32,
                ))
            },
        )
        .collect();
    let mut capture = TofCapture {
        histograms: Array3::zeros((rows, cols, bins)),
        reference_pixels: Array3::zeros((rows, cols, bins)),
        reference: Array1::zeros(bins),
        truth_range_mm: Array2::from_elem((rows, cols), f32::NAN),
        truth_label: Array2::from_elem((rows, cols), -1),
        pure: Array2::from_elem((rows, cols), false),
        signal_photons: Array2::zeros((rows, cols)),
    };
    for (i, pixel) in pixels.into_iter().enumerate() {
        let (r, c) = (i / cols, i % cols);
        let (scene_counts, reference_counts, range, label, pure, signal) = pixel?;
        for b in 0..bins {
            capture.histograms[(r, c, b)] = scene_counts[b];
            capture.reference_pixels[(r, c, b)] = reference_counts[b];
        }
        capture.truth_range_mm[(r, c)] = range;
        capture.truth_label[(r, c)] = label;
        capture.pure[(r, c)] = pure;
        capture.signal_photons[(r, c)] = signal;
    }
    let (r0, c0) = ((rows / 2).saturating_sub(2), (cols / 2).saturating_sub(2));
    for r in r0..(r0 + 4).min(rows) {
        for c in c0..(c0 + 4).min(cols) {
            for b in 0..bins {
                capture.reference[b] += capture.reference_pixels[(r, c, b)];
            }
        }
    }
    Ok(capture)
}

/// A per-(seed, stream, pixel) seed, so every pixel draws the same photons in any order.
pub(crate) fn seed_for(seed: u64, stream: u64, pixel: usize) -> u64 {
    let mut x = seed
        ^ stream.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (pixel as u64).wrapping_mul(0xD1B5_4A32_D192_ED03);
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^ (x >> 29)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneObject;

    fn small_camera() -> TofCamera {
        TofCamera {
            width: 24,
            height: 16,
            fov_deg: 16.0,
            position_mm: [0.0, 0.0, 900.0],
            look_at_mm: [0.0; 3],
        }
    }

    #[test]
    fn rays_hit_the_front_of_a_sphere_at_its_axial_depth() {
        let mut sphere = SceneObject::sphere(48.0);
        sphere.position_mm = Vector3::new(0.0, 0.0, 100.0);
        let scene = Scene::single(sphere);
        let cam = small_camera();
        let d = cam.ray(7.5, 11.5); // the optical axis
        let (axial, n, _, label) = cast_ray(&scene, &[0], &Vector3::from(cam.position_mm), &d)
            .unwrap()
            .unwrap();
        assert!((axial - (900.0 - 124.0)).abs() < 1e-9, "{axial}");
        assert!((n - Vector3::z()).norm() < 1e-9 && label == 0);
    }

    /// The histogram's mean photon count matches the detection probability, and strong pile-up
    /// (one period per exposure) skews the histogram towards early photons while the thesis'
    /// 3 125 periods per exposure do not.
    #[test]
    fn pile_up_only_matters_with_few_periods_per_exposure() {
        let profile = TrainProfile::new(&PulseTrain::default());
        // A 16.9 ns gate holding one whole pulse (delayed 4 ns by the 600 mm distance).
        let config = TofSimConfig {
            bins: 512,
            frames: 200_000,
            gate_start_ns: 120.0,
            ..TofSimConfig::default()
        };
        let mut expected = vec![0.0; 512];
        // 30 photons per train, about 3 of them inside the gate.
        expected_counts(&[(30.0, 600.0)], &profile, &config, 1.0, &mut expected);
        let mean_bin = |h: &[u32]| {
            let n: f64 = h.iter().map(|&v| f64::from(v)).sum();
            (
                h.iter()
                    .enumerate()
                    .map(|(b, &v)| b as f64 * f64::from(v))
                    .sum::<f64>()
                    / n,
                n,
            )
        };
        let mut probabilities = vec![0.0; 512];
        let mut draw = |pile_up: bool, exposure_ms: f64| {
            let mut out = vec![0u32; 512];
            let cfg = TofSimConfig {
                pile_up,
                exposure_ms,
                mode: TdcMode::Forward,
                ..config.clone()
            };
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            draw_histogram(&expected, &cfg, &mut rng, &mut probabilities, &mut out);
            mean_bin(&out)
        };
        let (ideal, n_ideal) = draw(false, 1.0);
        let (thesis, n_thesis) = draw(true, 1.0);
        let (single, _) = draw(true, 320e-6);
        let total: f64 = expected.iter().sum();
        let p = 1.0 - (-total).exp();
        assert!((n_ideal / 200_000.0 - p).abs() < 0.01 && (n_thesis / 200_000.0 - p).abs() < 0.01);
        assert!((thesis - ideal).abs() < 0.3, "{thesis} vs {ideal}");
        assert!(
            ideal - single > 30.0,
            "single-period pile-up should pull photons early: {single} vs {ideal}"
        );
    }
}
