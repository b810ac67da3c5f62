//! The time-of-flight side of `meb simulate --tof` (thesis Ch. 6): the rig's SPAD camera
//! records reverse-mode TCSPC histograms of the scene and of the reference board, and both
//! cameras see chequerboards for `meb tof calibrate`. The reference is the whole board as every
//! pixel sees it (H×W×bins, [`meb_sim::tof::TofCapture::reference_pixels`]), which
//! `meb tof range` pools into one on-axis reference (each pixel moved back by D·(1/cos θ − 1),
//! [`meb_pipeline::tof::estimate_range`]): the photon noise of a few central pixels would be a timing
//! error shared by every range (about 2 mm on the thesis capture). Written into `tof/` of the capture folder,
//! with `tof.json` holding the settings, the boards' ranges and the commands that use them.

use anyhow::{Context, Result, ensure};
use meb_core::io::{FilesError, write_npy};
use meb_core::rig::{Rig, TofCamera};
use meb_sim::Scene;
use meb_sim::tof::{Chequerboard, TofSimConfig, camera_labels, render_tof};
use nalgebra::Vector3;
use std::path::Path;

/// Inner corners of the calibration board, columns × rows.
pub const BOARD_CORNERS: (usize, usize) = (8, 5);
/// Square size of the calibration board, mm.
pub const BOARD_SQUARE_MM: f64 = 16.0;
/// Heights (scene z, mm) of the calibration boards: among the depths of the thesis-hybrid
/// scene's objects (thesis §6.4: calibrate where the objects are).
pub const BOARD_HEIGHTS_MM: [f64; 2] = [100.0, -100.0];
/// Mean photon counts on a white square at the reference distance in a board's SPAD image
/// (thesis §6.2.1: 200 frames of 10 ms).
const BOARD_PHOTONS: f64 = 400.0;
/// Read noise σ of the camera's board images (fraction of full scale).
const BOARD_NOISE: f64 = 0.01;

/// What the SPAD side of a simulated capture was rendered with.
pub struct TofSettings<'a> {
    /// The scene (analytic shapes only).
    pub scene: &'a Scene,
    /// Object group of each scene object.
    pub groups: &'a [usize],
    /// Name of each group.
    pub names: &'a [String],
    /// TCSPC exposures per histogram.
    pub frames: usize,
    /// Seed of the photon noise.
    pub seed: u64,
}

/// One calibration board in `tof.json`.
#[derive(serde::Serialize)]
struct BoardFiles {
    tof: String,
    camera: String,
    /// ToF range (axial depth) of the board's centre, mm: `meb tof calibrate --range-mm`.
    range_mm: f64,
    z_mm: f64,
}

/// Contents of `tof.json`.
#[derive(serde::Serialize)]
struct TofFile<'a> {
    histograms: &'static str,
    reference: &'static str,
    truth_range: &'static str,
    camera_labels: &'static str,
    objects: &'a [String],
    board: String,
    square_mm: f64,
    boards: Vec<BoardFiles>,
    settings: &'a TofSimConfig,
    commands: Vec<String>,
}

/// A board of [`BOARD_CORNERS`] at height `z_mm`, centred on the SPAD's line of sight, turned
/// by 3° (so that its rows are not aligned with either camera's).
fn board(tof: &TofCamera, z_mm: f64) -> Chequerboard {
    let c = Vector3::from(tof.position_mm);
    let (cols, rows) = BOARD_CORNERS;
    Chequerboard {
        cols,
        rows,
        square_mm: BOARD_SQUARE_MM,
        origin_mm: [
            c.x * z_mm / c.z - 0.5 * (cols - 1) as f64 * BOARD_SQUARE_MM,
            0.5 * (rows - 1) as f64 * BOARD_SQUARE_MM,
        ],
        z_mm,
        angle_rad: 3f64.to_radians(),
    }
}

/// Renders the SPAD side of `settings` for `rig` into `dir/tof/` (module docs); `capture` is
/// the capture folder's final path, used in the commands `tof.json` suggests. Returns the
/// boards' ranges.
pub fn write_tof(
    dir: &Path,
    capture: &Path,
    rig: &Rig,
    settings: &TofSettings,
) -> Result<Vec<f64>> {
    let tof = rig.tof_camera.as_ref().context(
        "--tof needs a rig with a [tof_camera] (the SPAD's pose, size and field of view), e.g. --rig thesis-hybrid",
    )?;
    let config = TofSimConfig {
        frames: settings.frames,
        seed: settings.seed,
        ..TofSimConfig::default()
    };
    let capture_tof = render_tof(settings.scene, settings.groups, tof, &config)?;
    let out = dir.join("tof");
    std::fs::create_dir_all(&out).map_err(|e| FilesError::write(&out, e))?;
    write_npy(&out.join("histograms.npy"), &capture_tof.histograms)?;
    write_npy(&out.join("reference.npy"), &capture_tof.reference_pixels)?;
    write_npy(&out.join("truth_range.npy"), &capture_tof.truth_range_mm)?;
    let labels = camera_labels(settings.scene, settings.groups, &rig.camera);
    write_npy(&dir.join("object_labels.npy"), &labels)?;
    let mut boards = Vec::new();
    for (k, z) in BOARD_HEIGHTS_MM.into_iter().enumerate() {
        let b = board(tof, z);
        let seed = settings.seed.wrapping_add(k as u64);
        let (tof_file, camera_file) = (
            format!("board_{}_tof.npy", k + 1),
            format!("board_{}_camera.npy", k + 1),
        );
        write_npy(
            &out.join(&tof_file),
            &b.tof_image(tof, BOARD_PHOTONS, config.reference_distance_mm, seed),
        )?;
        write_npy(
            &out.join(&camera_file),
            &b.camera_image(&rig.camera, BOARD_NOISE, seed),
        )?;
        let (_, _, range_mm) = tof
            .project(&b.centre())
            .context("a calibration board is behind the ToF camera")?;
        ensure!(
            range_mm.is_finite() && range_mm > 0.0,
            "calibration board {} has no range in the ToF camera",
            k + 1
        );
        boards.push(BoardFiles {
            tof: tof_file,
            camera: camera_file,
            range_mm: (range_mm * 10.0).round() / 10.0,
            z_mm: z,
        });
    }
    let ranges: Vec<f64> = boards.iter().map(|b| b.range_mm).collect();
    let file = TofFile {
        histograms: "histograms.npy",
        reference: "reference.npy",
        truth_range: "truth_range.npy",
        camera_labels: "../object_labels.npy",
        objects: settings.names,
        board: format!("{}x{}", BOARD_CORNERS.0, BOARD_CORNERS.1),
        square_mm: BOARD_SQUARE_MM,
        commands: commands(capture, tof, &config, &boards),
        boards,
        settings: &config,
    };
    let json = out.join("tof.json");
    let text = serde_json::to_string_pretty(&file)?;
    std::fs::write(&json, text).map_err(|e| FilesError::write(&json, e))?;
    Ok(ranges)
}

/// The `meb tof range`, `meb tof calibrate` and `meb reconstruct --tof` commands for the
/// capture folder `capture`.
fn commands(
    capture: &Path,
    tof: &TofCamera,
    config: &TofSimConfig,
    boards: &[BoardFiles],
) -> Vec<String> {
    let c = capture.display();
    let list = |pick: &dyn Fn(&BoardFiles) -> String| {
        boards.iter().map(pick).collect::<Vec<_>>().join(",")
    };
    vec![
        format!(
            "meb tof range {c}/tof/histograms.npy --reference {c}/tof/reference.npy --reference-mm {} --bin-ps {} --fov-deg {} --out range",
            config.reference_distance_mm, config.bin_ps, tof.fov_deg
        ),
        format!(
            "meb tof calibrate --tof {} --camera {} --board {}x{} --square-mm {} --range-mm {} --out calibration",
            list(&|b| format!("{c}/tof/{}", b.tof)),
            list(&|b| format!("{c}/tof/{}", b.camera)),
            BOARD_CORNERS.0,
            BOARD_CORNERS.1,
            BOARD_SQUARE_MM,
            list(&|b| format!("{}", b.range_mm)),
        ),
        format!(
            "meb reconstruct {c} --rig {c}/rig.toml --tof range --calibration calibration --ground-truth {c}/depth.npy --truth-labels {c}/object_labels.npy --out hybrid"
        ),
    ]
}
