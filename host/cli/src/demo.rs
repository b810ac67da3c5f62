//! The end-to-end demonstration (docs/maths/accuracy.md#the-demonstration): simulate a thesis
//! scene, decode it with the
//! MEB-FDMA demodulator, reconstruct it through the decoded-capture path every other caller
//! uses ([`meb_pipeline::reconstruct::reconstruct`]), and compare with the simulator's ground truth
//! over the surface lit by ≥ 3 LEDs.
//!
//! The capture is exposed like a real one, so that nothing clips
//! ([`meb_sim::exposure::expose_without_clipping`]).

use meb_core::capture::FrameSource;
use meb_core::metrics::{AngularErrors, DepthErrors, MetricsError, compare_depth, compare_normals};
use meb_core::rig::Rig;
use meb_core::timing::StageTiming;
use meb_pipeline::demod::{DecodeConfig, Decoded, DemodError, Linearize, decode};
use meb_pipeline::reconstruct::{
    ReconstructConfig, ReconstructError, Reconstruction, Request, Source, reconstruct,
};
use meb_sim::exposure::expose_without_clipping;
use meb_sim::{
    GroundTruth, NoiseModel, Scene, SimConfig, SimulateError, SimulatedCapture, ToneCurve,
};
use ndarray::Array2;
use std::time::Instant;
use thiserror::Error;

/// Errors of the demonstration run.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DemoError {
    /// The simulator rejected the settings.
    #[error("simulation")]
    Simulate(#[from] SimulateError),
    /// Decoding failed.
    #[error(transparent)]
    Decode(#[from] DemodError),
    /// Reconstruction failed.
    #[error(transparent)]
    Reconstruct(#[from] ReconstructError),
    /// Comparison with ground truth failed.
    #[error(transparent)]
    Metrics(#[from] MetricsError),
}

/// The thesis' Ch. 4 capture settings: 128 frames, σ = 1 % noise, background at 0 dB SNR,
/// exposure 0.8 of the frame period, gamma 2.2 output.
pub fn thesis_capture_config(seed: u64) -> SimConfig {
    SimConfig {
        frames: 128,
        exposure: 0.8,
        noise: NoiseModel {
            sigma: 0.01,
            full_well_electrons: None,
        },
        tone: ToneCurve::Gamma(2.2),
        snr_db: Some(0.0),
        seed,
        ..SimConfig::default()
    }
}

/// Decoder settings matching [`thesis_capture_config`] (linearise gamma 2.2).
pub fn thesis_decode_config(leds: usize) -> DecodeConfig {
    DecodeConfig {
        leds: meb_pipeline::demod::LedCount::Fixed(leds),
        linearize: Linearize::Gamma(2.2),
        ..DecodeConfig::default()
    }
}

/// Everything one demonstration run produced.
#[derive(Debug)]
pub struct DemoRun {
    /// The decoder's output.
    pub decoded: Decoded,
    /// The reconstruction.
    pub reconstruction: Reconstruction,
    /// Ground truth at frame 0.
    pub truth: GroundTruth,
    /// Object pixels lit by at least three LEDs (where the accuracy is measured).
    pub lit_by_three: Array2<bool>,
    /// Depth accuracy over `lit_by_three`.
    pub depth_errors: DepthErrors,
    /// Normal accuracy over `lit_by_three`.
    pub angular_errors: AngularErrors,
    /// Timing of simulation + decoding + reconstruction stages.
    pub timings: Vec<StageTiming>,
}

/// Simulates `scene` under `rig` (exposed by [`expose_without_clipping`]), decodes,
/// reconstructs with `config` and compares; `progress(done, total)` reports decoded frames.
pub fn run(
    rig: &Rig,
    scene: Scene,
    sim: SimConfig,
    decode_config: &DecodeConfig,
    config: &ReconstructConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<DemoRun, DemoError> {
    let start = Instant::now();
    let sim = expose_without_clipping(rig, &scene, sim)?;
    let mut capture = SimulatedCapture::new(rig.clone(), scene, sim)?;
    let truth = capture.truth_at(0.0);
    let mut timings = vec![StageTiming::since(
        "simulation set-up + ground truth",
        start,
    )];
    let start = Instant::now();
    let source: &mut dyn FrameSource = &mut capture;
    let decoded = decode(source, decode_config, progress)?;
    timings.push(StageTiming::since("render frames + decode", start));
    let reconstruction = reconstruct(Source::Decoded(&decoded), rig, config, Request::default())?;
    timings.extend(reconstruction.timings.iter().cloned());
    let lit_by_three = Array2::from_shape_fn(truth.mask.dim(), |p| {
        truth.mask[p]
            && truth
                .led_true
                .images
                .iter()
                .filter(|im| im[p] > 0.0)
                .count()
                >= 3
    });
    let depth_errors = compare_depth(
        &reconstruction.integration.depth.depth_mm,
        &truth.depth_mm,
        Some(&lit_by_three),
    )?;
    let angular_errors = compare_normals(
        &reconstruction.photometric.field.normals,
        &truth.normals,
        &lit_by_three,
    )?;
    Ok(DemoRun {
        decoded,
        reconstruction,
        truth,
        lit_by_three,
        depth_errors,
        angular_errors,
        timings,
    })
}
