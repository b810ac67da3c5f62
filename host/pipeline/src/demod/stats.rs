//! Report statistics over the decodable pixels (neither saturated nor under-exposed): counts,
//! mean noise power and each LED's mean on-level. The matched filter gathers them row by row
//! as it writes a single-window decode (saving a pass over ~20 MB of 720p images); otherwise
//! they are gathered from the averaged images.

use rayon::prelude::*;

/// Sums over the decodable pixels for the report.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PixelStats {
    /// Pixels that reached the white level.
    pub saturated_pixels: usize,
    /// Pixels whose brightest frame stayed below the under-exposure level.
    pub underexposed_pixels: usize,
    /// Pixels that are neither.
    pub valid_pixels: usize,
    /// Σ σ² over valid pixels (per-frame noise variance, fraction² of full scale).
    pub noise_power: f64,
    /// Σ A_i over valid pixels, per LED.
    pub level_sums: Vec<f64>,
}

impl PixelStats {
    /// Empty sums for `leds` LEDs.
    pub fn new(leds: usize) -> Self {
        Self {
            level_sums: vec![0.0; leds],
            ..Self::default()
        }
    }

    /// Adds one pixel: its masks, noise variance and on-levels (`level(i)` for LED i).
    #[inline(always)]
    pub fn add(
        &mut self,
        saturated: bool,
        underexposed: bool,
        variance: f32,
        level: impl Fn(usize) -> f32,
    ) {
        self.saturated_pixels += usize::from(saturated);
        self.underexposed_pixels += usize::from(underexposed);
        if saturated || underexposed {
            return;
        }
        self.valid_pixels += 1;
        self.noise_power += f64::from(variance);
        for (i, sum) in self.level_sums.iter_mut().enumerate() {
            *sum += f64::from(level(i));
        }
    }

    /// Adds another part of the image.
    pub fn merge(mut self, other: &Self) -> Self {
        self.saturated_pixels += other.saturated_pixels;
        self.underexposed_pixels += other.underexposed_pixels;
        self.valid_pixels += other.valid_pixels;
        self.noise_power += other.noise_power;
        if self.level_sums.len() < other.level_sums.len() {
            self.level_sums.resize(other.level_sums.len(), 0.0);
        }
        self.level_sums
            .iter_mut()
            .zip(&other.level_sums)
            .for_each(|(x, y)| *x += y);
        self
    }

    /// One parallel pass over whole images (`variance`: per-frame noise variance).
    pub fn gather(
        leds: &[Vec<f32>],
        variance: &[f32],
        saturated: &[bool],
        underexposed: &[bool],
    ) -> Self {
        const CHUNK: usize = 1 << 14;
        let pixels = variance
            .len()
            .min(saturated.len())
            .min(underexposed.len())
            .min(leds.iter().map(Vec::len).min().unwrap_or(usize::MAX));
        (0..pixels)
            .into_par_iter()
            .step_by(CHUNK)
            .map(|start| {
                let mut stats = Self::new(leds.len());
                for p in start..(start + CHUNK).min(pixels) {
                    stats.add(saturated[p], underexposed[p], variance[p], |i| leds[i][p]);
                }
                stats
            })
            // Merged in order: the sums do not depend on how the pool split the work.
            .collect::<Vec<_>>()
            .into_iter()
            .fold(Self::new(leds.len()), |a, b| a.merge(&b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gathers_only_valid_pixels() {
        let leds = vec![vec![1.0, 2.0, 3.0, 4.0], vec![0.5; 4]];
        let variance = [0.01, 0.02, 0.03, 0.04];
        let saturated = [false, true, false, false];
        let underexposed = [false, false, true, false];
        let stats = PixelStats::gather(&leds, &variance, &saturated, &underexposed);
        assert_eq!(stats.saturated_pixels, 1);
        assert_eq!(stats.underexposed_pixels, 1);
        assert_eq!(stats.valid_pixels, 2);
        assert!((stats.noise_power - 0.05).abs() < 1e-7);
        assert!((stats.level_sums[0] - 5.0).abs() < 1e-12);
        assert!((stats.level_sums[1] - 1.0).abs() < 1e-12);
        let halves =
            PixelStats::gather(&[vec![1.0, 2.0]], &[0.01, 0.02], &[false; 2], &[false; 2]).merge(
                &PixelStats::gather(&[vec![3.0]], &[0.03], &[false], &[false]),
            );
        assert_eq!(halves.valid_pixels, 3);
        assert!((halves.level_sums[0] - 6.0).abs() < 1e-12);
    }
}
