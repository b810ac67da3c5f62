//! End to end at reduced resolution: the thesis' out-of-plane sphere Ø48 mm (128 frames,
//! σ = 1 %, background 0 dB SNR, exposure 0.8, gamma 2.2) simulated, decoded and reconstructed
//! must reach depth RMSE ≤ 0.5 mm over ≥ 95 % of the surface lit by ≥ 3 LEDs (thesis: 2.69 mm).

use meb::demo::{run, thesis_capture_config, thesis_decode_config};
use meb::reconstruct::ReconstructConfig;
use meb::rig::Rig;
use meb::simulate::{Scene, SceneObject};

#[test]
fn simulated_sphere_depth_rmse_within_half_a_millimetre() {
    let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
    rig.camera.width = 192;
    rig.camera.height = 128;
    rig.camera.pixel_pitch_mm = Some(0.5);
    let out = run(
        &rig,
        Scene::single(SceneObject::sphere(48.0)),
        thesis_capture_config(7),
        &thesis_decode_config(4),
        &ReconstructConfig::decoded_capture(),
        &mut |_, _| {},
    )
    .unwrap();
    // Exposed like a real capture: nothing clips (clipping biased the LED gains by up to 9 %).
    assert_eq!(out.decoded.report.saturated_pixels, 0);
    let e = &out.depth_errors;
    eprintln!(
        "simulated sphere: RMSE {:.3} mm, NRMSE {:.2} %, {:.1} % of the ≥3-lit surface, \
         normals mean {:.2}° median {:.2}°",
        e.rmse_mm,
        100.0 * e.nrmse.unwrap_or(f64::NAN),
        100.0 * e.reconstructed_fraction,
        out.angular_errors.mean_deg,
        out.angular_errors.median_deg
    );
    // Oracle: the same reconstruction on the simulator's noise-free per-LED images.
    let oracle = meb::reconstruct::reconstruct(
        &out.truth.led_true,
        &rig,
        None,
        None,
        &ReconstructConfig::default(),
    )
    .unwrap();
    let o = meb::metrics::compare_depth(
        &oracle.integration.depth.depth_mm,
        &out.truth.depth_mm,
        Some(&out.lit_by_three),
    )
    .unwrap();
    eprintln!(
        "oracle LED images: RMSE {:.3} mm, {:.1} %",
        o.rmse_mm,
        100.0 * o.reconstructed_fraction
    );
    assert!(e.rmse_mm <= 0.5, "RMSE {:.3} mm", e.rmse_mm);
    assert!(
        e.reconstructed_fraction >= 0.95,
        "{:.3}",
        e.reconstructed_fraction
    );
}
