//! Robustness of reader + state machine against arbitrary input.
//!
//! Every stream is fed through [`Endpoint::on_bytes`] in random chunks and compared with an
//! independent reference: split the whole stream at 0x00 with `split`, decode each piece on
//! its own and apply a three-line model of the configuration (valid `SetConfig` replaces it,
//! `Start`/`Stop` set `running`). Checked after every chunk: no panic, exactly one reply per
//! completed non-empty piece, the configuration equals the model's (so it changes only through
//! a valid `SetConfig`, `Start` or `Stop` that arrived intact), and every intact request is
//! answered with a command response, never a protocol error.
//!
//! Case counts: `MEB_FUZZ_CASES` (default 20 000 deterministic mixed streams) plus the
//! proptest cases (raise `MEB_FUZZ_CASES` for a long run).

mod common;
use common::Rng;
use proptest::prelude::*;
use protocol::config::{ChipRate, LuminaireConfig};
use protocol::framing::{
    MAX_COBS_LEN, MAX_FRAME_LEN, decode_request, decode_response, encode_request,
};
use protocol::luminaire::{BoardInfo, Effect, Endpoint, Luminaire, RestoredConfig};
use protocol::wire::{CommandError, Request, Response};

fn endpoint() -> Endpoint {
    let board = BoardInfo {
        firmware_version: heapless::String::try_from("fuzz").unwrap(),
        board: heapless::String::try_from("fuzz").unwrap(),
    };
    Endpoint::new(Luminaire::new(board, RestoredConfig::Missing))
}

/// The reference model: configuration after each piece that decodes.
fn apply_model(config: &mut LuminaireConfig, piece: &[u8]) -> bool {
    let mut raw = piece.to_vec();
    match decode_request(&mut raw) {
        Ok((_, Request::SetConfig(new))) => {
            if new.validate_for_people().is_ok() {
                *config = new;
            }
            true
        }
        Ok((_, Request::Start(()))) => {
            config.running = true;
            true
        }
        Ok((_, Request::Stop(()))) => {
            config.running = false;
            true
        }
        Ok(_) => true,
        Err(_) => false,
    }
}

/// Feeds `stream` in chunks of the given sizes (cycled) and checks it against the reference.
fn check_stream(stream: &[u8], chunk_sizes: &[usize], save_ok: bool) {
    let mut endpoint = endpoint();
    let mut model = *endpoint.luminaire.config();
    let mut expected_replies = 0usize;
    let mut expected_ok = 0usize;
    let mut replies = 0usize;
    let mut ok_replies = 0usize;
    let mut piece_start = 0usize;
    let mut pos = 0usize;
    let mut sizes = chunk_sizes.iter().cycle();
    while pos < stream.len() {
        let size = (*sizes.next().unwrap()).max(1);
        let end = (pos + size).min(stream.len());
        let mut persist = false;
        endpoint.on_bytes(&stream[pos..end], |bytes, effects| {
            assert!(bytes.len() <= MAX_FRAME_LEN);
            let mut raw = bytes.to_vec();
            let (_, response) = decode_response(&mut raw).expect("device reply decodes");
            replies += 1;
            if !matches!(response, Response::ProtocolError(_)) {
                ok_replies += 1;
            }
            persist |= effects.iter().any(|e| matches!(e, Effect::Persist(_)));
        });
        if persist {
            let result = if save_ok {
                Ok(())
            } else {
                Err(CommandError::StorageFailed)
            };
            endpoint.luminaire.notify_saved(result);
        }
        // Reference: every piece terminated inside this chunk.
        for (i, &byte) in stream.iter().enumerate().take(end).skip(pos) {
            if byte == 0 {
                let piece = &stream[piece_start..i];
                if !piece.is_empty() {
                    expected_replies += 1;
                    if piece.len() <= MAX_COBS_LEN && apply_model(&mut model, piece) {
                        expected_ok += 1;
                    }
                }
                piece_start = i + 1;
            }
        }
        // An oversized pending piece is answered as soon as it overflows.
        let pending = end - piece_start;
        let overflow_reply = usize::from(pending > MAX_COBS_LEN);
        assert_eq!(
            replies,
            expected_replies + overflow_reply,
            "reply count at byte {end}"
        );
        assert_eq!(ok_replies, expected_ok, "good frames at byte {end}");
        assert_eq!(*endpoint.luminaire.config(), model, "config at byte {end}");
        pos = end;
    }
}

fn random_config(rng: &mut Rng) -> LuminaireConfig {
    let mut config = LuminaireConfig {
        led_count: 1 + rng.below(8) as u8,
        chip_rate: ChipRate(rng.below(4_100_000) as u32),
        brightness_permille: [0; 8],
        phase_chips: [0; 8],
        running: rng.below(2) == 0,
        off_level_permille: [0; 8],
        allow_flicker: rng.below(2) == 0,
    };
    let chips = 1u64 << (config.led_count + 1);
    for led in 0..8 {
        config.brightness_permille[led] = rng.below(1002) as u16;
        config.phase_chips[led] = rng.below(chips + 1) as u16;
        config.off_level_permille[led] = rng.below(1002) as u16;
    }
    if rng.below(4) == 0 {
        config.led_count = rng.byte();
    }
    // About half of all generated configs are valid.
    if rng.below(2) == 0 {
        config.brightness_permille = [rng.below(1001) as u16; 8];
        config.phase_chips = [0; 8];
        config.led_count = 1 + rng.below(8) as u8;
        config.chip_rate = ChipRate(1_000 + rng.below(3_999_001) as u32);
        config.off_level_permille = [rng.below(1001) as u16; 8];
        config.allow_flicker = true;
    }
    config
}

fn random_request(rng: &mut Rng) -> Request {
    match rng.below(9) {
        0 => Request::Ping(rng.next() as u32),
        1 => Request::GetInfo(()),
        2 => Request::GetConfig(()),
        3 | 4 => Request::SetConfig(random_config(rng)),
        5 => Request::SaveConfig(()),
        6 => Request::Start(()),
        7 => Request::Stop(()),
        _ => Request::Identify(rng.byte()),
    }
}

fn random_stream(rng: &mut Rng) -> Vec<u8> {
    let mut stream = Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    for _ in 0..1 + rng.below(12) {
        let seq = rng.below(6) as u32;
        let request = random_request(rng);
        let frame = encode_request(seq, &request, &mut buf).unwrap().to_vec();
        match rng.below(10) {
            0..=4 => stream.extend_from_slice(&frame),
            5 => {
                // Flip one bit anywhere (may create or destroy a delimiter).
                let mut frame = frame;
                let i = rng.below(frame.len() as u64) as usize;
                frame[i] ^= 1 << rng.below(8);
                stream.extend_from_slice(&frame);
            }
            6 => {
                // Truncate (possibly dropping the terminator: glued to what follows).
                let keep = rng.below(frame.len() as u64) as usize;
                stream.extend_from_slice(&frame[..keep]);
            }
            7 => {
                // Insert or overwrite a random byte.
                let mut frame = frame;
                let i = rng.below(frame.len() as u64) as usize;
                if rng.below(2) == 0 {
                    frame.insert(i, rng.byte());
                } else {
                    frame[i] = rng.byte();
                }
                stream.extend_from_slice(&frame);
            }
            8 => {
                let len = if rng.below(8) == 0 {
                    200 + rng.below(400)
                } else {
                    rng.below(24)
                };
                stream.extend((0..len).map(|_| rng.byte() | u8::from(rng.below(4) != 0)));
            }
            _ => stream.push(0),
        }
    }
    stream
}

fn fuzz_cases() -> u64 {
    std::env::var("MEB_FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20_000)
}

#[test]
fn mixed_valid_and_mutated_frames() {
    let cases = fuzz_cases();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut bytes = 0usize;
    for case in 0..cases {
        let stream = random_stream(&mut rng);
        let chunks: Vec<usize> = (0..4).map(|_| 1 + rng.below(80) as usize).collect();
        bytes += stream.len();
        check_stream(&stream, &chunks, case % 7 != 0);
    }
    eprintln!("robustness: {cases} mixed streams, {bytes} bytes");
}

#[test]
fn intact_frames_after_delimiters_are_never_dropped() {
    // Garbage of every length 0..=300 (no delimiter) + 0x00 + a valid SetConfig.
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut target = LuminaireConfig::DEFAULT;
    target.led_count = 2;
    let frame = encode_request(1, &Request::SetConfig(target), &mut buf).unwrap();
    for len in 0..=300 {
        let mut stream = vec![0x5A; len];
        stream.push(0);
        stream.extend_from_slice(frame);
        let mut endpoint = endpoint();
        endpoint.on_bytes(&stream, |_, _| {});
        assert_eq!(*endpoint.luminaire.config(), target, "garbage length {len}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4_000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes(
        stream in prop::collection::vec(
            prop_oneof![4 => any::<u8>(), 1 => Just(0u8), 1 => 1u8..4],
            0..1200,
        ),
        chunks in prop::collection::vec(1usize..300, 1..6),
        save_ok in any::<bool>(),
    ) {
        check_stream(&stream, &chunks, save_ok);
    }

    #[test]
    fn valid_frames_in_arbitrary_chunks(
        seeds in prop::collection::vec(any::<u64>(), 1..16),
        chunks in prop::collection::vec(1usize..64, 1..6),
    ) {
        let mut stream = Vec::new();
        let mut buf = [0u8; MAX_FRAME_LEN];
        for seed in seeds {
            let mut rng = Rng(seed | 1);
            let request = random_request(&mut rng);
            stream.extend_from_slice(encode_request(seed as u32, &request, &mut buf).unwrap());
        }
        check_stream(&stream, &chunks, true);
    }
}
