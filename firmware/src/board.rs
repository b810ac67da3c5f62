//! The WeAct "Black Pill" STM32F411CEU6 as this firmware uses it: clock tree, flash map, board
//! name. The LED pin table, with each bank's timer, DMA stream and trigger, lives in
//! `chip_plan::outputs` so the host tests see the same table; the USB identity in `protocol::usb`
//! so the host's discovery sees the same IDs.
//!
//! Kept free: PA11/PA12 (USB OTG_FS), PA13/PA14 (SWD), PC13 (board LED, active low),
//! PC14/PC15 (32 kHz crystal), PH0/PH1 (25 MHz crystal), PB2 (BOOT1). Timers: TIM2 is the chip
//! clock, TIM3/TIM5 the PWM banks, TIM4 the embassy time driver.

use core::ops::Range;

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

/// Board name reported by `GetInfo`.
pub const BOARD_NAME: &str = "WeAct BlackPill STM32F411CEU6";
