//! The USB identity of a meb luminaire: what the firmware enumerates with and what the host's
//! port discovery looks for.
//!
//! The vendor ID is pid.codes' 0x1209, open to open-source hardware projects. The product ID is
//! a placeholder, pid.codes' test PID 0x0001, until pid.codes assigns this project a PID of its
//! own (pending: requested through a pull request to the pid.codes registry). A test PID is
//! shared by everyone testing, so the host also requires both strings, in full: a port is a
//! luminaire only if all four of [`USB_VID`], [`USB_PID`], [`USB_MANUFACTURER`] and
//! [`USB_PRODUCT`] match ([`is_luminaire`]). When the real PID arrives, only [`USB_PID`] changes.

/// USB vendor ID: pid.codes.
pub const USB_VID: u16 = 0x1209;
/// USB product ID: pid.codes test PID, a placeholder until this project's PID is assigned.
pub const USB_PID: u16 = 0x0001;
/// USB manufacturer string.
pub const USB_MANUFACTURER: &str = "meb project";
/// USB product string.
pub const USB_PRODUCT: &str = "meb luminaire";

/// Whether a USB device with these IDs and strings is a meb luminaire: IDs equal, both strings
/// equal in full (surrounding whitespace from the OS aside).
pub fn is_luminaire(vid: u16, pid: u16, manufacturer: Option<&str>, product: Option<&str>) -> bool {
    vid == USB_VID
        && pid == USB_PID
        && manufacturer.is_some_and(|m| m.trim() == USB_MANUFACTURER)
        && product.is_some_and(|p| p.trim() == USB_PRODUCT)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_full_identity_is_a_luminaire() {
        let ok = |v, p, m, n| is_luminaire(v, p, m, n);
        assert!(ok(
            USB_VID,
            USB_PID,
            Some("meb project"),
            Some("meb luminaire\n")
        ));
        // Other test-PID gadgets, partial strings, missing strings, other IDs.
        assert!(!ok(
            USB_VID,
            USB_PID,
            Some("someone else"),
            Some("meb luminaire")
        ));
        assert!(!ok(
            USB_VID,
            USB_PID,
            Some("meb project"),
            Some("meb luminaire v2")
        ));
        assert!(!ok(USB_VID, USB_PID, Some("meb"), Some("meb luminaire")));
        assert!(!ok(USB_VID, USB_PID, None, Some("meb luminaire")));
        assert!(!ok(USB_VID, USB_PID, Some("meb project"), None));
        assert!(!ok(
            0x16c0,
            0x05e1,
            Some("meb project"),
            Some("meb luminaire")
        ));
        assert!(!ok(
            USB_VID,
            0x0002,
            Some("meb project"),
            Some("meb luminaire")
        ));
    }
}
