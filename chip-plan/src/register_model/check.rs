//! Reads the model's output log back as "what each chip played" and compares it with the chip
//! table: during chip k (from its TIM2 update T_k to the next one), from one PWM period after
//! T_k on, bank slot s must play `brightness[led]` if the table's on-mask of chip k has that LED
//! on and its off level ⌈brightness·off_level/1000⌉ otherwise (0 for a slot without an LED of
//! the table), with the PWM at [`PWM_STEPS`] steps and nothing changing until T_{k+1}.
//! The one-PWM-period grace is the design's constant lag (the new compare values are preloaded
//! during the period the chip boundary restarted).
//!
//! The expected values come straight from [`ChipTable::masks`], the brightness and the off
//! level, not from the plan's frame-filling code or `protocol::timing`'s level arithmetic.

use protocol::carriers::{ChipTable, MAX_LEDS};
use protocol::timing::{LedLevels, PWM_STEPS};

use crate::outputs::{Bank, SLOTS, slots_of};

use super::LogEntry;
use super::timer::{BankOutputs, TimerId};

fn timer_of(bank: Bank) -> TimerId {
    match bank {
        Bank::Tim3 => TimerId::Tim3,
        Bank::Tim5 => TimerId::Tim5,
    }
}

/// Brightness and off level of each LED in per mille: what a configuration asks the PWM for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lights {
    /// On level per LED, per mille of full (the compare value on a 1000-step PWM).
    pub brightness: [u16; MAX_LEDS],
    /// Off level per LED, per mille of its on level.
    pub off_level: [u16; MAX_LEDS],
}

impl Lights {
    /// Full on/off keying at `brightness`.
    pub const fn full_depth(brightness: [u16; MAX_LEDS]) -> Self {
        Self {
            brightness,
            off_level: [0; MAX_LEDS],
        }
    }

    /// The levels the engine is given (`protocol::timing`'s arithmetic).
    pub const fn levels(&self) -> LedLevels {
        LedLevels::new(&self.brightness, &self.off_level)
    }

    /// Both arrays in reverse LED order.
    pub fn reversed(&self) -> Self {
        let mut out = *self;
        out.brightness.reverse();
        out.off_level.reverse();
        out
    }
}

/// The compare values bank `bank` must play during chip `chip` of `table`.
pub fn expected_levels(
    table: &ChipTable,
    lights: &Lights,
    bank: Bank,
    chip: usize,
) -> [Option<u32>; SLOTS] {
    let mask = table.masks()[chip % table.chips()];
    slots_of(bank).map(|led| {
        Some(match led {
            Some(led) if led < table.led_count() => {
                let on = u32::from(lights.brightness[usize::from(led)]);
                if mask & (1 << led) != 0 {
                    on
                } else {
                    (on * u32::from(lights.off_level[usize::from(led)])).div_ceil(1000)
                }
            }
            _ => 0,
        })
    })
}

/// The changes of one bank's outputs in time order.
fn changes(log: &[LogEntry], timer: TimerId) -> Vec<(u64, BankOutputs)> {
    log.iter()
        .filter_map(|entry| match *entry {
            LogEntry::Outputs {
                t,
                timer: id,
                outputs,
            } if id == timer => Some((t, outputs)),
            _ => None,
        })
        .collect()
}

/// The outputs in effect at time `t` (the last change at or before `t`).
fn in_effect(changes: &[(u64, BankOutputs)], t: u64) -> Option<BankOutputs> {
    let after = changes.partition_point(|&(at, _)| at <= t);
    after.checked_sub(1).map(|i| changes[i].1)
}

/// The outputs of `timer` in effect at time `t`.
pub fn outputs_at(log: &[LogEntry], timer: TimerId, t: u64) -> Option<BankOutputs> {
    in_effect(&changes(log, timer), t)
}

/// Chip boundaries (TIM2 update events) at or after `from`.
pub fn chip_boundaries(log: &[LogEntry], from: u64) -> Vec<u64> {
    log.iter()
        .filter_map(|entry| match *entry {
            LogEntry::ChipTimerUpdate { t } if t >= from => Some(t),
            _ => None,
        })
        .collect()
}

/// Checks chips 0..`chips` of a playback started at `from` against `table` and `lights`.
pub fn check_playback(
    log: &[LogEntry],
    from: u64,
    table: &ChipTable,
    lights: &Lights,
    chips: usize,
) -> Result<(), String> {
    let boundaries = chip_boundaries(log, from);
    if boundaries.len() < chips + 1 {
        return Err(format!(
            "only {} chip boundaries after t = {from}, {} needed",
            boundaries.len(),
            chips + 1
        ));
    }
    let settle = u64::from(PWM_STEPS);
    for bank in [Bank::Tim3, Bank::Tim5] {
        let timer = timer_of(bank);
        let changes = changes(log, timer);
        for chip in 0..chips {
            let (start, end) = (boundaries[chip], boundaries[chip + 1]);
            let expected = expected_levels(table, lights, bank, chip);
            let at = start + settle;
            let Some(outputs) = in_effect(&changes, at) else {
                return Err(format!("chip {chip}: {timer:?} never configured"));
            };
            let pwm_ok = outputs.running
                && outputs.prescaler == 0
                && outputs.auto_reload == u32::from(PWM_STEPS) - 1;
            if !pwm_ok || outputs.levels != expected {
                return Err(format!(
                    "chip {chip} of {} (t = {start}..{end}): {timer:?} plays {:?} (running {}, \
                     PSC {}, ARR {}), the table says {expected:?}",
                    table.chips(),
                    outputs.levels,
                    outputs.running,
                    outputs.prescaler,
                    outputs.auto_reload
                ));
            }
            let next_change = changes.partition_point(|&(t, _)| t <= at);
            if changes.get(next_change).is_some_and(|&(t, _)| t < end) {
                return Err(format!(
                    "chip {chip} (t = {start}..{end}): {timer:?} changed its outputs mid-chip"
                ));
            }
        }
    }
    Ok(())
}

/// Checks that every output of both banks is 0 (LED off) at `t`.
pub fn check_all_off(log: &[LogEntry], t: u64) -> Result<(), String> {
    for timer in [TimerId::Tim3, TimerId::Tim5] {
        let levels = outputs_at(log, timer, t).map(|o| o.levels);
        if levels != Some([Some(0); SLOTS]) {
            return Err(format!(
                "{timer:?} plays {levels:?} at t = {t}, expected all off"
            ));
        }
    }
    Ok(())
}
