//! meb luminaire firmware for the WeAct Black Pill (STM32F411CEU6), issue 6.
//!
//! One task per job: `main` owns the chip engine and serves the USB link; `usb_device` runs the
//! USB stack; `config_saver` writes configurations to flash; `identify_blinker` blinks PC13.
//! Boot: clocks → outputs off → restore the stored configuration (defaults if missing or
//! corrupt) → play it → USB. See `board` for the pin table and `chips` for the carrier engine.
#![no_std]
#![no_main]

mod board;
mod chips;
mod identify;
mod link;
mod storage;
mod usb;

use defmt::{info, warn};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::flash::{self, Flash};
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::{bind_interrupts, peripherals};
use panic_probe as _;
use protocol::luminaire::{BoardInfo, Luminaire};
use protocol::wire::CommandError;

use crate::identify::{BoardLed, IDENTIFY};
use crate::storage::ConfigStore;

bind_interrupts!(struct Irqs {
    OTG_FS => embassy_stm32::usb::InterruptHandler<peripherals::USB_OTG_FS>;
    FLASH => flash::InterruptHandler;
});

#[embassy_executor::task]
async fn usb_device(mut device: embassy_usb::UsbDevice<'static, usb::UsbDriver>) -> ! {
    device.run().await
}

#[embassy_executor::task]
async fn config_saver(mut store: ConfigStore) -> ! {
    loop {
        let config = link::SAVE.wait().await;
        let result = store.save(&config).await;
        match result {
            Ok(()) => info!("config saved"),
            Err(e) => warn!("config save failed: {}", e),
        }
        link::with_luminaire(|l| l.notify_saved(result.map_err(|_| CommandError::StorageFailed)));
    }
}

#[embassy_executor::task]
async fn identify_blinker(mut led: BoardLed<'static>) -> ! {
    let mut next = None;
    loop {
        let seconds = match next.take() {
            Some(seconds) => seconds,
            None => IDENTIFY.wait().await,
        };
        next = identify::blink(&mut led, seconds).await;
        if next.is_none() {
            link::with_luminaire(|l| l.notify_identify_finished());
            info!("identify finished");
        }
    }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(board::clock_config());
    info!(
        "meb luminaire {} on {}, serial {}",
        env!("CARGO_PKG_VERSION"),
        board::BOARD_NAME,
        embassy_stm32::uid::uid_hex()
    );
    let mut engine = chips::ChipEngine::new(
        p.TIM2,
        p.TIM3,
        p.TIM5,
        (p.DMA1_CH4, p.DMA1_CH1),
        chips::LedPins {
            pa6: p.PA6,
            pa7: p.PA7,
            pb0: p.PB0,
            pb1: p.PB1,
            pa1: p.PA1,
            pa2: p.PA2,
            pa3: p.PA3,
            pa0: p.PA0,
        },
    );
    if engine.chip_clock_hz() == board::APB1_TIMER_HZ {
        info!("chip timer clock {} Hz", engine.chip_clock_hz());
    } else {
        warn!(
            "chip timer clock {} Hz, expected {} Hz: check the clock tree",
            engine.chip_clock_hz(),
            board::APB1_TIMER_HZ
        );
    }

    let mut store = ConfigStore::new(Flash::new(p.FLASH, Irqs));
    let restored = store.restore().await;
    info!("stored config: {}", restored);
    let luminaire = Luminaire::new(
        BoardInfo::new(env!("CARGO_PKG_VERSION"), board::BOARD_NAME),
        restored,
    );
    link::apply(&mut engine, &luminaire.startup_effects());
    link::install(luminaire);

    let led = BoardLed::new(Output::new(p.PC13, Level::High, Speed::Low));
    let (device, mut serial) = usb::build(p.USB_OTG_FS, Irqs, p.PA12, p.PA11);
    spawner.spawn(usb_device(device).expect("usb task slot"));
    spawner.spawn(config_saver(store).expect("saver task slot"));
    spawner.spawn(identify_blinker(led).expect("identify task slot"));

    loop {
        serial.wait_connection().await;
        info!("USB connected");
        let link::Disconnected = link::serve(&mut serial, &mut engine).await;
        link::reset_reader();
        info!(
            "USB disconnected; carriers {}",
            if engine.is_running() {
                "playing"
            } else {
                "stopped"
            }
        );
    }
}
