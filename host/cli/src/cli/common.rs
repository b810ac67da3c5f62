//! Helpers shared by the commands: mask loading, the atomic output folder with its `--force`
//! rule, and writing a reconstruction's folder.

use anyhow::{Context, Result};
use meb_cli::export::report::{ReportInputs, Summary, WrittenReport, write_report};
use meb_core::io::{FilesError, OutputFolder, Replace, read_mask, remove_temporaries_on_signal};
use meb_core::metrics::{AngularErrors, DepthErrors};
use meb_core::timing::StageTiming;
use meb_core::types::{Confidence, DepthMap, NormalField};
use meb_pipeline::reconstruct::acceptance;
use ndarray::Array2;
use std::path::Path;

/// Help text of every command's `--force` flag: one flag, one meaning.
pub const FORCE_HELP: &str = "Write even what meb would otherwise refuse: over a non-empty --out \
    that is not an earlier output of this command (its contents are replaced whole), or a \
    result meb judges implausible (written with the warning recorded)";

/// Reads a mask image (non-zero = inside) and checks it is not empty.
pub fn load_mask(path: &Path) -> Result<Array2<bool>> {
    let mask = read_mask(path)?;
    anyhow::ensure!(
        mask.iter().any(|&m| m),
        "empty mask: {} has no non-zero pixel",
        path.display()
    );
    Ok(mask)
}

/// Starts the atomic output folder `out` of `command` (see `meb_core::io::folder`):
/// refuses, before any work, a non-empty `out` that is not an earlier output of `command`
/// unless `force`. The first call installs the handler that deletes the temporary folder on
/// SIGINT/SIGTERM/SIGHUP (only commands that write folders get it: `meb device emulate`
/// handles SIGTERM itself).
pub fn output_folder(out: &Path, command: &str, force: bool) -> Result<OutputFolder> {
    static SIGNALS: std::sync::Once = std::sync::Once::new();
    SIGNALS.call_once(|| {
        if let Err(err) = remove_temporaries_on_signal() {
            eprintln!(
                "warning: cannot watch for interrupts ({err}); an interrupted run may leave a \
                 temporary folder, which the next run into the same folder removes"
            );
        }
    });
    let replace = if force {
        Replace::Anything
    } else {
        Replace::EarlierOutput
    };
    OutputFolder::create(out, command, replace).map_err(|e| match e {
        FilesError::OutputNotEmpty { .. } => {
            anyhow::anyhow!("{e}; choose another --out or pass --force to replace it")
        }
        e => e.into(),
    })
}

/// Moves a finished output folder into place and returns its final path.
pub fn commit(folder: OutputFolder) -> Result<std::path::PathBuf> {
    let target = folder.target().to_path_buf();
    folder
        .commit()
        .with_context(|| format!("cannot put the output in place at {}", target.display()))
}

/// Writes a reconstruction's files into `dir` and returns the report paths.
#[allow(clippy::too_many_arguments)]
pub fn write_outputs(
    dir: &Path,
    title: &str,
    source: String,
    normals: &NormalField,
    depth: &DepthMap,
    depth_errors: Option<&DepthErrors>,
    angular_errors: Option<&AngularErrors>,
    confidence: Option<&Array2<Confidence>>,
    timings: &[StageTiming],
    summary: Summary,
    mesh_formats: Vec<String>,
) -> Result<WrittenReport> {
    Ok(write_report(
        dir,
        &ReportInputs {
            title: title.to_string(),
            source,
            normals,
            depth,
            depth_errors,
            angular_errors,
            confidence,
            highlights: None,
            timings,
            summary,
            mesh_formats,
        },
    )?)
}

/// The report's name of an integrator, e.g. `least-squares`.
pub fn integrator_name(integrator: meb_pipeline::integrate::Integrator) -> String {
    serde_json::to_value(integrator)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_else(|| format!("{integrator:?}"))
}

/// The report's description of a light model.
pub fn light_model_name(model: meb_pipeline::reconstruct::LightModel) -> String {
    match model {
        meb_pipeline::reconstruct::LightModel::Distant => "distant (L_i(0))".into(),
        meb_pipeline::reconstruct::LightModel::NearField { refinements } => {
            format!("near-field ({refinements} refinements)")
        }
    }
}

/// Surface mesh formats written besides `surface.ply`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ (`surface.obj`).
    Obj,
    /// Binary STL (`surface.stl`).
    Stl,
}

/// The file extensions of `formats`.
pub fn mesh_extensions(formats: &[MeshFormat]) -> Vec<String> {
    formats
        .iter()
        .map(|f| match f {
            MeshFormat::Obj => "obj".to_string(),
            MeshFormat::Stl => "stl".to_string(),
        })
        .collect()
}

/// Refuses a reconstruction whose depth its support check ([`meb_pipeline::reconstruct::Support`])
/// finds implausible, saying what looks wrong and what to try, unless `force` (then warns);
/// `rig_hint` ([`super::rig::enforce`]) joins the refusal.
pub fn check_support(
    reconstruction: &meb_pipeline::reconstruct::Reconstruction,
    rig_hint: Option<&str>,
    force: bool,
) -> Result<()> {
    apply(acceptance::support(
        &reconstruction.support.verdict,
        rig_hint,
        force,
        "--force",
    ))
}

/// Prints a ruling's warning, or returns its refusal as the command's error.
pub fn apply(ruling: acceptance::Ruling) -> Result<()> {
    match ruling {
        acceptance::Ruling::Keep => Ok(()),
        acceptance::Ruling::Warn(warning) => {
            eprintln!("warning: {warning}");
            Ok(())
        }
        acceptance::Ruling::Refuse(refusal) => Err(anyhow::anyhow!(refusal)),
    }
}

/// The report summary every decoded-capture reconstruction shares: LED images, frames,
/// integrator, light model, object pixels, the artefact filter's share and the measured share
/// (with what its support check found, when kept by `--force`).
pub fn reconstruction_summary(
    decoded: &meb_pipeline::demod::Decoded,
    config: &meb_pipeline::reconstruct::ReconstructConfig,
    reconstruction: &meb_pipeline::reconstruct::Reconstruction,
) -> Summary {
    let mask = &reconstruction.photometric.field.mask;
    Summary {
        leds: Some(decoded.leds.images.len()),
        decoded_frames: Some(decoded.report.frames_used),
        integrator: Some(integrator_name(config.integrate.integrator)),
        light_model: Some(light_model_name(config.light_model)),
        object_pixels: Some(mask.iter().filter(|&&m| m).count()),
        kept_fraction: Some(reconstruction.integration.kept_fraction),
        integrator_choice: super::integrate::integrator_choice(&reconstruction.integration),
        measured_share: Some(reconstruction.support.measured_share),
        absolute_depth: Some(reconstruction.support.absolute_depth.describe()),
        implausible: reconstruction.support.verdict.problems.clone(),
        clipping: decoded.report.clipping.as_ref().map(|c| c.message.clone()),
        ..Summary::default()
    }
}
