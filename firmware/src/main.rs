//! meb luminaire firmware for the WeAct Black Pill (STM32F411CEU6), issue 6.
#![no_std]
#![no_main]

mod board;
mod chips;
mod identify;
mod usb;

use defmt::info;
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::{bind_interrupts, peripherals};
use panic_probe as _;
use protocol::carriers::{ChipTable, MAX_LEDS};

bind_interrupts!(struct Irqs {
    OTG_FS => embassy_stm32::usb::InterruptHandler<peripherals::USB_OTG_FS>;
});

#[embassy_executor::task]
async fn usb_device(mut device: embassy_usb::UsbDevice<'static, usb::UsbDriver>) -> ! {
    device.run().await
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(board::clock_config());
    info!("meb luminaire {}", env!("CARGO_PKG_VERSION"));
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
    if let Ok(table) = ChipTable::new(4)
        && let Ok(loaded) = engine.load(&table, &[1000; MAX_LEDS], 960_000)
    {
        info!("loaded {}", loaded);
        engine.start();
    }
    let mut led = identify::BoardLed::new(Output::new(p.PC13, Level::High, Speed::Low));
    let (device, mut serial) = usb::build(p.USB_OTG_FS, Irqs, p.PA12, p.PA11);
    spawner.spawn(usb_device(device).expect("usb task"));
    identify::blink(&mut led, 1).await;
    loop {
        serial.wait_connection().await;
        info!("USB connected");
        let mut packet = [0u8; 64];
        while serial.read_packet(&mut packet).await.is_ok() {}
        info!("USB disconnected");
    }
}
