//! Ground-truth depth from a mesh (STL or OBJ) in the rig's camera: the front-most surface of
//! every pixel's ray (largest z) and its face normal, through the same loader and rasteriser the
//! simulator uses ([`crate::mesh`]). Sharing them is deliberate: both need the exact visible
//! surface of a mesh, and the rasteriser's own tests pin it to the ray geometry; the simulator's
//! wall is against the reconstruction code, which neither this module nor [`crate::mesh`] touch.

use super::MetricsError;
use crate::mesh::{TriMesh, rasterise_triangle};
use crate::rig::Camera;
use nalgebra::Vector3;
use ndarray::{Array2, Array3};
use std::path::Path;

/// A mesh rendered to depth and normals on the camera grid.
#[derive(Debug, Clone)]
pub struct MeshDepth {
    /// z in mm of the visible surface, NaN where the mesh does not cover the pixel.
    pub depth_mm: Array2<f32>,
    /// Unit face normals of the visible surface (turned towards the camera), NaN elsewhere.
    pub normals: Array3<f32>,
}

/// Loads the triangles of an STL (binary or ASCII) or OBJ file, in mm.
pub fn load_mesh_triangles(path: &Path) -> Result<Vec<[Vector3<f64>; 3]>, MetricsError> {
    let mesh = TriMesh::load(path)?;
    Ok((0..mesh.triangles.len()).map(|t| mesh.corners(t)).collect())
}

/// Renders triangles (scene mm) to depth and normals on `camera`'s grid.
pub fn render_mesh_depth(triangles: &[[Vector3<f64>; 3]], camera: &Camera) -> MeshDepth {
    let (rows, cols) = (camera.height, camera.width);
    let mut depth = Array2::from_elem((rows, cols), f32::NAN);
    let mut normals = Array3::from_elem((rows, cols, 3), f32::NAN);
    for tri in triangles {
        let Some(n) = (tri[1] - tri[0])
            .cross(&(tri[2] - tri[0]))
            .try_normalize(0.0)
        else {
            continue;
        };
        rasterise_triangle(camera, tri, |hit| {
            let (r, c) = (hit.pixel / cols, hit.pixel % cols);
            let z = hit.z as f32;
            let current = depth[(r, c)];
            if current.is_nan() || z > current {
                depth[(r, c)] = z;
                let n = if n.dot(&hit.ray.slope) < 0.0 { -n } else { n };
                for j in 0..3 {
                    normals[(r, c, j)] = n[j] as f32;
                }
            }
        });
    }
    MeshDepth {
        depth_mm: depth,
        normals,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_a_tilted_square() {
        let camera = Camera {
            width: 20,
            height: 10,
            fps: 1.0,
            distance_mm: 100.0,
            fov_deg: None,
            pixel_pitch_mm: Some(1.0),
            intrinsics: None,
            axis_px: None,
        };
        // Square x, y ∈ [−4, 4] with z = 0.5 x + 3.
        let p = |x: f64, y: f64| Vector3::new(x, y, 0.5 * x + 3.0);
        let tris = [
            [p(-4.0, -4.0), p(4.0, -4.0), p(4.0, 4.0)],
            [p(-4.0, -4.0), p(4.0, 4.0), p(-4.0, 4.0)],
        ];
        let out = render_mesh_depth(&tris, &camera);
        let covered = out.depth_mm.iter().filter(|z| z.is_finite()).count();
        assert_eq!(covered, 64, "8×8 pixel centres inside");
        let (x, _) = camera.pixel_centre_xy(5.0, 10.0);
        assert!((f64::from(out.depth_mm[(5, 10)]) - (0.5 * x + 3.0)).abs() < 1e-5);
        assert!(out.normals[(5, 10, 0)] < 0.0 && out.normals[(5, 10, 2)] > 0.0);
        assert!(out.depth_mm[(0, 0)].is_nan());
    }
}
