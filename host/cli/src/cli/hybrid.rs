//! `meb reconstruct --tof DIR --calibration C`: the hybrid reconstruction of thesis Ch. 6 from a
//! decoded capture. The range map separates the objects, photometric stereo reconstructs each
//! inside its own mask, and each is placed at its absolute ToF depth and fused with it. The
//! fusion follows Nehab, Rusinkiewicz, Davis & Ramamoorthi, "Efficiently combining positions and
//! normals for precise 3D geometry", SIGGRAPH 2005 ([`meb_pipeline::tof::hybrid::reconstruct_objects`]).
//! It gets the LED images and their noise exactly as [`meb_pipeline::reconstruct::reconstruct`] gives
//! them to the plain command. Writes one folder per object and `objects.json` with a row per
//! object.

use anyhow::{Context, Result, bail, ensure};
use meb_cli::export::report::Summary;
use meb_core::io::{preview, read_exact, write_mask, write_npy};
use meb_pipeline::reconstruct::{ReconstructConfig, level_noise, usable_led_images};
use meb_pipeline::tof::hybrid::{
    HybridConfig, HybridObject, HybridReconstruction, reconstruct_objects,
};
use meb_pipeline::tof::{Calibration, RangeMap, read_range_folder};
use ndarray::{Array2, Ix2};
use std::path::Path;

/// What the hybrid reconstruction needs besides the plain command's inputs, read before any
/// work so that a bad folder is refused at once.
pub struct TofInputs {
    /// The range map.
    range: RangeMap,
    /// The ToF → camera calibration.
    calibration: Calibration,
    /// Per-pixel object labels of the ground truth (−1: background).
    truth_labels: Option<Array2<i32>>,
    /// Where they came from, for messages.
    origin: String,
}

impl TofInputs {
    /// Reads the `meb tof range` folder, the calibration (folder or file) and the optional
    /// truth labels.
    pub fn load(range: &Path, calibration: &Path, truth_labels: Option<&Path>) -> Result<Self> {
        let truth_labels = truth_labels
            .map(|path| {
                read_exact::<i32, Ix2>(path, &[None, None]).with_context(|| {
                    format!(
                        "--truth-labels {}: expected the camera's object labels (H×W int32 .npy, −1 = background)",
                        path.display()
                    )
                })
            })
            .transpose()?;
        Ok(Self {
            range: read_range_folder(range)?,
            calibration: super::tof::load_calibration(calibration)?,
            truth_labels,
            origin: format!(
                "--tof {} and --calibration {}",
                range.display(),
                calibration.display()
            ),
        })
    }
}

/// One object's row of `objects.json`.
#[derive(serde::Serialize)]
struct ObjectRow {
    /// 1-based, nearest first.
    object: usize,
    /// Its folder in the output.
    folder: String,
    /// Camera pixels of its mask.
    pixels: usize,
    /// Pixels with a fused depth.
    reconstructed_pixels: usize,
    /// ToF pixels of its layer.
    tof_pixels: usize,
    /// Its layer's ToF range, [1st, 99th] percentile, mm.
    tof_range_mm: [f64; 2],
    /// Weighted median of its ToF depth (scene z), mm.
    tof_depth_mm: f64,
    /// Pixels with a ToF position.
    position_pixels: usize,
    /// Weighted RMS of (fused − ToF position), mm.
    fused_to_tof_rms_mm: f64,
    /// Conjugate-gradient iterations of the fusion.
    fusion_iterations: usize,
    /// Offset moved onto the ToF pixels' own ranges after the fusion, and their tilt.
    rigid: meb_pipeline::tof::rigid::RigidCorrection,
    /// Absolute depth error against the ground truth (no offset removed).
    #[serde(skip_serializing_if = "Option::is_none")]
    truth: Option<TruthRow>,
}

/// Absolute depth errors of one object against the ground truth, mm.
#[derive(serde::Serialize)]
struct TruthRow {
    /// The truth's object label compared with (the one the mask overlaps most), if labels
    /// were given.
    #[serde(skip_serializing_if = "Option::is_none")]
    truth_label: Option<i32>,
    /// Pixels compared.
    compared_pixels: usize,
    /// RMSE of the depth placed at the ToF depth.
    placed_rmse_mm: f64,
    /// RMSE of the fused depth.
    fused_rmse_mm: f64,
    /// Mean of (fused − truth).
    fused_mean_error_mm: f64,
}

/// What every object's folder shares: the plain command's inputs and report fields.
pub struct ObjectReport<'a> {
    /// The plain command's inputs (rig, decoded capture, ground truth).
    pub inputs: &'a super::truth::Inputs,
    /// The reconstruction settings.
    pub config: &'a ReconstructConfig,
    /// Input, rig and truth for the report's summary.
    pub summary: Summary,
    /// Where the data came from.
    pub source: String,
    /// Extra mesh formats.
    pub mesh_formats: Vec<String>,
}

/// Runs the hybrid reconstruction and writes its files into `dir` (module docs); returns one
/// line of text per object.
pub fn run(dir: &Path, tof: &TofInputs, report: &ObjectReport) -> Result<Vec<String>> {
    let (decoded, rig) = (&report.inputs.decoded, &report.inputs.rig);
    let labels = tof.truth_labels.as_ref();
    if let Some(labels) = labels {
        let camera = (rig.camera.height, rig.camera.width);
        ensure!(
            labels.dim() == camera,
            "--truth-labels is {}x{} but the camera is {}x{}",
            labels.ncols(),
            labels.nrows(),
            camera.1,
            camera.0
        );
    }
    let hybrid = reconstruct_objects(
        &usable_led_images(decoded),
        Some(&level_noise(decoded)),
        rig,
        &tof.range,
        &tof.calibration,
        report.config,
        &HybridConfig::default(),
    )
    .with_context(|| format!("hybrid reconstruction with {}", tof.origin))?;
    let truth = report.inputs.truth.as_ref();
    let mut rows = Vec::with_capacity(hybrid.objects.len());
    for (k, object) in hybrid.objects.iter().enumerate() {
        let folder = format!("object_{}", k + 1);
        let sub = dir.join(&folder);
        std::fs::create_dir(&sub).map_err(|e| meb_core::io::FilesError::write(&sub, e))?;
        report.write_object(&sub, &hybrid, k)?;
        let truth_row = truth
            .map(|t| absolute_errors(object, &t.depth, labels))
            .transpose()?;
        rows.push(ObjectRow {
            object: k + 1,
            folder,
            pixels: object.mask.iter().filter(|&&m| m).count(),
            reconstructed_pixels: object
                .fused
                .depth
                .depth_mm
                .iter()
                .filter(|z| z.is_finite())
                .count(),
            tof_pixels: object.layer.tof_pixels,
            tof_range_mm: object.layer.range_mm,
            tof_depth_mm: object.tof_depth_mm,
            position_pixels: object.fused.prior_pixels,
            fused_to_tof_rms_mm: object.fused.rms_to_prior_mm,
            fusion_iterations: object.fused.iterations,
            rigid: object.rigid,
            truth: truth_row,
        });
    }
    write_npy(&dir.join("depth.npy"), &hybrid.fused)?;
    write_npy(&dir.join("depth_placed.npy"), &hybrid.placed)?;
    write_npy(&dir.join("labels.npy"), &hybrid.labels)?;
    preview::write_png(&dir.join("depth.png"), &preview::depth_map(&hybrid.fused))?;
    super::tof::write_json(&dir.join("objects.json"), &rows)?;
    Ok(rows.iter().map(row_text).collect())
}

impl ObjectReport<'_> {
    /// Writes object `k`'s folder: the plain command's files, with the fused depth.
    fn write_object(&self, dir: &Path, hybrid: &HybridReconstruction, k: usize) -> Result<()> {
        let object = &hybrid.objects[k];
        let field = &object.reconstruction.photometric.field;
        let depth = &object.fused.depth;
        let (depth_errors, angular_errors) = match &self.inputs.truth {
            Some(t) => super::truth::compare(t, field, &depth.depth_mm)?,
            None => (None, None),
        };
        let mut summary = super::common::reconstruction_summary(
            &self.inputs.decoded,
            self.config,
            &object.reconstruction,
        );
        summary.object = Some(format!(
            "object {} of {}, ToF depth {:.1} mm",
            k + 1,
            hybrid.objects.len(),
            object.tof_depth_mm
        ));
        // The fused depth's distance comes from the range camera.
        summary.absolute_depth = Some(format!(
            "placed by the range camera (ToF depth {:.1} mm)",
            object.tof_depth_mm
        ));
        summary.input.clone_from(&self.summary.input);
        summary.rig.clone_from(&self.summary.rig);
        summary.ground_truth.clone_from(&self.summary.ground_truth);
        super::common::write_outputs(
            dir,
            &format!("meb reconstruct --tof: object {}", k + 1),
            self.source.clone(),
            field,
            depth,
            depth_errors.as_ref(),
            angular_errors.as_ref(),
            Some(object.reconstruction.confidence()),
            &hybrid.timings,
            summary,
            self.mesh_formats.clone(),
        )?;
        write_mask(&dir.join("object_mask.png"), &object.mask)?;
        write_npy(&dir.join("depth_placed.npy"), &object.placed)?;
        Ok(())
    }
}

/// Absolute (no offset removed) depth errors of `object` against `truth`, on its mask's pixels
/// of the truth object it overlaps most when `labels` are given.
fn absolute_errors(
    object: &HybridObject,
    truth: &Array2<f32>,
    labels: Option<&Array2<i32>>,
) -> Result<TruthRow> {
    let label = labels.map(|labels| {
        let mut counts = std::collections::BTreeMap::new();
        for (p, &m) in object.mask.indexed_iter() {
            if m && labels[p] >= 0 {
                *counts.entry(labels[p]).or_insert(0usize) += 1;
            }
        }
        counts
            .into_iter()
            .max_by_key(|&(l, n)| (n, -l))
            .map(|(l, _)| l)
    });
    if label == Some(None) {
        bail!(
            "the object at ToF depth {:.0} mm covers no labelled object of --truth-labels",
            object.tof_depth_mm
        );
    }
    let label = label.flatten();
    let compared = |p: (usize, usize)| {
        object.mask[p]
            && truth[p].is_finite()
            && match (labels, label) {
                (Some(labels), Some(l)) => labels[p] == l,
                _ => true,
            }
    };
    let errors = |depth: &Array2<f32>| -> Vec<f64> {
        depth
            .indexed_iter()
            .filter(|&(p, z)| z.is_finite() && compared(p))
            .map(|(p, &z)| f64::from(z) - f64::from(truth[p]))
            .collect()
    };
    let rms = |e: &[f64]| (e.iter().map(|e| e * e).sum::<f64>() / e.len() as f64).sqrt();
    let fused = errors(&object.fused.depth.depth_mm);
    let placed = errors(&object.placed);
    ensure!(
        !fused.is_empty(),
        "the ground truth has no depth under the object at ToF depth {:.0} mm",
        object.tof_depth_mm
    );
    Ok(TruthRow {
        truth_label: label,
        compared_pixels: fused.len(),
        placed_rmse_mm: rms(&placed),
        fused_rmse_mm: rms(&fused),
        fused_mean_error_mm: fused.iter().sum::<f64>() / fused.len() as f64,
    })
}

/// One object's line of the printed summary.
fn row_text(row: &ObjectRow) -> String {
    let truth = row.truth.as_ref().map_or_else(String::new, |t| {
        format!(
            ", absolute depth RMSE {:.2} mm placed, {:.2} mm fused (mean {:+.2} mm, {} px)",
            t.placed_rmse_mm, t.fused_rmse_mm, t.fused_mean_error_mm, t.compared_pixels
        )
    });
    format!(
        "object {}: {} pixels at ToF depth {:.1} mm ({} ToF pixels, {:.0}..{:.0} mm){truth}",
        row.object,
        row.pixels,
        row.tof_depth_mm,
        row.tof_pixels,
        row.tof_range_mm[0],
        row.tof_range_mm[1]
    )
}
