//! The reconstruction stage: LED images + rig → normals, albedo and depth, with near-field
//! refinement (docs/maths/photometric-stereo.md#the-near-field-loop).
//!
//! The first pass uses light vectors at the plane z = 0; every further pass recomputes each pixel's
//! light vectors L_i(X(p)) at the point X(p) of its ray at the previous depth, re-solves the
//! normals and re-integrates (warm-started). Pixels lit by two LEDs and holes inside the object are
//! integrated with the rest ([`crate::integrate::coverage`]). Integration fixes depth only up to a
//! constant per separate part of the object (a scale for a perspective camera): per piece of the
//! mask, and per part the bilateral integrator cut off along a depth discontinuity. The light
//! vectors depend on it: after each integration every part's constant is chosen by a
//! one-dimensional search (Brent's method) that minimises the Lambertian misfit of its pixels lit
//! by more than three LEDs ([`ModelMisfit`](crate::photometric::ModelMisfit), module `offset`),
//! bracketed to ±`offset_search_mm` around the integrated depth in the first pass, and to a few mm
//! around the offset that puts it back on the previous pass's depth in the later ones (the whole
//! range again when the minimum lies at that bracket's edge).
//!
//! [`reconstruct`] is the one path from LED images or a decoded capture ([`Source`]) to a
//! reconstruction: `meb reconstruct`, `meb demo` and the hardware-in-the-loop tests call it with
//! a decoded capture and the settings of [`ReconstructConfig::decoded_capture`]. `meb video` calls
//! the same path with a [`WarmStart`] from the previous window ([`Request::warm`]): the first
//! pass's light vectors come from the previous depth instead of z = 0, each part's offset is
//! carried over in closed form (the median offset that puts the integrated depth on the previous
//! one) and kept unless the misfit clearly prefers another in a bracket of a few mm (a t-test
//! over bands of the part, [`OFFSET_PREFERENCE_T`]); a preferred offset is blended with the
//! carried one by a prior across windows ([`WARM_OFFSET_GAIN`]), and the integrator starts from
//! the previous depth with looser settings than a cold window's early passes (one two-LED
//! alternation, [`pass_integration`]). One pass is normally enough: a second runs only when the
//! depth moved more than [`WARM_LIGHTS_MOVED_MM`] from the one its light vectors were computed
//! at. A warm result that strays from its start is redone cold. A warm window is reconstructed
//! inside the previous depth's bounding box grown by [`ROI_MARGIN_PX`] (its region of interest,
//! module `roi`; a decode's usable images are made for that region alone, module `inputs`) and
//! pasted back into the full frame, or kept there for a caller that pastes only what it needs
//! ([`reconstruct_extent`], [`Extent`]); an object that reaches the region's edge is
//! reconstructed on the full frame instead. A window of `meb video` with nothing to start
//! from (the first) starts from its own reconstruction binned 2×2, itself started the same
//! way while large enough ([`ReconstructConfig::coarse_start`], module `coarse`; a window
//! whose warm start strayed is redone that way too), and a window decoded only around the
//! object is reconstructed there and kept there ([`Request::region`],
//! [`RegionReconstruction`]).
//!
//! Every result carries a verdict on whether its depth rests on what the LEDs measured (module
//! `support`: enough of the surface lit by three or more LEDs, every part placed by its
//! offset search). The commands refuse an
//! implausible result unless `--force`; a warm result found implausible is redone cold.

use crate::demod::Decoded;
use crate::integrate::{
    AutoConfig, BilateralConfig, Confidence, IntegrateConfig, IntegrateError, Integration,
    IntegrationWorkspace, SurfaceEvidence, integrate_surface_with,
};
use crate::photometric::highlights::{HighlightShares, looks_glossy};
use crate::photometric::{
    Lights, PhotometricConfig, PhotometricError, PhotometricResult, estimate_normals,
};
use meb_core::rig::Rig;
pub use meb_core::timing::StageTiming;
use meb_core::types::{LedImages, NormalField};
use ndarray::{Array2, Zip};
use rayon::prelude::*;
use std::time::Instant;
use thiserror::Error;

pub mod acceptance;
mod coarse;
mod inputs;
mod offset;
mod region;
pub mod rig_check;
mod roi;
mod support;
pub use coarse::{COARSE_BIN, COARSE_MIN_PIXELS, bin_decoded};
pub use inputs::{Source, level_noise, level_noise_factor, usable_led_images};
pub use offset::{
    OFFSET_PREFERENCE_T, WARM_OFFSET_BRACKET_MM, WARM_OFFSET_GAIN, WARM_WIDE_BRACKET_MM,
};
use offset::{OffsetPrior, Unplaced, place_parts};
pub use region::{Extent, RegionReconstruction};
pub use roi::ROI_MARGIN_PX;
use roi::Roi;
pub use support::{AbsoluteDepth, MIN_MEASURED_SHARE, Support};

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

/// Depth departure from the slopes (pixels) a decisive bilateral weight or a cut edge of the
/// automatic integrator (`--integrator auto`) must come with in reconstructions
/// ([`AutoConfig::min_jump_px`]). At k = 10 the decoder's noise alone makes weights decisive on
/// smooth surfaces. On the simulator's blobby shape (out-of-plane rig, 352×224, seed 1) least
/// squares gives 0.154 mm and the automatic integrator 0.169 mm (0.196 mm without this test);
/// on Suzanne (384×288, seeds 1–4) 3.93 / 3.90 / 4.30 / 3.34 mm against least squares'
/// 7.65 / 7.47 / 7.48 / 7.34 mm.
const AUTO_MIN_JUMP_PX: f64 = 0.5;

/// Median absolute depth change in mm, from the depth a warm pass's light vectors were computed
/// at to the depth it found, up to which a warm start stops after that pass. Near-field light
/// vectors L_i(X) = Φ_i (P_i − X) cos θ_i / |P_i − X|³
/// (docs/maths/photometric-stereo.md#light-vectors) move slowly with X: a point
/// moved by δ along its ray turns L_i by at most δ/|P_i − X| rad and changes its length by
/// about 3δ/|P_i − X|, mostly common to all LEDs (which only scales the albedo). On the thesis
/// rigs the LEDs stand 420–560 mm from the object, so 1.5 mm turns each L_i by ≤ 0.2° and
/// tilts the solved normals by at most [`WARM_LIGHTS_NORMAL_DEG`] (measured by the unit test
/// `stale_light_vectors_tilt_normals_by_less_than_the_stated_bound`), below the photometric
/// noise of a decoded capture. The turning ellipsoid's surface moves about 1–1.5 mm between
/// windows of 40 frames: at 1 mm, 10 of its 49 warm windows (2000 frames, 1280×720) ran a second
/// or third pass; at 1.5 mm none did, and the per-frame depth RMSE against truth every 20
/// frames stayed as it was (median 0.659 → 0.669 mm, mean 0.755 → 0.744 mm, worst 1.274 →
/// 1.195 mm; binned 2×2: median 0.422 mm either way, worst 1.154 → 1.102 mm).
pub const WARM_LIGHTS_MOVED_MM: f64 = 1.5;

/// Largest normal tilt in degrees from light vectors computed [`WARM_LIGHTS_MOVED_MM`] away
/// from the surface on the thesis-dynamic rig (see there).
pub const WARM_LIGHTS_NORMAL_DEG: f64 = 0.75;

/// Median absolute difference in mm from the warm start beyond which a warm result is redone
/// cold.
pub const WARM_MAX_MOVE_MM: f64 = 5.0;

/// Share of a warm result's pixels whose depth the warm start must know.
const WARM_MIN_OVERLAP: f64 = 0.9;

/// Relative residual at which conjugate gradients stops in the passes before the last: their
/// depth only places the next pass's light vectors, which a 10⁻⁵ residual leaves unchanged.
const EARLY_PASS_TOLERANCE: f64 = 1e-5;

/// Two-LED alternations of a warm pass's integration. A warm start takes the two-LED pixels'
/// slopes (and their albedo side) from the previous window's depth before the first solve, so
/// the later alternations only refine the slope along each pixel's line of possible normals, as
/// the next window's first solve does again: on the 1280×720 turning ellipsoid (400 frames,
/// 10 windows against truth every 20 frames) one alternation instead of up to 8 left every
/// window's depth RMSE within 0.1 µm (0.5155–0.7970 mm) and cut its CG iterations from a median
/// 13 to 6 with [`WARM_SOLVE_TOLERANCE`].
const WARM_COVERAGE_ALTERNATIONS: usize = 1;

/// Relative residual at which conjugate gradients stops in a warm pass. It starts next to the
/// answer; on the turning ellipsoid 10⁻⁴ instead of 10⁻⁵ moved no window's depth RMSE by more
/// than 0.1 µm. 10⁻³ instead of 10⁻⁴ (1280×720, 600 frames, 15 windows against
/// truth every 20 frames) moved them by −1.1 to +2.4 µm (median +0.6 µm, on RMSEs of
/// 0.52–0.80 mm) and cut a warm window's iterations from 5 to 3 (≈ 2 ms of a 40 ms 3-D frame).
const WARM_SOLVE_TOLERANCE: f64 = 1e-3;

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
    /// Start a decoded capture of 640×360 pixels or more that has no warm start (or whose warm
    /// start strayed) from its own reconstruction binned 2×2 (started the same way while large
    /// enough) instead of four cold passes at full resolution (module `coarse`; `meb video`).
    #[serde(default)]
    pub coarse_start: bool,
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
                auto: AutoConfig {
                    min_jump_px: AUTO_MIN_JUMP_PX,
                    ..AutoConfig::default()
                },
                ..IntegrateConfig::default()
            },
            light_model: LightModel::default(),
            offset_search_mm: 60.0,
            coarse_start: false,
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
    /// The images were decoded in a region of the frame that does not hold the whole object.
    #[error("decoded region: {0}")]
    Region(String),
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
    /// Whether it started from a warm start.
    pub start: Start,
    /// Whether the depth rests on what the LEDs measured (\[`support`\]): a result to refuse
    /// unless its verdict is plausible.
    pub support: Support,
}

/// How a reconstruction started.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum Start {
    /// From the plane z = 0 (no warm start).
    Cold,
    /// From a warm start, accepted.
    Warm {
        /// Passes run.
        passes: usize,
        /// Median absolute depth difference from the warm start, mm.
        moved_mm: f64,
    },
    /// From the window's own reconstruction binned 2×2 (a cold window, module `coarse`),
    /// accepted.
    Coarse {
        /// Full-resolution passes run.
        passes: usize,
        /// Median absolute depth difference from the binned depth, mm.
        moved_mm: f64,
    },
    /// A warm start was rejected and the reconstruction redone cold.
    Redone {
        /// Why the warm result was not trusted.
        reason: String,
    },
}

/// Where a video's previous 3-D frame left the object, to start the next window from (in 40 ms
/// the object moves a few mm at most): light vectors at its depth, each part's offset carried
/// from it, integration warm-started from it.
#[derive(Debug, Clone)]
pub struct WarmStart {
    /// Depth in mm (NaN where it was not reconstructed).
    pub depth_mm: Array2<f32>,
    /// Whether the surface was glossy ([`crate::photometric::highlights::looks_glossy`]): the
    /// next reconstruction then rejects highlight tails from its first pass
    /// ([`crate::photometric::PhotometricConfig::reject_highlight_tails`]).
    pub glossy: bool,
}

impl WarmStart {
    /// The warm start a reconstruction leaves for the next window.
    pub fn of(reconstruction: &Reconstruction) -> Self {
        Self {
            depth_mm: reconstruction.integration.depth.depth_mm.clone(),
            glossy: looks_glossy(&reconstruction.photometric),
        }
    }
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

/// Where and from what a reconstruction starts, beside its [`ReconstructConfig`]; the default
/// reconstructs the object the images show over the whole frame, from scratch.
#[derive(Debug, Clone, Copy, Default)]
pub struct Request<'a> {
    /// The pixels to reconstruct; `None` finds the object in the images.
    pub mask: Option<&'a Array2<bool>>,
    /// The previous result to start from ([`WarmStart`]): `meb video` passes the previous
    /// window's.
    pub warm: Option<&'a WarmStart>,
    /// The region of the camera's frame the source covers, when it covers only part of it (a
    /// capture decoded with a region of interest, as `meb video` decodes around the object): the
    /// rig's camera is cut to it, every pixel keeping its ray ([`meb_core::rig::Camera::cropped`]),
    /// and the warm start (of the whole frame) with it. An object that reaches an edge of the
    /// region that is not an edge of the frame may go on beyond it, so it is refused
    /// ([`ReconstructError::Region`]). The mask, if any, is the region's.
    pub region: Option<crate::demod::Roi>,
}

/// Reconstructs a surface: photometric stereo on `source` with the lights of `rig`, the
/// near-field loop and the depth offset search of `config`, and normal integration.
///
/// With [`Request::warm`] and the near-field model ([`WarmStart`]) it starts from the previous
/// depth: light vectors at the previous depth, each part's offset searched within
/// ±[`WARM_OFFSET_BRACKET_MM`] of the offset carried from it (kept unless the misfit clearly
/// prefers another, [`OFFSET_PREFERENCE_T`], and then moved by the share [`WARM_OFFSET_GAIN`]
/// of the way to it), integration warm-started with loose settings ([`pass_integration`]), and
/// passes stopped once the depth lies within [`WARM_LIGHTS_MOVED_MM`] (median) of the one the
/// pass's light vectors came from. A warm result that moved more than [`WARM_MAX_MOVE_MM`]
/// (median) from the start, clearly preferred an offset at the edge of the wider bracket
/// ([`WARM_WIDE_BRACKET_MM`]), covers pixels the start did not know, or failed, is redone cold
/// ([`Start::Redone`]). The warm passes run in the start's region of interest (the box of its
/// depth and the mask grown by [`ROI_MARGIN_PX`]) unless the object reaches that region's edge.
///
/// ```
/// use meb_core::rig::Rig;
/// use meb_core::types::LedImages;
/// use meb_pipeline::reconstruct::{ReconstructConfig, ReconstructError, Request, Source, reconstruct};
/// use ndarray::Array2;
///
/// // Four blank LED images of the thesis' out-of-plane rig: nothing to reconstruct.
/// let rig = Rig::preset("thesis-out-of-plane").expect("a built-in rig");
/// let blank = Array2::<f32>::zeros((rig.camera.height, rig.camera.width));
/// let images = LedImages { images: vec![blank; 4] };
/// let source = Source::Images { images: &images, noise: None };
/// let result = reconstruct(source, &rig, &ReconstructConfig::default(), Request::default());
/// assert!(result.is_err(), "an empty scene is refused, not reconstructed");
/// ```
pub fn reconstruct(
    source: Source<'_>,
    rig: &Rig,
    config: &ReconstructConfig,
    request: Request<'_>,
) -> Result<Reconstruction, ReconstructError> {
    reconstruct_extent(source, rig, config, request)
        .map(|extent| extent.into_frame(&rig.camera.projection()))
}

/// [`reconstruct`], with a result that ran in a region of the frame kept there
/// ([`Extent::Region`]): `meb video` pastes into the frame only what it writes.
pub fn reconstruct_extent(
    source: Source<'_>,
    rig: &Rig,
    config: &ReconstructConfig,
    request: Request<'_>,
) -> Result<Extent, ReconstructError> {
    // A decode brought to full depth carries its image scale in its noise.
    let floors = source.noise_gain_floors();
    let scaled;
    let config = if floors.is_empty() {
        config
    } else {
        scaled = ReconstructConfig {
            photometric: PhotometricConfig {
                noise_gain_floors: floors,
                ..config.photometric.clone()
            },
            ..config.clone()
        };
        &scaled
    };
    match request.region {
        Some(region) => region::in_region(source, region, rig, config, request).map(Extent::Region),
        None => reconstruct_inputs(
            &source,
            rig,
            request.mask,
            config,
            request.warm,
            ColdPasses::All,
        ),
    }
}

/// How many passes a cold reconstruction runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ColdPasses {
    /// All of them, the last with the configured integration settings.
    All,
    /// Until a pass moves the depth by at most [`WARM_LIGHTS_MOVED_MM`] (median) from the one
    /// its light vectors came from, as warm passes stop: for a reconstruction that only starts
    /// another ([`coarse`]), whose light vectors its depth merely places. On the 1280×720 turning
    /// ellipsoid's first window binned 2×2 the passes moved the depth by 1.64, 0.052 and
    /// 0.006 mm: the fourth (≈ 22 ms) changed nothing the full-resolution pass would see.
    UntilSettled,
}

/// [`reconstruct`] of `inputs` over the whole frame, its cold passes run as `cold` says.
fn reconstruct_inputs(
    inputs: &Source,
    rig: &Rig,
    mask: Option<&Array2<bool>>,
    config: &ReconstructConfig,
    warm: Option<&WarmStart>,
    cold: ColdPasses,
) -> Result<Extent, ReconstructError> {
    if rig.leds.len() < 3 {
        return Err(ReconstructError::Rig(format!(
            "photometric stereo needs at least 3 LEDs, the rig has {}",
            rig.leds.len()
        )));
    }
    if rig.leds.len() != inputs.leds() {
        return Err(ReconstructError::Rig(format!(
            "the rig has {} LEDs but there are {} LED images",
            rig.leds.len(),
            inputs.leds()
        )));
    }
    config.integrate.validate()?;
    let mut timings = Vec::new();
    let shape = (rig.camera.height, rig.camera.width);
    let near_field = matches!(config.light_model, LightModel::NearField { .. });
    let mut start = Start::Cold;
    // The full frame's images and noise, made once if a pass needs them.
    let full = std::cell::OnceCell::new();
    let full_frame = || full.get_or_init(|| inputs.full());
    // The warm passes from `warm`: the reconstruction (with the region of interest it is cut
    // to, when it ran in one), or why it cannot be trusted.
    let attempt = |warm: &WarmStart, timings: &mut Vec<StageTiming>| {
        let in_region = Roi::around(&warm.depth_mm, mask, ROI_MARGIN_PX)
            .and_then(|roi| warm_in_region(&roi, inputs, rig, mask, config, warm, timings));
        let (roi, result) = match in_region {
            Some((roi, result)) => (Some(roi), result),
            None => {
                let (images, noise) = full_frame();
                let result = passes(
                    images,
                    rig,
                    mask,
                    noise.as_deref(),
                    config,
                    Some(warm),
                    ColdPasses::All,
                    timings,
                );
                (None, result)
            }
        };
        match result {
            Ok((photometric, integration, Ok(start), support)) => {
                Ok((roi, photometric, integration, start, support))
            }
            Ok((_, _, Err(reason), _)) => Err(reason),
            Err(error) => Err(format!("the warm-started reconstruction failed: {error}")),
        }
    };
    let done = |(roi, photometric, integration, start, support), timings| {
        let reconstruction = Reconstruction {
            photometric,
            integration,
            timings,
            start,
            support,
        };
        match roi {
            Some(roi) => Extent::Region(RegionReconstruction::new(roi, reconstruction)),
            None => Extent::Frame(reconstruction),
        }
    };
    if let Some(warm) = warm.filter(|w| near_field && w.depth_mm.dim() == shape) {
        match attempt(warm, &mut timings) {
            Ok(parts) => return Ok(done(parts, timings)),
            Err(reason) => start = Start::Redone { reason },
        }
    }
    let coarse = (near_field && config.coarse_start && mask.is_none())
        .then(|| coarse::start(inputs, rig, config, &mut timings))
        .flatten();
    if let Some(coarse) = coarse {
        match attempt(&coarse, &mut timings) {
            Ok((roi, photometric, integration, kept, support)) => {
                let start = match (start, kept) {
                    (Start::Redone { reason }, _) => Start::Redone {
                        reason: format!("{reason}; redone from the window binned 2×2"),
                    },
                    (_, Start::Warm { passes, moved_mm }) => Start::Coarse { passes, moved_mm },
                    (_, kept) => kept,
                };
                return Ok(done(
                    (roi, photometric, integration, start, support),
                    timings,
                ));
            }
            Err(reason) => {
                start = match start {
                    Start::Redone { reason: first } => Start::Redone {
                        reason: format!("{first}; the start from the window binned 2×2: {reason}"),
                    },
                    _ => Start::Redone {
                        reason: format!("the start from the window binned 2×2: {reason}"),
                    },
                }
            }
        }
    }
    let (images, noise) = full_frame();
    let (photometric, integration, _, support) = passes(
        images,
        rig,
        mask,
        noise.as_deref(),
        config,
        None,
        cold,
        &mut timings,
    )?;
    Ok(Extent::Frame(Reconstruction {
        photometric,
        integration,
        timings,
        start,
        support,
    }))
}

/// The warm [`passes`] inside the region of interest `roi` ([`roi`]), with their results cut to
/// it; `None` when the object reached the region's edge (the full frame is needed).
#[allow(clippy::too_many_arguments)]
fn warm_in_region(
    roi: &Roi,
    inputs: &Source,
    rig: &Rig,
    mask: Option<&Array2<bool>>,
    config: &ReconstructConfig,
    warm: &WarmStart,
    timings: &mut Vec<StageTiming>,
) -> Option<(Roi, PassesResult)> {
    let started = Instant::now();
    let (region_images, region_noise) = inputs.region(roi)?;
    let region_rig = roi.cut_rig(rig);
    let region_mask = mask.map(|m| roi.cut(m));
    let region_warm = WarmStart {
        depth_mm: roi.cut(&warm.depth_mm),
        glossy: warm.glossy,
    };
    timings.push(StageTiming::since(
        "region of interest, warm".to_string(),
        started,
    ));
    let result = passes(
        &region_images,
        &region_rig,
        region_mask.as_ref(),
        region_noise.as_ref(),
        config,
        Some(&region_warm),
        ColdPasses::All,
        timings,
    );
    match result {
        Ok((photometric, ..)) if roi.reached_edge(&photometric.object_mask) => None,
        result => Some((roi.clone(), result)),
    }
}

/// What [`passes`] returns: the last pass's photometric stereo and integration, how the result
/// started or why a warm one cannot be trusted, and its support ([`support`]).
type PassesResult = Result<
    (
        PhotometricResult,
        Integration,
        Result<Start, String>,
        Support,
    ),
    ReconstructError,
>;

/// The photometric stereo ↔ integration passes (module docs), cold or from `warm`, with how the
/// result started ([`Start::Cold`], or [`Start::Warm`] with the passes run and how far it moved)
/// or why a warm result cannot be trusted; a cold reconstruction runs its passes as `cold`
/// says.
#[allow(clippy::too_many_arguments)]
fn passes(
    images: &LedImages,
    rig: &Rig,
    mask: Option<&Array2<bool>>,
    noise: Option<&Array2<f32>>,
    config: &ReconstructConfig,
    warm: Option<&WarmStart>,
    cold: ColdPasses,
    timings: &mut Vec<StageTiming>,
) -> PassesResult {
    let projection = rig.camera.projection();
    let label = if warm.is_some() { ", warm" } else { "" };
    let mut time = |stage: &str, pass: usize, start: Instant| {
        timings.push(StageTiming::since(
            format!("{stage}{label} (pass {})", pass + 1),
            start,
        ))
    };
    let passes = match config.light_model {
        LightModel::Distant => 1,
        LightModel::NearField { refinements } => refinements + 1,
    };
    // The passes integrate on the same object mask: the integration graph is built once.
    let mut workspace = IntegrationWorkspace::new();
    let distant = Lights::Distant(
        rig.distant_light_vectors()
            .iter()
            .map(|l| l * Lights::near_field_scale(rig))
            .collect(),
    );
    let mut object_mask = mask.cloned();
    let mut previous: Option<(PhotometricResult, Integration)> = None;
    let mut verdict = Ok(0);
    // Parts a pass's offset search could not place (a part keeps its number from pass to pass).
    let mut unplaced = std::collections::BTreeMap::new();
    // Whether a pass scanned for every part's offset and judged the minimum.
    let mut scanned = false;
    // The last pass's depth change from the warm start, when its light vectors came from it.
    let mut moved_from_warm: Option<DepthChange> = None;
    // Highlight tails are rejected once the surface is known to be glossy: from the warm
    // start, or from the first pass whose highlights show it (that pass is solved again).
    let mut pass_config = config.clone();
    pass_config.photometric.reject_highlight_tails |= warm.is_some_and(|w| w.glossy);
    for pass in 0..passes {
        let start = Instant::now();
        let depth = previous
            .as_ref()
            .map(|(_, i)| &i.depth.depth_mm)
            .or(warm.map(|w| &w.depth_mm));
        let lights = match config.light_model {
            LightModel::Distant => distant.clone(),
            LightModel::NearField { .. } => Lights::near_field(rig, depth),
        };
        let solve = |photometric: &PhotometricConfig| {
            estimate_normals(images, &lights, object_mask.as_ref(), noise, photometric)
        };
        let mut ps = solve(&pass_config.photometric)?;
        if !pass_config.photometric.reject_highlight_tails && looks_glossy(&ps) {
            pass_config.photometric.reject_highlight_tails = true;
            ps = solve(&pass_config.photometric)?;
        }
        let config = &pass_config;
        time("photometric stereo", pass, start);
        object_mask.get_or_insert_with(|| ps.object_mask.clone());
        let start = Instant::now();
        let evidence = SurfaceEvidence {
            field: &ps.field,
            planes: &ps.planes,
            fill: Some(&ps.fill),
        };
        let integrate_config = pass_integration(config, pass + 1 == passes, warm.is_some());
        let mut integration = integrate_surface_with(
            &evidence,
            &projection,
            &integrate_config,
            depth,
            &mut workspace,
        )?;
        time("integration", pass, start);
        if matches!(config.light_model, LightModel::NearField { .. })
            && config.offset_search_mm > 0.0
        {
            let start = Instant::now();
            let prior = match (warm, depth) {
                (Some(_), Some(before)) => OffsetPrior::Warm(before),
                (None, Some(before)) => OffsetPrior::Previous(before),
                (_, None) => OffsetPrior::None,
            };
            match place_parts(images, rig, noise, &ps, &mut integration, config, prior) {
                Ok(placed) => {
                    unplaced.extend(placed.unplaced.into_iter().map(|u| (u.part, u)));
                    scanned |= placed.scanned;
                }
                Err(reason) => verdict = Err(reason),
            }
            time("depth offset search", pass, start);
        }
        // A warm pass's light vectors came from `depth`; once the depth found lies near it they
        // were right (WARM_LIGHTS_MOVED_MM) and another pass would change nothing material.
        // In a warm start's first pass the light vectors came from the warm depth itself: that
        // change is also how far the result moved from the warm start, if it is the last pass.
        let settled = match (warm, depth) {
            (Some(_), Some(lit_at)) => {
                let change = depth_change(&integration.depth.depth_mm, lit_at);
                let settled = change.median_mm <= WARM_LIGHTS_MOVED_MM;
                moved_from_warm = (pass == 0).then_some(change);
                settled
            }
            (None, Some(lit_at)) if cold == ColdPasses::UntilSettled => {
                depth_change(&integration.depth.depth_mm, lit_at).median_mm <= WARM_LIGHTS_MOVED_MM
            }
            _ => false,
        };
        previous = Some((ps, integration));
        if verdict.is_err() {
            break;
        }
        verdict = Ok(pass + 1);
        if settled {
            break;
        }
    }
    let (photometric, integration) = previous
        .ok_or_else(|| ReconstructError::Rig("no reconstruction pass was run".to_string()))?;
    let unplaced: Vec<Unplaced> = unplaced.into_values().collect();
    let mut support = support::judge(&integration, &unplaced, scanned);
    support.verdict = HighlightShares::of(&photometric).judge(support.verdict);
    let start = verdict.and_then(|passes| {
        let Some(warm) = warm else {
            return Ok(Start::Cold);
        };
        let moved = moved_from_warm
            .unwrap_or_else(|| depth_change(&integration.depth.depth_mm, &warm.depth_mm));
        let kept = integration.kept.iter().filter(|&&k| k).count();
        if !support.verdict.is_plausible() {
            Err(format!(
                "the warm result is implausible: {}",
                support.verdict.problems.join("; ")
            ))
        } else if moved.median_mm > WARM_MAX_MOVE_MM {
            Err(format!(
                "the depth moved {:.2} mm (median) from the warm start (more than {WARM_MAX_MOVE_MM} mm)",
                moved.median_mm
            ))
        } else if (moved.pixels as f64) < WARM_MIN_OVERLAP * kept as f64 {
            Err(format!(
                "the warm start knew the depth of only {} of {kept} reconstructed pixels",
                moved.pixels
            ))
        } else {
            Ok(Start::Warm {
                passes,
                moved_mm: moved.median_mm,
            })
        }
    });
    Ok((photometric, integration, start, support))
}

/// The integration settings of a pass: the configured ones for the last pass of a cold
/// reconstruction. Early passes only feed the light vectors of the next, so a few reweightings
/// (or two-LED alternations) and a looser solve suffice (at most 8, relative residual 10⁻⁵); a
/// warm pass begins next to the answer and takes those, with one alternation and a looser solve
/// still (10⁻³; the constants' docs give the measurements).
pub fn pass_integration(config: &ReconstructConfig, last: bool, warm: bool) -> IntegrateConfig {
    let mut integrate = config.integrate.clone();
    if !last || warm {
        integrate.bilateral.max_iterations = integrate
            .bilateral
            .max_iterations
            .min(EARLY_PASS_REWEIGHTINGS);
        integrate.coverage.iterations = integrate.coverage.iterations.min(EARLY_PASS_REWEIGHTINGS);
        integrate.tolerance = integrate.tolerance.max(EARLY_PASS_TOLERANCE);
    }
    if warm {
        integrate.coverage.iterations = integrate
            .coverage
            .iterations
            .min(WARM_COVERAGE_ALTERNATIONS);
        integrate.tolerance = integrate.tolerance.max(WARM_SOLVE_TOLERANCE);
    }
    integrate
}

/// How far one depth map lies from another over the pixels where both are finite.
#[derive(Debug, Clone, Copy, PartialEq)]
struct DepthChange {
    /// Median absolute difference, mm (infinite without shared pixels). The median, because
    /// the steep rims' depths swing by millimetres from pass to pass while the surface stays.
    median_mm: f64,
    /// Pixels with both depths.
    pixels: usize,
}

/// Pixels per parallel band of [`depth_change`].
const CHANGE_BAND: usize = 16_384;

/// The [`DepthChange`] from `before` to `after`.
fn depth_change(after: &Array2<f32>, before: &Array2<f32>) -> DepthChange {
    let change = |(a, b): (&f32, &f32)| (a.is_finite() && b.is_finite()).then(|| (a - b).abs());
    // Gathered in parallel bands (in order) where both arrays are contiguous and alike.
    let mut absolute: Vec<f32> = match (after.as_slice(), before.as_slice()) {
        (Some(a), Some(b)) if after.dim() == before.dim() => a
            .par_chunks(CHANGE_BAND)
            .zip(b.par_chunks(CHANGE_BAND))
            .flat_map_iter(|(a, b)| a.iter().zip(b).filter_map(change))
            .collect(),
        _ => after.iter().zip(before).filter_map(change).collect(),
    };
    let pixels = absolute.len();
    if pixels == 0 {
        return DepthChange {
            median_mm: f64::INFINITY,
            pixels,
        };
    }
    DepthChange {
        median_mm: f64::from(median(&mut absolute)),
        pixels,
    }
}

/// The median (upper median for an even count) of non-empty `values`, reordering them.
fn median(values: &mut [f32]) -> f32 {
    let middle = values.len() / 2;
    *values.select_nth_unstable_by(middle, f32::total_cmp).1
}

/// The rig check ([`rig_check`]) of `reconstruction`, a reconstruction of `decoded` with
/// `rig`: the usable LED images and level noise the reconstruction read, at its depth, over its
/// measured pixels (on a glossy surface, those outside every LED's lobe:
/// [`crate::photometric::highlights::glossy_lobes`]).
pub fn check_decoded_rig(
    decoded: &Decoded,
    rig: &Rig,
    reconstruction: &Reconstruction,
    config: &ReconstructConfig,
) -> rig_check::RigCheck {
    let depth = &reconstruction.integration.depth.depth_mm;
    let photometric = &reconstruction.photometric;
    let lights = Lights::near_field(rig, Some(depth));
    let (images, noise) = (usable_led_images(decoded), level_noise(decoded));
    let check = |mask: &Array2<bool>| {
        rig_check::check_rig(
            &images,
            Some(&noise),
            &photometric.noise_gains,
            rig,
            depth,
            mask,
        )
    };
    let lobes = crate::photometric::highlights::glossy_lobes(
        photometric,
        &lights,
        config.photometric.highlight_max_deg,
    );
    match lobes {
        // A rig whose intensities are wrong makes the brighter LEDs read above the others'
        // prediction nearly everywhere, as highlights would: when the lobes leave too few
        // pixels to judge, the whole surface is judged.
        Some(lobes) => {
            let outside = check(&(&photometric.field.mask & &lobes.mapv(|lobe| !lobe)));
            match outside.fit {
                rig_check::RigFit::Unjudged => check(&photometric.field.mask),
                _ => outside,
            }
        }
        None => check(&photometric.field.mask),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A still sphere's window as `meb video` passes it, its cold reconstruction and the warm
    /// start that leaves.
    pub(super) struct StillSphere {
        pub(super) rig: Rig,
        pub(super) images: LedImages,
        pub(super) noise: Array2<f32>,
        pub(super) config: ReconstructConfig,
        pub(super) warm: WarmStart,
        pub(super) cold: Reconstruction,
    }

    /// LED images of a sphere of radius 30 mm on a 320×180 thesis-dynamic rig with a flat
    /// noise map (the decoder's σ), reconstructed cold for the warm start.
    pub(super) fn still_sphere() -> StillSphere {
        use meb_sim::geometry::SurfaceMap;
        use meb_sim::lighting::led_images;
        use meb_sim::scene::{Scene, SceneObject, Shape};
        let mut rig = Rig::preset("thesis-dynamic").expect("preset");
        (rig.camera.width, rig.camera.height) = (320, 180);
        let scene = Scene::single(SceneObject::new(Shape::Sphere { radius_mm: 30.0 }));
        let map = SurfaceMap::render(&scene, &rig.camera, 0.0);
        let mut images = led_images(&map, &rig, 1.0);
        // Brightest reading 0.5 of full scale.
        let brightest = images.iter().flatten().fold(0.0f32, |m, &v| m.max(v));
        for image in &mut images {
            image.mapv_inplace(|v| v * 0.5 / brightest);
        }
        let images = LedImages { images };
        let noise = Array2::from_elem((180, 320), 1e-4);
        let config = ReconstructConfig::default();
        let cold = reconstruct(
            Source::Images {
                images: &images,
                noise: Some(&noise),
            },
            &rig,
            &config,
            Request::default(),
        )
        .expect("cold");
        StillSphere {
            warm: WarmStart::of(&cold),
            cold,
            rig,
            images,
            noise,
            config,
        }
    }

    /// `reconstruction` kept its warm start and was reconstructed in its region of interest.
    fn assert_warm_in_its_region(reconstruction: &Reconstruction) {
        assert!(
            matches!(reconstruction.start, Start::Warm { .. }),
            "{:?}",
            reconstruction.start
        );
        assert!(
            reconstruction
                .timings
                .iter()
                .any(|t| t.stage.starts_with("region of interest")),
            "the region of interest was not used"
        );
    }

    /// A warm window reconstructed in its region of interest and pasted back is the one the
    /// full frame gives: the same pixels, the same depth to float rounding.
    #[test]
    fn a_warm_window_in_its_region_equals_the_full_frames() {
        let sphere = still_sphere();
        let (full_ps, full, start, _) = passes(
            &sphere.images,
            &sphere.rig,
            None,
            Some(&sphere.noise),
            &sphere.config,
            Some(&sphere.warm),
            ColdPasses::All,
            &mut Vec::new(),
        )
        .expect("full frame");
        assert!(start.is_ok(), "{start:?}");
        let region = reconstruct(
            Source::Images {
                images: &sphere.images,
                noise: Some(&sphere.noise),
            },
            &sphere.rig,
            &sphere.config,
            Request {
                warm: Some(&sphere.warm),
                ..Request::default()
            },
        )
        .expect("in the region");
        assert_warm_in_its_region(&region);
        let worst =
            largest_depth_difference(&region.integration.depth.depth_mm, &full.depth.depth_mm);
        assert!(worst < 1e-3, "region vs full frame: {worst} mm");
        assert_eq!(region.integration.kept, full.kept);
        assert_eq!(region.integration.part, full.part);
        let (ps, full_ps) = (&region.photometric, &full_ps);
        assert_eq!(ps.object_mask, full_ps.object_mask);
        assert_eq!(ps.fill, full_ps.fill);
        assert_eq!(ps.lit_count, full_ps.lit_count);
        let pixels = |ps: &PhotometricResult| ps.planes.iter().map(|p| p.pixel).collect::<Vec<_>>();
        assert_eq!(pixels(ps), pixels(full_ps));
    }

    /// A decoded window is reconstructed warm from usable images and noise made for its region
    /// alone, exactly as from the full frame's [`usable_led_images`] and [`level_noise`].
    #[test]
    fn a_decoded_window_gives_what_its_full_frame_images_give() {
        let sphere = still_sphere();
        // A decode's report, with the sphere's images, noise and flags.
        let mut decoded = synthetic_decode();
        let dim = sphere.noise.dim();
        decoded.leds = sphere.images.clone();
        decoded.noise = Array2::from_shape_fn(dim, |(r, c)| 1e-3 * (1.0 + ((r * c) % 7) as f32));
        decoded.saturated = Array2::from_shape_fn(dim, |(r, c)| (r, c) == (90, 160));
        decoded.underexposed = Array2::from_shape_fn(dim, |(r, c)| r == 100 && c % 9 == 0);
        let from_region = reconstruct(
            Source::Decoded(&decoded),
            &sphere.rig,
            &sphere.config,
            Request {
                warm: Some(&sphere.warm),
                ..Request::default()
            },
        )
        .expect("from the decode");
        let from_full = reconstruct(
            Source::Images {
                images: &usable_led_images(&decoded),
                noise: Some(&level_noise(&decoded)),
            },
            &sphere.rig,
            &sphere.config,
            Request {
                warm: Some(&sphere.warm),
                ..Request::default()
            },
        )
        .expect("from the full frame's images");
        assert_warm_in_its_region(&from_region);
        let bits = |r: &Reconstruction| r.integration.depth.depth_mm.mapv(f32::to_bits);
        assert_eq!(bits(&from_region), bits(&from_full));
        let normals = |r: &Reconstruction| r.photometric.field.normals.mapv(f32::to_bits);
        assert_eq!(normals(&from_region), normals(&from_full));
        assert_eq!(from_region.start, from_full.start);
        // The flagged pixels have no normal.
        assert!(!from_region.photometric.field.mask[(90, 160)]);
        assert!(!from_region.photometric.field.mask[(100, 153)]);
    }

    /// An object that reaches an inner edge of the region may go on beyond it: the region's
    /// result is not used.
    #[test]
    fn an_object_beyond_its_region_is_left_to_the_full_frame() {
        let sphere = still_sphere();
        // A region around the sphere's middle alone.
        let mut middle = Array2::from_elem(sphere.warm.depth_mm.dim(), f32::NAN);
        middle[(90, 160)] = 0.0;
        let roi = Roi::around(&middle, None, 10).expect("a small region");
        let mut timings = Vec::new();
        let inputs = Source::Images {
            images: &sphere.images,
            noise: Some(&sphere.noise),
        };
        let result = warm_in_region(
            &roi,
            &inputs,
            &sphere.rig,
            None,
            &sphere.config,
            &sphere.warm,
            &mut timings,
        );
        assert!(result.is_none(), "a cut-off object was pasted back");
    }

    /// The largest difference in mm of two depth maps of one size, which must have depths at
    /// the same pixels.
    pub(super) fn largest_depth_difference(a: &Array2<f32>, b: &Array2<f32>) -> f32 {
        assert_eq!(a.dim(), b.dim());
        let mut worst = 0.0f32;
        for ((p, x), y) in a.indexed_iter().zip(b) {
            assert_eq!(x.is_finite(), y.is_finite(), "pixel {p:?}: {x} vs {y}");
            if x.is_finite() {
                worst = worst.max((x - y).abs());
            }
        }
        worst
    }

    /// The decode of the demodulator's default synthetic scene.
    pub(super) fn synthetic_decode() -> Decoded {
        use crate::demod::synthetic::{Scene, render};
        use crate::demod::{DecodeConfig, LedCount, decode};
        let scene = Scene::default();
        let (mut source, _, _) = render(&scene);
        let config = DecodeConfig {
            leds: LedCount::Fixed(scene.leds),
            ..DecodeConfig::default()
        };
        decode(&mut source, &config, &mut |_, _| {}).expect("decodes")
    }

    /// The decoder's saturated and under-exposed pixels become NaN in every LED image; the
    /// other readings are kept as decoded.
    #[test]
    fn flagged_pixels_are_left_out_of_every_led_image() {
        let mut decoded = synthetic_decode();
        decoded.saturated[(3, 4)] = true;
        decoded.underexposed[(10, 20)] = true;
        decoded.underexposed[(47, 63)] = true;
        let usable = usable_led_images(&decoded);
        assert_eq!(usable.images.len(), decoded.leds.images.len());
        for (image, original) in usable.images.iter().zip(&decoded.leds.images) {
            for ((p, v), o) in image.indexed_iter().zip(original) {
                let flagged = decoded.saturated[p] || decoded.underexposed[p];
                if flagged {
                    assert!(v.is_nan(), "pixel {p:?} kept");
                } else {
                    assert_eq!(v.to_bits(), o.to_bits(), "pixel {p:?}");
                }
            }
        }
        let nans = usable.images[0].iter().filter(|v| v.is_nan()).count();
        assert_eq!(nans, 3);
    }

    /// Cold passes until settled stop before the last once the depth stops moving, with the
    /// depth all passes give.
    #[test]
    fn cold_passes_until_settled_stop_early_with_the_same_depth() {
        let sphere = still_sphere();
        let run = |cold| {
            let mut timings = Vec::new();
            let (_, integration, start, _) = passes(
                &sphere.images,
                &sphere.rig,
                None,
                Some(&sphere.noise),
                &sphere.config,
                None,
                cold,
                &mut timings,
            )
            .expect("cold passes");
            assert_eq!(start, Ok(Start::Cold));
            let ran = timings
                .iter()
                .filter(|t| t.stage.starts_with("integration"))
                .count();
            (integration.depth.depth_mm, ran)
        };
        let (all, all_passes) = run(ColdPasses::All);
        let (settled, settled_passes) = run(ColdPasses::UntilSettled);
        let LightModel::NearField { refinements } = sphere.config.light_model else {
            panic!("the sphere is reconstructed in the near field");
        };
        assert_eq!(all_passes, refinements + 1);
        assert!(
            (2..all_passes).contains(&settled_passes),
            "{settled_passes} of {all_passes} passes"
        );
        let worst = largest_depth_difference(&settled, &all);
        let median = depth_change(&settled, &all).median_mm;
        eprintln!("settled after {settled_passes} of {all_passes} passes: {median} mm, {worst} mm");
        // The last of all passes integrates with the full settings, an early one loosely: the
        // rim differs most.
        assert!(
            median < 0.02 && worst < 0.25,
            "settled vs all passes: {median}, {worst} mm"
        );
    }

    #[test]
    fn the_depth_change_is_the_median_over_shared_pixels() {
        let before = Array2::from_shape_vec((1, 5), vec![0.0, 0.0, 0.0, 0.0, f32::NAN]).unwrap();
        // One rim pixel swings by 40 mm; the others move by 0.1–0.3 mm.
        let after = Array2::from_shape_vec((1, 5), vec![0.1, 0.2, 0.3, 40.0, 1.0]).unwrap();
        let change = depth_change(&after, &before);
        assert_eq!(change.pixels, 4);
        assert!((change.median_mm - 0.3).abs() < 1e-6, "{change:?}");
        let shifted = before.mapv(|z| z + 2.5);
        let moved = depth_change(&shifted, &before);
        assert!((moved.median_mm - 2.5).abs() < 1e-6, "{moved:?}");
        let nothing = depth_change(&after, &Array2::from_elem((1, 5), f32::NAN));
        assert_eq!(nothing.pixels, 0);
        assert!(nothing.median_mm.is_infinite());
    }
}
