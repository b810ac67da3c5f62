//! `meb simulate` end to end on small rigs: files written, formats, determinism, bad input.

use std::path::{Path, PathBuf};

use crate::common;
use common::{OUT_OF_PLANE_LEDS, meb, rig_toml, run_ok};

fn setup() -> (tempfile::TempDir, String) {
    let tmp = tempfile::tempdir().unwrap();
    let rig = tmp.path().join("small.toml");
    std::fs::write(&rig, rig_toml(64, 36, 2.0, &OUT_OF_PLANE_LEDS)).unwrap();
    let rig = rig.display().to_string();
    (tmp, rig)
}

fn run_err(args: &[&str]) -> String {
    let out = meb(args);
    assert!(!out.status.success(), "meb {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn path(dir: &Path, name: &str) -> String {
    dir.join(name).display().to_string()
}

#[test]
fn writes_frames_and_all_truth_files() {
    let (tmp, rig) = setup();
    let out = path(tmp.path(), "sphere");
    run_ok(&[
        "simulate", "--rig", &rig, "--scene", "sphere", "--frames", "3", "--out", &out, "--snr-db",
        "3", "--seed", "9",
    ]);
    let out = PathBuf::from(out);
    for name in [
        "frame_00000.png",
        "frame_00002.png",
        "depth.npy",
        "normals.npy",
        "mask.png",
        "albedo.npy",
        "led1_true.npy",
        "led4_true.npy",
        "rig.toml",
        "truth.json",
    ] {
        assert!(out.join(name).exists(), "{name} missing");
    }
    assert!(!out.join("frame_00003.png").exists());
    let depth: ndarray::Array2<f32> = ndarray_npy::read_npy(out.join("depth.npy")).unwrap();
    assert_eq!(depth.dim(), (36, 64));
    let top = depth
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f32::MIN, f32::max);
    assert!((top - 24.0).abs() < 0.5, "sphere top at {top} mm");
    assert!(depth[[0, 0]].is_nan());
    let normals: ndarray::Array3<f32> = ndarray_npy::read_npy(out.join("normals.npy")).unwrap();
    assert_eq!(normals.dim(), (36, 64, 3));
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap()).unwrap();
    assert_eq!(truth["frames"], 3);
    assert_eq!(truth["seed"], 9);
    assert_eq!(truth["phases_chips"].as_array().unwrap().len(), 4);
    assert_eq!(truth["snr_db"], 3.0);
    let frame = image::open(out.join("frame_00001.png")).unwrap().to_luma8();
    assert_eq!(frame.dimensions(), (64, 36));
    // No staging directory is left behind.
    let leftovers = std::fs::read_dir(tmp.path())
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .contains("partial")
        })
        .count();
    assert_eq!(leftovers, 0);
}

#[test]
fn a_seed_reproduces_the_capture_and_y4m_is_mono() {
    let (tmp, rig) = setup();
    let a = path(tmp.path(), "a");
    let b = path(tmp.path(), "b");
    let common = [
        "simulate",
        "--rig",
        &rig,
        "--frames",
        "4",
        "--format",
        "y4m",
        "--seed",
        "3",
        "--bit-depth",
        "16",
        "--full-well",
        "20000",
    ];
    run_ok(&[&common[..], &["--out", &a]].concat());
    run_ok(&[&common[..], &["--out", &b]].concat());
    let ya = std::fs::read(Path::new(&a).join("capture.y4m")).unwrap();
    let yb = std::fs::read(Path::new(&b).join("capture.y4m")).unwrap();
    assert_eq!(ya, yb);
    let header = b"YUV4MPEG2 W64 H36 F960:1 Ip A1:1 Cmono16\n";
    assert!(ya.starts_with(header));
    assert_eq!(ya.len(), header.len() + 4 * (6 + 64 * 36 * 2));
}

#[test]
fn meshes_cubes_ellipsoids_and_datasets_render() {
    let (tmp, rig) = setup();
    // A tetrahedron as ASCII STL.
    let stl = tmp.path().join("tetra.stl");
    let facet = |a: [f32; 3], b: [f32; 3], c: [f32; 3]| {
        format!(
            "facet normal 0 0 0\nouter loop\nvertex {} {} {}\nvertex {} {} {}\nvertex {} {} {}\nendloop\nendfacet\n",
            a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2]
        )
    };
    let (p0, p1, p2, p3) = (
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    );
    let text = format!(
        "solid t\n{}{}{}{}endsolid t\n",
        facet(p0, p2, p1),
        facet(p0, p1, p3),
        facet(p0, p3, p2),
        facet(p1, p2, p3)
    );
    std::fs::write(&stl, text).unwrap();
    let stl = stl.display().to_string();
    let m = path(tmp.path(), "mesh");
    run_ok(&[
        "simulate",
        "--rig",
        &rig,
        "--scene",
        "mesh",
        "--mesh",
        &stl,
        "--size-mm",
        "40",
        "--frames",
        "1",
        "--out",
        &m,
    ]);
    let mask = image::open(Path::new(&m).join("mask.png"))
        .unwrap()
        .to_luma8();
    assert!(mask.pixels().filter(|p| p.0[0] == 255).count() > 20);
    let c = path(tmp.path(), "corner");
    run_ok(&[
        "simulate",
        "--rig",
        &rig,
        "--scene",
        "cube",
        "--corner",
        "--frames",
        "1",
        "--out",
        &c,
        "--ground-mm",
        "-60",
    ]);
    let e = path(tmp.path(), "ellipsoid");
    run_ok(&[
        "simulate",
        "--rig",
        &rig,
        "--scene",
        "ellipsoid",
        "--axes-mm",
        "100,60,60",
        "--rpm",
        "7.5",
        "--frames",
        "2",
        "--truth-frame",
        "1",
        "--out",
        &e,
    ]);
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(Path::new(&e).join("truth.json")).unwrap())
            .unwrap();
    assert_eq!(truth["moving"], true);
    let d = path(tmp.path(), "dataset");
    run_ok(&[
        "simulate", "dataset", "--count", "2", "--width", "64", "--height", "36", "--out", &d,
    ]);
    for name in [
        "led1.npy",
        "led4.npy",
        "mask.png",
        "depth.npy",
        "light_vectors.json",
    ] {
        assert!(
            Path::new(&d).join("object_0001").join(name).exists(),
            "{name}"
        );
    }
}

#[test]
fn bad_inputs_fail_clearly() {
    let (tmp, rig) = setup();
    let out = path(tmp.path(), "x");
    let err = run_err(&["simulate", "--rig", &rig, "--frames", "0", "--out", &out]);
    assert!(err.contains("frames"), "{err}");
    let err = run_err(&[
        "simulate",
        "--rig",
        "thesis-nowhere",
        "--frames",
        "1",
        "--out",
        &out,
    ]);
    assert!(err.contains("thesis-nowhere"), "{err}");
    let err = run_err(&[
        "simulate",
        "--rig",
        &rig,
        "--scene",
        "mesh",
        "--mesh",
        "/no/such.stl",
        "--frames",
        "1",
        "--out",
        &out,
    ]);
    assert!(err.contains("/no/such.stl"), "{err}");
    let err = run_err(&[
        "simulate",
        "--rig",
        &rig,
        "--bit-depth",
        "9",
        "--frames",
        "1",
        "--out",
        &out,
    ]);
    assert!(err.contains("bit-depth"), "{err}");
    assert!(!Path::new(&out).exists(), "no output after a failure");
    // An existing non-empty directory is not overwritten without --force.
    let taken = tmp.path().join("taken");
    std::fs::create_dir(&taken).unwrap();
    std::fs::write(taken.join("keep.txt"), "x").unwrap();
    let taken = taken.display().to_string();
    let err = run_err(&["simulate", "--rig", &rig, "--frames", "1", "--out", &taken]);
    assert!(
        err.contains("not an earlier `meb simulate` output") && err.contains("--force"),
        "{err}"
    );
    run_ok(&[
        "simulate", "--rig", &rig, "--frames", "1", "--out", &taken, "--force",
    ]);
    assert!(!Path::new(&taken).join("keep.txt").exists());
}

#[test]
fn mp4_goes_through_ffmpeg_when_installed() {
    if !common::ffmpeg_available() {
        return;
    }
    let (tmp, rig) = setup();
    let out = path(tmp.path(), "video");
    run_ok(&[
        "simulate", "--rig", &rig, "--frames", "4", "--format", "mp4", "--out", &out,
    ]);
    let size = std::fs::metadata(Path::new(&out).join("capture.mp4"))
        .unwrap()
        .len();
    assert!(size > 100);
}

/// The brightest code and the number of samples at full scale in a mono 8-bit y4m file.
fn y4m_extremes(path: &Path) -> (u8, usize) {
    let data = std::fs::read(path).unwrap();
    let header = data.iter().position(|&b| b == b'\n').unwrap() + 1;
    let text = String::from_utf8_lossy(&data[..header]).into_owned();
    assert!(text.contains("Cmono"), "{text}");
    let field = |key: char| -> usize {
        let word = text
            .split_whitespace()
            .find(|w| w.starts_with(key))
            .unwrap();
        word[1..].parse().unwrap()
    };
    let samples = field('W') * field('H');
    let (mut brightest, mut clipped) = (0u8, 0usize);
    let mut at = header;
    while at < data.len() {
        at += data[at..].iter().position(|&b| b == b'\n').unwrap() + 1;
        let frame = &data[at..at + samples];
        brightest = brightest.max(*frame.iter().max().unwrap());
        clipped += frame.iter().filter(|&&v| v == u8::MAX).count();
        at += samples;
    }
    (brightest, clipped)
}

#[test]
fn auto_exposure_keeps_a_corner_on_cube_from_clipping() {
    // The corner-on cube's top face is lit by all four LEDs at once (1.22 of full scale
    // together at the default gain).
    let tmp = tempfile::tempdir().unwrap();
    let simulate = |name: &str, extra: &[&str]| {
        let out = path(tmp.path(), name);
        let args = [
            "simulate",
            "--rig",
            "thesis-out-of-plane",
            "--camera-size",
            "160x90",
            "--scene",
            "cube",
            "--corner",
            "--seed",
            "1",
            "--frames",
            "32",
            "--format",
            "y4m",
            "--out",
            &out,
        ];
        run_ok(&[&args[..], extra].concat());
        let truth: serde_json::Value =
            serde_json::from_slice(&std::fs::read(Path::new(&out).join("truth.json")).unwrap())
                .unwrap();
        let gain = truth["gain"].as_f64().unwrap();
        (y4m_extremes(&Path::new(&out).join("capture.y4m")), gain)
    };
    let ((_, clipped), gain) = simulate("default", &[]);
    assert!(clipped > 0, "the default gain no longer clips this scene");
    let ((brightest, clipped_auto), gain_auto) = simulate("auto", &["--auto-exposure"]);
    println!(
        "default gain {gain:.4e}: {clipped} clipped samples; auto-exposed {gain_auto:.4e}: \
         brightest code {brightest}, {clipped_auto} clipped"
    );
    assert_eq!(clipped_auto, 0);
    // 90 % of full scale, plus the read noise that may overshoot its 3 σ allowance.
    assert!(brightest <= 235, "brightest code {brightest}");
    assert!(
        gain_auto < gain && gain_auto > 0.5 * gain,
        "{gain_auto} vs {gain}"
    );
    // Either sets the gain: both at once is refused.
    let err = run_err(&[
        "simulate",
        "--gain",
        "1e5",
        "--auto-exposure",
        "--out",
        &path(tmp.path(), "both"),
    ]);
    assert!(
        err.contains("--gain") && err.contains("--auto-exposure"),
        "{err}"
    );
}
