//! Ray casting the scene into a height field on the camera's pixel grid.
//!
//! Every pixel's ray is parametrised by the height z of its points ([`meb_core::rig::PixelRay`]:
//! parallel rays along −z for the orthographic camera of docs/maths/coordinates.md#pixels-and-rays,
//! rays through the camera centre
//! for a perspective one), so the visible surface is the hit with the largest z. Analytic shapes
//! are intersected exactly per pixel (one rayon task per row); triangle meshes go through the
//! shared rasteriser [`meb_core::mesh::rasterise_triangle`] into the same depth buffer (z-test, flat
//! or smooth normals).

use super::scene::{Scene, Shape, intersect_analytic};
use meb_core::mesh::{RayHit, rasterise_triangle};
use meb_core::rig::Camera;
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
                        let ray = camera.ray(row as f64, col as f64);
                        let mut best: Hit = (f64::NEG_INFINITY, Vector3::zeros(), 0.0, false);
                        if let Some(g) = &scene.ground {
                            best = (g.z_mm, Vector3::z(), g.albedo, false);
                        }
                        for (object, (c, r)) in scene.objects.iter().zip(&poses) {
                            if let Some((z, n)) = intersect_analytic(&object.shape, c, r, &ray)
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
        let Some(face) = (p[1] - p[0]).cross(&(p[2] - p[0])).try_normalize(0.0) else {
            return; // degenerate
        };
        rasterise_triangle(camera, &p, |hit: RayHit| {
            let i = hit.pixel;
            if hit.z <= self.z_mm[i] {
                return;
            }
            // Turned towards the camera along this pixel's ray.
            let towards = hit.ray.slope;
            let face = if face.dot(&towards) < 0.0 {
                -face
            } else {
                face
            };
            let w = hit.weights;
            let normal = match vertex_normals {
                Some(ns) => {
                    let n = w[0] * ns[tri[0]] + w[1] * ns[tri[1]] + w[2] * ns[tri[2]];
                    let n = n.try_normalize(1e-12).unwrap_or(face);
                    if n.dot(&face) < 0.0 { -n } else { n }
                }
                None => face,
            };
            self.z_mm[i] = hit.z;
            self.normals[i] = normal;
            self.albedo[i] = albedo;
            self.is_object[i] = true;
        });
    }

    /// Scene point X of pixel `i`: where its ray meets the surface.
    pub fn point(&self, camera: &Camera, i: usize) -> Vector3<f64> {
        camera
            .ray((i / self.width) as f64, (i % self.width) as f64)
            .at(self.z_mm[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;
    use crate::scene::SceneObject;
    use std::sync::Arc;

    fn camera() -> Camera {
        Camera::test_64x48(Some(1.0), None)
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
        for camera in [camera(), perspective_camera()] {
            let ma = SurfaceMap::render(&Scene::single(a.clone()), &camera, 0.0);
            let mb = SurfaceMap::render(&Scene::single(b.clone()), &camera, 0.0);
            let mut compared = 0;
            for i in 0..ma.z_mm.len() {
                assert_eq!(ma.is_object[i], mb.is_object[i] && ma.is_object[i]);
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

    /// A 64×48 pinhole camera 400 mm away with f = 1500 px (≈ 0.27 mm per pixel at the origin)
    /// and barrel distortion.
    fn perspective_camera() -> Camera {
        Camera::test_64x48(
            None,
            Some(meb_core::rig::Intrinsics {
                fx: 1500.0,
                fy: 1500.0,
                cx: 31.5,
                cy: 23.5,
                k1: -0.5,
                k2: 0.0,
            }),
        )
    }

    /// Seen in perspective, every sphere pixel's point lies on the sphere with the radial normal,
    /// and the silhouette is the cone of rays tangent to it: a disc of angular radius
    /// asin(R/D), larger than the orthographic R.
    #[test]
    fn perspective_sphere_points_lie_on_the_sphere() {
        let camera = perspective_camera();
        let radius = 5.0;
        let scene = Scene::single(SceneObject::new(Shape::Sphere { radius_mm: radius }));
        let map = SurfaceMap::render(&scene, &camera, 0.0);
        let mut inside = 0usize;
        for i in 0..map.z_mm.len() {
            let ray = camera.ray((i / 64) as f64, (i % 64) as f64);
            // The ray's closest approach to the centre decides whether it hits.
            let dir = ray.slope.normalize();
            let miss = (ray.base - dir * ray.base.dot(&dir)).norm();
            if !map.is_object[i] {
                assert!(miss >= radius - 1e-6, "pixel {i} should hit");
                continue;
            }
            inside += 1;
            let x = map.point(&camera, i);
            assert!((x.norm() - radius).abs() < 1e-9);
            assert!((map.normals[i] - x / radius).norm() < 1e-9);
            // The front hit is the one nearer the camera.
            assert!(x.dot(&ray.towards_camera()) >= -1e-9);
        }
        assert!(inside > 900, "{inside}");
    }
}
