//! The seeded random "blobby" shapes of the thesis' synthetic data set (Ch. 7,
//! docs/formats/simulated-folders.md#the-synthetic-data-set): a
//! sphere whose radius is modulated by a few broad random bumps, so the surface has only low
//! spatial frequencies. Meshes themselves (loading, rasterising) live in [`meb_core::mesh`].

pub use meb_core::mesh::TriMesh;
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A seeded random smooth closed shape whose largest extent is about `size_mm`
/// (thesis Ch. 7): radius r(u) = 1 + Σ_k a_k·exp((u·c_k − 1)/w_k²) over the unit sphere.
pub fn blobby(seed: u64, size_mm: f64) -> TriMesh {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let bumps: Vec<(Vector3<f64>, f64, f64)> = (0..7)
        .map(|_| {
            let dir = loop {
                let v = Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                );
                let n = v.norm();
                if n > 0.1 && n <= 1.0 {
                    break v / n;
                }
            };
            (
                dir,
                rng.random_range(-0.3..0.45),
                rng.random_range(0.45..0.9),
            )
        })
        .collect();
    let squash = Vector3::new(
        rng.random_range(0.8..1.2),
        rng.random_range(0.8..1.2),
        rng.random_range(0.7..1.1),
    );
    let (n_lat, n_lon) = (64usize, 128usize);
    let mut vertices = Vec::with_capacity((n_lat + 1) * n_lon);
    for i in 0..=n_lat {
        let theta = std::f64::consts::PI * i as f64 / n_lat as f64;
        for j in 0..n_lon {
            let phi = std::f64::consts::TAU * j as f64 / n_lon as f64;
            let u = Vector3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            let r: f64 = 1.0
                + bumps
                    .iter()
                    .map(|(c, a, w)| a * ((u.dot(c) - 1.0) / (w * w)).exp())
                    .sum::<f64>();
            vertices.push(u.component_mul(&squash) * r.max(0.3));
        }
    }
    let idx = |i: usize, j: usize| i * n_lon + j % n_lon;
    let mut triangles = Vec::with_capacity(2 * n_lat * n_lon);
    for i in 0..n_lat {
        for j in 0..n_lon {
            // Outward winding (y up, poles at ±y).
            triangles.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
            triangles.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
        }
    }
    TriMesh {
        vertices,
        triangles,
        vertex_normals: None,
    }
    .centred(Some(size_mm))
    .with_smooth_normals()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blobby_is_seeded_and_sized() {
        let a = blobby(7, 60.0);
        let b = blobby(7, 60.0);
        let c = blobby(8, 60.0);
        assert_eq!(a, b);
        assert_ne!(a, c);
        let (lo, hi) = a.bounds();
        assert!(((hi - lo).max() - 60.0).abs() < 1e-9);
    }
}
