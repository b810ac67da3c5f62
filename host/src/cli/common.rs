//! Helpers shared by the reconstruction commands: mask loading and writing the output folder.

use anyhow::{Context, Result};
use meb::export::report::{ReportInputs, WrittenReport, write_report};
use meb::metrics::{AngularErrors, DepthErrors};
use meb::reconstruct::StageTiming;
use meb::types::{DepthMap, NormalField};
use ndarray::Array2;
use std::path::Path;

/// Reads a mask image (non-zero = inside) and checks it is not empty.
pub fn load_mask(path: &Path) -> Result<Array2<bool>> {
    let mask = meb::datasets::diligent::read_mask(path)?;
    anyhow::ensure!(
        mask.iter().any(|&m| m),
        "empty mask: {} has no non-zero pixel",
        path.display()
    );
    Ok(mask)
}

/// Writes the output folder and returns the report paths.
#[allow(clippy::too_many_arguments)]
pub fn write_outputs(
    out: &Path,
    title: &str,
    source: String,
    normals: &NormalField,
    depth: &DepthMap,
    depth_errors: Option<&DepthErrors>,
    angular_errors: Option<&AngularErrors>,
    timings: &[StageTiming],
    summary: serde_json::Map<String, serde_json::Value>,
    mesh_formats: Vec<String>,
) -> Result<WrittenReport> {
    write_report(
        out,
        &ReportInputs {
            title: title.to_string(),
            source,
            normals,
            depth,
            depth_errors,
            angular_errors,
            timings,
            summary,
            mesh_formats,
        },
    )
    .with_context(|| format!("writing {}", out.display()))
}
