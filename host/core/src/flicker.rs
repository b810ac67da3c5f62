//! Spectrum and IEEE 1789-2015 flicker-risk class of each LED's MEB-FDMA carrier.
//!
//! An LED plays its ±1 carrier as rectangular on/off chips of length T_c = 1/R at chip rate R,
//! repeating every n chips. Its light output w(t) ∈ {0, 1} is periodic with period n/R, so its
//! spectrum is a line spectrum at f_k = k·R/n. With W_k = Σ_j w_j e^{−2πi·jk/n} the DFT of the
//! chip values, the Fourier-series coefficient of the rectangular-chip waveform is
//!
//! ```text
//! c_k = W_k / n · sinc(k/n) · e^{−iπk/n},     sinc(x) = sin(πx)/(πx)
//! ```
//!
//! and component k modulates the light by Mod%_k = 100 · 2|c_k| / c_0 (c_0 = 0.5, the 50 % duty).
//! IEEE 1789-2015 §8 recommends, per frequency f (Hz):
//!
//! ```text
//! low risk:               Mod% ≤ 0.025·f  (f < 90 Hz),  Mod% ≤ 0.08·f  (90 ≤ f ≤ 1250 Hz), any above
//! no observable effect:   Mod% ≤ 0.01·f   (f < 90 Hz),  Mod% ≤ 0.0333·f (90 ≤ f ≤ 3000 Hz), any above
//! ```
//!
//! Each Fourier component is checked against these limits and the LED takes the worst class.
//! Brightness PWM (tens of kHz, far above the limits) does not change the result.

use protocol::carriers::ChipTable;
use serde::Serialize;
use std::f64::consts::PI;

/// Components above this frequency are inside IEEE 1789's unrestricted region for both classes.
const UNRESTRICTED_HZ: f64 = 3000.0;
/// Components weaker than this (percent) are rounding noise, not light.
const NEGLIGIBLE_PERCENT: f64 = 1e-9;

/// IEEE 1789-2015 flicker-risk class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RiskClass {
    /// Inside the "no observable effect level" everywhere.
    NoObservableEffect,
    /// Inside the low-risk region, above NOEL somewhere.
    LowRisk,
    /// Outside the low-risk region at some frequency.
    ElevatedRisk,
}

impl std::fmt::Display for RiskClass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::NoObservableEffect => "no observable effect",
            Self::LowRisk => "low risk",
            Self::ElevatedRisk => "elevated risk",
        })
    }
}

/// IEEE 1789 low-risk limit on percent modulation at `f` Hz (`None` = unrestricted).
pub fn low_risk_limit(f: f64) -> Option<f64> {
    if f < 90.0 {
        Some(0.025 * f)
    } else if f <= 1250.0 {
        Some(0.08 * f)
    } else {
        None
    }
}

/// IEEE 1789 no-observable-effect limit on percent modulation at `f` Hz (`None` = unrestricted).
pub fn noel_limit(f: f64) -> Option<f64> {
    if f < 90.0 {
        Some(0.01 * f)
    } else if f <= UNRESTRICTED_HZ {
        Some(0.0333 * f)
    } else {
        None
    }
}

/// Class of one component of `percent` modulation at `f` Hz.
pub fn classify(f: f64, percent: f64) -> RiskClass {
    let within = |limit: Option<f64>| limit.is_none_or(|l| percent <= l);
    if within(noel_limit(f)) {
        RiskClass::NoObservableEffect
    } else if within(low_risk_limit(f)) {
        RiskClass::LowRisk
    } else {
        RiskClass::ElevatedRisk
    }
}

/// One line of an LED's light spectrum.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Component {
    /// Frequency in Hz.
    pub frequency_hz: f64,
    /// Percent modulation of the mean light by this component.
    pub modulation_percent: f64,
    /// Its IEEE 1789 class.
    pub class: RiskClass,
}

/// Flicker assessment of one LED.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LedFlicker {
    /// LED number, 1-based.
    pub led: usize,
    /// Percent flicker 100·(max−min)/(max+min) of the whole waveform (100 for on/off keying).
    pub percent_flicker: f64,
    /// Lowest frequency present in the light, Hz.
    pub fundamental_hz: f64,
    /// Components up to the reporting limit.
    pub components: Vec<Component>,
    /// Worst class over every component up to 3 kHz.
    pub class: RiskClass,
}

/// Spectrum of each LED of `table` played at `rate_hz` chips per second; components at or below
/// `report_below_hz` are listed, every component up to 3 kHz is classified.
pub fn analyse(table: &ChipTable, rate_hz: f64, report_below_hz: f64) -> Vec<LedFlicker> {
    let n = table.chips();
    (0..usize::from(table.led_count()))
        .map(|led| {
            let on: Vec<f64> = table
                .masks()
                .iter()
                .map(|m| f64::from((m >> led) & 1))
                .collect();
            let mean = on.iter().sum::<f64>() / n as f64;
            let mut components = Vec::new();
            let mut class = RiskClass::NoObservableEffect;
            let mut fundamental_hz = f64::NAN;
            for k in 1..=n * 64 {
                let f = k as f64 * rate_hz / n as f64;
                if f > UNRESTRICTED_HZ && f > report_below_hz {
                    break;
                }
                let percent = 100.0 * 2.0 * coefficient(&on, k).abs() / mean;
                if percent < NEGLIGIBLE_PERCENT {
                    continue;
                }
                if fundamental_hz.is_nan() {
                    fundamental_hz = f;
                }
                let c = classify(f, percent);
                class = class.max(c);
                if f <= report_below_hz {
                    components.push(Component {
                        frequency_hz: f,
                        modulation_percent: percent,
                        class: c,
                    });
                }
            }
            LedFlicker {
                led: led + 1,
                percent_flicker: 100.0,
                fundamental_hz,
                components,
                class,
            }
        })
        .collect()
}

/// |c_k| of the rectangular-chip waveform (module docs).
fn coefficient(on: &[f64], k: usize) -> Complex {
    let n = on.len() as f64;
    let (mut re, mut im) = (0.0, 0.0);
    for (j, w) in on.iter().enumerate() {
        let angle = -2.0 * PI * (j * k) as f64 / n;
        re += w * angle.cos();
        im += w * angle.sin();
    }
    let x = k as f64 / n;
    let sinc = if x == 0.0 {
        1.0
    } else {
        (PI * x).sin() / (PI * x)
    };
    Complex(re / n * sinc, im / n * sinc)
}

/// A complex number, just enough for a magnitude.
struct Complex(f64, f64);

impl Complex {
    fn abs(&self) -> f64 {
        self.0.hypot(self.1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_wave_fundamental_has_textbook_amplitude() {
        // N = 1: LED 1 plays [on, off, off, on], a 50 % square wave of period 4 chips. The
        // fundamental of a 0/1 square wave has amplitude 2/π: 100·(2/π)/0.5 = 127.3 %.
        let table = ChipTable::new(1).unwrap();
        let report = analyse(&table, 400.0, 200.0);
        let first = &report[0].components[0];
        assert!((first.frequency_hz - 100.0).abs() < 1e-9);
        assert!((first.modulation_percent - 400.0 / PI).abs() < 1e-6);
    }

    #[test]
    fn limits_follow_the_standard() {
        assert_eq!(classify(100.0, 3.0), RiskClass::NoObservableEffect);
        assert_eq!(classify(100.0, 5.0), RiskClass::LowRisk);
        assert_eq!(classify(100.0, 9.0), RiskClass::ElevatedRisk);
        assert_eq!(classify(60.0, 1.0), RiskClass::LowRisk);
        assert_eq!(classify(5000.0, 100.0), RiskClass::NoObservableEffect);
        assert_eq!(classify(2000.0, 100.0), RiskClass::LowRisk);
    }

    #[test]
    fn four_leds_at_960_hz_list_their_low_components() {
        let table = ChipTable::new(4).unwrap();
        let report = analyse(&table, 960.0, 200.0);
        assert_eq!(report.len(), 4);
        // LED 4's subspace holds every odd bin q: lines at 30, 90, 150 Hz
        // (docs/maths/carriers.md#spectrum-of-a-carrier).
        let freqs: Vec<f64> = report[3]
            .components
            .iter()
            .map(|c| c.frequency_hz)
            .collect();
        assert_eq!(freqs, vec![30.0, 90.0, 150.0]);
        // LED 1 only has bins q ≡ 8 (mod 16): first line at 240 Hz, nothing below 200 Hz.
        assert!(report[0].components.is_empty());
        assert!((report[0].fundamental_hz - 240.0).abs() < 1e-9);
    }
}
