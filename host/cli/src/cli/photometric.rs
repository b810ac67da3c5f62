//! `meb photometric`: photometric stereo on any image set with known lights (or DiLiGenT).

use anyhow::{Context, Result};
use clap::Args;
use meb_cli::export::report::Summary;
use meb_core::datasets::diligent::{ImageSet, load_diligent, load_image_set};
use meb_core::metrics::compare_normals;
use meb_core::timing::StageTiming;
use meb_pipeline::integrate::{IntegrateConfig, SurfaceEvidence, integrate_surface};
use meb_pipeline::photometric::{Lights, PhotometricConfig, estimate_normals};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `meb photometric`.
#[derive(Args, Debug)]
pub struct PhotometricArgs {
    /// Images, one per light (8/16-bit grey or RGB PNG/TIFF/…).
    #[arg(long, num_args = 3.., conflicts_with = "diligent")]
    pub images: Vec<PathBuf>,
    /// Light vectors, one "x y z" row per image (x right, y up, z towards the camera).
    #[arg(long, required_unless_present = "diligent")]
    pub lights: Option<PathBuf>,
    /// Light intensities, one "r g b" (or one value) row per image.
    #[arg(long)]
    pub intensities: Option<PathBuf>,
    /// Object mask image (non-zero = object); found automatically when absent.
    #[arg(long)]
    pub mask: Option<PathBuf>,
    /// A DiLiGenT object folder instead of --images/--lights.
    #[arg(long)]
    pub diligent: Option<PathBuf>,
    /// The camera for the depth output: --pitch (orthographic, mm per pixel; 1 when no camera is
    /// given), --intrinsics with --distance, or --rig.
    #[command(flatten)]
    pub camera: super::camera::CameraArgs,
    /// Integrator.
    #[arg(long, value_enum, default_value = "auto")]
    pub integrator: super::integrate::IntegratorArg,
    /// Output folder, replaced whole and atomically.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
}

/// Runs `meb photometric`.
pub fn run(args: &PhotometricArgs) -> Result<()> {
    let folder = super::common::output_folder(&args.out, "photometric", args.force)?;
    let mut set: ImageSet = match &args.diligent {
        Some(dir) => load_diligent(dir)?,
        None => {
            let lights = args.lights.as_ref().context("--lights is required")?;
            anyhow::ensure!(
                args.images.len() >= 3,
                "photometric stereo needs at least 3 images"
            );
            load_image_set(&args.images, lights, args.intensities.as_deref(), None)?
        }
    };
    if let Some(m) = &args.mask {
        set.mask = Some(super::common::load_mask(m)?);
    }
    let start = Instant::now();
    let ps = estimate_normals(
        &set.images,
        &Lights::Distant(set.lights.clone()),
        set.mask.as_ref(),
        None,
        &PhotometricConfig::default(),
    )?;
    let mut timings = vec![StageTiming::since("photometric stereo", start)];
    let start = Instant::now();
    let camera = args.camera.choose(ps.field.mask.dim(), Some(1.0))?;
    let config = IntegrateConfig {
        integrator: args.integrator.into(),
        ..IntegrateConfig::default()
    };
    let evidence = SurfaceEvidence {
        field: &ps.field,
        planes: &[],
        fill: None,
    };
    let integration = integrate_surface(&evidence, &camera.projection, &config, None)?;
    timings.push(StageTiming::since("integration", start));
    let angular = match (&set.normals_gt, &set.mask) {
        (Some(gt), Some(mask)) => Some(compare_normals(&ps.field.normals, gt, mask)?),
        _ => None,
    };
    let summary = Summary {
        input: args.diligent.as_ref().map(|d| d.display().to_string()),
        leds: Some(set.lights.len()),
        integrator: Some(super::common::integrator_name(config.integrator)),
        integrator_choice: super::integrate::integrator_choice(&integration),
        camera: Some(camera.describe),
        depth_convention: Some(camera.depth_convention),
        light_model: Some("distant (given light vectors)".into()),
        object_pixels: Some(ps.field.mask.iter().filter(|&&m| m).count()),
        kept_fraction: Some(integration.kept_fraction),
        ..Summary::default()
    };
    super::common::write_outputs(
        folder.path(),
        "meb photometric",
        args.diligent.as_ref().map_or_else(
            || format!("{} images", args.images.len()),
            |d| d.display().to_string(),
        ),
        &ps.field,
        &integration.depth,
        None,
        angular.as_ref(),
        Some(&integration.confidence),
        &timings,
        summary,
        vec![],
    )?;
    let out = super::common::commit(folder)?;
    if let Some(a) = &angular {
        println!(
            "normal error vs ground truth: mean {:.2}°, median {:.2}° over {} pixels",
            a.mean_deg, a.median_deg, a.compared_pixels
        );
    }
    println!("report: {}", out.join("report.html").display());
    Ok(())
}
