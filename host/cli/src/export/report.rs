//! Writes a reconstruction's files: arrays, previews, surface mesh(es), and the report as JSON
//! ([`Report`], a versioned schema: every metric, settings, per-stage timing) and as one
//! self-contained HTML page (previews cropped to the object, one stage-timing table, an
//! interactive 3-D view of the surface, everything inlined so it works offline).

use super::ExportError;
use super::mesh::SurfaceMesh;
use super::render::{VIEWS, render_surface};
use super::viewer;
use base64::Engine;
use image::RgbImage;
use meb_core::io::preview::{depth_map, error_map, grey_map, mask_image, normal_map, png_bytes};
use meb_core::io::{FilesError, write_npy};
use meb_core::metrics::{AngularErrors, DepthErrors};
use meb_core::timing::StageTiming;
pub use meb_core::types::ConfidenceCounts;
use meb_core::types::{Confidence, DepthMap, NormalField};
use meb_pipeline::photometric::highlights::HighlightShares;
use ndarray::Array2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Name of the `report.json` layout.
pub const REPORT_SCHEMA: &str = "meb-report";
/// Version of the `report.json` layout; raised whenever a field changes meaning or goes away.
pub const REPORT_SCHEMA_VERSION: u32 = 1;

/// Settings and counts of a run, each shown in the report when present.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// The input file or folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input: Option<String>,
    /// The rig (file or preset name).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig: Option<String>,
    /// The simulated object (`meb demo`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object: Option<String>,
    /// Number of LED images (lights).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub leds: Option<usize>,
    /// Frames the decoder used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decoded_frames: Option<usize>,
    /// The normal integrator, e.g. `least-squares`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub integrator: Option<String>,
    /// The light model, e.g. `near-field (3 refinements)`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_model: Option<String>,
    /// Pixels photometric stereo solved (the object mask).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object_pixels: Option<usize>,
    /// Fraction (0..1) of the object pixels the integrator's artefact filter kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kept_fraction: Option<f64>,
    /// Object pixels lit by at least three LEDs in the ground truth (where accuracy is measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lit_by_three_pixels: Option<usize>,
    /// Share (0..1) of the reconstructed pixels measured by three or more LEDs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_share: Option<f64>,
    /// What is known of the depth's distance from the camera (measured by the lighting, or not:
    /// then only the shape is).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub absolute_depth: Option<String>,
    /// What the reconstruction's support check found implausible, written on request
    /// (`--force`); empty for a plausible result.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub implausible: Vec<String>,
    /// The ground-truth file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_truth: Option<String>,
    /// The camera the normals were integrated through (orthographic pitch, or intrinsics and
    /// distance), when the command was given one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<String>,
    /// What `depth.npy` holds and which of its scale and offset are assumed rather than measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_convention: Option<String>,
    /// Why the automatic integrator chose what it chose (the data it looked at).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub integrator_choice: Option<String>,
    /// How well the rig explains the capture (`meb reconstruct`'s rig check: misfit, per-LED
    /// residuals and apparent intensities, verdict; docs/formats/report-json.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig_check: Option<serde_json::Value>,
    /// Solved pixels with LEDs rejected as highlights (`highlights.npy`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub highlights: Option<HighlightShares>,
    /// The decoder's note on clipped pixels and the exposure that keeps the object usable.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clipping: Option<String>,
}

/// Depth accuracy against ground truth (see [`DepthErrors`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DepthAccuracy {
    /// RMSE in mm after removing the best constant offset.
    pub rmse_mm: f64,
    /// RMSE / depth range of the truth; `null` when the truth is flat.
    pub nrmse: Option<f64>,
    /// Fraction (0..1) of the true surface with an estimate.
    pub reconstructed_fraction: f64,
    /// Pixels compared.
    pub compared_pixels: usize,
    /// The offset removed (mean of estimate − truth), mm.
    pub offset_mm: f64,
}

/// Normal accuracy against ground truth (see [`AngularErrors`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NormalAccuracy {
    /// Mean angle between estimated and true normals, degrees.
    pub mean_deg: f64,
    /// Median angle, degrees.
    pub median_deg: f64,
    /// Pixels compared.
    pub compared_pixels: usize,
}

/// Total time of one stage over all its passes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageTotal {
    /// Stage name, without the pass number.
    pub stage: String,
    /// How many times it ran.
    pub passes: usize,
    /// Milliseconds over all passes.
    pub ms: f64,
}

/// Image size in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ImageSize {
    /// Rows (height).
    pub rows: usize,
    /// Columns (width).
    pub cols: usize,
}

/// The contents of `report.json` (schema [`REPORT_SCHEMA`], version
/// [`REPORT_SCHEMA_VERSION`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Always [`REPORT_SCHEMA`].
    pub schema: String,
    /// [`REPORT_SCHEMA_VERSION`] of the writer.
    pub schema_version: u32,
    /// Page title, e.g. "meb reconstruct".
    pub title: String,
    /// Where the data came from.
    pub source: String,
    /// Size of the camera grid.
    pub image: ImageSize,
    /// Grid pitch, mm per pixel.
    pub pitch_mm: f64,
    /// Pixels with a depth.
    pub reconstructed_pixels: usize,
    /// Depth accuracy, when ground truth was given.
    pub depth_accuracy: Option<DepthAccuracy>,
    /// Normal accuracy, when ground truth was given.
    pub normal_accuracy: Option<NormalAccuracy>,
    /// How the reconstructed pixels' depth is known, when the integrator said.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<ConfidenceCounts>,
    /// Settings and counts.
    pub summary: Summary,
    /// Each stage's total time, in the order the stages first ran.
    pub stages: Vec<StageTotal>,
    /// Every timed step in order (one row per pass).
    pub timings: Vec<StageTiming>,
    /// Sum of all timings, ms.
    pub total_ms: f64,
    /// The preview files written.
    pub files: Vec<String>,
}

/// The colour of each confidence class in `confidence.png`: green measured, amber two LEDs,
/// red filled, black not reconstructed.
fn confidence_image(confidence: &Array2<Confidence>) -> RgbImage {
    let (rows, cols) = confidence.dim();
    RgbImage::from_fn(cols as u32, rows as u32, |c, r| {
        image::Rgb(match confidence[(r as usize, c as usize)] {
            Confidence::Measured => [40, 170, 70],
            Confidence::TwoLeds => [240, 170, 0],
            Confidence::Filled => [220, 40, 40],
            Confidence::None => [0, 0, 0],
        })
    })
}

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
    /// How each pixel's depth is known (written as `confidence.npy`, one byte a pixel).
    pub confidence: Option<&'a Array2<Confidence>>,
    /// LEDs rejected as highlights per pixel (bit i = LED i + 1; written as `highlights.npy`,
    /// uint16).
    pub highlights: Option<&'a Array2<u16>>,
    /// Per-stage timing.
    pub timings: &'a [StageTiming],
    /// Settings and counts for the report.
    pub summary: Summary,
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
    /// The report written.
    pub report: Report,
}

/// A preview image: caption, file name, image.
struct Preview {
    caption: String,
    file: String,
    image: RgbImage,
    /// Whether the image is on the camera grid (and is cropped to the object in the page).
    on_grid: bool,
}

/// Writes the reconstruction's files into the existing folder `dir` (normally an
/// [`OutputFolder`](meb_core::io::OutputFolder) being written).
pub fn write_report(dir: &Path, inputs: &ReportInputs) -> Result<WrittenReport, ExportError> {
    let write = |path: &Path, bytes: &[u8]| {
        std::fs::write(path, bytes).map_err(|e| FilesError::write(path, e))
    };
    if !inputs.depth.depth_mm.iter().any(|z| z.is_finite()) {
        return Err(ExportError::Empty(
            "the depth map has no reconstructed pixel".into(),
        ));
    }
    let mask = inputs.depth.depth_mm.mapv(f32::is_finite);
    // The arrays are written while the previews are drawn and encoded, each preview on its
    // own (drawn one after another they took 46 ms of a 1280×720 `meb reconstruct`).
    let (arrays, drawn) = rayon::join(
        || -> Result<(), ExportError> {
            write_npy(&dir.join("normals.npy"), &inputs.normals.normals)?;
            write_npy(&dir.join("albedo.npy"), &inputs.normals.albedo)?;
            write_npy(&dir.join("depth.npy"), &inputs.depth.depth_mm)?;
            if let Some(confidence) = inputs.confidence {
                write_npy(&dir.join("confidence.npy"), &confidence.mapv(|k| k as u8))?;
            }
            if let Some(highlights) = inputs.highlights {
                write_npy(&dir.join("highlights.npy"), highlights)?;
            }
            Ok(())
        },
        || {
            previews(inputs, &mask)
                .into_par_iter()
                .map(|preview| png_bytes(&preview.image).map(|png| (preview, png)))
                .collect::<Result<Vec<_>, _>>()
        },
    );
    arrays?;
    let (previews, pngs): (Vec<Preview>, Vec<Vec<u8>>) = drawn?.into_iter().unzip();
    for (preview, png) in previews.iter().zip(&pngs) {
        write(&dir.join(&preview.file), png)?;
    }
    let mesh = SurfaceMesh::from_depth(inputs.depth);
    mesh.write(&dir.join("surface.ply"))?;
    for ext in &inputs.mesh_formats {
        mesh.write(&dir.join(format!("surface.{ext}")))?;
    }
    let report = Report {
        schema: REPORT_SCHEMA.into(),
        schema_version: REPORT_SCHEMA_VERSION,
        title: inputs.title.clone(),
        source: inputs.source.clone(),
        image: ImageSize {
            rows: inputs.depth.depth_mm.nrows(),
            cols: inputs.depth.depth_mm.ncols(),
        },
        pitch_mm: inputs.depth.pitch_mm,
        reconstructed_pixels: mask.iter().filter(|&&m| m).count(),
        depth_accuracy: inputs.depth_errors.map(|e| DepthAccuracy {
            rmse_mm: e.rmse_mm,
            nrmse: e.nrmse,
            reconstructed_fraction: e.reconstructed_fraction,
            compared_pixels: e.compared_pixels,
            offset_mm: e.offset_mm,
        }),
        normal_accuracy: inputs.angular_errors.map(|a| NormalAccuracy {
            mean_deg: a.mean_deg,
            median_deg: a.median_deg,
            compared_pixels: a.compared_pixels,
        }),
        confidence: inputs.confidence.map(ConfidenceCounts::of),
        summary: inputs.summary.clone(),
        stages: stage_totals(inputs.timings),
        timings: inputs.timings.to_vec(),
        total_ms: inputs.timings.iter().map(|t| t.ms).sum(),
        files: previews.iter().map(|p| p.file.clone()).collect(),
    };
    let json_path = dir.join("report.json");
    let text = serde_json::to_string_pretty(&report).map_err(|e| FilesError::Encode {
        path: json_path.clone(),
        source: Box::new(e),
    })?;
    write(&json_path, text.as_bytes())?;
    let html_path = dir.join("report.html");
    let page = html_page(
        &report,
        &text,
        &previews,
        &mask,
        &viewer::viewer_mesh(inputs.depth),
    )?;
    write(&html_path, page.as_bytes())?;
    Ok(WrittenReport {
        json: json_path,
        html: html_path,
        report,
    })
}

/// The preview images of a reconstruction.
fn previews(inputs: &ReportInputs, mask: &ndarray::Array2<bool>) -> Vec<Preview> {
    /// Draws one preview.
    type Draw<'a> = Box<dyn Fn() -> Preview + Send + Sync + 'a>;
    fn grid<'a>(
        caption: String,
        file: &'static str,
        image: impl Fn() -> RgbImage + Send + Sync + 'a,
    ) -> Draw<'a> {
        Box::new(move || Preview {
            caption: caption.clone(),
            file: file.into(),
            image: image(),
            on_grid: true,
        })
    }
    let mut draws: Vec<Draw> = vec![
        grid("normal map".into(), "normals.png", || {
            normal_map(&inputs.normals.normals)
        }),
        grid("albedo".into(), "albedo.png", || {
            grey_map(&inputs.normals.albedo)
        }),
        grid("depth".into(), "depth.png", || {
            depth_map(&inputs.depth.depth_mm)
        }),
        grid("mask".into(), "mask.png", || mask_image(mask)),
    ];
    if let Some(confidence) = inputs.confidence {
        draws.push(grid(
            "confidence (green ≥ 3 LEDs, amber 2 LEDs, red filled)".into(),
            "confidence.png",
            || confidence_image(confidence),
        ));
    }
    if let Some(highlights) = inputs.highlights {
        draws.push(grid(
            "highlights rejected (grey none; LED 1 red, 2 green, 3 blue, 4 yellow, 5+ magenta; \
             white several)"
                .into(),
            "highlights.png",
            move || highlight_image(highlights, mask),
        ));
    }
    if let Some(e) = inputs.depth_errors {
        let limit = (3.0 * e.rmse_mm as f32).max(1e-3);
        draws.push(grid(
            format!("depth error (±{limit:.2} mm)"),
            "depth_error.png",
            move || error_map(&e.error_map, limit),
        ));
    }
    if let Some(a) = inputs.angular_errors {
        draws.push(grid(
            "normal error (0–10°)".into(),
            "normal_error.png",
            || {
                let capped = a
                    .error_map
                    .mapv(|d| if d.is_nan() { d } else { d.min(10.0) });
                grey_map(&capped)
            },
        ));
    }
    for view in VIEWS {
        draws.push(Box::new(move || Preview {
            caption: format!("render: {}", view.name),
            file: format!("render_{}.png", view.name),
            image: render_surface(inputs.depth, view, 480),
            on_grid: false,
        }));
    }
    draws.into_par_iter().map(|draw| draw()).collect()
}

/// The colour of each pixel of `highlights.png`: black off the surface, grey where no LED was
/// rejected, one colour per rejected LED (LED 1 red, 2 green, 3 blue, 4 yellow, 5 and above
/// magenta), white where several were.
fn highlight_image(highlights: &Array2<u16>, surface: &Array2<bool>) -> RgbImage {
    let (rows, cols) = highlights.dim();
    RgbImage::from_fn(cols as u32, rows as u32, |c, r| {
        let p = (r as usize, c as usize);
        let bits = highlights[p];
        image::Rgb(if bits.count_ones() > 1 {
            [255, 255, 255]
        } else if bits != 0 {
            match bits.trailing_zeros() {
                0 => [230, 40, 40],
                1 => [40, 200, 60],
                2 => [60, 110, 255],
                3 => [240, 210, 0],
                _ => [220, 60, 220],
            }
        } else if surface.get(p).copied().unwrap_or(false) {
            [90, 90, 90]
        } else {
            [0, 0, 0]
        })
    })
}

/// Per-stage totals: "integration (pass 2)" counts towards "integration".
pub fn stage_totals(timings: &[StageTiming]) -> Vec<StageTotal> {
    let mut totals: Vec<StageTotal> = Vec::new();
    for t in timings {
        let stage = match t.stage.rsplit_once(" (pass ") {
            Some((name, rest)) if rest.ends_with(')') => name,
            _ => t.stage.as_str(),
        };
        match totals.iter_mut().find(|s| s.stage == stage) {
            Some(total) => {
                total.passes += 1;
                total.ms += t.ms;
            }
            None => totals.push(StageTotal {
                stage: stage.to_string(),
                passes: 1,
                ms: t.ms,
            }),
        }
    }
    totals
}

/// Rows, columns (inclusive ranges) of the `mask`'s bounding box grown by a margin of 10 % of
/// its size (at least 4 pixels), clipped to the image; the whole image when `mask` is empty.
pub fn crop_box(mask: &ndarray::Array2<bool>) -> ([usize; 2], [usize; 2]) {
    let (rows, cols) = mask.dim();
    let mut lo = [usize::MAX; 2];
    let mut hi = [0usize; 2];
    for ((r, c), &m) in mask.indexed_iter() {
        if m {
            lo = [lo[0].min(r), lo[1].min(c)];
            hi = [hi[0].max(r), hi[1].max(c)];
        }
    }
    if lo[0] == usize::MAX {
        return ([0, rows.saturating_sub(1)], [0, cols.saturating_sub(1)]);
    }
    let grow = |lo: usize, hi: usize, len: usize| {
        let margin = ((hi - lo + 1) / 10).max(4);
        [lo.saturating_sub(margin), (hi + margin).min(len - 1)]
    };
    (grow(lo[0], hi[0], rows), grow(lo[1], hi[1], cols))
}

/// Escapes text for HTML.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The report's key figures as (label, value) rows.
fn figure_rows(report: &Report) -> Vec<(String, String)> {
    let mut rows = Vec::new();
    if let Some(e) = &report.depth_accuracy {
        rows.push(("depth RMSE".into(), format!("{:.3} mm", e.rmse_mm)));
        rows.push((
            "depth NRMSE".into(),
            e.nrmse
                .map_or_else(|| "n/a".into(), |n| format!("{:.2} %", 100.0 * n)),
        ));
        rows.push((
            "surface reconstructed".into(),
            format!("{:.1} %", 100.0 * e.reconstructed_fraction),
        ));
    }
    if let Some(a) = &report.normal_accuracy {
        rows.push((
            "normal error mean / median".into(),
            format!("{:.2}° / {:.2}°", a.mean_deg, a.median_deg),
        ));
    }
    if let Some(k) = &report.confidence {
        let total = (k.measured + k.two_leds + k.filled).max(1) as f64;
        for (label, n) in [
            ("depth from ≥ 3 LEDs", k.measured),
            ("depth from 2 LEDs + integrability", k.two_leds),
            ("holes filled by the integrator", k.filled),
        ] {
            rows.push((
                label.into(),
                format!("{n} px ({:.1} %)", 100.0 * n as f64 / total),
            ));
        }
    }
    let s = &report.summary;
    let mut text = |label: &str, value: &Option<String>| {
        if let Some(v) = value {
            rows.push((label.into(), v.clone()));
        }
    };
    text("input", &s.input);
    text("rig", &s.rig);
    text("object", &s.object);
    text("integrator", &s.integrator);
    text("light model", &s.light_model);
    text("ground truth", &s.ground_truth);
    text("camera", &s.camera);
    text("depth.npy", &s.depth_convention);
    text("integrator choice", &s.integrator_choice);
    let mut count = |label: &str, value: Option<usize>| {
        if let Some(v) = value {
            rows.push((label.into(), v.to_string()));
        }
    };
    count("LED images", s.leds);
    count("decoded frames", s.decoded_frames);
    count("object pixels", s.object_pixels);
    count("surface lit by ≥ 3 LEDs (pixels)", s.lit_by_three_pixels);
    count("reconstructed pixels", Some(report.reconstructed_pixels));
    if let Some(k) = s.kept_fraction {
        rows.push((
            "kept by the artefact filter".into(),
            format!("{:.1} %", 100.0 * k),
        ));
    }
    if let Some(m) = s.measured_share {
        rows.push((
            "reconstructed surface lit by ≥ 3 LEDs".into(),
            format!("{:.1} %", 100.0 * m),
        ));
    }
    if let Some(a) = &s.absolute_depth {
        rows.push(("distance from the camera".into(), a.clone()));
    }
    if let Some(h) = &s.highlights {
        rows.push((
            "solved pixels with a highlight rejected".into(),
            format!(
                "{} px ({:.1} %; per LED {})",
                h.pixels_with_highlight,
                100.0 * h.share,
                h.per_led
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join(" / ")
            ),
        ));
    }
    for problem in &s.implausible {
        rows.push(("implausible, kept by --force".into(), problem.clone()));
    }
    rows.push((
        "image".into(),
        format!(
            "{}×{} px at {:.3} mm/px",
            report.image.cols, report.image.rows, report.pitch_mm
        ),
    ));
    rows
}

/// The self-contained HTML page.
fn html_page(
    report: &Report,
    json_text: &str,
    previews: &[Preview],
    mask: &ndarray::Array2<bool>,
    mesh: &SurfaceMesh,
) -> Result<String, ExportError> {
    let table: String = figure_rows(report)
        .iter()
        .map(|(k, v)| format!("<tr><th>{}</th><td>{}</td></tr>\n", escape(k), escape(v)))
        .collect();
    let stages: String = report
        .stages
        .iter()
        .map(|s| {
            format!(
                "<tr><th>{}</th><td>{}</td><td>{:.1} ms</td></tr>\n",
                escape(&s.stage),
                s.passes,
                s.ms
            )
        })
        .collect();
    let (rows, cols) = crop_box(mask);
    let mut figures = String::new();
    for p in previews {
        let image = if p.on_grid {
            image::imageops::crop_imm(
                &p.image,
                cols[0] as u32,
                rows[0] as u32,
                (cols[1] - cols[0] + 1) as u32,
                (rows[1] - rows[0] + 1) as u32,
            )
            .to_image()
        } else {
            p.image.clone()
        };
        figures.push_str(&format!(
            "<figure><img src=\"data:image/png;base64,{}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>\n",
            base64::engine::general_purpose::STANDARD.encode(png_bytes(&image)?),
            c = escape(&p.caption)
        ));
    }
    let crop_note = format!(
        "Previews on the camera grid are cropped to the object (columns {}–{}, rows {}–{} of {}×{}); the PNG files in the folder are full frame.",
        cols[0], cols[1], rows[0], rows[1], report.image.cols, report.image.rows
    );
    Ok(format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{title}</title>\n<style>\n\
         body{{font-family:system-ui,sans-serif;margin:2em;background:#fafafa;color:#222}}\n\
         table{{border-collapse:collapse;margin:1em 0}} th,td{{padding:4px 12px;border-bottom:1px solid #ddd;text-align:left}}\n\
         .grid{{display:flex;flex-wrap:wrap;gap:12px}} figure{{margin:0;background:#fff;padding:8px;border:1px solid #ddd}}\n\
         figure img{{width:300px;max-height:360px;object-fit:contain;image-rendering:pixelated}} figcaption{{font-size:90%;color:#555}}\n\
         pre{{background:#fff;border:1px solid #ddd;padding:8px;overflow:auto;max-height:300px}}\n</style></head><body>\n\
         <h1>{title}</h1><p>{source}</p>\n<table>{table}</table>\n\
         <h2>Surface</h2>\n{viewer}\n\
         <h2>Stage timing</h2>\n<table><tr><th>stage</th><th>passes</th><th>time</th></tr>\n{stages}<tr><th>total</th><td></td><td>{total:.1} ms</td></tr></table>\n\
         <h2>Previews</h2><p>{crop_note}</p>\n<div class=\"grid\">{figures}</div>\n\
         <h2>report.json</h2><pre>{json}</pre>\n</body></html>\n",
        title = escape(&report.title),
        source = escape(&report.source),
        viewer = viewer::surface_viewer(mesh),
        total = report.total_ms,
        crop_note = escape(&crop_note),
        json = escape(json_text),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_collapse_into_one_row_per_stage() {
        let t = |stage: &str, ms: f64| StageTiming {
            stage: stage.into(),
            ms,
        };
        let totals = stage_totals(&[
            t("photometric stereo (pass 1)", 2.0),
            t("integration (pass 1)", 3.0),
            t("photometric stereo (pass 2)", 4.0),
            t("integration (pass 2)", 5.0),
            t("render frames + decode", 7.0),
        ]);
        let rows: Vec<(&str, usize, f64)> = totals
            .iter()
            .map(|s| (s.stage.as_str(), s.passes, s.ms))
            .collect();
        assert_eq!(
            rows,
            [
                ("photometric stereo", 2, 6.0),
                ("integration", 2, 8.0),
                ("render frames + decode", 1, 7.0)
            ]
        );
    }

    #[test]
    fn crop_box_frames_the_object_with_a_margin() {
        let mut mask = ndarray::Array2::from_elem((100, 200), false);
        for r in 40..60 {
            for c in 90..140 {
                mask[(r, c)] = true;
            }
        }
        assert_eq!(crop_box(&mask), ([36, 63], [85, 144]));
        mask[(0, 0)] = true;
        assert_eq!(crop_box(&mask), ([0, 65], [0, 153]));
        let empty = ndarray::Array2::from_elem((10, 20), false);
        assert_eq!(crop_box(&empty), ([0, 9], [0, 19]));
    }
}
