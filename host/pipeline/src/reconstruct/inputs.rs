//! What a reconstruction reads: LED images with their noise, or a decoded capture whose usable
//! images (the decoder's flagged pixels left out) and level noise are made only where a pass
//! needs them — a warm window's region of interest, or the full frame.

use super::roi::Roi;
use crate::demod::Decoded;
use meb_core::types::LedImages;
use ndarray::{Array2, ArrayView2, Zip};
use rayon::prelude::*;
use std::borrow::Cow;

/// The full frame's LED images and noise of a [`Source`].
type FullFrame<'a> = (Cow<'a, LedImages>, Option<Cow<'a, Array2<f32>>>);

/// What a reconstruction reads: a decoded capture, whose usable images and noise
/// ([`usable_led_images`], [`level_noise`]) are made only where a pass needs them (a warm
/// window's region of interest, or the full frame), or LED images with their noise.
#[derive(Debug, Clone, Copy)]
pub enum Source<'a> {
    /// A decoded capture: the pixels the decoder flagged as saturated or under-exposed are left
    /// out and photometric stereo weighs each LED image with its own noise. Use
    /// [`super::ReconstructConfig::decoded_capture`] with it.
    Decoded(&'a Decoded),
    /// LED images (one per LED of the rig, as fractions of full scale) and, when known, the
    /// per-pixel noise σ of one image.
    Images {
        /// The LED images.
        images: &'a LedImages,
        /// Per-pixel noise σ, when known.
        noise: Option<&'a Array2<f32>>,
    },
}

impl<'a> Source<'a> {
    /// The number of LED images.
    pub(super) fn leds(&self) -> usize {
        match self {
            Source::Images { images, .. } => images.images.len(),
            Source::Decoded(decoded) => decoded.leds.images.len(),
        }
    }

    /// Each LED image's least noise gain when a decode brought it to full depth (its image
    /// scale 1/(1 − ℓ_i), `crate::demod::depth`); empty for LED images given as such or decoded
    /// at full depth.
    pub(super) fn noise_gain_floors(&self) -> Vec<f64> {
        match self {
            Source::Decoded(decoded) if !decoded.report.modulation.is_full_depth() => {
                decoded.report.modulation.image_scale.clone()
            }
            _ => Vec::new(),
        }
    }

    /// The full frame's LED images and noise (borrowed where they are given).
    pub(super) fn full(&self) -> FullFrame<'a> {
        match *self {
            Source::Images { images, noise } => (Cow::Borrowed(images), noise.map(Cow::Borrowed)),
            Source::Decoded(decoded) => (
                Cow::Owned(usable_led_images(decoded)),
                Some(Cow::Owned(level_noise(decoded))),
            ),
        }
    }

    /// The LED images and noise cut to `roi`, or `None` when they are not of its frame's size
    /// (the full frame's passes then say what is wrong).
    pub(super) fn region(&self, roi: &Roi) -> Option<(LedImages, Option<Array2<f32>>)> {
        match self {
            Source::Images { images, noise } => {
                let sizes = images
                    .images
                    .iter()
                    .map(|i| i.dim())
                    .chain(noise.map(|n| n.dim()));
                roi.fits(sizes)
                    .then(|| (roi.cut_images(images), noise.map(|n| roi.cut(n))))
            }
            Source::Decoded(decoded) => {
                let flags = [decoded.saturated.dim(), decoded.underexposed.dim()];
                let sizes = decoded.leds.images.iter().map(|i| i.dim());
                let sizes = sizes.chain(flags).chain([decoded.noise.dim()]);
                roi.fits(sizes).then(|| {
                    (
                        usable_images_in(decoded, Some(roi)),
                        Some(level_noise_in(decoded, Some(roi))),
                    )
                })
            }
        }
    }
}

/// The decoded LED images with the pixels the decoder flagged as saturated or under-exposed
/// set to NaN, so photometric stereo leaves them out.
pub fn usable_led_images(decoded: &Decoded) -> LedImages {
    usable_images_in(decoded, None)
}

/// [`usable_led_images`] inside `roi` (the whole frame for `None`): one pass per image (no copy
/// to overwrite), the images side by side.
fn usable_images_in(decoded: &Decoded, roi: Option<&Roi>) -> LedImages {
    let (saturated, underexposed) = (
        area(&decoded.saturated, roi),
        area(&decoded.underexposed, roi),
    );
    let images = decoded
        .leds
        .images
        .par_iter()
        .map(|image| usable(area(image, roi), saturated, underexposed))
        .collect();
    LedImages { images }
}

/// `full` inside `roi` (all of it for `None`).
fn area<'a, T>(full: &'a Array2<T>, roi: Option<&Roi>) -> ArrayView2<'a, T> {
    roi.map_or_else(|| full.view(), |r| r.view(full))
}

/// `image` with its `saturated` or `underexposed` pixels set to NaN.
fn usable(
    image: ArrayView2<f32>,
    saturated: ArrayView2<bool>,
    underexposed: ArrayView2<bool>,
) -> Array2<f32> {
    Zip::from(image)
        .and(saturated)
        .and(underexposed)
        .map_collect(|&v, &sat, &under| if sat || under { f32::NAN } else { v })
}

/// Per-pixel noise σ_A of the decoded on-levels A_i. The decoder reports σ of one frame
/// sample; an on-level averages about frames/2 samples (each carrier is on half the time), so
/// σ_A = σ · √(2/frames).
pub fn level_noise(decoded: &Decoded) -> Array2<f32> {
    level_noise_in(decoded, None)
}

/// The factor √(2/frames) from a decode's σ to its level noise σ_A ([`level_noise`]).
pub fn level_noise_factor(decoded: &Decoded) -> f32 {
    let frames = decoded.report.frames_used.max(2) as f32;
    (2.0 / frames).sqrt()
}

/// [`level_noise`] inside `roi` (the whole frame for `None`).
fn level_noise_in(decoded: &Decoded, roi: Option<&Roi>) -> Array2<f32> {
    let factor = level_noise_factor(decoded);
    area(&decoded.noise, roi).mapv(|s| s * factor)
}
