//! The LED outputs of the WeAct Black Pill luminaire: which timer channel plays which LED, and
//! the timer, DMA stream and trigger each PWM bank uses.
//!
//! | LED | pin  | timer channel | chip trigger → DMA                      |
//! |-----|------|---------------|-----------------------------------------|
//! | 1   | PA6  | TIM3 CH1      | TIM3_TRIG → DMA1 stream 4, channel 5    |
//! | 2   | PA7  | TIM3 CH2      |                                         |
//! | 3   | PB0  | TIM3 CH3      |                                         |
//! | 4   | PB1  | TIM3 CH4      |                                         |
//! | 5   | PA1  | TIM5 CH2      | TIM5_TRIG → DMA1 stream 1, channel 6    |
//! | 6   | PA2  | TIM5 CH3      |                                         |
//! | 7   | PA3  | TIM5 CH4      |                                         |
//! | 8   | PA0  | TIM5 CH1      | (PA0 is also the board's KEY button)    |
//!
//! Only timers whose *trigger* DMA request exists on the F411 can play chips without the CPU
//! (TIM1, TIM3, TIM5; RM0383 table 27, DMA1/DMA2 request mapping), which is why the second bank
//! is TIM5 and not TIM4 (TIM4 is also the embassy time driver). TIM5 CH1 has no pin but PA0, so
//! LED 8 shares the KEY button: with 7 LEDs or fewer (the default is 4) the plan holds LED 8's
//! compare value at 0, PA0 stays low and pressing KEY is harmless; see `firmware/README.md` for
//! the 8-LED wiring. [`LED_OUTPUTS`] is checked at compile time by [`pin_table_is_valid`].

use protocol::carriers::MAX_LEDS;

use crate::regs::{DmaStream, GpTimer, TIM3, TIM5};

/// Compare values per chip and bank (CCR1..CCR4).
pub const SLOTS: usize = 4;

/// The PWM timer bank an LED output belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Bank {
    /// TIM3 (16-bit), LEDs 1–4.
    Tim3,
    /// TIM5 (32-bit), LEDs 5–8.
    Tim5,
}

/// Both banks, in the order their DMA streams are programmed.
pub const BANKS: [Bank; 2] = [Bank::Tim3, Bank::Tim5];

/// LEDs 1–4 repeat within 32 chips whatever N and the phases
/// (`protocol::timing::slot_pattern_period`), so TIM3 needs 32 frames; TIM5 needs the full 512.
pub const TIM3_MAX_CHIPS: usize = 32;

impl Bank {
    /// The PWM timer.
    pub const fn timer(self) -> GpTimer {
        match self {
            Bank::Tim3 => TIM3,
            Bank::Tim5 => TIM5,
        }
    }

    /// The DMA1 stream serving the timer's trigger request (RM0383 table 27).
    pub const fn stream(self) -> DmaStream {
        match self {
            Bank::Tim3 => DmaStream { number: 4 },
            Bank::Tim5 => DmaStream { number: 1 },
        }
    }

    /// The request channel (SxCR.CHSEL) of TIM3_TRIG / TIM5_TRIG on that stream.
    pub const fn request_channel(self) -> u32 {
        match self {
            Bank::Tim3 => 5,
            Bank::Tim5 => 6,
        }
    }

    /// SMCR.TS of the internal trigger wired to TIM2's TRGO (RM0383 table 54, TIMx internal
    /// trigger connection): ITR1 for TIM3, ITR0 for TIM5.
    pub const fn tim2_trigger(self) -> u32 {
        match self {
            Bank::Tim3 => 1,
            Bank::Tim5 => 0,
        }
    }

    /// Bytes per compare value in the frame buffer and per DMA item. TIM5's registers are 32
    /// bits wide and the APB bridge copies a 16-bit write into both halves of a 32-bit register
    /// (RM0383 section 2.1, AHB/APB bridges), so TIM5 gets words; TIM3's compare registers are 16 bits.
    pub const fn item_bytes(self) -> u32 {
        match self {
            Bank::Tim3 => 2,
            Bank::Tim5 => 4,
        }
    }

    /// Largest number of chips in the bank's frame buffer.
    pub const fn max_chips(self) -> usize {
        match self {
            Bank::Tim3 => TIM3_MAX_CHIPS,
            Bank::Tim5 => protocol::carriers::MAX_CHIPS,
        }
    }

    /// Bytes of the bank's frame buffer.
    pub const fn frame_buffer_bytes(self) -> u32 {
        (self.max_chips() * SLOTS) as u32 * self.item_bytes()
    }
}

/// One row of the LED pin table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LedOutput {
    /// Timer bank.
    pub bank: Bank,
    /// Timer channel 1..=4.
    pub channel: u8,
    /// Port and pin, for documentation and logs.
    pub pin: &'static str,
    /// The pin's alternate function number for this timer channel (GPIOx_AFRL/AFRH; AF2 is
    /// TIM3–TIM5 on the F411). The firmware's pin driver selects it from the same table.
    pub af: u8,
}

/// LED i (0-based) is driven by `LED_OUTPUTS[i]`.
pub const LED_OUTPUTS: [LedOutput; MAX_LEDS] = [
    led(Bank::Tim3, 1, "PA6"),
    led(Bank::Tim3, 2, "PA7"),
    led(Bank::Tim3, 3, "PB0"),
    led(Bank::Tim3, 4, "PB1"),
    led(Bank::Tim5, 2, "PA1"),
    led(Bank::Tim5, 3, "PA2"),
    led(Bank::Tim5, 4, "PA3"),
    led(Bank::Tim5, 1, "PA0"),
];

const fn led(bank: Bank, channel: u8, pin: &'static str) -> LedOutput {
    LedOutput {
        bank,
        channel,
        pin,
        af: 2,
    }
}

/// Pins the LED table must never use: USB (PA11/PA12), SWD (PA13/PA14), the board LED (PC13),
/// both crystals (PC14/PC15, PH0/PH1) and BOOT1 (PB2).
pub const RESERVED_PINS: [&str; 10] = [
    "PA11", "PA12", "PA13", "PA14", "PC13", "PC14", "PC15", "PH0", "PH1", "PB2",
];

const fn str_eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

const fn same_bank(a: Bank, b: Bank) -> bool {
    matches!((a, b), (Bank::Tim3, Bank::Tim3) | (Bank::Tim5, Bank::Tim5))
}

/// Every channel is 1..=4, no two LEDs share a (bank, channel) or a pin, no pin is reserved.
pub const fn pin_table_is_valid(table: &[LedOutput]) -> bool {
    let mut i = 0;
    while i < table.len() {
        let a = table[i];
        if a.channel == 0 || a.channel > 4 {
            return false;
        }
        let mut r = 0;
        while r < RESERVED_PINS.len() {
            if str_eq(a.pin, RESERVED_PINS[r]) {
                return false;
            }
            r += 1;
        }
        let mut j = i + 1;
        while j < table.len() {
            let b = table[j];
            if (same_bank(a.bank, b.bank) && a.channel == b.channel) || str_eq(a.pin, b.pin) {
                return false;
            }
            j += 1;
        }
        i += 1;
    }
    true
}

const _: () = assert!(pin_table_is_valid(&LED_OUTPUTS), "LED pin table is invalid");
const _: () = assert!(
    !pin_table_is_valid(&[led(Bank::Tim3, 1, "PA6"), led(Bank::Tim3, 1, "PA7")]),
    "pin table check must reject a shared channel"
);
const _: () = assert!(
    !pin_table_is_valid(&[led(Bank::Tim5, 1, "PA11")]),
    "pin table check must reject the USB pins"
);

/// Whether [`LED_OUTPUTS`] puts `pin` on `bank`'s channel `channel` (for the board code's
/// compile-time check that it hands each timer channel the pin this table names).
pub const fn channel_pin_is(bank: Bank, channel: u8, pin: &str) -> bool {
    let mut i = 0;
    while i < LED_OUTPUTS.len() {
        let out = LED_OUTPUTS[i];
        if same_bank(out.bank, bank) && out.channel == channel {
            return str_eq(out.pin, pin);
        }
        i += 1;
    }
    false
}

/// For each channel slot (CCR1..CCR4) of `bank`, the 0-based LED it plays.
pub const fn slots_of(bank: Bank) -> [Option<u8>; SLOTS] {
    let mut slots = [None; SLOTS];
    let mut i = 0;
    while i < LED_OUTPUTS.len() {
        let out = LED_OUTPUTS[i];
        if same_bank(out.bank, bank) {
            slots[out.channel as usize - 1] = Some(i as u8);
        }
        i += 1;
    }
    slots
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_frame_buffers_hold_every_chip_of_each_bank() {
        // TIM3: 32 chips × 4 half-words; TIM5: 512 chips × 4 words.
        assert_eq!(Bank::Tim3.frame_buffer_bytes(), 256);
        assert_eq!(Bank::Tim5.frame_buffer_bytes(), 8192);
        assert_eq!(Bank::Tim3.max_chips(), 32);
        assert_eq!(Bank::Tim5.max_chips(), 512);
    }

    #[test]
    fn outputs_pin_table_check_rejects_each_kind_of_mistake() {
        assert!(pin_table_is_valid(&LED_OUTPUTS));
        let bad: [&[LedOutput]; 6] = [
            &[led(Bank::Tim3, 0, "PA6")],
            &[led(Bank::Tim3, 5, "PA6")],
            &[led(Bank::Tim3, 1, "PA6"), led(Bank::Tim3, 1, "PA7")],
            &[led(Bank::Tim3, 1, "PA6"), led(Bank::Tim5, 1, "PA6")],
            &[led(Bank::Tim5, 1, "PA13")],
            &[led(Bank::Tim3, 1, "PA6"), led(Bank::Tim3, 2, "PA6")],
        ];
        for table in bad {
            assert!(!pin_table_is_valid(table), "{table:?}");
        }
        // The same channel number on the two banks, and pins of equal length, are fine.
        assert!(pin_table_is_valid(&[
            led(Bank::Tim3, 1, "PA6"),
            led(Bank::Tim5, 1, "PA0")
        ]));
        assert!(str_eq("PA6", "PA6") && !str_eq("PA6", "PA7") && !str_eq("PA6", "PA60"));
    }

    #[test]
    fn outputs_trigger_inputs_are_wired_to_tim2() {
        // The register model's copy of RM0383's internal trigger table (the vendor metadata
        // does not describe the ITR connections).
        use crate::register_model::itr_source;
        use crate::register_model::timer::TimerId;
        for (bank, id) in [(Bank::Tim3, TimerId::Tim3), (Bank::Tim5, TimerId::Tim5)] {
            assert_eq!(
                itr_source(id, bank.tim2_trigger()),
                Some(TimerId::Tim2),
                "{bank:?}"
            );
        }
    }

    #[test]
    fn outputs_channel_pins() {
        assert!(channel_pin_is(Bank::Tim3, 1, "PA6"));
        assert!(channel_pin_is(Bank::Tim5, 1, "PA0"));
        assert!(!channel_pin_is(Bank::Tim5, 1, "PA1"));
        assert!(!channel_pin_is(Bank::Tim3, 5, "PA6"));
    }

    #[test]
    fn outputs_slots_follow_the_pin_table() {
        assert_eq!(slots_of(Bank::Tim3), [Some(0), Some(1), Some(2), Some(3)]);
        assert_eq!(slots_of(Bank::Tim5), [Some(7), Some(4), Some(5), Some(6)]);
        for bank in BANKS {
            assert_eq!(bank.timer(), if bank == Bank::Tim3 { TIM3 } else { TIM5 });
        }
        assert_eq!(Bank::Tim3.item_bytes(), 2);
        assert_eq!(Bank::Tim5.item_bytes(), 4);
    }
}
