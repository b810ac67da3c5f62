//! Ground-truth depth from a mesh (STL or OBJ): a small orthographic z-buffer rasteriser in the
//! rig's camera (pixel centres from [`Camera::pixel_centre_xy`], nearest surface = largest z).
//! Independent of the simulator's renderer on purpose: metrics must not share its mistakes.

use super::MetricsError;
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
    let err = |reason: String| MetricsError::Mesh {
        path: path.to_path_buf(),
        reason,
    };
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let v = |p: [f32; 3]| Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
    let triangles: Vec<[Vector3<f64>; 3]> = match ext.as_deref() {
        Some("stl") => {
            let mut file = std::fs::File::open(path).map_err(|e| err(e.to_string()))?;
            let mesh = stl_io::read_stl(&mut file).map_err(|e| err(e.to_string()))?;
            let mut out = Vec::with_capacity(mesh.faces.len());
            for f in &mesh.faces {
                let corner = |i: usize| {
                    mesh.vertices
                        .get(f.vertices[i])
                        .map(|p| v(p.0))
                        .ok_or_else(|| err("face refers to a missing vertex".into()))
                };
                out.push([corner(0)?, corner(1)?, corner(2)?]);
            }
            out
        }
        Some("obj") => {
            let options = tobj::LoadOptions {
                triangulate: true,
                single_index: true,
                ..Default::default()
            };
            let (models, _) = tobj::load_obj(path, &options).map_err(|e| err(e.to_string()))?;
            let mut out = Vec::new();
            for m in &models {
                let pos = &m.mesh.positions;
                let vertex = |i: u32| {
                    let i = i as usize * 3;
                    pos.get(i..i + 3)
                        .map(|p| v([p[0], p[1], p[2]]))
                        .ok_or_else(|| err("face refers to a missing vertex".into()))
                };
                for t in m.mesh.indices.chunks_exact(3) {
                    out.push([vertex(t[0])?, vertex(t[1])?, vertex(t[2])?]);
                }
            }
            out
        }
        _ => return Err(err("expected a .stl or .obj file".into())),
    };
    if triangles.is_empty() {
        return Err(err("the mesh has no triangles".into()));
    }
    if triangles
        .iter()
        .flatten()
        .any(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(err("the mesh has non-finite vertices".into()));
    }
    Ok(triangles)
}

/// Renders triangles (scene mm) to depth and normals on `camera`'s grid.
pub fn render_mesh_depth(triangles: &[[Vector3<f64>; 3]], camera: &Camera) -> MeshDepth {
    let (rows, cols) = (camera.height, camera.width);
    let mut depth = Array2::from_elem((rows, cols), f32::NAN);
    let mut normals = Array3::from_elem((rows, cols, 3), f32::NAN);
    for tri in triangles {
        let mut n = (tri[1] - tri[0]).cross(&(tri[2] - tri[0]));
        let len = n.norm();
        if len.is_nan() || len <= 0.0 {
            continue;
        }
        n /= len;
        if n.z < 0.0 {
            n = -n;
        }
        // Triangle corners in continuous (row, col).
        let rc: Vec<(f64, f64)> = tri.iter().map(|p| camera.xy_to_pixel(p.x, p.y)).collect();
        let r_lo = rc
            .iter()
            .map(|p| p.0)
            .fold(f64::INFINITY, f64::min)
            .ceil()
            .max(0.0);
        let r_hi = rc
            .iter()
            .map(|p| p.0)
            .fold(f64::NEG_INFINITY, f64::max)
            .floor();
        let c_lo = rc
            .iter()
            .map(|p| p.1)
            .fold(f64::INFINITY, f64::min)
            .ceil()
            .max(0.0);
        let c_hi = rc
            .iter()
            .map(|p| p.1)
            .fold(f64::NEG_INFINITY, f64::max)
            .floor();
        if r_hi < 0.0 || c_hi < 0.0 || r_lo > (rows - 1) as f64 || c_lo > (cols - 1) as f64 {
            continue;
        }
        let (r_hi, c_hi) = (r_hi.min((rows - 1) as f64), c_hi.min((cols - 1) as f64));
        let area = edge(rc[0], rc[1], rc[2]);
        if area.abs() < 1e-12 {
            continue;
        }
        for r in r_lo as usize..=r_hi as usize {
            for c in c_lo as usize..=c_hi as usize {
                let p = (r as f64, c as f64);
                let w0 = edge(rc[1], rc[2], p) / area;
                let w1 = edge(rc[2], rc[0], p) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < -1e-9 || w1 < -1e-9 || w2 < -1e-9 {
                    continue;
                }
                let z = (w0 * tri[0].z + w1 * tri[1].z + w2 * tri[2].z) as f32;
                let current = depth[(r, c)];
                if current.is_nan() || z > current {
                    depth[(r, c)] = z;
                    for j in 0..3 {
                        normals[(r, c, j)] = n[j] as f32;
                    }
                }
            }
        }
    }
    MeshDepth {
        depth_mm: depth,
        normals,
    }
}

/// Twice the signed area of (a, b, p).
fn edge(a: (f64, f64), b: (f64, f64), p: (f64, f64)) -> f64 {
    (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0)
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
