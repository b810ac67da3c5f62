//! The reconstruction stage: LED images + rig → normals, albedo and depth, with near-field
//! refinement (SPEC §5–§6).
//!
//! The first pass uses light vectors at the plane z = 0; every further pass recomputes each
//! pixel's light vectors L_i(X(p)) at the point X(p) of its ray at the previous depth, re-solves
//! the normals and re-integrates (warm-started). Pixels lit by two LEDs and holes inside the
//! object are integrated with the rest ([`crate::integrate::coverage`]). Integration fixes depth
//! only up to a constant per separate part of the object (a scale for a perspective camera): per
//! piece of the mask, and per part the bilateral integrator cut off along a depth discontinuity.
//! The light vectors depend on it: after each integration every part's constant is chosen by a
//! golden-section search that minimises the Lambertian misfit of its pixels lit by more than
//! three LEDs ([`ModelMisfit`]), bracketed to ±`offset_search_mm` around the integrated depth.
//!
//! [`from_decoded`] is the one path from a decoded capture to a reconstruction: `meb
//! reconstruct`, `meb demo` and the hardware-in-the-loop tests all call it, with the
//! decoded-capture settings of [`ReconstructConfig::decoded_capture`].

use crate::demod::Decoded;
use crate::integrate::{
    BilateralConfig, Confidence, IntegrateConfig, IntegrateError, Integration, SurfaceEvidence,
    integrate_surface,
};
use crate::photometric::lights::moved_depth;
use crate::photometric::{
    Lights, ModelMisfit, PhotometricConfig, PhotometricError, PhotometricResult, estimate_normals,
};
use crate::rig::{Projection, Rig};
pub use crate::timing::StageTiming;
use crate::types::{LedImages, NormalField};
use ndarray::{Array2, Zip};
use std::time::Instant;
use thiserror::Error;

/// Bilateral reweightings, or two-LED alternations, of the near-field passes before the last
/// (they only feed the next pass's light vectors).
const EARLY_PASS_REWEIGHTINGS: usize = 8;

/// Bilateral stiffness k of reconstructions. Stiffer than the paper's 2: on Suzanne (out-of-plane
/// rig, through `meb reconstruct`) k = 2, 5, 8, 10, 13, 20 gave a depth RMSE of 6.72, 6.12,
/// 5.68, 5.11, 5.51, 5.33 mm before two-LED pixels used the albedo; with it k = 10 gives 3.97 /
/// 4.02 / 4.78 / 3.46 mm on simulator seeds 1–4 (other k not re-measured). Plain normal
/// integration keeps the paper's k, which leans less on smooth curved surfaces (Quéau's vase:
/// NRMSE 0.35 % at k = 2, 0.67 % at k = 10).
const BILATERAL_STIFFNESS: f64 = 10.0;

/// Width in mm of the bracket at which the golden-section search for a part's depth offset
/// stops (far below the depth accuracy; each step costs one misfit evaluation).
const OFFSET_TOLERANCE_MM: f64 = 0.01;

/// Relative residual at which conjugate gradients stops in the passes before the last: their
/// depth only places the next pass's light vectors, which a 10⁻⁵ residual leaves unchanged.
const EARLY_PASS_TOLERANCE: f64 = 1e-5;

/// Settings of the whole reconstruction.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReconstructConfig {
    /// Photometric stereo.
    pub photometric: PhotometricConfig,
    /// Normal integration.
    pub integrate: IntegrateConfig,
    /// Which light model to use.
    pub light_model: LightModel,
    /// Half-width in mm of the search for the depth offset in near-field passes (0 = off).
    pub offset_search_mm: f64,
}

impl Default for ReconstructConfig {
    fn default() -> Self {
        Self {
            photometric: PhotometricConfig::default(),
            integrate: IntegrateConfig {
                bilateral: BilateralConfig {
                    stiffness: BILATERAL_STIFFNESS,
                    ..BilateralConfig::default()
                },
                ..IntegrateConfig::default()
            },
            light_model: LightModel::default(),
            offset_search_mm: 60.0,
        }
    }
}

impl ReconstructConfig {
    /// Settings for decoded captures. They are the defaults: with the decoder's noise map the
    /// shadow test is statistical per LED ([`crate::photometric::solve`]), which replaced a
    /// fixed 7 % ratio (an LED image's noise can be 3.5 times the level noise, so grazing and
    /// shadowed values were mixed up; the ratio hid that at the cost of coverage).
    pub fn decoded_capture() -> Self {
        Self::default()
    }
}

/// Distant or near-field light vectors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LightModel {
    /// L_i = L_i(0) for every pixel (the thesis' model).
    Distant,
    /// Per-pixel L_i(X(p)), refined over this many extra PS ↔ integration passes.
    NearField {
        /// Passes after the first.
        refinements: usize,
    },
}

impl Default for LightModel {
    fn default() -> Self {
        Self::NearField { refinements: 3 }
    }
}

/// Errors of the reconstruction stage.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ReconstructError {
    /// The rig cannot be used.
    #[error("rig: {0}")]
    Rig(String),
    /// Photometric stereo failed.
    #[error(transparent)]
    Photometric(#[from] PhotometricError),
    /// Integration failed.
    #[error(transparent)]
    Integrate(#[from] IntegrateError),
}

/// Normals, albedo, depth and timings.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// The last photometric solve.
    pub photometric: PhotometricResult,
    /// The last integration.
    pub integration: Integration,
    /// Per-stage timings in order.
    pub timings: Vec<StageTiming>,
}

impl Reconstruction {
    /// Normals of every reconstructed pixel: measured where three or more LEDs lit it, the
    /// integrator's choice for two-LED and filled pixels; the mask is the reconstructed pixels.
    pub fn surface_normals(&self) -> NormalField {
        let measured = &self.photometric.field;
        let mut normals = measured.normals.clone();
        Zip::indexed(&self.integration.confidence).for_each(|(r, c), &k| {
            for j in 0..3 {
                normals[(r, c, j)] = match k {
                    Confidence::Measured => measured.normals[(r, c, j)],
                    Confidence::None => f32::NAN,
                    _ => self.integration.completed_normals[(r, c, j)],
                };
            }
        });
        NormalField {
            normals,
            albedo: measured.albedo.clone(),
            mask: self.integration.kept.clone(),
        }
    }

    /// How each pixel's depth is known.
    pub fn confidence(&self) -> &Array2<Confidence> {
        &self.integration.confidence
    }
}

/// Reconstructs a surface from LED images taken with `rig`.
pub fn reconstruct(
    images: &LedImages,
    rig: &Rig,
    mask: Option<&Array2<bool>>,
    noise: Option<&Array2<f32>>,
    config: &ReconstructConfig,
) -> Result<Reconstruction, ReconstructError> {
    if rig.leds.len() < 3 {
        return Err(ReconstructError::Rig(format!(
            "photometric stereo needs at least 3 LEDs, the rig has {}",
            rig.leds.len()
        )));
    }
    if rig.leds.len() != images.images.len() {
        return Err(ReconstructError::Rig(format!(
            "the rig has {} LEDs but there are {} LED images",
            rig.leds.len(),
            images.images.len()
        )));
    }
    config.integrate.validate()?;
    let projection = rig.camera.projection();
    let mut timings = Vec::new();
    let mut time = |stage: String, start: Instant| {
        timings.push(StageTiming {
            stage,
            ms: start.elapsed().as_secs_f64() * 1e3,
        })
    };
    let passes = match config.light_model {
        LightModel::Distant => 1,
        LightModel::NearField { refinements } => refinements + 1,
    };
    let distant = Lights::Distant(
        rig.distant_light_vectors()
            .iter()
            .map(|l| l * Lights::near_field_scale(rig))
            .collect(),
    );
    let mut object_mask = mask.cloned();
    let mut previous: Option<(PhotometricResult, Integration)> = None;
    for pass in 0..passes {
        let start = Instant::now();
        let depth = previous.as_ref().map(|(_, i)| &i.depth.depth_mm);
        let lights = match config.light_model {
            LightModel::Distant => distant.clone(),
            LightModel::NearField { .. } => Lights::near_field(rig, depth),
        };
        let ps = estimate_normals(
            images,
            &lights,
            object_mask.as_ref(),
            noise,
            &config.photometric,
        )?;
        time(format!("photometric stereo (pass {})", pass + 1), start);
        object_mask.get_or_insert_with(|| ps.object_mask.clone());
        let start = Instant::now();
        let evidence = SurfaceEvidence {
            field: &ps.field,
            planes: &ps.planes,
            fill: Some(&ps.fill),
        };
        // Early passes only feed the light vectors of the next: a few reweightings (or
        // two-LED alternations) and a looser solve suffice.
        let mut integrate_config = config.integrate.clone();
        if pass + 1 < passes {
            integrate_config.bilateral.max_iterations = integrate_config
                .bilateral
                .max_iterations
                .min(EARLY_PASS_REWEIGHTINGS);
            integrate_config.coverage.iterations = integrate_config
                .coverage
                .iterations
                .min(EARLY_PASS_REWEIGHTINGS);
            integrate_config.tolerance = integrate_config.tolerance.max(EARLY_PASS_TOLERANCE);
        }
        let mut integration = integrate_surface(&evidence, &projection, &integrate_config, depth)?;
        time(format!("integration (pass {})", pass + 1), start);
        if matches!(config.light_model, LightModel::NearField { .. })
            && config.offset_search_mm > 0.0
        {
            let start = Instant::now();
            place_parts(images, rig, noise, &ps, &mut integration, config);
            time(format!("depth offset search (pass {})", pass + 1), start);
        }
        previous = Some((ps, integration));
    }
    let (photometric, integration) = previous
        .ok_or_else(|| ReconstructError::Rig("no reconstruction pass was run".to_string()))?;
    Ok(Reconstruction {
        photometric,
        integration,
        timings,
    })
}

/// `depth` with the pixels of `part` moved by `offset` mm towards the camera
/// ([`moved_depth`]).
fn moved_part(
    depth: &Array2<f32>,
    parts: &Array2<u32>,
    part: u32,
    offset: f64,
    projection: &Projection,
) -> Array2<f32> {
    let mut out = depth.clone();
    Zip::from(&mut out).and(parts).for_each(|z, &p| {
        if p == part && z.is_finite() {
            *z = moved_depth(f64::from(*z), offset, projection) as f32;
        }
    });
    out
}

/// Moves every part of the integrated depth to the offset that minimises the Lambertian
/// misfit of its pixels lit by more than three LEDs (module docs); parts with too few such
/// pixels stay where the integrator put them.
fn place_parts(
    images: &LedImages,
    rig: &Rig,
    noise: Option<&Array2<f32>>,
    ps: &PhotometricResult,
    integration: &mut Integration,
    config: &ReconstructConfig,
) {
    let projection = rig.camera.projection();
    for part in 0..integration.parts as u32 {
        let pixels = constraining_pixels(ps, &integration.depth.depth_mm, |p| {
            integration.part[p] == part
        });
        let offset = best_offset(
            images,
            rig,
            noise,
            &integration.depth.depth_mm,
            &pixels,
            ps,
            config,
            config.offset_search_mm,
        );
        if offset != 0.0 {
            integration.depth.depth_mm = moved_part(
                &integration.depth.depth_mm,
                &integration.part,
                part,
                offset,
                &projection,
            );
        }
    }
}

/// The pixels chosen by `inside` that constrain absolute depth: lit by more than three LEDs,
/// with a depth; at most about 20 000, evenly spread.
fn constraining_pixels(
    ps: &PhotometricResult,
    depth: &Array2<f32>,
    inside: impl Fn((usize, usize)) -> bool,
) -> Vec<(usize, usize)> {
    let pixels: Vec<(usize, usize)> = ps
        .lit_count
        .indexed_iter()
        .filter(|(p, n)| **n > 3 && depth[*p].is_finite() && inside(*p))
        .map(|(p, _)| p)
        .collect();
    let step = pixels.len().div_ceil(20_000).max(1);
    pixels.into_iter().step_by(step).collect()
}

/// The offset (mm towards the camera, within ±`half_range`) of the depth of `pixels` that
/// minimises their Lambertian misfit (module docs); 0 with fewer than 16 pixels.
#[allow(clippy::too_many_arguments)]
fn best_offset(
    images: &LedImages,
    rig: &Rig,
    noise: Option<&Array2<f32>>,
    depth: &Array2<f32>,
    pixels: &[(usize, usize)],
    ps: &PhotometricResult,
    config: &ReconstructConfig,
    half_range: f64,
) -> f64 {
    if pixels.len() < 16 {
        return 0.0;
    }
    let lights = Lights::near_field(rig, Some(depth));
    let model = ModelMisfit::new(
        images,
        &lights,
        pixels,
        noise,
        &ps.noise_gains,
        &config.photometric,
    );
    let misfit = |offset: f64| model.at(offset);
    // Coarse scan, then golden-section refinement around the best sample.
    let half = half_range;
    let samples = 13;
    let step = 2.0 * half / (samples - 1) as f64;
    let (mut best, mut best_value) = (0.0, misfit(0.0));
    for i in 0..samples {
        let o = -half + step * i as f64;
        let v = misfit(o);
        if v < best_value {
            (best, best_value) = (o, v);
        }
    }
    let (mut a, mut b) = (best - step, best + step);
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let mut c = b - ratio * (b - a);
    let mut d = a + ratio * (b - a);
    let (mut fc, mut fd) = (misfit(c), misfit(d));
    while b - a > OFFSET_TOLERANCE_MM {
        if fc < fd {
            (b, d, fd) = (d, c, fc);
            c = b - ratio * (b - a);
            fc = misfit(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + ratio * (b - a);
            fd = misfit(d);
        }
    }
    let refined = 0.5 * (a + b);
    if misfit(refined) <= best_value {
        refined
    } else {
        best
    }
}

/// Reconstructs a decoded capture taken with `rig`: the pixels the decoder flagged as
/// saturated or under-exposed are left out ([`usable_led_images`]) and photometric stereo
/// weighs the LED images with their own noise ([`level_noise`]). Use
/// [`ReconstructConfig::decoded_capture`] unless a setting is deliberately changed.
pub fn from_decoded(
    decoded: &Decoded,
    rig: &Rig,
    mask: Option<&Array2<bool>>,
    config: &ReconstructConfig,
) -> Result<Reconstruction, ReconstructError> {
    reconstruct(
        &usable_led_images(decoded),
        rig,
        mask,
        Some(&level_noise(decoded)),
        config,
    )
}

/// The decoded LED images with the pixels the decoder flagged as saturated or under-exposed
/// set to NaN, so photometric stereo leaves them out.
pub fn usable_led_images(decoded: &Decoded) -> LedImages {
    let mut images = decoded.leds.clone();
    for image in &mut images.images {
        Zip::from(image)
            .and(&decoded.saturated)
            .and(&decoded.underexposed)
            .for_each(|v, &sat, &under| {
                if sat || under {
                    *v = f32::NAN;
                }
            });
    }
    images
}

/// Per-pixel noise σ_A of the decoded on-levels A_i. The decoder reports σ of one frame
/// sample; an on-level averages about frames/2 samples (each carrier is on half the time), so
/// σ_A = σ · √(2/frames).
pub fn level_noise(decoded: &Decoded) -> Array2<f32> {
    let frames = decoded.report.frames_used.max(2) as f32;
    decoded.noise.mapv(|s| s * (2.0 / frames).sqrt())
}
