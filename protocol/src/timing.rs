//! Timer arithmetic of the luminaire: the chip clock and the brightness PWM
//! (docs/maths/carriers.md#playing-the-table-on-a-luminaire).
//!
//! The firmware plays the on-mask table at the chip rate (chip rate = camera frame rate). The
//! chip period is an integer number of timer-clock ticks, `(PSC + 1) · (ARR + 1)`, so the rate a
//! board actually plays is `f_timer / ticks`; this module picks the prescaler and auto-reload that
//! come closest to a requested rate and reports the achieved rate and its error. The same pure
//! functions run in the firmware and in the host tests below, so the ppm figures in the tests are
//! the board's figures (given the crystal is exact).
//!
//! Why not a software ticker: `embassy_time` at a 1 MHz tick gives 960 Hz as 1042 µs, −320 ppm,
//! one chip slipped every 3.3 s, and every wake-up adds interrupt latency. A hardware timer whose
//! update event paces the chips has neither drift beyond the rounding below nor jitter.
//!
//! Brightness: each output is a PWM of [`PWM_STEPS`] steps at `f_timer / PWM_STEPS` (96 kHz from
//! a 96 MHz timer clock), far above any chip rate so that a chip contains ≥ 24 whole PWM periods.
//! [`fill_compare_frames`] turns a chip table and per-LED [`LedLevels`] (the on level from the
//! brightness, the off level a fraction of it) into the compare values the
//! PWM timers load at every chip.

use crate::carriers::{ChipTable, MAX_LEDS};

/// Steps of the brightness PWM: compare value 1000 = always on, 0 = always off.
pub const PWM_STEPS: u16 = 1000;

/// Prescaler candidates tried above the smallest one that fits (see [`chip_timer_period`]).
const PRESCALER_SEARCH: u32 = 64;

/// Why no timer setting exists for a request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TimingError {
    /// The requested rate is zero.
    ZeroRate,
    /// The timer clock is zero.
    ZeroClock,
    /// The counter width is not 1..=32 bits.
    CounterBits(u8),
    /// The period would need more than 65536 · 2^bits ticks.
    RateTooLow,
    /// The period would be shorter than two timer ticks.
    RateTooHigh,
    /// A compare-frame buffer does not hold `chips · slots` values.
    FrameBuffer {
        /// Values the table needs.
        needed: usize,
        /// Values the buffer holds.
        got: usize,
    },
}

impl core::fmt::Display for TimingError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::ZeroRate => f.write_str("chip rate is zero"),
            Self::ZeroClock => f.write_str("timer clock is zero"),
            Self::CounterBits(b) => write!(f, "counter width {b} bits is outside 1..=32"),
            Self::RateTooLow => f.write_str("chip rate too low for this timer"),
            Self::RateTooHigh => f.write_str("chip rate too high for this timer"),
            Self::FrameBuffer { needed, got } => {
                write!(f, "compare-frame buffer holds {got} values, needs {needed}")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for TimingError {}

/// Register values of one timer period: the counter runs `(prescaler + 1) · (auto_reload + 1)`
/// ticks of the timer clock between update events.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimerPeriod {
    /// TIMx_PSC: the clock is divided by `prescaler + 1`.
    pub prescaler: u16,
    /// TIMx_ARR: the counter wraps after `auto_reload + 1` prescaled ticks.
    pub auto_reload: u32,
}

impl TimerPeriod {
    /// Timer-clock ticks per period.
    pub const fn ticks(&self) -> u64 {
        (self.prescaler as u64 + 1) * (self.auto_reload as u64 + 1)
    }

    /// Achieved rate in microhertz for a timer clocked at `clock_hz`, rounded to nearest.
    pub const fn rate_microhertz(&self, clock_hz: u32) -> u64 {
        let ticks = self.ticks();
        (clock_hz as u64 * 1_000_000 + ticks / 2) / ticks
    }

    /// Error of the achieved rate against `requested_millihertz` in parts per billion
    /// (positive: the board plays faster than requested), rounded toward zero.
    pub const fn error_ppb(&self, clock_hz: u32, requested_millihertz: u32) -> i64 {
        if requested_millihertz == 0 {
            return 0;
        }
        // achieved / requested − 1 = (f·1000 − ticks·r) / (ticks·r), exact in i128.
        let ticks = self.ticks() as i128;
        let requested = requested_millihertz as i128;
        let numerator = clock_hz as i128 * 1000 - ticks * requested;
        (numerator * 1_000_000_000 / (ticks * requested)) as i64
    }
}

/// Rate error (in ppb) of `ticks` timer ticks per chip against `requested_millihertz`.
fn ticks_error_ppb(clock_hz: u32, ticks: u64, requested_millihertz: u32) -> u128 {
    let exact = clock_hz as u128 * 1000;
    let played = ticks as u128 * requested_millihertz as u128;
    exact.abs_diff(played) * 1_000_000_000 / played
}

/// Prescaler and auto-reload of a `counter_bits`-wide timer (16 or 32 on the STM32F4) clocked
/// at `clock_hz` whose update rate comes closest to `requested_millihertz`.
///
/// Starts at the smallest prescaler whose period fits the counter (the finest resolution) and
/// tries the next few prescalers too, keeping the first setting with the smallest error. With
/// the 32-bit TIM2 at 96 MHz the prescaler is always 0 and the error at most ±0.5 tick per chip
/// (±5 ppb at 1 Hz … ±12 ppm at 4 kHz); every integer rate that divides 96 MHz is exact.
pub fn chip_timer_period(
    clock_hz: u32,
    requested_millihertz: u32,
    counter_bits: u8,
) -> Result<TimerPeriod, TimingError> {
    if requested_millihertz == 0 {
        return Err(TimingError::ZeroRate);
    }
    if clock_hz == 0 {
        return Err(TimingError::ZeroClock);
    }
    if counter_bits == 0 || counter_bits > 32 {
        return Err(TimingError::CounterBits(counter_bits));
    }
    let counter_span = 1u64 << counter_bits;
    let numerator = u64::from(clock_hz) * 1000;
    let rate = u64::from(requested_millihertz);
    // Ideal ticks per chip = numerator / rate; the smallest divider whose rounded period fits.
    let ideal_floor = numerator / rate;
    if ideal_floor < 2 {
        return Err(TimingError::RateTooHigh);
    }
    let smallest_divider = ideal_floor.div_ceil(counter_span).max(1);
    let mut best: Option<(u128, TimerPeriod)> = None;
    let mut divider = smallest_divider;
    while divider <= 65_536 && divider < smallest_divider + u64::from(PRESCALER_SEARCH) {
        // Nearest reload count for this divider: round(numerator / (rate · divider)).
        let scaled = rate * divider;
        let reload_count = (numerator + scaled / 2) / scaled;
        if (2..=counter_span).contains(&reload_count) {
            let period = TimerPeriod {
                prescaler: (divider - 1) as u16,
                auto_reload: (reload_count - 1) as u32,
            };
            let error = ticks_error_ppb(clock_hz, period.ticks(), requested_millihertz);
            if best.is_none_or(|(best_error, _)| error < best_error) {
                best = Some((error, period));
            }
            if error == 0 {
                break;
            }
        }
        divider += 1;
    }
    best.map(|(_, period)| period)
        .ok_or(if smallest_divider > 65_536 {
            TimingError::RateTooLow
        } else {
            TimingError::RateTooHigh
        })
}

/// Brightness PWM period for a timer clocked at `clock_hz`: prescaler 0, [`PWM_STEPS`] steps.
pub fn brightness_pwm_period(clock_hz: u32) -> Result<TimerPeriod, TimingError> {
    if clock_hz == 0 {
        return Err(TimingError::ZeroClock);
    }
    Ok(TimerPeriod {
        prescaler: 0,
        auto_reload: u32::from(PWM_STEPS) - 1,
    })
}

/// Compare value for an LED at `brightness_permille` (clamped to 1000) on a [`PWM_STEPS`] PWM:
/// in PWM mode 1 the output is on while the counter is below it, so [`PWM_STEPS`] = always on.
pub const fn on_compare(brightness_permille: u16) -> u16 {
    let permille = if brightness_permille > 1000 {
        1000
    } else {
        brightness_permille
    };
    ((permille as u32 * PWM_STEPS as u32 + 500) / 1000) as u16
}

/// Compare value of an LED's off chips: `off_level_permille` (clamped to 1000) of its on
/// compare value `on`, rounded up so that the modulation depth played is never above the one
/// configured (docs/howto/flicker-safety.md).
pub const fn off_compare(on: u16, off_level_permille: u16) -> u16 {
    let level = if off_level_permille > 1000 {
        1000
    } else {
        off_level_permille
    };
    ((on as u32 * level as u32).div_ceil(1000)) as u16
}

/// On and off compare values of every LED: what the PWM plays during its on and off chips.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LedLevels {
    /// Compare value during an LED's on chips ([`on_compare`] of its brightness).
    pub on: [u16; MAX_LEDS],
    /// Compare value during its off chips ([`off_compare`] of its off level).
    pub off: [u16; MAX_LEDS],
}

impl LedLevels {
    /// Levels of per-LED brightness and off levels, both in per mille.
    pub const fn new(
        brightness_permille: &[u16; MAX_LEDS],
        off_level_permille: &[u16; MAX_LEDS],
    ) -> Self {
        let mut on = [0u16; MAX_LEDS];
        let mut off = [0u16; MAX_LEDS];
        let mut led = 0;
        while led < MAX_LEDS {
            on[led] = on_compare(brightness_permille[led]);
            off[led] = off_compare(on[led], off_level_permille[led]);
            led += 1;
        }
        Self { on, off }
    }

    /// Full on/off keying (off chips dark) at per-LED brightness.
    pub const fn full_depth(brightness_permille: &[u16; MAX_LEDS]) -> Self {
        Self::new(brightness_permille, &[0; MAX_LEDS])
    }
}

/// Bit mask of the table's LEDs among `led_of_slot` (LEDs beyond the table are ignored).
fn slot_led_mask(table: &ChipTable, led_of_slot: &[Option<u8>]) -> u8 {
    led_of_slot
        .iter()
        .flatten()
        .filter(|&&led| led < table.led_count())
        .fold(0, |mask, &led| mask | (1 << led))
}

/// Smallest number of chips after which the on/off pattern of the LEDs in `led_of_slot`
/// repeats: a power of two dividing the frame length. LED i's carrier has period 2^(i+2) chips
/// whatever its phase (it depends on bits 0 and i+1 of the chip index,
/// docs/maths/carriers.md#the-carrier-table), so LEDs 1–4
/// repeat within 32 chips even in a 512-chip frame, and a bank without LEDs has period 1.
pub fn slot_pattern_period(table: &ChipTable, led_of_slot: &[Option<u8>]) -> usize {
    let mask = slot_led_mask(table, led_of_slot);
    let masks = table.masks();
    let mut period = 1;
    while period < masks.len() {
        let repeats = masks
            .iter()
            .enumerate()
            .all(|(chip, &m)| m & mask == masks[chip % period] & mask);
        if repeats {
            return period;
        }
        period *= 2;
    }
    masks.len()
}

/// Writes the compare values a PWM timer loads at each chip: one frame of `led_of_slot.len()`
/// values per chip, for the first [`slot_pattern_period`] chips (played cyclically, they repeat
/// the whole table for these LEDs). Slot s carries LED `led_of_slot[s]`'s compare value: its
/// on level when on during that chip, its off level when off, 0 for `None` or an LED beyond
/// the table. Returns the number of values written (`period · slots`).
pub fn fill_compare_frames<W: From<u16> + Copy>(
    table: &ChipTable,
    levels: &LedLevels,
    led_of_slot: &[Option<u8>],
    out: &mut [W],
) -> Result<usize, TimingError> {
    let slots = led_of_slot.len();
    let needed = slot_pattern_period(table, led_of_slot) * slots;
    if out.len() < needed || slots == 0 {
        return Err(TimingError::FrameBuffer {
            needed,
            got: out.len(),
        });
    }
    for (frame, &mask) in out[..needed].chunks_exact_mut(slots).zip(table.masks()) {
        for (value, &led) in frame.iter_mut().zip(led_of_slot) {
            *value = W::from(slot_compare(table, levels, led, mask));
        }
    }
    Ok(needed)
}

/// Compare value of a slot playing LED `led` (`None`: no LED) during a chip with on-mask
/// `mask`: the LED's on level when it is on, its off level when it is off, 0 when the slot is
/// unused or its LED beyond the table.
pub fn slot_compare(table: &ChipTable, levels: &LedLevels, led: Option<u8>, mask: u8) -> u16 {
    match led {
        Some(led) if led < table.led_count() => {
            let led = usize::from(led);
            if mask & (1 << led) != 0 {
                levels.on[led]
            } else {
                levels.off[led]
            }
        }
        _ => 0,
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::println;

    use super::*;

    /// Timer clock of TIM2/TIM3/TIM5 on the Black Pill: APB1 = 48 MHz, ×2 for timers.
    const CLOCK: u32 = 96_000_000;

    fn ppm(period: &TimerPeriod, requested: u32) -> f64 {
        period.error_ppb(CLOCK, requested) as f64 / 1000.0
    }

    /// Independent check: achieved rate from the register values in floating point.
    fn achieved_hz(period: &TimerPeriod) -> f64 {
        f64::from(CLOCK)
            / ((f64::from(period.prescaler) + 1.0) * (f64::from(period.auto_reload) + 1.0))
    }

    #[test]
    fn integer_rates_on_the_32_bit_chip_timer_are_exact() {
        // (requested mHz, expected ARR + 1): 96 MHz / rate.
        for (mhz, reload) in [
            (960_000, 100_000u32),
            (1_000_000, 96_000),
            (240_000, 400_000),
            (30_000, 3_200_000),
        ] {
            let period = chip_timer_period(CLOCK, mhz, 32).unwrap();
            println!(
                "{:>9.3} Hz: PSC {} ARR {} -> {:.6} Hz, {:+.4} ppm",
                f64::from(mhz) / 1000.0,
                period.prescaler,
                period.auto_reload,
                period.rate_microhertz(CLOCK) as f64 / 1e6,
                ppm(&period, mhz)
            );
            assert_eq!(period.prescaler, 0);
            assert_eq!(period.auto_reload + 1, reload);
            assert_eq!(period.error_ppb(CLOCK, mhz), 0);
            assert_eq!(period.rate_microhertz(CLOCK), u64::from(mhz) * 1000);
        }
    }

    #[test]
    fn fractional_rate_rounds_to_the_nearest_tick() {
        // 96e9 / 959_500 = 100_052.11 ticks -> 100_052; the board plays 959.501 Hz.
        let period = chip_timer_period(CLOCK, 959_500, 32).unwrap();
        println!(
            "  959.500 Hz: PSC {} ARR {} -> {:.6} Hz, {:+.4} ppm",
            period.prescaler,
            period.auto_reload,
            period.rate_microhertz(CLOCK) as f64 / 1e6,
            ppm(&period, 959_500)
        );
        assert_eq!(period.ticks(), 100_052);
        let expected_ppm = (achieved_hz(&period) / 959.5 - 1.0) * 1e6;
        assert!((ppm(&period, 959_500) - expected_ppm).abs() < 0.001);
        assert!(ppm(&period, 959_500) > 0.0 && ppm(&period, 959_500) < 1.2);
        // Either neighbour is worse.
        for ticks in [100_051u32, 100_053] {
            let other = TimerPeriod {
                prescaler: 0,
                auto_reload: ticks - 1,
            };
            assert!(other.error_ppb(CLOCK, 959_500).abs() > period.error_ppb(CLOCK, 959_500));
        }
    }

    #[test]
    fn sixteen_bit_timer_needs_a_prescaler_and_stays_within_a_few_ppm() {
        for mhz in [
            960_000, 1_000_000, 240_000, 30_000, 959_500, 1_000, 4_000_000,
        ] {
            let period = chip_timer_period(CLOCK, mhz, 16).unwrap();
            assert!(period.auto_reload <= 0xFFFF);
            let expected_ppm = (achieved_hz(&period) / (f64::from(mhz) / 1000.0) - 1.0) * 1e6;
            assert!((ppm(&period, mhz) - expected_ppm).abs() < 0.001, "{mhz}");
            // Resolution bound: half a prescaled tick of the period.
            let bound = 0.5 * (f64::from(period.prescaler) + 1.0) / period.ticks() as f64 * 1e6;
            assert!(ppm(&period, mhz).abs() <= bound + 1e-3, "{mhz}: {period:?}");
        }
        // 30 Hz is 3.2 M ticks: 49 · 65_306.1 does not divide, but a nearby prescaler does.
        let period = chip_timer_period(CLOCK, 30_000, 16).unwrap();
        assert_eq!(period.error_ppb(CLOCK, 30_000), 0);
        assert_eq!(period.ticks(), 3_200_000);
    }

    #[test]
    fn a_microsecond_ticker_would_be_320_ppm_slow_at_960_hz() {
        // What the module docs warn about: 1 MHz tick, 960 Hz -> 1042 ticks.
        let period = chip_timer_period(1_000_000, 960_000, 32).unwrap();
        assert_eq!(period.ticks(), 1042);
        assert_eq!(period.error_ppb(1_000_000, 960_000) / 1000, -319);
    }

    #[test]
    fn impossible_requests_are_errors() {
        assert_eq!(chip_timer_period(CLOCK, 0, 32), Err(TimingError::ZeroRate));
        assert_eq!(
            chip_timer_period(0, 960_000, 32),
            Err(TimingError::ZeroClock)
        );
        assert_eq!(
            chip_timer_period(CLOCK, 960_000, 33),
            Err(TimingError::CounterBits(33))
        );
        // Faster than half the timer clock: 600 Hz from a 1 kHz clock.
        assert_eq!(
            chip_timer_period(1000, 600_000, 32),
            Err(TimingError::RateTooHigh)
        );
        // 1 mHz on a 16-bit timer needs 96e9 ticks > 65536².
        assert_eq!(
            chip_timer_period(CLOCK, 1, 16),
            Err(TimingError::RateTooLow)
        );
    }

    #[test]
    fn brightness_pwm_runs_at_96_khz_with_1000_steps() {
        let pwm = brightness_pwm_period(CLOCK).unwrap();
        assert_eq!(pwm.ticks(), 1000);
        assert_eq!(pwm.rate_microhertz(CLOCK), 96_000 * 1_000_000);
        assert_eq!(on_compare(1000), 1000);
        assert_eq!(on_compare(0), 0);
        assert_eq!(on_compare(500), 500);
        assert_eq!(on_compare(4000), 1000);
    }

    #[test]
    fn compare_frames_follow_the_chip_table() {
        // N = 2: s_0 = [1 -1 -1 1 1 -1 -1 1], s_1 = [1 -1 1 -1 -1 1 -1 1]
        // (docs/maths/carriers.md#worked-values).
        let table = ChipTable::new(2).unwrap();
        let mut brightness = [1000u16; MAX_LEDS];
        brightness[1] = 250;
        let brightness = LedLevels::full_depth(&brightness);
        // Slot 0 plays LED 1 (index 1), slot 1 LED 0, slot 2 nothing, slot 3 an LED beyond N.
        let slots = [Some(1), Some(0), None, Some(5)];
        let mut out = [0xFFFFu16; 8 * 4];
        let written = fill_compare_frames(&table, &brightness, &slots, &mut out).unwrap();
        // LED index 1 repeats every 8 chips: the whole N = 2 frame.
        assert_eq!(written, 32);
        let s0 = [1, -1, -1, 1, 1, -1, -1, 1];
        let s1 = [1, -1, 1, -1, -1, 1, -1, 1];
        for chip in 0..8 {
            let frame = &out[chip * 4..chip * 4 + 4];
            assert_eq!(frame[0], if s1[chip] > 0 { 250 } else { 0 }, "chip {chip}");
            assert_eq!(frame[1], if s0[chip] > 0 { 1000 } else { 0 }, "chip {chip}");
            assert_eq!(frame[2..], [0, 0]);
        }
        let mut wide = [0u32; 8 * 4];
        fill_compare_frames(&table, &brightness, &slots, &mut wide).unwrap();
        assert!(wide.iter().zip(out).all(|(&w, n)| w == u32::from(n)));
        let mut short = [0u16; 31];
        assert_eq!(slot_pattern_period(&table, &slots), 8);
        assert_eq!(
            fill_compare_frames(&table, &brightness, &slots, &mut short),
            Err(TimingError::FrameBuffer {
                needed: 32,
                got: 31
            })
        );
    }

    #[test]
    fn low_leds_repeat_within_32_chips_whatever_the_frame_length_and_phases() {
        let bank_a = [Some(0), Some(1), Some(2), Some(3)];
        let bank_b = [Some(7), Some(4), Some(5), Some(6)];
        for leds in 1..=MAX_LEDS as u8 {
            let n = crate::carriers::chips_per_frame(leds);
            // Phases: a spread of values below n for every LED.
            let mut phases = [0u16; MAX_LEDS];
            for (i, p) in phases.iter_mut().enumerate() {
                *p = ((i * 37 + 11) % n) as u16;
            }
            for table in [
                ChipTable::new(leds).unwrap(),
                ChipTable::with_phases(leds, &phases).unwrap(),
            ] {
                let period_a = slot_pattern_period(&table, &bank_a);
                assert!(period_a <= 32 && period_a <= n, "N = {leds}: {period_a}");
                assert_eq!(period_a, n.min(32), "N = {leds}");
                let period_b = slot_pattern_period(&table, &bank_b);
                let expected_b = if leds <= 4 { 1 } else { n };
                assert_eq!(period_b, expected_b, "N = {leds}");
                // Played cyclically, the short frames reproduce every chip of the table.
                let brightness = LedLevels::full_depth(&[1000u16; MAX_LEDS]);
                let mut frames = [0u16; 32 * 4];
                let written = fill_compare_frames(&table, &brightness, &bank_a, &mut frames);
                assert_eq!(written, Ok(period_a * 4));
                for (chip, &mask) in table.masks().iter().enumerate() {
                    let frame = &frames[(chip % period_a) * 4..][..4];
                    for (slot, led) in bank_a.iter().flatten().enumerate() {
                        let on = *led < leds && mask & (1 << led) != 0;
                        assert_eq!(frame[slot] == 1000, on, "N = {leds} chip {chip}");
                    }
                }
            }
        }
    }

    #[test]
    fn off_chips_play_their_fraction_of_the_on_level() {
        let table = ChipTable::new(2).unwrap();
        let mut brightness = [1000u16; MAX_LEDS];
        brightness[1] = 250;
        // LED 2 off at 90 % of 250 (225), LED 1 at 88.7 % of 1000; a slot beyond N stays 0.
        let mut off = [0u16; MAX_LEDS];
        off[0] = 887;
        off[1] = 900;
        off[5] = 500;
        let levels = LedLevels::new(&brightness, &off);
        let slots = [Some(1), Some(0), None, Some(5)];
        let mut out = [0u16; 8 * 4];
        fill_compare_frames(&table, &levels, &slots, &mut out).unwrap();
        let s0 = [1, -1, -1, 1, 1, -1, -1, 1];
        let s1 = [1, -1, 1, -1, -1, 1, -1, 1];
        for chip in 0..8 {
            let frame = &out[chip * 4..chip * 4 + 4];
            assert_eq!(
                frame[0],
                if s1[chip] > 0 { 250 } else { 225 },
                "chip {chip}"
            );
            assert_eq!(
                frame[1],
                if s0[chip] > 0 { 1000 } else { 887 },
                "chip {chip}"
            );
            assert_eq!(frame[2..], [0, 0]);
        }
        // Rounded up: 1 per mille of 7 is 0.007 of a step, played as 1 step.
        assert_eq!(off_compare(7, 1), 1);
        assert_eq!(off_compare(7, 0), 0);
        assert_eq!(off_compare(1000, 1000), 1000);
        assert_eq!(off_compare(1000, 2000), 1000);
    }
}
