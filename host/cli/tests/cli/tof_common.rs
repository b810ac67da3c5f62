//! Helpers shared by the ToF test files: the thesis-hybrid rig at a test size and rendered
//! chequerboard positions seen by both cameras.
#![allow(dead_code)] // each test binary uses a different subset

use meb_core::rig::{Rig, TofCamera};
use meb_pipeline::tof::calibration::BoardView;
use meb_pipeline::tof::chequerboard::{BoardSize, find_corners};
use meb_sim::tof::{
    Chequerboard, HybridScene, TofCapture, TofSimConfig, render_tof, thesis_hybrid_scene,
};
use nalgebra::Vector3;
use ndarray::Array2;

/// The board every test uses: 8×5 inner corners.
pub const BOARD: BoardSize = BoardSize { cols: 8, rows: 5 };

/// Heights (scene z, mm) of the two calibration boards, among the objects' depths (−165 to
/// +124 mm; thesis §6.4: calibrate where the objects are).
pub const BOARD_HEIGHTS: [f64; 2] = [100.0, -100.0];

/// The thesis-hybrid rig with its phone at 384×216 (pitch 0.75 mm).
pub fn rig() -> Rig {
    let mut rig = Rig::preset("thesis-hybrid").unwrap();
    rig.camera.pixel_pitch_mm = Some(rig.camera.pitch_mm() * 10.0 / 3.0);
    rig.camera.width = 384;
    rig.camera.height = 216;
    rig
}

/// An 8×5 board of 16 mm squares at height `z`, centred on the SPAD's axis, turned by 3°.
pub fn board(tof: &TofCamera, z: f64) -> Chequerboard {
    let c = Vector3::from(tof.position_mm);
    Chequerboard {
        cols: BOARD.cols,
        rows: BOARD.rows,
        square_mm: 16.0,
        origin_mm: [c.x * z / c.z - 3.5 * 16.0, 2.0 * 16.0],
        z_mm: z,
        angle_rad: 3f64.to_radians(),
    }
}

/// The board's images: the SPAD's photon counts (200 frames of 10 ms, ~400 counts on a white
/// square at 600 mm, thesis §6.2.1) and the phone's image (1 % noise).
pub fn board_images(rig: &Rig, board: &Chequerboard, seed: u64) -> (Array2<f32>, Array2<f32>) {
    let tof = rig.tof_camera.as_ref().unwrap();
    (
        board.tof_image(tof, 400.0, 600.0, seed),
        board.camera_image(&rig.camera, 0.01, seed),
    )
}

/// The ToF range (axial depth, mm) of the board's centre.
pub fn board_range(tof: &TofCamera, board: &Chequerboard) -> f64 {
    tof.project(&board.centre()).unwrap().2
}

/// Corners found in both images of the board, with its range.
pub fn board_view(rig: &Rig, board: &Chequerboard, seed: u64) -> BoardView {
    let (tof_image, camera_image) = board_images(rig, board, seed);
    BoardView {
        tof_corners: find_corners(&tof_image, BOARD, "ToF").unwrap(),
        camera_corners: find_corners(&camera_image, BOARD, "camera").unwrap(),
        range_mm: Some(board_range(rig.tof_camera.as_ref().unwrap(), board)),
    }
}

/// The thesis' hybrid scene and its SPAD capture at the thesis' settings (photons of `seed`).
pub fn hybrid_capture(tof: &TofCamera, seed: u64) -> (HybridScene, TofCapture) {
    let hybrid = thesis_hybrid_scene();
    let config = TofSimConfig {
        seed,
        ..TofSimConfig::default()
    };
    let capture = render_tof(&hybrid.scene, &hybrid.groups, tof, &config).unwrap();
    (hybrid, capture)
}
