//! Manchester-encoded binary FDMA carriers (MEB-FDMA), docs/maths/carriers.md#the-carrier-table.
//!
//! For N LEDs (i = 0..N-1, LED 1 of the thesis is i = 0) a frame has n = 2^(N+1) chips:
//!
//! ```text
//! base square wave  b_i[m] = -(-1)^floor(m / 2^i)          m = 0 .. 2^N - 1
//! Manchester        s_i[2m] = -b_i[m],  s_i[2m+1] = +b_i[m]
//! ```
//!
//! s_i\[j\] = +1 means LED i is on during chip j. Written with the bits of the chip index j,
//! LED i is on exactly when bit 0 of j equals bit i+1 of j: for an even chip (bit 0 = 0) the
//! Manchester half is -b, which is +1 when floor(m/2^i) is even, i.e. bit i+1 of j is 0; for an
//! odd chip it is +b, +1 when bit i+1 is 1. Every row has 50 % duty, no run longer than two
//! chips, and is orthogonal to every cyclic shift of every other row (thesis Eq. 3.17), which is
//! what lets the luminaires run without any synchronisation.

/// Largest number of LEDs a carrier table supports.
pub const MAX_LEDS: usize = 8;
/// Largest frame length in chips (N = 8: 2^9).
pub const MAX_CHIPS: usize = 1 << (MAX_LEDS + 1);

/// Error building a carrier table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CarrierError {
    /// The LED count is outside 1..=8.
    LedCount(u8),
    /// The LED index is not below the table's LED count.
    LedIndex(u8),
}

impl core::fmt::Display for CarrierError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::LedCount(n) => write!(f, "LED count {n} is outside 1..={MAX_LEDS}"),
            Self::LedIndex(i) => write!(f, "LED index {i} is outside the table"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for CarrierError {}

/// Frame length n = 2^(N+1) in chips for `led_count` LEDs
/// (docs/maths/carriers.md#the-carrier-table).
pub const fn chips_per_frame(led_count: u8) -> usize {
    1 << (led_count as usize + 1)
}

/// Whether LED `led` (0-based) is on during chip `chip` of any table with more than `led` LEDs.
///
/// The carrier of LED i does not depend on the LED count N except through the frame
/// length: rows of the N-LED table are the first 2^(N+1) chips of the same sequence.
pub const fn chip_is_on(led: usize, chip: usize) -> bool {
    (chip & 1) == ((chip >> (led + 1)) & 1)
}

/// A complete carrier table: one on-mask per chip, bit i = LED i+1 on.
///
/// Fixed capacity ([`MAX_CHIPS`] bytes), built without allocation, usable in `const` context.
#[derive(Clone, PartialEq, Eq)]
pub struct ChipTable {
    led_count: u8,
    masks: [u8; MAX_CHIPS],
}

impl core::fmt::Debug for ChipTable {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ChipTable")
            .field("led_count", &self.led_count)
            .field("masks", &self.masks())
            .finish()
    }
}

impl ChipTable {
    /// Builds the table for `led_count` LEDs (1..=8), all phase offsets zero.
    pub const fn new(led_count: u8) -> Result<Self, CarrierError> {
        Self::with_phases(led_count, &[0; MAX_LEDS])
    }

    /// Builds the table with LED i's carrier delayed by `phases[i]` chips (cyclically):
    /// LED i is on during chip j when s_i[(j - phase_i) mod n] = +1.
    pub const fn with_phases(
        led_count: u8,
        phases: &[u16; MAX_LEDS],
    ) -> Result<Self, CarrierError> {
        if led_count == 0 || led_count as usize > MAX_LEDS {
            return Err(CarrierError::LedCount(led_count));
        }
        let n = chips_per_frame(led_count);
        let mut masks = [0u8; MAX_CHIPS];
        let mut chip = 0;
        while chip < n {
            let mut led = 0;
            let mut mask = 0u8;
            while led < led_count as usize {
                let shift = phases[led] as usize % n;
                let source = (chip + n - shift) % n;
                if chip_is_on(led, source) {
                    mask |= 1 << led;
                }
                led += 1;
            }
            masks[chip] = mask;
            chip += 1;
        }
        Ok(Self { led_count, masks })
    }

    /// Number of LEDs N.
    pub const fn led_count(&self) -> u8 {
        self.led_count
    }

    /// Frame length n = 2^(N+1) chips.
    pub const fn chips(&self) -> usize {
        chips_per_frame(self.led_count)
    }

    /// On-mask of every chip in frame order, bit i = LED i+1 on.
    pub fn masks(&self) -> &[u8] {
        &self.masks[..self.chips()]
    }

    /// Writes LED `led`'s carrier as ±1 values (+1 = on) into `row`, which must hold
    /// [`Self::chips`] values; returns the written prefix.
    pub fn row_into<'a>(&self, led: u8, row: &'a mut [i8]) -> Result<&'a [i8], CarrierError> {
        if led >= self.led_count || row.len() < self.chips() {
            return Err(CarrierError::LedIndex(led));
        }
        for (value, mask) in row.iter_mut().zip(self.masks()) {
            *value = if mask & (1 << led) != 0 { 1 } else { -1 };
        }
        Ok(&row[..self.chips()])
    }

    /// CRC-32 (ISO-HDLC) of the LED count followed by the on-masks: a fingerprint of the
    /// table a luminaire is playing, reported by `GetInfo`.
    pub fn fingerprint(&self) -> u32 {
        let mut digest = crate::checksum::CRC32.digest();
        digest.update(&[self.led_count]);
        digest.update(self.masks());
        digest.finalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(table: &ChipTable, led: u8) -> [i8; MAX_CHIPS] {
        let mut buf = [0i8; MAX_CHIPS];
        table.row_into(led, &mut buf).unwrap();
        buf
    }

    #[test]
    fn two_led_rows_match_spec() {
        let table = ChipTable::new(2).unwrap();
        assert_eq!(&row(&table, 0)[..8], &[1, -1, -1, 1, 1, -1, -1, 1]);
        assert_eq!(&row(&table, 1)[..8], &[1, -1, 1, -1, -1, 1, -1, 1]);
    }

    #[test]
    fn four_led_masks_match_spec() {
        const TABLE: ChipTable = match ChipTable::new(4) {
            Ok(t) => t,
            Err(_) => panic!("4 LEDs is valid"),
        };
        let expected: [u8; 32] = [
            15, 0, 14, 1, 13, 2, 12, 3, 11, 4, 10, 5, 9, 6, 8, 7, 7, 8, 6, 9, 5, 10, 4, 11, 3, 12,
            2, 13, 1, 14, 0, 15,
        ];
        assert_eq!(TABLE.masks(), &expected);
    }

    #[test]
    fn rejects_bad_led_counts() {
        assert_eq!(ChipTable::new(0), Err(CarrierError::LedCount(0)));
        assert_eq!(ChipTable::new(9), Err(CarrierError::LedCount(9)));
        let table = ChipTable::new(3).unwrap();
        let mut short = [0i8; 4];
        assert_eq!(
            table.row_into(0, &mut short),
            Err(CarrierError::LedIndex(0))
        );
        let mut buf = [0i8; 16];
        assert_eq!(table.row_into(3, &mut buf), Err(CarrierError::LedIndex(3)));
    }

    /// Thesis Eq. 3.17: Σ_j s_a[j] · s_b[(j + k) mod n] = 0 for a ≠ b and every shift k.
    #[test]
    fn phase_invariant_orthogonality_for_every_pair_and_shift() {
        for leds in 1..=MAX_LEDS as u8 {
            let table = ChipTable::new(leds).unwrap();
            let n = table.chips();
            for a in 0..leds {
                let ra = row(&table, a);
                for b in 0..leds {
                    if a == b {
                        continue;
                    }
                    let rb = row(&table, b);
                    for shift in 0..n {
                        let dot: i32 = (0..n)
                            .map(|j| i32::from(ra[j]) * i32::from(rb[(j + shift) % n]))
                            .sum();
                        assert_eq!(dot, 0, "N={leds} LEDs {a},{b} shift {shift}");
                    }
                }
            }
        }
    }

    #[test]
    fn half_duty_and_short_runs() {
        for leds in 1..=MAX_LEDS as u8 {
            let table = ChipTable::new(leds).unwrap();
            let n = table.chips();
            for led in 0..leds {
                let r = row(&table, led);
                let on = r[..n].iter().filter(|&&v| v == 1).count();
                assert_eq!(on * 2, n, "N={leds} LED {led} duty");
                // Runs are checked cyclically: the table is played in a loop.
                for start in 0..n {
                    let run = (0..3).all(|k| r[(start + k) % n] == r[start]);
                    assert!(!run, "N={leds} LED {led}: run of 3 at chip {start}");
                }
            }
        }
    }

    #[test]
    fn phase_offset_delays_the_carrier() {
        let mut phases = [0u16; MAX_LEDS];
        phases[1] = 5;
        let base = ChipTable::new(4).unwrap();
        let shifted = ChipTable::with_phases(4, &phases).unwrap();
        let n = base.chips();
        for chip in 0..n {
            let src = (chip + n - 5) % n;
            assert_eq!(shifted.masks()[chip] & 2, base.masks()[src] & 2);
            assert_eq!(shifted.masks()[chip] & !2, base.masks()[chip] & !2);
        }
        assert_ne!(base.fingerprint(), shifted.fingerprint());
    }
}
