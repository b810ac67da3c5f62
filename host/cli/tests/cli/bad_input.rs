//! Bad input through the `meb` binary: each case exits non-zero with one readable line — no
//! Rust debug text, no panic or abort, no cause printed twice — and writes nothing.

use std::path::Path;

use crate::common;
use common::{OUT_OF_PLANE_LEDS, meb, rig_toml};

/// Runs a command that must fail cleanly and returns its error line.
fn run_err(args: &[&str]) -> String {
    let out = meb(args);
    assert_eq!(out.status.code(), Some(1), "meb {args:?}: {:?}", out.status);
    let stderr = String::from_utf8_lossy(&out.stderr).trim().to_string();
    let line = stderr.lines().last().unwrap_or_default().to_string();
    assert!(line.starts_with("error: "), "meb {args:?}: {stderr}");
    // No cause twice ("entity not found: entity not found").
    let parts: Vec<&str> = line.split(": ").collect();
    for pair in parts.windows(2) {
        assert_ne!(pair[0], pair[1], "repeated cause in {line:?}");
    }
    assert!(!line.contains(" { "), "Rust debug text in {line:?}");
    line
}

fn s(path: &Path) -> String {
    path.display().to_string()
}

#[test]
fn huge_simulated_cameras_are_refused_before_allocating() {
    let tmp = tempfile::tempdir().unwrap();
    for (w, h) in [(100_000usize, 100_000usize), (usize::MAX, usize::MAX)] {
        let rig = tmp.path().join(format!("rig{w}.toml"));
        std::fs::write(&rig, rig_toml(w, h, 0.1, &OUT_OF_PLANE_LEDS)).unwrap();
        let out = tmp.path().join("out");
        let err = run_err(&[
            "simulate",
            "--rig",
            &s(&rig),
            "--frames",
            "1",
            "--out",
            &s(&out),
        ]);
        assert!(
            err.contains("camera size") && err.contains("at most"),
            "{err}"
        );
        assert!(!out.exists());
    }
}

#[test]
fn raw_layouts_and_missing_files_read_in_words() {
    let tmp = tempfile::tempdir().unwrap();
    let raw = tmp.path().join("frames.raw");
    std::fs::write(&raw, [0u8; 64]).unwrap();
    let out = s(&tmp.path().join("out"));
    let err = run_err(&["decode", &s(&raw), "--raw", "0x0x8", "--out", &out]);
    assert!(
        err.contains("0x0, 8-bit") && err.contains("at least 1"),
        "{err}"
    );
    let err = run_err(&["decode", &s(&raw), "--raw", "8x8x40", "--out", &out]);
    assert!(
        err.contains("8x8, 40-bit") && err.contains("1 to 16"),
        "{err}"
    );
    let missing = s(&tmp.path().join("nothing-here.y4m"));
    let err = run_err(&["decode", &missing, "--out", &out]);
    assert!(err.contains("nothing-here.y4m"), "{err}");
    let err = run_err(&[
        "reconstruct",
        &missing,
        "--rig",
        "/no/rig.toml",
        "--out",
        &out,
    ]);
    assert!(err.contains("/no/rig.toml"), "{err}");
    assert!(!tmp.path().join("out").exists());
}

#[test]
fn npy_inputs_say_what_is_expected() {
    let tmp = tempfile::tempdir().unwrap();
    let mask = tmp.path().join("mask.png");
    image::GrayImage::from_pixel(5, 4, image::Luma([255]))
        .save(&mask)
        .unwrap();
    let out = s(&tmp.path().join("out"));
    let integrate = |npy: &Path| {
        run_err(&[
            "integrate",
            &s(npy),
            "--mask",
            &s(&mask),
            "--pitch",
            "1",
            "--out",
            &out,
        ])
    };
    let ints = tmp.path().join("ints.npy");
    ndarray_npy::write_npy(&ints, &ndarray::Array3::<i32>::zeros((4, 5, 3))).unwrap();
    let err = integrate(&ints);
    assert!(
        err.contains("int32") && err.contains("float32 (or float64) expected"),
        "{err}"
    );
    let flat = tmp.path().join("flat.npy");
    ndarray_npy::write_npy(&flat, &ndarray::Array2::<f32>::zeros((4, 5))).unwrap();
    let err = integrate(&flat);
    assert!(
        err.contains("2-D, 4×5") && err.contains("expected 3-D, H×W×3"),
        "{err}"
    );
    let garbage = tmp.path().join("garbage.npy");
    std::fs::write(&garbage, b"not an array").unwrap();
    let err = integrate(&garbage);
    assert!(err.contains("not a .npy array file"), "{err}");
}

#[test]
fn a_mesh_without_area_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    let stl = tmp.path().join("flat.stl");
    std::fs::write(
        &stl,
        "solid flat\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 1 1\nvertex 2 2 2\n\
         endloop\nendfacet\nendsolid flat\n",
    )
    .unwrap();
    let rig = tmp.path().join("rig.toml");
    std::fs::write(&rig, rig_toml(32, 24, 1.0, &OUT_OF_PLANE_LEDS)).unwrap();
    let out = tmp.path().join("out");
    let err = run_err(&[
        "simulate",
        "--rig",
        &s(&rig),
        "--scene",
        "mesh",
        "--mesh",
        &s(&stl),
        "--frames",
        "1",
        "--out",
        &s(&out),
    ]);
    assert!(
        err.contains("flat.stl") && err.contains("zero area"),
        "{err}"
    );
    assert!(!out.exists());
}

/// The luminaire's settings and the chequerboard's size are parsed by clap too: usage errors
/// (exit 2) naming the flag, before any port or photo is opened.
#[test]
fn bad_luminaire_settings_and_board_sizes_are_usage_errors() {
    let set = ["device", "--port", "/dev/meb-none", "set", "--rate", "960"];
    let cases: [(Vec<&str>, &[&str]); 4] = [
        ([&set[..], &["--leds", "9"]].concat(), &["--leds", "1..=8"]),
        (
            [&set[..], &["--leds", "4", "--depth", "1.5"]].concat(),
            &["--depth", "1.5"],
        ),
        (
            [&set[..], &["--leds", "4", "--depth", "half"]].concat(),
            &["--depth", "half"],
        ),
        (
            vec![
                "calibrate",
                "camera",
                "no-such-photo.png",
                "--board",
                "9by6",
                "--square-mm",
                "20",
                "--rig",
                "thesis-dynamic",
                "--out",
                "no-such-folder",
            ],
            &["--board", "COLSxROWS"],
        ),
    ];
    for (args, wanted) in cases {
        assert_usage_error(&args, wanted);
    }
}

/// Structured and enumerated flags are parsed by clap: a bad value is a usage error (exit 2)
/// that names the flag and what it accepts, before any input is opened.
#[test]
fn bad_flag_values_are_usage_errors_that_list_what_is_accepted() {
    let cases: [(&[&str], &[&str]); 6] = [
        (
            &["--estimator", "median"],
            &["--estimator", "waveform", "thesis"],
        ),
        (&["--leds", "9"], &["--leds", "1 to 8", "auto"]),
        (&["--linearize", "gamma:0"], &["--linearize", "gamma:G"]),
        (&["--roi", "64x48+1"], &["--roi", "WxH+X+Y"]),
        (&["--raw", "64x48"], &["--raw", "WxHxBITS"]),
        (&["--exposure", "1.5"], &["--exposure", "at most 1"]),
    ];
    for (flag, wanted) in cases {
        let mut args = vec!["decode", "no-such-capture.y4m", "--out", "no-such-folder"];
        args.extend_from_slice(flag);
        assert_usage_error(&args, wanted);
    }
}

/// `meb ARGS` is a usage error (exit 2) whose message contains every one of `wanted`.
fn assert_usage_error(args: &[&str], wanted: &[&str]) {
    let out = meb(args);
    assert_eq!(out.status.code(), Some(2), "meb {args:?}: {:?}", out.status);
    let stderr = String::from_utf8_lossy(&out.stderr);
    for w in wanted {
        assert!(
            stderr.contains(w),
            "meb {args:?}: {w:?} missing from {stderr}"
        );
    }
}
