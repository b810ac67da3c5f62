//! A chequerboard photographed by the rig's camera at a pose: the images a camera
//! calibration works from, with the board's inner corners in the image as the truth.
//!
//! The board lies in its own plane: inner corner (i, j) at board coordinates (u, v) =
//! (i·s, j·s) mm (s the square's edge, i along a row, j down a column), (cols + 1) × (rows + 1)
//! squares alternating dark (reflectance 0.1) and light (0.9), the one at the first corner
//! dark, inside a light margin one square wide, nothing (0) off the board. Its pose puts the middle of its inner corners at `centre_mm` with the board's
//! u axis along R·x̂, its v axis along −R·ŷ (image rows go down) and its face along R·ẑ,
//! towards the camera. A pixel reads 0.05 + 0.9·(mean reflectance over a 4×4 grid of
//! sub-pixel rays, each met with the board's plane) plus Gaussian noise, in [0, 1].

use meb_core::rig::Camera;
use nalgebra::{Rotation3, Vector3};
use ndarray::Array2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::Distribution;

/// A chequerboard at a pose in the scene (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct BoardView {
    /// Inner corners along a row.
    pub cols: usize,
    /// Inner corners along a column.
    pub rows: usize,
    /// Square edge, mm.
    pub square_mm: f64,
    /// Scene position of the middle of the inner corners, mm.
    pub centre_mm: Vector3<f64>,
    /// The board's orientation R (module docs).
    pub rotation: Rotation3<f64>,
}

impl BoardView {
    /// Board coordinates (u, v) relative to the middle of the inner corners → scene point.
    fn scene_point(&self, u: f64, v: f64) -> Vector3<f64> {
        let (mu, mv) = self.middle();
        self.centre_mm + self.rotation * Vector3::new(u - mu, -(v - mv), 0.0)
    }

    /// Board coordinates of the middle of the inner corners.
    fn middle(&self) -> (f64, f64) {
        (
            0.5 * (self.cols - 1) as f64 * self.square_mm,
            0.5 * (self.rows - 1) as f64 * self.square_mm,
        )
    }

    /// Scene point of inner corner (i along a row, j down a column).
    pub fn corner(&self, i: usize, j: usize) -> Vector3<f64> {
        self.scene_point(i as f64 * self.square_mm, j as f64 * self.square_mm)
    }

    /// The board's outline with its margin, scene points (four corners).
    pub fn outline(&self) -> [Vector3<f64>; 4] {
        let s = self.square_mm;
        let (u1, v1) = ((self.cols + 1) as f64 * s, (self.rows + 1) as f64 * s);
        [
            self.scene_point(-2.0 * s, -2.0 * s),
            self.scene_point(u1, -2.0 * s),
            self.scene_point(u1, v1),
            self.scene_point(-2.0 * s, v1),
        ]
    }

    /// Reflectance at board coordinates (u, v) (module docs).
    fn albedo(&self, u: f64, v: f64) -> f64 {
        let (a, b) = (u / self.square_mm, v / self.square_mm);
        let (cols, rows) = (self.cols as f64, self.rows as f64);
        if a < -2.0 || b < -2.0 || a > cols + 1.0 || b > rows + 1.0 {
            return 0.0;
        }
        if a < -1.0 || b < -1.0 || a > cols || b > rows {
            return 0.9;
        }
        if (a.floor() as i64 + b.floor() as i64).rem_euclid(2) == 0 {
            0.1
        } else {
            0.9
        }
    }

    /// Reflectance seen along the ray of the continuous pixel (row, col) of `camera`.
    fn albedo_seen(&self, camera: &Camera, row: f64, col: f64) -> f64 {
        let ray = camera.ray(row, col);
        let normal = self.rotation * Vector3::z();
        let along = normal.dot(&ray.slope);
        if along.abs() < 1e-12 {
            return 0.0;
        }
        let x = ray.at(normal.dot(&(self.centre_mm - ray.base)) / along);
        let d = self.rotation.inverse() * (x - self.centre_mm);
        let (mu, mv) = self.middle();
        self.albedo(d.x + mu, mv - d.y)
    }

    /// The board's image in `camera` with Gaussian noise σ = `noise` (module docs).
    pub fn image(&self, camera: &Camera, noise: f64, seed: u64) -> Array2<f32> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let normal = rand_distr::Normal::new(0.0, noise.max(0.0)).ok();
        let mut image = Array2::from_shape_fn((camera.height, camera.width), |(r, c)| {
            let mut sum = 0.0;
            for a in 0..4 {
                for b in 0..4 {
                    sum += self.albedo_seen(
                        camera,
                        r as f64 - 0.5 + (f64::from(a) + 0.5) / 4.0,
                        c as f64 - 0.5 + (f64::from(b) + 0.5) / 4.0,
                    );
                }
            }
            (0.05 + 0.9 * sum / 16.0) as f32
        });
        if let Some(n) = normal {
            image
                .iter_mut()
                .for_each(|v| *v = (*v + n.sample(&mut rng) as f32).clamp(0.0, 1.0));
        }
        image
    }

    /// The inner corners' image positions (x = column, y = row), row-major from corner (0, 0);
    /// `None` when one is behind the camera.
    pub fn corner_pixels(&self, camera: &Camera) -> Option<Vec<[f64; 2]>> {
        let mut pixels = Vec::with_capacity(self.cols * self.rows);
        for j in 0..self.rows {
            for i in 0..self.cols {
                let (row, col) = camera.project(&self.corner(i, j))?;
                pixels.push([col, row]);
            }
        }
        Some(pixels)
    }
}

/// `count` poses of a `cols`×`rows` board of `square_mm` squares seen whole by `camera` (with
/// a margin of `camera.width / 20` pixels), at distances that make it span 55–85 % of the
/// image's width, tilted 20–55° about a random axis in its plane and turned up to 30° in its
/// plane; seeded. Strong tilts and boards that fill the image are what pin the principal
/// point (Z. Zhang, IEEE TPAMI 2000, §5: the fit degrades as the views approach parallel
/// planes): with tilts up to 40° and boards over a third to two thirds of the width, ten
/// views leave cx and cy uncertain to 1–2 px.
pub fn random_board_views(
    camera: &Camera,
    cols: usize,
    rows: usize,
    square_mm: f64,
    count: usize,
    seed: u64,
) -> Vec<BoardView> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let projection = camera.projection();
    let width = (cols + 3) as f64 * square_mm;
    let margin = camera.width as f64 / 20.0;
    let mut views = Vec::with_capacity(count);
    for _ in 0..count * 200 {
        if views.len() == count {
            break;
        }
        let tilt_axis: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let tilt = rng.random_range(20f64.to_radians()..55f64.to_radians());
        let spin = rng.random_range(-30f64.to_radians()..30f64.to_radians());
        let rotation = Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(Vector3::new(tilt_axis.cos(), tilt_axis.sin(), 0.0)),
            tilt,
        ) * Rotation3::from_axis_angle(&Vector3::z_axis(), spin);
        // A distance from the camera at which the board spans the chosen share of the width.
        let share = rng.random_range(0.55..0.85);
        let pitch = camera.pitch_mm() / camera.distance_mm;
        let distance = width / (share * camera.width as f64 * pitch);
        let spread = 0.5 * (1.0 - share) * camera.width as f64 * pitch * distance;
        let centre = Vector3::new(
            rng.random_range(-spread..spread),
            rng.random_range(-0.5 * spread..0.5 * spread),
            camera.distance_mm - distance,
        );
        let view = BoardView {
            cols,
            rows,
            square_mm,
            centre_mm: centre,
            rotation,
        };
        let inside = view.outline().iter().all(|x| {
            projection.project(x).is_some_and(|(r, c)| {
                r > margin
                    && c > margin
                    && r < camera.height as f64 - 1.0 - margin
                    && c < camera.width as f64 - 1.0 - margin
            })
        });
        if inside {
            views.push(view);
        }
    }
    views
}

#[cfg(test)]
mod tests {
    use super::*;
    use meb_core::rig::Intrinsics;

    fn camera() -> Camera {
        let mut camera = Camera::test_64x48(None, None);
        camera.width = 320;
        camera.height = 180;
        camera.intrinsics = Some(Intrinsics {
            fx: 400.0,
            fy: 402.0,
            cx: 161.0,
            cy: 88.5,
            k1: -0.08,
            k2: 0.02,
        });
        camera
    }

    /// Every pose shows the whole board, and the image is dark and light around a corner where
    /// the truth puts it.
    #[test]
    fn random_views_show_the_board_with_its_corners_where_the_truth_says() {
        let camera = camera();
        let views = random_board_views(&camera, 7, 5, 20.0, 6, 3);
        assert_eq!(views.len(), 6);
        for view in &views {
            let image = view.image(&camera, 0.0, 1);
            let corners = view.corner_pixels(&camera).unwrap();
            assert_eq!(corners.len(), 35);
            // Across corner (0, 0) the squares alternate: the diagonal neighbours along the
            // board's u + v direction differ from those along u − v.
            let [x, y] = corners[0];
            let [xu, yu] = corners[1];
            let [xv, yv] = corners[7];
            let at = |a: f64, b: f64| {
                let (c, r) = (
                    x + 0.3 * (a * (xu - x) + b * (xv - x)),
                    y + 0.3 * (a * (yu - y) + b * (yv - y)),
                );
                f64::from(image[(r.round() as usize, c.round() as usize)])
            };
            let same = at(1.0, 1.0) + at(-1.0, -1.0);
            let other = at(1.0, -1.0) + at(-1.0, 1.0);
            assert!((same - other).abs() > 0.8, "{same} {other}");
            assert!(
                at(1.0, 1.0) < 0.3,
                "the first square is dark: {}",
                at(1.0, 1.0)
            );
        }
    }
}
