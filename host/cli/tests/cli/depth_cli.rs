//! `--depth` through the `meb` binary: `meb simulate --depth` plays the off levels a luminaire
//! would, `meb decode --depth` brings the LED images back to full depth and records it in
//! decode.json, and bad depths are refused in one line
//! (docs/howto/flicker-safety.md#decoding-a-low-depth-capture).

use crate::common::{arg, refused, run_ok, simulate_y4m};
use meb_pipeline::demod::Decoded;
use meb_pipeline::demod::output::read_decode_dir;
use serde_json::Value;
use std::path::Path;

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Each LED image's least-squares gain against `reference`'s over the pixels where the
/// reference LED lights to at least a tenth of its brightest and neither decode flagged.
fn gains_against(decoded: &Decoded, reference: &Decoded) -> Vec<f64> {
    let usable = |d: &Decoded, p: (usize, usize)| !d.saturated[p] && !d.underexposed[p];
    decoded
        .leds
        .images
        .iter()
        .zip(&reference.leds.images)
        .map(|(image, truth)| {
            let top = truth.iter().copied().fold(0.0f32, f32::max);
            let (mut dt, mut tt) = (0.0, 0.0);
            for (p, t) in truth.indexed_iter() {
                if *t > 0.1 * top && usable(decoded, p) && usable(reference, p) {
                    dt += f64::from(image[p]) * f64::from(*t);
                    tt += f64::from(*t) * f64::from(*t);
                }
            }
            dt / tt
        })
        .collect()
}

#[test]
fn decode_depth_restores_the_full_depth_images_of_a_simulated_half_depth_capture() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = ["--scene", "sphere", "--size-mm", "48", "--seed", "3"];
    let full = tmp.path().join("full");
    simulate_y4m(&full, "thesis-out-of-plane", "320x180", 128, &scene);
    let half = tmp.path().join("half");
    let mut half_scene = scene.to_vec();
    half_scene.extend_from_slice(&["--depth", "0.5"]);
    simulate_y4m(&half, "thesis-out-of-plane", "320x180", 128, &half_scene);
    // Depth 0.5 is an off level of ⌈1000·0.5/1.5⌉ = 334 ‰, as `meb device set` plays it.
    let truth = json(&half.join("truth.json"));
    assert_eq!(
        truth["off_levels"],
        serde_json::json!([0.334, 0.334, 0.334, 0.334])
    );

    let decode = |capture: &Path, name: &str, extra: &[&str]| {
        let out = tmp.path().join(name);
        let input = capture.join("capture.y4m");
        let mut args = vec!["decode", arg(&input), "--out", arg(&out)];
        args.extend_from_slice(extra);
        run_ok(&args);
        read_decode_dir(&out).unwrap()
    };
    let reference = decode(&full, "dec-full", &[]);
    let told = decode(&half, "dec-told", &["--depth", "0.5"]);
    let untold = decode(&half, "dec-untold", &[]);
    let modulation = serde_json::to_value(&told.report.modulation).unwrap();
    assert_eq!(modulation["setting"], serde_json::json!({"depths": [0.5]}));
    let restored = gains_against(&told, &reference);
    let kept = gains_against(&untold, &reference);
    for i in 0..4 {
        let scale = told.report.modulation.image_scale[i];
        assert!(
            (scale - 1.0 / 0.666).abs() < 1e-9,
            "LED {} scale {scale}",
            i + 1
        );
        // Thousands of pixels per gain: its noise is well below 1 %.
        assert!(
            (restored[i] - 1.0).abs() < 0.02,
            "LED {}: ×{:.4}",
            i + 1,
            restored[i]
        );
        assert!(
            (kept[i] - 0.666).abs() < 0.02,
            "LED {}: ×{:.4}",
            i + 1,
            kept[i]
        );
    }
    // Without --depth the report says full depth.
    let untold_report = json(&tmp.path().join("dec-untold/decode.json"));
    assert_eq!(untold_report["modulation"]["setting"], "full");
    assert_eq!(
        untold_report["modulation"]["image_scale"],
        serde_json::json!([1.0, 1.0, 1.0, 1.0])
    );
}

#[test]
fn bad_depths_are_refused_in_one_line() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = tmp.path().join("cap");
    simulate_y4m(
        &capture,
        "thesis-out-of-plane",
        "96x54",
        32,
        &["--scene", "sphere", "--size-mm", "48"],
    );
    let input = capture.join("capture.y4m");
    let out = tmp.path().join("dec");
    let decode = |extra: &[&str], expect: &str| {
        let mut args = vec!["decode", arg(&input), "--out", arg(&out)];
        args.extend_from_slice(extra);
        refused(&args, &out, expect);
    };
    decode(
        &["--depth", "0.5,0.5"],
        "2 modulation depths given for 4 LEDs",
    );
    decode(
        &["--timeline", arg(&tmp.path().join("missing.json"))],
        "timeline file",
    );
    // Values clap refuses before any work: exit 2 with the option named.
    for bad in ["0", "1.5", "-0.2", "x"] {
        let output =
            crate::common::meb(&["decode", arg(&input), "--out", arg(&out), "--depth", bad]);
        assert_eq!(output.status.code(), Some(2), "--depth {bad}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            stderr.contains("--depth") && stderr.contains("(0, 1]"),
            "--depth {bad}: {stderr}"
        );
        assert!(!out.exists());
    }
}
