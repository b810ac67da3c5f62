//! Where room-light flicker falls among the carriers' lines in the camera's frames.
//!
//! A lamp on mains of frequency f_m flickers at 2·f_m and its harmonics h·2·f_m (100 Hz for
//! 50 Hz mains, 120 Hz for 60 Hz; f_m within ±0.5 % of nominal). A camera at `fps` frames per
//! second sees harmonic h at ν_h = h·2·f_m/fps cycles per frame, folded into [0, ½]. LED i's
//! carrier, period P_i = 2^(i+2) chips, has lines at odd multiples m/P_i cycles per chip, seen at
//! ρ·m/P_i cycles per frame (ρ = chip rate / fps), each attenuated by the box integration
//! over a chip, |c_m| = |DFT_m|/P_i·|sinc(m/P_i)| (as in [`crate::flicker`]). A decoding window of
//! F frames resolves two tones 1/F cycles per frame apart; a flicker harmonic closer than
//! [`CLASH_BINS`] bins to one of a carrier's [`CARRIER_LINES`] strongest lines cannot be told
//! from that carrier, so the decoder cannot project it out without losing the carrier's line
//! (the LED's gain then rests on its other lines) and a flicker it does not project out biases
//! that LED's gain. [`clashes`] lists those coincidences for a chip rate; [`clear_chip_rates`]
//! lists chip rates near the camera's rate that have none.

use protocol::carriers::ChipTable;
use serde::Serialize;

/// Nominal flicker fundamentals, Hz: twice the 50 and 60 Hz mains.
pub const FLICKER_FAMILIES_HZ: [f64; 2] = [100.0, 120.0];
/// Largest relative offset of the mains frequency from nominal.
pub const MAINS_TOLERANCE: f64 = 0.005;
/// Flicker harmonics considered: the fundamental and the second, the strong ones of every
/// common lamp (a rectified sine's third is 8.6 % of its fundamental).
pub const FLICKER_HARMONICS: usize = 2;
/// Strongest lines of each carrier considered (in conjugate pairs: lines m and P − m fold onto
/// one frequency at a chip rate equal to the frame rate).
pub const CARRIER_LINES: usize = 4;
/// A flicker harmonic closer than this many frequency bins (1/F) to a carrier line clashes.
pub const CLASH_BINS: f64 = 1.0;

/// A flicker harmonic that falls on a carrier's line.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Clash {
    /// Nominal flicker fundamental of the family, Hz.
    pub family_hz: f64,
    /// Flicker harmonic h (frequency h × family).
    pub harmonic: usize,
    /// LED (1-based) whose carrier line it meets.
    pub led: usize,
    /// Where the harmonic lands, cycles per frame (nominal mains).
    pub flicker_cycles_per_frame: f64,
    /// Where the carrier's line lands, cycles per frame.
    pub line_cycles_per_frame: f64,
    /// Closest approach over the mains tolerance, frequency bins of the window.
    pub distance_bins: f64,
}

/// The flicker harmonics that clash with a carrier line for `leds` LEDs at `chip_rate_hz`, a
/// camera at `fps` and decoding windows of `window_frames` frames (module docs).
pub fn clashes(leds: u8, chip_rate_hz: f64, fps: f64, window_frames: usize) -> Vec<Clash> {
    let Ok(table) = ChipTable::new(leds) else {
        return Vec::new();
    };
    if !(chip_rate_hz > 0.0 && fps > 0.0 && window_frames > 0) {
        return Vec::new();
    }
    let rate = chip_rate_hz / fps;
    let bin = 1.0 / window_frames as f64;
    let mut found = Vec::new();
    for led in 0..usize::from(leds) {
        for line in strongest_lines(&table, led) {
            let at = fold(rate * line);
            for family in FLICKER_FAMILIES_HZ {
                for h in 1..=FLICKER_HARMONICS {
                    let nominal = h as f64 * family / fps;
                    let reach = nominal * MAINS_TOLERANCE;
                    let distance = (-4..=4)
                        .map(|k| fold(nominal + reach * f64::from(k) / 4.0))
                        .map(|nu| (nu - at).abs())
                        .fold(f64::INFINITY, f64::min);
                    // Lines m and P − m of one carrier land on one frequency: listed once.
                    let listed = found.iter().any(|c: &Clash| {
                        c.family_hz == family
                            && c.harmonic == h
                            && c.led == led + 1
                            && (c.line_cycles_per_frame - at).abs() < 1e-12
                    });
                    if distance < CLASH_BINS * bin && !listed {
                        found.push(Clash {
                            family_hz: family,
                            harmonic: h,
                            led: led + 1,
                            flicker_cycles_per_frame: fold(nominal),
                            line_cycles_per_frame: at,
                            distance_bins: distance / bin,
                        });
                    }
                }
            }
        }
    }
    found
}

/// Chip rates within `max_mismatch` of `fps` (steps of 0.25 %) at which no flicker harmonic
/// clashes with a carrier line, nearest to `fps` first, at most `count`.
pub fn clear_chip_rates(
    leds: u8,
    fps: f64,
    window_frames: usize,
    max_mismatch: f64,
    count: usize,
) -> Vec<f64> {
    let steps = (max_mismatch / 0.0025).floor() as i64;
    let mut order: Vec<i64> = (-steps..=steps).collect();
    order.sort_by_key(|k| (k.abs(), *k));
    order
        .into_iter()
        .map(|k| fps * (1.0 + 0.0025 * k as f64))
        .filter(|&rate| clashes(leds, rate, fps, window_frames).is_empty())
        .take(count)
        .collect()
}

/// The [`CARRIER_LINES`] strongest lines of LED `led`'s carrier, cycles per chip.
fn strongest_lines(table: &ChipTable, led: usize) -> Vec<f64> {
    let period = 1usize << (led + 2);
    let chips: Vec<f64> = (0..period)
        .map(|m| {
            let on = table.masks()[m % table.chips()] & (1 << led) != 0;
            if on { 1.0 } else { -1.0 }
        })
        .collect();
    let mut lines: Vec<(f64, f64)> = (1..period)
        .step_by(2)
        .map(|m| {
            let (mut re, mut im) = (0.0, 0.0);
            for (k, s) in chips.iter().enumerate() {
                let angle = -std::f64::consts::TAU * (m * k) as f64 / period as f64;
                re += s * angle.cos();
                im += s * angle.sin();
            }
            let x = std::f64::consts::PI * m as f64 / period as f64;
            let strength = (re * re + im * im).sqrt() / period as f64 * (x.sin() / x).abs();
            (strength, m as f64 / period as f64)
        })
        .collect();
    lines.sort_by(|a, b| b.0.total_cmp(&a.0));
    lines
        .into_iter()
        .take(CARRIER_LINES)
        .map(|(_, f)| f)
        .collect()
}

/// A frequency folded into [0, ½] cycles per frame.
fn fold(nu: f64) -> f64 {
    let x = nu.rem_euclid(1.0);
    if x > 0.5 { 1.0 - x } else { x }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixty_hz_mains_at_960_fps_falls_on_carrier_lines() {
        // 120 Hz at 960 fps is 1/8 cycle per frame: LED 2's fundamental (period 8 chips).
        let found = clashes(4, 960.0, 960.0, 128);
        assert!(
            found
                .iter()
                .any(|c| c.family_hz == 120.0 && c.harmonic == 1),
            "{found:?}"
        );
        let lines = |c: &Clash| (c.family_hz.to_bits(), c.harmonic, c.led);
        let mut unique: Vec<_> = found.iter().map(lines).collect();
        unique.dedup();
        assert_eq!(unique.len(), found.len(), "a clash listed twice: {found:?}");
        // With four carriers' lines every chip rate within 6 % of the frame rate meets one of
        // the families; with one LED there are clear rates, and each is clear.
        assert!(clear_chip_rates(4, 960.0, 128, 0.06, 3).is_empty());
        let clear = clear_chip_rates(1, 960.0, 128, 0.06, 3);
        assert_eq!(clear.len(), 3);
        for rate in clear {
            assert!(clashes(1, rate, 960.0, 128).is_empty(), "{rate}");
            assert!((rate / 960.0 - 1.0).abs() <= 0.06 + 1e-9);
        }
    }
}
