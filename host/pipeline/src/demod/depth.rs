//! The luminaire's modulation depths, and the LED images brought to full-depth equivalents
//! (docs/howto/flicker-safety.md#decoding-a-low-depth-capture).
//!
//! LED i's off chips keep a fraction ℓ_i of its on light (the luminaire's off level), so the
//! pixel sees ℓ_i·Φ_i + (1 − ℓ_i)·Φ_i·w_i(t) and the decoded on-level is A_i = (1 − ℓ_i)·Φ_i·s_i(p)
//! (s_i the shading). Photometric stereo compares the LEDs' images against the rig's relative
//! intensities Φ_i, so each decoded image is divided by 1 − ℓ_i: the result is the image the
//! same LED would give at full depth (off chips dark). The modulation depth
//! m_i = (1 − ℓ_i)/(1 + ℓ_i) is how the luminaire and `meb device set --depth` name it.
//!
//! The decoder cannot measure ℓ_i: the off chips' steady light adds to every frame alike, as a
//! room lamp does, so only the depths the luminaire was configured with can say it. They are
//! turned into off fractions exactly as the luminaire turns them into PWM compare values
//! (`protocol::flicker::off_level_for_depth`, `protocol::timing::off_compare`) at full
//! brightness.

use super::DemodError;
use protocol::config::{ChipRate, LuminaireConfig};
use protocol::flicker;
use protocol::timing::{PWM_STEPS, off_compare, on_compare};
use serde::{Deserialize, Serialize};

/// The modulation depths a capture's LEDs were played at.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModulationDepths {
    /// Off chips dark (depth 1): the thesis' luminaire, the simulator's default.
    #[default]
    Full,
    /// Each LED at its largest IEEE 1789 low-risk depth at the decoded chip rate, as
    /// `meb device set --depth auto` configures it.
    LowRiskAuto,
    /// The factory default's off levels (`LuminaireConfig::DEFAULT`: 743, 698, 891, 890 ‰ …).
    Factory,
    /// Depths in (0, 1] as `meb device set --depth` takes them: one for every LED or one per
    /// LED.
    Depths(Vec<f64>),
    /// Each LED's off light as a fraction of its on light, in [0, 1), as played (from a
    /// luminaire timeline).
    OffFractions(Vec<f64>),
}

/// The depths a decode assumed and how its LED images were scaled: `decode.json`'s
/// `modulation`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ModulationReport {
    /// What the decode was told.
    pub setting: ModulationDepths,
    /// Each LED's modulation depth m_i = (1 − ℓ_i)/(1 + ℓ_i) (empty: all 1, a decode written
    /// before depths were recorded).
    #[serde(default)]
    pub depths: Vec<f64>,
    /// Each LED's off light as a fraction ℓ_i of its on light.
    #[serde(default)]
    pub off_fractions: Vec<f64>,
    /// The factor 1/(1 − ℓ_i) each LED image (and its noise) was multiplied by.
    #[serde(default)]
    pub image_scale: Vec<f64>,
}

impl ModulationReport {
    /// The scale of LED `led` (0-based): 1 when none was recorded.
    pub fn scale(&self, led: usize) -> f64 {
        self.image_scale.get(led).copied().unwrap_or(1.0)
    }

    /// Whether every LED was decoded at full depth (no scaling).
    pub fn is_full_depth(&self) -> bool {
        self.image_scale.iter().all(|&s| s == 1.0)
    }
}

/// The off fraction a luminaire at full brightness plays for off level `permille`.
fn played_off_fraction(permille: u16) -> f64 {
    let on = on_compare(PWM_STEPS);
    f64::from(off_compare(on, permille)) / f64::from(on)
}

/// Resolves `setting` for `leds` LEDs at `chip_rate_hz` (used by
/// [`ModulationDepths::LowRiskAuto`] only) into each LED's off fraction, depth and image scale.
pub fn resolve(
    setting: &ModulationDepths,
    leds: usize,
    chip_rate_hz: f64,
) -> Result<ModulationReport, DemodError> {
    let off_fractions: Vec<f64> = match setting {
        ModulationDepths::Full => vec![0.0; leds],
        ModulationDepths::Factory => (0..leds)
            .map(|i| {
                let level = LuminaireConfig::DEFAULT
                    .off_level_permille
                    .get(i)
                    .copied()
                    .unwrap_or(0);
                played_off_fraction(level)
            })
            .collect(),
        ModulationDepths::LowRiskAuto => {
            let rate = ChipRate::from_hz(chip_rate_hz);
            if !(chip_rate_hz.is_finite() && rate.is_supported()) {
                return Err(DemodError::DepthNeedsChipRate {
                    chip_rate_hz: if chip_rate_hz.is_finite() {
                        chip_rate_hz
                    } else {
                        0.0
                    },
                });
            }
            let led_count =
                u8::try_from(leds).map_err(|_| DemodError::DepthCount { given: leds, leds })?;
            let config = flicker::at_largest_low_risk_depths(&LuminaireConfig {
                led_count,
                chip_rate: rate,
                ..LuminaireConfig::FULL_DEPTH
            });
            (0..leds)
                .map(|i| {
                    played_off_fraction(config.off_level_permille.get(i).copied().unwrap_or(0))
                })
                .collect()
        }
        ModulationDepths::Depths(depths) => {
            for &d in depths {
                if !(d > 0.0 && d <= 1.0) {
                    return Err(DemodError::InvalidDepth { value: d });
                }
            }
            per_led(depths, leds)?
                .into_iter()
                .map(|d| played_off_fraction(flicker::off_level_for_depth(d as f32)))
                .collect()
        }
        ModulationDepths::OffFractions(fractions) => {
            for &l in fractions {
                if !(0.0..1.0).contains(&l) {
                    return Err(DemodError::InvalidOffFraction { value: l });
                }
            }
            per_led(fractions, leds)?
        }
    };
    Ok(ModulationReport {
        setting: setting.clone(),
        depths: off_fractions
            .iter()
            .map(|l| (1.0 - l) / (1.0 + l))
            .collect(),
        image_scale: off_fractions.iter().map(|l| 1.0 / (1.0 - l)).collect(),
        off_fractions,
    })
}

/// `values` for `leds` LEDs: one value for all or one per LED.
fn per_led(values: &[f64], leds: usize) -> Result<Vec<f64>, DemodError> {
    match values.len() {
        1 => Ok(vec![values[0]; leds]),
        n if n == leds => Ok(values.to_vec()),
        given => Err(DemodError::DepthCount { given, leds }),
    }
}

/// Checks what can be checked before decoding: the values, and their count against a fixed
/// LED count.
pub fn check(setting: &ModulationDepths, leds: Option<usize>) -> Result<(), DemodError> {
    match setting {
        ModulationDepths::Depths(values) | ModulationDepths::OffFractions(values) => {
            let n = leds.unwrap_or(values.len().max(1));
            resolve(setting, n, 0.0).map(|_| ())
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factory_and_auto_depths_are_the_luminaires() {
        let factory = resolve(&ModulationDepths::Factory, 4, 960.0).expect("factory");
        assert_eq!(factory.off_fractions, vec![0.743, 0.698, 0.891, 0.890]);
        for (m, want) in factory.depths.iter().zip([0.147, 0.178, 0.058, 0.058]) {
            assert!((m - want).abs() < 1e-3, "{m} vs {want}");
        }
        assert!((factory.image_scale[2] - 1.0 / 0.109).abs() < 1e-9);
        let auto = resolve(&ModulationDepths::LowRiskAuto, 4, 960.0).expect("auto");
        // The factory default is 2 % below each LED's largest low-risk depth.
        for (a, f) in auto.depths.iter().zip(&factory.depths) {
            assert!(*a > *f && *a < f * 1.03, "auto {a} factory {f}");
        }
        let full = resolve(&ModulationDepths::Full, 3, 0.0).expect("full");
        assert!(full.is_full_depth() && full.depths == vec![1.0; 3]);
    }

    #[test]
    fn typed_depths_become_the_off_levels_a_luminaire_plays() {
        let one = resolve(&ModulationDepths::Depths(vec![0.5]), 2, 0.0).expect("0.5");
        // off level ⌈1000·0.5/1.5⌉ = 334 ‰.
        assert_eq!(one.off_fractions, vec![0.334, 0.334]);
        assert!(one.depths.iter().all(|m| *m <= 0.5 && *m > 0.499));
        let each = resolve(&ModulationDepths::Depths(vec![1.0, 0.2]), 2, 0.0).expect("two");
        assert_eq!(each.image_scale[0], 1.0);
    }

    #[test]
    fn bad_depths_are_refused_with_a_reason() {
        let wrong_count = resolve(&ModulationDepths::Depths(vec![0.5, 0.5]), 4, 0.0);
        assert!(matches!(
            wrong_count,
            Err(DemodError::DepthCount { given: 2, leds: 4 })
        ));
        for bad in [0.0, -0.1, 1.5, f64::NAN] {
            assert!(matches!(
                resolve(&ModulationDepths::Depths(vec![bad]), 4, 0.0),
                Err(DemodError::InvalidDepth { .. })
            ));
        }
        assert!(matches!(
            resolve(&ModulationDepths::OffFractions(vec![1.0]), 1, 0.0),
            Err(DemodError::InvalidOffFraction { .. })
        ));
        assert!(matches!(
            resolve(&ModulationDepths::LowRiskAuto, 4, 0.0),
            Err(DemodError::DepthNeedsChipRate { .. })
        ));
        assert!(check(&ModulationDepths::Depths(vec![0.5, 0.5, 0.5]), Some(4)).is_err());
        assert!(check(&ModulationDepths::Depths(vec![0.5, 0.5, 0.5]), None).is_ok());
    }
}
