//! Automatic object mask from the decoded albedo and the per-pixel signal-to-noise ratio.
//!
//! The thesis needed a black background; here a pixel belongs to the object when it was solved
//! (lit by enough LEDs), its brightest LED stands `snr_threshold` noise σ above zero (or, without
//! a noise map, above `relative_brightness` of the image's bright pixels) and its albedo reaches
//! `relative_albedo` of the object's. Specks smaller than `min_component_pixels` are removed.

use crate::types::LedImages;
use ndarray::Array2;
use std::collections::VecDeque;

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
}

impl Default for MaskConfig {
    fn default() -> Self {
        Self {
            snr_threshold: 8.0,
            relative_brightness: 0.05,
            relative_albedo: 0.1,
            min_component_pixels: 64,
        }
    }
}

/// The `q`-quantile of the finite values, or 0 when there are none.
fn quantile(values: impl Iterator<Item = f32>, q: f64) -> f32 {
    crate::stats::quantile(values, q).unwrap_or(0.0)
}

/// Object mask from LED images, solved albedo, the solved-pixel mask and an optional noise map.
pub fn object_mask(
    images: &LedImages,
    albedo: &Array2<f32>,
    solved: &Array2<bool>,
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
    let albedo_ref = quantile(
        albedo
            .iter()
            .zip(solved.iter())
            .filter(|(_, s)| **s)
            .map(|(a, _)| *a),
        0.99,
    );
    let mut mask = Array2::from_shape_fn(shape, |p| {
        if !solved[p] {
            return false;
        }
        let signal_ok = match noise {
            Some(n) => brightest[p] >= config.snr_threshold * n[p].max(f32::MIN_POSITIVE),
            None => brightest[p] >= config.relative_brightness * bright_ref,
        };
        signal_ok && albedo[p] >= config.relative_albedo * albedo_ref
    });
    remove_small_components(&mut mask, config.min_component_pixels);
    mask
}

/// Clears 4-connected pieces of `mask` with fewer than `min_pixels` pixels.
pub fn remove_small_components(mask: &mut Array2<bool>, min_pixels: usize) {
    let (rows, cols) = mask.dim();
    let mut seen = Array2::from_elem((rows, cols), false);
    let mut queue = VecDeque::new();
    let mut piece = Vec::new();
    for start in 0..rows * cols {
        let p = (start / cols, start % cols);
        if !mask[p] || seen[p] {
            continue;
        }
        piece.clear();
        seen[p] = true;
        queue.push_back(p);
        while let Some((r, c)) = queue.pop_front() {
            piece.push((r, c));
            let neighbours = [
                (r.wrapping_sub(1), c),
                (r + 1, c),
                (r, c.wrapping_sub(1)),
                (r, c + 1),
            ];
            for q in neighbours {
                if q.0 < rows && q.1 < cols && mask[q] && !seen[q] {
                    seen[q] = true;
                    queue.push_back(q);
                }
            }
        }
        if piece.len() < min_pixels {
            for &q in &piece {
                mask[q] = false;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_bright_disc_and_drops_specks() {
        let shape = (40, 40);
        let disc = Array2::from_shape_fn(shape, |(r, c)| {
            let d2 = (r as f32 - 20.0).powi(2) + (c as f32 - 20.0).powi(2);
            if d2 < 100.0 { 0.5 } else { 0.001 }
        });
        let mut speck = disc.clone();
        speck[(2, 2)] = 0.5;
        let images = LedImages {
            images: vec![speck.clone(), disc.clone(), disc.clone()],
        };
        let solved = Array2::from_elem(shape, true);
        let noise = Array2::from_elem(shape, 0.002f32);
        let mask = object_mask(
            &images,
            &speck,
            &solved,
            Some(&noise),
            &MaskConfig::default(),
        );
        assert!(mask[(20, 20)]);
        assert!(!mask[(0, 0)]);
        assert!(!mask[(2, 2)], "speck removed");
        let count = mask.iter().filter(|&&m| m).count();
        assert!((250..=330).contains(&count), "{count}");
    }
}
