//! Protocol tests against the virtual luminaire on a pseudo-terminal, driven by the real client.

use std::time::{Duration, Instant};

use hil_tests::{
    check_disconnect_recovery, check_garbage_recovery, check_invalid_configs_rejected,
    check_no_output_fault, client, configure_and_save, sample_config,
};
use meb_device::client::DeviceError;
use meb_device::{EmulatorOptions, VirtualLuminaire};
use protocol::config::LuminaireConfig;
use protocol::luminaire::RestoredConfig;
use protocol::wire::{ConfigSource, OutputFault};

fn emulator_with_storage(dir: &tempfile::TempDir) -> (VirtualLuminaire, EmulatorOptions) {
    let options = EmulatorOptions {
        storage: Some(dir.path().join("flash.rec")),
        ..EmulatorOptions::default()
    };
    (VirtualLuminaire::spawn(options.clone()).unwrap(), options)
}

#[test]
fn configure_read_back_save_power_cycle_restores_config() {
    let dir = tempfile::tempdir().unwrap();
    let (emulator, options) = emulator_with_storage(&dir);
    let config = sample_config();
    configure_and_save(emulator.port_path(), &config);
    emulator.shutdown().unwrap();

    // Power cycle: a new luminaire process on the same "flash".
    let emulator = VirtualLuminaire::spawn(options).unwrap();
    assert_eq!(emulator.restored(), RestoredConfig::Ok(config));
    let mut c = client(emulator.port_path());
    assert_eq!(c.config().unwrap(), config);
    let status = c.status().unwrap();
    assert_eq!(status.config_source, ConfigSource::Restored);
    assert!(!status.unsaved_changes);
}

#[test]
fn unsaved_config_is_lost_on_power_cycle() {
    let dir = tempfile::tempdir().unwrap();
    let (emulator, options) = emulator_with_storage(&dir);
    client(emulator.port_path())
        .set_config(&sample_config())
        .unwrap();
    emulator.shutdown().unwrap();
    let emulator = VirtualLuminaire::spawn(options).unwrap();
    assert_eq!(
        client(emulator.port_path()).config().unwrap(),
        LuminaireConfig::DEFAULT
    );
}

#[test]
fn corrupt_storage_boots_defaults_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("flash.rec"), b"MEBC\x01\x00\xff\x00garbage").unwrap();
    let (emulator, _) = emulator_with_storage(&dir);
    let mut c = client(emulator.port_path());
    assert_eq!(c.config().unwrap(), LuminaireConfig::DEFAULT);
    assert_eq!(
        c.status().unwrap().config_source,
        ConfigSource::CorruptRecordDefaults
    );
}

#[test]
fn invalid_configs_rejected_config_unchanged() {
    let emulator = VirtualLuminaire::spawn(EmulatorOptions::default()).unwrap();
    check_invalid_configs_rejected(emulator.port_path());
}

#[test]
fn garbage_and_partial_frames_recovered_from() {
    let emulator = VirtualLuminaire::spawn(EmulatorOptions::default()).unwrap();
    check_garbage_recovery(emulator.port_path());
}

#[test]
fn client_disconnect_mid_command_recovered_from() {
    let emulator = VirtualLuminaire::spawn(EmulatorOptions::default()).unwrap();
    check_disconnect_recovery(emulator.port_path());
}

#[test]
fn device_vanishing_mid_session_is_an_error_not_a_hang() {
    let dir = tempfile::tempdir().unwrap();
    let (emulator, options) = emulator_with_storage(&dir);
    let mut c = client(emulator.port_path());
    c.ping(1).unwrap();
    emulator.shutdown().unwrap();
    match c.ping(2) {
        Err(DeviceError::Link(_) | DeviceError::Timeout { .. }) => {}
        other => panic!("expected a link error or timeout, got {other:?}"),
    }
    // The device comes back ("replugged"): a new session works.
    let emulator = VirtualLuminaire::spawn(options).unwrap();
    client(emulator.port_path()).ping(3).unwrap();
}

#[test]
fn missing_port_is_a_clear_no_device_error() {
    match meb_device::DeviceClient::open(
        std::path::Path::new("/dev/meb-no-such-luminaire"),
        hil_tests::test_timeouts(),
    ) {
        Err(err @ DeviceError::Open(_)) => {
            assert!(err.to_string().contains("no device"), "{err}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn output_fault_is_reported_and_cleared_by_start() {
    let emulator = VirtualLuminaire::spawn(EmulatorOptions::default()).unwrap();
    check_no_output_fault(emulator.port_path());
    emulator.inject_output_fault(OutputFault::DmaStopTimeout);
    let mut c = client(emulator.port_path());
    let deadline = Instant::now() + Duration::from_secs(5);
    while c.status().unwrap().output_fault.is_none() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = c.status().unwrap();
    assert_eq!(status.output_fault, Some(OutputFault::DmaStopTimeout));
    assert!(!status.running);
    c.start().unwrap();
    drop(c);
    check_no_output_fault(emulator.port_path());
}

#[test]
fn a_save_during_a_two_second_flash_stall_completes() {
    let dir = tempfile::tempdir().unwrap();
    let options = EmulatorOptions {
        storage: Some(dir.path().join("flash.rec")),
        save_stall: Duration::from_secs(2),
        ..EmulatorOptions::default()
    };
    let emulator = VirtualLuminaire::spawn(options).unwrap();
    configure_and_save(emulator.port_path(), &sample_config());
}
