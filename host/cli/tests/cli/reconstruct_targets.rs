//! The reconstruction targets, through the binary: `meb simulate` writes a capture with its
//! ground truth, `meb reconstruct` decodes and reconstructs it, and the depth it wrote is
//! compared with the truth over the surface lit by three or more LEDs (from the simulator's
//! noise-free per-LED images) after removing the mean offset.
//!
//! Captures use the thesis' out-of-plane LEDs and its camera's pitch (0.2585 mm per pixel)
//! on a camera cropped to the object, 128 frames, strong background light (0 dB SNR), gamma 2.2,
//! σ = 1 % noise and exposure 0.8 — the conditions of the thesis' Ch. 4 experiments.

use meb_core::metrics::compare_depth;
use ndarray::Array2;
use std::path::{Path, PathBuf};

use crate::common;
use common::{OUT_OF_PLANE_LEDS, rig_toml, run_ok};

/// The thesis camera's grid pitch: 2·420·tan(21.5°)/1280 mm.
const THESIS_PITCH_MM: f64 = 0.258_49;

/// Depth RMSE target of Suzanne with the automatic integrator, mm (measured through `meb
/// reconstruct` on simulator seeds 1–4: 3.93 / 3.90 / 4.30 / 3.34 mm).
const SUZANNE_MAX_RMSE_MM: f64 = 4.5;

/// Depth RMSE bound of the blobby shape (measured 0.14 mm), mm.
const BLOBBY_MAX_RMSE_MM: f64 = 1.0;

/// Depth RMSE bound of the two-object scene (measured 0.83 mm), mm.
const MULTI_MAX_RMSE_MM: f64 = 2.0;

/// Depth RMSE bound of the sphere seen by a pinhole camera with distortion (measured 0.11 mm),
/// mm.
const PERSPECTIVE_MAX_RMSE_MM: f64 = 0.25;

/// A temporary folder holding a rig and its captures.
struct Bench {
    tmp: tempfile::TempDir,
}

impl Bench {
    fn new(rig: &str) -> Self {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("rig.toml"), rig).unwrap();
        Self { tmp }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.tmp.path().join(name)
    }

    fn p(&self, name: &str) -> String {
        self.path(name).display().to_string()
    }

    /// `meb simulate` with the thesis capture settings and `scene` arguments into `name`.
    fn simulate(&self, name: &str, scene: &[&str]) {
        self.simulate_seed(name, 1, scene);
    }

    /// [`Self::simulate`] with the simulator's noise seed `seed`.
    fn simulate_seed(&self, name: &str, seed: u64, scene: &[&str]) {
        let seed = seed.to_string();
        let mut args = vec![
            "simulate",
            "--rig",
            "RIG",
            "--frames",
            "128",
            "--snr-db",
            "0",
            "--gamma",
            "2.2",
            "--noise",
            "0.01",
            "--exposure",
            "0.8",
            "--peak",
            "0.25",
            "--seed",
            &seed,
            "--out",
            "OUT",
        ];
        let (rig, out) = (self.p("rig.toml"), self.p(name));
        for a in args.iter_mut() {
            if *a == "RIG" {
                *a = &rig;
            } else if *a == "OUT" {
                *a = &out;
            }
        }
        args.extend_from_slice(scene);
        run_ok(&args);
    }

    /// `meb reconstruct` of capture `capture` into `out` with `extra` arguments; returns the
    /// wall time in seconds.
    fn reconstruct(&self, capture: &str, out: &str, extra: &[&str]) -> f64 {
        let (cap, rig, dest) = (self.p(capture), self.p("rig.toml"), self.p(out));
        let mut args = vec![
            "reconstruct",
            cap.as_str(),
            "--rig",
            rig.as_str(),
            "--out",
            dest.as_str(),
            "--leds",
            "4",
            "--linearize",
            "gamma:2.2",
        ];
        args.extend_from_slice(extra);
        let start = std::time::Instant::now();
        run_ok(&args);
        start.elapsed().as_secs_f64()
    }

    /// Coverage of the ≥ 3-lit surface and depth RMSE there (mean offset removed).
    fn accuracy(&self, capture: &str, out: &str) -> (f64, f64) {
        lit_by_three_accuracy(&self.path(capture), &self.path(out))
    }
}

/// Coverage and RMSE of `out/depth.npy` against `capture/depth.npy` over the pixels lit by
/// three or more LEDs in `capture/ledN_true.npy`.
fn lit_by_three_accuracy(capture: &Path, out: &Path) -> (f64, f64) {
    let truth: Array2<f32> = ndarray_npy::read_npy(capture.join("depth.npy")).unwrap();
    let depth: Array2<f32> = ndarray_npy::read_npy(out.join("depth.npy")).unwrap();
    let leds: Vec<Array2<f32>> = (1..=4)
        .map(|i| ndarray_npy::read_npy(capture.join(format!("led{i}_true.npy"))).unwrap())
        .collect();
    let lit3 = Array2::from_shape_fn(truth.dim(), |p| {
        truth[p].is_finite() && leds.iter().filter(|l| l[p] > 0.0).count() >= 3
    });
    let e = compare_depth(&depth, &truth, Some(&lit3)).unwrap();
    (e.reconstructed_fraction, e.rmse_mm)
}

/// Ø48 mm sphere: ≥ 95 % of the surface lit by ≥ 3 LEDs reconstructed, depth RMSE ≤ 0.25 mm.
#[test]
fn sphere_under_strong_background_light_meets_its_target() {
    let bench = Bench::new(&rig_toml(256, 224, THESIS_PITCH_MM, &OUT_OF_PLANE_LEDS));
    bench.simulate("sphere", &["--scene", "sphere", "--size-mm", "48"]);
    let seconds = bench.reconstruct("sphere", "rec", &[]);
    let (coverage, rmse) = bench.accuracy("sphere", "rec");
    println!(
        "sphere Ø48: {:.2} % of the ≥3-lit surface, RMSE {rmse:.3} mm, {seconds:.1} s",
        100.0 * coverage
    );
    assert!(coverage >= 0.95, "coverage {coverage}");
    assert!(rmse <= 0.25, "RMSE {rmse} mm");
}

/// Blender's Suzanne, 90 mm wide, face to the camera, on two simulator seeds: ≥ 90 % of the
/// surface lit by ≥ 3 LEDs reconstructed and depth RMSE ≤ [`SUZANNE_MAX_RMSE_MM`] with
/// `--integrator auto` (the thesis' monkey: 10.9 mm), which finds the depth discontinuities
/// and beats least squares (7.6 mm) across the brow, nose and ears.
#[test]
fn suzanne_head_coverage_and_depth() {
    let bench = Bench::new(&rig_toml(384, 288, THESIS_PITCH_MM, &OUT_OF_PLANE_LEDS));
    let mesh = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/suzanne.obj");
    let scene = ["--scene", "mesh", "--mesh", mesh, "--size-mm", "90"];
    bench.simulate("head", &scene);
    bench.simulate_seed("head2", 2, &scene);
    let mut rmse = f64::NAN;
    for (capture, out) in [("head2", "rec2"), ("head", "rec")] {
        let seconds = bench.reconstruct(capture, out, &["--integrator", "auto"]);
        let (coverage, r) = bench.accuracy(capture, out);
        rmse = r;
        println!(
            "Suzanne 90 mm ({capture}), automatic integrator: {:.2} % of the ≥3-lit surface, RMSE {rmse:.3} \
             mm, {seconds:.1} s",
            100.0 * coverage
        );
        assert!(coverage >= 0.90, "{capture}: coverage {coverage}");
        assert!(rmse <= SUZANNE_MAX_RMSE_MM, "{capture}: RMSE {rmse} mm");
    }
    check_confidence(&bench.path("rec"));
    let report = std::fs::read_to_string(bench.path("rec").join("report.json")).unwrap();
    assert!(
        report.contains("grid edges cut"),
        "the report says what the automatic integrator found"
    );
    // Least squares (the default) smooths across the brow, nose and ears.
    let seconds = bench.reconstruct("head", "ls", &[]);
    let (ls_coverage, ls_rmse) = bench.accuracy("head", "ls");
    println!(
        "Suzanne 90 mm, least squares: {:.2} %, RMSE {ls_rmse:.3} mm, {seconds:.1} s",
        100.0 * ls_coverage
    );
    assert!(ls_coverage >= 0.90, "least squares: coverage {ls_coverage}");
    assert!(
        rmse < ls_rmse,
        "automatic {rmse} mm vs least squares {ls_rmse} mm"
    );
}

/// `confidence.npy` marks every reconstructed pixel (and only those) as measured, two-LED or
/// filled, there are two-LED pixels on a head with cast shadows, and the report and its
/// preview say the same.
fn check_confidence(out: &Path) {
    let depth: Array2<f32> = ndarray_npy::read_npy(out.join("depth.npy")).unwrap();
    let confidence: Array2<u8> = ndarray_npy::read_npy(out.join("confidence.npy")).unwrap();
    assert_eq!(confidence.dim(), depth.dim());
    let mut counts = [0usize; 4];
    for (k, z) in confidence.iter().zip(&depth) {
        assert!(*k <= 3, "confidence code {k}");
        assert_eq!(*k > 0, z.is_finite(), "confidence {k} where depth is {z}");
        counts[*k as usize] += 1;
    }
    println!(
        "confidence: {} measured, {} two-LED, {} filled",
        counts[3], counts[2], counts[1]
    );
    assert!(counts[2] > 0, "no pixel lit by two LEDs");
    let report: meb_cli::export::report::Report =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let c = report.confidence.expect("confidence counts in the report");
    assert_eq!(
        [c.filled, c.two_leds, c.measured],
        [counts[1], counts[2], counts[3]]
    );
    assert!(report.files.iter().any(|f| f == "confidence.png"));
    assert!(out.join("confidence.png").is_file());
}

/// The simulator's seeded blobby shape (thesis Ch. 7) and its two-object scene (a sphere in
/// front of a cube 70 mm further back) reconstruct end to end: the blob as one surface, the
/// two objects as two pieces each placed at its own depth by the near-field stage.
#[test]
fn blobby_and_multi_scenes_reconstruct() {
    let bench = Bench::new(&rig_toml(352, 224, 0.4, &OUT_OF_PLANE_LEDS));
    bench.simulate("blob", &["--scene", "blobby", "--size-mm", "70"]);
    bench.simulate("multi", &["--scene", "multi"]);
    for (name, max_rmse) in [("blob", BLOBBY_MAX_RMSE_MM), ("multi", MULTI_MAX_RMSE_MM)] {
        let out = format!("{name}-rec");
        let seconds = bench.reconstruct(name, &out, &[]);
        let (coverage, rmse) = bench.accuracy(name, &out);
        println!(
            "{name}: {:.2} % of the ≥3-lit surface, RMSE {rmse:.3} mm, {seconds:.1} s",
            100.0 * coverage
        );
        assert!(coverage >= 0.95, "{name}: coverage {coverage}");
        assert!(rmse <= max_rmse, "{name}: RMSE {rmse} mm");
    }
}

/// A pinhole camera with lens distortion in the rig file: the simulator renders through it, the
/// reconstruction integrates in log depth, and the PLY holds metric camera coordinates (z along
/// the optical axis, about 420 mm for an object at the rig's origin).
#[test]
fn perspective_rig_end_to_end() {
    let mut rig = String::from(
        "[camera]\nwidth = 256\nheight = 224\nfps = 960.0\ndistance_mm = 420.0\n\
         [camera.intrinsics]\nfx = 1600.0\nfy = 1600.0\ncx = 125.5\ncy = 113.0\nk1 = -0.15\n",
    );
    for [x, y, z] in OUT_OF_PLANE_LEDS {
        rig.push_str(&format!("[[led]]\nposition_mm = [{x:?}, {y:?}, {z:?}]\n"));
    }
    let bench = Bench::new(&rig);
    bench.simulate("sphere", &["--scene", "sphere", "--size-mm", "48"]);
    bench.reconstruct("sphere", "rec", &[]);
    let (coverage, rmse) = bench.accuracy("sphere", "rec");
    println!(
        "perspective sphere Ø48: {:.2} % of the ≥3-lit surface, RMSE {rmse:.3} mm",
        100.0 * coverage
    );
    assert!(coverage >= 0.95, "coverage {coverage}");
    assert!(rmse <= PERSPECTIVE_MAX_RMSE_MM, "RMSE {rmse} mm");
    let (count, z_range) = ply_vertices(&bench.path("rec/surface.ply"));
    let depth: Array2<f32> = ndarray_npy::read_npy(bench.path("rec/depth.npy")).unwrap();
    assert_eq!(count, depth.iter().filter(|z| z.is_finite()).count());
    // Camera coordinates: 420 mm minus the sphere's heights (0 to 24 mm).
    assert!(
        z_range.0 > 390.0 && z_range.1 < 425.0,
        "PLY z range {z_range:?}"
    );
}

/// Vertex count and z range of a binary little-endian PLY with float x, y, z first.
fn ply_vertices(path: &Path) -> (usize, (f32, f32)) {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = String::from_utf8_lossy(&bytes[..end]);
    let count: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let mut range = (f32::INFINITY, f32::NEG_INFINITY);
    for v in 0..count {
        let at = end + 12 * v + 8;
        let z = f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
        range = (range.0.min(z), range.1.max(z));
    }
    (count, range)
}
