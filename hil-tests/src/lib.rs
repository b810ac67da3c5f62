//! Helpers for the hardware-in-the-loop tests.
//!
//! Every protocol scenario here takes a serial port path and drives it with the real `meb`
//! client ([`meb_device::DeviceClient`] over `serialport`), so the same checks run against the
//! virtual luminaire on a pseudo-terminal (by default) and against a real board. The board tests
//! (`tests/hardware.rs`) are `#[ignore = "needs MEB_HIL_PORT"]`: they show as ignored in every
//! run, and `MEB_HIL_PORT=/dev/ttyACM0 cargo test -p hil-tests --test hardware -- --ignored`
//! runs them; run without the variable they fail, they never pass silently.
//!
//! The scenarios panic on failure: they are test code.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use meb_device::client::{DeviceClient, DeviceError, Timeouts};
use protocol::config::{ChipRate, ConfigError, LuminaireConfig};
use protocol::framing::{MAX_FRAME_LEN, encode_request};
use protocol::wire::{Request, SaveState};

pub mod elf_budget;

/// Environment variable naming a real board's serial port.
pub const HIL_PORT_VAR: &str = "MEB_HIL_PORT";

/// The board's port from `MEB_HIL_PORT`; panics with how to set it when it is missing (the
/// hardware tests are ignored unless asked for, and asked for they must not pass without a board).
pub fn board_port() -> PathBuf {
    match std::env::var_os(HIL_PORT_VAR) {
        Some(port) if !port.is_empty() => PathBuf::from(port),
        _ => panic!(
            "no board: set {HIL_PORT_VAR}=/dev/ttyACM0 (the luminaire's port) to run the hardware tests"
        ),
    }
}

/// Timeouts for tests: generous per attempt (a loaded CI machine), three attempts.
pub fn test_timeouts() -> Timeouts {
    Timeouts {
        reply: Duration::from_millis(800),
        attempts: 3,
        save: Duration::from_secs(10),
        ..Timeouts::default()
    }
}

/// A client on `port`.
pub fn client(port: &Path) -> DeviceClient {
    match DeviceClient::open(port, test_timeouts()) {
        Ok(client) => client,
        Err(err) => panic!("cannot open {}: {err}", port.display()),
    }
}

/// A distinctive valid configuration: 3 LEDs at 959.5 Hz, mixed brightness, phases and
/// low-risk off levels.
pub fn sample_config() -> LuminaireConfig {
    let mut config = LuminaireConfig::DEFAULT;
    config.led_count = 3;
    config.chip_rate = ChipRate(959_500);
    config.brightness_permille[..3].copy_from_slice(&[1000, 800, 650]);
    config.phase_chips[..3].copy_from_slice(&[0, 3, 11]);
    config.off_level_permille[..3].copy_from_slice(&[750, 700, 900]);
    config
}

/// A healthy luminaire reports no output fault and plays when its configuration says so.
pub fn check_no_output_fault(port: &Path) {
    let mut c = client(port);
    let status = c.status().unwrap();
    assert_eq!(status.output_fault, None, "{status:?}");
    assert_eq!(status.running, c.config().unwrap().running, "{status:?}");
}

/// Sets `config`, reads it back, saves it and waits until storage has it.
pub fn configure_and_save(port: &Path, config: &LuminaireConfig) {
    let mut c = client(port);
    c.set_config(config)
        .unwrap_or_else(|e| panic!("set_config: {e}"));
    assert_eq!(c.config().unwrap(), *config, "read-back differs");
    c.save_and_wait().unwrap_or_else(|e| panic!("save: {e}"));
    let status = c.status().unwrap();
    assert!(!status.unsaved_changes, "{status:?}");
    assert_eq!(status.save, SaveState::Idle);
}

/// Invalid configurations are rejected naming the field, and leave the config unchanged.
pub fn check_invalid_configs_rejected(port: &Path) {
    let mut c = client(port);
    let before = c.config().unwrap();
    let base = sample_config();
    let mut cases = Vec::new();
    let mut bad = base;
    bad.led_count = 9;
    cases.push((bad, ConfigError::LedCount { got: 9 }));
    let mut bad = base;
    bad.chip_rate = ChipRate(4_000_001);
    cases.push((
        bad,
        ConfigError::ChipRate {
            got_millihertz: 4_000_001,
        },
    ));
    let mut bad = base;
    bad.brightness_permille[2] = 1001;
    cases.push((bad, ConfigError::Brightness { led: 2, got: 1001 }));
    let mut bad = base;
    bad.phase_chips[1] = 16; // 3 LEDs: 16 chips per frame
    cases.push((bad, ConfigError::Phase { led: 1, got: 16 }));
    for (config, expected) in cases {
        match c.set_config(&config) {
            Err(DeviceError::InvalidConfig(got)) => assert_eq!(got, expected),
            other => panic!("expected {expected:?}, got {other:?}"),
        }
        assert_eq!(
            c.config().unwrap(),
            before,
            "rejected config changed the device"
        );
    }
}

/// An encoded request frame (no delimiters) with sequence number `seq`.
pub fn request_frame(seq: u32, request: &Request) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    match encode_request(seq, request, &mut buf) {
        Ok(frame) => frame.to_vec(),
        Err(e) => panic!("encode: {e}"),
    }
}

/// Writes `bytes` to `port` through a separate raw handle, then closes it.
pub fn write_raw(port: &Path, bytes: &[u8]) {
    let mut raw = serialport::new(port.to_string_lossy(), 115_200)
        .timeout(Duration::from_millis(200))
        .open()
        .unwrap_or_else(|e| panic!("raw open {}: {e}", port.display()));
    raw.write_all(bytes).unwrap();
    raw.flush().unwrap();
    // Let the device consume (and answer) before the handle goes.
    std::thread::sleep(Duration::from_millis(150));
}

/// Line noise: random bytes, junk frames, an overlong frame, a CRC-damaged frame and a frame
/// cut in half. Afterwards the device answers normally, counted the damage, and changed nothing.
pub fn check_garbage_recovery(port: &Path) {
    let mut c = client(port);
    let before = c.config().unwrap();
    let counters_before = c.status().unwrap();
    drop(c);

    let mut noise: Vec<u8> = (0..200u32).map(|i| (i * 37 % 251 + 1) as u8).collect();
    noise.push(0); // ends the random run: one malformed candidate
    noise.extend(std::iter::repeat_n(0x55, MAX_FRAME_LEN + 40)); // overlong
    noise.push(0);
    let mut damaged = request_frame(77, &Request::SetConfig(sample_config()));
    let middle = damaged.len() / 2;
    damaged[middle] ^= 0x10; // CRC mismatch (still valid COBS: no zero introduced)
    if damaged[middle] == 0 {
        damaged[middle] = 0x01;
    }
    noise.extend_from_slice(&damaged);
    let whole = request_frame(78, &Request::SetConfig(sample_config()));
    noise.extend_from_slice(&whole[..whole.len() / 2]); // partial: no terminator
    write_raw(port, &noise);

    let mut c = client(port);
    c.ping(0xC0FFEE)
        .unwrap_or_else(|e| panic!("ping after noise: {e}"));
    assert_eq!(
        c.config().unwrap(),
        before,
        "noise changed the configuration"
    );
    let after = c.status().unwrap();
    assert!(after.rx_too_long > counters_before.rx_too_long, "{after:?}");
    assert!(
        after.rx_bad_crc + after.rx_malformed
            > counters_before.rx_bad_crc + counters_before.rx_malformed,
        "{after:?}"
    );
    // Noise in the middle of a session, from the client's own handle.
    c.link_mut_send(&[0x13, 0x37, 0x00, 0xff, 0xfe]);
    c.set_config(&sample_config()).unwrap();
    assert_eq!(c.config().unwrap(), sample_config());
    c.set_config(&before).unwrap();
}

/// A client that vanishes mid-command (half a frame sent, port closed) leaves the device
/// unchanged and ready for the next client.
pub fn check_disconnect_recovery(port: &Path) {
    let before = client(port).config().unwrap();
    let mut target = before;
    target.chip_rate = ChipRate(if before.chip_rate == ChipRate(1_000_000) {
        2_000_000
    } else {
        1_000_000
    });
    let frame = request_frame(5, &Request::SetConfig(target));
    write_raw(port, &frame[..frame.len() - 3]);
    let mut c = client(port);
    assert_eq!(c.config().unwrap(), before, "half a frame was applied");
    c.set_config(&target).unwrap();
    assert_eq!(c.config().unwrap(), target);
    c.set_config(&before).unwrap();
}

/// Extension: send raw bytes over a client's own link.
pub trait RawSend {
    /// Writes `bytes` on the client's link as they are.
    fn link_mut_send(&mut self, bytes: &[u8]);
}

impl RawSend for DeviceClient {
    fn link_mut_send(&mut self, bytes: &[u8]) {
        use meb_device::transport::Link;
        self.link_mut().send(bytes).unwrap();
    }
}
