//! Shaded renders of a reconstructed surface from a few viewpoints (the thesis used Blender):
//! the depth map's grid triangles are rotated (yaw about y, then pitch about x), projected
//! orthographically, z-buffered and Lambert-shaded with a light over the viewer's shoulder.

use image::{Rgb, RgbImage};
use meb_core::types::DepthMap;
use nalgebra::{Rotation3, Vector3};

/// A named viewpoint: yaw and pitch in degrees.
#[derive(Debug, Clone, Copy)]
pub struct View {
    /// Caption.
    pub name: &'static str,
    /// Rotation about the vertical axis, degrees.
    pub yaw_deg: f64,
    /// Rotation about the horizontal axis, degrees (positive looks from above).
    pub pitch_deg: f64,
}

/// The default viewpoints: front, from the left, from the right, from above.
pub const VIEWS: [View; 4] = [
    View {
        name: "front",
        yaw_deg: 0.0,
        pitch_deg: 0.0,
    },
    View {
        name: "left",
        yaw_deg: -40.0,
        pitch_deg: 10.0,
    },
    View {
        name: "right",
        yaw_deg: 40.0,
        pitch_deg: 10.0,
    },
    View {
        name: "above",
        yaw_deg: 0.0,
        pitch_deg: 55.0,
    },
];

/// Renders `depth` seen from `view` into a `size`×`size` image (grey surface, dark background).
pub fn render_surface(depth: &DepthMap, view: View, size: u32) -> RgbImage {
    let mesh = super::mesh::SurfaceMesh::from_depth(depth);
    let mut img = RgbImage::from_pixel(size, size, Rgb([24, 26, 32]));
    if mesh.triangles.is_empty() {
        return img;
    }
    let rot = Rotation3::from_axis_angle(&Vector3::x_axis(), view.pitch_deg.to_radians())
        * Rotation3::from_axis_angle(&Vector3::y_axis(), view.yaw_deg.to_radians());
    let pts: Vec<Vector3<f64>> = mesh
        .vertices
        .iter()
        .map(|v| rot * Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])))
        .collect();
    let (mut lo, mut hi) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for p in &pts {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let extent = (hi.x - lo.x).max(hi.y - lo.y).max(f64::MIN_POSITIVE);
    let scale = 0.9 * f64::from(size) / extent;
    let centre = (lo + hi) / 2.0;
    let half = f64::from(size) / 2.0;
    // Screen: column right, row down.
    let screen: Vec<(f64, f64, f64)> = pts
        .iter()
        .map(|p| {
            (
                half + (p.x - centre.x) * scale,
                half - (p.y - centre.y) * scale,
                p.z,
            )
        })
        .collect();
    let light = Vector3::new(-0.4, 0.5, 1.0).normalize();
    let mut zbuf = vec![f64::NEG_INFINITY; (size * size) as usize];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i as usize);
        let n = (pts[b] - pts[a]).cross(&(pts[c] - pts[a]));
        let len = n.norm();
        if len <= 0.0 {
            continue;
        }
        let n = n / len;
        let shade = 0.15 + 0.85 * n.dot(&light).abs();
        let colour = Rgb([
            (shade * 215.0) as u8,
            (shade * 205.0) as u8,
            (shade * 190.0) as u8,
        ]);
        let (p0, p1, p2) = (screen[a], screen[b], screen[c]);
        let min_x = p0.0.min(p1.0).min(p2.0).floor().max(0.0) as u32;
        let max_x = (p0.0.max(p1.0).max(p2.0).ceil() as u32).min(size - 1);
        let min_y = p0.1.min(p1.1).min(p2.1).floor().max(0.0) as u32;
        let max_y = (p0.1.max(p1.1).max(p2.1).ceil() as u32).min(size - 1);
        let area = (p1.0 - p0.0) * (p2.1 - p0.1) - (p1.1 - p0.1) * (p2.0 - p0.0);
        if area.abs() < 1e-12 {
            continue;
        }
        for y in min_y..=max_y {
            for x in min_x..=max_x {
                let (px, py) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
                let w0 = ((p1.0 - px) * (p2.1 - py) - (p1.1 - py) * (p2.0 - px)) / area;
                let w1 = ((p2.0 - px) * (p0.1 - py) - (p2.1 - py) * (p0.0 - px)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * p0.2 + w1 * p1.2 + w2 * p2.2;
                let k = (y * size + x) as usize;
                if z > zbuf[k] {
                    zbuf[k] = z;
                    img.put_pixel(x, y, colour);
                }
            }
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    #[test]
    fn a_dome_fills_the_middle_of_the_picture() {
        let depth_mm = Array2::from_shape_fn((40, 40), |(r, c)| {
            let d2 = (r as f32 - 20.0).powi(2) + (c as f32 - 20.0).powi(2);
            if d2 < 300.0 {
                (300.0 - d2).sqrt()
            } else {
                f32::NAN
            }
        });
        let img = render_surface(
            &DepthMap {
                depth_mm,
                pitch_mm: 1.0,
                perspective: None,
            },
            VIEWS[1],
            64,
        );
        let centre = img.get_pixel(32, 32).0;
        let corner = img.get_pixel(1, 1).0;
        assert!(
            centre[0] > 60 && corner == [24, 26, 32],
            "{centre:?} {corner:?}"
        );
    }
}
