//! The object: which pixels belong to it, and the holes it encloses.
//!
//! The thesis needed a black background; here, unless a mask is given, a pixel belongs to the
//! object when it was solved from three or more LEDs or lies on a two-LED circle, its brightest
//! LED stands `snr_threshold` noise σ above zero (or, without a noise map, above
//! `relative_brightness` of the image's bright pixels) and, where an albedo is known, it reaches
//! `relative_albedo` of the object's. Specks smaller than `min_component_pixels` are removed.
//! Pixels the object encloses (pieces of the rest no larger than `max_hole_fraction` of the
//! object, not touching the image border) are holes: shadowed or flagged pixels of the object
//! that the integrator fills. With a given mask the object is its solved and two-LED pixels and
//! their holes inside it.

use super::outcome::Outcome;
use crate::regions::{enclosed_holes, remove_small};
use meb_core::types::LedImages;
use ndarray::{Array2, Zip, s};
use rayon::prelude::*;
use std::ops::Range;

/// Image rows per parallel task of the object tests.
const ROWS_PER_TASK: usize = 8;

/// Thresholds of the automatic mask.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MaskConfig {
    /// Brightest LED value over noise σ a pixel needs (with a noise map).
    pub snr_threshold: f32,
    /// Brightest LED value as a fraction of the 99th percentile (without a noise map).
    pub relative_brightness: f32,
    /// Albedo as a fraction of the 99th-percentile albedo.
    pub relative_albedo: f32,
    /// Connected pieces smaller than this are dropped.
    pub min_component_pixels: usize,
    /// Largest hole the integrator fills, as a fraction of the object's pixels.
    pub max_hole_fraction: f64,
}

impl Default for MaskConfig {
    fn default() -> Self {
        Self {
            snr_threshold: 8.0,
            relative_brightness: 0.05,
            relative_albedo: 0.1,
            min_component_pixels: 64,
            max_hole_fraction: 0.25,
        }
    }
}

/// The `q`-quantile of the finite values, or 0 when there are none.
fn quantile(values: impl Iterator<Item = f32>, q: f64) -> f32 {
    meb_core::stats::quantile(values, q).unwrap_or(0.0)
}

/// The object and its holes.
#[derive(Debug, Clone)]
pub(crate) struct ObjectRegion {
    /// Object pixels, holes included.
    pub object: Array2<bool>,
    /// Holes: object pixels with neither a normal nor a two-LED circle.
    pub fill: Array2<bool>,
    /// Whether the object holds a usable pixel (one with a normal or a two-LED circle): every
    /// object that is not empty does, for holes are only looked for around usable pixels.
    pub usable: bool,
}

/// The object from the solve's outcomes (module docs).
pub(crate) fn object_region(
    images: &LedImages,
    albedo: &Array2<f32>,
    outcome: &Array2<Outcome>,
    given: Option<&Array2<bool>>,
    noise: Option<&Array2<f32>>,
    config: &MaskConfig,
) -> ObjectRegion {
    let mut core = match given {
        Some(m) => {
            let mut core = m.clone();
            core.zip_mut_with(outcome, |inside, o| *inside &= o.is_usable());
            core
        }
        None => found_object(images, albedo, outcome, noise, config),
    };
    // The object fills a small part of the frame: its pieces and holes lie inside its bounding
    // box grown by one pixel, where labelling them costs a fraction of the whole frame.
    let frame = core.dim();
    let mut fill = Array2::from_elem(frame, false);
    let Some((rows, cols)) = bounding_box(&core) else {
        return ObjectRegion {
            object: core,
            fill,
            usable: false,
        };
    };
    let (rows, cols) = if given.is_none() {
        let mut inner = core.slice(s![rows.clone(), cols.clone()]).to_owned();
        remove_small(&mut inner, config.min_component_pixels);
        core.slice_mut(s![rows, cols]).assign(&inner);
        // Without the specks the box may shrink.
        match bounding_box(&core) {
            Some(bounds) => bounds,
            None => {
                return ObjectRegion {
                    object: core,
                    fill,
                    usable: false,
                };
            }
        }
    } else {
        (rows, cols)
    };
    let inner = core.slice(s![rows.clone(), cols.clone()]).to_owned();
    let size = inner.iter().filter(|&&m| m).count();
    let max_hole = (config.max_hole_fraction * size as f64) as usize;
    // A hole of the box that does not touch its border is one of the frame (the one-pixel rim
    // is background wherever the box does not reach the frame's edge), and conversely.
    fill.slice_mut(s![rows, cols])
        .assign(&enclosed_holes(&inner, max_hole));
    if let Some(m) = given {
        fill.zip_mut_with(m, |f, &inside| *f &= inside);
    }
    let mut object = core;
    object.zip_mut_with(&fill, |o, &f| *o |= f);
    // The box holds a pixel of the core, which is usable.
    ObjectRegion {
        object,
        fill,
        usable: true,
    }
}

/// Rows and columns of the pixels set in `mask`, grown by one pixel within the frame; `None`
/// when none is set.
fn bounding_box(mask: &Array2<bool>) -> Option<(Range<usize>, Range<usize>)> {
    let (rows, cols) = mask.dim();
    let (mut top, mut bottom, mut left, mut right) = (usize::MAX, 0, usize::MAX, 0);
    for (r, row) in mask.outer_iter().enumerate() {
        let Some(first) = row.iter().position(|&m| m) else {
            continue;
        };
        let last = row.iter().rposition(|&m| m).unwrap_or(first);
        (top, bottom) = (top.min(r), r);
        (left, right) = (left.min(first), right.max(last));
    }
    (top != usize::MAX).then(|| {
        (
            top.saturating_sub(1)..(bottom + 2).min(rows),
            left.saturating_sub(1)..(right + 2).min(cols),
        )
    })
}

/// Usable pixels that pass the brightness and albedo tests (module docs).
fn found_object(
    images: &LedImages,
    albedo: &Array2<f32>,
    outcome: &Array2<Outcome>,
    noise: Option<&Array2<f32>>,
    config: &MaskConfig,
) -> Array2<bool> {
    let albedo_ref = quantile(albedo.iter().copied(), 0.99);
    match noise {
        Some(noise) => found_over_noise(images, albedo, albedo_ref, outcome, noise, config),
        None => found_over_bright_pixels(images, albedo, albedo_ref, outcome, config),
    }
}

/// Whether a pixel of `outcome` and `albedo` passes the albedo test against the reference
/// `albedo_ref`; `None` for a pixel that is not usable (module docs).
fn albedo_passes(
    outcome: Outcome,
    albedo: f32,
    albedo_ref: f32,
    config: &MaskConfig,
) -> Option<bool> {
    match outcome {
        Outcome::Solved => Some(albedo >= config.relative_albedo * albedo_ref),
        Outcome::TwoLeds => Some(true),
        _ => None,
    }
}

/// The object with a noise map: usable pixels whose albedo passes and whose brightest LED stands
/// `snr_threshold` σ above zero. Only usable pixels can pass, so the brightest LED is read at
/// those alone.
fn found_over_noise(
    images: &LedImages,
    albedo: &Array2<f32>,
    albedo_ref: f32,
    outcome: &Array2<Outcome>,
    noise: &Array2<f32>,
    config: &MaskConfig,
) -> Array2<bool> {
    let (rows, cols) = albedo.dim();
    let mut object = Array2::from_elem((rows, cols), false);
    let Some(flat) = object.as_slice_mut() else {
        unreachable!("a new array is in standard layout")
    };
    // By rows in parallel: a video window's object box is ≈ 110 000 pixels.
    flat.par_chunks_mut(cols.max(1))
        .enumerate()
        .with_min_len(ROWS_PER_TASK)
        .for_each_init(Vec::new, |brightest, (r, inside)| {
            brightest.resize(inside.len(), 0.0);
            images.brightest_in_row(r, brightest);
            let (outcome, albedo, noise) = (outcome.row(r), albedo.row(r), noise.row(r));
            for (c, inside) in inside.iter_mut().enumerate() {
                let Some(albedo_ok) = albedo_passes(outcome[c], albedo[c], albedo_ref, config)
                else {
                    continue;
                };
                *inside = albedo_ok
                    && brightest[c] >= config.snr_threshold * noise[c].max(f32::MIN_POSITIVE);
            }
        });
    object
}

/// The object without a noise map: usable pixels whose albedo passes and whose brightest LED
/// reaches `relative_brightness` of the image's bright pixels (its 99th percentile).
fn found_over_bright_pixels(
    images: &LedImages,
    albedo: &Array2<f32>,
    albedo_ref: f32,
    outcome: &Array2<Outcome>,
    config: &MaskConfig,
) -> Array2<bool> {
    let mut brightest = Array2::from_elem(albedo.dim(), f32::NEG_INFINITY);
    for image in &images.images {
        brightest.zip_mut_with(image, |b, &v| *b = b.max(v));
    }
    let bright_ref = quantile(brightest.iter().copied(), 0.99);
    let mut object = Array2::from_elem(albedo.dim(), false);
    Zip::from(&mut object)
        .and(outcome)
        .and(albedo)
        .and(&brightest)
        .for_each(|inside, &outcome, &albedo, &brightest| {
            let Some(albedo_ok) = albedo_passes(outcome, albedo, albedo_ref, config) else {
                return;
            };
            *inside = brightest >= config.relative_brightness * bright_ref && albedo_ok;
        });
    object
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bright disc with a dark hole and a bright speck: the object is the disc, the speck is
    /// dropped and the hole is kept for the integrator to fill.
    #[test]
    fn finds_the_disc_its_hole_and_drops_specks() {
        let shape = (40, 40);
        let inside = |(r, c): (usize, usize)| {
            let d2 = (r as f32 - 20.0).powi(2) + (c as f32 - 20.0).powi(2);
            d2 < 100.0
        };
        let hole = |(r, c): (usize, usize)| (19..22).contains(&r) && (19..22).contains(&c);
        let value = Array2::from_shape_fn(shape, |p| {
            if (inside(p) && !hole(p)) || p == (2, 2) {
                0.5
            } else {
                0.001
            }
        });
        let images = LedImages {
            images: vec![value.clone(), value.clone(), value.clone()],
        };
        let outcome = value.mapv(|v| {
            if v > 0.1 {
                Outcome::Solved
            } else {
                Outcome::Dark
            }
        });
        let albedo = value.mapv(|v| if v > 0.1 { 0.5 } else { f32::NAN });
        let noise = Array2::from_elem(shape, 0.002f32);
        let region = object_region(
            &images,
            &albedo,
            &outcome,
            None,
            Some(&noise),
            &MaskConfig::default(),
        );
        assert!(region.object[(20, 20)] && region.fill[(20, 20)]);
        assert!(!region.object[(0, 0)] && !region.fill[(0, 0)]);
        assert!(!region.object[(2, 2)], "speck removed");
        assert_eq!(region.fill.iter().filter(|&&f| f).count(), 9);
        let count = region.object.iter().filter(|&&m| m).count();
        assert!((250..=330).contains(&count), "{count}");
    }
}
