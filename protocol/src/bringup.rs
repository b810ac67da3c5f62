//! The wiring check a person can do without a probe or a scope (`meb device blink`): the
//! luminaire lights each LED alone, one after the other about once a second, then plays every
//! carrier slowly enough to follow by eye, then returns to the configuration it had.
//!
//! The check is a sequence of ordinary configurations ([`blink_sequence`]) that the host sends
//! with `SetConfig` and holds for the given time, so it runs on any firmware that speaks this
//! protocol and on the virtual luminaire, and costs the firmware no flash. Nothing is saved: if
//! the host is interrupted, the luminaire keeps the step it was in until the next `SetConfig`,
//! and a power cycle brings back the stored configuration.
//!
//! What a person sees, for N LEDs:
//! 1. LED 1 alone, then LED 2, … LED N, each for [`LED_STEP_MS`]: the carrier at
//!    [`STEADY_RATE`] is too fast to see, so the LED looks steadily lit at half intensity. A dark
//!    step is a wiring or driver fault on that output; a different LED lighting up means the
//!    outputs are swapped.
//! 2. All N carriers at [`WALK_RATE`] for [`WALK_CHIPS`] chips: every LED blinks, on in about
//!    half the chips; LEDs 1–4 each in a pattern of its own (beyond 4 LEDs, the higher
//!    carriers can look alike in these first 32 chips). An LED that stays dark or steady here but lit in step 1 points
//!    at the carrier chain (timer DMA), not the wiring.
//! 3. The configuration from before the check.
//!
//! The steps play full on/off keying, and the walk flickers at a few hertz on purpose: they
//! carry `allow_flicker` and are exempt from the IEEE 1789 low-risk check that `SetConfig`
//! applies otherwise (docs/howto/flicker-safety.md); `meb device blink` says so before it starts.

use heapless::Vec;

use crate::carriers::MAX_LEDS;
use crate::config::{ChipRate, FULL_BRIGHTNESS_PERMILLE, LuminaireConfig};

/// How long each LED is lit alone.
pub const LED_STEP_MS: u32 = 1_000;
/// Chip rate while one LED is lit alone: far above flicker fusion, so the LED looks steady.
pub const STEADY_RATE: ChipRate = ChipRate(960_000);
/// Chip rate of the carrier walk: 4 chips a second, each chip's on/off visible.
pub const WALK_RATE: ChipRate = ChipRate(4_000);
/// Chips played in the carrier walk (8 s at [`WALK_RATE`]; a whole code period for N ≤ 4).
pub const WALK_CHIPS: u32 = 32;

/// One step of the check: the configuration to set and how long to hold it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlinkStep {
    /// What the luminaire plays during the step.
    pub config: LuminaireConfig,
    /// How long the host holds it before the next step, in milliseconds.
    pub hold_ms: u32,
}

/// The steps of the check for a luminaire whose active configuration is `active`: one per LED,
/// the carrier walk, then `active` again (held 0 ms). Every step is a valid configuration when
/// `active` is.
pub fn blink_sequence(active: &LuminaireConfig) -> Vec<BlinkStep, { MAX_LEDS + 2 }> {
    let leds = usize::from(active.led_count).min(MAX_LEDS);
    let mut steps = Vec::new();
    for led in 0..leds {
        let mut brightness = [0; MAX_LEDS];
        brightness[led] = FULL_BRIGHTNESS_PERMILLE;
        let config = LuminaireConfig {
            chip_rate: STEADY_RATE,
            brightness_permille: brightness,
            running: true,
            off_level_permille: [0; MAX_LEDS],
            allow_flicker: true,
            ..*active
        };
        push(&mut steps, config, LED_STEP_MS);
    }
    let mut walk_brightness = [0; MAX_LEDS];
    walk_brightness[..leds].fill(FULL_BRIGHTNESS_PERMILLE);
    let walk = LuminaireConfig {
        chip_rate: WALK_RATE,
        brightness_permille: walk_brightness,
        running: true,
        off_level_permille: [0; MAX_LEDS],
        allow_flicker: true,
        ..*active
    };
    push(
        &mut steps,
        walk,
        WALK_CHIPS * 1_000_000 / WALK_RATE.millihertz(),
    );
    push(&mut steps, *active, 0);
    steps
}

fn push(steps: &mut Vec<BlinkStep, { MAX_LEDS + 2 }>, config: LuminaireConfig, hold_ms: u32) {
    // Capacity MAX_LEDS + 2 holds the per-LED steps, the walk and the restore.
    let _ = steps.push(BlinkStep { config, hold_ms });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::carriers::ChipTable;

    fn configured(leds: u8) -> LuminaireConfig {
        LuminaireConfig {
            led_count: leds,
            chip_rate: ChipRate(959_500),
            brightness_permille: [700, 600, 500, 400, 300, 200, 100, 50],
            phase_chips: [0; MAX_LEDS],
            running: false,
            ..LuminaireConfig::DEFAULT
        }
    }

    #[test]
    fn each_led_alone_then_the_slow_walk_then_the_configuration_back() {
        for leds in 1..=MAX_LEDS as u8 {
            let active = configured(leds);
            let steps = blink_sequence(&active);
            let n = usize::from(leds);
            assert_eq!(steps.len(), n + 2, "N = {leds}");
            for (i, step) in steps[..n].iter().enumerate() {
                let lit: std::vec::Vec<usize> = (0..MAX_LEDS)
                    .filter(|&l| step.config.brightness_permille[l] > 0)
                    .collect();
                assert_eq!(lit, [i], "N = {leds}, step {i}");
                assert_eq!(step.config.brightness_permille[i], 1000);
                assert_eq!(step.config.chip_rate, ChipRate(960_000));
                assert_eq!(step.config.led_count, leds);
                assert!(step.config.running);
                assert_eq!(step.hold_ms, 1_000);
                assert_eq!(step.config.validate(), Ok(()));
            }
            let walk = steps[n];
            assert_eq!(walk.config.chip_rate, ChipRate(4_000));
            assert_eq!(walk.hold_ms, 8_000, "32 chips at 4 Hz");
            assert!(walk.config.running);
            assert_eq!(walk.config.led_count, leds);
            for l in 0..MAX_LEDS {
                let expected = if l < n { 1000 } else { 0 };
                assert_eq!(walk.config.brightness_permille[l], expected, "LED {l}");
            }
            assert_eq!(walk.config.validate(), Ok(()));
            assert_eq!(
                steps[n + 1],
                BlinkStep {
                    config: active,
                    hold_ms: 0
                }
            );
        }
    }

    #[test]
    fn the_walk_modulates_every_carrier() {
        // In the walk's 32 chips every LED is on in some chips and off in others; up to 4 LEDs
        // (a whole code period) no two LEDs share their pattern. Beyond 4 the higher carriers
        // can start alike, so the walk shows that they modulate and step 1 which is which.
        for leds in 1..=MAX_LEDS as u8 {
            let table = ChipTable::new(leds).unwrap();
            let chips = (WALK_CHIPS as usize).min(table.chips());
            let pattern = |led: u8| -> std::vec::Vec<bool> {
                table.masks()[..chips]
                    .iter()
                    .map(|m| m & (1 << led) != 0)
                    .collect()
            };
            for a in 0..leds {
                let p = pattern(a);
                assert!(
                    p.contains(&true) && p.contains(&false),
                    "N = {leds} LED {a}"
                );
                for b in a + 1..leds.min(4) {
                    assert_ne!(p, pattern(b), "N = {leds}: LEDs {a} and {b}");
                }
            }
        }
    }

    #[test]
    fn phases_are_kept() {
        let mut active = configured(3);
        active.phase_chips = [1, 2, 3, 0, 0, 0, 0, 0];
        for step in blink_sequence(&active) {
            assert_eq!(step.config.phase_chips, active.phase_chips);
        }
    }
}
