//! End to end at the factory default's low modulation depths: a virtual luminaire that was never
//! configured (4 LEDs at 960 Hz, each LED 2 % below its largest IEEE 1789 low-risk depth: off
//! levels 743, 698, 891, 890 ‰) lights a simulated sphere through its recorded timeline. Decoded
//! with the timeline's depths, the LED images are their full-depth equivalents and the
//! reconstruction with the true rig meets a normal-error bound propagated from the decode's own
//! noise; decoded without them, the rig check refuses the result
//! (docs/howto/flicker-safety.md#decoding-a-low-depth-capture).

use std::sync::Arc;

use hil_tests::client;
use meb_core::capture::{FrameFormat, FrameSource, Samples};
use meb_core::metrics::angular::compare_normals;
use meb_core::metrics::depth::compare_depth;
use meb_core::rig::Rig;
use meb_device::{EmulatorOptions, Timeline, TimelineWaveform, VirtualLuminaire};
use meb_pipeline::demod::{
    DecodeConfig, Decoded, Linearize, ModulationDepths, OnImplausible, decode_frames,
};
use meb_pipeline::reconstruct::acceptance::{self, Ruling};
use meb_pipeline::reconstruct::{
    ReconstructConfig, Reconstruction, Request, Source, check_decoded_rig, level_noise, reconstruct,
};
use meb_sim::exposure::expose_without_clipping;
use meb_sim::{NoiseModel, Scene, SceneObject, Shape, SimConfig, SimulatedCapture, ToneCurve};
use nalgebra::{Matrix3, Vector3};
use ndarray::Array2;
use protocol::config::LuminaireConfig;
use protocol::flicker;

/// Frames: 8× the thesis' 128, so that LEDs 3 and 4 (depth 0.058, images ×9.2 of full depth's
/// noise) have their gains determined as the decode verdict asks.
const FRAMES: usize = 1024;

/// Records what a factory-fresh virtual luminaire plays.
fn factory_timeline() -> Timeline {
    let emulator = VirtualLuminaire::spawn(EmulatorOptions::default()).unwrap();
    let mut c = client(emulator.port_path());
    let config = c.config().unwrap();
    assert_eq!(config, LuminaireConfig::DEFAULT);
    assert!(
        flicker::is_low_risk(&config),
        "the factory default flickers"
    );
    drop(c);
    emulator.shutdown().unwrap()
}

fn rig() -> Rig {
    let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
    rig.camera.width = 192;
    rig.camera.height = 128;
    rig.camera.fov_deg = None;
    rig.camera.pixel_pitch_mm = Some(0.5);
    rig
}

/// Decodes the rendered `frames` as `meb decode --linearize gamma:2.2` does, told `depths`.
fn decode_with(frames: &[Samples], format: &FrameFormat, depths: ModulationDepths) -> Decoded {
    let config = DecodeConfig {
        linearize: Linearize::Gamma(2.2),
        depths,
        on_implausible: OnImplausible::Keep,
        ..DecodeConfig::default()
    };
    decode_frames(frames, format, &config).unwrap()
}

/// Mean normal error in degrees that the decode's noise alone gives over `pixels`, propagated
/// through the four-LED Lambertian solve at the true normals and albedo (light vectors at the
/// sphere's centre, times the simulator's `gain` from rig units to full scale): cov(ρn) =
/// (Lᵀ Σ⁻¹ L)⁻¹ with σ_i = g_i·σ_A(p), its part across n over ρ², and E|δθ| = √(π/4 · trace)
/// for a two-dimensional Gaussian.
fn predicted_normal_error_deg(
    decoded: &Decoded,
    reconstruction: &Reconstruction,
    rig: &Rig,
    truth: &meb_sim::GroundTruth,
    gain: f64,
    pixels: &Array2<bool>,
) -> f64 {
    let sigma_a = level_noise(decoded);
    let gains = &reconstruction.photometric.noise_gains;
    let lights: Vec<Vector3<f64>> = rig
        .leds
        .iter()
        .map(|led| gain * led.light_vector_at(&Vector3::zeros()))
        .collect();
    let (mut sum, mut count) = (0.0, 0usize);
    for ((row, col), &use_it) in pixels.indexed_iter() {
        let rho = f64::from(truth.albedo[(row, col)]);
        let n = Vector3::from_fn(|k, _| f64::from(truth.normals[(row, col, k)]));
        if !use_it || rho.is_nan() || rho <= 0.0 || !n.iter().all(|v| v.is_finite()) {
            continue;
        }
        let mut information = Matrix3::zeros();
        for (l, g) in lights.iter().zip(gains) {
            let sigma = g * f64::from(sigma_a[(row, col)]);
            information += l * l.transpose() / (sigma * sigma);
        }
        let Some(cov) = information.try_inverse() else {
            continue;
        };
        let across = Matrix3::identity() - n * n.transpose();
        let trace = (across * cov * across).trace() / (rho * rho);
        sum += (std::f64::consts::FRAC_PI_4 * trace).sqrt().to_degrees();
        count += 1;
    }
    sum / count.max(1) as f64
}

#[test]
fn factory_depths_decoded_with_the_timeline_reconstruct_and_without_are_refused() {
    let timeline = factory_timeline();
    let segment = timeline.segment_at(None).unwrap();
    let off_fractions = segment.off_fractions();
    assert_eq!(off_fractions, vec![0.743, 0.698, 0.891, 0.890]);

    // The thesis' conditions (σ = 1 %, background at 0 dB SNR, exposure 0.8, gamma 2.2).
    let rig = rig();
    let scene = Scene::single(SceneObject::new(Shape::Sphere { radius_mm: 24.0 }));
    let sim = SimConfig {
        frames: FRAMES,
        exposure: 0.8,
        noise: NoiseModel {
            sigma: 0.01,
            full_well_electrons: None,
        },
        snr_db: Some(0.0),
        tone: ToneCurve::Gamma(2.2),
        seed: 7,
        ..SimConfig::default()
    };
    let sim = expose_without_clipping(&rig, &scene, sim).unwrap();
    let waveform = TimelineWaveform::from_last_change(&timeline).unwrap();
    let capture = SimulatedCapture::new(rig.clone(), scene, sim)
        .unwrap()
        .with_waveform(Arc::new(waveform))
        .unwrap();
    let truth = capture.truth_at(0.0);
    let format = capture.format().clone();
    let frames: Vec<Samples> = (0..FRAMES)
        .map(|j| capture.render_frame(j).samples)
        .collect();
    let lit = |count: usize| {
        Array2::from_shape_fn(truth.mask.dim(), |p| {
            truth.mask[p] && truth.led_true.images.iter().filter(|i| i[p] > 0.0).count() >= count
        })
    };
    let (lit_by_three, lit_by_four) = (lit(3), lit(4));

    // With the timeline's depths: plausible, scaled, and each LED image on the truth's scale.
    let decoded = decode_with(
        &frames,
        &format,
        ModulationDepths::OffFractions(off_fractions.clone()),
    );
    let report = &decoded.report;
    assert!(
        report.verdict.is_plausible(),
        "{:?}",
        report.verdict.problems
    );
    for (i, (scale, l)) in report
        .modulation
        .image_scale
        .iter()
        .zip(&off_fractions)
        .enumerate()
    {
        assert!((scale * (1.0 - l) - 1.0).abs() < 1e-12, "LED {}", i + 1);
    }
    let gains = gains_against_truth(&decoded, &truth);
    eprintln!("low depth: LED gains against the truth {gains:.4?}");
    for (i, g) in gains.iter().enumerate() {
        // Each gain rests on thousands of pixels: its noise is far below 1 %; the decoder's
        // own gain bias at the thesis' exposure is a few tenths of a percent.
        assert!((g - 1.0).abs() < 0.03, "LED {} gain {g:.4}", i + 1);
    }
    let config = ReconstructConfig::decoded_capture();
    let reconstruction =
        reconstruct(Source::Decoded(&decoded), &rig, &config, Request::default()).unwrap();
    let check = check_decoded_rig(&decoded, &rig, &reconstruction, &config);
    let implausible = !reconstruction.support.verdict.is_plausible();
    let (ruling, _) = acceptance::rig(&check, "true rig", false, implausible, "--force");
    assert_eq!(ruling, Ruling::Keep, "{}", check.describe("true rig"));
    assert!(!implausible, "{:?}", reconstruction.support);
    let normals = compare_normals(
        &reconstruction.photometric.field.normals,
        &truth.normals,
        &lit_by_four,
    )
    .unwrap();
    let predicted = predicted_normal_error_deg(
        &decoded,
        &reconstruction,
        &rig,
        &truth,
        capture.info().gain,
        &lit_by_four,
    );
    let depth = compare_depth(
        &reconstruction.integration.depth.depth_mm,
        &truth.depth_mm,
        Some(&lit_by_three),
    )
    .unwrap();
    eprintln!(
        "low depth: noise gains {:.2?}, normal error mean {:.2}° (noise alone {predicted:.2}°), \
         depth RMSE {:.3} mm over {:.1} % of the surface lit by ≥ 3 LEDs",
        reconstruction.photometric.noise_gains,
        normals.mean_deg,
        depth.rmse_mm,
        100.0 * depth.reconstructed_fraction
    );
    assert!(
        normals.mean_deg <= NOISE_MARGIN * predicted + MODEL_ERROR_DEG,
        "normal error {:.2}° against {predicted:.2}° from the noise",
        normals.mean_deg
    );
    assert!(
        depth.rmse_mm <= DEPTH_RMSE_MM && depth.reconstructed_fraction >= 0.95,
        "depth RMSE {:.3} mm over {:.1} %",
        depth.rmse_mm,
        100.0 * depth.reconstructed_fraction
    );

    // Without the depths: the LED images keep 1 − ℓ_i (0.26, 0.30, 0.11, 0.11) and the rig
    // check (or the support check) refuses the reconstruction.
    let unscaled = decode_with(&frames, &format, ModulationDepths::Full);
    let refused = match reconstruct(
        Source::Decoded(&unscaled),
        &rig,
        &ReconstructConfig::decoded_capture(),
        Request::default(),
    ) {
        Err(_) => true,
        Ok(reconstruction) => {
            let check = check_decoded_rig(&unscaled, &rig, &reconstruction, &config);
            let implausible = !reconstruction.support.verdict.is_plausible();
            let (ruling, _) = acceptance::rig(&check, "true rig", false, implausible, "--force");
            eprintln!("low depth without depths: {}", check.describe("true rig"));
            matches!(ruling, Ruling::Refuse(_))
                || matches!(
                    acceptance::support(&reconstruction.support.verdict, None, false, "--force"),
                    Ruling::Refuse(_)
                )
        }
    };
    assert!(
        refused,
        "a low-depth capture decoded as full depth was kept"
    );
}

/// Largest mean normal error over the propagated noise's: the near-field light vectors and
/// the shadow boundary add their own.
const NOISE_MARGIN: f64 = 1.25;
/// Normal error the pipeline adds to the noise's (near-field light vectors, shadow edges),
/// degrees.
const MODEL_ERROR_DEG: f64 = 0.5;
/// Depth RMSE bound, mm: the product's target at full depth (hil-tests/tests/end_to_end.rs),
/// which 8× the frames must bring back at depths whose noise is up to 9.2× full depth's.
const DEPTH_RMSE_MM: f64 = 0.5;

/// Each LED image's least-squares gain against the simulator's full-depth truth over the pixels
/// it lights to at least a tenth of its brightest.
fn gains_against_truth(decoded: &Decoded, truth: &meb_sim::GroundTruth) -> Vec<f64> {
    decoded
        .leds
        .images
        .iter()
        .zip(&truth.led_true.images)
        .map(|(image, truth)| {
            let top = truth.iter().copied().fold(0.0f32, f32::max);
            let (mut dt, mut tt) = (0.0, 0.0);
            for (((d, t), s), u) in image
                .iter()
                .zip(truth)
                .zip(&decoded.saturated)
                .zip(&decoded.underexposed)
            {
                if !s && !u && *t > 0.1 * top {
                    dt += f64::from(*d) * f64::from(*t);
                    tt += f64::from(*t) * f64::from(*t);
                }
            }
            dt / tt
        })
        .collect()
}
