//! Golden bytes for every request and response variant (sequence number 1).
//!
//! Hand-checked examples (protocol version 3; the bytes of every literal below were computed
//! outside the crate from postcard's varints, COBS and zlib's CRC-32):
//! * `Ping(0x1234_5678)` request: payload `03 01 | 00 | F8 AC D1 91 01 | crc32_le` (header
//!   version 3 and seq 1 as varints, variant 0, the nonce as a LEB128 varint), COBS-encoded as
//!   `[3, 3, 1]` (two bytes then the zero of the variant) `[10, F8 AC D1 91 01 + 4 CRC bytes]`
//!   and the `0` terminator.
//! * `ProtocolError(FrameTooLong)` response: payload `03 01 00 00 | crc`, COBS `[3, 3, 1] [1]
//!   [5, crc…] 0`: variant 0 of `Response` and variant 0 of `ProtocolError` are both zeros.
//! * `SetConfig(DEFAULT)`: after `03 01 03` comes `04` (LED count), `80 CC 3A` (960 000 mHz as
//!   a varint: 0x00|0x80, 0x4C|0x80, 0x3A), eight times `E8 07` (1000), eight zero phases
//!   (each becoming a COBS code `01`), `01` (running), the eight off levels as varints
//!   (`E7 05` = 743, `BA 05` = 698, `FB 06` = 891, `FA 06` = 890 …) and `00` (allow_flicker).

use protocol::config::{ChipRate, ConfigError, LuminaireConfig};
use protocol::framing::{decode_request, decode_response, encode_request, encode_response};
use protocol::wire::{
    Command, CommandError, ConfigSource, DeviceInfo, OutputFault, PROTOCOL_VERSION, ProtocolError,
    Request, Response, SaveOutcome, SaveState, Status,
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
        output_fault: Some(OutputFault::DmaTransferError),
        config_source: ConfigSource::Restored,
        unsaved_changes: false,
        flicker_limited: true,
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
            &[3, 3, 1, 10, 248, 172, 209, 145, 1, 213, 186, 53, 161, 0],
        ),
        check_request(Request::GetInfo(()), &[8, 3, 1, 1, 156, 102, 27, 147, 0]),
        check_request(Request::GetConfig(()), &[8, 3, 1, 2, 38, 55, 18, 10, 0]),
        check_request(
            Request::SetConfig(LuminaireConfig::DEFAULT),
            &[
                24, 3, 1, 3, 4, 128, 204, 58, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7, 232,
                7, 232, 7, 1, 1, 1, 1, 1, 1, 1, 18, 1, 231, 5, 186, 5, 251, 6, 250, 6, 250, 6, 250,
                6, 250, 6, 250, 6, 5, 1, 13, 216, 227, 0,
            ],
        ),
        check_request(Request::SaveConfig(()), &[8, 3, 1, 4, 19, 146, 113, 227, 0]),
        check_request(Request::Start(()), &[8, 3, 1, 5, 133, 162, 118, 148, 0]),
        check_request(Request::Stop(()), &[8, 3, 1, 6, 63, 243, 127, 13, 0]),
        check_request(Request::GetStatus(()), &[8, 3, 1, 7, 169, 195, 120, 122, 0]),
        check_request(Request::Identify(5), &[9, 3, 1, 8, 5, 66, 100, 128, 138, 0]),
    ];
    assert_eq!(covered, Command::ALL);
}

#[test]
fn every_response_variant_has_golden_bytes() {
    check_response(
        Response::ProtocolError(ProtocolError::FrameTooLong),
        &[3, 3, 1, 1, 5, 197, 26, 51, 50, 0],
    );
    check_response(
        Response::ProtocolError(ProtocolError::BadCrc),
        &[3, 3, 1, 6, 1, 83, 42, 52, 69, 0],
    );
    check_response(
        Response::ProtocolError(ProtocolError::Malformed),
        &[3, 3, 1, 6, 2, 233, 123, 61, 220, 0],
    );
    check_response(
        Response::ProtocolError(ProtocolError::UnsupportedVersion { supported: 1 }),
        &[3, 3, 1, 7, 3, 1, 253, 137, 20, 101, 0],
    );
    check_response(
        Response::Ping(0x1234_5678),
        &[13, 3, 1, 1, 248, 172, 209, 145, 1, 112, 105, 105, 106, 0],
    );
    check_response(
        Response::GetInfo(info()),
        &[
            36, 3, 1, 2, 5, 48, 46, 49, 46, 48, 3, 8, 101, 109, 117, 108, 97, 116, 111, 114, 8,
            232, 7, 128, 146, 244, 1, 239, 253, 182, 245, 13, 1, 162, 238, 231, 0,
        ],
    );
    check_response(
        Response::GetConfig(LuminaireConfig::DEFAULT),
        &[
            24, 3, 1, 3, 4, 128, 204, 58, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7, 232, 7,
            232, 7, 1, 1, 1, 1, 1, 1, 1, 18, 1, 231, 5, 186, 5, 251, 6, 250, 6, 250, 6, 250, 6,
            250, 6, 250, 6, 5, 1, 13, 216, 227, 0,
        ],
    );
    check_response(
        Response::SetConfig(Ok(())),
        &[4, 3, 1, 4, 5, 193, 223, 95, 86, 0],
    );
    check_response(
        Response::SetConfig(Err(ConfigError::Phase { led: 2, got: 40 })),
        &[12, 3, 1, 4, 1, 3, 2, 40, 194, 163, 33, 47, 0],
    );
    check_response(
        Response::SaveConfig(Ok(SaveOutcome::Deferred)),
        &[4, 3, 1, 5, 6, 1, 213, 24, 242, 72, 0],
    );
    check_response(
        Response::SaveConfig(Err(CommandError::Busy)),
        &[5, 3, 1, 5, 1, 5, 2, 25, 238, 38, 0],
    );
    check_response(
        Response::Start(Ok(())),
        &[4, 3, 1, 6, 5, 67, 189, 105, 100, 0],
    );
    check_response(
        Response::Stop(Ok(())),
        &[4, 3, 1, 7, 5, 2, 140, 114, 125, 0],
    );
    check_response(
        Response::GetStatus(status()),
        &[
            6, 3, 1, 8, 1, 1, 2, 1, 14, 1, 1, 1, 172, 2, 1, 2, 3, 4, 81, 169, 67, 132, 0,
        ],
    );
    check_response(
        Response::Identify(Ok(())),
        &[4, 3, 1, 9, 5, 140, 161, 241, 227, 0],
    );
    check_response(
        Response::Identify(Err(CommandError::InvalidArgument)),
        &[10, 3, 1, 9, 1, 2, 74, 129, 250, 193, 0],
    );
}
