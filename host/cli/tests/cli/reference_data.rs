//! Accuracy on public reference data: Quéau's vase (normal integration) and the DiLiGenT ball
//! 4-light subset (photometric stereo). Targets: vase NRMSE ≤ 0.2 % for the default integrator
//! and least squares, the thesis' 2.5 % for Fast Marching; ball mean error ≤ 3.95°.

use meb_core::datasets::{diligent::load_diligent, mat::read_mat_array};
use meb_core::metrics::{compare_depth, compare_normals};
use meb_pipeline::integrate::{IntegrateConfig, Integrator, SurfaceGradients, integrate_gradients};
use meb_pipeline::photometric::{Lights, PhotometricConfig, estimate_normals};
use ndarray::{Array2, Ix2};
use std::path::PathBuf;

fn data(path: &str) -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/"
    ))
    .join(path)
}

/// Vase slopes in this project's convention: p = ∂u/∂row, q = ∂u/∂col, so with h = 1,
/// ∂z/∂x = q and ∂z/∂y = −p (y up).
fn vase() -> (SurfaceGradients, Array2<f32>) {
    let load = |name: &str| {
        read_mat_array(&data("vase.mat"), name)
            .unwrap()
            .into_dimensionality::<Ix2>()
            .unwrap()
    };
    let (p, q, u, mask) = (load("p"), load("q"), load("u"), load("mask"));
    let mask = mask.mapv(|m| m > 0.5);
    assert_eq!(mask.iter().filter(|&&m| m).count(), 25_410);
    let truth = Array2::from_shape_fn(u.dim(), |ix| if mask[ix] { u[ix] as f32 } else { f32::NAN });
    let g = SurfaceGradients {
        dzdx: q,
        dzdy: p.mapv(|v| -v),
        mask,
    };
    (g, truth)
}

fn vase_nrmse(integrator: Integrator) -> (f64, f64) {
    let (g, truth) = vase();
    let config = IntegrateConfig {
        integrator,
        filter: meb_pipeline::integrate::ArtefactFilter { max_jump_mm: None },
        ..Default::default()
    };
    let out = integrate_gradients(&g, 1.0, &config, None).unwrap();
    let e = compare_depth(&out.depth.depth_mm, &truth, None).unwrap();
    eprintln!(
        "vase {integrator:?}: RMSE {:.4}, NRMSE {:.3} %, {:.1} % reconstructed, {} iterations",
        e.rmse_mm,
        100.0 * e.nrmse.unwrap_or(f64::NAN),
        100.0 * e.reconstructed_fraction,
        out.iterations
    );
    (e.nrmse.unwrap_or(f64::INFINITY), e.reconstructed_fraction)
}

/// The default integrator must reach NRMSE ≤ 0.2 % on this smooth surface.
#[test]
fn vase_default_integrator_nrmse_at_most_0_2_percent() {
    let (nrmse, covered) = vase_nrmse(IntegrateConfig::default().integrator);
    assert!(nrmse <= 0.002, "NRMSE {:.3} %", 100.0 * nrmse);
    assert!(covered > 0.999);
}

/// Bilateral normal integration on the smooth vase: measured NRMSE 0.349 % (least squares
/// 0.149 %), which is why it is not the default.
#[test]
fn vase_bilateral_nrmse_at_most_0_4_percent() {
    let (nrmse, covered) = vase_nrmse(Integrator::Bilateral);
    assert!(nrmse <= 0.004, "NRMSE {:.3} %", 100.0 * nrmse);
    assert!(covered > 0.999);
}

#[test]
fn vase_least_squares_nrmse_at_most_0_2_percent() {
    let (nrmse, covered) = vase_nrmse(Integrator::LeastSquares);
    assert!(nrmse <= 0.002, "NRMSE {:.3} %", 100.0 * nrmse);
    assert!(covered > 0.999);
}

#[test]
fn vase_fast_marching_within_thesis_figure() {
    // The thesis reports 2.5 % for its Fast Marching integrator on this data set.
    let (nrmse, covered) = vase_nrmse(Integrator::FastMarching);
    assert!(nrmse <= 0.05, "NRMSE {:.3} %", 100.0 * nrmse);
    assert!(covered > 0.999);
}

#[test]
fn diligent_ball_four_lights_mean_error_at_most_3_95_degrees() {
    let set = load_diligent(&data("diligent-ball")).unwrap();
    let mask = set.mask.clone().unwrap();
    assert_eq!(mask.iter().filter(|&&m| m).count(), 15_791);
    let config = PhotometricConfig::default();
    let res = estimate_normals(
        &set.images,
        &Lights::Distant(set.lights.clone()),
        Some(&mask),
        None,
        &config,
    )
    .unwrap();
    let gt = set.normals_gt.unwrap();
    let e = compare_normals(&res.field.normals, &gt, &mask).unwrap();
    let solved = e.compared_pixels as f64 / 15_791.0;
    eprintln!(
        "DiLiGenT ball (4 lights): mean {:.3}°, median {:.3}°, {:.1} % solved",
        e.mean_deg,
        e.median_deg,
        100.0 * solved
    );
    assert!(e.mean_deg <= 3.95, "mean {:.3}°", e.mean_deg);
    assert!(solved > 0.95);
}
