//! Finding luminaires among the host's serial ports.
//!
//! `serialport::available_ports()` (built without libudev) scans `/sys/class/tty` and reads each
//! USB device's `idVendor`, `idProduct`, `manufacturer` and `product` attributes. A port is a
//! luminaire when all four match the identity the firmware enumerates with
//! ([`protocol::usb::is_luminaire`]): pid.codes' VID with a placeholder test PID, so the strings
//! are compared in full too.

use std::path::{Path, PathBuf};

use serde::Serialize;

pub use protocol::usb::{USB_MANUFACTURER, USB_PID, USB_PRODUCT, USB_VID};

/// One serial port on the host.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PortEntry {
    /// Device path, e.g. `/dev/ttyACM0`.
    pub path: PathBuf,
    /// USB vendor ID, when the port is on USB.
    pub vid: Option<u16>,
    /// USB product ID, when the port is on USB.
    pub pid: Option<u16>,
    /// USB manufacturer string, when reported.
    pub manufacturer: Option<String>,
    /// USB product string, when reported.
    pub product: Option<String>,
    /// USB serial number, when reported.
    pub serial_number: Option<String>,
    /// Whether the port is a meb luminaire (IDs and both strings match).
    pub is_luminaire: bool,
}

/// Error listing or choosing ports.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DiscoveryError {
    /// The operating system's port list could not be read.
    #[error("cannot list serial ports")]
    List(#[from] serialport::Error),
    /// No luminaire is attached.
    #[error(
        "no meb luminaire found (looked for USB {USB_VID:04x}:{USB_PID:04x}, \
         \"{USB_MANUFACTURER}\" \"{USB_PRODUCT}\")"
    )]
    NoLuminaire,
    /// More than one luminaire is attached and none was chosen.
    #[error("{} meb luminaires attached ({}): name the one to use", .0.len(), join_paths(.0))]
    SeveralLuminaires(Vec<PathBuf>),
}

fn join_paths(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Whether USB identity `(vid, pid, manufacturer, product)` is a meb luminaire.
pub fn is_luminaire(vid: u16, pid: u16, manufacturer: Option<&str>, product: Option<&str>) -> bool {
    protocol::usb::is_luminaire(vid, pid, manufacturer, product)
}

/// Every serial port the OS reports, luminaires marked.
pub fn list_ports() -> Result<Vec<PortEntry>, DiscoveryError> {
    let mut ports: Vec<PortEntry> = serialport::available_ports()?
        .into_iter()
        .map(entry_from_info)
        .collect();
    ports.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(ports)
}

fn entry_from_info(info: serialport::SerialPortInfo) -> PortEntry {
    let path = PathBuf::from(info.port_name);
    match info.port_type {
        serialport::SerialPortType::UsbPort(usb) => PortEntry {
            is_luminaire: is_luminaire(
                usb.vid,
                usb.pid,
                usb.manufacturer.as_deref(),
                usb.product.as_deref(),
            ),
            path,
            vid: Some(usb.vid),
            pid: Some(usb.pid),
            manufacturer: usb.manufacturer,
            product: usb.product,
            serial_number: usb.serial_number,
        },
        _ => PortEntry {
            path,
            vid: None,
            pid: None,
            manufacturer: None,
            product: None,
            serial_number: None,
            is_luminaire: false,
        },
    }
}

/// The port to talk to: `explicit` when given, else the only attached luminaire.
pub fn select_port(explicit: Option<&Path>) -> Result<PathBuf, DiscoveryError> {
    if let Some(path) = explicit {
        return Ok(path.to_path_buf());
    }
    choose_luminaire(&list_ports()?)
}

/// The only luminaire among `ports`, or why there is not exactly one.
pub fn choose_luminaire(ports: &[PortEntry]) -> Result<PathBuf, DiscoveryError> {
    let ours: Vec<PathBuf> = ports
        .iter()
        .filter(|p| p.is_luminaire)
        .map(|p| p.path.clone())
        .collect();
    match ours.as_slice() {
        [] => Err(DiscoveryError::NoLuminaire),
        [one] => Ok(one.clone()),
        _ => Err(DiscoveryError::SeveralLuminaires(ours)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(path: &str, vid: u16, pid: u16, manufacturer: &str, product: &str) -> PortEntry {
        PortEntry {
            path: PathBuf::from(path),
            vid: Some(vid),
            pid: Some(pid),
            manufacturer: Some(manufacturer.into()),
            product: Some(product.into()),
            serial_number: None,
            is_luminaire: is_luminaire(vid, pid, Some(manufacturer), Some(product)),
        }
    }

    #[test]
    fn marks_only_the_full_identity() {
        assert!(is_luminaire(
            USB_VID,
            USB_PID,
            Some(USB_MANUFACTURER),
            Some(USB_PRODUCT)
        ));
        // Another gadget on the shared test PID, or the old V-USB pair.
        assert!(!is_luminaire(
            USB_VID,
            USB_PID,
            Some("someone"),
            Some(USB_PRODUCT)
        ));
        assert!(!is_luminaire(
            0x16c0,
            0x05e1,
            Some(USB_MANUFACTURER),
            Some(USB_PRODUCT)
        ));
        assert!(!is_luminaire(USB_VID, USB_PID, None, Some(USB_PRODUCT)));
    }

    #[test]
    fn chooses_exactly_one() {
        let other = entry("/dev/ttyACM0", 0x2341, 0x0043, "Arduino", "Arduino Uno");
        let a = entry(
            "/dev/ttyACM1",
            USB_VID,
            USB_PID,
            USB_MANUFACTURER,
            USB_PRODUCT,
        );
        let b = entry(
            "/dev/ttyACM2",
            USB_VID,
            USB_PID,
            USB_MANUFACTURER,
            USB_PRODUCT,
        );
        assert!(matches!(
            choose_luminaire(std::slice::from_ref(&other)),
            Err(DiscoveryError::NoLuminaire)
        ));
        assert_eq!(
            choose_luminaire(&[other.clone(), a.clone()]).unwrap(),
            PathBuf::from("/dev/ttyACM1")
        );
        let err = choose_luminaire(&[a, other, b]).unwrap_err();
        assert!(matches!(&err, DiscoveryError::SeveralLuminaires(p) if p.len() == 2));
        assert!(err.to_string().contains("/dev/ttyACM2"), "{err}");
    }

    #[test]
    fn errors_name_no_command_line_flag() {
        // The library does not know how its caller lets a user pick a port.
        for err in [
            DiscoveryError::NoLuminaire,
            DiscoveryError::SeveralLuminaires(vec!["/dev/a".into(), "/dev/b".into()]),
        ] {
            assert!(!err.to_string().contains("--"), "{err}");
        }
    }

    #[test]
    fn explicit_port_wins() {
        let path = Path::new("/dev/pts/9");
        assert_eq!(select_port(Some(path)).unwrap(), path);
    }

    #[test]
    fn listing_does_not_fail() {
        // Whatever this machine has attached, listing must work and never mark a non-USB port.
        for port in list_ports().unwrap() {
            assert!(!port.is_luminaire || port.vid == Some(USB_VID));
        }
    }
}
