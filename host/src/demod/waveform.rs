//! The received waveform of one LED: its carrier integrated over the camera's exposure (SPEC §3).
//!
//! Frame j of a camera running at ρ chips per frame exposes from chip time `j·ρ + Δ_i` (Δ_i the
//! LED's unknown shift, integer and fractional part together) for `e·ρ` chips (e the exposure
//! as a fraction of the frame period). The pixel integrates the on/off carrier over that
//! window, normalised by the window length, so its reading is
//!
//! ```text
//! r_j = B + Σ_i A_i · on_i(j) = B' + Σ_i (A_i / 2) · g_i(j·ρ + Δ_i),
//! g_i(t) = (1 / w) ∫_t^{t+w} s_i(u) du,   w = e·ρ,   s_i(u) = ±1 (SPEC §2)
//! ```
//!
//! With w = 1 and ρ = 1 this is exactly SPEC §3's `(1-α)·s[j+k] + α·s[j+k+1]`. The integral is
//! evaluated in O(1) from the carrier's cumulative sum, which is periodic because every
//! carrier has 50 % duty.

use protocol::carriers::chip_is_on;

/// LED `led`'s carrier s_i as ±1 over one period of `2^(led+2)` chips (SPEC §2).
pub fn carrier_period(led: usize) -> usize {
    1 << (led + 2)
}

/// The box-integrated carrier of one LED, evaluated at any real chip time.
#[derive(Debug, Clone)]
pub struct ReceivedWaveform {
    /// Cumulative sum S[m] = Σ_{k<m} s[k] over one period (S[period] = 0).
    cumulative: Vec<f64>,
    /// The carrier ±1 over one period.
    chips: Vec<f64>,
}

impl ReceivedWaveform {
    /// Builds the waveform model of LED `led` (0-based).
    pub fn new(led: usize) -> Self {
        let period = carrier_period(led);
        let chips: Vec<f64> = (0..period)
            .map(|m| if chip_is_on(led, m) { 1.0 } else { -1.0 })
            .collect();
        let mut cumulative = Vec::with_capacity(period + 1);
        let mut sum = 0.0;
        cumulative.push(0.0);
        for s in &chips {
            sum += s;
            cumulative.push(sum);
        }
        Self { cumulative, chips }
    }

    /// Carrier period in chips.
    pub fn period(&self) -> usize {
        self.chips.len()
    }

    /// The cumulative integral S(t) = ∫_0^t s(u) du (periodic).
    fn integral(&self, t: f64) -> f64 {
        let period = self.chips.len() as f64;
        let u = t.rem_euclid(period);
        let m = (u.floor() as usize).min(self.chips.len() - 1);
        self.cumulative[m] + (u - m as f64) * self.chips[m]
    }

    /// g(t): the carrier averaged over the window `[t, t + width]` (width > 0, in chips).
    pub fn average(&self, t: f64, width: f64) -> f64 {
        if width <= 1e-9 {
            let period = self.chips.len() as f64;
            let m = (t.rem_euclid(period).floor() as usize).min(self.chips.len() - 1);
            return self.chips[m];
        }
        (self.integral(t + width) - self.integral(t)) / width
    }
}

/// Timing shared by every LED of a capture: camera rate and exposure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// ρ: chips per camera frame (chip rate / frame rate); 1 when the rates match.
    pub rate_ratio: f64,
    /// e: exposure as a fraction of the frame period, in (0, 1].
    pub exposure: f64,
}

impl Timing {
    /// Template value of an LED with shift `shift` (chips) at frame `frame`: g(j·ρ + Δ) / 2, so
    /// that its least-squares coefficient is the on-level A_i.
    pub fn template(&self, wave: &ReceivedWaveform, shift: f64, frame: usize) -> f64 {
        0.5 * wave.average(
            frame as f64 * self.rate_ratio + shift,
            self.exposure * self.rate_ratio,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_exposure_matches_spec_fractional_shift_formula() {
        let wave = ReceivedWaveform::new(1);
        let s: Vec<f64> = (0..8)
            .map(|m| if chip_is_on(1, m) { 1.0 } else { -1.0 })
            .collect();
        let (k, alpha) = (3usize, 0.3);
        for j in 0..16 {
            let expected = (1.0 - alpha) * s[(j + k) % 8] + alpha * s[(j + k + 1) % 8];
            let got = wave.average(j as f64 + k as f64 + alpha, 1.0);
            assert!((got - expected).abs() < 1e-12, "j={j}: {got} vs {expected}");
        }
    }

    #[test]
    fn short_exposure_sees_the_bare_chip() {
        let wave = ReceivedWaveform::new(0);
        // A window of a quarter chip inside chip 1 (s_0[1] = -1).
        assert!((wave.average(1.25, 0.25) + 1.0).abs() < 1e-12);
        assert_eq!(wave.period(), 4);
    }
}
