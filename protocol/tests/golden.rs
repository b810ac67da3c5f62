//! Golden bytes for every request and response variant (sequence number 1).
//!
//! Hand-checked examples:
//! * `Ping(0x1234_5678)` request: payload `01 01 | 00 | F8 AC D1 91 01 | crc32_le` (header
//!   version 1 and seq 1 as varints, variant 0, the nonce as a LEB128 varint), COBS-encoded as
//!   `[3, 1, 1]` (two bytes then the zero of the variant) `[10, F8 AC D1 91 01 + 4 CRC bytes]`
//!   and the `0` terminator.
//! * `ProtocolError(FrameTooLong)` response: payload `01 01 00 00 | crc`, COBS `[3, 1, 1] [1]
//!   [5, crc…] 0`: variant 0 of `Response` and variant 0 of `ProtocolError` are both zeros.
//! * `SetConfig(DEFAULT)`: after `01 01 03` comes `04` (LED count), `80 CC 3A` (960 000 mHz as
//!   a varint: 0x00|0x80, 0x4C|0x80, 0x3A), eight times `E8 07` (1000), eight zero phases
//!   (each becoming a COBS code `01`), `01` (running).

use protocol::config::{ChipRate, ConfigError, LuminaireConfig};
use protocol::framing::{decode_request, decode_response, encode_request, encode_response};
use protocol::wire::{
    Command, CommandError, ConfigSource, DeviceInfo, PROTOCOL_VERSION, ProtocolError, Request,
    Response, SaveOutcome, SaveState, Status,
};

fn info() -> DeviceInfo {
    DeviceInfo {
        firmware_version: heapless::String::try_from("0.1.0").unwrap(),
        protocol_version: PROTOCOL_VERSION,
        board: heapless::String::try_from("emulator").unwrap(),
        max_leds: 8,
        min_chip_rate: ChipRate::MIN,
        max_chip_rate: ChipRate::MAX,
        carrier_fingerprint: 0xDEAD_BEEF,
    }
}

fn status() -> Status {
    Status {
        running: true,
        config_source: ConfigSource::Restored,
        unsaved_changes: false,
        save: SaveState::Pending,
        identify_active: true,
        rx_frames_ok: 300,
        rx_bad_crc: 1,
        rx_malformed: 2,
        rx_too_long: 3,
        rx_unsupported_version: 4,
    }
}

fn check_request(request: Request, golden: &[u8]) -> Command {
    let mut buf = [0u8; 256];
    let bytes = encode_request(1, &request, &mut buf).unwrap();
    assert_eq!(bytes, golden, "{request:?}");
    let mut raw = golden.to_vec();
    let (header, decoded) = decode_request(&mut raw).unwrap();
    assert_eq!((header.version, header.seq), (PROTOCOL_VERSION, 1));
    assert_eq!(decoded, request);
    request.command()
}

fn check_response(response: Response, golden: &[u8]) {
    let mut buf = [0u8; 256];
    let bytes = encode_response(1, &response, &mut buf).unwrap();
    assert_eq!(bytes, golden, "{response:?}");
    let mut raw = golden.to_vec();
    let (header, decoded) = decode_response(&mut raw).unwrap();
    assert_eq!((header.version, header.seq), (PROTOCOL_VERSION, 1));
    assert_eq!(decoded, response);
}

#[test]
fn every_request_variant_has_golden_bytes() {
    let covered = [
        check_request(
            Request::Ping(0x1234_5678),
            &[3, 1, 1, 10, 248, 172, 209, 145, 1, 168, 189, 16, 227, 0],
        ),
        check_request(Request::GetInfo(()), &[8, 1, 1, 1, 242, 178, 159, 144, 0]),
        check_request(Request::GetConfig(()), &[8, 1, 1, 2, 72, 227, 150, 9, 0]),
        check_request(
            Request::SetConfig(LuminaireConfig::DEFAULT),
            &[
                24, 1, 1, 3, 4, 128, 204, 58, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7, 232,
                7, 232, 7, 1, 1, 1, 1, 1, 1, 1, 6, 1, 154, 251, 57, 119, 0,
            ],
        ),
        check_request(Request::SaveConfig(()), &[8, 1, 1, 4, 125, 70, 245, 224, 0]),
        check_request(Request::Start(()), &[8, 1, 1, 5, 235, 118, 242, 151, 0]),
        check_request(Request::Stop(()), &[8, 1, 1, 6, 81, 39, 251, 14, 0]),
        check_request(Request::GetStatus(()), &[8, 1, 1, 7, 199, 23, 252, 121, 0]),
        check_request(Request::Identify(5), &[9, 1, 1, 8, 5, 201, 172, 137, 32, 0]),
    ];
    assert_eq!(covered, Command::ALL);
}

#[test]
fn every_response_variant_has_golden_bytes() {
    check_response(
        Response::ProtocolError(ProtocolError::FrameTooLong),
        &[3, 1, 1, 1, 5, 78, 210, 58, 152, 0],
    );
    check_response(
        Response::ProtocolError(ProtocolError::BadCrc),
        &[3, 1, 1, 6, 1, 216, 226, 61, 239, 0],
    );
    check_response(
        Response::ProtocolError(ProtocolError::Malformed),
        &[3, 1, 1, 6, 2, 98, 179, 52, 118, 0],
    );
    check_response(
        Response::ProtocolError(ProtocolError::UnsupportedVersion { supported: 1 }),
        &[3, 1, 1, 7, 3, 1, 157, 218, 212, 31, 0],
    );
    check_response(
        Response::Ping(0x1234_5678),
        &[13, 1, 1, 1, 248, 172, 209, 145, 1, 13, 110, 76, 40, 0],
    );
    check_response(
        Response::GetInfo(info()),
        &[
            36, 1, 1, 2, 5, 48, 46, 49, 46, 48, 1, 8, 101, 109, 117, 108, 97, 116, 111, 114, 8,
            232, 7, 128, 146, 244, 1, 239, 253, 182, 245, 13, 35, 186, 113, 212, 0,
        ],
    );
    check_response(
        Response::GetConfig(LuminaireConfig::DEFAULT),
        &[
            24, 1, 1, 3, 4, 128, 204, 58, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7,
            232, 7, 1, 1, 1, 1, 1, 1, 1, 6, 1, 154, 251, 57, 119, 0,
        ],
    );
    check_response(
        Response::SetConfig(Ok(())),
        &[4, 1, 1, 4, 5, 74, 23, 86, 252, 0],
    );
    check_response(
        Response::SetConfig(Err(ConfigError::Phase { led: 2, got: 40 })),
        &[12, 1, 1, 4, 1, 3, 2, 40, 235, 178, 190, 184, 0],
    );
    check_response(
        Response::SaveConfig(Ok(SaveOutcome::Deferred)),
        &[4, 1, 1, 5, 6, 1, 181, 75, 50, 50, 0],
    );
    check_response(
        Response::SaveConfig(Err(CommandError::Busy)),
        &[5, 1, 1, 5, 1, 5, 98, 74, 46, 92, 0],
    );
    check_response(
        Response::Start(Ok(())),
        &[4, 1, 1, 6, 5, 200, 117, 96, 206, 0],
    );
    check_response(
        Response::Stop(Ok(())),
        &[4, 1, 1, 7, 5, 137, 68, 123, 215, 0],
    );
    check_response(
        Response::GetStatus(status()),
        &[
            6, 1, 1, 8, 1, 1, 13, 1, 1, 172, 2, 1, 2, 3, 4, 58, 46, 217, 80, 0,
        ],
    );
    check_response(
        Response::Identify(Ok(())),
        &[4, 1, 1, 9, 5, 7, 105, 248, 73, 0],
    );
    check_response(
        Response::Identify(Err(CommandError::InvalidArgument)),
        &[10, 1, 1, 9, 1, 2, 42, 210, 58, 187, 0],
    );
}
