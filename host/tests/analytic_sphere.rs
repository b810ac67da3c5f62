//! An analytic sphere rendered from A_i = ρ max(0, n·L_i(X)) with the near-field light vectors
//! of the thesis' out-of-plane rig reconstructs with small depth and normal errors.

use meb::metrics::{compare_depth, compare_normals};
use meb::reconstruct::{LightModel, ReconstructConfig, ReconstructError, reconstruct};
use meb::rig::Rig;
use meb::types::LedImages;
use nalgebra::Vector3;
use ndarray::{Array2, Array3};

const RADIUS: f64 = 24.0;

/// A small camera (pitch 0.5 mm) on the out-of-plane rig, the sphere Ø48 at the origin.
fn scene() -> (Rig, LedImages, Array2<f32>, Array3<f32>) {
    let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
    rig.camera.width = 128;
    rig.camera.height = 112;
    rig.camera.pixel_pitch_mm = Some(0.5);
    let (rows, cols) = (rig.camera.height, rig.camera.width);
    let mut depth = Array2::from_elem((rows, cols), f32::NAN);
    let mut normals = Array3::from_elem((rows, cols, 3), f32::NAN);
    let mut images = vec![Array2::zeros((rows, cols)); rig.leds.len()];
    let scale = meb::photometric::Lights::near_field_scale(&rig);
    for r in 0..rows {
        for c in 0..cols {
            let (x, y) = rig.camera.pixel_centre_xy(r as f64, c as f64);
            let s = RADIUS * RADIUS - x * x - y * y;
            if s <= 0.0 {
                continue;
            }
            let point = Vector3::new(x, y, s.sqrt());
            let n = point / RADIUS;
            depth[(r, c)] = point.z as f32;
            for j in 0..3 {
                normals[(r, c, j)] = n[j] as f32;
            }
            for (im, led) in images.iter_mut().zip(&rig.leds) {
                let l = led.light_vector_at(&point) * scale;
                im[(r, c)] = (0.6 * n.dot(&l).max(0.0)) as f32;
            }
        }
    }
    (rig, LedImages { images }, depth, normals)
}

fn lit_by_three(images: &LedImages) -> Array2<bool> {
    let shape = images.shape().unwrap();
    Array2::from_shape_fn(shape, |p| {
        images.images.iter().filter(|im| im[p] > 0.0).count() >= 3
    })
}

#[test]
fn near_field_sphere_reconstructs_within_a_tenth_of_a_millimetre() {
    let (rig, images, depth, normals) = scene();
    let out = reconstruct(&images, &rig, None, None, &ReconstructConfig::default()).unwrap();
    let surface = lit_by_three(&images);
    let e = compare_depth(&out.integration.depth.depth_mm, &depth, Some(&surface)).unwrap();
    let a = compare_normals(&out.photometric.field.normals, &normals, &surface).unwrap();
    eprintln!(
        "analytic sphere, near field: RMSE {:.4} mm, NRMSE {:.3} %, {:.1} % of the ≥3-lit surface, \
         normals mean {:.3}° median {:.3}°, offset {:.3} mm",
        e.rmse_mm,
        100.0 * e.nrmse.unwrap_or(f64::NAN),
        100.0 * e.reconstructed_fraction,
        a.mean_deg,
        a.median_deg,
        e.offset_mm
    );
    assert!(e.rmse_mm < 0.1, "RMSE {}", e.rmse_mm);
    assert!(e.reconstructed_fraction > 0.95);
    assert!(a.median_deg < 0.5, "median {}", a.median_deg);
}

#[test]
fn distant_model_is_worse_than_near_field() {
    let (rig, images, _, normals) = scene();
    let surface = lit_by_three(&images);
    let config = ReconstructConfig {
        light_model: LightModel::Distant,
        ..Default::default()
    };
    let distant = reconstruct(&images, &rig, None, None, &config).unwrap();
    let near = reconstruct(&images, &rig, None, None, &ReconstructConfig::default()).unwrap();
    let ed = compare_normals(&distant.photometric.field.normals, &normals, &surface).unwrap();
    let en = compare_normals(&near.photometric.field.normals, &normals, &surface).unwrap();
    eprintln!(
        "median normal error: distant {:.2}°, near field {:.2}°",
        ed.median_deg, en.median_deg
    );
    assert!(ed.median_deg > 4.0 * en.median_deg);
}

#[test]
fn rig_with_two_leds_is_rejected() {
    let (mut rig, mut images, _, _) = scene();
    rig.leds.truncate(2);
    images.images.truncate(2);
    let err = reconstruct(&images, &rig, None, None, &ReconstructConfig::default()).unwrap_err();
    assert!(matches!(err, ReconstructError::Rig(_)));
    assert!(err.to_string().contains("at least 3 LEDs"), "{err}");
}
