//! Tests of the rig: parsing, presets, projection, light vectors, validation.

use super::*;

#[test]
fn presets_validate_and_round_trip() {
    for name in PRESETS {
        let rig = Rig::preset(name).expect("preset exists");
        rig.validate().expect("preset is valid");
        let text = rig.to_toml_string();
        assert_eq!(Rig::from_toml_str(&text, name).unwrap(), rig);
    }
}

#[test]
fn documented_format_parses() {
    let text = r#"
        [camera]
        width = 1280
        height = 720
        fps = 960.0
        distance_mm = 420.0
        fov_deg = 43.0
        [[led]]
        position_mm = [-270.0, 420.0, 100.0]
        [[led]]
        position_mm = [270.0, 420.0, 100.0]
        intensity = 2.0
    "#;
    let rig = Rig::from_toml_str(text, "test").unwrap();
    assert_eq!(rig.leds.len(), 2);
    assert_eq!(rig.leds[1].intensity, 2.0);
    // h = 2 · 420 · tan(21.5°) / 1280 = 0.2585 mm
    assert!((rig.camera.pitch_mm() - 0.25849).abs() < 1e-4);
}

#[test]
fn invalid_fields_are_named() {
    let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
    rig.leds[2].intensity = -1.0;
    let err = rig.validate().unwrap_err().to_string();
    assert!(err.contains("led[3].intensity"), "{err}");
    let err = Rig::from_toml_str("[camera]\nwidth = 1", "x.toml").unwrap_err();
    assert!(matches!(err, RigError::Parse { .. }));
    assert!(matches!(
        Rig::load("no-such-rig"),
        Err(RigError::UnknownPreset(_))
    ));
}

#[test]
fn pixel_mapping_inverts_and_puts_y_up() {
    let cam = Rig::preset("thesis-out-of-plane").unwrap().camera;
    let (x, y) = cam.pixel_centre_xy(0.0, 0.0);
    assert!(x < 0.0 && y > 0.0, "row 0, col 0 is top-left");
    let (r, c) = cam.xy_to_pixel(x, y);
    assert!(r.abs() < 1e-9 && c.abs() < 1e-9);
}

#[test]
fn light_vector_follows_inverse_square_and_cosine() {
    let led = Led {
        position_mm: [0.0, 0.0, 100.0],
        axis: None,
        intensity: 1.0,
        lambert_order: 1.0,
    };
    let l0 = led.light_vector_at(&Vector3::zeros());
    assert!((l0 - Vector3::new(0.0, 0.0, 1e-4)).norm() < 1e-12);
    // A point 100 mm to the side: d² = 2e4, cos θ = 1/√2, direction (−1, 0, 1)/√2.
    let l1 = led.light_vector_at(&Vector3::new(100.0, 0.0, 0.0));
    let expected = Vector3::new(-1.0, 0.0, 1.0) / 2f64.sqrt() * (0.5f64.sqrt() / 2e4);
    assert!((l1 - expected).norm() < 1e-12);
    // A narrower emitter (m = 2) falls off as cos² θ; the general path agrees with the
    // Lambertian one's as m → 1; nothing is emitted behind the LED.
    let narrow = Led {
        lambert_order: 2.0,
        ..led.clone()
    };
    let l2 = narrow.light_vector_at(&Vector3::new(100.0, 0.0, 0.0));
    assert!((l2 - expected * 0.5f64.sqrt()).norm() < 1e-12);
    let almost = Led {
        lambert_order: 1.0 + 1e-12,
        ..led.clone()
    };
    for point in [
        Vector3::new(100.0, 0.0, 0.0),
        Vector3::new(-30.0, 55.0, 20.0),
    ] {
        let (a, b) = (led.light_vector_at(&point), almost.light_vector_at(&point));
        assert!((a - b).norm() < 1e-9 * a.norm(), "{a} {b}");
    }
    assert_eq!(
        led.light_vector_at(&Vector3::new(0.0, 0.0, 150.0)),
        Vector3::zeros()
    );
    assert_eq!(
        narrow.light_vector_at(&Vector3::new(0.0, 0.0, 150.0)),
        Vector3::zeros()
    );
}

fn perspective() -> Camera {
    Camera::test_64x48(
        None,
        Some(Intrinsics {
            fx: 900.0,
            fy: 880.0,
            cx: 30.5,
            cy: 25.0,
            k1: -0.2,
            k2: 0.05,
        }),
    )
}

#[test]
fn perspective_rays_project_back_to_their_pixel() {
    let cam = perspective();
    for (row, col) in [(0.0, 0.0), (25.0, 30.5), (47.0, 63.0), (10.3, 50.7)] {
        let ray = cam.ray(row, col);
        for z in [-30.0, 0.0, 25.0] {
            let (r, c) = cam.project(&ray.at(z)).unwrap();
            assert!((r - row).abs() < 1e-9 && (c - col).abs() < 1e-9, "{r} {c}");
        }
        // The ray passes through the camera centre (0, 0, D).
        let centre = ray.at(cam.distance_mm);
        assert!((centre.z - cam.distance_mm).abs() < 1e-9 && centre.xy().norm() < 1e-9);
    }
    // Principal point looks straight down; a pixel to the right sees +x, one below sees −y.
    let (x, y) = cam.pixel_centre_xy(25.0, 30.5);
    assert!(x.abs() < 1e-12 && y.abs() < 1e-12);
    let (x, y) = cam.pixel_centre_xy(40.0, 60.0);
    assert!(x > 0.0 && y < 0.0);
    assert!((cam.pitch_mm() - 400.0 / 900.0).abs() < 1e-12);
    assert!(cam.project(&Vector3::new(0.0, 0.0, 400.0)).is_none());
}

/// Every third pixel of a distorted camera sees along the ray of its full-grid pixel.
#[test]
fn sub_sampled_projection_keeps_each_pixels_ray() {
    let full = perspective().projection();
    let coarse = full.every(3);
    for (row, col) in [(0.0, 0.0), (4.0, 7.0), (15.0, 20.0)] {
        let (a, b) = (coarse.ray(row, col), full.ray(3.0 * row, 3.0 * col));
        let (pa, pb) = (a.at(10.0), b.at(10.0));
        assert!((pa - pb).norm() < 1e-9, "{pa} vs {pb}");
    }
}

/// Each pixel of a camera cut to a region of interest sees along the ray of its pixel in
/// the full image, for a field-of-view, a pitch and a pinhole camera.
#[test]
fn a_cropped_camera_keeps_each_pixels_ray() {
    let mut by_fov = Camera::test_64x48(None, None);
    by_fov.fov_deg = Some(40.0);
    for full in [by_fov, Camera::test_64x48(Some(0.7), None), perspective()] {
        let region = full.cropped(10..30, 25..60);
        assert_eq!((region.width, region.height), (35, 20));
        let rig = |camera: &Camera| Rig {
            camera: camera.clone(),
            ..Rig::preset("thesis-dynamic").expect("preset")
        };
        let region_rig = rig(&region);
        region_rig.validate().expect("a valid region camera");
        let text = region_rig.to_toml_string();
        assert_eq!(Rig::from_toml_str(&text, "region").unwrap(), region_rig);
        for (row, col) in [(0.0, 0.0), (4.5, 7.0), (19.0, 34.0)] {
            let (a, b) = (region.ray(row, col), full.ray(row + 10.0, col + 25.0));
            assert!(
                (a.at(7.0) - b.at(7.0)).norm() < 1e-9,
                "{full:?} at {row}, {col}"
            );
            let (r, c) = region.project(&b.at(-3.0)).expect("in front of the camera");
            assert!((r - row).abs() < 1e-6 && (c - col).abs() < 1e-6, "{r}, {c}");
        }
    }
    // An axis is for orthographic cameras, in finite pixels.
    let mut rig = Rig::preset("thesis-dynamic").expect("preset");
    rig.camera.axis_px = Some([f64::NAN, 3.0]);
    assert!(rig.validate().is_err());
    rig.camera = Camera {
        axis_px: Some([1.0, 2.0]),
        ..perspective()
    };
    assert!(rig.validate().is_err());
}

/// Each pixel of a binned camera sees along the ray through the centre of its block, for
/// a field-of-view, a pitch and a distorted pinhole camera, and a binned rig is valid and
/// round-trips through TOML.
#[test]
fn a_binned_camera_sees_through_each_blocks_centre() {
    let mut by_fov = Camera::test_64x48(None, None);
    by_fov.fov_deg = Some(40.0);
    for full in [by_fov, Camera::test_64x48(Some(0.7), None), perspective()] {
        for k in [2usize, 3] {
            let binned = full.binned(k);
            assert_eq!(
                (binned.width, binned.height),
                (full.width / k, full.height / k)
            );
            let rig = Rig {
                camera: full.clone(),
                ..Rig::preset("thesis-dynamic").expect("preset")
            }
            .binned(k);
            rig.validate().expect("a valid binned camera");
            assert_eq!(rig.camera, binned);
            let text = rig.to_toml_string();
            assert_eq!(Rig::from_toml_str(&text, "binned").unwrap(), rig);
            let centre = (k as f64 - 1.0) / 2.0;
            for (row, col) in [(0.0, 0.0), (4.0, 7.0), (12.0, 17.0)] {
                let (r, c) = (row * k as f64 + centre, col * k as f64 + centre);
                let (a, b) = (binned.ray(row, col), full.ray(r, c));
                assert!(
                    (a.at(7.0) - b.at(7.0)).norm() < 1e-9
                        && (a.at(-5.0) - b.at(-5.0)).norm() < 1e-9,
                    "{full:?} by {k} at {row}, {col}"
                );
            }
        }
        assert_eq!(full.binned(1), full);
    }
}

/// Every third pixel of an orthographic camera sees along the ray of its full-grid pixel.
#[test]
fn sub_sampled_orthographic_projection_keeps_each_pixels_ray() {
    let full = Camera::test_64x48(Some(0.5), None).projection();
    let coarse = full.every(3);
    for (row, col) in [(0.0, 0.0), (4.0, 7.0), (15.0, 20.0)] {
        let (a, b) = (coarse.ray(row, col), full.ray(3.0 * row, 3.0 * col));
        assert!((a.at(10.0) - b.at(10.0)).norm() < 1e-9);
    }
}

#[test]
fn distortion_jacobian_matches_finite_differences() {
    let k = perspective().intrinsics.unwrap();
    let (row, col) = (3.0, 60.0);
    let j = k.jacobian(row, col);
    let e = 1e-4;
    let (xp, yp) = k.normalised(row, col + e);
    let (xm, ym) = k.normalised(row, col - e);
    let (xr, yr) = k.normalised(row + e, col);
    let (xs, ys) = k.normalised(row - e, col);
    let numeric = [
        [(xp - xm) / (2.0 * e), (xr - xs) / (2.0 * e)],
        [(yp - ym) / (2.0 * e), (yr - ys) / (2.0 * e)],
    ];
    for a in 0..2 {
        for b in 0..2 {
            assert!((j[a][b] - numeric[a][b]).abs() < 1e-9, "{j:?} {numeric:?}");
        }
    }
}

#[test]
fn perspective_rig_parses_and_bad_intrinsics_are_named() {
    let text = r#"
        [camera]
        width = 640
        height = 480
        fps = 960.0
        distance_mm = 420.0
        [camera.intrinsics]
        fx = 1500.0
        fy = 1500.0
        cx = 319.5
        cy = 239.5
        k1 = -0.1
        [[led]]
        position_mm = [-270.0, 420.0, 100.0]
    "#;
    let rig = Rig::from_toml_str(text, "test").unwrap();
    assert!(rig.camera.is_perspective());
    assert_eq!(rig.camera.intrinsics.unwrap().k2, 0.0);
    assert_eq!(Rig::from_toml_str(&rig.to_toml_string(), "x").unwrap(), rig);
    let with_fov = text.replace("fps = 960.0", "fps = 960.0\nfov_deg = 40.0");
    let err = Rig::from_toml_str(&with_fov, "x").unwrap_err().to_string();
    assert!(
        err.contains("camera.intrinsics") && err.contains("fov_deg"),
        "{err}"
    );
    let folded = text.replace("k1 = -0.1", "k1 = -4.0");
    let err = Rig::from_toml_str(&folded, "x").unwrap_err().to_string();
    assert!(err.contains("camera.intrinsics.k1"), "{err}");
    let zero = text.replace("fy = 1500.0", "fy = 0.0");
    let err = Rig::from_toml_str(&zero, "x").unwrap_err().to_string();
    assert!(err.contains("camera.intrinsics.fy"), "{err}");
}
