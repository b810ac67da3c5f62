//! `meb rig check --sphere-mm` through the binary: a capture of a matte sphere of known size
//! reconstructed with the rig under test gives back the sphere's radius and normals with the
//! true rig, not with a rig whose LEDs are 25 mm off; a wrong diameter is refused.
//!
//! Captures: out-of-plane rig, 640×360, 64 frames, noise 1 %, gamma 2.2, Ø50 mm sphere.

use crate::common::{arg, meb, stderr_of};

/// The figure after `label` in `text` (e.g. "radius 24.91 mm" → 24.91).
fn figure_after(text: &str, label: &str) -> f64 {
    let at = text
        .find(label)
        .unwrap_or_else(|| panic!("no `{label}` in {text}"));
    text[at + label.len()..]
        .trim_start()
        .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == '+'))
        .next()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no number after `{label}` in {text}"))
}

#[test]
fn a_sphere_of_known_size_checks_the_rig() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = tmp.path().join("sphere");
    let output = meb(&[
        "simulate",
        "--rig",
        "thesis-out-of-plane",
        "--out",
        arg(&capture),
        "--camera-size",
        "640x360",
        "--frames",
        "64",
        "--noise",
        "0.01",
        "--gamma",
        "2.2",
        "--scene",
        "sphere",
        "--size-mm",
        "50",
        "--seed",
        "42",
        "--perturb-leds-mm",
        "25",
        "--perturb-seed",
        "8",
    ]);
    assert!(output.status.success(), "{}", stderr_of(&output));
    let check = |rig: &str, sphere_mm: &str| {
        meb(&[
            "rig",
            "check",
            arg(&capture),
            "--rig",
            arg(&capture.join(rig)),
            "--sphere-mm",
            sphere_mm,
            "--linearize",
            "gamma:2.2",
        ])
    };
    let right = check("rig.toml", "50");
    let printed = String::from_utf8_lossy(&right.stdout).into_owned();
    assert!(right.status.success(), "{printed}{}", stderr_of(&right));
    let radius = figure_after(&printed, "sphere: radius");
    let normal = figure_after(&printed, "normal error mean");
    eprintln!("true rig: {printed}");
    assert!((radius / 25.0 - 1.0).abs() < 0.03, "{printed}");
    assert!(normal < 3.0, "{printed}");

    let wrong = check("rig-nominal.toml", "50");
    let printed = String::from_utf8_lossy(&wrong.stdout).into_owned();
    eprintln!("25 mm off: {printed}{}", stderr_of(&wrong));
    assert!(!wrong.status.success(), "a rig 25 mm off passed\n{printed}");
    let normal_wrong = figure_after(&printed, "normal error mean");
    assert!(normal_wrong > normal, "{printed}");

    let size = check("rig.toml", "35");
    assert!(
        !size.status.success(),
        "a Ø35 mm sphere was found in a Ø50 mm one"
    );
    let message = stderr_of(&size);
    assert!(message.contains("sphere"), "{message}");
}
