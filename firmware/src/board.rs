//! The WeAct "Black Pill" STM32F411CEU6 as this firmware uses it: LED pin table, clock tree,
//! flash map and USB identity (issue 6).
//!
//! LED outputs (3.3 V push-pull PWM, ~96 kHz; drive a logic-level MOSFET or the PWM/enable input
//! of a constant-current driver per LED, never an LED directly):
//!
//! | LED | pin  | timer channel | DMA (chip trigger)    | note                                   |
//! |-----|------|---------------|-----------------------|----------------------------------------|
//! | 1   | PA6  | TIM3 CH1      | DMA1 stream 4, ch 5   |                                        |
//! | 2   | PA7  | TIM3 CH2      |                       |                                        |
//! | 3   | PB0  | TIM3 CH3      |                       |                                        |
//! | 4   | PB1  | TIM3 CH4      |                       |                                        |
//! | 5   | PA1  | TIM5 CH2      | DMA1 stream 1, ch 6   |                                        |
//! | 6   | PA2  | TIM5 CH3      |                       |                                        |
//! | 7   | PA3  | TIM5 CH4      |                       |                                        |
//! | 8   | PA0  | TIM5 CH1      |                       | shared with the KEY button (to GND)    |
//!
//! Kept free: PA11/PA12 (USB OTG_FS), PA13/PA14 (SWD), PC13 (board LED, active low),
//! PC14/PC15 (32 kHz crystal), PH0/PH1 (25 MHz crystal), PB2 (BOOT1). Timers: TIM2 is the chip
//! clock, TIM4 the embassy time driver. LED 8 sits on PA0 because TIM5 CH1 has no other pin;
//! do not press KEY while 8 LEDs are configured (it would short a driven-high output).
//!
//! Only timers whose *trigger* DMA request exists on the F411 can play chips without the CPU
//! (TIM1, TIM3, TIM5; RM0383 table 27), which is why the second bank is TIM5 and not TIM4.
//! [`LED_OUTPUTS`] is checked at compile time by [`pin_table_is_valid`].

use core::ops::Range;

use protocol::carriers::MAX_LEDS;

/// The PWM timer bank an LED output belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Bank {
    /// TIM3 (16-bit), LEDs 1–4.
    Tim3,
    /// TIM5 (32-bit), LEDs 5–8.
    Tim5,
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
    LedOutput { bank, channel, pin }
}

/// Pins the LED table must never use.
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
            let same_bank = matches!(
                (a.bank, b.bank),
                (Bank::Tim3, Bank::Tim3) | (Bank::Tim5, Bank::Tim5)
            );
            if (same_bank && a.channel == b.channel) || str_eq(a.pin, b.pin) {
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

/// For each channel slot (CCR1..CCR4) of `bank`, the 0-based LED it plays.
pub const fn slots_of(bank: Bank) -> [Option<u8>; 4] {
    let mut slots = [None; 4];
    let mut i = 0;
    while i < LED_OUTPUTS.len() {
        let out = LED_OUTPUTS[i];
        if matches!(
            (out.bank, bank),
            (Bank::Tim3, Bank::Tim3) | (Bank::Tim5, Bank::Tim5)
        ) {
            slots[out.channel as usize - 1] = Some(i as u8);
        }
        i += 1;
    }
    slots
}

/// Crystal on the Black Pill.
pub const HSE_HZ: u32 = 25_000_000;
/// SYSCLK = 25 MHz / 25 · 192 / 2.
pub const SYSCLK_HZ: u32 = 96_000_000;
const _: () = assert!(
    HSE_HZ / 25 * 192 / 2 == SYSCLK_HZ,
    "PLL settings and SYSCLK disagree"
);

/// Clock of TIM2–TIM5 (APB1 = 48 MHz, doubled for timers because the APB1 prescaler is 2).
pub const APB1_TIMER_HZ: u32 = 96_000_000;

/// The embassy clock configuration: HSE 25 MHz → PLL (M 25, N 192, P 2, Q 4) → 96 MHz SYSCLK and
/// 48 MHz USB; AHB 96 MHz, APB1 48 MHz (timers 96 MHz), APB2 96 MHz.
pub fn clock_config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::{
        AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv,
        PllSource, Sysclk,
    };
    use embassy_stm32::time::Hertz;

    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(HSE_HZ),
        mode: HseMode::Oscillator,
    });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV25,  // 1 MHz VCO input
        mul: PllMul::MUL192,       // 192 MHz VCO
        divp: Some(PllPDiv::DIV2), // 96 MHz SYSCLK
        divq: Some(PllQDiv::DIV4), // 48 MHz USB
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV2;
    config.rcc.apb2_pre = APBPrescaler::DIV1;
    config
}

/// Configuration flash area as offsets from the flash base: sectors 6–7 (see `memory.x`).
pub const CONFIG_FLASH: Range<u32> = 0x0004_0000..0x0008_0000;

/// USB vendor ID: the shared V-USB (obdev) CDC-ACM pair the host's port discovery expects
/// (`host/src/device/discovery.rs`); boards are told apart by [`USB_PRODUCT`].
pub const USB_VID: u16 = 0x16c0;
/// USB product ID of the shared V-USB CDC-ACM pair.
pub const USB_PID: u16 = 0x05e1;
/// USB manufacturer string (the shared-ID licence asks for the owner's domain or e-mail here).
pub const USB_MANUFACTURER: &str = "meb project";
/// USB product string; the host finds luminaires by it.
pub const USB_PRODUCT: &str = "meb luminaire";
/// Board name reported by `GetInfo`.
pub const BOARD_NAME: &str = "WeAct BlackPill STM32F411CEU6";
