//! Every error's message as a user reads it (the host prints them; the firmware logs them):
//! each variant names what went wrong and the offending value.

use protocol::carriers::CarrierError;
use protocol::config::ConfigError;
use protocol::framing::{EncodeError, FrameError};
use protocol::record::RecordError;
use protocol::timing::TimingError;
use protocol::wire::{CommandError, OutputFault, ProtocolError};

fn check(cases: &[(String, &str)]) {
    for (shown, expected) in cases {
        assert_eq!(shown, expected);
    }
}

#[test]
fn error_messages_name_the_fault_and_the_value() {
    check(&[
        (
            CarrierError::LedCount(9).to_string(),
            "LED count 9 is outside 1..=8",
        ),
        (
            CarrierError::LedIndex(5).to_string(),
            "LED index 5 is outside the table",
        ),
        (
            ConfigError::LedCount { got: 0 }.to_string(),
            "led_count 0 is outside 1..=8",
        ),
        (
            ConfigError::ChipRate { got_millihertz: 5 }.to_string(),
            "chip_rate 5 mHz is outside 1000..=4000000 mHz",
        ),
        (
            ConfigError::Brightness { led: 2, got: 1001 }.to_string(),
            "brightness_permille[2] = 1001 exceeds 1000",
        ),
        (
            ConfigError::Phase { led: 1, got: 64 }.to_string(),
            "phase_chips[1] = 64 is not below the frame length",
        ),
        (
            EncodeError::BufferFull.to_string(),
            "frame does not fit the buffer (256 B max)",
        ),
        (
            EncodeError::Serialize.to_string(),
            "message could not be serialized",
        ),
        (FrameError::Cobs.to_string(), "invalid COBS frame"),
        (FrameError::BadCrc.to_string(), "CRC mismatch"),
        (
            FrameError::Malformed { seq: Some(7) }.to_string(),
            "malformed frame (seq 7)",
        ),
        (
            FrameError::Malformed { seq: None }.to_string(),
            "malformed frame",
        ),
        (
            FrameError::UnsupportedVersion { version: 9, seq: 3 }.to_string(),
            "protocol version 9 unsupported (seq 3)",
        ),
        (
            RecordError::BufferFull.to_string(),
            "record buffer too small",
        ),
        (RecordError::Truncated.to_string(), "record truncated"),
        (
            RecordError::BadMagic.to_string(),
            "no config record (bad magic)",
        ),
        (
            RecordError::UnknownVersion(4).to_string(),
            "unknown record version 4",
        ),
        (RecordError::BadCrc.to_string(), "record CRC mismatch"),
        (
            RecordError::Malformed.to_string(),
            "record payload malformed",
        ),
        (
            RecordError::Invalid(ConfigError::LedCount { got: 9 }).to_string(),
            "stored config invalid: led_count 9 is outside 1..=8",
        ),
        (TimingError::ZeroRate.to_string(), "chip rate is zero"),
        (TimingError::ZeroClock.to_string(), "timer clock is zero"),
        (
            TimingError::CounterBits(33).to_string(),
            "counter width 33 bits is outside 1..=32",
        ),
        (
            TimingError::RateTooLow.to_string(),
            "chip rate too low for this timer",
        ),
        (
            TimingError::RateTooHigh.to_string(),
            "chip rate too high for this timer",
        ),
        (
            TimingError::FrameBuffer { needed: 8, got: 4 }.to_string(),
            "compare-frame buffer holds 4 values, needs 8",
        ),
        (ProtocolError::FrameTooLong.to_string(), "frame too long"),
        (ProtocolError::BadCrc.to_string(), "bad CRC"),
        (ProtocolError::Malformed.to_string(), "malformed frame"),
        (
            ProtocolError::UnsupportedVersion { supported: 2 }.to_string(),
            "unsupported protocol version (device speaks 2)",
        ),
        (CommandError::Busy.to_string(), "busy"),
        (CommandError::StorageFailed.to_string(), "storage failed"),
        (
            CommandError::InvalidArgument.to_string(),
            "invalid argument",
        ),
        (
            OutputFault::DmaTransferError.to_string(),
            "DMA transfer error: carriers stopped, outputs off",
        ),
        (
            OutputFault::DmaStopTimeout.to_string(),
            "DMA stream did not stop: outputs off, new settings not started",
        ),
    ]);
}
