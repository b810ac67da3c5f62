//! `meb calibrate camera`: the rig camera's intrinsics (fx, fy, cx, cy, k1, k2) from photos of
//! a chequerboard ([`meb_pipeline::calibrate::camera`]), written into the rig file.

use super::tof::read_grey;
use anyhow::{Context, Result, ensure};
use clap::Args;
use meb_core::rig::Rig;
use meb_pipeline::calibrate::calibrate_camera;
use meb_pipeline::tof::chequerboard::{BoardSize, require_corner_detector};
use std::path::PathBuf;

/// A principal point standard error above this, pixels, is reported with what photos would
/// pin it down (ten photos tilted 20–55° give 0.4–0.9 px).
const PRINCIPAL_POINT_SE_PX: f64 = 1.0;

/// Arguments of `meb calibrate camera`.
#[derive(Args)]
pub struct CameraArgs {
    /// Photos of the board (PNG, TIFF, JPEG or 2-D .npy), taken in the camera mode the
    /// captures use (same size), at different tilts and across the whole image.
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Inner corners of the board, COLSxROWS (squares − 1 each way), e.g. 9x6.
    #[arg(long, value_parser = super::parse::board)]
    board: BoardSize,
    /// The board's square edge, mm.
    #[arg(long)]
    square_mm: f64,
    /// The rig whose camera took the photos (a TOML file or a preset): written to
    /// DIR/rig.toml with the fitted intrinsics, its LEDs unchanged.
    #[arg(long)]
    rig: String,
    /// Output folder (rig.toml, calibration.json), replaced whole and atomically.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
}

/// Runs `meb calibrate camera`.
pub fn run(args: &CameraArgs) -> Result<()> {
    require_corner_detector()?;
    let board = args.board;
    let folder = super::common::output_folder(&args.out, "calibrate camera", args.force)?;
    let mut rig = Rig::load(&args.rig).with_context(|| format!("cannot load rig {}", args.rig))?;
    let mut images = Vec::with_capacity(args.images.len());
    let names: Vec<String> = args
        .images
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    for (path, name) in args.images.iter().zip(&names) {
        let image = read_grey(path).with_context(|| format!("cannot read {name}"))?;
        ensure!(
            image.dim() == (rig.camera.height, rig.camera.width),
            "{name} is {}x{} but the rig's camera {}x{}: calibrate with photos in the mode the \
             captures use (a phone's stills are cropped and scaled differently from its video)",
            image.dim().1,
            image.dim().0,
            rig.camera.width,
            rig.camera.height
        );
        images.push(image);
    }
    let calibration = calibrate_camera(&images, &names, board, args.square_mm)?;
    let k = calibration.intrinsics;
    let se = calibration.standard_errors;
    println!(
        "fx {:.2} ± {:.2} px, fy {:.2} ± {:.2} px, cx {:.2} ± {:.2} px, cy {:.2} ± {:.2} px, \
         k1 {:.4} ± {:.4}, k2 {:.4} ± {:.4}",
        k.fx, se[0], k.fy, se[1], k.cx, se[2], k.cy, se[3], k.k1, se[4], k.k2, se[5]
    );
    println!(
        "reprojection RMS {:.3} px over {} photos (worst photo {:.3} px)",
        calibration.rms_px,
        images.len(),
        calibration.view_rms_px.iter().copied().fold(0.0, f64::max)
    );
    if se[2].max(se[3]) > PRINCIPAL_POINT_SE_PX {
        eprintln!(
            "note: the principal point is uncertain to ± {:.1} px (cx), ± {:.1} px (cy): add \
             photos with the board tilted 30–50° about different axes and filling more of the \
             image",
            se[2], se[3]
        );
    }
    // A pinhole camera takes its scale from the intrinsics, not a field of view or a pitch.
    rig.camera.intrinsics = Some(k);
    rig.camera.fov_deg = None;
    rig.camera.pixel_pitch_mm = None;
    rig.camera.axis_px = None;
    rig.validate()
        .context("the fitted intrinsics do not make a valid rig")?;
    std::fs::write(folder.path().join("rig.toml"), rig.to_toml_string())
        .context("cannot write rig.toml")?;
    let json = serde_json::json!({
        "schema": "meb-calibration-camera",
        "version": 1,
        "rig": args.rig,
        "images": names,
        "board": board,
        "square_mm": args.square_mm,
        "convention": "pixel coordinates with integer values at pixel centres; radial distortion r², r⁴ (OpenCV's k1, k2; p1 = p2 = k3 = 0)",
        "fit": calibration,
    });
    std::fs::write(
        folder.path().join("calibration.json"),
        serde_json::to_string_pretty(&json)?,
    )
    .context("cannot write calibration.json")?;
    let out = super::common::commit(folder)?;
    println!("rig: {}", out.join("rig.toml").display());
    Ok(())
}
