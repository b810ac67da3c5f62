//! Ray casting the scene into a height field on the camera's pixel grid.
//!
//! The camera is orthographic and looks along −z (SPEC §5), so the ray through a pixel centre
//! (x, y) is the line {(x, y, z)} and the visible surface is the hit with the largest z.
//! Analytic shapes are intersected exactly per pixel (one rayon task per row); triangle
//! meshes are rasterised into the same depth buffer (z-test, flat or smooth normals).

use super::scene::{Scene, Shape, intersect_analytic};
use crate::rig::Camera;
use nalgebra::Vector3;
use rayon::prelude::*;

/// The visible surface of the scene at one instant, row-major on the pixel grid.
#[derive(Debug, Clone)]
pub struct SurfaceMap {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Front-most surface height z in mm; −∞ where the ray hits nothing.
    pub z_mm: Vec<f64>,
    /// Unit normal of the visible surface (zero where nothing is hit).
    pub normals: Vec<Vector3<f64>>,
    /// Albedo of the visible surface (0 where nothing is hit).
    pub albedo: Vec<f64>,
    /// Whether the visible surface belongs to an object (not the ground plane).
    pub is_object: Vec<bool>,
}

impl SurfaceMap {
    /// Renders `scene` at time `t_s` seconds as seen by `camera`.
    pub fn render(scene: &Scene, camera: &Camera, t_s: f64) -> Self {
        let (width, height) = (camera.width, camera.height);
        let poses: Vec<_> = scene
            .objects
            .iter()
            .map(|o| (o.position_mm, o.rotation_at(t_s)))
            .collect();
        // Analytic objects and the ground plane, per pixel.
        type Hit = (f64, Vector3<f64>, f64, bool);
        let rows: Vec<Vec<Hit>> = (0..height)
            .into_par_iter()
            .map(|row| {
                (0..width)
                    .map(|col| {
                        let (x, y) = camera.pixel_centre_xy(row as f64, col as f64);
                        let mut best: Hit = (f64::NEG_INFINITY, Vector3::zeros(), 0.0, false);
                        if let Some(g) = &scene.ground {
                            best = (g.z_mm, Vector3::z(), g.albedo, false);
                        }
                        for (object, (c, r)) in scene.objects.iter().zip(&poses) {
                            if let Some((z, n)) = intersect_analytic(&object.shape, c, r, x, y)
                                && z > best.0
                            {
                                best = (z, n, object.albedo, true);
                            }
                        }
                        best
                    })
                    .collect()
            })
            .collect();
        let mut map = Self {
            width,
            height,
            z_mm: Vec::with_capacity(width * height),
            normals: Vec::with_capacity(width * height),
            albedo: Vec::with_capacity(width * height),
            is_object: Vec::with_capacity(width * height),
        };
        for (z, n, a, o) in rows.into_iter().flatten() {
            map.z_mm.push(z);
            map.normals.push(n);
            map.albedo.push(a);
            map.is_object.push(o);
        }
        for (object, (c, r)) in scene.objects.iter().zip(&poses) {
            if let Shape::Mesh(mesh) = &object.shape {
                let world: Vec<Vector3<f64>> = mesh.vertices.iter().map(|v| r * v + c).collect();
                let normals: Option<Vec<Vector3<f64>>> = mesh
                    .vertex_normals
                    .as_ref()
                    .map(|ns| ns.iter().map(|n| r * n).collect());
                for tri in &mesh.triangles {
                    map.rasterise(camera, tri, &world, normals.as_deref(), object.albedo);
                }
            }
        }
        map
    }

    /// Draws one triangle into the depth buffer.
    fn rasterise(
        &mut self,
        camera: &Camera,
        tri: &[usize; 3],
        world: &[Vector3<f64>],
        vertex_normals: Option<&[Vector3<f64>]>,
        albedo: f64,
    ) {
        let p = tri.map(|i| world[i]);
        let mut face = (p[1] - p[0]).cross(&(p[2] - p[0]));
        let len = face.norm();
        if len == 0.0 || face.z == 0.0 {
            return; // degenerate or seen edge-on
        }
        face /= len;
        if face.z < 0.0 {
            face = -face;
        }
        // Continuous pixel coordinates (row, col) of the corners.
        let q = p.map(|v| camera.xy_to_pixel(v.x, v.y));
        let rmin = q
            .iter()
            .map(|v| v.0)
            .fold(f64::INFINITY, f64::min)
            .ceil()
            .max(0.0);
        let rmax = q
            .iter()
            .map(|v| v.0)
            .fold(f64::NEG_INFINITY, f64::max)
            .floor();
        let cmin = q
            .iter()
            .map(|v| v.1)
            .fold(f64::INFINITY, f64::min)
            .ceil()
            .max(0.0);
        let cmax = q
            .iter()
            .map(|v| v.1)
            .fold(f64::NEG_INFINITY, f64::max)
            .floor();
        if rmax < 0.0 || cmax < 0.0 || rmin > rmax || cmin > cmax {
            return;
        }
        let rmax = rmax.min(self.height as f64 - 1.0);
        let cmax = cmax.min(self.width as f64 - 1.0);
        let area = (q[1].0 - q[0].0) * (q[2].1 - q[0].1) - (q[2].0 - q[0].0) * (q[1].1 - q[0].1);
        if area.abs() < 1e-15 {
            return;
        }
        let eps = 1e-9;
        for row in rmin as usize..=rmax as usize {
            for col in cmin as usize..=cmax as usize {
                let (r, c) = (row as f64, col as f64);
                let edge = |a: (f64, f64), b: (f64, f64)| {
                    ((b.0 - a.0) * (c - a.1) - (r - a.0) * (b.1 - a.1)) / area
                };
                let w0 = edge(q[1], q[2]);
                let w1 = edge(q[2], q[0]);
                let w2 = edge(q[0], q[1]);
                if w0 < -eps || w1 < -eps || w2 < -eps {
                    continue;
                }
                let z = w0 * p[0].z + w1 * p[1].z + w2 * p[2].z;
                let i = row * self.width + col;
                if z <= self.z_mm[i] {
                    continue;
                }
                let normal = match vertex_normals {
                    Some(ns) => {
                        let n = w0 * ns[tri[0]] + w1 * ns[tri[1]] + w2 * ns[tri[2]];
                        let n = n.try_normalize(1e-12).unwrap_or(face);
                        if n.dot(&face) < 0.0 { -n } else { n }
                    }
                    None => face,
                };
                self.z_mm[i] = z;
                self.normals[i] = normal;
                self.albedo[i] = albedo;
                self.is_object[i] = true;
            }
        }
    }

    /// Scene point X of pixel `i` (x, y of the pixel centre, z of the surface).
    pub fn point(&self, camera: &Camera, i: usize) -> Vector3<f64> {
        let (x, y) = camera.pixel_centre_xy((i / self.width) as f64, (i % self.width) as f64);
        Vector3::new(x, y, self.z_mm[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::mesh::TriMesh;
    use crate::simulate::scene::SceneObject;
    use std::sync::Arc;

    fn camera() -> Camera {
        Camera {
            width: 64,
            height: 48,
            fps: 960.0,
            distance_mm: 400.0,
            fov_deg: None,
            pixel_pitch_mm: Some(1.0),
        }
    }

    #[test]
    fn sphere_mask_and_depth() {
        let scene = Scene::single(SceneObject::new(Shape::Sphere { radius_mm: 10.0 }));
        let map = SurfaceMap::render(&scene, &camera(), 0.0);
        let inside = map.is_object.iter().filter(|&&b| b).count() as f64;
        assert!(
            (inside - std::f64::consts::PI * 100.0).abs() < 20.0,
            "{inside}"
        );
        let centre = 24 * 64 + 32; // pixel centre (0.5, -0.5)
        assert!((map.z_mm[centre] - (100.0f64 - 0.5).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn mesh_rasterises_like_the_analytic_shape() {
        let cube = |s: f64| {
            let v: Vec<Vector3<f64>> = (0..8)
                .map(|i| {
                    Vector3::new(
                        if i & 1 == 0 { -s } else { s },
                        if i & 2 == 0 { -s } else { s },
                        if i & 4 == 0 { -s } else { s },
                    )
                })
                .collect();
            let t = vec![
                [4, 5, 7],
                [4, 7, 6],
                [0, 2, 3],
                [0, 3, 1],
                [0, 1, 5],
                [0, 5, 4],
                [2, 6, 7],
                [2, 7, 3],
                [0, 4, 6],
                [0, 6, 2],
                [1, 3, 7],
                [1, 7, 5],
            ];
            TriMesh::new(v, t, "cube").unwrap()
        };
        let rot = nalgebra::UnitQuaternion::from_euler_angles(0.4, 0.3, 0.2);
        let mut a = SceneObject::new(Shape::Mesh(Arc::new(cube(10.0))));
        a.rotation = rot;
        let mut b = SceneObject::new(Shape::Cuboid {
            half_extents_mm: [10.0; 3],
        });
        b.rotation = rot;
        let ma = SurfaceMap::render(&Scene::single(a), &camera(), 0.0);
        let mb = SurfaceMap::render(&Scene::single(b), &camera(), 0.0);
        let mut compared = 0;
        for i in 0..ma.z_mm.len() {
            if ma.is_object[i] && mb.is_object[i] {
                assert!((ma.z_mm[i] - mb.z_mm[i]).abs() < 1e-6);
                // Pixels on a face edge may pick either neighbouring face.
                if (ma.normals[i] - mb.normals[i]).norm() < 1e-9 {
                    compared += 1;
                }
            }
        }
        assert!(compared > 500, "{compared}");
    }
}
