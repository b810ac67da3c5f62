//! The flicker check the luminaire runs ([`protocol::flicker`]: `f32`, a Taylor sine, two
//! harmonics per residue, a rounding margin) is conservative: over a seeded sweep of
//! configurations it never accepts one that an exact reference rejects, and what it plays at
//! power-up for a stored configuration above low risk is within low risk by the reference.
//!
//! The reference shares no arithmetic with the module: it takes each LED's on/off chips from
//! [`chip_is_on`], their DFT W_r (r < P) in `f64`, the rectangular chip's sinc, and walks every
//! harmonic k up to the limit's top frequency, choosing the slope segment by integer
//! comparison of k·R with the knee (IEEE Std 1789-2015 §8; docs/howto/flicker-safety.md):
//!
//! ```text
//! |c_k| = |W_(k mod P)| · |sin(πk/P)| / (πk),   c_0 = 1/2,   Mod%_k = m · 100 · 2|c_k| / c_0
//! ```
//!
//! with m = (on − off)/(on + off) from the PWM compare values the luminaire loads.

mod common;
use common::Rng;
use protocol::carriers::{MAX_LEDS, chip_is_on};
use protocol::config::{ChipRate, LuminaireConfig};
use protocol::flicker::{self, LOW_RISK, Limit, NO_OBSERVABLE_EFFECT};
use protocol::luminaire::{BoardInfo, Luminaire, RestoredConfig};
use protocol::timing::{off_compare, on_compare};

/// Configurations per sweep.
const CASES: usize = 400;

/// A chip rate: log-uniform over the supported range, or next to a knee or top frequency of
/// some harmonic of some LED (where the slope segment changes).
fn random_rate(rng: &mut Rng) -> ChipRate {
    let (lo, hi) = (
        f64::from(ChipRate::MIN.millihertz()),
        f64::from(ChipRate::MAX.millihertz()),
    );
    if rng.below(3) == 0 {
        let period = 4u64 << rng.below(MAX_LEDS as u64);
        let k = 1 + 2 * rng.below(8);
        let edge = [LOW_RISK.knee_millihertz, LOW_RISK.top_millihertz][rng.below(2) as usize];
        let at = u64::from(edge) * period / k;
        let mhz = (at + rng.below(3)).saturating_sub(1);
        return ChipRate(mhz.clamp(lo as u64, hi as u64) as u32);
    }
    ChipRate((lo * (hi / lo).powf(rng.unit())).round() as u32)
}

/// A configuration; half of them with every off level within a few per mille of the exact
/// largest depth under `LOW_RISK` or `NO_OBSERVABLE_EFFECT`, where a check that is not
/// conservative would accept too much.
fn random_config(rng: &mut Rng, reference: &Reference) -> LuminaireConfig {
    let mut config = LuminaireConfig {
        led_count: 1 + rng.below(MAX_LEDS as u64) as u8,
        chip_rate: random_rate(rng),
        allow_flicker: false,
        ..LuminaireConfig::DEFAULT
    };
    let near_edge =
        [None, Some(&LOW_RISK), Some(&NO_OBSERVABLE_EFFECT)][rng.below(4).min(2) as usize];
    for led in 0..MAX_LEDS {
        config.brightness_permille[led] = match rng.below(4) {
            0 => 1000,
            1 => 1 + rng.below(20) as u16,
            _ => rng.below(1001) as u16,
        };
        config.off_level_permille[led] = match (near_edge, rng.below(4)) {
            (Some(limit), _) => {
                let depth = reference.max_depth(led, config.chip_rate, limit);
                let level = 1000.0 * (1.0 - depth) / (1.0 + depth);
                (level.round() as i64 + rng.below(7) as i64 - 3).clamp(0, 1000) as u16
            }
            (None, 0) => 0,
            (None, 1) => 800 + rng.below(201) as u16,
            (None, _) => rng.below(1001) as u16,
        };
    }
    config
}

/// Exact per-LED reference: the largest depth within `limit` (module docs), by brute force.
struct Reference {
    /// |W_r| for r in 0..P, per LED.
    dft: Vec<Vec<f64>>,
}

impl Reference {
    fn new() -> Self {
        let dft = (0..MAX_LEDS)
            .map(|led| {
                let period = 4usize << led;
                for j in 0..period {
                    assert_eq!(chip_is_on(led, j), chip_is_on(led, j + period), "{led} {j}");
                }
                let on = (0..period).filter(|&j| chip_is_on(led, j)).count();
                assert_eq!(2 * on, period, "LED {led} is on half its chips");
                (0..period)
                    .map(|r| {
                        let (mut re, mut im) = (0.0f64, 0.0f64);
                        for j in (0..period).filter(|&j| chip_is_on(led, j)) {
                            let phase =
                                -2.0 * std::f64::consts::PI * (r * j) as f64 / period as f64;
                            re += phase.cos();
                            im += phase.sin();
                        }
                        re.hypot(im)
                    })
                    .collect()
            })
            .collect();
        Self { dft }
    }

    /// Largest modulation depth of LED `led` at `rate` within `limit`, over every harmonic.
    fn max_depth(&self, led: usize, rate: ChipRate, limit: &Limit) -> f64 {
        let period = 4u64 << led;
        let rate_mhz = u64::from(rate.millihertz());
        let mut best = 1.0f64;
        let mut k = 1u64;
        while k * rate_mhz <= u64::from(limit.top_millihertz) * period {
            let w = self.dft[led][(k % period) as usize];
            let x = std::f64::consts::PI * k as f64 / period as f64;
            let c_k = w * x.sin().abs() / (std::f64::consts::PI * k as f64);
            let full_percent = 100.0 * 2.0 * c_k / 0.5;
            let slope = if k * rate_mhz < u64::from(limit.knee_millihertz) * period {
                f64::from(limit.slope_below)
            } else {
                f64::from(limit.slope_above)
            };
            let hz = (k * rate_mhz) as f64 / (period as f64 * 1000.0);
            if full_percent > 1e-12 {
                best = best.min(slope * hz / full_percent);
            }
            k += 1;
        }
        best
    }
}

/// Depth LED `led` of `config` plays, from the compare values, in `f64`.
fn played(config: &LuminaireConfig, led: usize) -> f64 {
    let on = on_compare(config.brightness_permille[led]);
    let off = off_compare(on, config.off_level_permille[led]).min(on);
    if on == 0 {
        0.0
    } else {
        f64::from(on - off) / f64::from(on + off)
    }
}

/// The first LED that plays above `limit` by the reference.
fn exact_excess(reference: &Reference, config: &LuminaireConfig, limit: &Limit) -> Option<usize> {
    (0..usize::from(config.led_count))
        .find(|&led| played(config, led) > reference.max_depth(led, config.chip_rate, limit))
}

fn board() -> BoardInfo {
    BoardInfo::new("test", "test")
}

#[test]
fn the_luminaires_check_never_accepts_what_the_exact_reference_rejects() {
    let reference = Reference::new();
    let mut rng = Rng(0x0F11_C4E2_1789_2015);
    let (mut accepted, mut rejected) = (0usize, 0usize);
    for case in 0..CASES {
        let config = random_config(&mut rng, &reference);
        for limit in [&LOW_RISK, &NO_OBSERVABLE_EFFECT] {
            let chip = flicker::first_excess(&config, limit);
            let exact = exact_excess(&reference, &config, limit);
            if chip.is_none() {
                accepted += 1;
                assert_eq!(
                    exact, None,
                    "case {case}: {config:?} accepted under {limit:?}"
                );
            } else {
                rejected += 1;
            }
        }
        // Power-up with the stored configuration (either record layout): what plays is within
        // low risk.
        let restored = if case % 2 == 0 {
            RestoredConfig::Ok(config)
        } else {
            RestoredConfig::WithoutDepth(config)
        };
        let luminaire = Luminaire::new(board(), restored);
        let playing = luminaire.config();
        assert_eq!(
            exact_excess(&reference, playing, &LOW_RISK),
            None,
            "case {case}: power-up plays {playing:?} for {config:?}"
        );
    }
    // The sweep reaches both answers (a check that accepted nothing would pass the loop).
    assert!(
        accepted > CASES / 4 && rejected > CASES / 4,
        "{accepted} accepted, {rejected} rejected"
    );
}

#[test]
fn the_luminaires_depth_limits_are_below_the_exact_ones_and_close_to_them() {
    let reference = Reference::new();
    let mut rng = Rng(0x5EED_0000_0000_0059);
    for _ in 0..CASES {
        let rate = random_rate(&mut rng);
        let led = rng.below(MAX_LEDS as u64) as usize;
        for limit in [&LOW_RISK, &NO_OBSERVABLE_EFFECT] {
            let chip = f64::from(flicker::max_depth(led as u8, rate, limit).depth);
            let exact = reference.max_depth(led, rate, limit);
            assert!(
                chip <= exact,
                "LED {led} at {rate:?}: {chip} > exact {exact}"
            );
            // Conservative by the rounding margin, not by throwing depth away.
            assert!(
                chip >= exact * (1.0 - 3.0 * f64::from(flicker::ROUNDING_MARGIN)),
                "LED {led} at {rate:?}: {chip} far below exact {exact}"
            );
        }
    }
}

#[test]
fn limiting_to_low_risk_is_exactly_low_risk_and_changes_only_what_flickers() {
    let reference = Reference::new();
    let mut rng = Rng(0xB0A7_D00D_1789_0001);
    for case in 0..CASES {
        let config = random_config(&mut rng, &reference);
        let limited = flicker::limited_to_low_risk(&config);
        assert_eq!(
            exact_excess(&reference, &limited, &LOW_RISK),
            None,
            "case {case}: {config:?}"
        );
        for led in 0..usize::from(config.led_count) {
            let bound = flicker::max_depth(led as u8, config.chip_rate, &LOW_RISK).depth;
            if flicker::played_depth(&config, led) <= bound {
                assert_eq!(
                    limited.off_level_permille[led], config.off_level_permille[led],
                    "case {case}: LED {led} was within low risk"
                );
            } else {
                assert!(
                    limited.off_level_permille[led] > config.off_level_permille[led],
                    "case {case}: LED {led} above low risk kept its off level"
                );
            }
        }
    }
}
