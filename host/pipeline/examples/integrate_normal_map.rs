//! Integrates a normal map into depth: `cargo run --release -p meb-pipeline --example
//! integrate_normal_map`. The normals are those of a hemisphere of radius 40 pixels on a
//! 128×128 grid (x right, y up, z towards the camera; one pixel per mm, orthographic); the
//! example prints how far the integrated depth lies from the true one.

use meb_core::types::NormalField;
use meb_pipeline::integrate::{IntegrateConfig, integrate_normals};
use ndarray::{Array2, Array3};
use std::error::Error;

fn main() -> Result<(), Box<dyn Error>> {
    let (size, radius) = (128usize, 40.0f64);
    let centre = (size as f64 - 1.0) / 2.0;
    let height = |r: usize, c: usize| {
        let (x, y) = (c as f64 - centre, centre - r as f64);
        (radius * radius - x * x - y * y).sqrt()
    };
    let inside = |r: usize, c: usize| height(r, c) > 5.0;
    let mut normals = Array3::<f32>::from_elem((size, size, 3), f32::NAN);
    for r in 0..size {
        for c in 0..size {
            if inside(r, c) {
                let (x, y, z) = (c as f64 - centre, centre - r as f64, height(r, c));
                for (k, v) in [x, y, z].into_iter().enumerate() {
                    normals[(r, c, k)] = (v / radius) as f32;
                }
            }
        }
    }
    let mask = Array2::from_shape_fn((size, size), |(r, c)| inside(r, c));
    let albedo = Array2::from_elem((size, size), 1.0f32);
    let field = NormalField {
        normals,
        albedo,
        mask,
    };
    let depth = integrate_normals(&field, 1.0, &IntegrateConfig::default(), None)?.depth;
    // Depth is known up to a constant: compare after removing the mean difference.
    let pairs: Vec<(f64, f64)> = (0..size * size)
        .map(|i| (i / size, i % size))
        .filter(|&(r, c)| inside(r, c) && depth.depth_mm[(r, c)].is_finite())
        .map(|(r, c)| (f64::from(depth.depth_mm[(r, c)]), height(r, c)))
        .collect();
    let offset = pairs.iter().map(|(z, t)| t - z).sum::<f64>() / pairs.len() as f64;
    let rmse = (pairs
        .iter()
        .map(|(z, t)| (z + offset - t).powi(2))
        .sum::<f64>()
        / pairs.len() as f64)
        .sqrt();
    println!("{} pixels integrated, depth RMSE {rmse:.3} mm", pairs.len());
    Ok(())
}
