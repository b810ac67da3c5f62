//! The one colour ramp of every preview: anchors of the perceptually uniform "viridis" map
//! (van der Walt & Smith, matplotlib, 2015), dark blue → teal → yellow, interpolated linearly.

use image::Rgb;

/// Viridis at t = 0, ¼, ½, ¾, 1.
const ANCHORS: [[f32; 3]; 5] = [
    [68.0, 1.0, 84.0],
    [59.0, 82.0, 139.0],
    [33.0, 145.0, 140.0],
    [94.0, 201.0, 98.0],
    [253.0, 231.0, 37.0],
];

/// The ramp's colour at `t` (clamped to [0, 1]; NaN maps to 0).
pub fn ramp(t: f32) -> Rgb<u8> {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (ANCHORS.len() - 1) as f32;
    let k = (x.floor() as usize).min(ANCHORS.len() - 2);
    let f = x - k as f32;
    Rgb([0, 1, 2].map(|c| (ANCHORS[k][c] * (1.0 - f) + ANCHORS[k + 1][c] * f).round() as u8))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_runs_from_dark_blue_to_yellow_through_its_anchors() {
        assert_eq!(ramp(0.0).0, [68, 1, 84]);
        assert_eq!(ramp(0.5).0, [33, 145, 140]);
        assert_eq!(ramp(1.0).0, [253, 231, 37]);
        assert_eq!(ramp(7.0), ramp(1.0));
        assert_eq!(ramp(f32::NAN), ramp(0.0));
        let lum = |t: f32| ramp(t).0.iter().map(|&c| u32::from(c)).sum::<u32>();
        assert!((0..10).all(|i| lum(i as f32 / 10.0) < lum((i + 1) as f32 / 10.0)));
    }
}
