//! `meb tof range | calibrate | mask` end to end on a simulated capture of the thesis' hybrid
//! scene (thesis Ch. 6): files in, folders out, checked against the simulator's truth; bad
//! inputs exit non-zero with a clear message and leave no output.

mod common;
mod tof_common;

use common::meb;
use meb::export::files::{read_float, read_mask, write_npy};
use meb::rig::Rig;
use meb::simulate::tof::camera_labels;
use meb::tof::Calibration;
use ndarray::{Array1, Array2, Array3, Ix2};
use std::path::Path;
use std::process::Output;
use tof_common::{BOARD_HEIGHTS, board, board_images, board_range, hybrid_capture, rig};

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Writes the two board positions' images and runs `meb tof calibrate`; returns its folder.
fn calibrate(dir: &Path, rig: &Rig) -> std::path::PathBuf {
    let tof = rig.tof_camera.as_ref().unwrap();
    let (mut tofs, mut cams, mut ranges) = (Vec::new(), Vec::new(), Vec::new());
    for (k, z) in BOARD_HEIGHTS.into_iter().enumerate() {
        let b = board(tof, z);
        let (tof_image, camera_image) = board_images(rig, &b, k as u64);
        let t = dir.join(format!("board{k}_tof.npy"));
        let c = dir.join(format!("board{k}_camera.npy"));
        write_npy(&t, &tof_image).unwrap();
        write_npy(&c, &camera_image).unwrap();
        ranges.push(format!("{:.1}", board_range(tof, &b)));
        tofs.push(path(&t).to_string());
        cams.push(path(&c).to_string());
    }
    let out = dir.join("cal");
    let run = meb(&[
        "tof",
        "calibrate",
        "--tof",
        &tofs.join(","),
        "--camera",
        &cams.join(","),
        "--board",
        "8x5",
        "--square-mm",
        "16",
        "--range-mm",
        &ranges.join(","),
        "--out",
        path(&out),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    out
}

#[test]
fn range_calibrate_and_segment_the_hybrid_scene() {
    let dir = tempfile::tempdir().unwrap();
    let rig = rig();
    let tof = rig.tof_camera.clone().unwrap();
    let (hybrid, capture) = hybrid_capture(&tof);
    let histograms = dir.path().join("histograms.npy");
    let reference = dir.path().join("reference.npy");
    write_npy(&histograms, &capture.histograms).unwrap();
    write_npy(&reference, &capture.reference).unwrap();

    // Range: RMSE against the truth on pixels whose footprint is one surface.
    let range_dir = dir.path().join("range");
    let fov = format!("{}", tof.fov_deg);
    let run = meb(&[
        "tof",
        "range",
        path(&histograms),
        "--reference",
        path(&reference),
        "--fov-deg",
        &fov,
        "--out",
        path(&range_dir),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let range: Array2<f32> =
        read_float::<Ix2>(&range_dir.join("range.npy"), &[None, None]).unwrap();
    let errors: Vec<f64> = range
        .indexed_iter()
        .filter(|(p, v)| {
            capture.pure[*p] && v.is_finite() && capture.truth_range_mm[*p].is_finite()
        })
        .map(|(p, &v)| f64::from(v - capture.truth_range_mm[p]))
        .collect();
    let pure = capture.pure.iter().filter(|&&p| p).count();
    let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    eprintln!(
        "meb tof range: RMSE {rmse:.2} mm over {} of {pure} single-surface pixels",
        errors.len()
    );
    assert!(
        rmse <= 34.0 / 1.5,
        "range RMSE {rmse} mm (thesis 34 mm, bar 22.7 mm)"
    );
    assert!(errors.len() as f64 >= 0.95 * pure as f64);
    for file in [
        "sigma.npy",
        "confidence.npy",
        "signal.npy",
        "range.png",
        "range.json",
    ] {
        assert!(range_dir.join(file).is_file(), "{file}");
    }

    // Calibration from two rendered board positions.
    let cal_dir = calibrate(dir.path(), &rig);
    let cal = Calibration::load(&cal_dir.join("calibration.toml")).unwrap();
    for plane in &cal.planes {
        eprintln!(
            "meb tof calibrate: corner RMS {:.3} camera px (max {:.3})",
            plane.rms_px, plane.max_px
        );
        assert!(plane.rms_px <= 0.5, "{}", plane.rms_px);
    }

    // Masks: one per object, against the objects' true camera pixels.
    let mask_dir = dir.path().join("masks");
    let run = meb(&[
        "tof",
        "mask",
        path(&range_dir),
        "--calibration",
        path(&cal_dir),
        "--segment",
        "--out",
        path(&mask_dir),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let truth = camera_labels(&hybrid.scene, &hybrid.groups, &rig.camera);
    let objects = hybrid.names.len();
    for k in 0..objects {
        let mask = read_mask(&mask_dir.join(format!("mask_{}.png", k + 1))).unwrap();
        assert_eq!(mask.dim(), truth.dim());
        // Masks are nearest first, as are the scene's groups (sphere, head, cube).
        let label = k as i32;
        let object = truth.iter().filter(|&&l| l == label).count();
        let covered = truth
            .iter()
            .zip(&mask)
            .filter(|&(&l, &m)| m && l == label)
            .count();
        let foreign = truth
            .iter()
            .zip(&mask)
            .filter(|&(&l, &m)| m && l >= 0 && l != label)
            .count();
        let outside = truth
            .iter()
            .zip(&mask)
            .filter(|&(&l, &m)| m && l < 0)
            .count();
        let coverage = covered as f64 / object as f64;
        eprintln!(
            "meb tof mask --segment: {}: {:.1} % of its {object} pixels, {foreign} of another object, {outside} of the wall",
            hybrid.names[k],
            100.0 * coverage
        );
        assert_eq!(foreign, 0, "{}", hybrid.names[k]);
        assert!(coverage >= 0.9, "{}: {coverage}", hybrid.names[k]);
    }
    assert!(!mask_dir.join(format!("mask_{}.png", objects + 1)).exists());
    let labels =
        meb::export::files::read_exact::<i32, Ix2>(&mask_dir.join("labels.npy"), &[None, None])
            .unwrap();
    assert_eq!(labels.iter().copied().max(), Some(objects as i32 - 1));

    // The thesis' interval selection of the sphere.
    let sphere = dir.path().join("sphere");
    let lo = capture
        .truth_range_mm
        .iter()
        .zip(&capture.truth_label)
        .filter(|&(_, &l)| l == 0)
        .map(|(&r, _)| r)
        .fold(f32::INFINITY, f32::min);
    let interval = format!("{}..{}", lo - 20.0, lo + 60.0);
    let run = meb(&[
        "tof",
        "mask",
        path(&range_dir),
        "--calibration",
        path(&cal_dir),
        "--interval",
        &interval,
        "--out",
        path(&sphere),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let mask = read_mask(&sphere.join("mask.png")).unwrap();
    let covered = truth
        .iter()
        .zip(&mask)
        .filter(|&(&l, &m)| m && l == 0)
        .count();
    let foreign = truth
        .iter()
        .zip(&mask)
        .filter(|&(&l, &m)| m && l > 0)
        .count();
    assert!(covered > 0 && foreign == 0, "{covered} {foreign}");

    // Bad inputs: no output, a message that says what is wrong.
    let refused = |args: &[&str], out: &Path, expect: &str| {
        let run = meb(args);
        assert!(!run.status.success(), "{args:?} succeeded");
        let text = stderr(&run);
        assert!(text.contains(expect), "{args:?}: {text}");
        assert!(!out.exists(), "{args:?} left {}", out.display());
    };
    let out = dir.path().join("refused");
    let short = dir.path().join("short.npy");
    write_npy(&short, &Array1::<u32>::ones(512)).unwrap();
    refused(
        &[
            "tof",
            "range",
            path(&histograms),
            "--reference",
            path(&short),
            "--out",
            path(&out),
        ],
        &out,
        "512 time bins",
    );
    let zeros = dir.path().join("zeros.npy");
    write_npy(&zeros, &Array3::<u32>::zeros((4, 4, 1024))).unwrap();
    refused(
        &[
            "tof",
            "range",
            path(&zeros),
            "--reference",
            path(&reference),
            "--out",
            path(&out),
        ],
        &out,
        "no photon",
    );
    refused(
        &[
            "tof",
            "mask",
            path(&range_dir),
            "--calibration",
            path(&cal_dir),
            "--interval",
            "5000..6000",
            "--out",
            path(&out),
        ],
        &out,
        "no ToF pixel has a range in 5000..6000",
    );
    let small = dir.path().join("small_range.npy");
    write_npy(&small, &Array2::<f32>::from_elem((64, 96), 700.0)).unwrap();
    refused(
        &[
            "tof",
            "mask",
            path(&small),
            "--calibration",
            path(&cal_dir),
            "--segment",
            "--out",
            path(&out),
        ],
        &out,
        "made for 192x128 ToF images",
    );
    let blank = dir.path().join("blank.npy");
    write_npy(&blank, &Array2::<f32>::from_elem((128, 192), 3.0)).unwrap();
    let camera = dir.path().join("board0_camera.npy");
    refused(
        &[
            "tof",
            "calibrate",
            "--tof",
            path(&blank),
            "--camera",
            path(&camera),
            "--board",
            "8x5",
            "--out",
            path(&out),
        ],
        &out,
        "no 8x5 chequerboard found in the ToF",
    );
}
