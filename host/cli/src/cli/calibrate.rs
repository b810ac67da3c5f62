//! `meb calibrate lights`: a rig's LED positions and relative intensities fitted to captures
//! of a matte sphere of known diameter ([`meb_pipeline::calibrate`]); `meb calibrate camera`
//! ([`super::calibrate_camera`]).

use super::decode::{DecodeOptions, decode_capture};
use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use meb_core::rig::Rig;
use meb_pipeline::calibrate::calibrate_lights;
use std::path::PathBuf;

/// Arguments of `meb calibrate`.
#[derive(Args)]
pub struct CalibrateArgs {
    #[command(subcommand)]
    command: CalibrateCommand,
}

#[derive(Subcommand)]
enum CalibrateCommand {
    /// Fit each LED's position and relative intensity to captures of a matte sphere of known
    /// diameter (several placements, spread across the view and in depth), starting from a
    /// nominal rig: writes rig.toml and calibration.json.
    Lights(Box<LightsArgs>),
    /// Fit the camera's intrinsics (fx, fy, cx, cy, k1, k2) to photos of a chequerboard:
    /// writes the rig with them (rig.toml) and calibration.json with the reprojection RMS.
    Camera(super::calibrate_camera::CameraArgs),
}

/// Arguments of `meb calibrate lights`.
#[derive(Args)]
struct LightsArgs {
    /// Captures of the sphere (frame folders, .y4m, video…), one per placement.
    #[arg(required = true)]
    captures: Vec<PathBuf>,
    /// The sphere's diameter, mm.
    #[arg(long)]
    sphere_mm: f64,
    /// The nominal rig (measured roughly): a TOML file or a preset.
    #[arg(long)]
    rig: String,
    /// Output folder (rig.toml, calibration.json), replaced whole and atomically.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
    /// Decoder settings.
    #[command(flatten)]
    decode: DecodeOptions,
}

/// Runs `meb calibrate`.
pub fn run(args: &CalibrateArgs) -> Result<()> {
    match &args.command {
        CalibrateCommand::Lights(lights) => run_lights(lights),
        CalibrateCommand::Camera(camera) => super::calibrate_camera::run(camera),
    }
}

fn run_lights(args: &LightsArgs) -> Result<()> {
    let folder = super::common::output_folder(&args.out, "calibrate lights", args.force)?;
    let nominal = Rig::load(&args.rig).with_context(|| format!("cannot load rig {}", args.rig))?;
    let mut decoded = Vec::with_capacity(args.captures.len());
    for capture in &args.captures {
        decoded.push(decode_capture(
            capture,
            &args.decode,
            nominal.leds.len(),
            false,
        )?);
    }
    let calibration = calibrate_lights(&decoded, &nominal, args.sphere_mm)?;
    let fit = &calibration.fit;
    for (c, sphere) in calibration.spheres.iter().enumerate() {
        println!(
            "sphere {}: centre ({:.1}, {:.1}) px, radius {:.1} px (free fit {:.1} px), rim RMS {:.2} px",
            c + 1,
            sphere.centre_px[0],
            sphere.centre_px[1],
            sphere.radius_px,
            sphere.free_radius_px,
            sphere.rim_rms_px
        );
    }
    println!("LED  position (mm)                      ± (mm)              moved   intensity   ±");
    for led in &fit.leds {
        let [x, y, z] = led.position_mm;
        let [sx, sy, sz] = led.position_se_mm;
        println!(
            "{:>3}  ({x:8.2}, {y:8.2}, {z:8.2})  ({sx:.2}, {sy:.2}, {sz:.2})  {:6.1} mm  {:.4}  {:.2} %",
            led.led,
            led.moved_mm,
            led.intensity,
            100.0 * led.intensity_se
        );
    }
    println!(
        "residual RMS {:.2} σ ({:.2} % of the mean reading) over {} readings, {} iterations",
        fit.rms_sigmas,
        100.0 * fit.rms_relative,
        fit.residuals,
        fit.iterations
    );
    let mut problems = Vec::new();
    if !fit.undetermined.is_empty() {
        problems.push(format!(
            "the captures do not determine {}",
            fit.undetermined.join("; ")
        ));
    }
    if fit.rms_relative > MAX_RESIDUAL {
        problems.push(format!(
            "the fitted model leaves {:.1} % of the readings unexplained (a matte sphere of the \
             given size under the rig's LEDs leaves ≤ {:.0} %): is the sphere matte, its \
             diameter right, and the nominal rig within a few cm?",
            100.0 * fit.rms_relative,
            100.0 * MAX_RESIDUAL
        ));
    }
    if !problems.is_empty() && !args.force {
        bail!(
            "calibration refused: {} (--force writes it anyway)",
            problems.join("; ")
        );
    }
    for problem in &problems {
        eprintln!("warning: written despite (--force): {problem}");
    }
    let rig = fit.rig.as_ref().context("the fit returned no rig")?;
    std::fs::write(folder.path().join("rig.toml"), rig.to_toml_string())
        .context("cannot write rig.toml")?;
    let json = serde_json::json!({
        "schema": "meb-calibration-lights",
        "version": 1,
        "nominal_rig": args.rig,
        "captures": args.captures.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "sphere_diameter_mm": args.sphere_mm,
        "frame": if rig.camera.is_perspective() {
            "camera model: every sphere's distance from its silhouette and known size"
        } else {
            "orthographic camera: the first sphere's centre lies at z = 0 (the rig's origin plane); the other spheres' heights are fitted"
        },
        "spheres": calibration.spheres,
        "fit": fit,
        "problems": problems,
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

/// Largest RMS residual of an accepted calibration, relative to the mean reading.
const MAX_RESIDUAL: f64 = 0.05;
