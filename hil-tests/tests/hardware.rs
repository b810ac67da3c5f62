//! The protocol tests against a real board: opt-in with `MEB_HIL_PORT=/dev/ttyACM0`.
//! Without it each test prints a loud SKIPPED line and returns.
//!
//! These change the board's configuration; the last one restores the one it found.

use std::sync::{Mutex, MutexGuard, PoisonError};

use hil_tests::{
    board_or_skip, check_disconnect_recovery, check_garbage_recovery,
    check_invalid_configs_rejected, client, configure_and_save, sample_config,
};

/// One board: the tests take turns.
static BOARD: Mutex<()> = Mutex::new(());

fn board() -> MutexGuard<'static, ()> {
    BOARD.lock().unwrap_or_else(PoisonError::into_inner)
}

#[test]
fn hardware_configure_read_back_save() {
    let Some(port) = board_or_skip("hardware_configure_read_back_save") else {
        return;
    };
    let _turn = board();
    let original = client(&port).config().unwrap();
    configure_and_save(&port, &sample_config());
    configure_and_save(&port, &original);
}

#[test]
fn hardware_invalid_configs_rejected() {
    let Some(port) = board_or_skip("hardware_invalid_configs_rejected") else {
        return;
    };
    let _turn = board();
    check_invalid_configs_rejected(&port);
}

#[test]
fn hardware_garbage_and_partial_frames_recovered() {
    let Some(port) = board_or_skip("hardware_garbage_and_partial_frames_recovered") else {
        return;
    };
    let _turn = board();
    check_garbage_recovery(&port);
}

#[test]
fn hardware_disconnect_mid_command_recovered() {
    let Some(port) = board_or_skip("hardware_disconnect_mid_command_recovered") else {
        return;
    };
    let _turn = board();
    check_disconnect_recovery(&port);
}

#[test]
fn hardware_identifies_itself() {
    let Some(port) = board_or_skip("hardware_identifies_itself") else {
        return;
    };
    let _turn = board();
    let mut c = client(&port);
    let info = c.info().unwrap();
    assert_eq!(info.protocol_version, protocol::wire::PROTOCOL_VERSION);
    c.identify(1).unwrap();
    c.identify(0).unwrap();
}
