//! Talks to a luminaire: `cargo run -p meb-device --example luminaire -- [PORT]`.
//!
//! With a serial port (e.g. `/dev/ttyACM0`) it talks to that board; without one it starts a
//! virtual luminaire on a pseudo-terminal, the same protocol state machine the firmware runs,
//! so the example works on any Unix machine. It reads the board's identity and configuration,
//! plays three LEDs at 480 chips per second, saves that to flash and reads the status back.

#[cfg(unix)]
use meb_device::{DeviceClient, EmulatorOptions, Timeouts, VirtualLuminaire};
#[cfg(unix)]
use protocol::config::{ChipRate, LuminaireConfig};
#[cfg(unix)]
use std::path::PathBuf;

#[cfg(not(unix))]
fn main() {
    eprintln!("this example needs Unix pseudo-terminals or a board's serial port");
}

#[cfg(unix)]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    // A board named on the command line, or a virtual one for as long as `main` runs.
    let mut virtual_luminaire = None;
    let port = match std::env::args_os().nth(1) {
        Some(port) => PathBuf::from(port),
        None => {
            let luminaire = VirtualLuminaire::spawn(EmulatorOptions::default())?;
            let port = luminaire.port_path().to_path_buf();
            virtual_luminaire = Some(luminaire);
            port
        }
    };
    let mut client = DeviceClient::open(&port, Timeouts::default())?;
    println!("{}: {:?}", port.display(), client.info()?);

    let config = LuminaireConfig {
        led_count: 3,
        chip_rate: ChipRate(480_000),
        ..client.config()?
    };
    client.set_config(&config)?;
    println!("saved: {:?}", client.save_and_wait()?);
    println!("status: {:?}", client.status()?);
    if let Some(luminaire) = virtual_luminaire {
        luminaire.shutdown()?;
    }
    Ok(())
}
