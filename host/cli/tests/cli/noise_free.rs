//! A perfect capture gives the best reconstruction, not a degenerate one.
//!
//! A noise-free 16-bit simulation of the thesis' ellipsoid (100×60×60 mm, dynamic rig at
//! 640×360) once reconstructed only 23 % of the surface at 2.8 mm while the same scene with
//! read noise gave 76 % at 0.5 mm: the decoder's σ of a noise-free pixel is a model residual,
//! the negative readings of an unlit LED are rounding residue far below it, and the per-LED
//! noise gain measured from them came out ~10⁻⁴ (photometric::noise). Here both captures go
//! through `meb simulate` and `meb reconstruct` and the noise-free one must do at least as
//! well as the noisy one.

use std::path::Path;

use crate::common;
use common::{dynamic_rig, run_ok};

/// Surface fraction reconstructed and depth RMSE (mm) of the ellipsoid simulated with read
/// noise `noise` (fraction of full scale).
fn ellipsoid_accuracy(dir: &Path, rig: &str, noise: &str) -> (f64, f64) {
    let capture = dir.join(format!("capture-{noise}"));
    let out = dir.join(format!("reconstruction-{noise}"));
    let capture_arg = capture.display().to_string();
    run_ok(&[
        "simulate",
        "--rig",
        rig,
        "--scene",
        "ellipsoid",
        "--axes-mm",
        "100,60,60",
        "--frames",
        "32",
        "--bit-depth",
        "16",
        "--noise",
        noise,
        "--out",
        &capture_arg,
    ]);
    run_ok(&[
        "reconstruct",
        &capture_arg,
        "--rig",
        rig,
        "--out",
        &out.display().to_string(),
        "--ground-truth",
        &capture.join("depth.npy").display().to_string(),
    ]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let accuracy = &report["depth_accuracy"];
    (
        accuracy["reconstructed_fraction"].as_f64().unwrap(),
        accuracy["rmse_mm"].as_f64().unwrap(),
    )
}

#[test]
fn a_noise_free_capture_reconstructs_at_least_as_well_as_a_noisy_one() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = dynamic_rig(tmp.path(), 640, 360);
    let (clean_fraction, clean_rmse) = ellipsoid_accuracy(tmp.path(), &rig, "0");
    let (noisy_fraction, noisy_rmse) = ellipsoid_accuracy(tmp.path(), &rig, "0.005");
    let summary = format!(
        "noise-free {:.1} % at {clean_rmse:.3} mm, noisy {:.1} % at {noisy_rmse:.3} mm",
        100.0 * clean_fraction,
        100.0 * noisy_fraction
    );
    assert!(noisy_fraction > 0.7 && noisy_rmse < 1.0, "{summary}");
    assert!(clean_fraction >= noisy_fraction - 0.005, "{summary}");
    assert!(clean_rmse <= noisy_rmse, "{summary}");
}
