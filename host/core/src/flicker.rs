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
//!
//! **Depth.** With off chips at a fraction of the on level (the luminaire's off level) every
//! component scales by the modulation depth m = (on − off)/(on + off) ([`analyse_at_depth`]).
//! The demodulated LED images scale with the on − off difference, so at the same mean light
//! the noise on the LED images, and on the normals, grows as 1/m. The largest depths a rate
//! and LED count allow come from `protocol::flicker`, the acceptance function the luminaire
//! runs; [`class_by_every_line`] is an independent check of it in `f64` over every line.

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
    /// Modulation depth (on − off)/(on + off) analysed (1 for on/off keying).
    pub depth: f64,
    /// Largest IEEE 1789 low-risk depth of this LED at this rate (`protocol::flicker`).
    pub low_risk_depth: f64,
    /// Largest no-observable-effect depth of this LED at this rate.
    pub no_observable_effect_depth: f64,
    /// Noise on the LED image and the normals relative to full depth at the same mean light:
    /// 1/depth.
    pub noise_factor: f64,
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
    analyse_at_depth(table, rate_hz, report_below_hz, 1.0)
}

/// [`analyse`] with every LED at modulation depth `depth` in (0, 1].
pub fn analyse_at_depth(
    table: &ChipTable,
    rate_hz: f64,
    report_below_hz: f64,
    depth: f64,
) -> Vec<LedFlicker> {
    let rate = protocol::config::ChipRate::from_hz(rate_hz);
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
                let percent = depth * 100.0 * 2.0 * coefficient(&on, k).abs() / mean;
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
            let max = |limit| f64::from(protocol::flicker::max_depth(led as u8, rate, limit).depth);
            LedFlicker {
                led: led + 1,
                percent_flicker: 100.0 * depth,
                depth,
                low_risk_depth: max(&protocol::flicker::LOW_RISK),
                no_observable_effect_depth: max(&protocol::flicker::NO_OBSERVABLE_EFFECT),
                noise_factor: 1.0 / depth,
                fundamental_hz,
                components,
                class,
            }
        })
        .collect()
}

/// IEEE 1789 class of LED `led` (0-based) at chip rate `rate_hz` and depth `depth`, from the
/// closed form Mod%_k = depth · (400/π)·|tan(πk/P)|/k (P = 2^(led+2), odd k;
/// docs/howto/flicker-safety.md) evaluated in `f64` at every line up to 3 kHz: a check of
/// `protocol::flicker`'s shortcut and its `f32` arithmetic.
pub fn class_by_every_line(led: u8, rate_hz: f64, depth: f64) -> RiskClass {
    let period = f64::from(4u32 << led);
    let mut class = RiskClass::NoObservableEffect;
    let mut k = 1u64;
    loop {
        let f = k as f64 * rate_hz / period;
        if f > UNRESTRICTED_HZ {
            return class;
        }
        let percent = depth * 400.0 / PI * (PI * k as f64 / period).tan().abs() / k as f64;
        class = class.max(classify(f, percent));
        if class == RiskClass::ElevatedRisk {
            return class;
        }
        k += 2;
    }
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

    #[test]
    fn depth_scales_every_line_and_the_closed_form_matches_the_dft() {
        let table = ChipTable::new(4).unwrap();
        let full = analyse(&table, 960.0, 200.0);
        let low = analyse_at_depth(&table, 960.0, 200.0, 0.05);
        for (f, l) in full.iter().zip(&low) {
            for (a, b) in f.components.iter().zip(&l.components) {
                assert!((b.modulation_percent - 0.05 * a.modulation_percent).abs() < 1e-9);
                // The closed form |tan(πk/P)|/k against the DFT.
                let period = f64::from(4u32 << (f.led - 1));
                let k = (a.frequency_hz * period / 960.0).round();
                let closed = 400.0 / PI * (PI * k / period).tan().abs() / k;
                assert!(
                    (closed - a.modulation_percent).abs() < 1e-6 * closed,
                    "{a:?}"
                );
            }
            assert!((l.noise_factor - 20.0).abs() < 1e-9);
        }
        assert_eq!(full[3].class, RiskClass::ElevatedRisk);
        assert_eq!(low[3].class, RiskClass::LowRisk);
        assert!((full[3].low_risk_depth - 0.75 / 12.54).abs() < 1e-3);
    }

    /// Every rate 1–4000 Hz (whole hertz) and N = 1..=8 that the luminaire accepts without
    /// `allow_flicker` is low-risk by every line in `f64`: at each LED's largest depth
    /// (`--depth auto`), and at full depth wherever the luminaire accepts that.
    #[test]
    fn every_configuration_accepted_without_allow_flicker_is_low_risk() {
        use protocol::config::{ChipRate, LuminaireConfig};
        use protocol::flicker::{at_largest_low_risk_depths, played_depth};
        let mut accepted_full = 0;
        for leds in 1..=protocol::carriers::MAX_LEDS as u8 {
            for hz in 1..=4000u32 {
                let rate = ChipRate(hz * 1000);
                let auto = at_largest_low_risk_depths(&LuminaireConfig {
                    led_count: leds,
                    chip_rate: rate,
                    ..LuminaireConfig::DEFAULT
                });
                assert_eq!(auto.validate_for_people(), Ok(()), "{leds} LEDs {hz} Hz");
                let full = LuminaireConfig {
                    off_level_permille: [0; 8],
                    ..auto
                };
                let full_ok = full.validate_for_people().is_ok();
                accepted_full += usize::from(full_ok);
                for led in 0..leds {
                    let depth = f64::from(played_depth(&auto, usize::from(led)));
                    let class = class_by_every_line(led, f64::from(hz), depth);
                    assert!(class <= RiskClass::LowRisk, "{leds} LEDs {hz} Hz LED {led}");
                    if full_ok {
                        assert!(class_by_every_line(led, f64::from(hz), 1.0) <= RiskClass::LowRisk);
                    }
                }
            }
        }
        // On/off keying is never low-risk up to 4 kHz: LED 1's fundamental at R/4 ≤ 1 kHz
        // carries 127 %, above the 0.08·f ≤ 80 % allowed there.
        assert_eq!(accepted_full, 0);
    }
}
