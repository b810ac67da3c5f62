//! meb luminaire firmware for the WeAct Black Pill (STM32F411CEU6).
//!
//! One task per job: `main` serves the USB link; `usb_device` runs the USB stack;
//! `config_saver` writes configurations to flash; `identify_blinker` blinks PC13;
//! `carrier_watch` polls the chip engine for DMA faults; `watchdog_feeder` feeds the IWDG.
//! Boot: clocks → outputs off → watchdog → restore the stored configuration (defaults if missing
//! or corrupt) → play it → USB. See `chips` for the carrier engine (its register plans come from
//! the `chip_plan` crate) and `board` for the clock tree and flash map.
#![no_std]
#![no_main]

mod board;
mod chips;
mod identify;
mod link;
mod storage;
mod usb;

use chip_plan::plan::WATCHDOG_FEED_MS;
use defmt::{info, warn};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::flash::{self, Flash};
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::{bind_interrupts, peripherals};
use embassy_time::{Duration, Ticker};
use panic_probe as _;
use protocol::luminaire::{BoardInfo, Luminaire};
use protocol::wire::CommandError;

use crate::chips::{ChipHardware, LedPins, Watchdog};
use crate::identify::{BoardLed, IDENTIFY};
use crate::storage::ConfigStore;

bind_interrupts!(struct Irqs {
    OTG_FS => embassy_stm32::usb::InterruptHandler<peripherals::USB_OTG_FS>;
    FLASH => flash::InterruptHandler;
});

/// How often `carrier_watch` checks the DMA streams.
const FAULT_POLL: Duration = Duration::from_millis(100);

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

/// A DMA transfer error stops the carriers silently in hardware: notice it, switch the outputs
/// off cleanly and report it in `GetStatus`.
#[embassy_executor::task]
async fn carrier_watch() -> ! {
    let mut ticker = Ticker::every(FAULT_POLL);
    loop {
        ticker.next().await;
        if let Some(fault) = chips::poll_fault() {
            warn!("carriers stopped: {}", fault);
            link::with_luminaire(|l| l.notify_output_fault(fault));
        }
    }
}

/// Fed from the executor: a wedged task, a stuck interrupt or a panic stops the feeding and the
/// IWDG resets the board (USB comes back without a power cycle).
#[embassy_executor::task]
async fn watchdog_feeder(mut watchdog: Watchdog) -> ! {
    let mut ticker = Ticker::every(Duration::from_millis(u64::from(WATCHDOG_FEED_MS)));
    loop {
        watchdog.feed();
        ticker.next().await;
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
    let timer_clock = embassy_stm32::rcc::frequency::<peripherals::TIM2>().0;
    if timer_clock != board::APB1_TIMER_HZ {
        warn!(
            "chip timer clock {} Hz, expected {} Hz: check the clock tree",
            timer_clock,
            board::APB1_TIMER_HZ
        );
    }
    let hardware = ChipHardware {
        tim2: p.TIM2,
        tim3: p.TIM3,
        tim5: p.TIM5,
        tim3_stream: p.DMA1_CH4,
        tim5_stream: p.DMA1_CH1,
        pins: LedPins {
            pa6: p.PA6,
            pa7: p.PA7,
            pb0: p.PB0,
            pb1: p.PB1,
            pa1: p.PA1,
            pa2: p.PA2,
            pa3: p.PA3,
            pa0: p.PA0,
        },
    };
    if let Err(e) = chips::install(hardware, timer_clock) {
        warn!("chip engine: {}", e);
    }
    spawner.spawn(watchdog_feeder(Watchdog::start(p.IWDG)).expect("watchdog task slot"));

    let mut store = ConfigStore::new(Flash::new(p.FLASH, Irqs));
    let restored = store.restore().await;
    info!("stored config: {}", restored);
    let luminaire = Luminaire::new(
        BoardInfo::new(env!("CARGO_PKG_VERSION"), board::BOARD_NAME),
        restored,
    );
    let startup = luminaire.startup_effects();
    link::install(luminaire);
    link::apply(&startup);

    let led = BoardLed::new(Output::new(p.PC13, Level::High, Speed::Low));
    let (device, mut serial) = usb::build(p.USB_OTG_FS, Irqs, p.PA12, p.PA11);
    spawner.spawn(usb_device(device).expect("usb task slot"));
    spawner.spawn(config_saver(store).expect("saver task slot"));
    spawner.spawn(identify_blinker(led).expect("identify task slot"));
    spawner.spawn(carrier_watch().expect("watch task slot"));

    loop {
        serial.wait_connection().await;
        info!("USB connected");
        let link::Disconnected = link::serve(&mut serial).await;
        link::reset_reader();
        info!(
            "USB disconnected; carriers {}",
            if chips::is_running() {
                "playing"
            } else {
                "stopped"
            }
        );
    }
}
