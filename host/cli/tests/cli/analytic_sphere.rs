//! Analytic spheres rendered from A_i = ρ max(0, n·L_i(X)) with the near-field light vectors of
//! the thesis' out-of-plane rig reconstruct with small depth and normal errors: seen by the
//! orthographic camera, by a pinhole camera with lens distortion, and as two separate objects at
//! different depths (each placed by the near-field stage).

use meb_core::metrics::{compare_depth, compare_normals};
use meb_core::rig::{Intrinsics, Rig};
use meb_core::types::LedImages;
use meb_pipeline::reconstruct::{
    LightModel, ReconstructConfig, ReconstructError, Request, Source, reconstruct,
};
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
    let scale = meb_pipeline::photometric::Lights::near_field_scale(&rig);
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
    let out = reconstruct(
        Source::Images {
            images: &images,
            noise: None,
        },
        &rig,
        &ReconstructConfig::default(),
        Request::default(),
    )
    .unwrap();
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
    let distant = reconstruct(
        Source::Images {
            images: &images,
            noise: None,
        },
        &rig,
        &config,
        Request::default(),
    )
    .unwrap();
    let near = reconstruct(
        Source::Images {
            images: &images,
            noise: None,
        },
        &rig,
        &ReconstructConfig::default(),
        Request::default(),
    )
    .unwrap();
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
    let err = reconstruct(
        Source::Images {
            images: &images,
            noise: None,
        },
        &rig,
        &ReconstructConfig::default(),
        Request::default(),
    )
    .unwrap_err();
    assert!(matches!(err, ReconstructError::Rig(_)));
    assert!(err.to_string().contains("at least 3 LEDs"), "{err}");
}

/// Spheres (centre, radius) seen through `rig`'s camera: LED images (no cast shadows), the true
/// depth and the pixels lit by three or more LEDs.
fn render_spheres(rig: &Rig, spheres: &[(Vector3<f64>, f64)]) -> (LedImages, Array2<f32>) {
    let (rows, cols) = (rig.camera.height, rig.camera.width);
    let mut depth = Array2::from_elem((rows, cols), f32::NAN);
    let mut images = vec![Array2::zeros((rows, cols)); rig.leds.len()];
    let scale = meb_pipeline::photometric::Lights::near_field_scale(rig);
    for r in 0..rows {
        for c in 0..cols {
            let ray = rig.camera.ray(r as f64, c as f64);
            // Nearest hit: the largest z on the ray |base + z·slope − centre| = R.
            let hit = spheres
                .iter()
                .filter_map(|(centre, radius)| {
                    let o = ray.base - centre;
                    let (a, b, k) = (
                        ray.slope.norm_squared(),
                        2.0 * o.dot(&ray.slope),
                        o.norm_squared() - radius * radius,
                    );
                    let disc = b * b - 4.0 * a * k;
                    (disc > 0.0).then(|| {
                        let z = (-b + disc.sqrt()) / (2.0 * a);
                        (z, (ray.at(z) - centre) / *radius)
                    })
                })
                .max_by(|x, y| x.0.total_cmp(&y.0));
            let Some((z, n)) = hit else { continue };
            depth[(r, c)] = z as f32;
            let point = ray.at(z);
            for (im, led) in images.iter_mut().zip(&rig.leds) {
                let l = led.light_vector_at(&point) * scale;
                im[(r, c)] = (0.6 * n.dot(&l).max(0.0)) as f32;
            }
        }
    }
    (LedImages { images }, depth)
}

/// The out-of-plane rig's LEDs with a 200×160 pinhole camera 420 mm away: f = 1400 px (≈ 0.3 mm
/// per pixel at the object), barrel distortion, principal point off centre.
fn perspective_rig() -> Rig {
    let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
    rig.camera.width = 200;
    rig.camera.height = 160;
    rig.camera.fov_deg = None;
    rig.camera.pixel_pitch_mm = None;
    rig.camera.intrinsics = Some(Intrinsics {
        fx: 1400.0,
        fy: 1400.0,
        cx: 97.0,
        cy: 82.0,
        k1: -0.3,
        k2: 0.0,
    });
    rig
}

#[test]
fn perspective_sphere_reconstructs_in_metric_depth() {
    let rig = perspective_rig();
    let (images, depth) = render_spheres(&rig, &[(Vector3::zeros(), RADIUS)]);
    let surface = lit_by_three(&images);
    let out = reconstruct(
        Source::Images {
            images: &images,
            noise: None,
        },
        &rig,
        &ReconstructConfig::default(),
        Request::default(),
    )
    .unwrap();
    let e = compare_depth(&out.integration.depth.depth_mm, &depth, Some(&surface)).unwrap();
    // The same images read as if the camera were orthographic (same pitch at the object).
    let mut ortho = rig.clone();
    ortho.camera.intrinsics = None;
    ortho.camera.pixel_pitch_mm = Some(rig.camera.pitch_mm());
    let wrong = reconstruct(
        Source::Images {
            images: &images,
            noise: None,
        },
        &ortho,
        &ReconstructConfig::default(),
        Request::default(),
    )
    .unwrap();
    let w = compare_depth(&wrong.integration.depth.depth_mm, &depth, Some(&surface)).unwrap();
    eprintln!(
        "perspective sphere: RMSE {:.4} mm over {:.1} % of the ≥3-lit surface, offset {:.3} mm; \
         read as orthographic {:.3} mm",
        e.rmse_mm,
        100.0 * e.reconstructed_fraction,
        e.offset_mm,
        w.rmse_mm
    );
    assert!(e.rmse_mm < 0.1, "RMSE {}", e.rmse_mm);
    assert!(e.reconstructed_fraction > 0.98);
    assert!(
        e.offset_mm.abs() < 1.0,
        "absolute depth off by {} mm",
        e.offset_mm
    );
    assert!(
        w.rmse_mm > 3.0 * e.rmse_mm,
        "orthographic reading {} mm",
        w.rmse_mm
    );
}

/// Two spheres 50 mm apart in depth: each is a separate piece of the mask, placed at its own
/// depth by the near-field offset search (an outline anchor would put both at z = 0).
#[test]
fn separate_objects_are_placed_at_their_own_depth() {
    let (mut rig, _, _, _) = scene();
    rig.camera.width = 160;
    let spheres = [
        (Vector3::new(-20.0, 0.0, 0.0), 15.0),
        (Vector3::new(22.0, 0.0, -50.0), 15.0),
    ];
    let (images, depth) = render_spheres(&rig, &spheres);
    let surface = lit_by_three(&images);
    let out = reconstruct(
        Source::Images {
            images: &images,
            noise: None,
        },
        &rig,
        &ReconstructConfig::default(),
        Request::default(),
    )
    .unwrap();
    assert_eq!(out.integration.pieces, 2);
    for (i, (centre, _)) in spheres.iter().enumerate() {
        let this = Array2::from_shape_fn(depth.dim(), |(r, c)| {
            let (x, _) = rig.camera.pixel_centre_xy(r as f64, c as f64);
            surface[(r, c)] && (x - centre.x).abs() < 16.0
        });
        let e = compare_depth(&out.integration.depth.depth_mm, &depth, Some(&this)).unwrap();
        eprintln!(
            "sphere {} at z = {}: RMSE {:.3} mm, offset {:.3} mm",
            i + 1,
            centre.z,
            e.rmse_mm,
            e.offset_mm
        );
        assert!(e.rmse_mm < 0.2, "RMSE {}", e.rmse_mm);
        assert!(
            e.offset_mm.abs() < 2.0,
            "sphere {} off by {} mm",
            i + 1,
            e.offset_mm
        );
    }
}
