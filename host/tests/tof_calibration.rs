//! Two-camera calibration from rendered chequerboards (thesis §6.4): corners found by OpenCV in
//! the SPAD's photon-counting image and the phone's image, a homography per board position,
//! interpolated in range between two positions.

use meb::rig::{Rig, TofCamera};
use meb::simulate::tof::Chequerboard;
use meb::tof::calibration::{BoardView, Calibration, apply};
use meb::tof::chequerboard::{BoardSize, find_corners};
use nalgebra::Vector3;

/// The thesis-hybrid rig with its phone at 384×216 (pitch 0.75 mm).
fn rig() -> Rig {
    let mut rig = Rig::preset("thesis-hybrid").unwrap();
    rig.camera.pixel_pitch_mm = Some(rig.camera.pitch_mm() * 10.0 / 3.0);
    rig.camera.width = 384;
    rig.camera.height = 216;
    rig
}

/// A 8×5 board of 16 mm squares at height `z`, centred on the SPAD's axis, turned by 3°.
fn board(tof: &TofCamera, z: f64) -> Chequerboard {
    let c = Vector3::from(tof.position_mm);
    let axis_x = c.x * z / c.z;
    Chequerboard {
        cols: 8,
        rows: 5,
        square_mm: 16.0,
        origin_mm: [axis_x - 3.5 * 16.0, 2.0 * 16.0],
        z_mm: z,
        angle_rad: 3f64.to_radians(),
    }
}

fn view(rig: &Rig, board: &Chequerboard, seed: u64) -> (BoardView, nalgebra::Matrix3<f64>) {
    let tof = rig.tof_camera.as_ref().unwrap();
    let size = BoardSize { cols: board.cols, rows: board.rows };
    let camera_image = board.camera_image(&rig.camera, 0.01, seed);
    // Photon counting: 200 frames of 10 ms, ~400 counts on a white square at 600 mm.
    let tof_image = board.tof_image(tof, 400.0, 600.0, seed);
    let camera_corners = find_corners(&camera_image, size, "camera").unwrap();
    let tof_corners = find_corners(&tof_image, size, "ToF").unwrap();
    let range = tof.project(&board.centre()).unwrap().2;
    (
        BoardView {
            tof_corners,
            camera_corners,
            range_mm: Some(range),
        },
        board.truth_homography(tof, &rig.camera),
    )
}

/// Largest distance (camera px) between the fitted and the true mapping of the board's area.
fn worst_over_board(cal: &Calibration, truth: &nalgebra::Matrix3<f64>, corners: &[[f64; 2]], range: Option<f64>) -> f64 {
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for c in corners {
        for k in 0..2 {
            lo[k] = lo[k].min(c[k]);
            hi[k] = hi[k].max(c[k]);
        }
    }
    let mut worst: f64 = 0.0;
    for i in 0..=20 {
        for j in 0..=20 {
            let p = [
                lo[0] + (hi[0] - lo[0]) * i as f64 / 20.0,
                lo[1] + (hi[1] - lo[1]) * j as f64 / 20.0,
            ];
            let a = cal.tof_to_camera(p, range);
            let b = apply(truth, p);
            worst = worst.max((a[0] - b[0]).hypot(a[1] - b[1]));
        }
    }
    worst
}

#[test]
fn recovers_the_true_homography_of_each_board_within_half_a_camera_pixel() {
    let rig = rig();
    let tof = rig.tof_camera.clone().unwrap();
    let size = BoardSize { cols: 8, rows: 5 };
    for (k, z) in [100.0, -100.0].into_iter().enumerate() {
        let (view, truth) = view(&rig, &board(&tof, z), k as u64);
        let corners = view.tof_corners.clone();
        let cal = Calibration::fit(&[view], [tof.width, tof.height], [rig.camera.width, rig.camera.height], size, Some(16.0))
            .unwrap();
        let worst = worst_over_board(&cal, &truth, &corners, None);
        eprintln!(
            "board at z = {z}: corner RMS {:.3} px, worst {:.3} px; fitted vs true homography over the board: worst {worst:.3} camera px",
            cal.planes[0].rms_px, cal.planes[0].max_px
        );
        assert!(cal.planes[0].rms_px <= 0.5, "{}", cal.planes[0].rms_px);
        assert!(worst <= 0.5, "worst {worst} camera px");
    }
}

/// Two board positions interpolated in range map points of the three objects' depths (z from
/// −165 to +124 mm) into the camera within a camera pixel.
#[test]
fn two_boards_map_every_object_depth() {
    let rig = rig();
    let tof = rig.tof_camera.clone().unwrap();
    let (near, _) = view(&rig, &board(&tof, 100.0), 1);
    let (far, _) = view(&rig, &board(&tof, -100.0), 2);
    let cal = Calibration::fit(
        &[near, far],
        [tof.width, tof.height],
        [rig.camera.width, rig.camera.height],
        BoardSize { cols: 8, rows: 5 },
        Some(16.0),
    )
    .unwrap();
    let text = cal.to_toml_string();
    assert!(text.contains("range_mm"), "{text}");
    let mut worst: f64 = 0.0;
    for z in [-165.0, -100.0, -40.0, 0.0, 60.0, 124.0] {
        for x in [-90.0, -30.0, 0.0, 40.0, 100.0] {
            for y in [-60.0, 0.0, 50.0] {
                let point = Vector3::new(x, y, z);
                let (row, col, s) = tof.project(&point).unwrap();
                let (r, c) = rig.camera.xy_to_pixel(x, y);
                let mapped = cal.tof_to_camera([col, row], Some(s));
                worst = worst.max((mapped[0] - c).hypot(mapped[1] - r));
            }
        }
    }
    eprintln!("two-plane calibration: worst mapping error {worst:.3} camera px over z −165..124 mm");
    assert!(worst < 1.0, "{worst}");
}

#[test]
fn blank_images_and_mismatched_sizes_are_refused() {
    let rig = rig();
    let tof = rig.tof_camera.clone().unwrap();
    let size = BoardSize { cols: 8, rows: 5 };
    let blank = ndarray::Array2::from_elem((tof.height, tof.width), 3.0f32);
    let err = find_corners(&blank, size, "ToF").unwrap_err().to_string();
    assert!(err.contains("ToF") && err.contains("8x5"), "{err}");
    let (view, _) = view(&rig, &board(&tof, 100.0), 3);
    let cal = Calibration::fit(&[view], [tof.width, tof.height], [rig.camera.width, rig.camera.height], size, None).unwrap();
    let err = cal.check_sizes([tof.width, tof.height], [1280, 720]).unwrap_err().to_string();
    assert!(err.contains("384x216") && err.contains("1280x720"), "{err}");
}
