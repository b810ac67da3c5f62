//! The received waveform of one LED: its carrier integrated over the camera's exposure
//! (docs/maths/demodulation.md#the-received-signal).
//!
//! Frame j of a camera running at ρ chips per frame exposes from chip time `j·ρ + Δ_i` (Δ_i the
//! LED's unknown shift, integer and fractional part together) for `e·ρ` chips (e the exposure
//! as a fraction of the frame period). The pixel integrates the on/off carrier over that
//! window, normalised by the window length, so its reading is
//!
//! ```text
//! r_j = B + Σ_i A_i · on_i(j) = B' + Σ_i (A_i / 2) · g_i(j·ρ + Δ_i),
//! g_i(t) = (1 / w) ∫_t^{t+w} s_i(u) du,   w = e·ρ,   s_i(u) = ±1
//! (docs/maths/carriers.md#the-carrier-table)
//! ```
//!
//! With w = 1 and ρ = 1 this is exactly docs/maths/demodulation.md#the-received-signal's
//! `(1-α)·s[j+k] + α·s[j+k+1]`. The integral is
//! evaluated in O(1) from the carrier's cumulative sum S, which is periodic because every
//! carrier has 50 % duty: S(t) = S\[m\] + (t − m)·s\[m\] with m = ⌊t⌋.
//!
//! Whole templates ([`Timing::fill_template`], the seed scans' and the timing fit's innermost
//! loop) use the carriers' Manchester structure instead of the tables, so that the loop
//! vectorises without gathers: s_i\[m\] = +1 exactly when bit 0 of m equals bit i + 1
//! (docs/maths/carriers.md#the-carrier-table),
//! so every chip pair (2q, 2q+1) sums to zero and, with σ = 1 − 2·(bit i + 1 of m),
//!
//! ```text
//! m even: S[m] = 0, s[m] = σ;      m odd: S[m] = σ, s[m] = −σ,
//! ```
//!
//! where the bits come from exact floors of t·2^−b. The same `S[m] + (t − m)·s[m]` is then
//! formed with the same operands, so the values are those of the tables bit for bit (a test
//! checks both against each other, and the tables against the carrier definition). On x86-64
//! the loop is built for AVX (vector floors) and chosen at run time; elsewhere the tables serve.

use protocol::carriers::chip_is_on;

/// LED `led`'s carrier s_i as ±1 over one period of `2^(led+2)` chips
/// (docs/maths/carriers.md#the-carrier-table).
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
    /// 2^−(led+1): chip index times this, floored, has bit i + 1 of the index as its parity.
    pair_scale: f64,
    /// The window's nuisance components, projected out of every filled template
    /// ([`super::nuisance`]).
    nuisance: Option<std::sync::Arc<super::nuisance::Nuisance>>,
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
        Self {
            cumulative,
            chips,
            pair_scale: 0.5f64.powi(led as i32 + 1),
            nuisance: None,
        }
    }

    /// The waveforms of LEDs `0..leds` with the window's nuisance components (none for `None`).
    pub fn set(
        leds: usize,
        nuisance: Option<&std::sync::Arc<super::nuisance::Nuisance>>,
    ) -> Vec<Self> {
        (0..leds)
            .map(|led| Self {
                nuisance: nuisance.filter(|n| !n.is_empty()).cloned(),
                ..Self::new(led)
            })
            .collect()
    }

    /// v ← (I − PPᵀ)·v with the window's nuisance columns P (nothing without them).
    pub fn project(&self, v: &mut [f64]) {
        if let Some(nuisance) = &self.nuisance {
            nuisance.project(v);
        }
    }

    /// Carrier period in chips.
    pub fn period(&self) -> usize {
        self.chips.len()
    }

    /// The carrier s_i (±1) at chip `m` of its period.
    pub fn chip(&self, m: usize) -> f64 {
        self.chips
            .get(m % self.chips.len().max(1))
            .copied()
            .unwrap_or(0.0)
    }

    /// Chip index (within one period) and fraction of the chip at chip time `t`: the floor
    /// is taken with an integer cast because this sits in the waveform fit's innermost loop
    /// (`f64::rem_euclid` and `floor` are library calls on the baseline x86-64 target).
    #[inline]
    fn locate(&self, t: f64) -> (usize, f64) {
        let truncated = t as i64;
        let floor = if (truncated as f64) > t {
            truncated - 1
        } else {
            truncated
        };
        // The period is a power of two, so masking is the Euclidean remainder.
        let chip = (floor & (self.chips.len() as i64 - 1)) as usize;
        (chip, t - floor as f64)
    }

    /// The cumulative integral S(t) = ∫_0^t s(u) du (periodic: S(period) = 0), in chips.
    #[inline]
    pub fn integral(&self, t: f64) -> f64 {
        let (m, fraction) = self.locate(t);
        match (self.cumulative.get(m), self.chips.get(m)) {
            (Some(c), Some(s)) => c + fraction * s,
            _ => 0.0,
        }
    }

    /// g(t): the carrier averaged over the window `[t, t + width]` (width > 0, in chips).
    #[inline]
    pub fn average(&self, t: f64, width: f64) -> f64 {
        if width <= 1e-9 {
            return self.chips.get(self.locate(t).0).copied().unwrap_or(0.0);
        }
        (self.integral(t + width) - self.integral(t)) / width
    }

    /// [`ReceivedWaveform::integral`] from the Manchester structure (module docs) instead of
    /// the tables: the same value bit for bit, with floors in place of table look-ups.
    #[inline(always)]
    fn manchester_integral(&self, t: f64) -> f64 {
        let floor = t.floor();
        let fraction = t - floor;
        let odd = floor - 2.0 * (floor * 0.5).floor();
        let block = (floor * self.pair_scale).floor();
        let bit = block - 2.0 * (block * 0.5).floor();
        let sigma = 1.0 - 2.0 * bit;
        let (cumulative, chip) = if odd == 0.0 {
            (0.0, sigma)
        } else {
            (sigma, -sigma)
        };
        cumulative + fraction * chip
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
    #[inline]
    pub fn template(&self, wave: &ReceivedWaveform, shift: f64, frame: usize) -> f64 {
        0.5 * wave.average(
            frame as f64 * self.rate_ratio + shift,
            self.exposure * self.rate_ratio,
        )
    }
}

impl Timing {
    /// Writes the template of frames `0..out.len()` (see [`Timing::template`]) into `out`,
    /// with the window's nuisance components projected out ([`super::nuisance`]).
    pub fn fill_template(&self, wave: &ReceivedWaveform, shift: f64, out: &mut [f64]) {
        self.fill_carrier(wave, shift, out);
        if let Some(nuisance) = &wave.nuisance {
            nuisance.project_template(out);
        }
    }

    /// [`Timing::fill_template`] without the nuisance projection. At full exposure frame j's
    /// window ends where frame j + 1's starts, so each cumulative integral serves two frames.
    fn fill_carrier(&self, wave: &ReceivedWaveform, shift: f64, out: &mut [f64]) {
        let rate = self.rate_ratio;
        let width = self.exposure * rate;
        if width <= 1e-9 {
            for (j, v) in out.iter_mut().enumerate() {
                *v = self.template(wave, shift, j);
            }
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if out.len() < i32::MAX as usize && std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX (checked just above).
            unsafe { self.fill_template_avx(wave, shift, out) };
            return;
        }
        self.fill_template_tables(wave, shift, out);
    }

    /// [`Timing::fill_template`] from the Manchester closed form, built for AVX (4-lane vector
    /// floors); frame indices go through `i32` so that their conversion vectorises too.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn fill_template_avx(&self, wave: &ReceivedWaveform, shift: f64, out: &mut [f64]) {
        self.fill_template_closed_form(wave, shift, out);
    }

    /// The positive-width templates from [`ReceivedWaveform::manchester_integral`], each frame
    /// on its own (no carried state, so the loop vectorises): the same operations on the same
    /// operands as [`Timing::fill_template_tables`].
    #[inline(always)]
    fn fill_template_closed_form(&self, wave: &ReceivedWaveform, shift: f64, out: &mut [f64]) {
        let rate = self.rate_ratio;
        let width = self.exposure * rate;
        let scale = 0.5 / width;
        if self.exposure == 1.0 {
            // Frame 0 starts at `shift` itself, as in the table loop: 0·ρ + Δ is Δ for ρ > 0
            // except for the sign of a zero, and S(±0) is the same +0.
            for (j, v) in out.iter_mut().enumerate() {
                let start = f64::from(j as i32) * rate + shift;
                let end = f64::from(j as i32 + 1) * rate + shift;
                *v = (wave.manchester_integral(end) - wave.manchester_integral(start)) * scale;
            }
        } else {
            for (j, v) in out.iter_mut().enumerate() {
                let t = f64::from(j as i32) * rate + shift;
                *v = (wave.manchester_integral(t + width) - wave.manchester_integral(t)) * scale;
            }
        }
    }

    /// The positive-width templates from the carrier tables (any target).
    fn fill_template_tables(&self, wave: &ReceivedWaveform, shift: f64, out: &mut [f64]) {
        let rate = self.rate_ratio;
        let width = self.exposure * rate;
        if self.exposure == 1.0 {
            let scale = 0.5 / width;
            let mut start = wave.integral(shift);
            for (j, v) in out.iter_mut().enumerate() {
                let end = wave.integral((j + 1) as f64 * rate + shift);
                *v = (end - start) * scale;
                start = end;
            }
        } else {
            let scale = 0.5 / width;
            for (j, v) in out.iter_mut().enumerate() {
                let t = j as f64 * rate + shift;
                *v = (wave.integral(t + width) - wave.integral(t)) * scale;
            }
        }
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
    fn filled_templates_match_pointwise_ones() {
        for exposure in [1.0, 0.6, 0.0] {
            let timing = Timing {
                rate_ratio: 1.037,
                exposure,
            };
            let wave = ReceivedWaveform::new(2);
            let mut filled = vec![0.0; 40];
            timing.fill_template(&wave, 3.3, &mut filled);
            for (j, v) in filled.iter().enumerate() {
                let expected = timing.template(&wave, 3.3, j);
                assert!(
                    (v - expected).abs() < 1e-9,
                    "e={exposure} j={j}: {v} vs {expected}"
                );
            }
        }
    }

    #[test]
    fn closed_form_integral_is_the_tables_bit_for_bit() {
        for led in 0..8 {
            let wave = ReceivedWaveform::new(led);
            let period = wave.period() as f64;
            for k in -4000..4000 {
                // Chip boundaries, their neighbours and odd fractions, both signs, several periods.
                for t in [
                    k as f64 * 0.25,
                    k as f64 * 0.37 + 1e-9,
                    k as f64 * period / 97.0,
                ] {
                    let (want, got) = (wave.integral(t), wave.manchester_integral(t));
                    assert_eq!(
                        want.to_bits(),
                        got.to_bits(),
                        "led {led}, t {t}: {want} vs {got}"
                    );
                }
            }
        }
    }

    #[test]
    fn filled_templates_are_the_table_loop_bit_for_bit() {
        let mut fast = vec![0.0; 131];
        let mut tables = vec![0.0; 131];
        for led in 0..6 {
            let wave = ReceivedWaveform::new(led);
            for rate in [1.0, 0.97, 1.0 + 1.0 / 256.0, 1.0213, 0.6] {
                for exposure in [1.0, 0.95, 0.5, 0.1] {
                    let timing = Timing {
                        rate_ratio: rate,
                        exposure,
                    };
                    for shift in [0.0, -0.0, 0.3, 2.75, -1.4, 17.125, 63.99, 200.5] {
                        timing.fill_template(&wave, shift, &mut fast);
                        timing.fill_template_tables(&wave, shift, &mut tables);
                        for (j, (a, b)) in fast.iter().zip(&tables).enumerate() {
                            assert_eq!(
                                a.to_bits(),
                                b.to_bits(),
                                "led {led} rate {rate} e {exposure} shift {shift} frame {j}"
                            );
                        }
                    }
                }
            }
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
