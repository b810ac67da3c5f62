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
use crate::types::LedImages;
use ndarray::Array2;

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
    crate::stats::quantile(values, q).unwrap_or(0.0)
}

/// The object and its holes.
#[derive(Debug, Clone)]
pub(crate) struct ObjectRegion {
    /// Object pixels, holes included.
    pub object: Array2<bool>,
    /// Holes: object pixels with neither a normal nor a two-LED circle.
    pub fill: Array2<bool>,
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
    let usable = |o: &Outcome| matches!(o, Outcome::Solved(..) | Outcome::TwoLeds(..));
    let mut core = match given {
        Some(m) => Array2::from_shape_fn(m.dim(), |p| m[p] && usable(&outcome[p])),
        None => found_object(images, albedo, outcome, noise, config),
    };
    if given.is_none() {
        remove_small(&mut core, config.min_component_pixels);
    }
    let size = core.iter().filter(|&&m| m).count();
    let max_hole = (config.max_hole_fraction * size as f64) as usize;
    let mut fill = enclosed_holes(&core, max_hole);
    if let Some(m) = given {
        fill.zip_mut_with(m, |f, &inside| *f &= inside);
    }
    let mut object = core;
    object.zip_mut_with(&fill, |o, &f| *o |= f);
    ObjectRegion { object, fill }
}

/// Usable pixels that pass the brightness and albedo tests (module docs).
fn found_object(
    images: &LedImages,
    albedo: &Array2<f32>,
    outcome: &Array2<Outcome>,
    noise: Option<&Array2<f32>>,
    config: &MaskConfig,
) -> Array2<bool> {
    let shape = albedo.dim();
    let brightest = Array2::from_shape_fn(shape, |p| {
        images
            .images
            .iter()
            .map(|im| im[p])
            .fold(f32::NEG_INFINITY, f32::max)
    });
    let bright_ref = quantile(brightest.iter().copied(), 0.99);
    let albedo_ref = quantile(albedo.iter().copied(), 0.99);
    Array2::from_shape_fn(shape, |p| {
        let albedo_ok = match outcome[p] {
            Outcome::Solved(..) => albedo[p] >= config.relative_albedo * albedo_ref,
            Outcome::TwoLeds(..) => true,
            _ => return false,
        };
        let signal_ok = match noise {
            Some(n) => brightest[p] >= config.snr_threshold * n[p].max(f32::MIN_POSITIVE),
            None => brightest[p] >= config.relative_brightness * bright_ref,
        };
        signal_ok && albedo_ok
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

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
                Outcome::Solved(Vector3::z(), 0.5, 3)
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
