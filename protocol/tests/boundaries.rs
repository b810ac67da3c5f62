//! The edges of the contract: the largest frame a reader holds, a frame that carries nothing
//! but a valid CRC, the longest identify blink, LEDs beyond the table, and that the chip timer
//! picks the finest setting among equally good ones.

use protocol::carriers::{ChipTable, MAX_LEDS};
use protocol::config::ChipRate;
use protocol::framing::{
    FrameError, FrameEvent, MAX_COBS_LEN, MAX_FRAME_LEN, WireFrameReader, decode_request,
};
use protocol::luminaire::{BoardInfo, Luminaire, RestoredConfig};
use protocol::timing::{LedLevels, chip_timer_period, slot_compare, slot_pattern_period};
use protocol::wire::{CommandError, MAX_IDENTIFY_SECONDS, Request, Response};

#[test]
fn a_reader_holds_a_frame_of_max_cobs_len_bytes_and_no_more() {
    assert_eq!(MAX_COBS_LEN, MAX_FRAME_LEN - 1);
    for (len, fits) in [(MAX_COBS_LEN, true), (MAX_COBS_LEN + 1, false)] {
        let mut reader = WireFrameReader::default();
        let mut events = Vec::new();
        let mut bytes = vec![1u8; len];
        bytes.push(0);
        reader.feed(&bytes, |event| {
            events.push(match event {
                FrameEvent::Frame(frame) => Some(frame.len()),
                FrameEvent::TooLong => None,
            })
        });
        let expected = if fits { vec![Some(len)] } else { vec![None] };
        assert_eq!(events, expected, "{len} bytes");
    }
}

#[test]
fn a_valid_crc_over_nothing_is_a_malformed_frame() {
    // Decoded: just the CRC-32 of the empty payload (0x00000000, so COBS codes only).
    let mut raw = vec![0x01, 0x01, 0x01, 0x01, 0x01];
    assert_eq!(
        decode_request(&mut raw),
        Err(FrameError::Malformed { seq: None })
    );
    // Three bytes cannot even hold a CRC.
    let mut short = vec![0x04, 0xAA, 0xBB, 0xCC];
    assert_eq!(decode_request(&mut short), Err(FrameError::BadCrc));
}

#[test]
fn identify_accepts_the_longest_blink_and_refuses_one_second_more() {
    let mut luminaire = Luminaire::new(BoardInfo::new("0", "test"), RestoredConfig::Missing);
    let (ok, _) = luminaire.handle(1, &Request::Identify(MAX_IDENTIFY_SECONDS));
    assert_eq!(ok, Response::Identify(Ok(())));
    let (refused, effects) = luminaire.handle(2, &Request::Identify(MAX_IDENTIFY_SECONDS + 1));
    assert_eq!(
        refused,
        Response::Identify(Err(CommandError::InvalidArgument))
    );
    assert!(effects.is_empty());
}

#[test]
fn a_slot_beyond_the_table_plays_nothing_whatever_the_mask() {
    let table = ChipTable::new(2).unwrap();
    let brightness = LedLevels::new(&[1000; MAX_LEDS], &[500; MAX_LEDS]);
    assert_eq!(slot_compare(&table, &brightness, Some(1), 0xFF), 1000);
    assert_eq!(slot_compare(&table, &brightness, Some(1), 0), 500);
    assert_eq!(slot_compare(&table, &brightness, Some(2), 0xFF), 0);
    assert_eq!(slot_compare(&table, &brightness, Some(2), 0), 0);
    assert_eq!(slot_compare(&table, &brightness, None, 0xFF), 0);
    assert_eq!(slot_compare(&table, &brightness, None, 0), 0);
}

#[test]
fn a_led_on_two_slots_repeats_as_often_as_on_one() {
    let table = ChipTable::new(4).unwrap();
    for led in 0..4 {
        assert_eq!(
            slot_pattern_period(&table, &[Some(led), Some(led)]),
            slot_pattern_period(&table, &[Some(led)]),
            "LED {led}"
        );
    }
    assert!(slot_pattern_period(&table, &[Some(3)]) > 1);
}

#[test]
fn chip_rate_reads_back_in_millihertz() {
    assert_eq!(ChipRate(959_500).millihertz(), 959_500);
    assert_eq!(ChipRate::from_hz(959.5).millihertz(), 959_500);
}

/// Brute force over every prescaler: the chosen setting has the smallest rate error of all,
/// and among settings that tie, the smallest prescaler (the finest resolution).
#[test]
fn chip_timer_period_is_the_best_and_finest_setting() {
    const CLOCK: u32 = 96_000_000;
    for bits in [16u8, 32] {
        for millihertz in (1_000..=4_000_000)
            .step_by(7_919)
            .chain([1_000, 1_001, 3_333])
        {
            let chosen = chip_timer_period(CLOCK, millihertz, bits).unwrap();
            let exact = f64::from(CLOCK) * 1000.0 / f64::from(millihertz);
            let error = |ticks: u64| (ticks as f64 - exact).abs() / ticks as f64;
            let span = 1u64 << bits;
            let smallest = (exact as u64).div_ceil(span).max(1);
            let mut best: Option<(f64, u64)> = None;
            for divider in smallest..(smallest + 64).min(65_537) {
                let reload = ((exact / divider as f64).round() as u64).clamp(2, span);
                let e = error(divider * reload);
                if best.is_none_or(|(b, _)| e < b - 1e-15) {
                    best = Some((e, divider));
                }
            }
            let (best_error, best_divider) = best.unwrap();
            let chosen_error = error(chosen.ticks());
            assert!(
                chosen_error <= best_error + 1e-12,
                "{bits}-bit {millihertz} mHz: error {chosen_error} > {best_error}"
            );
            if (chosen_error - best_error).abs() < 1e-15 {
                assert!(
                    u64::from(chosen.prescaler) < best_divider,
                    "{bits}-bit {millihertz} mHz: prescaler {} for divider {best_divider}",
                    chosen.prescaler
                );
            }
        }
    }
}
