//! End to end at reduced resolution: the thesis' out-of-plane sphere Ø48 mm (128 frames,
//! σ = 1 %, background 0 dB SNR, exposure 0.8, gamma 2.2) simulated, decoded and reconstructed
//! must reach depth RMSE ≤ 0.5 mm over ≥ 95 % of the surface lit by ≥ 3 LEDs (thesis: 2.69 mm).

use meb_cli::demo::{run, thesis_capture_config, thesis_decode_config};
use meb_core::rig::Rig;
use meb_pipeline::reconstruct::{ReconstructConfig, Request, Source};
use meb_sim::exposure::expose_without_clipping;
use meb_sim::{Scene, SceneObject};
use ndarray::Array2;

use crate::common;
use common::run_ok;

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
    let oracle = meb_pipeline::reconstruct::reconstruct(
        Source::Images {
            images: &out.truth.led_true,
            noise: None,
        },
        &rig,
        &ReconstructConfig::default(),
        Request::default(),
    )
    .unwrap();
    let o = meb_core::metrics::compare_depth(
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

/// `meb reconstruct` on a capture written by `meb simulate` and `meb demo`'s pipeline on the
/// same capture rendered in memory give the same depth: one path from a decoded capture to a
/// reconstruction, with the same settings (flagged pixels, level noise, shadow threshold).
#[test]
fn meb_reconstruct_and_the_demo_pipeline_give_the_same_depth() {
    let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
    rig.camera.width = 96;
    rig.camera.height = 64;
    rig.camera.fov_deg = None;
    rig.camera.pixel_pitch_mm = Some(1.0);
    let scene = Scene::single(SceneObject::sphere(48.0));
    let seed = 3;
    let demo = run(
        &rig,
        scene.clone(),
        thesis_capture_config(seed),
        &thesis_decode_config(4),
        &ReconstructConfig::decoded_capture(),
        &mut |_, _| {},
    )
    .unwrap();

    // The same capture through the command line: the demo's exposure, noise, tone and seed.
    let exposed = expose_without_clipping(&rig, &scene, thesis_capture_config(seed)).unwrap();
    let sim = thesis_capture_config(seed);
    let tmp = tempfile::tempdir().unwrap();
    let dir = |name: &str| tmp.path().join(name).display().to_string();
    std::fs::write(tmp.path().join("rig.toml"), rig.to_toml_string()).unwrap();
    let gain = format!("{:?}", exposed.gain.unwrap());
    let noise = format!("{:?}", sim.noise.sigma);
    let exposure = format!("{:?}", sim.exposure);
    run_ok(&[
        "simulate",
        "--rig",
        &dir("rig.toml"),
        "--scene",
        "sphere",
        "--size-mm",
        "48",
        "--frames",
        "128",
        "--exposure",
        &exposure,
        "--noise",
        &noise,
        "--gamma",
        "2.2",
        "--snr-db",
        "0",
        "--seed",
        &seed.to_string(),
        "--gain",
        &gain,
        "--out",
        &dir("cap"),
    ]);
    run_ok(&[
        "reconstruct",
        &dir("cap"),
        "--rig",
        &dir("rig.toml"),
        "--leds",
        "4",
        "--linearize",
        "gamma:2.2",
        "--out",
        &dir("rec"),
    ]);
    let cli: Array2<f32> = ndarray_npy::read_npy(tmp.path().join("rec/depth.npy")).unwrap();
    let library = &demo.reconstruction.integration.depth.depth_mm;
    assert_eq!(cli.dim(), library.dim());
    let mut largest = 0.0f32;
    for (a, b) in cli.iter().zip(library) {
        assert_eq!(
            a.is_finite(),
            b.is_finite(),
            "different pixels reconstructed"
        );
        if a.is_finite() {
            largest = largest.max((a - b).abs());
        }
    }
    let pixels = cli.iter().filter(|z| z.is_finite()).count();
    eprintln!("CLI vs demo pipeline: {pixels} pixels, largest depth difference {largest:e} mm");
    assert!(pixels > 500, "{pixels} pixels");
    assert!(largest < 1e-3, "depth differs by up to {largest} mm");
}
