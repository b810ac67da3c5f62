//! The decoder on captures from the simulator (the independent oracle): gain within 1 % of
//! `led_true`, less noise than the thesis estimator, rate mismatch, and `meb decode` on the
//! files `meb simulate` writes.

use meb_core::rig::Rig;
use meb_pipeline::demod::{
    DecodeConfig, Decoded, DemodError, Estimator, LedCount, Linearize, decode,
};
use meb_sim::ToneCurve;
use meb_sim::capture::{SimConfig, SimulatedCapture};
use meb_sim::exposure::expose_without_clipping;
use meb_sim::scene::{Scene, SceneObject};
use meb_sim::sensor::NoiseModel;
use std::path::Path;

use crate::common;
use common::{OUT_OF_PLANE_LEDS, meb, rig_toml};

fn capture(exposure: f64, chip_rate_hz: Option<f64>, seed: u64) -> SimulatedCapture {
    let rig = Rig::from_toml_str(&rig_toml(160, 90, 0.6, &OUT_OF_PLANE_LEDS), "test").unwrap();
    let config = SimConfig {
        frames: 128,
        exposure,
        bit_depth: 16,
        noise: NoiseModel {
            sigma: 0.01,
            full_well_electrons: None,
        },
        chip_rates_hz: chip_rate_hz.map(|r| vec![r]),
        seed,
        // Keep background + all LEDs below white: clipped pixels are flagged, not decoded.
        peak: 0.25,
        ..SimConfig::default()
    };
    SimulatedCapture::new(rig, Scene::single(SceneObject::sphere(48.0)), config).unwrap()
}

/// Least-squares gain of decoded vs truth over lit pixels, and RMS error after that gain.
fn gain_and_noise(decoded: &ndarray::Array2<f32>, truth: &ndarray::Array2<f32>) -> (f64, f64) {
    let top = truth.iter().copied().fold(0.0f32, f32::max);
    let lit: Vec<(f64, f64)> = decoded
        .iter()
        .zip(truth)
        .filter(|(_, t)| **t > 0.1 * top)
        .map(|(d, t)| (f64::from(*d), f64::from(*t)))
        .collect();
    let gain =
        lit.iter().map(|(d, t)| d * t).sum::<f64>() / lit.iter().map(|(_, t)| t * t).sum::<f64>();
    let rms =
        (lit.iter().map(|(d, t)| (d - gain * t).powi(2)).sum::<f64>() / lit.len() as f64).sqrt();
    (gain, rms)
}

fn run(capture: &mut SimulatedCapture, estimator: Estimator) -> Decoded {
    let config = DecodeConfig {
        leds: LedCount::Fixed(4),
        estimator,
        ..DecodeConfig::default()
    };
    decode(capture, &config, &mut |_, _| {}).unwrap()
}

#[test]
fn waveform_gains_within_one_percent_and_less_noise_than_thesis() {
    for (exposure, seed) in [(1.0, 1), (0.5, 2), (0.75, 3)] {
        let mut cap = capture(exposure, None, seed);
        let truth = cap.truth_at(0.0).led_true;
        let ours = run(&mut cap, Estimator::Waveform);
        let mut cap = capture(exposure, None, seed);
        let theirs = run(&mut cap, Estimator::Thesis);
        let (mut ours_total, mut theirs_total) = (0.0, 0.0);
        for i in 0..4 {
            let (g, n) = gain_and_noise(&ours.leds.images[i], &truth.images[i]);
            let (tg, tn) = gain_and_noise(&theirs.leds.images[i], &truth.images[i]);
            eprintln!(
                "exposure {exposure} LED {}: waveform gain {g:.4} noise {n:.5} | thesis gain {tg:.4} noise {tn:.5}",
                i + 1
            );
            assert!((g - 1.0).abs() < 0.01, "LED {} gain {g}", i + 1);
            // Per LED never worse (2 % slack for an LED whose carrier the exposure nearly
            // cancels, where both are limited by the same weak signal) …
            assert!(n < 1.02 * tn, "LED {} noise {n} vs thesis {tn}", i + 1);
            ours_total += n;
            theirs_total += tn;
        }
        // … and clearly lower overall.
        assert!(
            ours_total < 0.9 * theirs_total,
            "{ours_total} vs {theirs_total}"
        );
    }
}

#[test]
fn rate_mismatch_of_five_percent_is_estimated_and_decoded() {
    for chip_rate in [912.0, 1008.0] {
        let mut cap = capture(0.8, Some(chip_rate), 5);
        let truth = cap.truth_at(0.0).led_true;
        let decoded = run(&mut cap, Estimator::Waveform);
        let expected = chip_rate / 960.0;
        eprintln!("rate ratio {} (true {expected})", decoded.report.rate_ratio);
        assert!((decoded.report.rate_ratio - expected).abs() < 1e-3);
        for i in 0..4 {
            let (g, _) = gain_and_noise(&decoded.leds.images[i], &truth.images[i]);
            assert!(
                (g - 1.0).abs() < 0.01,
                "chip rate {chip_rate} LED {} gain {g}",
                i + 1
            );
        }
    }
}

#[test]
fn cli_decodes_what_simulate_writes() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = tmp.path().join("rig.toml");
    std::fs::write(&rig, rig_toml(96, 54, 0.6, &OUT_OF_PLANE_LEDS)).unwrap();
    let sim = tmp.path().join("sim");
    common::run_ok(&[
        "simulate",
        "--rig",
        rig.to_str().unwrap(),
        "--frames",
        "64",
        "--noise",
        "0.005",
        "--format",
        "y4m",
        "--bit-depth",
        "16",
        "--out",
        sim.to_str().unwrap(),
    ]);
    let dec = tmp.path().join("dec");
    common::run_ok(&[
        "decode",
        sim.join("capture.y4m").to_str().unwrap(),
        "--leds",
        "4",
        "--out",
        dec.to_str().unwrap(),
    ]);
    for i in 1..=4 {
        let decoded: ndarray::Array2<f32> =
            ndarray_npy::read_npy(dec.join(format!("led{i}.npy"))).unwrap();
        let truth: ndarray::Array2<f32> =
            ndarray_npy::read_npy(sim.join(format!("led{i}_true.npy"))).unwrap();
        let (g, _) = gain_and_noise(&decoded, &truth);
        assert!((g - 1.0).abs() < 0.01, "LED {i} gain {g}");
        assert!(dec.join(format!("led{i}.png")).exists());
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dec.join("decode.json")).unwrap()).unwrap();
    assert_eq!(report["leds"], 4);
    assert!(dec.join("noise.npy").exists());
    // Too many LEDs requested, and too few frames, are clear errors.
    let out = meb(&[
        "decode",
        sim.join("capture.y4m").to_str().unwrap(),
        "--leds",
        "5",
        "--out",
        tmp.path().join("x").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let out = meb(&[
        "decode",
        sim.join("capture.y4m").to_str().unwrap(),
        "--frames",
        "20",
        "--out",
        tmp.path().join("y").to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && text.contains("at least 32"),
        "{text}"
    );
}

#[test]
fn truncated_y4m_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("cut.y4m");
    let mut bytes = b"YUV4MPEG2 W8 H4 F960:1 Cmono\n".to_vec();
    for _ in 0..40 {
        bytes.extend_from_slice(b"FRAME\n");
        bytes.extend_from_slice(&[100u8; 32]);
    }
    bytes.truncate(bytes.len() - 10);
    std::fs::write(&path, &bytes).unwrap();
    let out = meb(&[
        "decode",
        path.to_str().unwrap(),
        "--out",
        tmp.path().join("o").to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && text.contains("truncated"),
        "{text}"
    );
    assert!(!Path::new(&tmp.path().join("o").join("decode.json")).exists());
}

// ---------------------------------------------------------------------------------------------
// The captures of the decoder's known failures: the thesis' out-of-plane rig as `meb simulate`
// renders it by default (1280×720, 128 frames, 8 bit, read noise 0.5 %), a Ø48 mm sphere.

/// A default `meb simulate` capture of the sphere under `rig` with `config` changes.
fn sphere_capture(rig: Rig, config: SimConfig) -> SimulatedCapture {
    SimulatedCapture::new(rig, Scene::single(SceneObject::sphere(48.0)), config).unwrap()
}

/// Decodes `capture` as `meb decode --leds 4` does and returns it with each LED's gain over
/// the lit pixels the decoder kept.
fn decode_default(capture: &mut SimulatedCapture, config: &DecodeConfig) -> (Decoded, Vec<f64>) {
    let decoded = decode(capture, config, &mut |_, _| {}).unwrap_or_else(|e| panic!("{e}"));
    let gains = common::gains_against_truth(&decoded, capture, 0.0);
    (decoded, gains)
}

fn four_leds() -> DecodeConfig {
    DecodeConfig {
        leds: LedCount::Fixed(4),
        ..DecodeConfig::default()
    }
}

/// Every LED's gain within 1 % (`what` names the case in the failure).
fn assert_gains_within_one_percent(gains: &[f64], what: &str) {
    for (i, g) in gains.iter().enumerate() {
        assert!((g - 1.0).abs() < 0.01, "{what} LED {}: gain {g}", i + 1);
    }
}

fn thesis_rig() -> Rig {
    Rig::load("thesis-out-of-plane").unwrap()
}

#[test]
fn three_percent_rate_offset_decodes_every_seed() {
    // Chip rate 988.8 Hz at 960 fps (ρ = 1.03), exposure 0.9: on seeds 13, 16 and 21 a timing
    // fit that locks on the wrong minimum reports exposure 0.02 / 0.51 / 0.76 and gains off by
    // up to 30 % with exit 0.
    for seed in [13, 16, 21] {
        let config = SimConfig {
            exposure: 0.9,
            chip_rates_hz: Some(vec![988.8]),
            seed,
            ..SimConfig::default()
        };
        let (decoded, gains) =
            decode_default(&mut sphere_capture(thesis_rig(), config), &four_leds());
        let report = &decoded.report;
        eprintln!(
            "seed {seed}: rate {:.5} exposure {:.3} noise {:.4} gains {gains:.4?}",
            report.rate_ratio, report.exposure, report.median_noise
        );
        assert!((report.rate_ratio - 1.03).abs() < 2e-4, "{report:?}");
        assert!((report.exposure - 0.9).abs() < 0.02, "{report:?}");
        assert!(report.median_noise < 0.006, "{report:?}");
        assert_gains_within_one_percent(&gains, &format!("seed {seed}"));
    }
}

#[test]
fn rate_offset_with_given_phases_keeps_all_four_leds() {
    // Used to stop with "the video shows 3 modulated LED(s)"; without the LED check it fitted
    // exposure 0.06 and returned gains 0.92 / 0.83 / 0.93 / 0.07 with exit 0.
    let config = SimConfig {
        exposure: 0.9,
        chip_rates_hz: Some(vec![988.8]),
        phases_chips: Some(vec![25.76, 25.85, 16.49, 9.15]),
        ..SimConfig::default()
    };
    let (decoded, gains) = decode_default(&mut sphere_capture(thesis_rig(), config), &four_leds());
    eprintln!(
        "given phases: {:?} gains {gains:.4?}",
        decoded.report.per_led
    );
    assert_eq!(decoded.report.detected_leds, Some(4));
    assert_gains_within_one_percent(&gains, "");
}

#[test]
fn short_exposures_at_the_chip_rate_keep_gains_within_one_percent() {
    // ρ = 1, exposure 0.5 and 0.3, seed 3: a biased exposure fit puts LED 3 at 0.985 and 1.012.
    for exposure in [0.5, 0.3] {
        let config = SimConfig {
            exposure,
            seed: 3,
            ..SimConfig::default()
        };
        let (_, gains) = decode_default(&mut sphere_capture(thesis_rig(), config), &four_leds());
        eprintln!("exposure {exposure}: gains {gains:.4?}");
        assert_gains_within_one_percent(&gains, &format!("exposure {exposure}"));
    }
}

#[test]
fn rolling_shutter_is_fitted_by_default() {
    // Line time 1.4 µs (a 0.97-chip phase ramp over 720 rows), exposure 0.5: a decoder that
    // takes the shutter as global puts LED 3 at 1.086 (1.052 with 8 row bands).
    let config = SimConfig {
        exposure: 0.5,
        line_time_s: 1.4e-6,
        seed: 3,
        ..SimConfig::default()
    };
    let (decoded, gains) = decode_default(&mut sphere_capture(thesis_rig(), config), &four_leds());
    eprintln!(
        "rolling shutter: line time {:.3} µs, {} bands, gains {gains:.4?}",
        decoded.report.line_time_us, decoded.report.row_bands
    );
    assert!(decoded.report.row_bands > 1, "{:?}", decoded.report);
    assert_gains_within_one_percent(&gains, "");
}

#[test]
fn small_object_in_a_wide_dark_view_is_found() {
    // 640×480 pixels of 0.85 and 1.0 mm (a 544–640 mm wide view): the Ø48 mm sphere covers
    // 1–2 % of the frame. Used to fail with "the video shows 3 modulated LED(s)" and "no
    // MEB-FDMA modulation found".
    for pitch in [0.85, 1.0] {
        let rig =
            Rig::from_toml_str(&rig_toml(640, 480, pitch, &OUT_OF_PLANE_LEDS), "wide").unwrap();
        let (decoded, gains) =
            decode_default(&mut sphere_capture(rig, SimConfig::default()), &four_leds());
        eprintln!(
            "pitch {pitch}: gains {gains:.4?} {:?}",
            decoded.report.verdict
        );
        assert_gains_within_one_percent(&gains, &format!("pitch {pitch}"));
    }
}

#[test]
fn implausible_decode_is_refused_unless_forced_and_reconstruct_checks_the_verdict() {
    // A capture at the chip rate (ρ = 1) decoded with a wrong known rate ratio (1.03, a drift
    // of 1.9 chips over the 64 frames): the templates cannot explain the modulation, so the
    // verdict must refuse the result.
    let tmp = tempfile::tempdir().unwrap();
    let p = |name: &str| tmp.path().join(name).to_str().unwrap().to_string();
    std::fs::write(p("rig.toml"), rig_toml(96, 54, 0.6, &OUT_OF_PLANE_LEDS)).unwrap();
    common::run_ok(&[
        "simulate",
        "--rig",
        &p("rig.toml"),
        "--frames",
        "64",
        "--noise",
        "0.005",
        "--format",
        "y4m",
        "--bit-depth",
        "16",
        "--out",
        &p("sim"),
    ]);
    let capture = tmp.path().join("sim/capture.y4m");
    let decode = |out: &str, force: bool| {
        let mut args = vec![
            "decode".to_string(),
            capture.to_str().unwrap().to_string(),
            "--rate-ratio".into(),
            "1.03".into(),
            // The wrong rate also miscounts the LEDs; the verdict is what is tested here.
            "--no-led-check".into(),
            "--out".into(),
            p(out),
        ];
        if force {
            args.push("--force".into());
        }
        meb(&args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let refused = decode("dec", false);
    let text = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success(),
        "wrong rate ratio decoded with exit 0"
    );
    assert!(
        text.contains("unexplained") && text.contains("--force"),
        "{text}"
    );
    assert!(
        !tmp.path().join("dec").exists(),
        "a refused decode left a folder"
    );

    let forced = decode("dec", true);
    let text = String::from_utf8_lossy(&forced.stderr);
    assert!(forced.status.success(), "{text}");
    assert!(text.contains("warning"), "{text}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("dec/decode.json")).unwrap())
            .unwrap();
    assert_eq!(report["verdict"]["status"], "overridden", "{report}");
    assert!(
        report["verdict"]["problems"]
            .as_array()
            .is_some_and(|p| !p.is_empty())
    );

    let reconstruct = |force: bool| {
        let (dec, rig, rec) = (p("dec"), p("rig.toml"), p("rec"));
        let mut args = vec!["reconstruct", &dec, "--rig", &rig, "--out", &rec];
        if force {
            args.push("--force");
        }
        meb(&args)
    };
    let refused = reconstruct(false);
    let text = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success(),
        "reconstruct used an overridden decode without --force"
    );
    assert!(
        text.contains("implausible") && text.contains("--force"),
        "{text}"
    );
    assert!(!tmp.path().join("rec").exists());
    // With --force the verdict does not stop it (the reconstruction's own checks may still
    // refuse these amplitudes, which are wrong).
    let forced = reconstruct(true);
    let text = String::from_utf8_lossy(&forced.stderr);
    assert!(text.contains("using it anyway (--force)"), "{text}");
    assert!(!text.contains("use --force"), "{text}");
}

/// The hardware-in-the-loop capture's settings (thesis out-of-plane rig at 192×128, 0.5 mm
/// pixels, Ø48 mm sphere, background at 0 dB SNR, σ = 1 %, gamma 2.2, exposure 0.8, exposed
/// without clipping, global shutter) with the LEDs' clock `ppm` off the camera's.
fn hil_like_capture(ppm: f64, phases: Option<[f64; 4]>, seed: u64) -> SimulatedCapture {
    let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
    rig.camera.width = 192;
    rig.camera.height = 128;
    rig.camera.fov_deg = None;
    rig.camera.pixel_pitch_mm = Some(0.5);
    let scene = Scene::single(SceneObject::sphere(48.0));
    let sim = SimConfig {
        frames: 128,
        exposure: 0.8,
        noise: NoiseModel {
            sigma: 0.01,
            full_well_electrons: None,
        },
        snr_db: Some(0.0),
        tone: ToneCurve::Gamma(2.2),
        phases_chips: phases.map(|p| p.to_vec()),
        chip_rates_hz: Some(vec![rig.camera.fps * (1.0 + ppm * 1e-6)]),
        seed,
        ..SimConfig::default()
    };
    let sim = expose_without_clipping(&rig, &scene, sim).unwrap();
    SimulatedCapture::new(rig, scene, sim).unwrap()
}

/// A global shutter at rate ratio 1 ± 20 ppm, the case a faster fit once decoded with a
/// spurious line delay and a wrong exposure that the verdict called plausible: the rows must
/// agree (no line delay), every gain must be within 1 %, the verdict plausible, and the
/// exposure within three reported standard errors (or 0.05) of the truth: ρ ≈ 1 leaves the
/// exposure and the phases' fractional part along one nearly flat direction, which the
/// reported standard error must show.
#[test]
fn hil_settings_decode_without_a_line_delay() {
    let cases = [
        (20.0, Some([0.0, 9.0, 17.0, 26.0]), 0),
        (-20.0, Some([0.0, 9.0, 17.0, 26.0]), 1),
        (20.0, None, 2),
        (-20.0, None, 3),
    ];
    let mut failures = Vec::new();
    for (ppm, phases, seed) in cases {
        let mut cap = hil_like_capture(ppm, phases, seed);
        let truth = cap.truth_at(0.0).led_true;
        let config = DecodeConfig {
            linearize: Linearize::Gamma(2.2),
            ..DecodeConfig::default()
        };
        let decoded = decode(&mut cap, &config, &mut |_, _| {}).unwrap();
        let report = &decoded.report;
        let gains: Vec<f64> = (0..4)
            .map(|i| gain_and_noise(&decoded.leds.images[i], &truth.images[i]).0)
            .collect();
        eprintln!(
            "{ppm:+} ppm, phases {phases:?}, seed {seed}: {}, gains {gains:.4?}",
            report.timing_summary()
        );
        if (report.exposure - 0.8).abs() > (3.0 * report.exposure_std).max(0.05) {
            failures.push(format!(
                "{ppm:+} ppm seed {seed}: exposure {:.3} ± {:.3} (1σ) misses 0.8",
                report.exposure, report.exposure_std
            ));
        }
        if !report.verdict.is_plausible() {
            failures.push(format!("{ppm:+} ppm seed {seed}: {:?}", report.verdict));
        }
        if report.line_delay_frames != 0.0 {
            failures.push(format!(
                "{ppm:+} ppm seed {seed}: a global shutter decoded with a line delay of {:.3e} frames/row",
                report.line_delay_frames
            ));
        }
        for (i, g) in gains.iter().enumerate() {
            if (g - 1.0).abs() >= 0.01 {
                failures.push(format!("{ppm:+} ppm seed {seed}: LED {} gain {g}", i + 1));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The 75 mm cube corner-on at the default gain (thesis-out-of-plane rig, 256×144): the top
/// face, the only one LEDs 1 and 2 reach, clips whenever three LEDs are on, so the pixels that
/// do not clip show LEDs 3 and 4 alone. For these carrier phasings a decoder that counts the
/// LEDs of the unclipped pixels refuses as "the video shows 3 modulated LEDs (decode 3)",
/// which sends the user to a wrong decode; it must name the clipping instead. The same scene exposed without clipping must
/// decode all four LEDs, so the refusal is the clipping's and not the geometry's.
#[test]
fn leds_seen_only_in_clipped_pixels_are_refused_for_the_clipping() {
    let mut rig = thesis_rig();
    rig.camera.width = 256;
    rig.camera.height = 144;
    let scene = Scene::single(SceneObject::cube(75.0, true));
    for seed in [2, 4] {
        let sim = SimConfig {
            frames: 128,
            seed,
            ..SimConfig::default()
        };
        let mut clipped = SimulatedCapture::new(rig.clone(), scene.clone(), sim.clone()).unwrap();
        let err = decode(&mut clipped, &four_leds(), &mut |_, _| {}).unwrap_err();
        eprintln!("seed {seed}: {err}");
        assert!(
            matches!(
                err,
                DemodError::LedsHiddenByClipping {
                    requested: 4,
                    detected: 2..=3,
                    ..
                }
            ),
            "seed {seed}: {err}"
        );
        let exposed = expose_without_clipping(&rig, &scene, sim).unwrap();
        let mut unclipped = SimulatedCapture::new(rig.clone(), scene.clone(), exposed).unwrap();
        let (decoded, gains) = decode_default(&mut unclipped, &four_leds());
        eprintln!("seed {seed} without clipping: gains {gains:.4?}");
        assert_eq!(decoded.report.detected_leds, Some(4), "seed {seed}");
        assert_gains_within_one_percent(&gains, &format!("seed {seed} without clipping"));
    }
}
