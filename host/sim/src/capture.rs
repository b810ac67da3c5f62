//! The simulated camera: renders frames on demand (a [`FrameSource`]) and the ground truth.
//!
//! Frame f starts at t_f = start + f/fps; row r of it integrates light over
//! [t_f + r·line_time, t_f + r·line_time + exposure/fps) (rolling shutter; line time 0 is a
//! global shutter). A pixel then reads, before noise and tone curve
//! (docs/maths/demodulation.md#the-received-signal),
//!
//! ```text
//! v = E_bg-term + Σ_i A_i · on_fraction_i(window)
//! ```
//!
//! so with exposure 1 and chip rate = fps it equals B + Σ_i (A_i/2)·((1−α_i)s_i[j+k_i] +
//! α_i s_i[j+k_i+1]) with B = background + Σ_i A_i/2. Static scenes are shaded once; spinning
//! ones are re-shaded at every frame's start time. Noise is drawn from a ChaCha8 stream seeded
//! per (seed, frame, row), so any frame renders identically in any order and on any thread.

use super::SimulateError;
use super::geometry::SurfaceMap;
use super::lighting;
use super::material::Material;
use super::room::RoomEffects;
use super::scene::Scene;
use super::sensor::{NoiseModel, ToneCurve, quantise};
use super::waveform::{CarrierWaveform, LedWaveform};
use meb_core::capture::{CaptureError, Frame, FrameFormat, FrameSource, Samples};
use meb_core::rig::Rig;
use meb_core::types::LedImages;
use ndarray::{Array2, Array3};
use protocol::carriers::ChipTable;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::Arc;

/// Settings of a simulated capture (everything but the rig and the scene).
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Number of frames (≥ 1).
    pub frames: usize,
    /// Exposure time as a fraction of the frame period, in (0, 1].
    pub exposure: f64,
    /// Rolling-shutter line time in seconds (0 = global shutter).
    pub line_time_s: f64,
    /// Camera time of frame 0's start, seconds.
    pub start_time_s: f64,
    /// Bits per sample: 8, 10, 12 or 16.
    pub bit_depth: u8,
    /// Sensor noise.
    pub noise: NoiseModel,
    /// Output tone curve.
    pub tone: ToneCurve,
    /// Background light as an SNR in dB (thesis Eq. 4.3); `None` = dark room.
    pub snr_db: Option<f64>,
    /// Global gain g; `None` = [`lighting::default_gain`] with `peak`.
    pub gain: Option<f64>,
    /// Target peak of the brightest LED on the reference sphere when `gain` is `None`.
    pub peak: f64,
    /// Per-LED time shifts Δ_i in chips; `None` = uniform random in [0, n) from the seed.
    pub phases_chips: Option<Vec<f64>>,
    /// Per-LED chip rates in Hz (one value = all LEDs); `None` = the camera's fps.
    pub chip_rates_hz: Option<Vec<f64>>,
    /// Per-LED off-chip light as a fraction ℓ_i ∈ [0, 1) of the on light (one value = all
    /// LEDs; the luminaire's off level, [`CarrierWaveform::with_off_levels`]); `None` = dark
    /// off chips (full depth).
    pub off_levels: Option<Vec<f64>>,
    /// Seed of the phases and the noise.
    pub seed: u64,
    /// The objects' material (matte unless set; the ground plane is always matte).
    pub material: Material,
    /// Real-room effects: a flickering lamp, a gain drift, dropped or repeated frames (off by
    /// default, [`RoomEffects`]).
    pub room: RoomEffects,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            frames: 128,
            exposure: 1.0,
            line_time_s: 0.0,
            start_time_s: 0.0,
            bit_depth: 8,
            noise: NoiseModel {
                sigma: 0.005,
                full_well_electrons: None,
            },
            tone: ToneCurve::Linear,
            snr_db: None,
            gain: None,
            peak: lighting::DEFAULT_PEAK,
            phases_chips: None,
            chip_rates_hz: None,
            off_levels: None,
            seed: 0,
            material: Material::MATTE,
            room: RoomEffects::default(),
        }
    }
}

/// The scalar facts of a capture, as written to `truth.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TruthInfo {
    /// Number of LEDs N.
    pub leds: usize,
    /// Carrier frame length n = 2^(N+1) chips.
    pub chips_per_frame: usize,
    /// Time shift Δ_i of each LED in chips (LED i shows chip floor(t·rate_i + Δ_i) mod n).
    pub phases_chips: Vec<f64>,
    /// Chip rate of each LED in Hz.
    pub chip_rates_hz: Vec<f64>,
    /// Off-chip light of each LED as a fraction of its on light (0: full depth).
    pub off_levels: Vec<f64>,
    /// Camera frame rate.
    pub fps: f64,
    /// Number of frames.
    pub frames: usize,
    /// Exposure as a fraction of the frame period.
    pub exposure: f64,
    /// Rolling-shutter line time, seconds.
    pub line_time_s: f64,
    /// Start time of frame 0, seconds.
    pub start_time_s: f64,
    /// Bits per sample.
    pub bit_depth: u8,
    /// Sensor noise.
    pub noise: NoiseModel,
    /// Tone curve.
    pub tone: ToneCurve,
    /// Background SNR in dB, if any.
    pub snr_db: Option<f64>,
    /// Background irradiance E_bg (fraction of full scale on an upward white surface).
    pub background_irradiance: f64,
    /// Time-averaged LED irradiance P_signal on the same surface (Eq. 4.3).
    pub signal_irradiance: f64,
    /// Global gain g (code fraction per unit of Φ·cos^m θ/d², d in mm).
    pub gain: f64,
    /// Seed.
    pub seed: u64,
    /// Whether the geometry moves between frames.
    pub moving: bool,
    /// The objects' material.
    pub material: Material,
}

/// Ground truth of a capture at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundTruth {
    /// Camera time it describes, seconds.
    pub time_s: f64,
    /// Surface height z in mm; NaN outside the mask.
    pub depth_mm: Array2<f32>,
    /// H×W×3 unit normals; NaN outside the mask.
    pub normals: Array3<f32>,
    /// Object pixels (the ground plane is outside).
    pub mask: Array2<bool>,
    /// Albedo ρ; NaN outside the mask.
    pub albedo: Array2<f32>,
    /// What a perfect demodulator returns: each LED alone, no background, no noise.
    pub led_true: LedImages,
}

/// Per-LED images and background of one geometry.
#[derive(Debug)]
struct Shading {
    leds: Vec<Array2<f32>>,
    background: Array2<f32>,
}

/// A simulated capture: frames rendered on demand plus the ground truth.
pub struct SimulatedCapture {
    rig: Rig,
    scene: Scene,
    config: SimConfig,
    waveform: Arc<dyn LedWaveform>,
    format: FrameFormat,
    info: TruthInfo,
    static_shading: Option<Arc<Shading>>,
    next: usize,
}

impl std::fmt::Debug for SimulatedCapture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimulatedCapture")
            .field("info", &self.info)
            .field("next", &self.next)
            .finish_non_exhaustive()
    }
}

impl SimulatedCapture {
    /// Validates the settings and prepares a capture of `scene` under `rig` with the
    /// MEB-FDMA carriers (random phases from the seed unless given).
    pub fn new(rig: Rig, scene: Scene, config: SimConfig) -> Result<Self, SimulateError> {
        let bad = |field: &str, reason: String| SimulateError::Invalid {
            field: field.into(),
            reason,
        };
        rig.validate()?;
        super::check_camera_size(rig.camera.width, rig.camera.height, rig.leds.len())?;
        validate(&config, &scene)?;
        let leds = rig.leds.len();
        let table = ChipTable::new(leds as u8)?;
        let n = table.chips();
        let phases = match &config.phases_chips {
            Some(p) if p.len() == leds => p.clone(),
            Some(p) => {
                return Err(bad(
                    "phases",
                    format!("{} values given for {leds} LEDs", p.len()),
                ));
            }
            None => {
                let mut rng = ChaCha8Rng::seed_from_u64(mix(config.seed, 0x5048_4153, 0));
                (0..leds).map(|_| rng.random_range(0.0..n as f64)).collect()
            }
        };
        let rates = match &config.chip_rates_hz {
            None => vec![rig.camera.fps; leds],
            Some(r) if r.len() == 1 => vec![r[0]; leds],
            Some(r) if r.len() == leds => r.clone(),
            Some(r) => {
                return Err(bad(
                    "chip-rate",
                    format!(
                        "{} values given for {leds} LEDs (give 1 or {leds})",
                        r.len()
                    ),
                ));
            }
        };
        let waveform = CarrierWaveform::new(table, &rates, &phases).ok_or_else(|| {
            bad(
                "chip-rate/phases",
                "rates must be positive and phases finite".into(),
            )
        })?;
        let off_levels = match &config.off_levels {
            None => vec![0.0; leds],
            Some(l) if l.len() == 1 => vec![l[0]; leds],
            Some(l) if l.len() == leds => l.clone(),
            Some(l) => {
                return Err(bad(
                    "off-levels",
                    format!(
                        "{} values given for {leds} LEDs (give 1 or {leds})",
                        l.len()
                    ),
                ));
            }
        };
        if off_levels.iter().any(|l| !(0.0..1.0).contains(l)) {
            return Err(bad(
                "off-levels",
                format!("{off_levels:?}: each must lie in [0, 1)"),
            ));
        }
        let waveform = waveform
            .with_off_levels(&off_levels)
            .ok_or_else(|| bad("off-levels", "one per LED in [0, 1]".into()))?;
        let gain = config
            .gain
            .unwrap_or_else(|| lighting::default_gain(&rig, config.peak));
        let signal = lighting::signal_power(&rig, gain);
        let background = config
            .snr_db
            .map_or(0.0, |snr| lighting::background_power(&rig, gain, snr));
        let format = FrameFormat::full_range(
            rig.camera.width,
            rig.camera.height,
            config.bit_depth,
            rig.camera.fps,
        );
        let info = TruthInfo {
            leds,
            chips_per_frame: n,
            phases_chips: phases,
            chip_rates_hz: rates,
            off_levels,
            fps: rig.camera.fps,
            frames: config.frames,
            exposure: config.exposure,
            line_time_s: config.line_time_s,
            start_time_s: config.start_time_s,
            bit_depth: config.bit_depth,
            noise: config.noise,
            tone: config.tone,
            snr_db: config.snr_db,
            background_irradiance: background,
            signal_irradiance: signal,
            gain,
            seed: config.seed,
            moving: scene.is_moving(),
            material: config.material,
        };
        let mut capture = Self {
            rig,
            scene,
            config,
            waveform: Arc::new(waveform),
            format,
            info,
            static_shading: None,
            next: 0,
        };
        if !capture.scene.is_moving() {
            capture.static_shading = Some(Arc::new(capture.shade(0.0).1));
        }
        Ok(capture)
    }

    /// Replaces the LED waveform (e.g. a recorded luminaire timeline); it must drive as
    /// many LEDs as the rig has. `truth.json`'s phases and rates then describe nothing.
    pub fn with_waveform(mut self, waveform: Arc<dyn LedWaveform>) -> Result<Self, SimulateError> {
        if waveform.led_count() != self.rig.leds.len() {
            return Err(SimulateError::Invalid {
                field: "waveform".into(),
                reason: format!(
                    "drives {} LEDs, the rig has {}",
                    waveform.led_count(),
                    self.rig.leds.len()
                ),
            });
        }
        self.waveform = waveform;
        Ok(self)
    }

    /// The rig.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The settings.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// Phases, rates, gain and the other scalars of `truth.json`.
    pub fn info(&self) -> &TruthInfo {
        &self.info
    }

    /// Camera time at which frame `index` starts (its row 0).
    pub fn frame_time(&self, index: usize) -> f64 {
        self.config.start_time_s + index as f64 / self.rig.camera.fps
    }

    /// Ground truth at camera time `t_s` (geometry and the noise-free per-LED images).
    pub fn truth_at(&self, t_s: f64) -> GroundTruth {
        let (map, shading) = match (&self.static_shading, self.scene.is_moving()) {
            (Some(s), false) => (
                SurfaceMap::render(&self.scene, &self.rig.camera, t_s),
                Shading {
                    leds: s.leds.clone(),
                    background: s.background.clone(),
                },
            ),
            _ => self.shade(t_s),
        };
        let (h, w) = (map.height, map.width);
        let mask = Array2::from_shape_fn((h, w), |(r, c)| map.is_object[r * w + c]);
        let inside = |r: usize, c: usize, v: f64| {
            if mask[[r, c]] { v as f32 } else { f32::NAN }
        };
        GroundTruth {
            time_s: t_s,
            depth_mm: Array2::from_shape_fn((h, w), |(r, c)| inside(r, c, map.z_mm[r * w + c])),
            normals: Array3::from_shape_fn((h, w, 3), |(r, c, k)| {
                inside(r, c, map.normals[r * w + c][k])
            }),
            albedo: Array2::from_shape_fn((h, w), |(r, c)| inside(r, c, map.albedo[r * w + c])),
            mask,
            led_true: LedImages {
                images: shading.leds,
            },
        }
    }

    /// Integrated light of frame `index` per pixel, as a fraction of full scale, before
    /// noise, tone curve and quantisation (the docs/maths/demodulation.md#the-received-signal value
    /// r_j without its noise term).
    pub fn light_image(&self, index: usize) -> Array2<f32> {
        let t = self.frame_time(self.config.room.camera_frame(index));
        let shading = self.shading_at(t);
        let (w, h) = (self.format.width, self.format.height);
        Array2::from_shape_fn((h, w), |(row, col)| {
            let weights = self.row_weights(t, row, shading.leds.len());
            let mut v = shading.background[[row, col]];
            for (image, weight) in shading.leds.iter().zip(&weights) {
                v += weight * image[[row, col]];
            }
            self.room_light(index, t, row, col, f64::from(v)) as f32
        })
    }

    /// Light `v` of written frame `index` (camera time `t`) at (`row`, `col`) with the room's
    /// lamp added and the camera's gain drift applied ([`super::room`]).
    fn room_light(&self, index: usize, t: f64, row: usize, col: usize, v: f64) -> f64 {
        let room = &self.config.room;
        if room.is_off() {
            return v;
        }
        let mut v = v;
        if let Some(lamp) = &room.lamp {
            let t0 = t + row as f64 * self.config.line_time_s;
            let duration = self.config.exposure / self.rig.camera.fps;
            v += lamp.level
                * lamp.amplitude(col, self.format.width)
                * lamp.window_mean(t0, duration);
        }
        v * room.gain(index, self.config.frames)
    }

    /// Renders frame `index` (any index, in any order).
    pub fn render_frame(&self, index: usize) -> Frame {
        let t = self.frame_time(self.config.room.camera_frame(index));
        let shading = self.shading_at(t);
        let (w, h) = (self.format.width, self.format.height);
        let leds = shading.leds.len();
        let rows: Vec<Vec<u16>> = (0..h)
            .into_par_iter()
            .map(|row| {
                let weights = self.row_weights(t, row, leds);
                let mut rng =
                    ChaCha8Rng::seed_from_u64(mix(self.config.seed, index as u64, row as u64));
                let background = shading.background.row(row);
                (0..w)
                    .map(|col| {
                        let mut v = background[col];
                        for (image, weight) in shading.leds.iter().zip(&weights) {
                            v += weight * image[[row, col]];
                        }
                        let mut v = self.room_light(index, t, row, col, f64::from(v));
                        if !self.config.noise.is_noiseless() {
                            v = self.config.noise.apply(v, &mut rng);
                        }
                        quantise(self.config.tone.encode(v), self.config.bit_depth)
                    })
                    .collect()
            })
            .collect();
        let codes = rows.into_iter().flatten();
        let samples = if self.config.bit_depth == 8 {
            Samples::U8(codes.map(|c| c as u8).collect())
        } else {
            Samples::U16(codes.collect())
        };
        Frame { index, samples }
    }

    /// Fraction of row `row`'s exposure window each LED is on, for the frame starting at `t`.
    fn row_weights(&self, t: f64, row: usize, leds: usize) -> Vec<f32> {
        let exposure = self.config.exposure / self.rig.camera.fps;
        let t0 = t + row as f64 * self.config.line_time_s;
        (0..leds)
            .map(|i| self.waveform.on_fraction(i, t0, t0 + exposure) as f32)
            .collect()
    }

    /// Shading for a frame starting at `t` (cached when the scene is static).
    fn shading_at(&self, t: f64) -> Arc<Shading> {
        match &self.static_shading {
            Some(s) => Arc::clone(s),
            None => Arc::new(self.shade(t).1),
        }
    }

    /// Surface and shading at time `t_s`.
    fn shade(&self, t_s: f64) -> (SurfaceMap, Shading) {
        let map = SurfaceMap::render(&self.scene, &self.rig.camera, t_s);
        let leds = lighting::led_images_of(&map, &self.rig, self.info.gain, &self.config.material);
        let background = lighting::background_image(&map, self.info.background_irradiance);
        (map, Shading { leds, background })
    }
}

impl FrameSource for SimulatedCapture {
    fn format(&self) -> &FrameFormat {
        &self.format
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
        if self.next >= self.config.frames {
            return Ok(None);
        }
        let frame = self.render_frame(self.next);
        self.next += 1;
        Ok(Some(frame))
    }

    fn frame_count_hint(&self) -> Option<usize> {
        Some(self.config.frames.saturating_sub(self.next))
    }
}

/// Checks the settings; the error names the first bad one.
fn validate(config: &SimConfig, scene: &Scene) -> Result<(), SimulateError> {
    let bad = |field: &str, reason: &str| {
        Err(SimulateError::Invalid {
            field: field.into(),
            reason: reason.into(),
        })
    };
    if config.frames == 0 {
        return bad("frames", "must be at least 1");
    }
    if let Some(problem) = config.material.problem() {
        return bad("gloss/roughness", &problem);
    }
    if let Err((field, reason)) = config.room.validate() {
        return bad(field, reason);
    }
    if !(config.exposure > 0.0 && config.exposure <= 1.0) {
        return bad(
            "exposure",
            "must be in (0, 1] (fraction of the frame period)",
        );
    }
    if !(config.line_time_s.is_finite() && config.line_time_s >= 0.0) {
        return bad("line-time", "must be a number ≥ 0");
    }
    if !config.start_time_s.is_finite() {
        return bad("start-time", "must be finite");
    }
    if ![8, 10, 12, 16].contains(&config.bit_depth) {
        return bad("bit-depth", "must be 8, 10, 12 or 16");
    }
    if !(config.noise.sigma.is_finite() && config.noise.sigma >= 0.0) {
        return bad("noise", "must be a number ≥ 0");
    }
    if let Some(k) = config.noise.full_well_electrons
        && !(k.is_finite() && k > 0.0)
    {
        return bad("full-well", "must be a positive number of electrons");
    }
    if let ToneCurve::Gamma(g) = config.tone
        && !(g.is_finite() && g > 0.0)
    {
        return bad("gamma", "must be a positive number");
    }
    if let Some(snr) = config.snr_db
        && !snr.is_finite()
    {
        return bad("snr-db", "must be finite");
    }
    if let Some(g) = config.gain
        && !(g.is_finite() && g > 0.0)
    {
        return bad("gain", "must be a positive number");
    }
    if !(config.peak.is_finite() && config.peak > 0.0) {
        return bad("peak", "must be a positive number");
    }
    for object in &scene.objects {
        if !(object.albedo.is_finite() && (0.0..=1.0).contains(&object.albedo)) {
            return bad("albedo", "must be in [0, 1]");
        }
        if !object.position_mm.iter().all(|v| v.is_finite()) {
            return bad("position", "must be finite");
        }
        if let Some(spin) = &object.spin
            && !spin.rpm.is_finite()
        {
            return bad("rpm", "must be finite");
        }
    }
    Ok(())
}

/// SplitMix64-style mixing of a seed with two stream indices.
fn mix(seed: u64, a: u64, b: u64) -> u64 {
    let mut z =
        seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{GroundPlane, SceneObject, Shape};
    use meb_core::rig::Camera;
    use nalgebra::Vector3;

    /// The out-of-plane rig on a small camera with the same field of view in mm.
    fn small_rig(width: usize, height: usize) -> Rig {
        let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
        let pitch = rig.camera.pitch_mm() * 1280.0 / width as f64;
        rig.camera = Camera {
            width,
            height,
            fps: 960.0,
            distance_mm: 420.0,
            fov_deg: None,
            pixel_pitch_mm: Some(pitch),
            intrinsics: None,
            axis_px: None,
        };
        rig
    }

    fn sphere() -> Scene {
        Scene::single(SceneObject::new(Shape::Sphere { radius_mm: 24.0 }))
    }

    fn quiet(frames: usize) -> SimConfig {
        SimConfig {
            frames,
            noise: NoiseModel::NONE,
            bit_depth: 16,
            snr_db: Some(2.0),
            phases_chips: Some(vec![0.3, 1.7, 12.25, 29.9]),
            ..SimConfig::default()
        }
    }

    fn s(table: &ChipTable, led: usize, j: i64) -> f32 {
        let n = table.chips() as i64;
        if table.masks()[j.rem_euclid(n) as usize] & (1 << led) != 0 {
            1.0
        } else {
            -1.0
        }
    }

    /// docs/maths/demodulation.md#the-received-signal with exposure 1, no noise: r_j = B + Σ
    /// (A_i/2)((1−α)s[j+k] + α s[j+k+1]),
    /// B = background + Σ A_i/2; the quantised frame is that value rounded to 16 bits.
    #[test]
    fn frames_follow_the_spec_formula() {
        let capture = SimulatedCapture::new(small_rig(64, 36), sphere(), quiet(40)).unwrap();
        let truth = capture.truth_at(0.0);
        let background = capture.shading_at(0.0).background.clone();
        assert!(background.iter().any(|&b| b > 0.0));
        let table = ChipTable::new(4).unwrap();
        let phases = &capture.info().phases_chips;
        for j in [0usize, 1, 7, 31, 32, 39] {
            let light = capture.light_image(j);
            let frame = capture.render_frame(j);
            for (p, ((row, col), &value)) in light.indexed_iter().enumerate() {
                let a: Vec<f32> = truth
                    .led_true
                    .images
                    .iter()
                    .map(|im| im[[row, col]])
                    .collect();
                let mut want = background[[row, col]] + a.iter().sum::<f32>() / 2.0;
                for (i, ai) in a.iter().enumerate() {
                    let k = phases[i].floor() as i64;
                    let alpha = (phases[i] - k as f64) as f32;
                    let jj = j as i64 + k;
                    want += ai / 2.0
                        * ((1.0 - alpha) * s(&table, i, jj) + alpha * s(&table, i, jj + 1));
                }
                assert!(
                    (value - want).abs() < 1e-6,
                    "frame {j} ({row},{col}): {value} vs {want}"
                );
                let code = (f64::from(want).clamp(0.0, 1.0) * 65535.0).round();
                assert!((f64::from(frame.samples.code(p)) - code).abs() <= 1.0);
            }
        }
    }

    /// Row r of a rolling-shutter frame sees the carriers shifted by r·line_time·rate chips.
    #[test]
    fn rolling_shutter_shifts_the_phase_per_row() {
        let line_time = 0.37 / 960.0 / 36.0 * 10.0;
        let rolling = SimConfig {
            line_time_s: line_time,
            ..quiet(8)
        };
        let capture = SimulatedCapture::new(small_rig(64, 36), sphere(), rolling).unwrap();
        let global = SimulatedCapture::new(small_rig(64, 36), sphere(), quiet(8)).unwrap();
        for row in [0usize, 10, 18, 35] {
            let shift = row as f64 * line_time * 960.0;
            let phases: Vec<f64> = global
                .info()
                .phases_chips
                .iter()
                .map(|p| p + shift)
                .collect();
            let shifted = SimulatedCapture::new(
                small_rig(64, 36),
                sphere(),
                SimConfig {
                    phases_chips: Some(phases),
                    ..quiet(8)
                },
            )
            .unwrap();
            for j in 0..8 {
                let a = capture.light_image(j);
                let b = shifted.light_image(j);
                let g = global.light_image(j);
                for col in 0..64 {
                    assert!((a[[row, col]] - b[[row, col]]).abs() < 1e-6);
                }
                if row == 18 && j == 0 {
                    let differs = (0..64).any(|c| (a[[row, c]] - g[[row, c]]).abs() > 1e-4);
                    assert!(differs, "a late row must differ from a global shutter");
                }
            }
        }
    }

    #[test]
    fn a_seed_reproduces_a_capture_bit_for_bit() {
        let config = SimConfig {
            frames: 4,
            phases_chips: None,
            noise: NoiseModel {
                sigma: 0.01,
                full_well_electrons: Some(5000.0),
            },
            seed: 42,
            ..SimConfig::default()
        };
        let mut a = SimulatedCapture::new(small_rig(48, 27), sphere(), config.clone()).unwrap();
        let mut b = SimulatedCapture::new(small_rig(48, 27), sphere(), config.clone()).unwrap();
        let c = SimulatedCapture::new(
            small_rig(48, 27),
            sphere(),
            SimConfig { seed: 43, ..config },
        )
        .unwrap();
        assert_eq!(a.info().phases_chips, b.info().phases_chips);
        assert_ne!(a.info().phases_chips, c.info().phases_chips);
        assert_eq!(a.frame_count_hint(), Some(4));
        for j in 0..4 {
            let fa = a.next_frame().unwrap().unwrap();
            let fb = b.next_frame().unwrap().unwrap();
            assert_eq!(fa, fb);
            assert_ne!(fa, c.render_frame(j));
        }
        assert!(a.next_frame().unwrap().is_none());
        // The hint counts the frames not yet read.
        assert_eq!(a.frame_count_hint(), Some(0));
    }

    /// Under the out-of-plane rig, LED 1 (upper left, low) leaves the sphere's lower right in
    /// attached shadow and casts the sphere's shadow onto a ground plane to the lower right.
    #[test]
    fn out_of_plane_rig_shadows_the_sphere_where_expected() {
        let rig = small_rig(160, 90);
        let mut scene = sphere();
        scene.ground = Some(GroundPlane {
            z_mm: -24.0,
            albedo: 0.5,
        });
        let capture = SimulatedCapture::new(rig.clone(), scene, quiet(1)).unwrap();
        let truth = capture.truth_at(0.0);
        let led1 = &truth.led_true.images[0];
        let p1 = rig.leds[0].position();
        let (mut lit, mut attached) = (0, 0);
        for ((row, col), &inside) in truth.mask.indexed_iter() {
            if !inside {
                continue;
            }
            let (x, y) = rig.camera.pixel_centre_xy(row as f64, col as f64);
            let point = Vector3::new(x, y, f64::from(truth.depth_mm[[row, col]]));
            let n = Vector3::new(
                f64::from(truth.normals[[row, col, 0]]),
                f64::from(truth.normals[[row, col, 1]]),
                f64::from(truth.normals[[row, col, 2]]),
            );
            let facing = n.dot(&(p1 - point).normalize());
            if facing < -0.02 {
                assert_eq!(led1[[row, col]], 0.0, "attached shadow at ({row},{col})");
                attached += 1;
            } else if facing > 0.05 {
                assert!(led1[[row, col]] > 0.0, "lit at ({row},{col})");
                lit += 1;
            }
        }
        assert!(lit > 150 && attached > 50, "lit {lit} attached {attached}");
        // Ground point just beyond the sphere, away from LED 1: in its cast shadow.
        let away = -(p1.xy().normalize()) * 30.0;
        let (r, c) = rig.camera.xy_to_pixel(away.x, away.y);
        assert!(!truth.mask[[r.round() as usize, c.round() as usize]]);
        assert_eq!(led1[[r.round() as usize, c.round() as usize]], 0.0);
        // The same distance towards LED 1 is lit.
        let (r, c) = rig.camera.xy_to_pixel(-away.x, -away.y);
        assert!(led1[[r.round() as usize, c.round() as usize]] > 0.0);
        // The brightest LED peaks near the default 0.4 of full scale.
        let peak = truth
            .led_true
            .images
            .iter()
            .flatten()
            .fold(0f32, |m, &v| m.max(v));
        assert!((0.35..=0.45).contains(&peak), "peak {peak}");
    }

    #[test]
    fn bad_settings_are_named() {
        let err = SimulatedCapture::new(
            small_rig(8, 8),
            sphere(),
            SimConfig {
                frames: 0,
                ..SimConfig::default()
            },
        )
        .unwrap_err();
        assert!(err.to_string().contains("frames"), "{err}");
        let err = SimulatedCapture::new(
            small_rig(8, 8),
            sphere(),
            SimConfig {
                bit_depth: 9,
                ..SimConfig::default()
            },
        )
        .unwrap_err();
        assert!(err.to_string().contains("bit-depth"), "{err}");
        let err = SimulatedCapture::new(
            small_rig(8, 8),
            sphere(),
            SimConfig {
                phases_chips: Some(vec![0.0]),
                ..SimConfig::default()
            },
        )
        .unwrap_err();
        assert!(err.to_string().contains("phases"), "{err}");
    }
}
