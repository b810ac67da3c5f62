//! Triangle meshes: STL/OBJ loading (`stl_io`, `tobj`), centring and scaling, smooth vertex
//! normals, and the seeded random "blobby" shapes of the thesis' synthetic data set (Ch. 7,
//! SPEC §10): a sphere whose radius is modulated by a few broad random bumps, so the surface
//! has only low spatial frequencies.

use super::SimulateError;
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

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
    /// Builds a mesh, checking every index; flat shaded.
    pub fn new(
        vertices: Vec<Vector3<f64>>,
        triangles: Vec<[usize; 3]>,
        origin: &str,
    ) -> Result<Self, SimulateError> {
        let bad = |reason: &str| SimulateError::Mesh {
            path: origin.into(),
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
        Ok(Self {
            vertices,
            triangles,
            vertex_normals: None,
        })
    }

    /// Loads an STL (binary or ASCII) or OBJ file, chosen by extension.
    pub fn load(path: &Path) -> Result<Self, SimulateError> {
        let origin = path.display().to_string();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("stl") => {
                let mut file = std::fs::File::open(path).map_err(|e| SimulateError::Mesh {
                    path: origin.clone(),
                    reason: e.to_string(),
                })?;
                let mesh = stl_io::read_stl(&mut file).map_err(|e| SimulateError::Mesh {
                    path: origin.clone(),
                    reason: format!("not a readable STL file: {e}"),
                })?;
                let vertices = mesh
                    .vertices
                    .iter()
                    .map(|v| Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])))
                    .collect();
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
                    tobj::load_obj(path, &options).map_err(|e| SimulateError::Mesh {
                        path: origin.clone(),
                        reason: format!("not a readable OBJ file: {e}"),
                    })?;
                let mut vertices = Vec::new();
                let mut triangles = Vec::new();
                for model in models {
                    let base = vertices.len();
                    let m = model.mesh;
                    vertices.extend(
                        m.positions.chunks_exact(3).map(|p| {
                            Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
                        }),
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
            _ => Err(SimulateError::Mesh {
                path: origin,
                reason: "unknown mesh format (expected .stl or .obj)".into(),
            }),
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

    /// A seeded random smooth closed shape whose largest extent is about `size_mm`
    /// (thesis Ch. 7): radius r(u) = 1 + Σ_k a_k·exp((u·c_k − 1)/w_k²) over the unit sphere.
    pub fn blobby(seed: u64, size_mm: f64) -> Self {
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
        Self {
            vertices,
            triangles,
            vertex_normals: None,
        }
        .centred(Some(size_mm))
        .with_smooth_normals()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blobby_is_seeded_and_sized() {
        let a = TriMesh::blobby(7, 60.0);
        let b = TriMesh::blobby(7, 60.0);
        let c = TriMesh::blobby(8, 60.0);
        assert_eq!(a, b);
        assert_ne!(a, c);
        let (lo, hi) = a.bounds();
        assert!(((hi - lo).max() - 60.0).abs() < 1e-9);
    }

    #[test]
    fn bad_meshes_are_refused() {
        let err = TriMesh::new(vec![Vector3::zeros()], vec![[0, 1, 2]], "x").unwrap_err();
        assert!(err.to_string().contains("missing vertex"), "{err}");
        let err = TriMesh::load(Path::new("/no/such/file.stl")).unwrap_err();
        assert!(err.to_string().contains("/no/such/file.stl"), "{err}");
        let err = TriMesh::load(Path::new("shape.ply")).unwrap_err();
        assert!(err.to_string().contains("unknown mesh format"), "{err}");
    }
}
