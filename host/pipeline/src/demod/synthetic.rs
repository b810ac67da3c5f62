//! A small synthetic capture generator for the decoder's unit tests, written from
//! docs/maths/demodulation.md#the-received-signal
//! independently of the decoder's waveform model: each LED's on-time inside the exposure
//! window is summed chip by chip.

use meb_core::capture::memory::MemorySource;
use meb_core::capture::{Frame, FrameFormat, Samples};
use protocol::carriers::chip_is_on;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// A flat face filling the disc: LED i lights it at `levels[i]` in the middle, and each LED's
/// level grows towards the LED's side by the fraction 0.6·`tilt` per unit of the disc's
/// half-width (±0.55·`tilt` at its rim; 0: the LEDs in the same proportions on every pixel, a
/// sample of rank one).
pub struct Face {
    pub levels: Vec<f32>,
    pub tilt: f64,
}

/// Parameters of a synthetic capture.
pub struct Scene {
    pub width: usize,
    pub height: usize,
    pub leds: usize,
    pub frames: usize,
    pub exposure: f64,
    pub rate_ratio: f64,
    pub noise: f64,
    pub background: f64,
    pub seed: u64,
    pub bit_depth: u8,
    /// A flat face instead of the sphere.
    pub face: Option<Face>,
    /// Each LED's shift in chips (drawn from the seed when `None`).
    pub shifts: Option<Vec<f64>>,
}

impl Default for Scene {
    fn default() -> Self {
        Self {
            width: 64,
            height: 48,
            leds: 4,
            frames: 128,
            exposure: 1.0,
            rate_ratio: 1.0,
            noise: 0.01,
            background: 0.05,
            seed: 7,
            bit_depth: 16,
            face: None,
            shifts: None,
        }
    }
}

/// Fraction of `[t0, t0 + w]` during which LED `led` (shifted by `shift` chips) is on.
fn on_fraction(led: usize, shift: f64, t0: f64, w: f64) -> f64 {
    let start = t0 + shift;
    let end = start + w;
    let mut on = 0.0;
    let mut chip = start.floor();
    while chip < end {
        let lo = start.max(chip);
        let hi = end.min(chip + 1.0);
        let index = (chip as i64).rem_euclid(1 << 20) as usize;
        if chip_is_on(led, index) {
            on += hi - lo;
        }
        chip += 1.0;
    }
    on / w
}

/// Renders the scene: (source, true A_i images row-major, shifts used).
pub fn render(scene: &Scene) -> (MemorySource, Vec<Vec<f32>>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed);
    let drawn: Vec<f64> = (0..scene.leds)
        .map(|_| rng.random::<f64>() * 64.0)
        .collect();
    let shifts = scene.shifts.clone().unwrap_or(drawn);
    let (w, h) = (scene.width, scene.height);
    // A "sphere" lit from four sides: on-levels fall off towards each LED's far side.
    let truth: Vec<Vec<f32>> = (0..scene.leds)
        .map(|i| {
            let angle = i as f64 * std::f64::consts::TAU / scene.leds as f64;
            (0..w * h)
                .map(|p| {
                    let x = (p % w) as f64 / w as f64 * 2.0 - 1.0;
                    let y = (p / w) as f64 / h as f64 * 2.0 - 1.0;
                    let r2 = x * x + y * y;
                    if r2 > 0.85 {
                        return 0.0;
                    }
                    let (lx, ly) = (angle.cos() * 0.6, angle.sin() * 0.6);
                    if let Some(face) = &scene.face {
                        let level = f64::from(face.levels.get(i).copied().unwrap_or(0.0));
                        return (level * (1.0 + face.tilt * (x * lx + y * ly))) as f32;
                    }
                    let z = (1.0 - r2).sqrt();
                    (0.22 * (x * lx + y * ly + z * 0.8)).max(0.0) as f32
                })
                .collect()
        })
        .collect();
    let noise = Normal::new(0.0, scene.noise.max(1e-12)).ok();
    let max_code = ((1u32 << scene.bit_depth) - 1) as f64;
    let format = FrameFormat::full_range(w, h, scene.bit_depth, 960.0);
    let frames = (0..scene.frames)
        .map(|j| {
            let t0 = j as f64 * scene.rate_ratio;
            let width = scene.exposure * scene.rate_ratio;
            let on: Vec<f64> = (0..scene.leds)
                .map(|i| on_fraction(i, shifts[i], t0, width))
                .collect();
            let values = (0..w * h).map(|p| {
                let mut v = scene.background;
                for i in 0..scene.leds {
                    v += f64::from(truth[i][p]) * on[i];
                }
                if let Some(n) = &noise {
                    v += n.sample(&mut rng);
                }
                (v.clamp(0.0, 1.0) * max_code).round()
            });
            let samples = if scene.bit_depth > 8 {
                Samples::U16(values.map(|v| v as u16).collect())
            } else {
                Samples::U8(values.map(|v| v as u8).collect())
            };
            Frame { index: j, samples }
        })
        .collect();
    let source = MemorySource::new(format, frames).expect("synthetic frames match format");
    (source, truth, shifts)
}

/// Least-squares gain of `decoded` against `truth` over pixels where truth > 0.02, and the
/// RMS deviation from the gain-corrected truth.
pub fn gain_and_noise(decoded: &[f32], truth: &[f32]) -> (f64, f64) {
    let lit: Vec<usize> = (0..truth.len()).filter(|&p| truth[p] > 0.02).collect();
    let dot: f64 = lit
        .iter()
        .map(|&p| f64::from(decoded[p]) * f64::from(truth[p]))
        .sum();
    let norm: f64 = lit.iter().map(|&p| f64::from(truth[p]).powi(2)).sum();
    let gain = dot / norm;
    let rms = (lit
        .iter()
        .map(|&p| (f64::from(decoded[p]) - gain * f64::from(truth[p])).powi(2))
        .sum::<f64>()
        / lit.len() as f64)
        .sqrt();
    (gain, rms)
}
