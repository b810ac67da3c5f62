//! LED light waveforms: how much of an exposure window each LED is on.
//!
//! The simulator integrates each LED's on/off waveform over every row's exposure window
//! (docs/maths/demodulation.md#the-received-signal). [`LedWaveform`] is the pluggable source of
//! that waveform; [`CarrierWaveform`]
//! plays the MEB-FDMA chip table (docs/maths/carriers.md#the-carrier-table, `protocol::carriers`)
//! at a per-LED chip rate with a
//! per-LED time shift Δ_i in chips: at camera time t (seconds) LED i shows chip
//! `floor(t · rate_i + Δ_i) mod n`. With rate = fps and an exposure of one full frame, frame j
//! then integrates `(1 − α_i)·s_i[j + k_i] + α_i·s_i[j + k_i + 1]` (Δ_i = k_i + α_i), exactly the
//! received-signal formula of docs/maths/demodulation.md#the-received-signal.
//!
//! An LED whose off chips keep a fraction ℓ_i of its on light ([`CarrierWaveform::with_off_levels`],
//! the luminaire's off level, docs/howto/flicker-safety.md) shows ℓ_i + (1 − ℓ_i)·w: the
//! carrier's part of the light, and with it the demodulated LED image, scales with 1 − ℓ_i.

pub use meb_core::led_waveform::LedWaveform;
use protocol::carriers::ChipTable;

/// The MEB-FDMA carriers, each LED at its own chip rate and time shift.
#[derive(Debug, Clone)]
pub struct CarrierWaveform {
    table: ChipTable,
    rates_hz: Vec<f64>,
    phases_chips: Vec<f64>,
    off_levels: Vec<f64>,
}

impl CarrierWaveform {
    /// Carriers of `table`, LED i at `rates_hz[i]` chips per second shifted by
    /// `phases_chips[i]` chips. Both slices need one finite entry per LED, rates positive;
    /// returns `None` otherwise.
    pub fn new(table: ChipTable, rates_hz: &[f64], phases_chips: &[f64]) -> Option<Self> {
        let n = usize::from(table.led_count());
        let ok = rates_hz.len() == n
            && phases_chips.len() == n
            && rates_hz.iter().all(|r| r.is_finite() && *r > 0.0)
            && phases_chips.iter().all(|p| p.is_finite());
        ok.then(|| Self {
            table,
            rates_hz: rates_hz.to_vec(),
            phases_chips: phases_chips.to_vec(),
            off_levels: vec![0.0; n],
        })
    }

    /// The same carriers with LED i's off chips at `off_levels[i]` ∈ [0, 1] of its on light
    /// (0: dark, as [`Self::new`]); `None` unless there is one such entry per LED.
    pub fn with_off_levels(mut self, off_levels: &[f64]) -> Option<Self> {
        let ok = off_levels.len() == self.off_levels.len()
            && off_levels.iter().all(|l| (0.0..=1.0).contains(l));
        ok.then(|| {
            self.off_levels = off_levels.to_vec();
            self
        })
    }

    /// Light of LED i during its off chips, as a fraction of its on light.
    pub fn off_levels(&self) -> &[f64] {
        &self.off_levels
    }

    /// The chip table being played.
    pub fn table(&self) -> &ChipTable {
        &self.table
    }

    /// Chip rate of each LED in Hz.
    pub fn rates_hz(&self) -> &[f64] {
        &self.rates_hz
    }

    /// Time shift Δ_i of each LED in chips.
    pub fn phases_chips(&self) -> &[f64] {
        &self.phases_chips
    }

    fn is_on(&self, led: usize, chip: i64) -> bool {
        let masks = self.table.masks();
        let m = chip.rem_euclid(masks.len() as i64) as usize;
        masks[m] & (1 << led) != 0
    }
}

impl LedWaveform for CarrierWaveform {
    fn led_count(&self) -> usize {
        usize::from(self.table.led_count())
    }

    fn on_fraction(&self, led: usize, t0: f64, t1: f64) -> f64 {
        if led >= self.led_count() {
            return 0.0;
        }
        let off = self.off_levels[led];
        off + (1.0 - off) * self.keyed_fraction(led, t0, t1)
    }
}

impl CarrierWaveform {
    /// Fraction of [t0, t1) that LED `led` spends in on chips (its state at t0 for an empty window).
    fn keyed_fraction(&self, led: usize, t0: f64, t1: f64) -> f64 {
        let rate = self.rates_hz[led];
        let phase = self.phases_chips[led];
        // Window in chip units of this LED.
        let c0 = t0 * rate + phase;
        let c1 = t1 * rate + phase;
        if c1 <= c0 {
            return if self.is_on(led, c0.floor() as i64) {
                1.0
            } else {
                0.0
            };
        }
        let n = self.table.chips() as f64;
        // Whole table periods contribute n/2 on-chips each (50 % duty,
        // docs/maths/carriers.md#duty-runs-and-half-period-negation).
        let periods = ((c1 - c0) / n).floor();
        let mut on = periods * n / 2.0;
        let start = c0 + periods * n;
        let mut chip = start.floor();
        let mut t = start;
        while t < c1 {
            let end = (chip + 1.0).min(c1);
            if self.is_on(led, chip as i64) {
                on += end - t;
            }
            t = end;
            chip += 1.0;
        }
        (on / (c1 - c0)).clamp(0.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(table: &ChipTable, led: usize, j: i64) -> f64 {
        let n = table.chips() as i64;
        if table.masks()[j.rem_euclid(n) as usize] & (1 << led) != 0 {
            1.0
        } else {
            -1.0
        }
    }

    /// docs/maths/demodulation.md#the-received-signal: a full-frame window at rate = 1 chip per
    /// frame integrates
    /// (1 − α)·s[j + k] + α·s[j + k + 1] (as a ±1 value, i.e. 2·fraction − 1).
    #[test]
    fn full_frame_window_matches_spec_formula() {
        let table = ChipTable::new(4).unwrap();
        let phases = [0.3, 1.7, 5.0, 30.9];
        let w = CarrierWaveform::new(table.clone(), &[960.0; 4], &phases).unwrap();
        for (led, phase) in phases.iter().enumerate() {
            let k = phase.floor() as i64;
            let alpha = phase - k as f64;
            for j in 0..70i64 {
                let t0 = j as f64 / 960.0;
                let got = 2.0 * w.on_fraction(led, t0, t0 + 1.0 / 960.0) - 1.0;
                let want =
                    (1.0 - alpha) * s(&table, led, j + k) + alpha * s(&table, led, j + k + 1);
                assert!(
                    (got - want).abs() < 1e-9,
                    "led {led} j {j}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn long_windows_average_to_half_duty() {
        let w = CarrierWaveform::new(ChipTable::new(3).unwrap(), &[1000.0; 3], &[0.0; 3]).unwrap();
        for led in 0..3 {
            let f = w.on_fraction(led, 0.0123, 0.0123 + 0.016);
            assert!((f - 0.5).abs() < 1e-9, "{f}");
        }
        assert!(CarrierWaveform::new(ChipTable::new(2).unwrap(), &[0.0, 1.0], &[0.0; 2]).is_none());
    }
}
