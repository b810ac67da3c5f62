//! Finding luminaires among the host's serial ports.
//!
//! `serialport::available_ports()` (built without libudev) scans `/sys/class/tty` and reads each
//! USB device's `idVendor`, `idProduct` and `product` attributes. A port is a luminaire when its
//! USB IDs are [`USB_VID`]:[`USB_PID`] and its product string is [`USB_PRODUCT`]: the IDs are the
//! shared V-USB CDC-ACM pair, which by its licence must be told apart by the strings.

use std::path::{Path, PathBuf};

use serde::Serialize;

/// USB vendor ID the firmware enumerates with (shared V-USB/obdev CDC-ACM ID).
pub const USB_VID: u16 = 0x16c0;
/// USB product ID the firmware enumerates with (shared V-USB/obdev CDC-ACM ID).
pub const USB_PID: u16 = 0x05e1;
/// USB product string the firmware reports; it is what tells our boards apart.
pub const USB_PRODUCT: &str = "meb luminaire";

/// One serial port on the host.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PortEntry {
    /// Device path, e.g. `/dev/ttyACM0`.
    pub path: PathBuf,
    /// USB vendor ID, when the port is on USB.
    pub vid: Option<u16>,
    /// USB product ID, when the port is on USB.
    pub pid: Option<u16>,
    /// USB product string, when reported.
    pub product: Option<String>,
    /// USB serial number, when reported.
    pub serial_number: Option<String>,
    /// Whether the port is a meb luminaire (IDs and product string match).
    pub is_luminaire: bool,
}

/// Error listing or choosing ports.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DiscoveryError {
    /// The operating system's port list could not be read.
    #[error("cannot list serial ports: {0}")]
    List(#[from] serialport::Error),
    /// No luminaire is attached.
    #[error(
        "no meb luminaire found (looked for USB {USB_VID:04x}:{USB_PID:04x} \"{USB_PRODUCT}\"); \
         plug one in or pass --port PATH (e.g. the path printed by `meb device emulate`)"
    )]
    NoLuminaire,
    /// More than one luminaire is attached and none was chosen.
    #[error("{} meb luminaires attached ({}); choose one with --port PATH", .0.len(), join_paths(.0))]
    SeveralLuminaires(Vec<PathBuf>),
}

fn join_paths(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Whether USB identity `(vid, pid, product)` is a meb luminaire.
pub fn is_luminaire(vid: u16, pid: u16, product: Option<&str>) -> bool {
    vid == USB_VID && pid == USB_PID && product.is_some_and(|p| p.trim() == USB_PRODUCT)
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
            is_luminaire: is_luminaire(usb.vid, usb.pid, usb.product.as_deref()),
            path,
            vid: Some(usb.vid),
            pid: Some(usb.pid),
            product: usb.product,
            serial_number: usb.serial_number,
        },
        _ => PortEntry {
            path,
            vid: None,
            pid: None,
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

    fn entry(path: &str, vid: u16, pid: u16, product: &str) -> PortEntry {
        PortEntry {
            path: PathBuf::from(path),
            vid: Some(vid),
            pid: Some(pid),
            product: Some(product.into()),
            serial_number: None,
            is_luminaire: is_luminaire(vid, pid, Some(product)),
        }
    }

    #[test]
    fn marks_only_matching_ids_and_product() {
        assert!(is_luminaire(USB_VID, USB_PID, Some("meb luminaire")));
        assert!(!is_luminaire(
            USB_VID,
            USB_PID,
            Some("some other V-USB gadget")
        ));
        assert!(!is_luminaire(USB_VID, USB_PID, None));
        assert!(!is_luminaire(0x2341, USB_PID, Some("meb luminaire")));
    }

    #[test]
    fn chooses_exactly_one() {
        let other = entry("/dev/ttyACM0", 0x2341, 0x0043, "Arduino Uno");
        let a = entry("/dev/ttyACM1", USB_VID, USB_PID, USB_PRODUCT);
        let b = entry("/dev/ttyACM2", USB_VID, USB_PID, USB_PRODUCT);
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
