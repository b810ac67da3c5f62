//! Luminaire configuration: LED count, chip rate, per-LED brightness, off level and phase,
//! running flag and the flicker acceptance (docs/maths/carriers.md#playing-the-table-on-a-luminaire,
//! docs/howto/flicker-safety.md).
//!
//! The chip rate is a fixed-point number of millihertz so that fractional rates such as
//! 959.5 Hz are exact on the wire and in flash. Supported range: [`ChipRate::MIN`] = 1.000 Hz
//! to [`ChipRate::MAX`] = 4000.000 Hz. Below 1 Hz a frame of even 4 chips lasts seconds, useless
//! for any camera. The firmware's brightness PWM runs at 96 kHz (96 MHz timer clock / 1000
//! steps), so ≤ 4 kHz keeps ≥ 24 PWM periods per chip and the brightness even within a chip.
//!
//! Validation ([`LuminaireConfig::validate`]) names the offending field; the state machine
//! never applies an invalid configuration.

use serde::{Deserialize, Serialize};

use crate::carriers::{ChipTable, MAX_LEDS, chips_per_frame};

/// Full brightness in per mille.
pub const FULL_BRIGHTNESS_PERMILLE: u16 = 1000;

/// Chip rate in millihertz (959.5 Hz = `ChipRate(959_500)`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChipRate(pub u32);

impl ChipRate {
    /// Lowest supported chip rate, 1.000 Hz.
    pub const MIN: ChipRate = ChipRate(1_000);
    /// Highest supported chip rate, 4000.000 Hz (≥ 24 periods of the 96 kHz brightness PWM per chip).
    pub const MAX: ChipRate = ChipRate(4_000_000);

    /// Rate from hertz, rounded to the nearest millihertz (saturating; NaN gives 0).
    pub fn from_hz(hz: f64) -> Self {
        let mhz = hz * 1000.0;
        // `as` saturates and maps NaN to 0; rounding without libm: add 0.5 and truncate.
        if mhz <= 0.0 || mhz.is_nan() {
            ChipRate(0)
        } else {
            ChipRate((mhz + 0.5) as u32)
        }
    }

    /// Rate in hertz.
    pub fn hz(self) -> f64 {
        f64::from(self.0) / 1000.0
    }

    /// Rate in millihertz.
    pub const fn millihertz(self) -> u32 {
        self.0
    }

    /// Whether the rate lies in [`Self::MIN`]..=[`Self::MAX`].
    pub const fn is_supported(self) -> bool {
        self.0 >= Self::MIN.0 && self.0 <= Self::MAX.0
    }
}

/// Why a configuration was rejected; each variant names the field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// `led_count` is outside 1..=8.
    LedCount {
        /// The rejected value.
        got: u8,
    },
    /// `chip_rate` is outside 1.000..=4000.000 Hz.
    ChipRate {
        /// The rejected value in millihertz.
        got_millihertz: u32,
    },
    /// `brightness_permille[led]` exceeds 1000.
    Brightness {
        /// 0-based LED index.
        led: u8,
        /// The rejected value.
        got: u16,
    },
    /// `phase_chips[led]` is not below the frame length 2^(N+1).
    Phase {
        /// 0-based LED index.
        led: u8,
        /// The rejected value.
        got: u16,
    },
    /// `off_level_permille[led]` exceeds 1000.
    OffLevel {
        /// 0-based LED index.
        led: u8,
        /// The rejected value.
        got: u16,
    },
    /// LED `led` plays a modulation depth above IEEE 1789 low risk and `allow_flicker` is not
    /// set (depths in per mille; [`crate::flicker`]).
    Flicker {
        /// 0-based LED index.
        led: u8,
        /// The depth it would play, per mille.
        depth_permille: u16,
        /// The largest low-risk depth at this chip rate, per mille.
        max_depth_permille: u16,
        /// Frequency of the component that sets the limit, in millihertz.
        frequency_millihertz: u32,
    },
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::LedCount { got } => write!(f, "led_count {got} is outside 1..={MAX_LEDS}"),
            Self::ChipRate { got_millihertz } => write!(
                f,
                "chip_rate {got_millihertz} mHz is outside {}..={} mHz",
                ChipRate::MIN.0,
                ChipRate::MAX.0
            ),
            Self::Brightness { led, got } => write!(
                f,
                "brightness_permille[{led}] = {got} exceeds {FULL_BRIGHTNESS_PERMILLE}"
            ),
            Self::Phase { led, got } => {
                write!(
                    f,
                    "phase_chips[{led}] = {got} is not below the frame length"
                )
            }
            Self::OffLevel { led, got } => write!(
                f,
                "off_level_permille[{led}] = {got} exceeds {FULL_BRIGHTNESS_PERMILLE}"
            ),
            Self::Flicker {
                led,
                depth_permille,
                max_depth_permille,
                frequency_millihertz,
            } => write!(
                f,
                "LED {} flickers above IEEE 1789 low risk: depth {depth_permille}‰ > {max_depth_permille}‰ (line at {frequency_millihertz} mHz)",
                led + 1
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ConfigError {}

/// Everything the luminaire plays: persisted in flash, exchanged by GetConfig/SetConfig.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LuminaireConfig {
    /// Number of modulated LEDs N (1..=8).
    pub led_count: u8,
    /// Chip rate.
    pub chip_rate: ChipRate,
    /// Per-LED on-brightness in per mille (0..=1000); all 8 entries are validated.
    pub brightness_permille: [u16; MAX_LEDS],
    /// Per-LED cyclic carrier delay in chips (< 2^(N+1)); all 8 entries are validated.
    pub phase_chips: [u16; MAX_LEDS],
    /// Whether the carriers are playing.
    pub running: bool,
    /// Per-LED level of the off chips in per mille of the on level (0 = dark off chips, full
    /// on/off keying; 900 = a 5.3 % modulation depth); all 8 entries are validated.
    pub off_level_permille: [u16; MAX_LEDS],
    /// Whether a configuration above IEEE 1789 low risk was accepted on purpose
    /// (`--allow-flicker`); without it `SetConfig` refuses one and power-up limits one.
    pub allow_flicker: bool,
}

impl LuminaireConfig {
    /// Factory default: 4 LEDs at 960 Hz, full brightness, no phase offsets, running, each LED
    /// 2 % below its largest IEEE 1789 low-risk depth at 960 Hz (LED 1 14.8 %, LED 2 17.8 %,
    /// LED 3 5.8 %, LED 4 5.8 %; LEDs 5–8, not played, as LED 4), a test checks them.
    pub const DEFAULT: LuminaireConfig = LuminaireConfig {
        led_count: 4,
        chip_rate: ChipRate(960_000),
        brightness_permille: [FULL_BRIGHTNESS_PERMILLE; MAX_LEDS],
        phase_chips: [0; MAX_LEDS],
        running: true,
        off_level_permille: DEFAULT_OFF_LEVELS,
        allow_flicker: false,
    };

    /// The default with full on/off keying (every off level 0, `allow_flicker` set): what every
    /// configuration played before the off level was a setting.
    pub const FULL_DEPTH: LuminaireConfig = LuminaireConfig {
        off_level_permille: [0; MAX_LEDS],
        allow_flicker: true,
        ..Self::DEFAULT
    };

    /// Checks every field; the first offending field is reported.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.led_count == 0 || usize::from(self.led_count) > MAX_LEDS {
            return Err(ConfigError::LedCount {
                got: self.led_count,
            });
        }
        if !self.chip_rate.is_supported() {
            return Err(ConfigError::ChipRate {
                got_millihertz: self.chip_rate.0,
            });
        }
        for (led, &got) in (0u8..).zip(self.brightness_permille.iter()) {
            if got > FULL_BRIGHTNESS_PERMILLE {
                return Err(ConfigError::Brightness { led, got });
            }
        }
        for (led, &got) in (0u8..).zip(self.off_level_permille.iter()) {
            if got > FULL_BRIGHTNESS_PERMILLE {
                return Err(ConfigError::OffLevel { led, got });
            }
        }
        let chips = chips_per_frame(self.led_count);
        for (led, &got) in (0u8..).zip(self.phase_chips.iter()) {
            if usize::from(got) >= chips {
                return Err(ConfigError::Phase { led, got });
            }
        }
        Ok(())
    }

    /// [`Self::validate`], then the IEEE 1789 low-risk check unless `allow_flicker` is set:
    /// what `SetConfig` accepts.
    pub fn validate_for_people(&self) -> Result<(), ConfigError> {
        self.validate()?;
        if self.allow_flicker {
            return Ok(());
        }
        match crate::flicker::first_excess(self, &crate::flicker::LOW_RISK) {
            None => Ok(()),
            Some(excess) => Err(ConfigError::Flicker {
                led: excess.led,
                depth_permille: permille_up(excess.depth),
                max_depth_permille: permille(excess.limit.depth),
                frequency_millihertz: (excess.limit.frequency_hz * 1000.0 + 0.5) as u32,
            }),
        }
    }

    /// The chip table this configuration plays (phases applied); `LedCount` error if invalid.
    pub fn chip_table(&self) -> Result<ChipTable, ConfigError> {
        ChipTable::with_phases(self.led_count, &self.phase_chips).map_err(|_| {
            ConfigError::LedCount {
                got: self.led_count,
            }
        })
    }
}

/// Off levels of [`LuminaireConfig::DEFAULT`]: the largest low-risk depths at 960 Hz.
/// 2 % below the largest, so that nearby rates (959.5 Hz) stay low-risk too.
const DEFAULT_OFF_LEVELS: [u16; MAX_LEDS] = [743, 698, 891, 890, 890, 890, 890, 890];

/// A fraction in whole per mille, rounded down (0..=1 maps to 0..=1000).
fn permille(x: f32) -> u16 {
    (x * 1000.0) as u16
}

/// A fraction in whole per mille, rounded up: a depth above a limit never prints as equal.
fn permille_up(x: f32) -> u16 {
    let down = permille(x);
    if f32::from(down) < x * 1000.0 {
        down + 1
    } else {
        down
    }
}

impl Default for LuminaireConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid_and_plays_four_leds() {
        let config = LuminaireConfig::DEFAULT;
        assert_eq!(config.validate(), Ok(()));
        assert_eq!(config.chip_table().map(|t| t.chips()), Ok(32));
    }

    #[test]
    fn default_is_low_risk_at_the_largest_depths() {
        let config = LuminaireConfig::DEFAULT;
        assert_eq!(config.validate_for_people(), Ok(()));
        assert_eq!(crate::flicker::limited_to_low_risk(&config), config);
        let mut nearby = config;
        nearby.chip_rate = ChipRate(959_500);
        assert_eq!(nearby.validate_for_people(), Ok(()));
        // Each played LED within 3 % of its largest depth: 10 per mille less off light (a
        // deeper modulation) is refused.
        for led in 0..usize::from(config.led_count) {
            let max =
                crate::flicker::max_depth(led as u8, config.chip_rate, &crate::flicker::LOW_RISK);
            assert!(
                crate::flicker::played_depth(&config, led) > 0.97 * max.depth,
                "LED {led}"
            );
            let mut deeper = config;
            deeper.off_level_permille[led] -= 10;
            assert!(
                matches!(deeper.validate_for_people(), Err(ConfigError::Flicker { led: l, .. }) if usize::from(l) == led),
                "LED {led}"
            );
            deeper.allow_flicker = true;
            assert_eq!(deeper.validate_for_people(), Ok(()));
        }
        let mut bad = config;
        bad.off_level_permille[6] = 1001;
        assert_eq!(
            bad.validate(),
            Err(ConfigError::OffLevel { led: 6, got: 1001 })
        );
    }

    #[test]
    fn fractional_rates_are_exact() {
        assert_eq!(ChipRate::from_hz(959.5), ChipRate(959_500));
        assert_eq!(ChipRate(959_500).hz(), 959.5);
        assert_eq!(ChipRate::from_hz(f64::NAN), ChipRate(0));
        assert_eq!(ChipRate::from_hz(-3.0), ChipRate(0));
        assert_eq!(ChipRate::from_hz(1e30), ChipRate(u32::MAX));
    }

    #[test]
    fn rate_range_edges() {
        let mut c = LuminaireConfig::DEFAULT;
        for (mhz, ok) in [
            (999, false),
            (1_000, true),
            (4_000_000, true),
            (4_000_001, false),
        ] {
            c.chip_rate = ChipRate(mhz);
            assert_eq!(c.validate().is_ok(), ok, "{mhz}");
        }
        c.chip_rate = ChipRate(999);
        assert_eq!(
            c.validate(),
            Err(ConfigError::ChipRate {
                got_millihertz: 999
            })
        );
    }

    #[test]
    fn errors_name_the_field() {
        let mut c = LuminaireConfig::DEFAULT;
        c.led_count = 9;
        assert_eq!(c.validate(), Err(ConfigError::LedCount { got: 9 }));
        c.led_count = 0;
        assert_eq!(c.validate(), Err(ConfigError::LedCount { got: 0 }));
        let mut c = LuminaireConfig::DEFAULT;
        c.brightness_permille[7] = 1001;
        assert_eq!(
            c.validate(),
            Err(ConfigError::Brightness { led: 7, got: 1001 })
        );
        let mut c = LuminaireConfig::DEFAULT;
        c.phase_chips[2] = 32;
        assert_eq!(c.validate(), Err(ConfigError::Phase { led: 2, got: 32 }));
        c.phase_chips[2] = 31;
        assert_eq!(c.validate(), Ok(()));
    }

    #[test]
    fn phases_reach_the_chip_table() {
        let mut c = LuminaireConfig::DEFAULT;
        c.phase_chips[0] = 1;
        let shifted = c.chip_table().unwrap();
        let plain = LuminaireConfig::DEFAULT.chip_table().unwrap();
        assert_ne!(shifted.masks(), plain.masks());
        assert_eq!(shifted.masks()[1] & 1, plain.masks()[0] & 1);
    }
}
