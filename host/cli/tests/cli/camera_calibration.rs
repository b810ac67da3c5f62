//! `meb calibrate camera` through the binary: photos of a chequerboard rendered by the
//! simulator through a pinhole camera with radial distortion at random poses (seeded), the
//! intrinsics fitted and written into the rig; too few photos and a photo without the board
//! are refused. Corner finding and the fit need meb's `opencv` feature.

use crate::common::{arg, meb, run_ok, stderr_of};
use meb_core::rig::{Intrinsics, Rig};
use meb_sim::board_view::random_board_views;
use std::path::{Path, PathBuf};

/// The camera the photos are rendered with: 640×360, slightly unequal focal lengths, the
/// principal point off the image's middle, barrel distortion.
const TRUTH: Intrinsics = Intrinsics {
    fx: 812.0,
    fy: 808.5,
    cx: 324.6,
    cy: 176.2,
    k1: -0.12,
    k2: 0.08,
};

/// The out-of-plane rig with a 640×360 camera, without intrinsics (what a user starts from),
/// written to `dir/rig.toml`; and the rig with the true intrinsics.
fn rigs(dir: &Path) -> (PathBuf, Rig) {
    let mut rig = Rig::preset("thesis-out-of-plane").expect("preset");
    rig.camera.width = 640;
    rig.camera.height = 360;
    let path = dir.join("rig.toml");
    std::fs::write(&path, rig.to_toml_string()).unwrap();
    let mut truth = rig.clone();
    truth.camera.intrinsics = Some(TRUTH);
    (path, truth)
}

/// Renders `count` photos of a 9×6 board of 20 mm squares (noise σ 1 % of full scale, 8-bit
/// PNG) at poses from `seed`; returns their paths.
fn photos(dir: &Path, truth: &Rig, count: usize, seed: u64) -> Vec<PathBuf> {
    let views = random_board_views(&truth.camera, 9, 6, 20.0, count, seed);
    assert_eq!(views.len(), count, "too few poses found");
    views
        .iter()
        .enumerate()
        .map(|(k, view)| {
            let image = view.image(&truth.camera, 0.01, seed * 100 + k as u64);
            let (h, w) = image.dim();
            let bytes: Vec<u8> = image.iter().map(|v| (v * 255.0).round() as u8).collect();
            let path = dir.join(format!("board{k:02}.png"));
            image::GrayImage::from_raw(w as u32, h as u32, bytes)
                .unwrap()
                .save(&path)
                .unwrap();
            path
        })
        .collect()
}

/// Ten photos at random poses give fx, fy within 0.5 % and cx, cy within 1 px, written into
/// the rig with the reprojection RMS; two pose sets (seeds 13, 14) outside the sweep the poses were
/// tuned on.
#[test]
#[cfg_attr(
    not(feature = "opencv"),
    ignore = "needs the opencv feature (calibrate camera)"
)]
fn ten_board_photos_give_the_intrinsics() {
    let tmp = tempfile::tempdir().unwrap();
    let (nominal, truth) = rigs(tmp.path());
    for seed in [13u64, 14] {
        let dir = tmp.path().join(format!("seed{seed}"));
        std::fs::create_dir_all(&dir).unwrap();
        let images = photos(&dir, &truth, 10, seed);
        let out = dir.join("calibration");
        let mut args = vec!["calibrate", "camera"];
        args.extend(images.iter().map(|p| arg(p)));
        args.extend_from_slice(&[
            "--board",
            "9x6",
            "--square-mm",
            "20",
            "--rig",
            arg(&nominal),
            "--out",
            arg(&out),
        ]);
        let printed = run_ok(&args);
        let rig = Rig::load(arg(&out.join("rig.toml"))).unwrap();
        let k = rig.camera.intrinsics.expect("intrinsics written");
        eprintln!("seed {seed}: {printed}fitted {k:?}");
        assert!(
            (k.fx / TRUTH.fx - 1.0).abs() < 0.005,
            "fx {}\n{printed}",
            k.fx
        );
        assert!(
            (k.fy / TRUTH.fy - 1.0).abs() < 0.005,
            "fy {}\n{printed}",
            k.fy
        );
        assert!((k.cx - TRUTH.cx).abs() < 1.0, "cx {}\n{printed}", k.cx);
        assert!((k.cy - TRUTH.cy).abs() < 1.0, "cy {}\n{printed}", k.cy);
        assert!((k.k1 - TRUTH.k1).abs() < 0.03, "k1 {}\n{printed}", k.k1);
        assert_eq!(rig.leds, truth.leds, "the LEDs are kept");
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("calibration.json")).unwrap())
                .unwrap();
        let rms = json["fit"]["rms_px"].as_f64().expect("rms_px");
        assert!(rms > 0.0 && rms < 0.5, "reprojection RMS {rms}");
    }
}

/// Four photos are too few; a photo without the board (or of another board size) is named;
/// nothing is written.
#[test]
#[cfg_attr(
    not(feature = "opencv"),
    ignore = "needs the opencv feature (calibrate camera)"
)]
fn camera_calibration_refuses_too_few_photos_and_a_photo_without_the_board() {
    let tmp = tempfile::tempdir().unwrap();
    let (nominal, truth) = rigs(tmp.path());
    let images = photos(tmp.path(), &truth, 6, 9);
    let blank = tmp.path().join("wall.png");
    image::GrayImage::from_fn(640, 360, |x, y| {
        image::Luma([((x * 7 + y * 13) % 50) as u8 + 100])
    })
    .save(&blank)
    .unwrap();
    let refuse = |images: &[&Path], board: &str, name: &str| {
        let out = tmp.path().join(name);
        let mut args = vec!["calibrate", "camera"];
        args.extend(images.iter().map(|p| arg(p)));
        args.extend_from_slice(&[
            "--board",
            board,
            "--square-mm",
            "20",
            "--rig",
            arg(&nominal),
            "--out",
            arg(&out),
        ]);
        let output = meb(&args);
        assert!(!output.status.success(), "{name}: accepted");
        assert!(!out.exists(), "{name}: written");
        stderr_of(&output)
    };
    let four: Vec<&Path> = images.iter().take(4).map(|p| p.as_path()).collect();
    let message = refuse(&four, "9x6", "four");
    assert!(message.contains("at least 5"), "{message}");
    let mut with_wall: Vec<&Path> = images.iter().map(|p| p.as_path()).collect();
    with_wall.insert(2, &blank);
    let message = refuse(&with_wall, "9x6", "wall");
    assert!(message.contains("wall.png"), "{message}");
    let all: Vec<&Path> = images.iter().map(|p| p.as_path()).collect();
    let message = refuse(&all, "8x6", "wrong-board");
    assert!(
        message.contains("8x6") || message.contains("48"),
        "{message}"
    );
    let message = refuse(&all, "9by6", "bad-board");
    assert!(message.contains("COLSxROWS"), "{message}");
}

/// Twelve pose sets of ten photos each (seeds 1–12), through the library the command calls:
/// every set within the targets (fx, fy 0.5 %, cx, cy 1 px). Measured: worst fx 0.10 %,
/// fy 0.13 %, cx 0.66 px, cy 0.93 px; the standard errors OpenCV gives for cy are 0.6–0.9 px,
/// so the 1 px target is met by the poses' tilts (docs/maths/camera-calibration.md#accuracy).
#[test]
#[cfg_attr(
    not(feature = "opencv"),
    ignore = "needs the opencv feature (calibrate camera)"
)]
#[cfg_attr(
    feature = "opencv",
    ignore = "sweep of 120 rendered photos (about 40 s); the fast version is ten_board_photos_give_the_intrinsics"
)]
fn intrinsics_over_twelve_pose_sets() {
    use meb_pipeline::calibrate::calibrate_camera;
    use meb_pipeline::tof::chequerboard::BoardSize;
    let tmp = tempfile::tempdir().unwrap();
    let (_, truth) = rigs(tmp.path());
    let names: Vec<String> = (1..=10).map(|k| format!("photo {k}")).collect();
    let mut worst = [0.0f64; 4];
    for seed in 1..=12u64 {
        let views = random_board_views(&truth.camera, 9, 6, 20.0, 10, seed);
        // The 8-bit quantisation of the PNG photos the command reads.
        let images: Vec<_> = views
            .iter()
            .enumerate()
            .map(|(k, v)| {
                v.image(&truth.camera, 0.01, seed * 100 + k as u64)
                    .mapv(|x| (x * 255.0).round() / 255.0)
            })
            .collect();
        let fit = calibrate_camera(&images, &names, BoardSize { cols: 9, rows: 6 }, 20.0)
            .expect("calibration");
        let k = fit.intrinsics;
        let errors = [
            100.0 * (k.fx / TRUTH.fx - 1.0),
            100.0 * (k.fy / TRUTH.fy - 1.0),
            k.cx - TRUTH.cx,
            k.cy - TRUTH.cy,
        ];
        eprintln!(
            "| {seed} | {:+.3} % | {:+.3} % | {:+.2} px (± {:.2}) | {:+.2} px (± {:.2}) | {:.4} | {:.3} px |",
            errors[0],
            errors[1],
            errors[2],
            fit.standard_errors[2],
            errors[3],
            fit.standard_errors[3],
            k.k1,
            fit.rms_px
        );
        for (w, e) in worst.iter_mut().zip(errors) {
            *w = w.max(e.abs());
        }
    }
    eprintln!(
        "worst: fx {:.3} %, fy {:.3} %, cx {:.2} px, cy {:.2} px",
        worst[0], worst[1], worst[2], worst[3]
    );
    assert!(worst[0] < 0.5 && worst[1] < 0.5, "{worst:?}");
    assert!(worst[2] < 1.0 && worst[3] < 1.0, "{worst:?}");
}
