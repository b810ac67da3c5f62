//! A luminaire configuration from what a user asks for, and the IEEE 1789 check before it is
//! applied or saved: the rules `meb device set`/`save` and the Python `Luminaire` share.
//!
//! The two front ends spell their options differently (`--depth auto`, `depth="auto"`); every
//! message that names an option takes the front end's [`Spelling`].

use protocol::carriers::MAX_LEDS;
use protocol::config::{ChipRate, ConfigError, FULL_BRIGHTNESS_PERMILLE, LuminaireConfig};
use protocol::flicker::{self, LOW_RISK};
use protocol::timing::LedLevels;

/// How a front end spells the options a message names.
#[derive(Clone, Copy, Debug)]
pub struct Spelling {
    /// The LED count option (`--leds`).
    pub leds: &'static str,
    /// The chip rate option (`--rate`).
    pub rate: &'static str,
    /// The brightness option (`--brightness`).
    pub brightness: &'static str,
    /// The phase option (`--phase`).
    pub phase: &'static str,
    /// The depth option (`--depth`).
    pub depth: &'static str,
    /// The depth option set to each LED's largest low-risk depth (`--depth auto`).
    pub depth_auto: &'static str,
    /// The override of the flicker check (`pass --allow-flicker`).
    pub allow_flicker: &'static str,
}

impl Spelling {
    /// The `meb` command's flags.
    pub const CLI: Spelling = Spelling {
        leds: "--leds",
        rate: "--rate",
        brightness: "--brightness",
        phase: "--phase",
        depth: "--depth",
        depth_auto: "--depth auto",
        allow_flicker: "pass --allow-flicker",
    };
}

/// The modulation depth (on − off)/(on + off) asked for.
#[derive(Clone, Debug, PartialEq)]
pub enum DepthRequest {
    /// Each LED at its largest IEEE 1789 low-risk depth for the rate and LED count.
    Auto,
    /// One depth in (0, 1] for every LED, or one per LED.
    Depths(Vec<f32>),
}

impl DepthRequest {
    /// Parses `auto`, one depth or comma-separated depths (one per LED).
    pub fn parse(text: &str, spelling: &Spelling) -> Result<Self, SettingsError> {
        if text.trim() == "auto" {
            return Ok(DepthRequest::Auto);
        }
        text.split(',')
            .map(|v| {
                v.trim()
                    .parse::<f32>()
                    .ok()
                    .filter(|d| *d > 0.0 && *d <= 1.0)
                    .ok_or_else(|| SettingsError::Depth {
                        option: spelling.depth,
                        value: v.trim().to_string(),
                    })
            })
            .collect::<Result<Vec<_>, _>>()
            .map(DepthRequest::Depths)
    }
}

/// What a user asks a luminaire to play; options left `None` take their defaults (full
/// brightness, no phase offset, the luminaire's current off levels).
#[derive(Clone, Debug)]
pub struct SettingsRequest<'a> {
    /// LEDs driven, 1..=8.
    pub leds: u8,
    /// Chip rate in hertz (the camera's frame rate).
    pub rate_hz: f64,
    /// Per-LED brightness in permille, one per LED.
    pub brightness: Option<&'a [u16]>,
    /// Per-LED carrier phase in chips, one per LED.
    pub phase: Option<&'a [u16]>,
    /// Modulation depth.
    pub depth: Option<&'a DepthRequest>,
    /// Plays (and may save) a configuration above IEEE 1789 low risk.
    pub allow_flicker: bool,
}

/// A request that cannot become a valid configuration.
#[derive(Debug, thiserror::Error)]
pub enum SettingsError {
    /// The LED count is outside what the luminaire drives.
    #[error("{option} {leds} is outside 1..={MAX_LEDS}")]
    LedCount {
        /// The option's name.
        option: &'static str,
        /// The count asked for.
        leds: u8,
    },
    /// The chip rate is outside what the timer produces.
    #[error("{option} {rate_hz} Hz is outside the supported {min:.3}..={max:.3} Hz")]
    Rate {
        /// The option's name.
        option: &'static str,
        /// The rate asked for.
        rate_hz: f64,
        /// The lowest supported rate.
        min: f64,
        /// The highest supported rate.
        max: f64,
    },
    /// A per-LED option with the wrong number of values.
    #[error("{option} needs {expected} values (one per LED), got {got}")]
    PerLed {
        /// The option's name.
        option: &'static str,
        /// The LED count.
        expected: usize,
        /// The values given.
        got: usize,
    },
    /// A depth that is not in (0, 1] nor `auto`.
    #[error("{option} {value:?}: a depth in (0, 1] or `auto` expected")]
    Depth {
        /// The option's name.
        option: &'static str,
        /// The text given.
        value: String,
    },
    /// The protocol's validation refused the configuration.
    #[error("{0}")]
    Invalid(#[from] ConfigError),
}

/// The configuration `request` asks for, the off levels of LEDs without a depth taken from
/// `current` (and its running state kept), validated as the luminaire will.
pub fn configure(
    request: &SettingsRequest<'_>,
    current: &LuminaireConfig,
    spelling: &Spelling,
) -> Result<LuminaireConfig, SettingsError> {
    let n = usize::from(request.leds);
    if n == 0 || n > MAX_LEDS {
        return Err(SettingsError::LedCount {
            option: spelling.leds,
            leds: request.leds,
        });
    }
    let (min, max) = (ChipRate::MIN.hz(), ChipRate::MAX.hz());
    // Checked in hertz: converting first would saturate 1e9 Hz to u32::MAX millihertz.
    if !(request.rate_hz >= min && request.rate_hz <= max) {
        return Err(SettingsError::Rate {
            option: spelling.rate,
            rate_hz: request.rate_hz,
            min,
            max,
        });
    }
    let brightness = per_led(
        spelling.brightness,
        request.brightness,
        n,
        FULL_BRIGHTNESS_PERMILLE,
    )?;
    let phase_chips = per_led(spelling.phase, request.phase, n, 0)?;
    let mut config = LuminaireConfig {
        led_count: request.leds,
        chip_rate: ChipRate::from_hz(request.rate_hz),
        brightness_permille: brightness,
        phase_chips,
        running: current.running,
        off_level_permille: current.off_level_permille,
        allow_flicker: request.allow_flicker,
    };
    match request.depth {
        None => {}
        Some(DepthRequest::Auto) => {
            config.off_level_permille =
                flicker::at_largest_low_risk_depths(&config).off_level_permille;
        }
        Some(DepthRequest::Depths(depths)) => match depths.len() {
            1 => config.off_level_permille[..n].fill(flicker::off_level_for_depth(depths[0])),
            len if len == n => {
                for (level, &d) in config.off_level_permille.iter_mut().zip(depths) {
                    *level = flicker::off_level_for_depth(d);
                }
            }
            got => {
                return Err(SettingsError::PerLed {
                    option: spelling.depth,
                    expected: n,
                    got,
                });
            }
        },
    }
    config.validate()?;
    Ok(config)
}

/// Each LED's off-chip light as a fraction ℓ_i of its on light, as `config` plays it (its PWM
/// compare values; 0 for a dark LED): what the camera sees of the off level.
pub fn off_fractions(config: &LuminaireConfig) -> Vec<f64> {
    let levels = LedLevels::new(&config.brightness_permille, &config.off_level_permille);
    (0..usize::from(config.led_count).min(MAX_LEDS))
        .map(|i| match levels.on[i] {
            0 => 0.0,
            on => f64::from(levels.off[i]) / f64::from(on),
        })
        .collect()
}

/// `values` (one per LED) in an 8-entry table, the rest `default`.
fn per_led(
    option: &'static str,
    values: Option<&[u16]>,
    n: usize,
    default: u16,
) -> Result<[u16; MAX_LEDS], SettingsError> {
    let mut out = [default; MAX_LEDS];
    if let Some(values) = values {
        if values.len() != n {
            return Err(SettingsError::PerLed {
                option,
                expected: n,
                got: values.len(),
            });
        }
        out[..n].copy_from_slice(values);
    }
    Ok(out)
}

/// The first LED of a configuration above IEEE 1789 low risk, with what would make it
/// low-risk.
#[derive(Clone, Debug)]
pub struct FlickerExcess {
    /// LED index from 0.
    pub led: u8,
    /// The spectral line that breaks the limit, in hertz.
    pub frequency_hz: f32,
    /// Its modulation at the configured depth, in percent.
    pub modulation_percent: f32,
    /// The low-risk limit at that frequency, in percent.
    pub limit_percent: f32,
    /// The LED's modulation depth.
    pub depth: f32,
    /// Each LED's largest low-risk depth at this rate.
    pub low_risk_depths: Vec<f32>,
    /// The decoding noise at the offending LED's low-risk depth, relative to full depth.
    pub noise_factor: f32,
    /// The lowest whole chip rate up to 4000 Hz at which the configured depths are low-risk.
    pub low_risk_rate_hz: Option<u32>,
}

impl FlickerExcess {
    /// Whether the offending line lies in the 3–60 Hz band where flicker can trigger
    /// photosensitive seizures.
    pub fn in_seizure_band(&self) -> bool {
        (flicker::SEIZURE_BAND_HZ.0..=flicker::SEIZURE_BAND_HZ.1).contains(&self.frequency_hz)
    }

    /// The refusal of `command` ("set", "save"): what flickers, how much, and what would be
    /// low-risk, in the front end's spelling.
    pub fn refusal(&self, command: &str, spelling: &Spelling) -> String {
        let f = self.frequency_hz;
        let band = if self.in_seizure_band() {
            ", inside the 3–60 Hz band where flicker can trigger seizures"
        } else {
            ""
        };
        let depths: Vec<String> = self
            .low_risk_depths
            .iter()
            .map(|d| format!("{d:.3}"))
            .collect();
        let rate = self
            .low_risk_rate_hz
            .map(|hz| format!("a chip rate of at least {hz} Hz at this depth"))
            .unwrap_or_else(|| "no chip rate up to 4000 Hz at this depth".into());
        format!(
            "refusing to {command}: LED {} plays its {f:.2} Hz line at {:.2} % modulation \
             (depth {:.3}), above IEEE 1789 low risk ({:.2} % at {f:.2} Hz){band}. Low-risk: {} \
             (depths {}; decoding noise ×{:.1} of full depth), or {rate}; or {} to {command} it \
             anyway.",
            self.led + 1,
            self.modulation_percent,
            self.depth,
            self.limit_percent,
            spelling.depth_auto,
            depths.join(","),
            self.noise_factor,
            spelling.allow_flicker,
        )
    }
}

/// The first LED of `config` above IEEE 1789 low risk, or `None` when it is low-risk.
pub fn flicker_excess(config: &LuminaireConfig) -> Option<FlickerExcess> {
    let excess = flicker::first_excess(config, &LOW_RISK)?;
    let f = excess.limit.frequency_hz;
    let low_risk_depths: Vec<f32> = (0..config.led_count)
        .map(|led| flicker::max_depth(led, config.chip_rate, &LOW_RISK).depth)
        .collect();
    Some(FlickerExcess {
        led: excess.led,
        frequency_hz: f,
        modulation_percent: excess.depth * excess.limit.full_depth_percent,
        limit_percent: LOW_RISK.percent_at(f).unwrap_or(f32::INFINITY),
        depth: excess.depth,
        noise_factor: 1.0 / low_risk_depths[usize::from(excess.led)],
        low_risk_depths,
        low_risk_rate_hz: lowest_low_risk_rate(config),
    })
}

/// The lowest whole chip rate in hertz, from `config`'s up to 4000 Hz, at which its LEDs'
/// depths are low-risk.
fn lowest_low_risk_rate(config: &LuminaireConfig) -> Option<u32> {
    let start = config.chip_rate.hz().ceil() as u32;
    (start..=4000).find(|&hz| {
        let mut trial = *config;
        trial.chip_rate = ChipRate(hz * 1000);
        flicker::is_low_risk(&trial)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(depth: Option<&DepthRequest>) -> SettingsRequest<'_> {
        SettingsRequest {
            leds: 4,
            rate_hz: 960.0,
            brightness: None,
            phase: None,
            depth,
            allow_flicker: false,
        }
    }

    #[test]
    fn auto_depth_is_low_risk_and_full_depth_is_not() {
        let current = LuminaireConfig::default();
        let auto = configure(
            &request(Some(&DepthRequest::Auto)),
            &current,
            &Spelling::CLI,
        )
        .expect("auto depth");
        assert!(flicker_excess(&auto).is_none());
        let full = DepthRequest::Depths(vec![1.0]);
        let config = configure(&request(Some(&full)), &current, &Spelling::CLI).expect("full");
        let excess = flicker_excess(&config).expect("full on/off keying flickers at 960 Hz");
        assert!(excess.modulation_percent > excess.limit_percent);
        assert_eq!(excess.low_risk_depths.len(), 4);
        let message = excess.refusal("set", &Spelling::CLI);
        assert!(message.contains("--depth auto") && message.contains("--allow-flicker"));
    }

    #[test]
    fn wrong_counts_and_depths_are_refused_in_the_front_ends_spelling() {
        let current = LuminaireConfig::default();
        let mut bad = request(None);
        bad.leds = 9;
        assert!(matches!(
            configure(&bad, &current, &Spelling::CLI),
            Err(SettingsError::LedCount { leds: 9, .. })
        ));
        let three = [500u16, 500, 500];
        let mut short = request(None);
        short.brightness = Some(&three);
        let err = configure(&short, &current, &Spelling::CLI).expect_err("3 of 4 values");
        assert_eq!(
            err.to_string(),
            "--brightness needs 4 values (one per LED), got 3"
        );
        assert!(DepthRequest::parse("0", &Spelling::CLI).is_err());
        assert!(DepthRequest::parse("1.5", &Spelling::CLI).is_err());
        assert_eq!(
            DepthRequest::parse("0.5, 1", &Spelling::CLI).expect("two depths"),
            DepthRequest::Depths(vec![0.5, 1.0])
        );
        let mut rate = request(None);
        rate.rate_hz = 1e9;
        assert!(matches!(
            configure(&rate, &current, &Spelling::CLI),
            Err(SettingsError::Rate { .. })
        ));
    }
}
