//! Each LED's received waveform read straight off the window: the rank-1 template.
//!
//! In the notation of docs/maths/demodulation.md#the-received-signal, pixel p of a window of F
//! frames reads
//! `r_j(p) = B(p) + Σ_i A_i(p)·u_i(j) + noise`, u_i LED i's on-fraction in frame j. LED i's
//! subspace (docs/maths/demodulation.md#the-subspace-projection) is spanned by the cyclic shifts of
//! its carrier s_i; sampled at the rate
//! ratio ρ with full exposure they are the l_i = 2^(i+1) chip templates
//! `c_{i,k}(j) = ½·g_i(j·ρ + k)`, k = 0..l_i−1 (a shift by l_i negates the carrier,
//! docs/maths/carriers.md#duty-runs-and-half-period-negation).
//! At ρ = 1 any exposure e ≤ 1 and any shift Δ_i = k_i + α_i make u_i − ½ a combination
//! `a·c_{i,k_i} + b·c_{i,k_i+1}` of two adjacent chip templates with a, b ≥ 0 and a + b = 1:
//! the exposure window [Δ_i, Δ_i + e] spends the fraction a of its length in chip k_i and b in
//! chip k_i + 1 (docs/maths/demodulation.md#the-received-signal's `(1−α)·s[j+k] + α·s[j+k+1]` is e
//! = 1). Away from ρ = 1 this holds
//! approximately while the phase drifts by less than a chip over the window.
//!
//! So let C = [C_0 … C_{N−1}] be every LED's chip templates (F × D, centred, D = Σ l_i) and
//! Y = X·C·(CᵀC)⁻¹ the oblique coordinates of the centred window X (pixels × F) in them. LED
//! i's block of Y is, across pixels, `A_i(p)·w_iᵀ` plus noise — a rank-1 matrix whose leading
//! right singular vector w_i holds the chip weights of LED i's on-fraction sequence, whatever
//! the on-levels, the other LEDs or the background. Its block of the coordinate Gram matrix
//! `M = (CᵀC)⁻¹·Cᵀ·G·C·(CᵀC)⁻¹` (G = XᵀX, taken from the window's signal space, which leaves
//! most of the noise out) has w_i as leading eigenvector. Reading the adjacent pair (k_i, k_i+1)
//! that carries w_i's weight gives the template's centre without any search: for an exposure
//! e, `Δ_i = k_i + 1 − e·ρ·a` with a = w_{k_i} / (w_{k_i} + w_{k_i+1}). The exposure itself
//! only changes the template where ρ ≠ 1 (and the gain's scale, which the parametric
//! refinement of [`super::fit`] pins to the physics of the integration), so the refinement is
//! started from a few exposures with these shifts. The leading eigenvalue's share of the
//! block's trace measures how rank-1 the block is.

use super::spectrum::SignalSpace;
use super::waveform::{ReceivedWaveform, Timing};
use nalgebra::{DMatrix, SymmetricEigen};

/// Ridge added to CᵀC, relative to its mean diagonal (keeps the oblique coordinates stable
/// where a rate mismatch makes two LEDs' chip templates nearly collinear).
const RIDGE: f64 = 1e-9;

/// One LED's rank-1 template.
#[derive(Debug, Clone, PartialEq)]
pub struct LedTemplate {
    /// k_i: the first chip of the pair that carries the template, in `[0, period)`.
    pub chip: usize,
    /// a: the weight of chip k_i (b = 1 − a that of chip k_i + 1), in [0, 1].
    pub first_weight: f64,
    /// Leading eigenvalue's share of the LED's block trace (1 = exactly rank 1).
    pub rank_one_share: f64,
}

impl LedTemplate {
    /// Δ_i for exposure `exposure` at rate ratio `rate` (module docs).
    pub fn shift(&self, rate: f64, exposure: f64) -> f64 {
        let width = exposure * rate;
        self.chip as f64 + 1.0 - (width * self.first_weight).min(1.0)
    }
}

/// The rank-1 templates of `waves` at rate ratio `rate` from the window's signal space
/// (F = `frames`); `None` when the chip templates do not fit in the window.
pub fn rank_one_templates(
    space: &SignalSpace,
    waves: &[ReceivedWaveform],
    rate: f64,
    frames: usize,
) -> Option<Vec<LedTemplate>> {
    let timing = Timing {
        rate_ratio: rate,
        exposure: 1.0,
    };
    let sizes: Vec<usize> = waves.iter().map(|w| w.period() / 2).collect();
    let total: usize = sizes.iter().sum();
    if total == 0 || total + 1 > frames {
        return None;
    }
    let mut chips = DMatrix::zeros(frames, total);
    let mut column = vec![0.0; frames];
    let mut c = 0;
    for (wave, &size) in waves.iter().zip(&sizes) {
        for k in 0..size {
            timing.fill_template(wave, k as f64, &mut column);
            let mean = column.iter().sum::<f64>() / frames as f64;
            for (j, v) in column.iter().enumerate() {
                chips[(j, c)] = v - mean;
            }
            c += 1;
        }
    }
    let mut normal = chips.tr_mul(&chips);
    let ridge = RIDGE * normal.trace() / total as f64;
    for d in 0..total {
        normal[(d, d)] += ridge;
    }
    let cholesky = normal.cholesky()?;
    // Oblique coordinates of the signal directions scaled by √eigenvalue: M = Y·Yᵀ.
    let scaled = DMatrix::from_fn(frames, space.values.len(), |j, k| {
        space.vectors[(j, k)] * space.values[k].max(0.0).sqrt()
    });
    let coordinates = cholesky.solve(&chips.tr_mul(&scaled));
    let mut templates = Vec::with_capacity(waves.len());
    let mut first = 0;
    for &size in &sizes {
        let block = coordinates.rows(first, size);
        first += size;
        let eigen = SymmetricEigen::new(block * block.transpose());
        let (lead, &value) = eigen
            .eigenvalues
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))?;
        let weights: Vec<f64> = eigen.eigenvectors.column(lead).iter().copied().collect();
        let trace: f64 = eigen.eigenvalues.iter().map(|v| v.max(0.0)).sum();
        let (chip, first_weight) = adjacent_pair(&weights);
        templates.push(LedTemplate {
            chip,
            first_weight,
            rank_one_share: if trace > 0.0 {
                value.max(0.0) / trace
            } else {
                0.0
            },
        });
    }
    Some(templates)
}

/// The adjacent pair of chip weights (cyclic over the carrier's period: the weight of chip
/// l + k is minus that of chip k) with the largest same-signed sum: (k, a).
fn adjacent_pair(weights: &[f64]) -> (usize, f64) {
    let size = weights.len();
    // Weight of chip m of the period 2·size (chip size + k is chip k negated).
    let weight = |m: usize| {
        let w = weights[m % size];
        if (m / size) % 2 == 1 { -w } else { w }
    };
    let mut best = (f64::NEG_INFINITY, 0, 1.0);
    for k in 0..2 * size {
        let (a, b) = (weight(k), weight(k + 1));
        let sum = a + b;
        if sum > best.0 {
            let a = a.max(0.0);
            let b = b.max(0.0);
            let share = if a + b > 0.0 { a / (a + b) } else { 1.0 };
            best = (sum, k, share);
        }
    }
    (best.1, best.2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demod::spectrum::SignalSpace;

    /// A window of `pixels` pixels, each a random mix of the LEDs' templates.
    fn gram_of(
        waves: &[ReceivedWaveform],
        timing: Timing,
        shifts: &[f64],
        frames: usize,
    ) -> DMatrix<f64> {
        let pixels = 64;
        let mut x = DMatrix::zeros(pixels, frames);
        let mut t = vec![0.0; frames];
        for (i, (wave, &shift)) in waves.iter().zip(shifts).enumerate() {
            timing.fill_template(wave, shift, &mut t);
            let mean = t.iter().sum::<f64>() / frames as f64;
            for p in 0..pixels {
                let level = 0.2 + ((p * 7 + i * 13) % 17) as f64 / 17.0;
                for j in 0..frames {
                    x[(p, j)] += level * (t[j] - mean);
                }
            }
        }
        x.tr_mul(&x)
    }

    #[test]
    fn reads_shifts_off_the_window_at_the_chip_rate() {
        // At ρ = 1 the rank-1 template is exact for any exposure (module docs). Off the chip
        // rate it is a seed, not an answer: that the refinement converges from it is checked
        // on a whole decode in `demod::tests::rank_one_seeds_converge_off_the_chip_rate`.
        let waves: Vec<ReceivedWaveform> = (0..4).map(ReceivedWaveform::new).collect();
        let shifts = [1.3, 5.75, 2.2, 17.6];
        let frames = 32;
        for exposure in [1.0, 0.5] {
            let timing = Timing {
                rate_ratio: 1.0,
                exposure,
            };
            let gram = gram_of(&waves, timing, &shifts, frames);
            let space = SignalSpace::new(&gram, waves.len());
            let templates = rank_one_templates(&space, &waves, 1.0, frames)
                .unwrap_or_else(|| panic!("no templates"));
            for ((template, wave), &truth) in templates.iter().zip(&waves).zip(&shifts) {
                let got = template.shift(1.0, exposure);
                // The template, not the shift, is what the window determines (a short exposure
                // inside one chip fits anywhere in it); equal up to a carrier's sign
                // (docs/maths/carriers.md#duty-runs-and-half-period-negation).
                let (mut want, mut have) = (vec![0.0; frames], vec![0.0; frames]);
                timing.fill_template(wave, truth, &mut want);
                timing.fill_template(wave, got, &mut have);
                let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
                let cosine =
                    dot(&want, &have).abs() / (dot(&want, &want) * dot(&have, &have)).sqrt();
                assert!(
                    1.0 - cosine < 1e-9,
                    "e {exposure}: shift {got} vs {truth}, cosine {cosine} ({template:?})"
                );
                assert!(template.rank_one_share > 0.9, "{template:?}");
            }
        }
    }

    #[test]
    fn an_empty_window_has_no_templates() {
        let waves: Vec<ReceivedWaveform> = (0..2).map(ReceivedWaveform::new).collect();
        let space = SignalSpace::new(&DMatrix::zeros(0, 0), waves.len());
        assert!(rank_one_templates(&space, &waves, 1.0, 0).is_none());
    }
}
