//! Near-field shading with attached and cast shadows, and the background light.
//!
//! Per pixel with visible surface point X, normal n and albedo ρ, LED i contributes
//! (docs/maths/photometric-stereo.md#light-vectors with the exact per-point light vector of
//! `rig::Led::light_vector_at`)
//!
//! ```text
//! A_i = g · ρ · max(0, L_i(X)·n) · V_i(X)
//! ```
//!
//! g is a global gain (code fraction per unit irradiance), the clamp is the attached shadow and
//! V_i ∈ {0, 1} the cast shadow, found by marching from X towards the LED over the depth map
//! (a height-field shadow test: the object is taken to be solid behind its visible surface along
//! every camera ray, so a point of the segment is occluded when the surface seen at its pixel is
//! nearer the camera). Objects of a glossy [`Material`] add a specular lobe to the Lambertian
//! term ([`super::material`]). These A_i are the `led_true` images: the value a pixel reads with only
//! LED i constantly on, no background, no noise.
//!
//! Background (unmodulated room light, thesis Eq. 4.3 `SNR = 10·log10(P_signal/P_noise)`, both
//! measured as optical power at the object location): we model it as a uniform overhead dome,
//! which lights a surface of normal n with irradiance E_bg·(1 + n_z)/2 (no shadows). Reading
//! the thesis' photodetector as facing up (+z) at the object centre and time-averaging the
//! modulated LEDs (50 % duty), P_signal = Σ_i g·max(0, L_i(0)·ẑ)/2 and P_noise = E_bg, so
//! `E_bg = P_signal · 10^(−SNR/10)`.

use super::geometry::SurfaceMap;
use super::material::Material;
use meb_core::rig::{Camera, Rig};
use nalgebra::Vector3;
use ndarray::Array2;
use rayon::prelude::*;

/// Peak of the brightest LED image on the default scene (Ø48 mm sphere, albedo 1).
pub const DEFAULT_PEAK: f64 = 0.4;

/// Radius of the reference sphere used to set the default gain, mm.
const REFERENCE_RADIUS_MM: f64 = 24.0;

/// Global gain g such that the brightest LED peaks at `peak` of full scale on a Ø48 mm
/// sphere of albedo 1 at the origin (the brightest point faces that LED).
pub fn default_gain(rig: &Rig, peak: f64) -> f64 {
    let brightest = rig
        .leds
        .iter()
        .map(|led| {
            let p = led.position();
            let x = p.normalize() * REFERENCE_RADIUS_MM;
            led.light_vector_at(&x).norm()
        })
        .fold(0.0, f64::max);
    if brightest > 0.0 {
        peak / brightest
    } else {
        1.0
    }
}

/// Time-averaged LED irradiance (in code fractions) on an upward detector at the origin:
/// P_signal of thesis Eq. 4.3.
pub fn signal_power(rig: &Rig, gain: f64) -> f64 {
    rig.leds
        .iter()
        .map(|led| 0.5 * gain * led.light_vector_at(&Vector3::zeros()).z.max(0.0))
        .sum()
}

/// Background irradiance E_bg for a given SNR in dB (thesis Eq. 4.3).
pub fn background_power(rig: &Rig, gain: f64, snr_db: f64) -> f64 {
    signal_power(rig, gain) * 10f64.powf(-snr_db / 10.0)
}

/// Per-LED on-level images A_i (module docs) of matte objects, fractions of full scale.
pub fn led_images(map: &SurfaceMap, rig: &Rig, gain: f64) -> Vec<Array2<f32>> {
    led_images_of(map, rig, gain, &Material::MATTE)
}

/// Per-LED on-level images A_i of objects of `material` ([`super::material`]; the ground plane
/// stays matte), fractions of full scale.
pub fn led_images_of(
    map: &SurfaceMap,
    rig: &Rig,
    gain: f64,
    material: &Material,
) -> Vec<Array2<f32>> {
    let camera = &rig.camera;
    let field = HeightField::new(map, camera);
    rig.leds
        .iter()
        .map(|led| {
            let values: Vec<f32> = (0..map.z_mm.len())
                .into_par_iter()
                .map(|i| {
                    if !map.z_mm[i].is_finite() || map.albedo[i] <= 0.0 {
                        return 0.0;
                    }
                    let x = map.point(camera, i);
                    let l = led.light_vector_at(&x);
                    let shade = l.dot(&map.normals[i]);
                    if shade <= 0.0 {
                        return 0.0; // attached shadow
                    }
                    let (row, col) = (i / map.width, i % map.width);
                    if field.occluded(row as f64, col as f64, &x, &led.position()) {
                        return 0.0; // cast shadow
                    }
                    if material.is_matte() || !map.is_object[i] {
                        return (gain * map.albedo[i] * shade) as f32;
                    }
                    let view = camera.ray(row as f64, col as f64).towards_camera();
                    (gain * material.shade(map.albedo[i], &map.normals[i], &l, &view)) as f32
                })
                .collect();
            Array2::from_shape_vec((map.height, map.width), values)
                .unwrap_or_else(|_| Array2::zeros((map.height, map.width)))
        })
        .collect()
}

/// Background image ρ·E_bg·(1 + n_z)/2 (module docs).
pub fn background_image(map: &SurfaceMap, irradiance: f64) -> Array2<f32> {
    let values: Vec<f32> = (0..map.z_mm.len())
        .map(|i| {
            if map.z_mm[i].is_finite() {
                (irradiance * map.albedo[i] * (1.0 + map.normals[i].z) / 2.0) as f32
            } else {
                0.0
            }
        })
        .collect();
    Array2::from_shape_vec((map.height, map.width), values)
        .unwrap_or_else(|_| Array2::zeros((map.height, map.width)))
}

/// Side of the square pixel blocks of the max-height grid used to skip empty space.
const BLOCK: usize = 8;

/// The depth map prepared for shadow rays: a grid of per-block maximum heights (dilated by one
/// pixel, so it bounds every sample taken inside the block) lets a ray jump over whole blocks
/// it passes above.
struct HeightField<'a> {
    map: &'a SurfaceMap,
    camera: &'a Camera,
    pitch: f64,
    z_top: f64,
    blocks_wide: usize,
    block_max: Vec<f64>,
}

impl<'a> HeightField<'a> {
    fn new(map: &'a SurfaceMap, camera: &'a Camera) -> Self {
        let pitch = camera.pitch_mm();
        let blocks_wide = map.width.div_ceil(BLOCK);
        let blocks_high = map.height.div_ceil(BLOCK);
        let mut block_max = vec![f64::NEG_INFINITY; blocks_wide * blocks_high];
        for (i, &z) in map.z_mm.iter().enumerate() {
            if !z.is_finite() {
                continue;
            }
            let (row, col) = (i / map.width, i % map.width);
            // Every block whose dilated footprint contains this pixel.
            let rows = row.saturating_sub(1) / BLOCK..=((row + 1) / BLOCK).min(blocks_high - 1);
            for br in rows {
                let cols = col.saturating_sub(1) / BLOCK..=((col + 1) / BLOCK).min(blocks_wide - 1);
                for bc in cols {
                    let m = &mut block_max[br * blocks_wide + bc];
                    *m = m.max(z);
                }
            }
        }
        let z_top = map
            .z_mm
            .iter()
            .copied()
            .filter(|z| z.is_finite())
            .fold(f64::NEG_INFINITY, f64::max);
        Self {
            map,
            camera,
            pitch,
            z_top,
            blocks_wide,
            block_max,
        }
    }

    /// Height-field shadow test: does the depth map rise above the segment from surface
    /// point `x` (at pixel `row0`, `col0`) to the LED at `led`?
    fn occluded(&self, row0: f64, col0: f64, x: &Vector3<f64>, led: &Vector3<f64>) -> bool {
        if self.camera.is_perspective() {
            self.occluded_perspective(x, led)
        } else {
            self.occluded_orthographic(row0, col0, x, led)
        }
    }

    /// [`Self::occluded`] for a perspective camera: the segment's points are projected into
    /// the image one at a time, in steps of about half a pixel.
    fn occluded_perspective(&self, x: &Vector3<f64>, led: &Vector3<f64>) -> bool {
        let to_led = led - x;
        let rising = to_led.z > 0.0;
        let tolerance = 0.05 * self.pitch;
        let pixel = |s: f64| self.camera.project(&(x + to_led * s));
        let Some(mut here) = pixel(0.0) else {
            return false;
        };
        let mut s = 0.0;
        while s < 1.0 {
            // Step so that the projection moves about half a pixel.
            let probe = 1e-4_f64.min(1.0 - s).max(1e-9);
            let Some(ahead) = pixel(s + probe) else {
                return false; // the segment passes behind the camera
            };
            let speed = (ahead.0 - here.0).hypot(ahead.1 - here.1) / probe;
            s += if speed > 0.0 {
                (0.5 / speed).max(1e-6)
            } else {
                1.0
            };
            if s >= 1.0 {
                return false;
            }
            let q = x + to_led * s;
            if rising && q.z > self.z_top {
                return false;
            }
            let Some((row, col)) = self.camera.project(&q) else {
                return false;
            };
            here = (row, col);
            match sample_depth(self.map, row, col) {
                None => return false, // left the image
                Some(surface) if surface > q.z + tolerance => return true,
                Some(_) => {}
            }
        }
        false
    }

    /// [`Self::occluded`] for the orthographic camera: a straight march in pixel coordinates
    /// that jumps over blocks the segment passes above.
    fn occluded_orthographic(
        &self,
        row0: f64,
        col0: f64,
        x: &Vector3<f64>,
        led: &Vector3<f64>,
    ) -> bool {
        let to_led = led - x;
        let horizontal = (to_led.x * to_led.x + to_led.y * to_led.y).sqrt();
        if horizontal < 1e-9 {
            return false; // straight up: a height field cannot occlude
        }
        // Pixel coordinates along the ray: row = row0 + s·dr, col = col0 + s·dc (y up = row down).
        let dr = -to_led.y / self.pitch;
        let dc = to_led.x / self.pitch;
        let rising = to_led.z > 0.0;
        // Half-pixel steps in the image plane.
        let step = 0.5 * self.pitch / horizontal;
        let tolerance = 0.05 * self.pitch;
        let (h, w) = (self.map.height as f64, self.map.width as f64);
        let mut s = step;
        while s < 1.0 {
            let z = x.z + s * to_led.z;
            if rising && z > self.z_top {
                return false;
            }
            let (row, col) = (row0 + s * dr, col0 + s * dc);
            if !(row > -0.5 && col > -0.5 && row < h - 0.5 && col < w - 0.5) {
                return false; // left the image
            }
            let br = (row.max(0.0) as usize) / BLOCK;
            let bc = (col.max(0.0) as usize) / BLOCK;
            if rising && z > self.block_max[br * self.blocks_wide + bc] + tolerance {
                // Jump to where the ray leaves this block (the ray only rises).
                // Block b spans continuous coordinates [b·B, (b+1)·B); block 0 starts at the
                // image edge −0.5, so the exit always lies ahead of the current point.
                let exit = |p0: f64, d: f64, b: usize| {
                    if d > 0.0 {
                        ((b + 1) * BLOCK) as f64 - p0
                    } else if b == 0 {
                        -0.5 - p0
                    } else {
                        (b * BLOCK) as f64 - p0
                    }
                };
                let sr = if dr != 0.0 {
                    exit(row0, dr, br) / dr
                } else {
                    f64::INFINITY
                };
                let sc = if dc != 0.0 {
                    exit(col0, dc, bc) / dc
                } else {
                    f64::INFINITY
                };
                let next = sr.min(sc) + 1e-6 / dr.abs().max(dc.abs());
                s = next.max(s + 1e-3 * step);
                continue;
            }
            if let Some(surface) = sample_depth(self.map, row, col)
                && surface > z + tolerance
            {
                return true;
            }
            s += step;
        }
        false
    }
}

/// Depth at continuous pixel coordinates: bilinear where all four neighbours are surface,
/// nearest otherwise; `None` outside the image.
fn sample_depth(map: &SurfaceMap, row: f64, col: f64) -> Option<f64> {
    let (h, w) = (map.height as f64, map.width as f64);
    if !(row > -0.5 && col > -0.5 && row < h - 0.5 && col < w - 0.5) {
        return None;
    }
    let r0 = row.floor().clamp(0.0, h - 1.0);
    let c0 = col.floor().clamp(0.0, w - 1.0);
    let r1 = (r0 + 1.0).min(h - 1.0);
    let c1 = (c0 + 1.0).min(w - 1.0);
    let at = |r: f64, c: f64| map.z_mm[r as usize * map.width + c as usize];
    let (z00, z01, z10, z11) = (at(r0, c0), at(r0, c1), at(r1, c0), at(r1, c1));
    if z00.is_finite() && z01.is_finite() && z10.is_finite() && z11.is_finite() {
        let fr = (row - r0).clamp(0.0, 1.0);
        let fc = (col - c0).clamp(0.0, 1.0);
        let top = z00 + (z01 - z00) * fc;
        let bottom = z10 + (z11 - z10) * fc;
        Some(top + (bottom - top) * fr)
    } else {
        let r = row.round().clamp(0.0, h - 1.0);
        let c = col.round().clamp(0.0, w - 1.0);
        Some(at(r, c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{GroundPlane, Scene, SceneObject, Shape};
    use meb_core::rig::{Camera, Led};

    fn rig_with(leds: Vec<[f64; 3]>, w: usize, h: usize, pitch: f64) -> Rig {
        Rig {
            camera: Camera {
                width: w,
                height: h,
                fps: 960.0,
                distance_mm: 420.0,
                fov_deg: None,
                pixel_pitch_mm: Some(pitch),
                intrinsics: None,
                axis_px: None,
            },
            leds: leds
                .into_iter()
                .map(|position_mm| Led {
                    position_mm,
                    axis: None,
                    intensity: 1.0,
                    lambert_order: 1.0,
                })
                .collect(),
            tof_camera: None,
        }
    }

    /// A plane tilted about y by a known angle: every pixel equals g·ρ·n·L(X).
    #[test]
    fn tilted_plane_shading_is_n_dot_l() {
        let rig = rig_with(
            vec![[-200.0, 50.0, 300.0], [150.0, -80.0, 400.0]],
            40,
            30,
            0.5,
        );
        let tilt = 0.35f64;
        let mut plane = SceneObject::new(Shape::Cuboid {
            half_extents_mm: [100.0, 100.0, 1.0],
        });
        plane.rotation = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::y_axis(), tilt);
        plane.albedo = 0.7;
        let map = SurfaceMap::render(&Scene::single(plane), &rig.camera, 0.0);
        let images = led_images(&map, &rig, 2.0);
        let n = Vector3::new(tilt.sin(), 0.0, tilt.cos());
        for (i, led) in rig.leds.iter().enumerate() {
            for row in 0..30 {
                for col in 0..40 {
                    let (x, y) = rig.camera.pixel_centre_xy(row as f64, col as f64);
                    // Plane through (0, 0, 1/cos) with normal n: z = (1 − n_x·x)/n_z.
                    let z = (1.0 - n.x * x) / n.z;
                    let expected = 2.0 * 0.7 * led.light_vector_at(&Vector3::new(x, y, z)).dot(&n);
                    let got = f64::from(images[i][[row, col]]);
                    assert!((got - expected).abs() < 1e-6 * expected.abs().max(1e-3));
                }
            }
        }
    }

    /// A sphere on a ground plane under a low LED on the left: the shadow falls on the plane
    /// to the right of the sphere, the left of the plane stays lit.
    #[test]
    fn sphere_casts_a_shadow_away_from_the_led() {
        let rig = rig_with(vec![[-270.0, 0.0, 100.0]], 120, 60, 1.0);
        let mut scene = Scene::single(SceneObject::new(Shape::Sphere { radius_mm: 15.0 }));
        scene.ground = Some(GroundPlane {
            z_mm: -15.0,
            albedo: 1.0,
        });
        let map = SurfaceMap::render(&scene, &rig.camera, 0.0);
        let img = &led_images(&map, &rig, 1e4)[0];
        let px = |x: f64| {
            let (r, c) = rig.camera.xy_to_pixel(x, 0.0);
            img[[r.round() as usize, c.round() as usize]]
        };
        assert!(px(-30.0) > 0.0, "left of the sphere is lit");
        assert_eq!(px(30.0), 0.0, "right of the sphere is in its shadow");
        assert!(px(-10.0) > 0.0, "the side facing the LED is lit");
        assert_eq!(px(12.0), 0.0, "the far side is in attached shadow");
    }

    /// Seen by a perspective camera, the ground pixels in shadow are those whose segment to the
    /// LED passes behind the sphere's visible surface along some camera ray (the height-field
    /// model of the module docs, computed here exactly by intersecting each sample's camera ray
    /// with the sphere), but for a few pixels on the shadow's edge where the depth map's
    /// sampling decides.
    #[test]
    fn perspective_shadows_match_the_exact_sphere_shadow() {
        let mut rig = rig_with(vec![[-270.0, 60.0, 100.0]], 120, 60, 1.0);
        rig.camera.pixel_pitch_mm = None;
        rig.camera.intrinsics = Some(meb_core::rig::Intrinsics {
            fx: 435.0,
            fy: 435.0,
            cx: 59.5,
            cy: 29.5,
            k1: 0.0,
            k2: 0.0,
        });
        let radius = 15.0;
        let mut scene = Scene::single(SceneObject::new(Shape::Sphere { radius_mm: radius }));
        scene.ground = Some(GroundPlane {
            z_mm: -15.0,
            albedo: 1.0,
        });
        let map = SurfaceMap::render(&scene, &rig.camera, 0.0);
        let img = &led_images(&map, &rig, 1e4)[0];
        let led = rig.leds[0].position();
        let (mut shadowed, mut differ) = (0, 0);
        for i in 0..map.z_mm.len() {
            if map.is_object[i] {
                continue;
            }
            let x = map.point(&rig.camera, i);
            // Is some sample of x → LED behind the sphere's front surface along its camera ray?
            let camera_centre = Vector3::new(0.0, 0.0, 420.0);
            let exact = (1..4000).any(|k| {
                let q = x + (led - x) * (f64::from(k) / 4000.0);
                let dir = (q - camera_centre).normalize();
                let b = camera_centre.dot(&dir);
                let disc = b * b - (camera_centre.norm_squared() - radius * radius);
                // The ray from the camera centre meets the sphere first at distance t0.
                disc > 0.0 && {
                    let t0 = -b - disc.sqrt();
                    (camera_centre + dir * t0).z > q.z + 0.05
                }
            });
            let simulated = img[[i / 120, i % 120]] == 0.0;
            shadowed += usize::from(exact);
            differ += usize::from(exact != simulated);
        }
        assert!(shadowed > 300, "{shadowed}");
        // Measured: 46 of 1674, all on the shadow's outline.
        assert!(differ * 25 < shadowed, "{differ} of {shadowed} differ");
    }

    /// The block-skipping march agrees with a plain half-pixel march.
    #[test]
    fn block_skipping_matches_a_plain_march() {
        let rig = rig_with(
            vec![
                [-270.0, 420.0, 100.0],
                [140.0, 420.0, 350.0],
                [200.0, -150.0, 60.0],
            ],
            90,
            70,
            1.3,
        );
        let mut scene = Scene::single(SceneObject::new(Shape::Cuboid {
            half_extents_mm: [15.0; 3],
        }));
        scene.objects[0].rotation = nalgebra::UnitQuaternion::from_euler_angles(0.5, 0.4, 0.3);
        let mut ball = SceneObject::new(Shape::Sphere { radius_mm: 12.0 });
        ball.position_mm = Vector3::new(30.0, -20.0, -10.0);
        scene.objects.push(ball);
        scene.ground = Some(GroundPlane {
            z_mm: -25.0,
            albedo: 1.0,
        });
        let map = SurfaceMap::render(&scene, &rig.camera, 0.0);
        let field = HeightField::new(&map, &rig.camera);
        let (mut shadowed, mut differ) = (0, 0);
        for led in &rig.leds {
            let p = led.position();
            for i in 0..map.z_mm.len() {
                let x = map.point(&rig.camera, i);
                let (row, col) = ((i / 90) as f64, (i % 90) as f64);
                let fast = field.occluded(row, col, &x, &p);
                // Plain march with the same step and tolerance.
                let to_led = p - x;
                let step = 0.5 * 1.3 / (to_led.x.powi(2) + to_led.y.powi(2)).sqrt();
                let mut slow = false;
                let mut s = step;
                while s < 1.0 {
                    let q = x + to_led * s;
                    let (r, c) = rig.camera.xy_to_pixel(q.x, q.y);
                    match sample_depth(&map, r, c) {
                        None => break,
                        Some(z) if z > q.z + 0.05 * 1.3 => {
                            slow = true;
                            break;
                        }
                        _ => {}
                    }
                    s += step;
                }
                shadowed += usize::from(slow);
                differ += usize::from(slow != fast);
            }
        }
        assert!(shadowed > 1000, "{shadowed}");
        assert!(differ * 200 < shadowed, "{differ} of {shadowed} differ");
    }
}
