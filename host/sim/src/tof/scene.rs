//! The thesis' hybrid scene (Fig. 6.4): a Ø48 mm sphere, a head-like shape and a 75 mm cube
//! 100 mm apart in depth (sphere nearest; the thesis measured 20, 30 and 40 cm beyond its 60 cm
//! reference board), in front of a wall, within the view of both the phone and the SPAD of the
//! `thesis-hybrid` rig. The head is built from ellipsoids (skull, two ears, a nose, a muzzle) at
//! the thesis' monkey-head size, 130 × 94.5 × 79 mm; the cube is turned to show three faces, as
//! the thesis' "cube corner" did.

use crate::scene::{GroundPlane, Scene, SceneObject};
use nalgebra::{UnitQuaternion, Vector3};

/// A scene whose objects are grouped into named objects (several analytic parts may form one).
#[derive(Debug, Clone)]
pub struct HybridScene {
    /// The geometry (the wall is its ground plane).
    pub scene: Scene,
    /// Object group of each scene object.
    pub groups: Vec<usize>,
    /// Name of each group.
    pub names: Vec<String>,
}

/// The thesis-hybrid preset (module docs).
pub fn thesis_hybrid_scene() -> HybridScene {
    let mut objects = Vec::new();
    let mut groups = Vec::new();
    let mut add = |o: SceneObject, group: usize| {
        objects.push(o);
        groups.push(group);
    };
    let mut sphere = SceneObject::sphere(48.0);
    sphere.position_mm = Vector3::new(-80.0, -38.0, 100.0);
    sphere.albedo = 0.9;
    add(sphere, 0);
    let head_centre = Vector3::new(-15.0, 25.0, 0.0);
    let part = |axes: [f64; 3], offset: [f64; 3]| {
        let mut o = SceneObject::ellipsoid(axes);
        o.position_mm = head_centre + Vector3::from(offset);
        o.albedo = 0.8;
        o
    };
    // Skull 84 × 94.5 × 76, ears to 130 wide, nose and muzzle to 79 deep.
    add(part([84.0, 94.5, 76.0], [0.0, 0.0, 0.0]), 1);
    add(part([26.0, 30.0, 14.0], [-52.0, 10.0, -6.0]), 1);
    add(part([26.0, 30.0, 14.0], [52.0, 10.0, -6.0]), 1);
    add(part([52.0, 30.0, 30.0], [0.0, -22.0, 24.0]), 1);
    add(part([16.0, 22.0, 14.0], [0.0, -4.0, 33.0]), 1);
    let mut cube = SceneObject::cube(75.0, false);
    cube.rotation = UnitQuaternion::from_euler_angles(20f64.to_radians(), -20f64.to_radians(), 0.0);
    cube.position_mm = Vector3::new(85.0, -22.0, -100.0);
    cube.albedo = 0.85;
    add(cube, 2);
    HybridScene {
        scene: Scene {
            objects,
            ground: Some(GroundPlane {
                z_mm: -250.0,
                albedo: 0.5,
            }),
        },
        groups,
        names: vec!["sphere".into(), "head".into(), "cube".into()],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tof::{camera_labels, cast_ray};
    use meb_core::rig::Rig;

    /// Every object is whole in the phone's view and in the SPAD's, no two objects touch in the
    /// phone's image, and they stand at the thesis' 100 mm depth steps.
    #[test]
    fn objects_are_in_view_and_apart() {
        let hybrid = thesis_hybrid_scene();
        let mut rig = Rig::preset("thesis-hybrid").unwrap();
        rig.camera.pixel_pitch_mm = Some(rig.camera.pitch_mm() * 4.0);
        rig.camera.width = 320;
        rig.camera.height = 180;
        let labels = camera_labels(&hybrid.scene, &hybrid.groups, &rig.camera);
        let (rows, cols) = labels.dim();
        for g in 0..3 {
            let count = labels.iter().filter(|&&l| l == g).count();
            assert!(count > 200, "object {g}: {count} pixels");
            let on_border = labels
                .indexed_iter()
                .any(|((r, c), &l)| l == g && (r == 0 || c == 0 || r + 1 == rows || c + 1 == cols));
            assert!(!on_border, "object {g} is cut by the phone's frame");
        }
        let touching = labels.indexed_iter().any(|((r, c), &l)| {
            l >= 0
                && [(r + 1, c), (r, c + 1)]
                    .iter()
                    .any(|&q| q.0 < rows && q.1 < cols && labels[q] >= 0 && labels[q] != l)
        });
        assert!(!touching, "two objects touch in the phone's image");
        let tof = rig.tof_camera.expect("the hybrid rig has a SPAD");
        let origin = Vector3::from(tof.position_mm);
        let mut seen = [0usize; 3];
        let (h, w) = (tof.height, tof.width);
        for r in 0..h {
            for c in 0..w {
                let hit = cast_ray(
                    &hybrid.scene,
                    &hybrid.groups,
                    &origin,
                    &tof.ray(r as f64, c as f64),
                )
                .unwrap();
                let label = hit.map_or(-2, |h| h.3);
                if r == 0 || c == 0 || r + 1 == h || c + 1 == w {
                    assert_eq!(label, -1, "the SPAD's frame cuts an object at ({r}, {c})");
                } else if label >= 0 {
                    seen[label as usize] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&n| n > 100), "{seen:?}");
    }
}
