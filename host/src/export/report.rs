//! Writes a reconstruction's full output folder: arrays, previews, surface mesh(es), and the
//! report as JSON (every metric, per-stage timing) and as one self-contained HTML page.

use super::ExportError;
use super::files::preview::{depth_map, error_map, grey_map, mask_image, normal_map, png_bytes};
use super::files::{FilesError, write_npy};
use super::mesh::SurfaceMesh;
use super::render::{VIEWS, render_surface};
use crate::metrics::{AngularErrors, DepthErrors};
use crate::timing::StageTiming;
use crate::types::{DepthMap, NormalField};
use base64::Engine;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};

/// Everything that goes into an output folder.
#[derive(Debug, Clone)]
pub struct ReportInputs<'a> {
    /// Page title.
    pub title: String,
    /// Where the data came from (file, simulation description).
    pub source: String,
    /// Normals and albedo.
    pub normals: &'a NormalField,
    /// Depth.
    pub depth: &'a DepthMap,
    /// Depth accuracy, when ground truth was given.
    pub depth_errors: Option<&'a DepthErrors>,
    /// Normal accuracy, when ground truth was given.
    pub angular_errors: Option<&'a AngularErrors>,
    /// Per-stage timing.
    pub timings: &'a [StageTiming],
    /// Further named figures for the report (settings, counts, fractions).
    pub summary: serde_json::Map<String, Value>,
    /// Extra mesh formats besides PLY ("obj", "stl").
    pub mesh_formats: Vec<String>,
}

/// Paths of the written report.
#[derive(Debug, Clone)]
pub struct WrittenReport {
    /// `report.json`.
    pub json: PathBuf,
    /// `report.html`.
    pub html: PathBuf,
    /// The JSON value written.
    pub value: Value,
}

/// Writes the reconstruction's files into the existing folder `dir` (normally an
/// [`OutputFolder`](super::files::OutputFolder) being written).
pub fn write_report(dir: &Path, inputs: &ReportInputs) -> Result<WrittenReport, ExportError> {
    let write = |path: &Path, bytes: &[u8]| {
        std::fs::write(path, bytes).map_err(|e| FilesError::write(path, e))
    };
    if !inputs.depth.depth_mm.iter().any(|z| z.is_finite()) {
        return Err(ExportError::Empty(
            "the depth map has no reconstructed pixel".into(),
        ));
    }
    write_npy(&dir.join("normals.npy"), &inputs.normals.normals)?;
    write_npy(&dir.join("albedo.npy"), &inputs.normals.albedo)?;
    write_npy(&dir.join("depth.npy"), &inputs.depth.depth_mm)?;
    let mask = inputs.depth.depth_mm.mapv(f32::is_finite);
    let mut previews: Vec<(String, String, Vec<u8>)> = vec![
        (
            "normal map".into(),
            "normals.png".into(),
            png_bytes(&normal_map(&inputs.normals.normals))?,
        ),
        (
            "albedo".into(),
            "albedo.png".into(),
            png_bytes(&grey_map(&inputs.normals.albedo))?,
        ),
        (
            "depth".into(),
            "depth.png".into(),
            png_bytes(&depth_map(&inputs.depth.depth_mm))?,
        ),
        (
            "mask".into(),
            "mask.png".into(),
            png_bytes(&mask_image(&mask))?,
        ),
    ];
    if let Some(e) = inputs.depth_errors {
        let limit = (3.0 * e.rmse_mm as f32).max(1e-3);
        previews.push((
            format!("depth error (±{limit:.2} mm)"),
            "depth_error.png".into(),
            png_bytes(&error_map(&e.error_map, limit))?,
        ));
    }
    if let Some(a) = inputs.angular_errors {
        previews.push((
            "normal error (0–10°)".into(),
            "normal_error.png".into(),
            png_bytes(&grey_map(
                &a.error_map
                    .mapv(|d| if d.is_nan() { d } else { d.min(10.0) }),
            ))?,
        ));
    }
    for view in VIEWS {
        previews.push((
            format!("render: {}", view.name),
            format!("render_{}.png", view.name),
            png_bytes(&render_surface(inputs.depth, view, 480))?,
        ));
    }
    for (_, name, bytes) in &previews {
        write(&dir.join(name), bytes)?;
    }
    let mesh = SurfaceMesh::from_depth(inputs.depth);
    mesh.write(&dir.join("surface.ply"))?;
    for ext in &inputs.mesh_formats {
        mesh.write(&dir.join(format!("surface.{ext}")))?;
    }
    let total_ms: f64 = inputs.timings.iter().map(|t| t.ms).sum();
    let value = json!({
        "title": inputs.title,
        "source": inputs.source,
        "image": { "rows": inputs.depth.depth_mm.nrows(), "cols": inputs.depth.depth_mm.ncols() },
        "pitch_mm": inputs.depth.pitch_mm,
        "reconstructed_pixels": mask.iter().filter(|&&m| m).count(),
        "depth_errors": inputs.depth_errors,
        "normal_errors": inputs.angular_errors,
        "summary": inputs.summary,
        "timings_ms": inputs.timings,
        "total_ms": total_ms,
        "files": previews.iter().map(|(_, n, _)| n.clone()).collect::<Vec<_>>(),
    });
    let json_path = dir.join("report.json");
    let text = serde_json::to_string_pretty(&value).map_err(|e| FilesError::Encode {
        path: json_path.clone(),
        source: Box::new(e),
    })?;
    write(&json_path, text.as_bytes())?;
    let html_path = dir.join("report.html");
    write(&html_path, html_page(inputs, &value, &previews).as_bytes())?;
    Ok(WrittenReport {
        json: json_path,
        html: html_path,
        value,
    })
}

/// Escapes text for HTML.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The self-contained HTML page.
fn html_page(
    inputs: &ReportInputs,
    value: &Value,
    previews: &[(String, String, Vec<u8>)],
) -> String {
    let mut rows = Vec::new();
    if let Some(e) = inputs.depth_errors {
        rows.push(("depth RMSE".to_string(), format!("{:.3} mm", e.rmse_mm)));
        rows.push((
            "depth NRMSE".to_string(),
            e.nrmse
                .map_or_else(|| "n/a".into(), |n| format!("{:.2} %", 100.0 * n)),
        ));
        rows.push((
            "surface reconstructed".to_string(),
            format!("{:.1} %", 100.0 * e.reconstructed_fraction),
        ));
    }
    if let Some(a) = inputs.angular_errors {
        rows.push((
            "normal error mean / median".to_string(),
            format!("{:.2}° / {:.2}°", a.mean_deg, a.median_deg),
        ));
    }
    for (k, v) in &inputs.summary {
        let shown = match v {
            Value::String(s) => s.clone(),
            Value::Number(n) => n.as_f64().map_or(n.to_string(), |f| {
                if f.fract() == 0.0 {
                    format!("{f}")
                } else {
                    format!("{f:.4}")
                }
            }),
            other => other.to_string(),
        };
        rows.push((k.clone(), shown));
    }
    for t in inputs.timings {
        rows.push((format!("time: {}", t.stage), format!("{:.1} ms", t.ms)));
    }
    let table: String = rows
        .iter()
        .map(|(k, v)| format!("<tr><th>{}</th><td>{}</td></tr>\n", escape(k), escape(v)))
        .collect();
    let figures: String = previews
        .iter()
        .map(|(caption, _, bytes)| {
            format!(
                "<figure><img src=\"data:image/png;base64,{}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>\n",
                base64::engine::general_purpose::STANDARD.encode(bytes),
                c = escape(caption)
            )
        })
        .collect();
    let json_text = serde_json::to_string_pretty(value).unwrap_or_default();
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{title}</title>\n<style>\n\
         body{{font-family:system-ui,sans-serif;margin:2em;background:#fafafa;color:#222}}\n\
         table{{border-collapse:collapse;margin:1em 0}} th,td{{padding:4px 12px;border-bottom:1px solid #ddd;text-align:left}}\n\
         .grid{{display:flex;flex-wrap:wrap;gap:12px}} figure{{margin:0;background:#fff;padding:8px;border:1px solid #ddd}}\n\
         figure img{{max-width:360px;max-height:360px;image-rendering:pixelated}} figcaption{{font-size:90%;color:#555}}\n\
         pre{{background:#fff;border:1px solid #ddd;padding:8px;overflow:auto;max-height:300px}}\n</style></head><body>\n\
         <h1>{title}</h1><p>{source}</p>\n<table>{table}</table>\n<div class=\"grid\">{figures}</div>\n\
         <h2>report.json</h2><pre>{json}</pre>\n</body></html>\n",
        title = escape(&inputs.title),
        source = escape(&inputs.source),
        json = escape(&json_text),
    )
}
