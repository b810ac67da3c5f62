//! The reconstruction stage: LED images + rig → normals, albedo and depth, with near-field
//! refinement (SPEC §5–§6).
//!
//! The first pass uses light vectors at the plane z = 0; every further pass recomputes each
//! pixel's light vectors L_i(X(p)) at X(p) = (x, y, z(p)) from the previous depth, re-solves the
//! normals and re-integrates (warm-started). Depth zero is put on the object's outline, which
//! Integration fixes depth only up to a constant, and the light vectors depend on it: after each
//! integration the constant is chosen by a golden-section search that minimises the Lambertian
//! misfit of the pixels lit by more than three LEDs ([`model_misfit`]), bracketed to ±`offset
//! search` mm around the outline-anchored depth.
//!
//! [`from_decoded`] is the one path from a decoded capture to a reconstruction: `meb
//! reconstruct`, `meb demo` and the hardware-in-the-loop tests all call it, with the
//! decoded-capture settings of [`ReconstructConfig::decoded_capture`].

use crate::demod::Decoded;
use crate::integrate::{IntegrateConfig, IntegrateError, Integration, integrate_normals};
use crate::photometric::{
    Lights, PhotometricConfig, PhotometricError, PhotometricResult, estimate_normals, model_misfit,
};
use crate::rig::Rig;
pub use crate::timing::StageTiming;
use crate::types::LedImages;
use ndarray::{Array2, Zip};
use std::time::Instant;
use thiserror::Error;

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
            integrate: IntegrateConfig::default(),
            light_model: LightModel::default(),
            offset_search_mm: 60.0,
        }
    }
}

impl ReconstructConfig {
    /// Settings for decoded captures: an LED below 7 % of the pixel's brightest counts as
    /// shadowed. Near the terminator such grazing values sit at the noise floor and tilted the
    /// whole least-squares surface (sphere end to end, seed 7: 0.58 mm at the default 2 %,
    /// 0.18 mm at 7 % with 96.8 % of the ≥ 3-lit surface kept).
    pub fn decoded_capture() -> Self {
        let mut config = Self::default();
        config.photometric.shadow_fraction = 0.07;
        config
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
    let pitch = rig.camera.pitch_mm();
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
        let mut integration = integrate_normals(&ps.field, pitch, &config.integrate, depth)?;
        time(format!("integration (pass {})", pass + 1), start);
        if matches!(config.light_model, LightModel::NearField { .. })
            && config.offset_search_mm > 0.0
        {
            let start = Instant::now();
            let offset = best_depth_offset(images, rig, &integration.depth.depth_mm, &ps, config);
            integration
                .depth
                .depth_mm
                .mapv_inplace(|z| z + offset as f32);
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

/// The constant added to `depth` that minimises the Lambertian misfit (module docs).
fn best_depth_offset(
    images: &LedImages,
    rig: &Rig,
    depth: &Array2<f32>,
    ps: &PhotometricResult,
    config: &ReconstructConfig,
) -> f64 {
    // Only pixels lit by more than three LEDs constrain the offset; use at most ~20 000.
    let pixels: Vec<(usize, usize)> = ps
        .lit_count
        .indexed_iter()
        .filter(|(p, n)| **n > 3 && depth[*p].is_finite())
        .map(|(p, _)| p)
        .collect();
    if pixels.len() < 16 {
        return 0.0;
    }
    let step = pixels.len().div_ceil(20_000);
    let pixels: Vec<(usize, usize)> = pixels.into_iter().step_by(step).collect();
    let misfit = |offset: f64| {
        let shifted = depth.mapv(|z| z + offset as f32);
        model_misfit(
            images,
            &Lights::near_field(rig, Some(&shifted)),
            &pixels,
            &config.photometric,
        )
    };
    // Coarse scan, then golden-section refinement around the best sample.
    let half = config.offset_search_mm;
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
    for _ in 0..20 {
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
