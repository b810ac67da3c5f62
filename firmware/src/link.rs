//! The host link: CDC-ACM bytes → the protocol's [`Endpoint`] (streaming frame reader + luminaire
//! state machine) → reply frames back, [`Effects`] carried out on the hardware.
//!
//! The endpoint lives in a thread-mode mutex so the save and identify tasks can report back
//! (`notify_saved`, `notify_identify_finished`). A dropped USB link is a value
//! ([`Disconnected`]): the caller waits for the next connection, the luminaire keeps its
//! configuration and the carriers keep playing; a partial frame is forgotten on reconnect.

use core::cell::RefCell;

use defmt::{error, info};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, ThreadModeRawMutex};
use embassy_sync::signal::Signal;
use embassy_usb::driver::EndpointError;
use heapless::Vec;
use protocol::config::LuminaireConfig;
use protocol::framing::MAX_FRAME_LEN;
use protocol::luminaire::{Effect, Effects, Endpoint, Luminaire};

use chip_plan::plan::ChipError;

use crate::chips;
use crate::identify::IDENTIFY;
use crate::usb::{PACKET_SIZE, Serial};

/// The protocol endpoint, installed once at boot.
static ENDPOINT: Mutex<ThreadModeRawMutex, RefCell<Option<Endpoint>>> =
    Mutex::new(RefCell::new(None));

/// Configurations waiting to be written to flash (latest wins).
pub static SAVE: Signal<CriticalSectionRawMutex, LuminaireConfig> = Signal::new();

/// The USB host went away (cable pulled, port closed by the bus, suspend).
pub struct Disconnected;

impl From<EndpointError> for Disconnected {
    fn from(error: EndpointError) -> Self {
        match error {
            EndpointError::Disabled => Disconnected,
            // Our reads use a full packet buffer, so this is a bug, not a wire condition.
            EndpointError::BufferOverflow => defmt::panic!("USB packet larger than its buffer"),
        }
    }
}

/// Installs the endpoint around `luminaire`.
pub fn install(luminaire: Luminaire) {
    ENDPOINT.lock(|cell| *cell.borrow_mut() = Some(Endpoint::new(luminaire)));
}

/// Runs `f` on the luminaire state machine (None before [`install`]).
pub fn with_luminaire<R>(f: impl FnOnce(&mut Luminaire) -> R) -> Option<R> {
    ENDPOINT.lock(|cell| cell.borrow_mut().as_mut().map(|e| f(&mut e.luminaire)))
}

/// Forgets any partial frame (after a disconnect); the luminaire state is kept.
pub fn reset_reader() {
    ENDPOINT.lock(|cell| {
        let mut slot = cell.borrow_mut();
        if let Some(endpoint) = slot.as_mut() {
            *endpoint = Endpoint::new(endpoint.luminaire.clone());
        }
    });
}

/// Serves one connection until the host goes away.
pub async fn serve(serial: &mut Serial) -> Disconnected {
    match serve_inner(serial).await {
        Ok(never) => match never {},
        Err(disconnected) => disconnected,
    }
}

async fn serve_inner(serial: &mut Serial) -> Result<core::convert::Infallible, Disconnected> {
    let mut packet = [0u8; PACKET_SIZE as usize];
    loop {
        let received = serial.read_packet(&mut packet).await?;
        // One byte at a time: each call completes at most one frame, whose reply is sent
        // before the next byte is read, so no reply ever has to be queued.
        for &byte in &packet[..received] {
            let mut reply: Option<(Vec<u8, MAX_FRAME_LEN>, Effects)> = None;
            ENDPOINT.lock(|cell| {
                if let Some(endpoint) = cell.borrow_mut().as_mut() {
                    endpoint.on_bytes(&[byte], |bytes, effects| {
                        reply = Vec::from_slice(bytes).ok().map(|frame| (frame, effects));
                    });
                }
            });
            if let Some((frame, effects)) = reply {
                apply(&effects);
                send(serial, &frame).await?;
            }
        }
    }
}

/// Writes one frame as full-speed packets, closing a packet-aligned transfer with a ZLP.
async fn send(serial: &mut Serial, frame: &[u8]) -> Result<(), Disconnected> {
    let size = usize::from(PACKET_SIZE);
    for chunk in frame.chunks(size) {
        serial.write_packet(chunk).await?;
    }
    if frame.len().is_multiple_of(size) {
        serial.write_packet(&[]).await?;
    }
    Ok(())
}

/// Carries out the state machine's effects in order; a chip-engine error that stopped the
/// carriers is reported to the state machine as an output fault.
pub fn apply(effects: &Effects) {
    for effect in effects {
        match *effect {
            Effect::ApplyOutput(plan) => {
                let loaded = plan
                    .chip_table()
                    .map(|table| chips::load(&table, &plan.levels(), plan.chip_rate.millihertz()));
                match loaded {
                    Ok(Some(Ok(loaded))) => info!(
                        "output: {} LEDs, {} chips, {} mHz requested, {} uHz played ({} ppb), brightness {}, off level {}",
                        plan.led_count,
                        loaded.chips,
                        plan.chip_rate.millihertz(),
                        loaded.rate_microhertz,
                        loaded.error_ppb,
                        plan.brightness_permille,
                        plan.off_level_permille
                    ),
                    Ok(Some(Err(e))) => engine_error(e),
                    Ok(None) => error!("output not loaded: no chip engine"),
                    Err(e) => error!("output plan invalid: {}", e),
                }
            }
            Effect::Persist(config) => {
                info!("save requested");
                SAVE.signal(config);
            }
            Effect::Start => {
                if let Some(Err(e)) = chips::start() {
                    engine_error(e);
                }
                info!("carriers started");
            }
            Effect::Stop => {
                if let Some(Err(e)) = chips::stop() {
                    engine_error(e);
                }
                info!("carriers stopped");
            }
            Effect::Identify { seconds } => {
                info!("identify {} s", seconds);
                IDENTIFY.signal(seconds);
            }
        }
    }
}

/// Logs a chip-engine error and reports the fault it caused, if any.
fn engine_error(error: ChipError) {
    error!("chip engine: {}", error);
    if let Some(fault) = error.fault() {
        with_luminaire(|l| l.notify_output_fault(fault));
    }
}
