//! Captures from real rooms: a lamp flickering on the mains and an auto-exposure that drifts,
//! added by the simulator's `room` module to the issue's capture (4 LEDs at 960 fps, exposure
//! 0.6, read noise 1 %, steady background 0.15 of full scale, LED levels on the object a few
//! percent of full scale), here at 320×180 (and at the issue's 640×360 for a frame dropped or
//! repeated in the middle). Each is decoded with every gain within 1 % of the
//! truth (relative to the gains' mean for the exposure ramp, whose mean gain the LEDs share), or
//! refused; `decode.json`'s `room` section names what was found.
//!
//! A gain is the least-squares ratio of the decoded to the true on-levels over the lit pixels the
//! decoder kept.

use meb_core::capture::memory::MemorySource;
use meb_core::capture::{Frame, FrameFormat};
use meb_core::rig::Rig;
use meb_pipeline::demod::timing_break::{BreakKind, TimingBreak};
use meb_pipeline::demod::{DecodeConfig, Decoded, DemodError, LedCount, decode};
use meb_sim::capture::{SimConfig, SimulatedCapture};
use meb_sim::scene::{GroundPlane, Scene, SceneObject};
use meb_sim::sensor::NoiseModel;
use meb_sim::{LampWaveform, RoomEffects, RoomLamp};

use crate::common::{gains_against_truth, rig_toml};

/// The camera: width, height (px) and pixel pitch (mm) of an orthographic camera.
type Camera = (usize, usize, f64);
/// The tests' camera.
const SMALL: Camera = (320, 180, 0.5);
/// The issue's camera.
const ISSUE: Camera = (640, 360, 0.25);
const FPS: f64 = 960.0;
const LEDS: [[f64; 3]; 4] = [
    [-270.0, 420.0, 100.0],
    [-140.0, 420.0, 350.0],
    [140.0, 420.0, 350.0],
    [270.0, 420.0, 100.0],
];
/// Steady background light, fraction of full scale.
const BACKGROUND: f64 = 0.15;

/// The issue's capture with `room` added; `seed` fixes phases and noise.
fn capture(room: RoomEffects, seed: u64) -> SimulatedCapture {
    capture_at(room, seed, None)
}

/// [`capture`] by a camera at `rates.0` fps with every LED at a chip rate of `rates.1` Hz
/// (960 fps and chips when `None`).
fn capture_at(room: RoomEffects, seed: u64, rates: Option<(f64, f64)>) -> SimulatedCapture {
    capture_by(SMALL, room, seed, rates)
}

/// [`capture_at`] by `camera`.
fn capture_by(
    camera: Camera,
    room: RoomEffects,
    seed: u64,
    rates: Option<(f64, f64)>,
) -> SimulatedCapture {
    let (fps, chip_rate_hz) = rates.unwrap_or((FPS, FPS));
    let (width, height, pitch) = camera;
    let toml =
        rig_toml(width, height, pitch, &LEDS).replace("fps = 960.0", &format!("fps = {fps:?}"));
    let rig = Rig::from_toml_str(&toml, "room").unwrap();
    let mut scene = Scene::single(SceneObject::sphere(60.0));
    scene.ground = Some(GroundPlane {
        z_mm: -30.0,
        albedo: 0.5,
    });
    let config = |snr_db, room: RoomEffects| SimConfig {
        frames: 128,
        exposure: 0.6,
        noise: NoiseModel {
            sigma: 0.01,
            full_well_electrons: None,
        },
        snr_db,
        peak: 0.08,
        seed,
        room,
        chip_rates_hz: Some(vec![chip_rate_hz; LEDS.len()]),
        ..SimConfig::default()
    };
    let dark =
        SimulatedCapture::new(rig.clone(), scene.clone(), config(None, room.clone())).unwrap();
    let snr_db = 10.0 * (dark.info().signal_irradiance / BACKGROUND).log10();
    SimulatedCapture::new(rig, scene, config(Some(snr_db), room)).unwrap()
}

/// Decodes `capture` as 4 LEDs the way `meb decode` does.
fn decode_capture(capture: &SimulatedCapture) -> Result<Decoded, DemodError> {
    decode_capture_at(capture, capture.info().fps)
}

/// [`decode_capture`] with the frame rate the frames come with (0: unknown, as for images).
fn decode_capture_at(capture: &SimulatedCapture, fps: f64) -> Result<Decoded, DemodError> {
    let frames: Vec<Frame> = (0..capture.config().frames)
        .map(|j| capture.render_frame(j))
        .collect();
    let camera = &capture.rig().camera;
    let format = FrameFormat::full_range(camera.width, camera.height, 8, fps);
    let mut source = MemorySource::new(format, frames).unwrap();
    let config = DecodeConfig {
        leds: LedCount::Fixed(4),
        ..DecodeConfig::default()
    };
    decode(&mut source, &config, &mut |_, _| {})
}

/// Decodes a capture of `room` and checks it is decoded with every gain within 1 % of the
/// truth, or refused with a reason that names the flicker found and never advises more LEDs;
/// returns the flicker families reported (empty when refused).
fn decoded_or_refused_naming_flicker(
    room: RoomEffects,
    seed: u64,
    rates: Option<(f64, f64)>,
) -> Vec<f64> {
    let capture = capture_at(room.clone(), seed, rates);
    match decode_capture(&capture) {
        Ok(decoded) => {
            let gains = gains_against_truth(&decoded, &capture, 0.0);
            eprintln!(
                "{room:?} {rates:?} seed {seed}: gains {gains:.4?}, room {:?}",
                decoded.report.room
            );
            assert!(
                gains.iter().all(|g| (g - 1.0).abs() < 0.01),
                "{room:?}: decoded with gains {gains:.4?}"
            );
            decoded
                .report
                .room
                .flicker
                .iter()
                .map(|f| f.nominal_hz)
                .collect()
        }
        Err(e) => {
            let text = e.to_string();
            eprintln!("{room:?} {rates:?} seed {seed}: refused: {text}");
            assert!(text.contains("flicker at"), "{text}");
            assert!(!text.contains("--leds"), "{text}");
            Vec::new()
        }
    }
}

/// A lamp of mean `level` on `mains` Hz with `waveform`.
fn lamp(mains: f64, level: f64, waveform: LampWaveform) -> RoomEffects {
    RoomEffects {
        lamp: Some(RoomLamp::new(mains, level, waveform)),
        ..RoomEffects::default()
    }
}

/// Decodes and checks every gain within `tolerance` of 1 (of their mean with `relative`).
fn decoded_within(room: RoomEffects, seed: u64, tolerance: f64, relative: bool) -> Decoded {
    decoded_within_at(room, seed, None, tolerance, relative)
}

/// [`decoded_within`] of a capture by `camera`, absolute gains.
fn decoded_within_by(camera: Camera, room: RoomEffects, seed: u64, tolerance: f64) -> Decoded {
    let capture = capture_by(camera, room.clone(), seed, None);
    checked_gains(&capture, &room, seed, tolerance, false)
}

/// [`decoded_within`] with the camera's and the chips' rates `rates` ([`capture_at`]).
fn decoded_within_at(
    room: RoomEffects,
    seed: u64,
    rates: Option<(f64, f64)>,
    tolerance: f64,
    relative: bool,
) -> Decoded {
    let capture = capture_at(room.clone(), seed, rates);
    checked_gains(&capture, &room, seed, tolerance, relative)
}

/// Decodes `capture` (of `room`, `seed`) and checks its gains as [`decoded_within`] does.
fn checked_gains(
    capture: &SimulatedCapture,
    room: &RoomEffects,
    seed: u64,
    tolerance: f64,
    relative: bool,
) -> Decoded {
    let decoded =
        decode_capture(capture).unwrap_or_else(|e| panic!("{room:?} seed {seed}: refused: {e}"));
    let gains = gains_against_truth(&decoded, capture, 0.0);
    let reference = if relative {
        gains.iter().sum::<f64>() / gains.len() as f64
    } else {
        1.0
    };
    eprintln!(
        "{room:?} seed {seed}: gains {gains:.4?} (reference {reference:.4}), room {:?}",
        decoded.report.room
    );
    for (i, g) in gains.iter().enumerate() {
        assert!(
            (g / reference - 1.0).abs() < tolerance,
            "{room:?} seed {seed}: LED {} gain {g:.4} vs {reference:.4} (all {gains:.4?}), room {:?}",
            i + 1,
            decoded.report.room
        );
    }
    decoded
}

#[test]
fn a_steady_room_finds_no_flicker_and_no_drift() {
    let decoded = decoded_within(RoomEffects::default(), 1, 0.01, false);
    assert!(
        decoded.report.room.flicker.is_empty(),
        "{:?}",
        decoded.report.room
    );
    assert!(
        decoded.report.room.exposure_drift.is_none(),
        "{:?}",
        decoded.report.room
    );
    assert!(
        decoded.report.room.timing_breaks.is_empty(),
        "{:?}",
        decoded.report.room
    );
}

#[test]
fn a_lamp_on_50_hz_mains_is_modelled_and_reported() {
    // The issue's rows: 0.5 % (decoded 1.8 % off before) and 2 % (refused, "use --leds 5").
    for (level, seed) in [(0.005, 2), (0.02, 3)] {
        let decoded = decoded_within(
            lamp(50.1, level, LampWaveform::SinSquared),
            seed,
            0.01,
            false,
        );
        let flicker = &decoded.report.room.flicker;
        assert!(
            flicker
                .iter()
                .any(|f| f.nominal_hz == 100.0 && f.harmonics.contains(&1)),
            "level {level}: {flicker:?}"
        );
    }
}

#[test]
fn a_lamp_in_frames_without_a_frame_rate_is_found_by_its_frequency_in_frames() {
    // Image files carry no frame rate, so the lamp's flicker is looked for at any frequency in
    // frames: 100.2 Hz at 960 fps lands at 0.1044 cycles per frame. At 1 % of full scale it
    // moved LED 2's gain by 3.5 % with exit 0; at 2 % it showed as a fifth component.
    for (level, seed) in [(0.01, 2), (0.02, 3)] {
        let capture = capture(lamp(50.1, level, LampWaveform::SinSquared), seed);
        let decoded = decode_capture_at(&capture, 0.0)
            .unwrap_or_else(|e| panic!("level {level}: refused: {e}"));
        let gains = gains_against_truth(&decoded, &capture, 0.0);
        eprintln!(
            "lamp {level} without a rate: gains {gains:.4?}, room {:?}",
            decoded.report.room
        );
        assert!(
            gains.iter().all(|g| (g - 1.0).abs() < 0.01),
            "level {level}: gains {gains:.4?}, room {:?}",
            decoded.report.room
        );
        let flicker = &decoded.report.room.flicker;
        assert!(
            flicker
                .iter()
                .any(|f| f.nominal_hz == 0.0
                    && (f.cycles_per_frame - 100.2 / 960.0).abs() < 0.5 / 128.0),
            "level {level}: {flicker:?}"
        );
    }
}

#[test]
fn a_rectified_lamp_with_harmonics_far_brighter_than_the_leds_is_modelled_or_named() {
    // |sin| on 49.8 Hz mains, mean 0.15 of full scale: several times the LEDs' light.
    let families =
        decoded_or_refused_naming_flicker(lamp(49.8, 0.15, LampWaveform::AbsSin), 4, None);
    assert!(families.iter().all(|&f| f == 100.0), "{families:?}");
}

#[test]
fn an_exposure_ramp_is_modelled_and_reported() {
    // The issue's row: gain rising 5 % over the capture (LED 4 was 1.8 % off the gains' mean).
    let room = RoomEffects {
        gain_ramp: 0.05,
        ..RoomEffects::default()
    };
    let decoded = decoded_within(room.clone(), 5, 0.005, true);
    let drift = decoded.report.room.exposure_drift;
    assert!(
        drift.is_some_and(|d| (d - 0.05).abs() < 0.015),
        "{:?}",
        decoded.report.room
    );
    // A drift is smooth in frames: found without a frame rate too (image files carry none).
    let capture = capture(room, 5);
    let decoded = decode_capture_at(&capture, 0.0).expect("decoded without a frame rate");
    let gains = gains_against_truth(&decoded, &capture, 0.0);
    let mean = gains.iter().sum::<f64>() / gains.len() as f64;
    assert!(
        gains.iter().all(|g| (g / mean - 1.0).abs() < 0.005),
        "without a frame rate: gains {gains:.4?}, room {:?}",
        decoded.report.room
    );
    assert!(
        decoded
            .report
            .room
            .exposure_drift
            .is_some_and(|d| (d - 0.05).abs() < 0.015),
        "without a frame rate: {:?}",
        decoded.report.room
    );
}

/// A camera rate at which `meb carriers` finds chip rates clear of both flicker families for
/// 4 LEDs within the decoder's rate search (at 960 fps none is: LED 2's fundamental stays
/// within a bin of 120 Hz), and the first of them.
fn clear_rates() -> (f64, f64) {
    let fps = 720.0;
    let window = (1usize << (LEDS.len() + 3)).min(256);
    let clear = meb_core::mains::clear_chip_rates(
        LEDS.len() as u8,
        fps,
        window,
        DecodeConfig::default().max_rate_mismatch,
        3,
    );
    assert!(!clear.is_empty(), "no clear chip rate at {fps} fps");
    assert!(meb_core::mains::clashes(LEDS.len() as u8, clear[0], fps, window).is_empty());
    (fps, clear[0])
}

#[test]
fn a_lamp_on_60_hz_mains_on_the_carriers_lines_is_refused_naming_the_flicker() {
    // At a chip rate equal to the camera's 960 fps every 120 Hz harmonic falls on a carrier's
    // line: the flicker cannot be told from the carriers, and the refusal says so.
    let capture = capture(lamp(60.1, 0.025, LampWaveform::SinSquared), 6);
    match decode_capture(&capture) {
        Ok(decoded) => {
            // Decoded only if right.
            let gains = gains_against_truth(&decoded, &capture, 0.0);
            assert!(
                gains.iter().all(|g| (g - 1.0).abs() < 0.01),
                "decoded with gains {gains:.4?}"
            );
        }
        Err(e) => {
            let text = e.to_string();
            eprintln!("60 Hz lamp at 2.5 %, chip rate 960 Hz: {text}");
            assert!(text.contains("60 Hz mains"), "{text}");
            assert!(text.contains("meb carriers"), "{text}");
            assert!(!text.contains("--leds"), "{text}");
            assert!(!text.contains("frame timing"), "{text}");
        }
    }
}

#[test]
fn a_lamp_on_60_hz_mains_at_a_recommended_chip_rate_is_modelled() {
    let rates = clear_rates();
    let decoded = decoded_within_at(
        lamp(60.1, 0.025, LampWaveform::SinSquared),
        7,
        Some(rates),
        0.01,
        false,
    );
    let flicker = &decoded.report.room.flicker;
    assert!(
        flicker.iter().any(|f| f.nominal_hz == 120.0),
        "{rates:?}: {flicker:?}"
    );
}

#[test]
fn a_lamp_ten_times_the_leds_level_at_a_recommended_chip_rate_is_modelled_or_named() {
    // Mean 0.3 of full scale: ten times the LEDs' mean level on the object (0.03).
    let rates = clear_rates();
    for (mains, seed) in [(50.2, 8), (59.8, 9)] {
        let nominal = if mains < 55.0 { 100.0 } else { 120.0 };
        let families = decoded_or_refused_naming_flicker(
            lamp(mains, 0.3, LampWaveform::SinSquared),
            seed,
            Some(rates),
        );
        assert!(
            families.iter().all(|&f| f == nominal),
            "{mains} Hz: {families:?}"
        );
    }
}

#[test]
fn a_dropped_or_repeated_frame_is_found_and_the_capture_re_aligned() {
    // The issue's rows: one frame dropped at 60 of 128, or one repeated (refused before, with
    // "use --leds 5"). At 640×360 a timing with a near-instant exposure and a rate ratio of
    // 1.013 explained these captures within 1.1 σ²_G of the break and was kept, with LED 2
    // 5 % low.
    for (camera, room, seed, frame, kind) in [
        (SMALL, vec![60], vec![], 10, 60, BreakKind::Dropped),
        (SMALL, vec![], vec![60], 11, 61, BreakKind::Repeated),
        (ISSUE, vec![60], vec![], 7, 60, BreakKind::Dropped),
        (ISSUE, vec![], vec![60], 7, 61, BreakKind::Repeated),
    ]
    .map(|(camera, dropped, duplicated, seed, frame, kind)| {
        let room = RoomEffects {
            dropped,
            duplicated,
            ..RoomEffects::default()
        };
        (camera, room, seed, frame, kind)
    }) {
        let decoded = decoded_within_by(camera, room, seed, 0.01);
        assert_eq!(
            decoded.report.room.timing_breaks,
            vec![TimingBreak { frame, kind }],
            "{camera:?}: {:?}",
            decoded.report.room
        );
    }
}

#[test]
fn a_frame_dropped_or_repeated_near_an_end_is_found_or_refused() {
    // A break a few frames from an end barely moves one timing fitted to the whole window
    // (a drop 13 frames from the start was decoded with LEDs 3 and 4 7 % and 9 % low): each
    // position near both ends, dropped or repeated, is decoded within 1 % with the break
    // named, or refused.
    let cases = [
        (3, BreakKind::Dropped),
        (8, BreakKind::Dropped),
        (13, BreakKind::Dropped),
        (22, BreakKind::Dropped),
        (109, BreakKind::Dropped),
        (121, BreakKind::Dropped),
        (125, BreakKind::Dropped),
        (5, BreakKind::Repeated),
        (17, BreakKind::Repeated),
        (100, BreakKind::Repeated),
        (115, BreakKind::Repeated),
        (124, BreakKind::Repeated),
    ];
    for (i, (at, kind)) in cases.into_iter().enumerate() {
        let room = match kind {
            BreakKind::Dropped => RoomEffects {
                dropped: vec![at],
                ..RoomEffects::default()
            },
            BreakKind::Repeated => RoomEffects {
                duplicated: vec![at],
                ..RoomEffects::default()
            },
        };
        let seed = 12 + i as u64;
        let capture = capture(room.clone(), seed);
        match decode_capture(&capture) {
            Ok(decoded) => {
                let gains = gains_against_truth(&decoded, &capture, 0.0);
                eprintln!(
                    "{room:?} seed {seed}: gains {gains:.4?}, breaks {:?}",
                    decoded.report.room.timing_breaks
                );
                assert!(
                    gains.iter().all(|g| (g - 1.0).abs() < 0.01),
                    "{room:?} seed {seed}: decoded with gains {gains:.4?}, breaks {:?}",
                    decoded.report.room.timing_breaks
                );
                // A repeated frame's copy follows it.
                let frame = at + usize::from(kind == BreakKind::Repeated);
                assert_eq!(
                    decoded.report.room.timing_breaks,
                    vec![TimingBreak { frame, kind }],
                    "{room:?} seed {seed}"
                );
            }
            Err(e) => {
                // Refused (a drop 7 frames from the end is refused by the LED-count check).
                eprintln!("{room:?} seed {seed}: refused: {e}");
            }
        }
    }
}

/// The issue's steady capture with seed 7: LED 4's exposure window ends 0.006 chip past a
/// chip boundary, a sliver the timing fit finds only across a kink of its cost (2 % low with
/// exit 0 before).
#[test]
fn a_weak_led_a_sliver_past_a_chip_boundary_decodes_within_one_percent() {
    decoded_within_by(ISSUE, RoomEffects::default(), 7, 0.01);
}
