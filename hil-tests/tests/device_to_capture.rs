//! A configured virtual luminaire's recorded light drives the simulator: the capture shows
//! exactly the configured carriers (rate, phases, brightness, crystal error).

use std::sync::Arc;

use hil_tests::client;
use meb_core::rig::Rig;
use meb_device::{EmulatorOptions, Timeline, TimelineWaveform, VirtualLuminaire};
use meb_sim::{NoiseModel, Scene, SceneObject, Shape, SimConfig, SimulatedCapture};
use protocol::config::{ChipRate, LuminaireConfig};

const PHASES: [u16; 4] = [0, 5, 11, 20];
const FRAMES: usize = 32;

/// Configures 4 LEDs at 960 Hz with [`PHASES`] on a virtual luminaire; returns its timeline.
fn configured_timeline(rate_error_ppm: f64) -> Timeline {
    let emulator = VirtualLuminaire::spawn(EmulatorOptions {
        rate_error_ppm,
        ..EmulatorOptions::default()
    })
    .unwrap();
    let mut config = LuminaireConfig::DEFAULT;
    config.led_count = 4;
    config.chip_rate = ChipRate::from_hz(960.0);
    config.phase_chips[..4].copy_from_slice(&PHASES);
    // The thesis' full on/off carriers, which flicker above IEEE 1789 low risk: accepted on
    // purpose, as `meb device set --depth 1 --allow-flicker` does.
    config.off_level_permille = [0; 8];
    config.allow_flicker = true;
    let mut c = client(emulator.port_path());
    c.set_config(&config).unwrap();
    assert_eq!(c.config().unwrap(), config);
    drop(c);
    emulator.shutdown().unwrap()
}

fn small_rig() -> Rig {
    let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
    rig.camera.width = 96;
    rig.camera.height = 54;
    rig
}

fn sim_config() -> SimConfig {
    // A delay of p chips on the luminaire is a time shift Δ = n − p chips in the simulator's
    // carrier model (LED i shows chip floor(t·rate + Δ_i)); n = 32 for 4 LEDs.
    SimConfig {
        frames: FRAMES,
        noise: NoiseModel {
            sigma: 0.0,
            full_well_electrons: None,
        },
        phases_chips: Some(PHASES.iter().map(|&p| f64::from((32 - p) % 32)).collect()),
        ..SimConfig::default()
    }
}

/// Largest per-pixel difference of the light images over all frames, and the largest
/// frame-to-frame change of the recorded capture (to show there is a signal at all).
fn compare(timeline: &Timeline) -> (f32, f32) {
    let scene = Scene::single(SceneObject::new(Shape::Sphere { radius_mm: 24.0 }));
    let reference = SimulatedCapture::new(small_rig(), scene.clone(), sim_config()).unwrap();
    let waveform = TimelineWaveform::from_last_change(timeline).unwrap();
    let recorded = SimulatedCapture::new(small_rig(), scene, sim_config())
        .unwrap()
        .with_waveform(Arc::new(waveform))
        .unwrap();
    let mut max_diff = 0.0f32;
    let mut max_change = 0.0f32;
    let mut previous = recorded.light_image(0);
    for f in 0..FRAMES {
        let (a, b) = (recorded.light_image(f), reference.light_image(f));
        for (x, y) in a.iter().zip(b.iter()) {
            max_diff = max_diff.max((x - y).abs());
        }
        for (x, y) in a.iter().zip(previous.iter()) {
            max_change = max_change.max((x - y).abs());
        }
        previous = a;
    }
    (max_diff, max_change)
}

#[test]
fn recorded_timeline_lights_the_capture_with_the_configured_carriers() {
    let (max_diff, max_change) = compare(&configured_timeline(0.0));
    assert!(
        max_change > 0.05,
        "no modulation in the capture: {max_change}"
    );
    assert!(
        max_diff < 1e-4,
        "capture differs from the configured carriers by {max_diff}"
    );
}

#[test]
fn crystal_error_shows_up_as_drift_in_the_capture() {
    let timeline = configured_timeline(2000.0);
    let rate = timeline.segments.last().unwrap().effective_chip_rate_hz;
    assert!((rate - 960.0 * 1.002).abs() < 1e-9, "{rate}");
    // 32 frames at +2000 ppm drift 0.064 chips: visible against the exact-rate model.
    let (max_diff, _) = compare(&timeline);
    assert!(max_diff > 1e-3, "rate error not played: {max_diff}");
}
