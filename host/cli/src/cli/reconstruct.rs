//! `meb reconstruct`: a capture (decoded on the fly) or a `meb decode` folder + a rig →
//! normals, albedo, depth, mesh and report (docs/maths/photometric-stereo.md#the-near-field-loop),
//! optionally compared with ground truth;
//! with `--tof`, per object placed at and fused with a ToF range map ([`super::hybrid`]).

use super::decode::{DecodeOptions, check_folder_verdict, decode_capture};
use super::integrate::IntegratorArg;
use super::truth::{Inputs, compare, load_truth};
use anyhow::{Context, Result, ensure};
use clap::Args;
use meb_cli::export::report::Summary;
use meb_core::metrics::{AngularErrors, DepthErrors};
use meb_core::rig::Rig;
use meb_pipeline::demod::Decoded;
use meb_pipeline::demod::output::read_decode_dir;
use meb_pipeline::photometric::highlights::HighlightShares;
use meb_pipeline::reconstruct::{
    AbsoluteDepth, LightModel, ReconstructConfig, Reconstruction, Request, Source,
    check_decoded_rig, reconstruct,
};
use std::path::PathBuf;

/// Arguments of `meb reconstruct`.
#[derive(Args)]
pub struct ReconstructArgs {
    /// A capture (frame folder, TIFF, .y4m, raw or video: decoded first) or a `meb decode`
    /// output folder (recognised by its decode.json).
    input: PathBuf,
    /// Rig: a TOML file or a preset (thesis-in-plane, thesis-out-of-plane, thesis-dynamic,
    /// thesis-hybrid).
    #[arg(long)]
    rig: String,
    /// Output folder (normals.npy, albedo.npy, depth.npy, mask.png, previews, surface.ply,
    /// report.json, report.html), replaced whole and atomically.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
    /// Also write the surface in these formats (comma-separated): obj, stl.
    #[arg(long, value_enum, value_delimiter = ',')]
    mesh: Vec<super::common::MeshFormat>,
    /// Normal integrator.
    #[arg(long, value_enum, default_value = "least-squares")]
    integrator: IntegratorArg,
    /// Object mask image (non-zero = object), same size as the images; found automatically
    /// when absent.
    #[arg(long, conflicts_with = "tof")]
    mask: Option<PathBuf>,
    /// Hybrid reconstruction (thesis Ch. 6): a `meb tof range` folder. Every object the range
    /// map separates is reconstructed in its own mask, placed at its absolute ToF depth and
    /// fused with it (one folder per object and objects.json); needs --calibration and a rig
    /// with a `[tof_camera]` table.
    #[arg(long, requires = "calibration")]
    tof: Option<PathBuf>,
    /// With --tof: the `meb tof calibrate` folder (or its calibration.toml).
    #[arg(long, requires = "tof")]
    calibration: Option<PathBuf>,
    /// With --tof and --ground-truth: the camera's object labels (H×W int32 .npy, −1 =
    /// background; `meb simulate --tof` writes object_labels.npy): each object's absolute
    /// error is measured on the truth object its mask overlaps most.
    #[arg(long, requires_all = ["tof", "ground_truth"])]
    truth_labels: Option<PathBuf>,
    /// Ground truth: a depth map (H×W .npy, mm, NaN = background) or a mesh (.stl/.obj, mm,
    /// rendered in the rig's camera).
    #[arg(long)]
    ground_truth: Option<PathBuf>,
    /// Use distant light vectors L_i(0) (the thesis' model) instead of near-field refinement.
    #[arg(long)]
    no_near_field: bool,
    /// Decoder settings (only used when INPUT is a capture).
    #[command(flatten)]
    decode: DecodeOptions,
}

/// Runs `meb reconstruct`: read and check the inputs, reconstruct, compare with the truth,
/// write the folder, print a summary.
pub fn run(args: &ReconstructArgs) -> Result<()> {
    let folder = super::common::output_folder(&args.out, "reconstruct", args.force)?;
    let tof = match (&args.tof, &args.calibration) {
        (Some(range), Some(calibration)) => Some(super::hybrid::TofInputs::load(
            range,
            calibration,
            args.truth_labels.as_deref(),
        )?),
        _ => None,
    };
    let inputs = read_inputs(args)?;
    let config = reconstruct_config(args);
    if let Some(tof) = &tof {
        let report = super::hybrid::ObjectReport {
            inputs: &inputs,
            config: &config,
            summary: Summary {
                input: Some(args.input.display().to_string()),
                rig: Some(args.rig.clone()),
                ground_truth: args.ground_truth.as_ref().map(|p| p.display().to_string()),
                ..Summary::default()
            },
            source: source_text(args, &inputs),
            mesh_formats: super::common::mesh_extensions(&args.mesh),
        };
        let lines = super::hybrid::run(folder.path(), tof, &report)?;
        let out = super::common::commit(folder)?;
        for line in lines {
            println!("{line}");
        }
        println!("objects: {}", out.join("objects.json").display());
        return Ok(());
    }
    let reconstruction = reconstruct(
        Source::Decoded(&inputs.decoded),
        &inputs.rig,
        &config,
        Request {
            mask: inputs.mask.as_ref(),
            ..Request::default()
        },
    )?;
    let rig_check = check_decoded_rig(&inputs.decoded, &inputs.rig, &reconstruction, &config);
    let implausible = !reconstruction.support.verdict.is_plausible();
    let rig_hint = super::rig::enforce(&rig_check, &args.rig, args.force, implausible)?;
    super::common::check_support(&reconstruction, rig_hint.as_deref(), args.force)?;
    if let Some(clipping) = &inputs.decoded.report.clipping {
        eprintln!("note: {}", clipping.message);
    }
    let field = &reconstruction.photometric.field;
    let depth = &reconstruction.integration.depth;
    let (depth_errors, angular_errors) = match &inputs.truth {
        Some(t) => compare(t, field, &depth.depth_mm)?,
        None => (None, None),
    };
    meb_cli::export::report::write_report(
        folder.path(),
        &meb_cli::export::report::ReportInputs {
            title: "meb reconstruct".to_string(),
            source: source_text(args, &inputs),
            normals: field,
            depth,
            depth_errors: depth_errors.as_ref(),
            angular_errors: angular_errors.as_ref(),
            confidence: Some(reconstruction.confidence()),
            highlights: Some(&reconstruction.photometric.highlights),
            timings: &reconstruction.timings,
            summary: Summary {
                rig_check: serde_json::to_value(&rig_check).ok(),
                ..summary(args, &inputs, &config, &reconstruction)
            },
            mesh_formats: super::common::mesh_extensions(&args.mesh),
        },
    )?;
    let out = super::common::commit(folder)?;
    print_summary(
        &reconstruction,
        depth_errors.as_ref(),
        angular_errors.as_ref(),
    );
    println!("report: {}", out.join("report.html").display());
    Ok(())
}

/// Loads the rig, decodes or reads the capture, loads mask and truth, and checks that their
/// sizes agree.
fn read_inputs(args: &ReconstructArgs) -> Result<Inputs> {
    let rig = Rig::load(&args.rig).with_context(|| format!("cannot load rig {}", args.rig))?;
    ensure!(
        rig.leds.len() >= 3,
        "photometric stereo needs at least 3 LEDs, rig {} has {}",
        args.rig,
        rig.leds.len()
    );
    let from_folder = args.input.join("decode.json").is_file();
    let decoded: Decoded = if from_folder {
        let decoded = read_decode_dir(&args.input)?;
        check_folder_verdict(&decoded.report, &args.input, args.force)?;
        decoded
    } else {
        decode_capture(&args.input, &args.decode, rig.leds.len(), args.force)?
    };
    let leds = decoded.leds.images.len();
    ensure!(
        leds == rig.leds.len(),
        "rig {} has {} LEDs but {} has {leds} LED images",
        args.rig,
        rig.leds.len(),
        args.input.display()
    );
    let shape = decoded
        .leds
        .shape()
        .context("the decoded input holds no LED image")?;
    let camera = (rig.camera.height, rig.camera.width);
    ensure!(
        camera == shape,
        "rig camera is {}x{} but the images are {}x{} (cropped with --roi? use a rig of the crop's size)",
        camera.1,
        camera.0,
        shape.1,
        shape.0
    );
    let mask = match &args.mask {
        Some(path) => {
            let mask = super::common::load_mask(path)?;
            ensure!(
                mask.dim() == shape,
                "mask {} is {}x{} but the images are {}x{}",
                path.display(),
                mask.dim().1,
                mask.dim().0,
                shape.1,
                shape.0
            );
            Some(mask)
        }
        None => None,
    };
    let truth = args
        .ground_truth
        .as_deref()
        .map(|path| load_truth(path, &rig, shape))
        .transpose()?;
    Ok(Inputs {
        rig,
        decoded,
        from_folder,
        mask,
        truth,
    })
}

/// The decoded-capture settings with the command line's integrator and light model.
fn reconstruct_config(args: &ReconstructArgs) -> ReconstructConfig {
    let mut config = ReconstructConfig::decoded_capture();
    config.integrate.integrator = args.integrator.into();
    if args.no_near_field {
        config.light_model = LightModel::Distant;
    }
    config
}

/// Where the data came from, for the report.
fn source_text(args: &ReconstructArgs, inputs: &Inputs) -> String {
    if inputs.from_folder {
        format!("decode folder {}", args.input.display())
    } else {
        format!("capture {}, decoded with meb demod", args.input.display())
    }
}

/// The report's summary figures.
fn summary(
    args: &ReconstructArgs,
    inputs: &Inputs,
    config: &ReconstructConfig,
    reconstruction: &Reconstruction,
) -> Summary {
    Summary {
        input: Some(args.input.display().to_string()),
        rig: Some(args.rig.clone()),
        ground_truth: args.ground_truth.as_ref().map(|p| p.display().to_string()),
        highlights: Some(HighlightShares::of(&reconstruction.photometric)),
        ..super::common::reconstruction_summary(&inputs.decoded, config, reconstruction)
    }
}

/// Prints what was reconstructed and, with ground truth, how well.
fn print_summary(
    reconstruction: &Reconstruction,
    depth_errors: Option<&DepthErrors>,
    angular_errors: Option<&AngularErrors>,
) {
    let field = &reconstruction.photometric.field;
    let (rows, cols) = field.mask.dim();
    let total_ms: f64 = reconstruction.timings.iter().map(|t| t.ms).sum();
    println!(
        "reconstructed {} pixels ({cols}x{rows}) in {:.1} s, {:.1} % kept",
        field.mask.iter().filter(|&&m| m).count(),
        total_ms / 1e3,
        100.0 * reconstruction.integration.kept_fraction
    );
    if let Some(e) = depth_errors {
        println!(
            "depth RMSE {:.3} mm, NRMSE {}, surface reconstructed {:.1} %",
            e.rmse_mm,
            e.nrmse.map_or_else(
                || "n/a (flat truth)".to_string(),
                |n| format!("{:.2} %", 100.0 * n)
            ),
            100.0 * e.reconstructed_fraction
        );
    }
    if let Some(a) = angular_errors {
        println!(
            "normal error mean {:.2}°, median {:.2}° over {} pixels",
            a.mean_deg, a.median_deg, a.compared_pixels
        );
    }
    let absolute = reconstruction.support.absolute_depth;
    if matches!(absolute, AbsoluteDepth::Unmeasured { .. }) {
        eprintln!(
            "warning: the depth's distance from the camera is {}",
            absolute.describe()
        );
    }
}
