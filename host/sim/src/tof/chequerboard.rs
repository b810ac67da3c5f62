//! Chequerboard calibration targets rendered in the orthographic PS camera and in the SPAD's
//! photon-counting mode (thesis §6.2.1: 200 frames of 10 ms), with the exact ToF → camera
//! homography of the board's plane as the truth.

use super::seed_for;
use meb_core::rig::{Camera, TofCamera};
use nalgebra::{Matrix3, Vector3};
use ndarray::Array2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};

/// A chequerboard in the plane z = `z_mm` facing the cameras: `cols`×`rows` inner corners,
/// squares of `square_mm`, top-left inner corner at `origin_mm` (x, y), rows running along
/// the direction `angle_rad` from +x (towards −y, so image rows go down), with a white margin of
/// one square around the squares.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Chequerboard {
    /// Inner corners along a row.
    pub cols: usize,
    /// Inner corners along a column.
    pub rows: usize,
    /// Square edge, mm.
    pub square_mm: f64,
    /// Scene (x, y) of the top-left inner corner, mm.
    pub origin_mm: [f64; 2],
    /// Height of the board plane, mm.
    pub z_mm: f64,
    /// In-plane rotation, radians.
    pub angle_rad: f64,
}

impl Chequerboard {
    /// Reflectance at scene (x, y): 0.9 white, 0.1 black, 0.9 margin, 0 off the board.
    pub fn albedo(&self, x: f64, y: f64) -> f64 {
        let (s, c) = self.angle_rad.sin_cos();
        let (dx, dy) = (x - self.origin_mm[0], self.origin_mm[1] - y);
        let u = (c * dx + s * dy) / self.square_mm;
        let v = (-s * dx + c * dy) / self.square_mm;
        let (cols, rows) = (self.cols as f64, self.rows as f64);
        if u < -2.0 || v < -2.0 || u > cols + 1.0 || v > rows + 1.0 {
            return 0.0;
        }
        if u < -1.0 || v < -1.0 || u > cols || v > rows {
            return 0.9;
        }
        if (u.floor() as i64 + v.floor() as i64).rem_euclid(2) == 0 {
            0.1
        } else {
            0.9
        }
    }

    /// Scene point at the middle of the inner corners.
    pub fn centre(&self) -> Vector3<f64> {
        let a = self.corner(0, 0);
        let b = self.corner(self.cols - 1, self.rows - 1);
        Vector3::new(0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), self.z_mm)
    }

    /// The exact homography from ToF pixel (x = column, y = row) to camera pixel for points on
    /// the board's plane: ray through the pixel, meet the plane z = z_b, orthographic projection.
    pub fn truth_homography(&self, tof: &TofCamera, camera: &Camera) -> Matrix3<f64> {
        let f = tof.focal_px();
        let pixel_to_ray = tof.axes()
            * Matrix3::new(
                1.0 / f,
                0.0,
                (0.5 - tof.width as f64 / 2.0) / f,
                0.0,
                1.0 / f,
                (0.5 - tof.height as f64 / 2.0) / f,
                0.0,
                0.0,
                1.0,
            );
        let c = Vector3::from(tof.position_mm);
        let dz = self.z_mm - c.z;
        // (X, Y, 1) ∝ ((z_b − C_z)·d_x + C_x·d_z, (z_b − C_z)·d_y + C_y·d_z, d_z).
        let ray_to_plane = Matrix3::new(dz, 0.0, c.x, 0.0, dz, c.y, 0.0, 0.0, 1.0);
        let h = camera.pitch_mm();
        let plane_to_pixel = Matrix3::new(
            1.0 / h,
            0.0,
            camera.width as f64 / 2.0 - 0.5,
            0.0,
            -1.0 / h,
            camera.height as f64 / 2.0 - 0.5,
            0.0,
            0.0,
            1.0,
        );
        let m = plane_to_pixel * ray_to_plane * pixel_to_ray;
        m / m[(2, 2)]
    }

    /// Scene (x, y) of inner corner (i along a row, j down a column).
    pub fn corner(&self, i: usize, j: usize) -> [f64; 2] {
        let (s, c) = self.angle_rad.sin_cos();
        let (u, v) = (i as f64 * self.square_mm, j as f64 * self.square_mm);
        [
            self.origin_mm[0] + c * u - s * v,
            self.origin_mm[1] - (s * u + c * v),
        ]
    }

    /// The image of the board in the orthographic PS camera (4×4 supersampled reflectance plus
    /// Gaussian noise σ), in [0, 1].
    pub fn camera_image(&self, camera: &Camera, noise: f64, seed: u64) -> Array2<f32> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed_for(seed, 3, 0));
        let normal = rand_distr::Normal::new(0.0, noise.max(0.0)).ok();
        let mut image = Array2::from_shape_fn((camera.height, camera.width), |(r, c)| {
            let mut sum = 0.0;
            for a in 0..4 {
                for b in 0..4 {
                    let (x, y) = camera.pixel_centre_xy(
                        r as f64 - 0.5 + (a as f64 + 0.5) / 4.0,
                        c as f64 - 0.5 + (b as f64 + 0.5) / 4.0,
                    );
                    sum += self.albedo(x, y);
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

    /// The SPAD's photon-counting image of the board (thesis §6.2.1: 200 frames of 10 ms), with
    /// `photons` mean counts on a white square at the reference distance and Poisson noise.
    pub fn tof_image(
        &self,
        camera: &TofCamera,
        photons: f64,
        reference_mm: f64,
        seed: u64,
    ) -> Array2<f32> {
        let origin = Vector3::from(camera.position_mm);
        let k = 4;
        Array2::from_shape_fn((camera.height, camera.width), |(r, c)| {
            let mut mean = 0.0;
            for a in 0..k {
                for b in 0..k {
                    let d = camera.ray(
                        r as f64 - 0.5 + (a as f64 + 0.5) / k as f64,
                        c as f64 - 0.5 + (b as f64 + 0.5) / k as f64,
                    );
                    if d.z.abs() < 1e-12 {
                        continue;
                    }
                    let t = (self.z_mm - origin.z) / d.z;
                    if t <= 0.0 {
                        continue;
                    }
                    let x = origin + t * d;
                    let radial = t * d.norm();
                    let cos_i = (d.z.abs() / d.norm()).max(0.0);
                    mean += photons * self.albedo(x.x, x.y) / 0.9
                        * cos_i
                        * (reference_mm / radial).powi(2);
                }
            }
            mean /= (k * k) as f64;
            let mut rng = ChaCha8Rng::seed_from_u64(seed_for(seed, 4, r * camera.width + c));
            if mean > 0.0 {
                Poisson::new(mean).map_or(0.0, |p| p.sample(&mut rng)) as f32
            } else {
                0.0
            }
        })
    }
}
