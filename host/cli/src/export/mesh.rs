//! Surface meshes from a depth map: one vertex per reconstructed pixel at its 3-D point in mm
//! ([`DepthMap::point`]: x right, y up, origin at the image centre for the orthographic grid;
//! metric camera coordinates for a perspective camera), two triangles per grid square whose
//! corners exist, facing the camera. Written as binary PLY, OBJ or binary STL (via `stl_io`).

use super::ExportError;
use meb_core::io::FilesError;
use meb_core::types::DepthMap;
use std::path::Path;

/// Vertices and triangles of a depth map's surface.
#[derive(Debug, Clone, Default)]
pub struct SurfaceMesh {
    /// Vertex positions in mm.
    pub vertices: Vec<[f32; 3]>,
    /// Counter-clockwise (seen from the camera) vertex triples.
    pub triangles: Vec<[u32; 3]>,
}

impl SurfaceMesh {
    /// Builds the mesh of `depth`.
    pub fn from_depth(depth: &DepthMap) -> Self {
        let (rows, cols) = depth.depth_mm.dim();
        let mut index = vec![u32::MAX; rows * cols];
        let mut mesh = SurfaceMesh::default();
        for r in 0..rows {
            for c in 0..cols {
                if let Some(p) = depth.point(r, c) {
                    index[r * cols + c] = mesh.vertices.len() as u32;
                    mesh.vertices.push(p);
                }
            }
        }
        for r in 0..rows.saturating_sub(1) {
            for c in 0..cols.saturating_sub(1) {
                let (a, b) = (index[r * cols + c], index[r * cols + c + 1]);
                let (d, e) = (index[(r + 1) * cols + c], index[(r + 1) * cols + c + 1]);
                // Seen from +z with y up: a (top-left) → d (bottom-left) → b is counter-clockwise.
                for t in [[a, d, b], [b, d, e]] {
                    if t.iter().all(|&i| i != u32::MAX) {
                        mesh.triangles.push(t);
                    }
                }
            }
        }
        mesh
    }

    /// Binary little-endian PLY.
    pub fn to_ply(&self) -> Vec<u8> {
        let mut out = format!(
            "ply\nformat binary_little_endian 1.0\ncomment meb reconstruction, mm\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            self.vertices.len(),
            self.triangles.len()
        )
        .into_bytes();
        for v in &self.vertices {
            for x in v {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
        for t in &self.triangles {
            out.push(3);
            for &i in t {
                out.extend_from_slice(&(i as i32).to_le_bytes());
            }
        }
        out
    }

    /// Wavefront OBJ text.
    pub fn to_obj(&self) -> Vec<u8> {
        use std::fmt::Write;
        let mut s = String::from("# meb reconstruction, mm\n");
        for v in &self.vertices {
            let _ = writeln!(s, "v {} {} {}", v[0], v[1], v[2]);
        }
        for t in &self.triangles {
            let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
        }
        s.into_bytes()
    }

    /// Binary STL.
    pub fn to_stl(&self) -> Result<Vec<u8>, ExportError> {
        let tris: Vec<stl_io::Triangle> = self
            .triangles
            .iter()
            .map(|t| {
                let p = t.map(|i| self.vertices[i as usize]);
                let u = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
                let v = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
                let n = [
                    u[1] * v[2] - u[2] * v[1],
                    u[2] * v[0] - u[0] * v[2],
                    u[0] * v[1] - u[1] * v[0],
                ];
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
                    .sqrt()
                    .max(f32::MIN_POSITIVE);
                stl_io::Triangle {
                    normal: stl_io::Vector::new(n.map(|x| x / len)),
                    vertices: p.map(stl_io::Vector::new),
                }
            })
            .collect();
        let mut out = Vec::new();
        stl_io::write_stl(&mut out, tris.iter()).map_err(|e| FilesError::Encode {
            path: "(STL in memory)".into(),
            source: Box::new(e),
        })?;
        Ok(out)
    }

    /// Writes the mesh in the format named by `path`'s extension (ply, obj or stl).
    pub fn write(&self, path: &Path) -> Result<(), ExportError> {
        if self.triangles.is_empty() {
            return Err(ExportError::Empty("the surface has no triangles".into()));
        }
        let bytes = match path.extension().and_then(|e| e.to_str()) {
            Some("obj") => self.to_obj(),
            Some("stl") => self.to_stl()?,
            _ => self.to_ply(),
        };
        std::fs::write(path, bytes).map_err(|e| FilesError::write(path, e).into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    #[test]
    fn grid_becomes_triangles_facing_the_camera() {
        let mut depth_mm = Array2::from_elem((3, 4), 1.0f32);
        depth_mm[(0, 0)] = f32::NAN;
        let mesh = SurfaceMesh::from_depth(&DepthMap {
            depth_mm,
            pitch_mm: 0.5,
            perspective: None,
        });
        assert_eq!(mesh.vertices.len(), 11);
        assert_eq!(mesh.triangles.len(), 2 * 2 * 3 - 1);
        let stl = mesh.to_stl().unwrap();
        let back = stl_io::read_stl(&mut std::io::Cursor::new(stl)).unwrap();
        assert_eq!(back.faces.len(), mesh.triangles.len());
        assert!(back.faces.iter().all(|f| f.normal.0[2] > 0.99));
        assert!(mesh.to_ply().starts_with(b"ply\n"));
    }
}
