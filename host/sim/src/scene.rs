//! Scene description: objects (analytic shapes or triangle meshes), their pose, albedo and
//! motion, and an optional ground plane behind them.
//!
//! Coordinates follow docs/maths/coordinates.md#the-scene-frame: origin at the object centre, x
//! right, y up, z towards the
//! camera, millimetres. An object's shape is given in its own frame centred on the origin;
//! its pose at time t is `X = R(t)·x + c` with `R(t) = Rot(axis, 2π·rpm/60·t) · R₀` when it
//! spins (thesis Ch. 5: ellipsoid 100×60 mm turning at 7.5 rpm about a vertical axis).

use super::mesh::TriMesh;
use meb_core::rig::PixelRay;
use nalgebra::{Unit, UnitQuaternion, Vector3};
use std::sync::Arc;

/// The geometry of one object in its own frame (centred on its origin).
#[derive(Debug, Clone)]
pub enum Shape {
    /// A sphere of the given radius.
    Sphere {
        /// Radius in mm.
        radius_mm: f64,
    },
    /// An ellipsoid with the given semi-axes along its local x, y, z.
    Ellipsoid {
        /// Semi-axes in mm.
        semi_axes_mm: [f64; 3],
    },
    /// A box with the given half edge lengths along its local x, y, z.
    Cuboid {
        /// Half extents in mm.
        half_extents_mm: [f64; 3],
    },
    /// A triangle mesh (STL/OBJ file or a generated blobby shape).
    Mesh(Arc<TriMesh>),
}

/// Spin of an object about an axis through its centre.
#[derive(Debug, Clone, PartialEq)]
pub struct Spin {
    /// Rotation axis in scene coordinates.
    pub axis: Unit<Vector3<f64>>,
    /// Revolutions per minute (sign = direction, right-hand rule).
    pub rpm: f64,
}

/// One object of the scene.
#[derive(Debug, Clone)]
pub struct SceneObject {
    /// Its shape in its own frame.
    pub shape: Shape,
    /// Centre position c in mm.
    pub position_mm: Vector3<f64>,
    /// Orientation R₀ at t = 0.
    pub rotation: UnitQuaternion<f64>,
    /// Lambertian albedo ρ in [0, 1].
    pub albedo: f64,
    /// Optional spin.
    pub spin: Option<Spin>,
}

impl SceneObject {
    /// An object at the origin, unrotated, albedo 1, not moving.
    pub fn new(shape: Shape) -> Self {
        Self {
            shape,
            position_mm: Vector3::zeros(),
            rotation: UnitQuaternion::identity(),
            albedo: 1.0,
            spin: None,
        }
    }

    /// A sphere of diameter `diameter_mm` (thesis: Ø48 mm).
    pub fn sphere(diameter_mm: f64) -> Self {
        Self::new(Shape::Sphere {
            radius_mm: diameter_mm / 2.0,
        })
    }

    /// A cube of edge `edge_mm` (thesis: 75 mm), face-on, or corner-on (a body diagonal
    /// pointing at the camera).
    pub fn cube(edge_mm: f64, corner_on: bool) -> Self {
        let mut o = Self::new(Shape::Cuboid {
            half_extents_mm: [edge_mm / 2.0; 3],
        });
        if corner_on {
            o.rotation = UnitQuaternion::rotation_between(&Vector3::repeat(1.0), &Vector3::z())
                .unwrap_or_else(UnitQuaternion::identity);
        }
        o
    }

    /// An ellipsoid with full axis lengths `axes_mm` (thesis Ch. 5: 100×60×60 mm).
    pub fn ellipsoid(axes_mm: [f64; 3]) -> Self {
        Self::new(Shape::Ellipsoid {
            semi_axes_mm: axes_mm.map(|a| a / 2.0),
        })
    }

    /// Orientation at time `t_s` seconds.
    pub fn rotation_at(&self, t_s: f64) -> UnitQuaternion<f64> {
        match &self.spin {
            Some(spin) if spin.rpm != 0.0 => {
                let angle = std::f64::consts::TAU * spin.rpm / 60.0 * t_s;
                UnitQuaternion::from_axis_angle(&spin.axis, angle) * self.rotation
            }
            _ => self.rotation,
        }
    }
}

/// A flat background perpendicular to the camera axis.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundPlane {
    /// Its height z in mm (negative: behind the object centre).
    pub z_mm: f64,
    /// Its albedo.
    pub albedo: f64,
}

/// Everything in front of the camera.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// The objects (their pixels form the ground-truth mask).
    pub objects: Vec<SceneObject>,
    /// Optional ground plane (lit and shadowed, but outside the mask).
    pub ground: Option<GroundPlane>,
}

impl Scene {
    /// A scene holding one object.
    pub fn single(object: SceneObject) -> Self {
        Self {
            objects: vec![object],
            ground: None,
        }
    }

    /// Whether the geometry changes with time (some object spins).
    pub fn is_moving(&self) -> bool {
        self.objects
            .iter()
            .any(|o| o.spin.as_ref().is_some_and(|s| s.rpm != 0.0))
    }
}

/// Front-most hit of an analytic shape along a pixel's ray: returns (z, unit normal) in scene
/// coordinates.
pub(crate) fn intersect_analytic(
    shape: &Shape,
    centre: &Vector3<f64>,
    rotation: &UnitQuaternion<f64>,
    ray: &PixelRay,
) -> Option<(f64, Vector3<f64>)> {
    // Ray X(z) = base + z·slope; in the object frame q(z) = a + z·b.
    let inv = rotation.inverse();
    let a = inv * (ray.base - centre);
    let b = inv * ray.slope;
    let (z, local_normal) = match shape {
        Shape::Sphere { radius_mm } => quadric_hit(&a, &b, &Vector3::repeat(*radius_mm))?,
        Shape::Ellipsoid { semi_axes_mm } => quadric_hit(&a, &b, &Vector3::from(*semi_axes_mm))?,
        Shape::Cuboid { half_extents_mm } => box_hit(&a, &b, &Vector3::from(*half_extents_mm))?,
        Shape::Mesh(_) => return None,
    };
    let n = rotation * local_normal;
    Some((z, n.normalize()))
}

/// Largest z with |(a + z·b) ⊘ s| = 1 and the ellipsoid normal there.
fn quadric_hit(
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    s: &Vector3<f64>,
) -> Option<(f64, Vector3<f64>)> {
    let a2 = a.component_div(s);
    let b2 = b.component_div(s);
    let qa = b2.norm_squared();
    let qb = 2.0 * a2.dot(&b2);
    let qc = a2.norm_squared() - 1.0;
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 || qa <= 0.0 {
        return None;
    }
    let z = (-qb + disc.sqrt()) / (2.0 * qa);
    let q = a + z * b;
    let normal = q.component_div(&s.component_mul(s));
    Some((z, normal))
}

/// Largest z inside the box |q_k| ≤ h_k and the face normal there (slab method).
fn box_hit(a: &Vector3<f64>, b: &Vector3<f64>, h: &Vector3<f64>) -> Option<(f64, Vector3<f64>)> {
    let mut lo = f64::NEG_INFINITY;
    let mut hi = f64::INFINITY;
    let mut hi_axis = 0;
    for k in 0..3 {
        if b[k].abs() < 1e-12 {
            if a[k].abs() > h[k] {
                return None;
            }
            continue;
        }
        let z1 = (-h[k] - a[k]) / b[k];
        let z2 = (h[k] - a[k]) / b[k];
        let (z_min, z_max) = if z1 < z2 { (z1, z2) } else { (z2, z1) };
        lo = lo.max(z_min);
        if z_max < hi {
            hi = z_max;
            hi_axis = k;
        }
    }
    if lo > hi || !hi.is_finite() {
        return None;
    }
    let q = a + hi * b;
    let mut normal = Vector3::zeros();
    normal[hi_axis] = q[hi_axis].signum();
    Some((hi, normal))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The orthographic ray through (x, y).
    fn down(x: f64, y: f64) -> PixelRay {
        PixelRay {
            base: Vector3::new(x, y, 0.0),
            slope: Vector3::z(),
        }
    }

    #[test]
    fn sphere_hit_is_front_most() {
        let shape = Shape::Sphere { radius_mm: 10.0 };
        let (z, n) = intersect_analytic(
            &shape,
            &Vector3::zeros(),
            &UnitQuaternion::identity(),
            &down(6.0, 0.0),
        )
        .unwrap();
        assert!((z - 8.0).abs() < 1e-12);
        assert!((n - Vector3::new(0.6, 0.0, 0.8)).norm() < 1e-12);
        assert!(
            intersect_analytic(
                &shape,
                &Vector3::zeros(),
                &UnitQuaternion::identity(),
                &down(11.0, 0.0)
            )
            .is_none()
        );
    }

    #[test]
    fn rotated_box_shows_the_right_face() {
        let shape = Shape::Cuboid {
            half_extents_mm: [5.0, 5.0, 5.0],
        };
        let rot = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.3);
        let (z, n) = intersect_analytic(&shape, &Vector3::zeros(), &rot, &down(0.0, 0.0)).unwrap();
        assert!((n - rot * Vector3::z()).norm() < 1e-12);
        assert!((z - 5.0 / 0.3f64.cos()).abs() < 1e-9);
    }

    #[test]
    fn spin_turns_at_rpm() {
        let mut o = SceneObject::new(Shape::Sphere { radius_mm: 1.0 });
        o.spin = Some(Spin {
            axis: Vector3::y_axis(),
            rpm: 7.5,
        });
        // 7.5 rpm = a quarter turn in 2 s.
        let r = o.rotation_at(2.0);
        assert!((r.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }
}
