//! The protocol tests against a real board. Ignored by default (they show as ignored, never as
//! passed); run them with the board's port:
//!
//! ```sh
//! MEB_HIL_PORT=/dev/ttyACM0 cargo test -p hil-tests --test hardware -- --ignored
//! ```
//!
//! These change the board's configuration; the first one restores the one it found.

use std::sync::{Mutex, MutexGuard, PoisonError};

use hil_tests::{
    board_port, check_disconnect_recovery, check_garbage_recovery, check_invalid_configs_rejected,
    check_no_output_fault, client, configure_and_save, sample_config,
};

/// One board: the tests take turns.
static BOARD: Mutex<()> = Mutex::new(());

fn board() -> MutexGuard<'static, ()> {
    BOARD.lock().unwrap_or_else(PoisonError::into_inner)
}

#[test]
#[ignore = "needs MEB_HIL_PORT"]
fn hardware_configure_read_back_save() {
    let port = board_port();
    let _turn = board();
    let original = client(&port).config().unwrap();
    configure_and_save(&port, &sample_config());
    check_no_output_fault(&port);
    configure_and_save(&port, &original);
}

#[test]
#[ignore = "needs MEB_HIL_PORT"]
fn hardware_invalid_configs_rejected() {
    let port = board_port();
    let _turn = board();
    check_invalid_configs_rejected(&port);
}

#[test]
#[ignore = "needs MEB_HIL_PORT"]
fn hardware_garbage_and_partial_frames_recovered() {
    let port = board_port();
    let _turn = board();
    check_garbage_recovery(&port);
}

#[test]
#[ignore = "needs MEB_HIL_PORT"]
fn hardware_disconnect_mid_command_recovered() {
    let port = board_port();
    let _turn = board();
    check_disconnect_recovery(&port);
}

#[test]
#[ignore = "needs MEB_HIL_PORT"]
fn hardware_identifies_itself() {
    let port = board_port();
    let _turn = board();
    let mut c = client(&port);
    let info = c.info().unwrap();
    assert_eq!(info.protocol_version, protocol::wire::PROTOCOL_VERSION);
    c.identify(1).unwrap();
    c.identify(0).unwrap();
}
