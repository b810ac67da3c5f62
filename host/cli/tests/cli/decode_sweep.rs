//! Randomised sweep of the decoder over simulated captures (fixed seeds): every capture is
//! either decoded with each LED's gain within 1 % (2 % with a rolling shutter) or refused by the
//! quality verdict — never decoded wrong in silence — and at least 98 % are decoded. The room
//! is steady, so no decode may report mains flicker or an exposure drift.
//!
//! 200 captures of 96×64 pixels: chip/frame rate ratio uniform in [0.95, 1.05], exposure in
//! [0.2, 1], random phases, unmodulated background 0–0.3 of full scale, tone curve linear /
//! gamma 2.2 / sRGB (decoded with the matching linearisation), read noise 0.2–2 % (log-uniform),
//! rolling shutter on or off (a phase ramp of 0.2–1 chip over the frame), a sphere covering
//! 0.5–30 % of the frame on a dark or lit (ground plane) background, N = 2..6 LEDs.
//!
//! A gain is the least-squares ratio of the decoded to the true on-levels over the lit pixels
//! the decoder kept. On a small, noisy object that ratio is itself uncertain, so each LED's
//! tolerance is widened by three standard errors of an oracle that knows the true waveforms
//! (a per-pixel least-squares fit against the simulator's own on-fractions, written here from
//! docs/maths/demodulation.md#the-received-signal and the simulator's `CarrierWaveform`,
//! independent of the decoder).

use meb_core::capture::memory::MemorySource;
use meb_core::capture::{Frame, FrameFormat, FrameSource, Samples};
use meb_core::rig::Rig;
use meb_pipeline::demod::{
    DecodeConfig, DemodError, LedCount, Linearize, OnImplausible, VerdictStatus, decode,
};
use meb_sim::capture::{SimConfig, SimulatedCapture};
use meb_sim::scene::{GroundPlane, Scene, SceneObject};
use meb_sim::sensor::{NoiseModel, ToneCurve};
use meb_sim::{CarrierWaveform, LedWaveform};
use nalgebra::{DMatrix, DVector};
use protocol::carriers::ChipTable;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::common;
use common::rig_toml;

const WIDTH: usize = 96;
const HEIGHT: usize = 64;
const CAPTURES: u64 = 200;
const FPS: f64 = 960.0;
/// LED positions (mm); a capture with N LEDs uses the first N.
const LEDS: [[f64; 3]; 6] = [
    [-270.0, 420.0, 100.0],
    [-140.0, 420.0, 350.0],
    [140.0, 420.0, 350.0],
    [270.0, 420.0, 100.0],
    [0.0, -380.0, 300.0],
    [0.0, 200.0, 450.0],
];

/// One capture's settings.
#[derive(Debug, Clone)]
struct Case {
    index: u64,
    leds: usize,
    rate_ratio: f64,
    exposure: f64,
    background: f64,
    tone: ToneCurve,
    noise: f64,
    ramp_chips: Option<f64>,
    cover: f64,
    ground_albedo: Option<f64>,
    seed: u64,
}

impl Case {
    fn new(index: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(0x5_7ee9 + index);
        let log_uniform = |rng: &mut ChaCha8Rng, lo: f64, hi: f64| {
            (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp()
        };
        Self {
            index,
            leds: rng.random_range(2..=6),
            rate_ratio: rng.random_range(0.95..1.05),
            exposure: rng.random_range(0.2..1.0),
            background: rng.random_range(0.0..0.3),
            tone: match rng.random_range(0..3) {
                0 => ToneCurve::Linear,
                1 => ToneCurve::Gamma(2.2),
                _ => ToneCurve::Srgb,
            },
            noise: log_uniform(&mut rng, 0.002, 0.02),
            ramp_chips: rng.random_bool(0.5).then(|| rng.random_range(0.2..1.0)),
            cover: log_uniform(&mut rng, 0.005, 0.3),
            ground_albedo: rng.random_bool(0.5).then(|| rng.random_range(0.2..0.8)),
            seed: rng.random(),
        }
    }

    fn linearize(&self) -> Linearize {
        match self.tone {
            ToneCurve::Linear => Linearize::None,
            ToneCurve::Gamma(g) => Linearize::Gamma(g as f32),
            ToneCurve::Srgb => Linearize::Srgb,
        }
    }

    /// The simulated capture (pitch 1 mm, so the sphere's diameter sets the cover).
    fn capture(&self) -> SimulatedCapture {
        let rig =
            Rig::from_toml_str(&rig_toml(WIDTH, HEIGHT, 1.0, &LEDS[..self.leds]), "sweep").unwrap();
        let diameter = 2.0 * (self.cover * (WIDTH * HEIGHT) as f64 / std::f64::consts::PI).sqrt();
        let mut scene = Scene::single(SceneObject::sphere(diameter));
        if let Some(albedo) = self.ground_albedo {
            scene.ground = Some(GroundPlane {
                z_mm: -diameter / 2.0,
                albedo,
            });
        }
        let frames = 64usize.max(1 << (self.leds + 1));
        let config = |snr_db| SimConfig {
            frames,
            exposure: self.exposure,
            line_time_s: self
                .ramp_chips
                .map_or(0.0, |r| r / (HEIGHT as f64 * FPS * self.rate_ratio)),
            bit_depth: 8,
            noise: NoiseModel {
                sigma: self.noise,
                full_well_electrons: None,
            },
            tone: self.tone,
            snr_db,
            peak: (0.4f64).min((0.95 - self.background) / (0.7 * self.leds as f64)),
            chip_rates_hz: Some(vec![FPS * self.rate_ratio]),
            seed: self.seed,
            ..SimConfig::default()
        };
        let dark = SimulatedCapture::new(rig.clone(), scene.clone(), config(None)).unwrap();
        if self.background < 1e-3 {
            return dark;
        }
        let snr_db = 10.0 * (dark.info().signal_irradiance / self.background).log10();
        SimulatedCapture::new(rig, scene, config(Some(snr_db))).unwrap()
    }

    fn tolerance(&self) -> f64 {
        if self.ramp_chips.is_some() {
            0.02
        } else {
            0.01
        }
    }
}

/// What happened to one capture.
#[derive(Debug)]
enum Outcome {
    /// Decoded as plausible: per LED (gain, oracle gain, oracle standard error), and the room
    /// nuisances the decoder reported (a steady room: none).
    Decoded(Vec<(f64, f64, f64)>, Option<String>),
    /// Refused: the reason.
    Refused(String),
}

/// Code value → linear light for the capture's tone curve (the inverse of the simulator's).
fn linear(tone: ToneCurve, code: f64) -> f64 {
    match tone {
        ToneCurve::Linear => code,
        ToneCurve::Gamma(g) => code.powf(g),
        ToneCurve::Srgb => {
            if code <= 0.04045 {
                code / 12.92
            } else {
                ((code + 0.055) / 1.055).powf(2.4)
            }
        }
    }
}

/// Per LED: the oracle's gain and its standard error over `lit` pixels (see module docs).
fn oracle(
    case: &Case,
    capture: &SimulatedCapture,
    frames: &[Frame],
    keep: &[bool],
) -> Vec<(f64, f64)> {
    let info = capture.info();
    let table = ChipTable::new(case.leds as u8).unwrap();
    let waveform = CarrierWaveform::new(table, &info.chip_rates_hz, &info.phases_chips).unwrap();
    let truth = capture.truth_at(0.0).led_true;
    let count = frames.len();
    let k = case.leds + 1;
    let mut sums = vec![(0.0, 0.0, 0.0); case.leds];
    for row in 0..HEIGHT {
        let design = DMatrix::from_fn(count, k, |j, c| {
            if c == 0 {
                return 1.0;
            }
            let t0 = capture.frame_time(j) + row as f64 * info.line_time_s;
            waveform.on_fraction(c - 1, t0, t0 + info.exposure / FPS)
        });
        let normal = (design.transpose() * &design).try_inverse().unwrap();
        let solve = &normal * design.transpose();
        for col in 0..WIDTH {
            let p = row * WIDTH + col;
            let r = DVector::from_fn(count, |j, _| match &frames[j].samples {
                Samples::U8(v) => linear(case.tone, f64::from(v[p]) / 255.0),
                Samples::U16(v) => linear(case.tone, f64::from(v[p]) / 65535.0),
            });
            let c = &solve * &r;
            let residual = &r - &design * &c;
            let variance = residual.norm_squared() / (count - k) as f64;
            for (i, sum) in sums.iter_mut().enumerate() {
                let t = f64::from(truth.images[i][[row, col]]);
                let top = truth.images[i].iter().copied().fold(0.0f32, f32::max);
                if keep[p] && t > 0.1 * f64::from(top) {
                    sum.0 += c[i + 1] * t;
                    sum.1 += t * t;
                    sum.2 += t * t * variance * normal[(i + 1, i + 1)];
                }
            }
        }
    }
    sums.iter()
        .map(|(dt, tt, var)| (dt / tt, var.sqrt() / tt))
        .collect()
}

fn run(case: &Case) -> Outcome {
    let capture = case.capture();
    let frames: Vec<Frame> = (0..capture.config().frames)
        .map(|j| capture.render_frame(j))
        .collect();
    let format = FrameFormat::full_range(WIDTH, HEIGHT, 8, FPS);
    let mut source = MemorySource::new(format, frames.clone()).unwrap();
    assert_eq!(source.frame_count_hint(), Some(frames.len()));
    let config = DecodeConfig {
        leds: LedCount::Fixed(case.leds),
        linearize: case.linearize(),
        on_implausible: OnImplausible::Keep,
        ..DecodeConfig::default()
    };
    let decoded = match decode(&mut source, &config, &mut |_, _| {}) {
        Ok(d) => d,
        Err(
            e @ (DemodError::LedCountMismatch { .. }
            | DemodError::LedsHiddenByClipping { .. }
            | DemodError::NoModulation),
        ) => {
            return Outcome::Refused(e.to_string());
        }
        Err(e) => panic!("capture {}: unexpected error {e}", case.index),
    };
    if decoded.report.verdict.status != VerdictStatus::Plausible {
        return Outcome::Refused(decoded.report.verdict.problems.join("; "));
    }
    let keep: Vec<bool> = decoded
        .saturated
        .iter()
        .zip(decoded.underexposed.iter())
        .map(|(s, u)| !s && !u)
        .collect();
    let truth = capture.truth_at(0.0).led_true;
    let oracle = oracle(case, &capture, &frames, &keep);
    let gains = (0..case.leds)
        .map(|i| {
            let top = truth.images[i].iter().copied().fold(0.0f32, f32::max);
            let (mut dt, mut tt) = (0.0, 0.0);
            for ((d, t), k) in decoded.leds.images[i]
                .iter()
                .zip(&truth.images[i])
                .zip(&keep)
            {
                if *k && *t > 0.1 * top {
                    dt += f64::from(*d) * f64::from(*t);
                    tt += f64::from(*t) * f64::from(*t);
                }
            }
            (dt / tt, oracle[i].0, oracle[i].1)
        })
        .collect();
    let room = &decoded.report.room;
    let reported =
        (!room.flicker.is_empty() || room.exposure_drift.is_some()).then(|| format!("{room:?}"));
    Outcome::Decoded(gains, reported)
}

/// The q-quantile of sorted values.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

#[test]
fn every_capture_is_decoded_within_tolerance_or_refused() {
    let started = std::time::Instant::now();
    let cases: Vec<Case> = (0..CAPTURES).map(Case::new).collect();
    let outcomes: Vec<(Case, Outcome)> = cases
        .into_par_iter()
        .map(|case| {
            let outcome = run(&case);
            (case, outcome)
        })
        .collect();
    let mut errors = Vec::new();
    let mut versus_oracle = Vec::new();
    let mut silent = Vec::new();
    let mut refused = Vec::new();
    let mut room = Vec::new();
    for (case, outcome) in &outcomes {
        match outcome {
            Outcome::Decoded(gains, reported) => {
                if let Some(reported) = reported {
                    room.push(format!("capture {}: {reported} {case:?}", case.index));
                }
                for (i, &(gain, oracle, sigma)) in gains.iter().enumerate() {
                    errors.push((gain - 1.0).abs());
                    versus_oracle.push((gain - oracle).abs());
                    if (gain - 1.0).abs() > case.tolerance() + 3.0 * sigma {
                        silent.push(format!(
                            "capture {} LED {}: gain {gain:.4} (oracle {oracle:.4} ± {sigma:.4}) {case:?}",
                            case.index,
                            i + 1
                        ));
                    }
                }
            }
            Outcome::Refused(reason) => {
                refused.push(format!("capture {}: {reason} {case:?}", case.index))
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    versus_oracle.sort_by(f64::total_cmp);
    let decoded = outcomes.len() - refused.len();
    eprintln!(
        "sweep ({:.0} s): {decoded}/{} decoded, {} refused; |gain − 1| over {} LED gains: median \
         {:.4} %, 90 % {:.4} %, 99 % {:.4} %, max {:.4} %; |gain − oracle gain|: median {:.4} %, \
         99 % {:.4} %, max {:.4} %",
        started.elapsed().as_secs_f64(),
        outcomes.len(),
        refused.len(),
        errors.len(),
        100.0 * quantile(&errors, 0.5),
        100.0 * quantile(&errors, 0.9),
        100.0 * quantile(&errors, 0.99),
        100.0 * quantile(&errors, 1.0),
        100.0 * quantile(&versus_oracle, 0.5),
        100.0 * quantile(&versus_oracle, 0.99),
        100.0 * quantile(&versus_oracle, 1.0),
    );
    for line in &refused {
        eprintln!("refused: {line}");
    }
    assert!(silent.is_empty(), "silent failures:\n{}", silent.join("\n"));
    assert!(
        room.is_empty(),
        "room nuisances reported in steady captures:\n{}",
        room.join("\n")
    );
    assert!(
        decoded * 100 >= outcomes.len() * 98,
        "only {decoded} of {} captures decoded",
        outcomes.len()
    );
}
