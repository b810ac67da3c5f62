//! USB CDC-ACM device with the identity of `protocol::usb` (pid.codes VID, placeholder PID,
//! manufacturer and product strings the host matches in full); serial number = the chip's 96-bit
//! unique ID in hex, so the host can tell boards apart and find the same board again after a
//! replug.

use embassy_stm32::peripherals::{PA11, PA12, USB_OTG_FS};
use embassy_stm32::usb::{self, Driver};
use embassy_stm32::{Peri, interrupt};
use embassy_usb::class::cdc_acm::{CdcAcmClass, State};
use embassy_usb::{Builder, UsbDevice};
use static_cell::StaticCell;

use protocol::usb::{USB_MANUFACTURER, USB_PID, USB_PRODUCT, USB_VID};

/// Full-speed bulk packet size.
pub const PACKET_SIZE: u16 = 64;

/// The OTG_FS driver as this firmware uses it.
pub type UsbDriver = Driver<'static, USB_OTG_FS>;
/// The CDC-ACM class carrying the protocol's frames.
pub type Serial = CdcAcmClass<'static, UsbDriver>;

/// Descriptor and endpoint buffers (they must outlive the device).
struct Buffers {
    ep_out: [u8; 256],
    config_descriptor: [u8; 256],
    bos_descriptor: [u8; 256],
    control: [u8; 64],
    state: State<'static>,
}

static BUFFERS: StaticCell<Buffers> = StaticCell::new();

/// Builds the USB device and its CDC-ACM class. No VBUS sensing: the Black Pill does not route
/// VBUS to PA9, so the device is always "attached" while powered.
pub fn build(
    otg: Peri<'static, USB_OTG_FS>,
    irqs: impl interrupt::typelevel::Binding<
        <USB_OTG_FS as usb::Instance>::Interrupt,
        usb::InterruptHandler<USB_OTG_FS>,
    > + 'static,
    dp: Peri<'static, PA12>,
    dm: Peri<'static, PA11>,
) -> (UsbDevice<'static, UsbDriver>, Serial) {
    let buffers = BUFFERS.init(Buffers {
        ep_out: [0; 256],
        config_descriptor: [0; 256],
        bos_descriptor: [0; 256],
        control: [0; 64],
        state: State::new(),
    });
    let mut driver_config = usb::Config::default();
    driver_config.vbus_detection = false;
    let driver = Driver::new_fs(otg, irqs, dp, dm, &mut buffers.ep_out, driver_config);

    let mut config = embassy_usb::Config::new(USB_VID, USB_PID);
    config.manufacturer = Some(USB_MANUFACTURER);
    config.product = Some(USB_PRODUCT);
    config.serial_number = Some(embassy_stm32::uid::uid_hex());
    config.max_power = 100;
    config.max_packet_size_0 = 64;

    let mut builder = Builder::new(
        driver,
        config,
        &mut buffers.config_descriptor,
        &mut buffers.bos_descriptor,
        &mut [],
        &mut buffers.control,
    );
    let class = CdcAcmClass::new(&mut builder, &mut buffers.state, PACKET_SIZE);
    (builder.build(), class)
}
