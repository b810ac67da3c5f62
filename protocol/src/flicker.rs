//! IEEE 1789 flicker limits of a luminaire configuration: the one acceptance function that the
//! firmware, the virtual luminaire and `meb device set` run (docs/howto/flicker-safety.md).
//!
//! IEEE Std 1789-2015, "IEEE Recommended Practices for Modulating Current in High-Brightness
//! LEDs for Mitigating Health Risks to Viewers", §8, bounds the percent modulation of each
//! Fourier component of the light at frequency f:
//!
//! ```text
//! low risk:               Mod% ≤ 0.025·f  (f < 90 Hz),  Mod% ≤ 0.08·f   (90 ≤ f ≤ 1250 Hz), any above
//! no observable effect:   Mod% ≤ 0.01·f   (f < 90 Hz),  Mod% ≤ 0.0333·f (90 ≤ f ≤ 3000 Hz), any above
//! ```
//!
//! The band 3–60 Hz where flicker can trigger photosensitive seizures lies inside the first
//! segment, so a configuration that is low-risk has no component there above 0.025·f.
//!
//! **Closed form.** LED i (0-based) plays a carrier of period P = 2^(i+2) chips at chip rate R.
//! Its on/off chip values w_j (on when bit 0 of j equals bit i+1) have the DFT
//! W_k = 2 / (1 + e^(−2πik/P)) for odd k and 0 for even k ≠ 0, so |W_k| = 1/|cos(πk/P)|; with the
//! rectangular chip's sinc(k/P) the Fourier coefficient of the light is
//! |c_k| = |tan(πk/P)| / (πk), and at full depth (off chips dark) component k at f_k = k·R/P
//! modulates the mean light (c_0 = 1/2) by
//!
//! ```text
//! Mod%_k = 100 · 2|c_k| / c_0 = (400/π) · |tan(πk/P)| / k          (k odd)
//! ```
//!
//! (127.3 % for a plain square wave, k = 1, P = 4; 12.5 % for LED 4's 30 Hz line at 960 Hz).
//!
//! **Depth.** With off chips at a fraction of the on level the light is off + (on − off)·w(t),
//! so every component scales by the modulation depth m = (on − off)/(on + off) (1 for on/off
//! keying, 5.3 % for off chips at 90 % of on). LED i is within a limit L(f) = s·f when
//! m · Mod%_k ≤ s · f_k for every k, i.e.
//!
//! ```text
//! m ≤ min_k  s(f_k) · R · π · k² / (400 · P · |tan(πk/P)|)
//! ```
//!
//! For a fixed residue r = k mod P, |tan| is the same and k² grows, so within one slope segment
//! the smallest k of each residue binds: [`max_depth`] evaluates at most two k per odd residue
//! (the first below 90 Hz, the first at or above it), P/2 residues per LED, in `f32` with a
//! Taylor sine, and takes [`ROUNDING_MARGIN`] off the result.

use crate::carriers::MAX_LEDS;
use crate::config::{ChipRate, LuminaireConfig};
use crate::timing::{PWM_STEPS, off_compare, on_compare};

/// Fraction kept off every depth limit to cover the `f32` arithmetic (relative errors ~10⁻⁶).
pub const ROUNDING_MARGIN: f32 = 1e-4;

/// The seizure-relevant band named by the checks' messages, in hertz.
pub const SEIZURE_BAND_HZ: (f32, f32) = (3.0, 60.0);

/// One IEEE 1789 limit: Mod% ≤ `slope_below`·f below `knee`, ≤ `slope_above`·f from `knee` up
/// to `top`, unrestricted above `top`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limit {
    /// Slope below the knee, percent per hertz.
    pub slope_below: f32,
    /// Slope from the knee to the top, percent per hertz.
    pub slope_above: f32,
    /// Knee frequency in millihertz.
    pub knee_millihertz: u32,
    /// Highest restricted frequency in millihertz.
    pub top_millihertz: u32,
}

/// IEEE 1789-2015 Recommended Practice 1, low risk.
pub const LOW_RISK: Limit = Limit {
    slope_below: 0.025,
    slope_above: 0.08,
    knee_millihertz: 90_000,
    top_millihertz: 1_250_000,
};

/// IEEE 1789-2015 Recommended Practice 2, no observable effect.
pub const NO_OBSERVABLE_EFFECT: Limit = Limit {
    slope_below: 0.01,
    slope_above: 0.0333,
    knee_millihertz: 90_000,
    top_millihertz: 3_000_000,
};

impl Limit {
    /// The limit on percent modulation at `hz` (`None`: unrestricted).
    pub fn percent_at(&self, hz: f32) -> Option<f32> {
        let knee = self.knee_millihertz as f32 / 1000.0;
        let top = self.top_millihertz as f32 / 1000.0;
        if hz < knee {
            Some(self.slope_below * hz)
        } else if hz <= top {
            Some(self.slope_above * hz)
        } else {
            None
        }
    }
}

/// The largest depth an LED may play under a limit, and the component that sets it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DepthLimit {
    /// Largest modulation depth (on − off)/(on + off), at most 1.
    pub depth: f32,
    /// Frequency of the binding component in hertz (0 when nothing binds: depth 1).
    pub frequency_hz: f32,
    /// That component's percent modulation at full depth.
    pub full_depth_percent: f32,
}

/// Percent modulation of component `k` (odd) of LED `led`'s carrier at full depth (module docs).
pub fn full_depth_percent(led: u8, k: u32) -> f32 {
    let period = 4u32 << led.min(MAX_LEDS as u8 - 1);
    (400.0 / core::f32::consts::PI) * abs_tan_pi(k % period, period) / k as f32
}

/// The largest modulation depth of LED `led` (0-based) at chip rate `rate` that keeps every
/// component within `limit`.
#[inline(never)]
pub fn max_depth(led: u8, rate: ChipRate, limit: &Limit) -> DepthLimit {
    // u32 throughout (top·P ≤ 3000 Hz · 512 chips < 2^32 mHz·chips): the firmware has no
    // 64-bit divider.
    let period = 4u32 << led.min(MAX_LEDS as u8 - 1);
    let rate_mhz = rate.millihertz().max(1);
    let hz_per_k = rate_mhz as f32 / (period as f32 * 1000.0);
    // k·R/P < knee  ⇔  k·R < knee·P; the first k at or above the knee and the last below the top.
    let first_above_knee = (limit.knee_millihertz * period).div_ceil(rate_mhz);
    let last_restricted = limit.top_millihertz * period / rate_mhz;
    let mut best = DepthLimit {
        depth: 1.0,
        frequency_hz: 0.0,
        full_depth_percent: 0.0,
    };
    let mut consider = |k: u32, slope: f32, tan: f32| {
        if k > last_restricted {
            return;
        }
        let full = (400.0 / core::f32::consts::PI) * tan / k as f32;
        let f = k as f32 * hz_per_k;
        let depth = slope * f / full;
        if depth < best.depth {
            best = DepthLimit {
                depth,
                frequency_hz: f,
                full_depth_percent: full,
            };
        }
    };
    for residue in (1..period).step_by(2) {
        let tan = abs_tan_pi(residue, period);
        if residue < first_above_knee {
            consider(residue, limit.slope_below, tan);
        }
        let shift = (residue + period - first_above_knee % period) % period;
        consider(first_above_knee + shift, limit.slope_above, tan);
    }
    if best.frequency_hz > 0.0 {
        best.depth = (best.depth * (1.0 - ROUNDING_MARGIN)).min(1.0);
    }
    best
}

/// Modulation depth (on − off)/(on + off) of two PWM compare values (0 when both are 0).
pub fn depth_of(on: u16, off: u16) -> f32 {
    let (on, off) = (f32::from(on), f32::from(off.min(on)));
    if on <= 0.0 {
        0.0
    } else {
        (on - off) / (on + off)
    }
}

/// The modulation depth LED `led` of `config` plays, from the compare values the PWM loads.
pub fn played_depth(config: &LuminaireConfig, led: usize) -> f32 {
    let on = on_compare(config.brightness_permille[led]);
    depth_of(on, off_compare(on, config.off_level_permille[led]))
}

/// Off level in per mille of the on level for modulation depth `depth`: (1 − m)/(1 + m),
/// rounded up so that the depth played is never above the one asked for.
pub fn off_level_for_depth(depth: f32) -> u16 {
    let m = if depth.is_nan() {
        0.0
    } else {
        depth.clamp(0.0, 1.0)
    };
    let level = f32::from(PWM_STEPS) * (1.0 - m) / (1.0 + m);
    let whole = level as u16;
    if f32::from(whole) < level {
        whole + 1
    } else {
        whole
    }
}

/// An LED whose depth exceeds a limit.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Excess {
    /// 0-based LED index.
    pub led: u8,
    /// The depth it plays.
    pub depth: f32,
    /// The limit and the component that sets it.
    pub limit: DepthLimit,
}

/// The first LED of `config` whose played depth exceeds `limit`, if any.
#[inline(never)]
pub fn first_excess(config: &LuminaireConfig, limit: &Limit) -> Option<Excess> {
    let leds = usize::from(config.led_count).min(MAX_LEDS);
    (0..leds).find_map(|led| {
        let depth = played_depth(config, led);
        if depth <= 0.0 {
            return None;
        }
        let bound = max_depth(led as u8, config.chip_rate, limit);
        (depth > bound.depth).then_some(Excess {
            led: led as u8,
            depth,
            limit: bound,
        })
    })
}

/// Whether every LED of `config` is within IEEE 1789 low risk.
pub fn is_low_risk(config: &LuminaireConfig) -> bool {
    first_excess(config, &LOW_RISK).is_none()
}

/// `config` with the off level of every LED above low risk raised to its largest low-risk depth
/// (nothing else changes): what the luminaire plays at power-up when a stored configuration
/// above low risk was not saved with `allow_flicker`.
pub fn limited_to_low_risk(config: &LuminaireConfig) -> LuminaireConfig {
    let mut out = *config;
    let leds = usize::from(config.led_count).min(MAX_LEDS);
    for led in 0..leds {
        let bound = max_depth(led as u8, config.chip_rate, &LOW_RISK);
        let mut level = off_level_for_depth(bound.depth).max(config.off_level_permille[led]);
        // Compare-value rounding at low brightness can push the played depth over: step up.
        loop {
            out.off_level_permille[led] = level;
            if played_depth(&out, led) <= bound.depth || level >= PWM_STEPS {
                break;
            }
            level += 1;
        }
    }
    out
}

/// `config` with every LED at its largest low-risk depth (the lowest off level whose played
/// compare values stay within IEEE 1789 low risk): `meb device set --depth auto`.
pub fn at_largest_low_risk_depths(config: &LuminaireConfig) -> LuminaireConfig {
    limited_to_low_risk(&LuminaireConfig {
        off_level_permille: [0; MAX_LEDS],
        ..*config
    })
}

/// |tan(π·r/P)| for 0 ≤ r < P from two quarter-wave sines (exact integer folding).
fn abs_tan_pi(r: u32, period: u32) -> f32 {
    let r = r % period;
    let folded = if 2 * r > period { period - r } else { r };
    let quarter = period / 2;
    if folded == quarter {
        return f32::INFINITY;
    }
    let angle = |n: u32| core::f32::consts::PI * n as f32 / period as f32;
    sin_quarter(angle(folded)) / sin_quarter(angle(quarter - folded))
}

/// sin(x) for 0 ≤ x ≤ π/2 by its Taylor series to x¹¹ (error below 6·10⁻⁸).
fn sin_quarter(x: f32) -> f32 {
    let x2 = x * x;
    x * (1.0
        - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0 * (1.0 - x2 / 110.0)))))
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn closed_form_matches_the_textbook_and_the_thesis_settings() {
        // A 0/1 square wave's fundamental: 100·(2/π)/0.5.
        assert!((full_depth_percent(0, 1) - 400.0 / core::f32::consts::PI).abs() < 1e-3);
        // 960 Hz, LEDs 2–4: 120 Hz at 52.7 %, 60 Hz at 25.3 %, 30 Hz at 12.5 %.
        assert!((full_depth_percent(1, 1) - 52.74).abs() < 0.01);
        assert!((full_depth_percent(2, 1) - 25.33).abs() < 0.01);
        assert!((full_depth_percent(3, 1) - 12.54).abs() < 0.01);
    }

    #[test]
    fn sine_and_tangent_against_std() {
        for period in [4u32, 8, 64, 512] {
            for r in (1..period).step_by(2) {
                let exact = (std::f64::consts::PI * f64::from(r) / f64::from(period))
                    .tan()
                    .abs();
                let got = f64::from(abs_tan_pi(r, period));
                assert!((got - exact).abs() <= 2e-6 * exact, "{r}/{period}");
            }
        }
    }

    #[test]
    fn four_leds_at_960_hz_are_bound_by_their_lowest_line() {
        let rate = ChipRate(960_000);
        let led3 = max_depth(2, rate, &LOW_RISK);
        let led4 = max_depth(3, rate, &LOW_RISK);
        assert!((led3.frequency_hz - 60.0).abs() < 1e-3);
        assert!((led4.frequency_hz - 30.0).abs() < 1e-3);
        assert!((led3.depth - 1.5 / 25.33).abs() < 1e-3, "{led3:?}");
        assert!((led4.depth - 0.75 / 12.54).abs() < 1e-3, "{led4:?}");
        // Above 1250 Hz every component is unrestricted for low risk: nothing binds at 4 kHz
        // for LED 1 (lines at 1, 3, 5 … kHz; 1 kHz at 127 % needs m ≤ 0.63).
        let fast = max_depth(0, ChipRate(4_000_000), &LOW_RISK);
        assert!((fast.frequency_hz - 1000.0).abs() < 1e-2);
        assert!((fast.depth - 80.0 / 127.32).abs() < 1e-3);
    }

    #[test]
    fn off_level_rounds_towards_less_flicker() {
        assert_eq!(off_level_for_depth(1.0), 0);
        assert_eq!(off_level_for_depth(0.0), 1000);
        assert_eq!(off_level_for_depth(f32::NAN), 1000);
        for permille in 1..1000u16 {
            let m = f32::from(permille) / 1000.0;
            let level = off_level_for_depth(m);
            assert!(depth_of(1000, level) <= m + 1e-6, "{m}: {level}");
            assert!(
                depth_of(1000, level.saturating_sub(1)) > m - 1e-6,
                "{m}: {level}"
            );
        }
    }

    #[test]
    fn limiting_makes_any_configuration_low_risk_and_keeps_low_risk_ones() {
        for leds in 1..=MAX_LEDS as u8 {
            for rate in [1_000, 7_500, 30_000, 240_000, 959_500, 4_000_000] {
                for brightness in [1000, 333, 7] {
                    let config = LuminaireConfig {
                        led_count: leds,
                        chip_rate: ChipRate(rate),
                        brightness_permille: [brightness; MAX_LEDS],
                        off_level_permille: [0; MAX_LEDS],
                        ..LuminaireConfig::DEFAULT
                    };
                    let limited = limited_to_low_risk(&config);
                    assert!(is_low_risk(&limited), "{leds} LEDs {rate} mHz {brightness}");
                    assert_eq!(limited_to_low_risk(&limited), limited);
                }
            }
        }
    }
}
