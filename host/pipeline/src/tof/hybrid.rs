//! Per-object hybrid reconstruction (thesis Ch. 6, beyond it with Nehab et al. 2005): the range
//! map selects each object, photometric stereo reconstructs it inside its own mask, and its
//! absolute depth comes from the ToF range.
//!
//! 1. Layers of the range map ([`super::mask::segment`]); those touching the ToF image border
//!    (the background wall) are not objects unless asked for. All layers are mapped into the
//!    camera together so that each pixel has one owner, the owners' boundaries are snapped to
//!    the LED images' edges within ±one ToF pixel (watershed), and each object mask is cleaned.
//! 2. Positions: every camera pixel of an object is traced to the ToF image
//!    ([`super::mask`]); the axial depth s of the layer's *interior* ToF pixels (a margin of
//!    ToF pixels inside the layer: no blended edge pixels) is interpolated there and becomes the
//!    scene point X = C + s·d(u) on the ToF camera's ray (rig's pose), whose z is the position
//!    prior, weighted 1/(k·σ²) per camera pixel with k the camera pixels per ToF pixel (one ToF
//!    sample spread over k pixels carries its weight once). Two priors are built
//!    ([`PriorRanges`]): from the smoothed range map (σ² times the n pixels each range pooled,
//!    so shared photons count once), which the fusion follows between ToF pixels; and from each
//!    ToF pixel's own range, whose errors are independent, which sets the object's offset
//!    (step 4). The smoothed map's local plane fit is biased on curved surfaces (by mean(x²)/R:
//!    +0.2 mm on the scene's Ø48 sphere) and its robust weights by skewed per-pixel errors: on
//!    the simulated scene it placed every object 0.2–0.3 mm too far on average over five SPAD
//!    seeds, the per-pixel ranges 0.1–0.2 mm. A ToF pixel whose own range is farther than 4σ
//!    from the smoothed one (a wrong correlation peak) gives neither.
//! 3. Photometric stereo + integration ([`crate::reconstruct::reconstruct`]) in the rig moved
//!    so that the object's ToF depth is z = 0 (its near-field light vectors are then right from
//!    the first pass); the result is *placed* by the weighted mean of prior − depth over the
//!    pixels with measured normals, and *fused*
//!    with the positions by [`crate::integrate::fusion`] (depth that follows the normals while
//!    staying near the ToF range).
//! 4. The fused depth's offset is taken from the ToF pixels' own ranges ([`super::rigid`],
//!    which also reports the tilt between the two and its χ²).

use super::TofError;
use super::calibration::Calibration;
use super::mask::{self, Layer, MaskConfig, bilinear, trace_to_tof};
use super::range::RangeMap;
use super::rigid::{RigidCorrection, fit_rigid};
use crate::integrate::IntegrateError;
use crate::integrate::fusion::{Fusion, FusionConfig, PositionPrior, fuse_positions_and_normals};
use crate::reconstruct::{
    ReconstructConfig, ReconstructError, Reconstruction, Request, Source, StageTiming, reconstruct,
};
use meb_core::rig::Rig;
use meb_core::types::LedImages;
use nalgebra::Vector3;
use ndarray::Array2;
use std::time::Instant;
use thiserror::Error;

/// A ToF pixel's own range farther than this many of its standard deviations from the smoothed
/// range is a wrong correlation peak and gives no position.
const OUTLIER_SIGMAS: f32 = 4.0;

/// Settings of the hybrid reconstruction.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HybridConfig {
    /// Layer finding and mask clean-up.
    pub mask: MaskConfig,
    /// Position + normal fusion.
    pub fusion: FusionConfig,
    /// Snap mask boundaries to the LED images' edges within this many ToF pixels (0: off).
    pub snap_tof_pixels: f64,
    /// Also reconstruct layers touching the ToF image border (usually the background).
    pub include_border_layers: bool,
    /// ToF pixels give positions only this far (Chebyshev distance, ToF pixels) inside their
    /// layer: nearer its edge, the range blends the neighbouring surface (mixed pixels, and the
    /// range smoothing's window reaching them; its default radius is 3 too). An object too
    /// thin for the margin gets positions with a smaller one.
    pub prior_margin_tof_pixels: usize,
}

impl Default for HybridConfig {
    fn default() -> Self {
        Self {
            mask: MaskConfig::default(),
            fusion: FusionConfig::default(),
            snap_tof_pixels: 1.0,
            include_border_layers: false,
            prior_margin_tof_pixels: 3,
        }
    }
}

/// Errors of the hybrid reconstruction.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum HybridError {
    /// Range map, calibration or masks.
    #[error(transparent)]
    Tof(#[from] TofError),
    /// Photometric stereo or integration of an object.
    #[error("object {object}: {source}")]
    Reconstruct {
        /// Which object (1-based).
        object: usize,
        /// What failed.
        source: ReconstructError,
    },
    /// Fusion of an object.
    #[error("object {object}: fusing with the ToF range: {source}")]
    Fusion {
        /// Which object (1-based).
        object: usize,
        /// What failed.
        source: IntegrateError,
    },
    /// The rig has no ToF camera.
    #[error(
        "the rig has no [tof_camera]: absolute depth from a range map needs the ToF camera's pose and field of view"
    )]
    NoTofCamera,
}

/// One object's result.
#[derive(Debug, Clone)]
pub struct HybridObject {
    /// Its layer of the range map.
    pub layer: Layer,
    /// Its mask in camera pixels.
    pub mask: Array2<bool>,
    /// Weighted median of its ToF depth (scene z), mm.
    pub tof_depth_mm: f64,
    /// ToF positions on the camera grid.
    pub prior: PositionPrior,
    /// Photometric stereo + integration (depth in scene z, placed at `tof_depth_mm` first).
    pub reconstruction: Reconstruction,
    /// The reconstruction shifted by the weighted mean of (ToF − depth): scene z, mm.
    pub placed: Array2<f32>,
    /// Depth fused with the ToF positions, its offset from the ToF pixels' own ranges (`rigid`).
    pub fused: Fusion,
    /// The offset moved onto the ToF pixels' own ranges after the fusion (and their tilt).
    pub rigid: RigidCorrection,
}

/// All objects of a scene.
#[derive(Debug, Clone)]
pub struct HybridReconstruction {
    /// Per object, nearest first.
    pub objects: Vec<HybridObject>,
    /// Object index (0-based) per camera pixel, −1 outside every object.
    pub labels: Array2<i32>,
    /// Placed depth of every object, scene z in mm (NaN elsewhere).
    pub placed: Array2<f32>,
    /// Fused depth of every object, scene z in mm (NaN elsewhere).
    pub fused: Array2<f32>,
    /// Stage timings.
    pub timings: Vec<StageTiming>,
}

/// Per-object masks of the range map `range` (mm) in camera pixels (`camera_size` =
/// [width, height]), snapped to the LED images' edges when `images` are given (module docs).
pub fn object_masks(
    images: Option<&LedImages>,
    camera_size: [usize; 2],
    range: &Array2<f32>,
    calibration: &Calibration,
    config: &HybridConfig,
) -> Result<Vec<(Layer, Array2<bool>)>, TofError> {
    let (rows, cols) = range.dim();
    calibration.check_sizes([cols, rows], camera_size)?;
    let layers = mask::segment(range, &config.mask)?;
    let mut masks = mask::camera_masks(&layers, range, calibration, camera_size)?;
    let scale = mask::camera_pixels_per_tof_pixel(calibration, Some(layers[0].median_mm));
    if let Some(images) = images
        && config.snap_tof_pixels > 0.0
    {
        let band = (config.snap_tof_pixels * scale).round().max(1.0) as usize;
        masks = mask::snap_to_edges(&masks, &images.images, band)?;
    }
    let radius = mask::clean_radius(scale);
    let mut objects = Vec::new();
    for (layer, m) in layers.into_iter().zip(masks) {
        if layer.touches_border && !config.include_border_layers {
            continue;
        }
        let m = if config.mask.clean {
            mask::clean(&m, radius)?
        } else {
            m
        };
        if m.iter().any(|&v| v) {
            objects.push((layer, m));
        }
    }
    if objects.is_empty() {
        return Err(TofError::Empty(
            "the range map holds no object apart from layers touching the image border (the background); include the border layers to keep those".into(),
        ));
    }
    Ok(objects)
}

/// Which of a range map's ranges give positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PriorRanges {
    /// The smoothed map, weighted 1/(k·n·σ²) with n the ToF pixels each range pooled: smooth
    /// between ToF pixels, but its errors are correlated and biased on curved surfaces.
    Smoothed,
    /// Each ToF pixel's own range, weighted 1/(k·σ²): independent errors, no smoothing bias.
    PerPixel,
}

/// ToF positions (scene z and weight) on the camera grid for the pixels of `mask`, from the
/// layer's ToF pixels at least `margin` ToF pixels inside it (Chebyshev distance), from the
/// `ranges` chosen (module docs).
pub fn position_prior(
    layer: &Layer,
    mask: &Array2<bool>,
    range: &RangeMap,
    calibration: &Calibration,
    rig: &Rig,
    margin: usize,
    ranges: PriorRanges,
) -> Result<PositionPrior, HybridError> {
    let tof = rig.tof_camera.as_ref().ok_or(HybridError::NoTofCamera)?;
    let (rows, cols) = range.range_mm.dim();
    let inside = Array2::from_shape_fn((rows, cols), |(r, c)| {
        r >= margin
            && c >= margin
            && r + margin < rows
            && c + margin < cols
            && (r - margin..=r + margin)
                .all(|rr| (c - margin..=c + margin).all(|cc| layer.tof_mask[(rr, cc)]))
    });
    // (range, variance of one ToF pixel's share) of each usable ToF pixel.
    let sample = |r: usize, c: usize| -> Option<(f64, f64)> {
        let (raw, raw_sigma) = (range.raw_range_mm[(r, c)], range.raw_sigma_mm[(r, c)]);
        let (smooth, sigma) = (range.range_mm[(r, c)], range.sigma_mm[(r, c)]);
        let usable = inside[(r, c)]
            && raw.is_finite()
            && raw_sigma.is_finite()
            && raw_sigma > 0.0
            && smooth.is_finite()
            && sigma.is_finite()
            && (raw - smooth).abs() <= OUTLIER_SIGMAS * raw_sigma;
        usable.then(|| match ranges {
            PriorRanges::PerPixel => (f64::from(raw), f64::from(raw_sigma).powi(2)),
            // One pixel's share of the information: σ² times the pixels its range pooled.
            PriorRanges::Smoothed => (
                f64::from(smooth),
                f64::from(sigma).powi(2) * f64::from(range.samples[(r, c)]).max(1.0),
            ),
        })
    };
    let k = mask::camera_pixels_per_tof_pixel(calibration, Some(layer.median_mm))
        .powi(2)
        .max(1.0);
    let centre = Vector3::from(tof.position_mm);
    let mut depth = Array2::from_elem(mask.dim(), f32::NAN);
    let mut weight = Array2::zeros(mask.dim());
    for ((r, c), &m) in mask.indexed_iter() {
        if !m {
            continue;
        }
        let (u, _) = trace_to_tof(layer, &range.range_mm, calibration, [c as f64, r as f64]);
        let s = bilinear(u, (rows, cols), &|rr, cc| sample(rr, cc).map(|v| v.0));
        let variance = bilinear(u, (rows, cols), &|rr, cc| sample(rr, cc).map(|v| v.1));
        if let (Some(s), Some(variance)) = (s, variance)
            && variance > 0.0
        {
            let x = centre + s * tof.ray(u[1], u[0]);
            depth[(r, c)] = x.z as f32;
            weight[(r, c)] = (1.0 / (k * variance)) as f32;
        }
    }
    Ok(PositionPrior {
        depth_mm: depth,
        weight,
    })
}

/// The weighted median of the prior's depth.
fn weighted_median(prior: &PositionPrior) -> Option<f64> {
    let mut pairs: Vec<(f64, f64)> = prior
        .depth_mm
        .iter()
        .zip(&prior.weight)
        .filter(|(z, w)| z.is_finite() && **w > 0.0)
        .map(|(&z, &w)| (f64::from(z), f64::from(w)))
        .collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = pairs.iter().map(|p| p.1).sum();
    let mut acc = 0.0;
    pairs
        .into_iter()
        .find(|p| {
            acc += p.1;
            acc >= 0.5 * total
        })
        .map(|p| p.0)
}

/// The rig seen from an origin moved to z = `z0` (LEDs and camera shifted by −z0, pitch kept).
fn rig_at_depth(rig: &Rig, z0: f64) -> Rig {
    let mut moved = rig.clone();
    moved.camera.pixel_pitch_mm = Some(rig.camera.pitch_mm());
    moved.camera.distance_mm -= z0;
    for led in &mut moved.leds {
        led.position_mm[2] -= z0;
    }
    moved.tof_camera = None;
    moved
}

/// Reconstructs every object of the scene separately and places/fuses it with the ToF range
/// (module docs). `noise` is the per-pixel σ of the LED images.
pub fn reconstruct_objects(
    images: &LedImages,
    noise: Option<&Array2<f32>>,
    rig: &Rig,
    range: &RangeMap,
    calibration: &Calibration,
    config: &ReconstructConfig,
    hybrid: &HybridConfig,
) -> Result<HybridReconstruction, HybridError> {
    if rig.tof_camera.is_none() {
        return Err(HybridError::NoTofCamera);
    }
    let mut timings = Vec::new();
    let start = Instant::now();
    let found = object_masks(
        Some(images),
        [rig.camera.width, rig.camera.height],
        &range.range_mm,
        calibration,
        hybrid,
    )?;
    timings.push(StageTiming {
        stage: "ToF object masks".into(),
        ms: start.elapsed().as_secs_f64() * 1e3,
    });
    let shape = (rig.camera.height, rig.camera.width);
    let pitch = rig.camera.pitch_mm();
    let mut objects = Vec::new();
    for (index, (layer, mask)) in found.into_iter().enumerate() {
        let object = index + 1;
        let start = Instant::now();
        let mut placement = None;
        for margin in (0..=hybrid.prior_margin_tof_pixels).rev() {
            let prior =
                |ranges| position_prior(&layer, &mask, range, calibration, rig, margin, ranges);
            let smoothed = prior(PriorRanges::Smoothed)?;
            if let Some(z0) = weighted_median(&smoothed) {
                placement = Some((smoothed, prior(PriorRanges::PerPixel)?, z0));
                break;
            }
        }
        let Some((prior, own_ranges, z0)) = placement else {
            return Err(TofError::Empty(format!(
                "object {object}: no ToF pixel of its layer maps into its mask (is the calibration for this scene?)"
            ))
            .into());
        };
        let moved = rig_at_depth(rig, z0);
        let mut reconstruction = reconstruct(
            Source::Images { images, noise },
            &moved,
            config,
            Request {
                mask: Some(&mask),
                ..Request::default()
            },
        )
        .map_err(|source| HybridError::Reconstruct { object, source })?;
        reconstruction
            .integration
            .depth
            .depth_mm
            .mapv_inplace(|z| z + z0 as f32);
        let depth = &reconstruction.integration.depth.depth_mm;
        // The offset from the pixels with measured normals (three or more LEDs) when there are
        // any: two-LED pixels' depth follows a guessed normal and can be centimetres off.
        let measured = &reconstruction.photometric.field.mask;
        let any_measured = measured.iter().any(|&m| m);
        let (mut sum_w, mut sum_wd) = (0.0, 0.0);
        for (((z, &p), &w), &m) in depth
            .iter()
            .zip(&prior.depth_mm)
            .zip(&prior.weight)
            .zip(measured)
        {
            if z.is_finite() && p.is_finite() && w > 0.0 && (m || !any_measured) {
                sum_w += f64::from(w);
                sum_wd += f64::from(w) * f64::from(p - z);
            }
        }
        let offset = if sum_w > 0.0 { sum_wd / sum_w } else { 0.0 };
        let placed = depth.mapv(|z| z + offset as f32);
        let mut fused = fuse_positions_and_normals(
            &reconstruction.photometric.field,
            pitch,
            &prior,
            &hybrid.fusion,
            Some(&placed),
        )
        .map_err(|source| HybridError::Fusion { object, source })?;
        let rigid =
            fit_rigid(&fused.depth.depth_mm, &own_ranges, &fused.solved).ok_or_else(|| {
                HybridError::Fusion {
                    object,
                    source: IntegrateError::EmptyMask,
                }
            })?;
        fused.depth.depth_mm = rigid.apply(&fused.depth.depth_mm);
        timings.push(StageTiming {
            stage: format!("object {object}: photometric stereo, integration, fusion"),
            ms: start.elapsed().as_secs_f64() * 1e3,
        });
        objects.push(HybridObject {
            layer,
            mask,
            tof_depth_mm: z0,
            prior,
            reconstruction,
            placed,
            fused,
            rigid,
        });
    }
    let mut labels = Array2::from_elem(shape, -1);
    let mut placed = Array2::from_elem(shape, f32::NAN);
    let mut fused = Array2::from_elem(shape, f32::NAN);
    for (k, o) in objects.iter().enumerate() {
        for (p, &m) in o.mask.indexed_iter() {
            if m {
                labels[p] = k as i32;
                placed[p] = o.placed[p];
                fused[p] = o.fused.depth.depth_mm[p];
            }
        }
    }
    Ok(HybridReconstruction {
        objects,
        labels,
        placed,
        fused,
        timings,
    })
}
