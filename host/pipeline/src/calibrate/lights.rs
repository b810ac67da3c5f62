//! Fitting each LED's position and relative intensity to decoded captures of a matte sphere
//! of known size, on the near-field model the reconstruction uses.
//!
//! A sphere pixel p of capture c sees the surface point X on its ray and the sphere with unit
//! normal n = (X − C_c)/R. LED i then reads
//!
//! ```text
//! A_i(p) = s_c · max(0, n · L_i(X)),   L_i(X) = Φ_i · cos^m θ_i / |P_i − X|² · (P_i − X)/|P_i − X|
//! ```
//!
//! ([`meb_core::rig::Led::light_vector_at`]; s_c is the sphere's albedo times the camera's
//! gain in capture c). The unknowns are every LED's position P_i and intensity Φ_i, each
//! capture's s_c (s_1 = 1: Φ carries the first capture's scale), every sphere centre's shift
//! (x, y) from its silhouette fit and, for an orthographic camera, the height z of every
//! sphere centre but the first, which is fixed at z = 0 (an orthographic image does not show
//! distance; this fixes the frame). The shifts are fitted because the silhouette alone places
//! a centre to about 0.1 px (0.05 mm here), and the LEDs, 20 times further away than the
//! sphere's radius, magnify a centre error about 20-fold: on the simulator's captures the
//! silhouette centres alone put every LED 0.5–1.5 % too far from the origin (up to 8.6 mm).
//! Readings of an LED below [`MIN_READING_SHARE`] of its peak on the sphere are left out. They are fitted by
//! Levenberg–Marquardt on the residuals (A_i − model)/σ_i over the sphere's pixels (K.
//! Levenberg, Quarterly of Applied Mathematics, 1944; D. W. Marquardt, SIAM Journal on
//! Applied Mathematics, 1963), started from the nominal rig, as in Y. Quéau, B. Durix, T.
//! Wu, D. Cremers, F. Lauze and J.-D. Durou, "LED-based photometric stereo: modeling,
//! calibration and numerical solution", Journal of Mathematical Imaging and Vision, 2018.
//! Emission axes and Lambert orders are kept at the nominal rig's (an axis the rig leaves out
//! points at the origin from the fitted position, as the written rig file will say): near the
//! axis cos^m θ varies too little over a sphere to separate them from the position.
//!
//! Standard errors come from the Jacobian: s²·(JᵀJ)⁻¹ with s² the residual variance. A
//! parameter whose standard error exceeds [`MAX_POSITION_SE_MM`] or [`MAX_INTENSITY_SE`] is
//! not determined by the captures and is named, with the capture that would determine it.

use super::CalibrateError;
use super::sphere::SphereFit;
use meb_core::rig::{Emitter, PixelRay, Projection, Rig};
use nalgebra::{DMatrix, DVector, Vector3};
use ndarray::Array2;

/// Largest standard error of a fitted LED coordinate, mm, for it to count as determined. One
/// placement of a Ø50 mm sphere (out-of-plane rig, 640×360, noise 1 %) leaves 3.3–6.2 mm, two
/// up to 2.5 mm, three 0.5–1.0 mm.
pub const MAX_POSITION_SE_MM: f64 = 2.0;

/// Largest relative standard error of a fitted intensity to count as determined (one
/// placement: 1.7–2.9 %, three: 0.2–0.5 %).
pub const MAX_INTENSITY_SE: f64 = 0.01;

/// Most pixels used per capture (an even subsample).
const MAX_PIXELS_PER_CAPTURE: usize = 20_000;

/// Sphere pixels used lie within this share of the silhouette's radius (the rim's normals are
/// the least certain).
const INNER_SHARE: f64 = 0.95;

/// Readings below this share of their LED's brightest reading on the sphere (in the same
/// capture) are left out: near the attached shadow's edge a real matte surface departs most
/// from Lambert's law, and the decoded on-levels of a gamma-encoded capture read low there
/// (10 % low below a tenth of the peak, 3 % low below a fifth, within 0.5 % above a quarter, on
/// the simulator's captures with noise 1 % and gamma 2.2), which biases every LED's distance.
pub const MIN_READING_SHARE: f64 = 0.25;

/// Levenberg–Marquardt iterations at most.
const MAX_ITERATIONS: usize = 60;

/// One capture of the sphere: its decoded images, noise and the sphere found in it.
pub struct SphereCapture<'a> {
    /// LED images (linear, as decoded).
    pub images: &'a [Array2<f32>],
    /// Level noise σ(p).
    pub noise: &'a Array2<f32>,
    /// Per-LED noise gains g_i.
    pub noise_gains: &'a [f64],
    /// The sphere's silhouette fit.
    pub sphere: &'a SphereFit,
    /// The sphere's lit pixels.
    pub region: &'a Array2<bool>,
}

/// The fitted lights (module docs).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LightFit {
    /// The rig with fitted LED positions and relative intensities (geometric mean of the
    /// intensities that of the nominal rig).
    #[serde(skip)]
    pub rig: Option<Rig>,
    /// Per LED.
    pub leds: Vec<LedFit>,
    /// Sphere centres after the fit, mm (the first's z fixed for an orthographic camera).
    pub sphere_centres_mm: Vec<[f64; 3]>,
    /// RMS of the residuals in noise σ.
    pub rms_sigmas: f64,
    /// RMS of the residuals relative to the mean reading.
    pub rms_relative: f64,
    /// Residuals used.
    pub residuals: usize,
    /// Levenberg–Marquardt iterations run.
    pub iterations: usize,
    /// Parameters the captures do not determine, with what would.
    pub undetermined: Vec<String>,
}

/// One LED's fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LedFit {
    /// LED number, from 1.
    pub led: usize,
    /// Fitted position, mm.
    pub position_mm: [f64; 3],
    /// Standard errors of the position, mm.
    pub position_se_mm: [f64; 3],
    /// Distance from the nominal position, mm.
    pub moved_mm: f64,
    /// Fitted relative intensity.
    pub intensity: f64,
    /// Relative standard error of the intensity.
    pub intensity_se: f64,
    /// RMS residual of this LED's readings, noise σ.
    pub rms_sigmas: f64,
}

/// One sphere pixel: its ray, readings and their σ.
struct Pixel {
    capture: usize,
    ray: PixelRay,
    a: Vec<f64>,
    sigma: Vec<f64>,
}

/// The parameter layout: 4 per LED (x, y, z, ln Φ), then ln s_c for captures 2.., then the
/// centre heights of spheres 2.. (orthographic cameras), then every sphere's lateral shift
/// (x, y) from its silhouette fit.
struct Layout {
    leds: usize,
    captures: usize,
    heights: bool,
}

impl Layout {
    fn len(&self) -> usize {
        self.shifts_start() + 2 * self.captures
    }
    fn shifts_start(&self) -> usize {
        4 * self.leds + (self.captures - 1) * if self.heights { 2 } else { 1 }
    }
    fn scale(&self, c: usize) -> Option<usize> {
        (c > 0).then(|| 4 * self.leds + c - 1)
    }
    fn height(&self, c: usize) -> Option<usize> {
        (c > 0 && self.heights).then(|| 4 * self.leds + self.captures - 1 + c - 1)
    }
    fn shift(&self, c: usize) -> usize {
        self.shifts_start() + 2 * c
    }
    /// Whether parameter `j` is a length in mm (a position, a height or a shift).
    fn is_length(&self, j: usize) -> bool {
        (j < 4 * self.leds && j % 4 != 3)
            || j >= self.shifts_start()
            || self.height(1).is_some_and(|first| j >= first)
    }
}

/// Fits the LEDs of `nominal` to `captures` (module docs).
pub fn fit_lights(nominal: &Rig, captures: &[SphereCapture]) -> Result<LightFit, CalibrateError> {
    let k = nominal.leds.len();
    if captures.is_empty() {
        return Err(CalibrateError::Input(
            "no capture of the sphere given".into(),
        ));
    }
    let projection = nominal.camera.projection();
    let pixels = gather(captures, &projection);
    // Every LED must light part of the sphere in some capture.
    for i in 0..k {
        let lit = pixels.iter().filter(|p| p.a[i] > 5.0 * p.sigma[i]).count();
        if lit < 50 {
            return Err(CalibrateError::DarkLed { led: i + 1, lit });
        }
    }
    let layout = Layout {
        leds: k,
        captures: captures.len(),
        heights: matches!(projection, Projection::Orthographic { .. }),
    };
    let centres: Vec<Vector3<f64>> = captures
        .iter()
        .map(|c| Vector3::from(c.sphere.centre_mm))
        .collect();
    let radius = captures[0].sphere.radius_mm;
    let model = Model {
        nominal,
        pixels: &pixels,
        layout: &layout,
        centres: &centres,
        radius,
    };
    let mut theta = model.start();
    let mut r = model.residuals(&theta);
    let mut cost = r.norm_squared();
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut jacobian = model.jacobian(&theta);
    for _ in 0..MAX_ITERATIONS {
        iterations += 1;
        let jtj = jacobian.transpose() * &jacobian;
        let jtr = jacobian.transpose() * &r;
        let mut improved = false;
        for _ in 0..10 {
            let mut damped = jtj.clone();
            for d in 0..damped.nrows() {
                damped[(d, d)] += lambda * jtj[(d, d)].max(1e-12);
            }
            let Some(step) = damped.cholesky().map(|c| c.solve(&(-&jtr))) else {
                lambda *= 10.0;
                continue;
            };
            let candidate = &theta + &step;
            let r_new = model.residuals(&candidate);
            let c_new = r_new.norm_squared();
            if c_new.is_finite() && c_new < cost {
                let relative = (cost - c_new) / cost;
                theta = candidate;
                r = r_new;
                cost = c_new;
                lambda = (lambda / 5.0).max(1e-9);
                improved = relative > 1e-10;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
        jacobian = model.jacobian(&theta);
    }
    // Readings used (a reading left out has an infinite σ and a zero residual).
    let n: usize = pixels
        .iter()
        .map(|p| p.sigma.iter().filter(|s| s.is_finite()).count())
        .sum();
    let p = layout.len();
    if n <= p {
        return Err(CalibrateError::Input(format!(
            "{n} readings cannot determine {p} parameters"
        )));
    }
    let s2 = cost / (n - p) as f64;
    let jtj = jacobian.transpose() * &jacobian;
    let covariance = jtj
        .clone()
        .try_inverse()
        .unwrap_or_else(|| DMatrix::from_element(p, p, f64::INFINITY));
    let se = |j: usize| (s2 * covariance[(j, j)]).max(0.0).sqrt();
    // Intensities relative, with the nominal rig's geometric mean.
    let log_mean = (0..k).map(|i| theta[4 * i + 3]).sum::<f64>() / k as f64;
    let nominal_log_mean = nominal.leds.iter().map(|l| l.intensity.ln()).sum::<f64>() / k as f64;
    let mut rig = nominal.clone();
    let mut leds = Vec::with_capacity(k);
    let mut undetermined = Vec::new();
    for i in 0..k {
        let position = Vector3::new(theta[4 * i], theta[4 * i + 1], theta[4 * i + 2]);
        let intensity = (theta[4 * i + 3] - log_mean + nominal_log_mean).exp();
        rig.leds[i].position_mm = [position.x, position.y, position.z];
        rig.leds[i].intensity = intensity;
        let position_se_mm = [se(4 * i), se(4 * i + 1), se(4 * i + 2)];
        let intensity_se = se(4 * i + 3);
        let worst = position_se_mm.iter().copied().fold(0.0, f64::max);
        if worst.is_nan() || worst > MAX_POSITION_SE_MM {
            undetermined.push(format!(
                "LED {}'s position (standard error {worst:.1} mm): add sphere placements \
                 spread across the field of view and in depth, each lit by this LED",
                i + 1
            ));
        }
        if intensity_se.is_nan() || intensity_se > MAX_INTENSITY_SE {
            undetermined.push(format!(
                "LED {}'s intensity (standard error {:.2} %): add a placement where this \
                 LED lights most of the sphere",
                i + 1,
                100.0 * intensity_se
            ));
        }
        let per_led: Vec<f64> = (0..r.len())
            .filter(|j| j % k == i)
            .map(|j| r[j] * r[j])
            .collect();
        leds.push(LedFit {
            led: i + 1,
            position_mm: [position.x, position.y, position.z],
            position_se_mm,
            moved_mm: (position - nominal.leds[i].position()).norm(),
            intensity,
            intensity_se,
            rms_sigmas: (per_led.iter().sum::<f64>() / per_led.len().max(1) as f64).sqrt(),
        });
    }
    let sphere_centres_mm = (0..captures.len())
        .map(|c| {
            let centre = model.centre(&theta, c);
            [centre.x, centre.y, centre.z]
        })
        .collect();
    let mean_reading =
        pixels.iter().flat_map(|p| &p.a).sum::<f64>() / (pixels.len() * k).max(1) as f64;
    let rms_relative = model.rms_absolute(&theta) / mean_reading;
    Ok(LightFit {
        rig: Some(rig),
        leds,
        sphere_centres_mm,
        rms_sigmas: (cost / n as f64).sqrt(),
        rms_relative,
        residuals: n,
        iterations,
        undetermined,
    })
}

/// The sphere pixels of every capture within [`INNER_SHARE`] of the silhouette, subsampled.
fn gather(captures: &[SphereCapture], projection: &Projection) -> Vec<Pixel> {
    let mut pixels = Vec::new();
    for (c, capture) in captures.iter().enumerate() {
        let [cx, cy] = capture.sphere.centre_px;
        let inner = INNER_SHARE * capture.sphere.radius_px;
        let candidates: Vec<(usize, usize)> = capture
            .region
            .indexed_iter()
            .filter(|&((r, col), &m)| m && (col as f64 - cx).hypot(r as f64 - cy) < inner)
            .map(|(p, _)| p)
            .collect();
        let peaks: Vec<f64> = capture
            .images
            .iter()
            .map(|im| {
                let mut values: Vec<f64> = candidates
                    .iter()
                    .map(|&p| f64::from(im[p]))
                    .filter(|v| v.is_finite())
                    .collect();
                if values.is_empty() {
                    return f64::INFINITY;
                }
                let k = (values.len() - 1) * 99 / 100;
                *values.select_nth_unstable_by(k, f64::total_cmp).1
            })
            .collect();
        let stride = candidates.len().div_ceil(MAX_PIXELS_PER_CAPTURE).max(1);
        for &(r, col) in candidates.iter().step_by(stride) {
            let a: Vec<f64> = capture
                .images
                .iter()
                .map(|im| f64::from(im[(r, col)]))
                .collect();
            if a.iter().any(|v| !v.is_finite()) {
                continue;
            }
            let level = f64::from(capture.noise[(r, col)]).max(1e-6);
            // A reading left out (MIN_READING_SHARE) has an infinite σ: no weight.
            let sigma = capture
                .noise_gains
                .iter()
                .map(|g| g * level)
                .chain(std::iter::repeat(level))
                .take(a.len())
                .zip(capture.images.iter().zip(&peaks))
                .map(|(s, (im, &peak))| {
                    if local_mean(im, capture.region, r, col) >= MIN_READING_SHARE * peak {
                        s
                    } else {
                        f64::INFINITY
                    }
                })
                .collect();
            pixels.push(Pixel {
                capture: c,
                ray: projection.ray(r as f64, col as f64),
                a,
                sigma,
            });
        }
    }
    pixels
}

/// The mean of `image` over the 5×5 pixels around (`row`, `col`) inside `region`: the level
/// a reading is selected by (selecting by the reading itself would keep the ones that noise
/// pushed up).
fn local_mean(image: &Array2<f32>, region: &Array2<bool>, row: usize, col: usize) -> f64 {
    let (rows, cols) = image.dim();
    let (mut sum, mut count) = (0.0, 0usize);
    for r in row.saturating_sub(2)..(row + 3).min(rows) {
        for c in col.saturating_sub(2)..(col + 3).min(cols) {
            let v = f64::from(image[(r, c)]);
            if region[(r, c)] && v.is_finite() {
                sum += v;
                count += 1;
            }
        }
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// The model of the module docs over the gathered pixels.
struct Model<'a> {
    nominal: &'a Rig,
    pixels: &'a [Pixel],
    layout: &'a Layout,
    centres: &'a [Vector3<f64>],
    radius: f64,
}

impl Model<'_> {
    /// The nominal rig's positions, intensities from the first capture's readings, scales
    /// and heights from theirs.
    fn start(&self) -> DVector<f64> {
        let k = self.layout.leds;
        let mut theta = DVector::zeros(self.layout.len());
        for (i, led) in self.nominal.leds.iter().enumerate() {
            theta[4 * i] = led.position_mm[0];
            theta[4 * i + 1] = led.position_mm[1];
            theta[4 * i + 2] = led.position_mm[2];
            theta[4 * i + 3] = led.intensity.ln();
        }
        // Φ_i and s_c from median ratios of readings to the nominal model.
        let emitters: Vec<Emitter> = self.nominal.leds.iter().map(|l| l.emitter()).collect();
        let ratio = |i: usize, c: usize| {
            let mut ratios: Vec<f64> = self
                .pixels
                .iter()
                .filter(|p| p.capture == c)
                .filter_map(|p| {
                    let (x, n) = self.surface(&p.ray, &self.centres[c])?;
                    let predicted = n.dot(&emitters[i].light_vector_at(&x));
                    (predicted > 0.0 && p.a[i] > 5.0 * p.sigma[i]).then(|| p.a[i] / predicted)
                })
                .collect();
            if ratios.is_empty() {
                return None;
            }
            let middle = ratios.len() / 2;
            Some(*ratios.select_nth_unstable_by(middle, f64::total_cmp).1)
        };
        for i in 0..k {
            if let Some(q) = ratio(i, 0) {
                theta[4 * i + 3] += q.ln();
            }
        }
        for c in 1..self.layout.captures {
            let logs: Vec<f64> = (0..k)
                .filter_map(|i| Some((ratio(i, c)? / ratio(i, 0)?).ln()))
                .collect();
            if let (Some(j), false) = (self.layout.scale(c), logs.is_empty()) {
                theta[j] = logs.iter().sum::<f64>() / logs.len() as f64;
            }
            if let Some(j) = self.layout.height(c) {
                theta[j] = self.centres[c].z;
            }
        }
        theta
    }

    /// The centre of sphere `c` under `theta`.
    fn centre(&self, theta: &DVector<f64>, c: usize) -> Vector3<f64> {
        let mut centre = self.centres[c];
        if let Some(j) = self.layout.height(c) {
            centre.z = theta[j];
        }
        let j = self.layout.shift(c);
        centre.x += theta[j];
        centre.y += theta[j + 1];
        centre
    }

    /// The point and unit normal where `ray` meets the sphere at `centre` nearest the camera.
    fn surface(
        &self,
        ray: &PixelRay,
        centre: &Vector3<f64>,
    ) -> Option<(Vector3<f64>, Vector3<f64>)> {
        // |base + z·slope − C|² = R², the larger root (nearer the camera).
        let o = ray.base - centre;
        let (a, b, c) = (
            ray.slope.norm_squared(),
            2.0 * o.dot(&ray.slope),
            o.norm_squared() - self.radius * self.radius,
        );
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            return None;
        }
        let z = (-b + disc.sqrt()) / (2.0 * a);
        let x = ray.at(z);
        Some((x, (x - centre) / self.radius))
    }

    /// The weighted residuals (A_i − model)/σ_i, K per pixel (zero for a pixel whose ray
    /// misses the sphere under `theta`).
    fn residuals(&self, theta: &DVector<f64>) -> DVector<f64> {
        self.residuals_scaled(theta, true)
    }

    /// RMS of the unweighted residuals.
    fn rms_absolute(&self, theta: &DVector<f64>) -> f64 {
        let r = self.residuals_scaled(theta, false);
        (r.norm_squared() / r.len().max(1) as f64).sqrt()
    }

    fn residuals_scaled(&self, theta: &DVector<f64>, weighted: bool) -> DVector<f64> {
        let k = self.layout.leds;
        // Each LED as the rig file would hold it: an axis left out points at the origin from
        // the fitted position.
        let emitters: Vec<Emitter> = (0..k)
            .map(|i| {
                let mut led = self.nominal.leds[i].clone();
                led.position_mm = [theta[4 * i], theta[4 * i + 1], theta[4 * i + 2]];
                led.intensity = theta[4 * i + 3].exp();
                led.emitter()
            })
            .collect();
        let centres: Vec<Vector3<f64>> = (0..self.layout.captures)
            .map(|c| self.centre(theta, c))
            .collect();
        let scales: Vec<f64> = (0..self.layout.captures)
            .map(|c| self.layout.scale(c).map_or(1.0, |j| theta[j].exp()))
            .collect();
        let mut r = DVector::zeros(self.pixels.len() * k);
        for (j, p) in self.pixels.iter().enumerate() {
            let Some((x, n)) = self.surface(&p.ray, &centres[p.capture]) else {
                continue;
            };
            for i in 0..k {
                if !p.sigma[i].is_finite() {
                    continue;
                }
                let predicted =
                    scales[p.capture] * n.dot(&emitters[i].light_vector_at(&x)).max(0.0);
                let w = if weighted { p.sigma[i] } else { 1.0 };
                r[j * k + i] = (p.a[i] - predicted) / w;
            }
        }
        r
    }

    /// The Jacobian of [`Self::residuals`] by central differences.
    fn jacobian(&self, theta: &DVector<f64>) -> DMatrix<f64> {
        let p = theta.len();
        let columns: Vec<DVector<f64>> = (0..p)
            .map(|j| {
                // Positions and sphere heights in mm step by 0.01 mm; intensities and
                // scales (relative) by 10⁻⁵.
                let h = if self.layout.is_length(j) { 0.01 } else { 1e-5 };
                let (mut plus, mut minus) = (theta.clone(), theta.clone());
                plus[j] += h;
                minus[j] -= h;
                (self.residuals(&plus) - self.residuals(&minus)) / (2.0 * h)
            })
            .collect();
        DMatrix::from_columns(&columns)
    }
}
