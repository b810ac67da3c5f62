//! Triangle meshes shared by the simulator (scene objects) and the metrics (ground truth from a
//! mesh file): STL/OBJ loading (`stl_io`, `tobj`), centring and scaling, smooth vertex normals,
//! and the one triangle rasteriser both use.
//!
//! The rasteriser finds, for every pixel whose ray ([`PixelRay`]) crosses a triangle, the
//! crossing point by an exact ray–triangle intersection (Möller & Trumbore, "Fast, minimum storage
//! ray/triangle intersection", 1997). Rays are parametrised by their height z, so the front-most
//! surface is the largest z, for orthographic and perspective cameras alike. Candidate pixels
//! come from the bounding box of the projected corners, widened by one pixel for lens distortion.
//! This module depends on nothing of the reconstruction, so the simulator can stay its oracle.

use crate::rig::{Camera, PixelRay};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors loading or building a mesh.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The file could not be opened.
    #[error("cannot open mesh {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The STL reader rejected the file.
    #[error("mesh {path} is not a readable STL file: {source}")]
    Stl {
        /// The file.
        path: PathBuf,
        /// The reader's error.
        source: std::io::Error,
    },
    /// The OBJ reader rejected the file.
    #[error("mesh {path} is not a readable OBJ file: {source}")]
    Obj {
        /// The file.
        path: PathBuf,
        /// The reader's error.
        source: tobj::LoadError,
    },
    /// The extension is neither `.stl` nor `.obj`.
    #[error("mesh {0}: unknown mesh format (expected .stl or .obj)")]
    UnknownFormat(PathBuf),
    /// The mesh's contents cannot be used.
    #[error("mesh {origin}: {reason}")]
    Invalid {
        /// The file or generator.
        origin: String,
        /// What is wrong.
        reason: String,
    },
}

/// A triangle mesh in its own frame, millimetres.
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<Vector3<f64>>,
    /// Triangles as vertex indices.
    pub triangles: Vec<[usize; 3]>,
    /// Unit vertex normals for smooth shading; `None` shades each face flat.
    pub vertex_normals: Option<Vec<Vector3<f64>>>,
}

impl TriMesh {
    /// Builds a mesh, checking every index and that some triangle has an area; flat shaded.
    pub fn new(
        vertices: Vec<Vector3<f64>>,
        triangles: Vec<[usize; 3]>,
        origin: &str,
    ) -> Result<Self, MeshError> {
        let bad = |reason: &str| MeshError::Invalid {
            origin: origin.into(),
            reason: reason.into(),
        };
        if triangles.is_empty() {
            return Err(bad("the mesh has no triangles"));
        }
        if !vertices.iter().all(|v| v.iter().all(|c| c.is_finite())) {
            return Err(bad("a vertex is not finite"));
        }
        if triangles.iter().flatten().any(|&i| i >= vertices.len()) {
            return Err(bad("a triangle refers to a missing vertex"));
        }
        let mesh = Self {
            vertices,
            triangles,
            vertex_normals: None,
        };
        if (0..mesh.triangles.len()).all(|t| mesh.face_normal(t).is_none()) {
            return Err(bad(
                "every triangle has zero area (nothing to render or compare)",
            ));
        }
        Ok(mesh)
    }

    /// Loads an STL (binary or ASCII) or OBJ file, chosen by extension.
    pub fn load(path: &Path) -> Result<Self, MeshError> {
        let origin = path.display().to_string();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        let to_f64 = |p: [f32; 3]| Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        match ext.as_deref() {
            Some("stl") => {
                let mut file = std::fs::File::open(path).map_err(|source| MeshError::Io {
                    path: path.to_path_buf(),
                    source,
                })?;
                let mesh = stl_io::read_stl(&mut file).map_err(|source| MeshError::Stl {
                    path: path.to_path_buf(),
                    source,
                })?;
                let vertices = mesh.vertices.iter().map(|v| to_f64(v.0)).collect();
                let triangles = mesh.faces.iter().map(|f| f.vertices).collect();
                Self::new(vertices, triangles, &origin)
            }
            Some("obj") => {
                let options = tobj::LoadOptions {
                    triangulate: true,
                    single_index: true,
                    ..Default::default()
                };
                let (models, _materials) =
                    tobj::load_obj(path, &options).map_err(|source| MeshError::Obj {
                        path: path.to_path_buf(),
                        source,
                    })?;
                let mut vertices = Vec::new();
                let mut triangles = Vec::new();
                for model in models {
                    let base = vertices.len();
                    let m = model.mesh;
                    vertices.extend(
                        m.positions
                            .chunks_exact(3)
                            .map(|p| to_f64([p[0], p[1], p[2]])),
                    );
                    triangles.extend(m.indices.chunks_exact(3).map(|t| {
                        [
                            base + t[0] as usize,
                            base + t[1] as usize,
                            base + t[2] as usize,
                        ]
                    }));
                }
                Self::new(vertices, triangles, &origin)
            }
            _ => Err(MeshError::UnknownFormat(path.to_path_buf())),
        }
    }

    /// Axis-aligned bounding box (min, max).
    pub fn bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for v in &self.vertices {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
        (lo, hi)
    }

    /// Moves the bounding-box centre to the origin and, with `size_mm`, scales the mesh so
    /// its largest bounding-box extent equals `size_mm`.
    pub fn centred(mut self, size_mm: Option<f64>) -> Self {
        let (lo, hi) = self.bounds();
        let centre = (lo + hi) / 2.0;
        let extent = (hi - lo).max();
        let scale = match size_mm {
            Some(s) if extent > 0.0 => s / extent,
            _ => 1.0,
        };
        for v in &mut self.vertices {
            *v = (*v - centre) * scale;
        }
        self
    }

    /// Adds area-weighted vertex normals (smooth shading across shared vertices).
    pub fn with_smooth_normals(mut self) -> Self {
        let mut normals = vec![Vector3::zeros(); self.vertices.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i]);
            let n = (b - a).cross(&(c - a));
            for &i in t {
                normals[i] += n;
            }
        }
        for n in &mut normals {
            let len = n.norm();
            *n = if len > 0.0 { *n / len } else { Vector3::z() };
        }
        self.vertex_normals = Some(normals);
        self
    }

    /// The corners of triangle `t`.
    pub fn corners(&self, t: usize) -> [Vector3<f64>; 3] {
        self.triangles[t].map(|i| self.vertices[i])
    }

    /// Unit normal of triangle `t` by its winding, or `None` when it has no area.
    pub fn face_normal(&self, t: usize) -> Option<Vector3<f64>> {
        let [a, b, c] = self.corners(t);
        (b - a).cross(&(c - a)).try_normalize(0.0)
    }
}

/// Where a pixel's ray crosses a triangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// Pixel index row·width + column.
    pub pixel: usize,
    /// Height z of the crossing (larger = nearer the camera).
    pub z: f64,
    /// Barycentric weights of the three corners.
    pub weights: [f64; 3],
    /// The pixel's ray.
    pub ray: PixelRay,
}

/// Calls `visit` for every pixel of `camera` whose ray crosses the triangle `corners` (scene
/// mm), in no particular order; the caller keeps the front-most hit (largest z) per pixel.
pub fn rasterise_triangle(
    camera: &Camera,
    corners: &[Vector3<f64>; 3],
    mut visit: impl FnMut(RayHit),
) {
    let projection = camera.projection();
    let mut lo = (f64::INFINITY, f64::INFINITY);
    let mut hi = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for p in corners {
        let Some((r, c)) = projection.project(p) else {
            return; // a corner at or behind the camera
        };
        if !(r.is_finite() && c.is_finite()) {
            return;
        }
        lo = (lo.0.min(r), lo.1.min(c));
        hi = (hi.0.max(r), hi.1.max(c));
    }
    let margin = if camera.is_perspective() { 1.0 } else { 0.0 };
    let (rows, cols) = (camera.height as f64, camera.width as f64);
    let r0 = (lo.0 - margin).ceil().max(0.0);
    let c0 = (lo.1 - margin).ceil().max(0.0);
    let r1 = (hi.0 + margin).floor().min(rows - 1.0);
    let c1 = (hi.1 + margin).floor().min(cols - 1.0);
    if r0 > r1 || c0 > c1 {
        return;
    }
    let e1 = corners[1] - corners[0];
    let e2 = corners[2] - corners[0];
    let scale = e1.norm() * e2.norm();
    let eps = 1e-9;
    for row in r0 as usize..=r1 as usize {
        for col in c0 as usize..=c1 as usize {
            let ray = projection.ray(row as f64, col as f64);
            // Möller–Trumbore with direction = slope: base + z·slope = v0 + β·e1 + γ·e2.
            let h = ray.slope.cross(&e2);
            let det = e1.dot(&h);
            if det.abs() <= 1e-12 * scale {
                continue; // seen edge-on
            }
            let s = ray.base - corners[0];
            let beta = s.dot(&h) / det;
            if beta < -eps || beta > 1.0 + eps {
                continue;
            }
            let q = s.cross(&e1);
            let gamma = ray.slope.dot(&q) / det;
            if gamma < -eps || beta + gamma > 1.0 + eps {
                continue;
            }
            let z = e2.dot(&q) / det;
            visit(RayHit {
                pixel: row * camera.width + col,
                z,
                weights: [1.0 - beta - gamma, beta, gamma],
                ray,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::Intrinsics;

    fn orthographic() -> Camera {
        Camera {
            width: 20,
            height: 10,
            fps: 1.0,
            distance_mm: 100.0,
            fov_deg: None,
            pixel_pitch_mm: Some(1.0),
            intrinsics: None,
            axis_px: None,
        }
    }

    /// Square x, y ∈ [−4, 4] with z = 0.5 x + 3 as two triangles.
    fn tilted_square() -> [[Vector3<f64>; 3]; 2] {
        let p = |x: f64, y: f64| Vector3::new(x, y, 0.5 * x + 3.0);
        [
            [p(-4.0, -4.0), p(4.0, -4.0), p(4.0, 4.0)],
            [p(-4.0, -4.0), p(4.0, 4.0), p(-4.0, 4.0)],
        ]
    }

    #[test]
    fn orthographic_hits_are_exact_and_cover_the_square() {
        let camera = orthographic();
        let mut hits = std::collections::HashMap::new();
        for tri in &tilted_square() {
            rasterise_triangle(&camera, tri, |h| {
                hits.insert(h.pixel, h);
            });
        }
        assert_eq!(hits.len(), 64, "8×8 pixel centres inside");
        for h in hits.values() {
            let point = h.ray.at(h.z);
            assert!((point.z - (0.5 * point.x + 3.0)).abs() < 1e-12);
            assert!((h.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn perspective_hits_lie_on_the_triangle_and_the_ray() {
        let mut camera = orthographic();
        camera.pixel_pitch_mm = None;
        camera.intrinsics = Some(Intrinsics {
            fx: 200.0,
            fy: 200.0,
            cx: 9.5,
            cy: 4.5,
            k1: 0.1,
            k2: 0.0,
        });
        let mut count = 0;
        for tri in &tilted_square() {
            rasterise_triangle(&camera, tri, |h| {
                let point = h.ray.at(h.z);
                let on_plane =
                    h.weights[0] * tri[0] + h.weights[1] * tri[1] + h.weights[2] * tri[2];
                assert!((point - on_plane).norm() < 1e-9);
                let (r, c) = camera.project(&point).unwrap();
                assert!(
                    (r - (h.pixel / 20) as f64).abs() < 1e-9
                        && (c - (h.pixel % 20) as f64).abs() < 1e-9
                );
                count += 1;
            });
        }
        // At 100 mm with f = 200 px the 8 mm square spans about 16×16 px (clipped to 20×10).
        assert!(count > 100, "{count}");
    }

    #[test]
    fn bad_meshes_are_refused() {
        let err = TriMesh::new(vec![Vector3::zeros()], vec![[0, 1, 2]], "x").unwrap_err();
        assert!(err.to_string().contains("missing vertex"), "{err}");
        let flat = vec![Vector3::zeros(), Vector3::x(), Vector3::x() * 2.0];
        let err = TriMesh::new(flat, vec![[0, 1, 2]], "x").unwrap_err();
        assert!(err.to_string().contains("zero area"), "{err}");
        let err = TriMesh::load(Path::new("/no/such/file.stl")).unwrap_err();
        assert!(err.to_string().contains("/no/such/file.stl"), "{err}");
        assert!(matches!(err, MeshError::Io { .. }));
        let err = TriMesh::load(Path::new("shape.ply")).unwrap_err();
        assert!(err.to_string().contains("unknown mesh format"), "{err}");
    }
}
