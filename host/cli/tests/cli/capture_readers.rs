//! The capture readers on tiny known inputs: PNG/TIFF directories, multi-page TIFF, y4m, raw
//! frames and video containers through FFmpeg. Every reader must return the samples it was
//! given exactly, report the levels that map them to fractions of full scale, and turn bad
//! input into a typed error.

use crate::common;
use common::ffmpeg_available;
use meb_core::capture::ffmpeg::FfmpegSource;
use meb_core::capture::images::{ImageSequence, TiffStack};
use meb_core::capture::raw::RawLayout;
use meb_core::capture::y4m::Y4mSource;
use meb_core::capture::{CaptureError, Frame, FrameSource, OpenOptions, Samples, open};
use std::path::{Path, PathBuf};
use std::process::Command;

const W: usize = 32;
const H: usize = 24;

/// An 8-bit test pattern covering every code value 0..=255 over a few frames.
fn pattern8(frame: usize) -> Vec<u8> {
    (0..W * H)
        .map(|i| ((i % W) * 7 + (i / W) * 13 + frame * 29) as u8)
        .collect()
}

/// A test pattern with codes in `0..=max`.
fn pattern16(frame: usize, max: u32) -> Vec<u16> {
    (0..W * H)
        .map(|i| (((i % W) * 977 + (i / W) * 131 + frame * 4099) as u32 % (max + 1)) as u16)
        .collect()
}

fn read_all(source: &mut dyn FrameSource) -> Result<Vec<Frame>, CaptureError> {
    let mut frames = Vec::new();
    while let Some(frame) = source.next_frame()? {
        frames.push(frame);
    }
    Ok(frames)
}

fn u8s(frame: &Frame) -> &[u8] {
    match &frame.samples {
        Samples::U8(v) => v,
        Samples::U16(_) => panic!("frame {} is 16-bit, expected 8-bit", frame.index),
    }
}

fn u16s(frame: &Frame) -> &[u16] {
    match &frame.samples {
        Samples::U16(v) => v,
        Samples::U8(_) => panic!("frame {} is 8-bit, expected 16-bit", frame.index),
    }
}

fn options() -> OpenOptions {
    OpenOptions::default()
}

fn save_grey8(path: &Path, width: usize, height: usize, data: Vec<u8>) {
    image::GrayImage::from_raw(width as u32, height as u32, data)
        .unwrap()
        .save(path)
        .unwrap();
}

fn save_grey16(path: &Path, data: Vec<u16>) {
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(W as u32, H as u32, data)
        .unwrap()
        .save(path)
        .unwrap();
}

// ---------------------------------------------------------------------------------------------
// PNG / TIFF directories

#[test]
fn png_directory_8_bit_grey_round_trips() {
    let tmp = tempfile::tempdir().unwrap();
    for f in 0..5 {
        save_grey8(
            &tmp.path().join(format!("frame_{f:03}.png")),
            W,
            H,
            pattern8(f),
        );
    }
    let mut source = open(
        tmp.path(),
        &OpenOptions {
            fps: Some(240.0),
            raw: None,
        },
    )
    .unwrap();
    let format = source.format().clone();
    assert_eq!((format.width, format.height, format.bit_depth), (W, H, 8));
    assert_eq!((format.black_level, format.white_level), (0.0, 255.0));
    assert_eq!(format.fps, 240.0);
    assert_eq!(source.frame_count_hint(), Some(5));
    let frames = read_all(source.as_mut()).unwrap();
    assert_eq!(frames.len(), 5);
    for (f, frame) in frames.iter().enumerate() {
        assert_eq!(frame.index, f);
        assert_eq!(u8s(frame), pattern8(f).as_slice(), "frame {f}");
    }
}

#[test]
fn png_directory_16_bit_grey_stays_16_bit() {
    let tmp = tempfile::tempdir().unwrap();
    for f in 0..3 {
        save_grey16(
            &tmp.path().join(format!("f{f:02}.png")),
            pattern16(f, 65535),
        );
    }
    let mut source = ImageSequence::open(tmp.path(), 0.0).unwrap();
    assert_eq!(source.format().bit_depth, 16);
    assert_eq!(source.format().white_level, 65535.0);
    let frames = read_all(&mut source).unwrap();
    assert_eq!(frames.len(), 3);
    for (f, frame) in frames.iter().enumerate() {
        assert_eq!(u16s(frame), pattern16(f, 65535).as_slice(), "frame {f}");
    }
}

#[test]
fn png_directory_rgb_is_converted_to_rec709_luma() {
    let tmp = tempfile::tempdir().unwrap();
    let grey = pattern8(0);
    // Frame 0: neutral colours (R = G = B) must keep their value exactly.
    let neutral: Vec<u8> = grey.iter().flat_map(|&v| [v, v, v]).collect();
    image::RgbImage::from_raw(W as u32, H as u32, neutral)
        .unwrap()
        .save(tmp.path().join("frame_0.png"))
        .unwrap();
    // Frame 1: pure red, green and blue columns give the Rec. 709 weights.
    let primaries: Vec<u8> = (0..W * H)
        .flat_map(|i| match i % 3 {
            0 => [255, 0, 0],
            1 => [0, 255, 0],
            _ => [0, 0, 255],
        })
        .collect();
    image::RgbImage::from_raw(W as u32, H as u32, primaries)
        .unwrap()
        .save(tmp.path().join("frame_1.png"))
        .unwrap();
    let mut source = open(tmp.path(), &options()).unwrap();
    assert_eq!(source.format().bit_depth, 8);
    let frames = read_all(source.as_mut()).unwrap();
    assert_eq!(u8s(&frames[0]), grey.as_slice());
    let luma = u8s(&frames[1]);
    for (i, expected) in [0.2126, 0.7152, 0.0722].iter().enumerate() {
        let got = f64::from(luma[i]);
        assert!(
            (got - expected * 255.0).abs() <= 1.0,
            "primary {i}: luma {got}, expected {}",
            expected * 255.0
        );
    }
}

#[test]
fn png_directory_rgb_16_bit_stays_16_bit() {
    let tmp = tempfile::tempdir().unwrap();
    let grey = pattern16(0, 65535);
    let rgb: Vec<u16> = grey.iter().flat_map(|&v| [v, v, v]).collect();
    image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_raw(W as u32, H as u32, rgb)
        .unwrap()
        .save(tmp.path().join("frame_0.png"))
        .unwrap();
    let mut source = open(tmp.path(), &options()).unwrap();
    assert_eq!(source.format().bit_depth, 16);
    let frames = read_all(source.as_mut()).unwrap();
    for (got, want) in u16s(&frames[0]).iter().zip(&grey) {
        assert!(got.abs_diff(*want) <= 1, "{got} vs {want}");
    }
}

#[test]
fn png_directory_sorts_numbers_naturally_and_ignores_stray_stills() {
    let tmp = tempfile::tempdir().unwrap();
    // Unpadded numbers: frame10 must come after frame9, not after frame1.
    for f in 1..=12usize {
        save_grey8(
            &tmp.path().join(format!("frame{f}.png")),
            W,
            H,
            vec![(f * 10) as u8; W * H],
        );
    }
    // A still of another size that is not part of the numbered sequence.
    save_grey8(&tmp.path().join("mask.png"), 8, 8, vec![255; 64]);
    std::fs::write(tmp.path().join("notes.txt"), "not a frame").unwrap();
    let mut source = open(tmp.path(), &options()).unwrap();
    let order: Vec<u8> = read_all(source.as_mut())
        .unwrap()
        .iter()
        .map(|f| u8s(f)[0])
        .collect();
    let expected: Vec<u8> = (1..=12).map(|f| (f * 10) as u8).collect();
    assert_eq!(order, expected);
}

#[test]
fn png_directory_with_mismatched_sizes_is_a_size_error() {
    let tmp = tempfile::tempdir().unwrap();
    save_grey8(&tmp.path().join("frame_0.png"), W, H, pattern8(0));
    save_grey8(&tmp.path().join("frame_1.png"), W, H, pattern8(1));
    save_grey8(
        &tmp.path().join("frame_2.png"),
        W + 2,
        H,
        vec![0; (W + 2) * H],
    );
    let mut source = open(tmp.path(), &options()).unwrap();
    assert!(source.next_frame().unwrap().is_some());
    assert!(source.next_frame().unwrap().is_some());
    let error = source.next_frame().unwrap_err();
    assert!(
        matches!(
            error,
            CaptureError::SizeMismatch {
                index: 2,
                got_width,
                width: W,
                ..
            } if got_width == W + 2
        ),
        "{error}"
    );
    assert!(error.to_string().contains("34x24"), "{error}");
}

#[test]
fn png_directory_with_mixed_bit_depths_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    save_grey8(&tmp.path().join("frame_0.png"), W, H, pattern8(0));
    save_grey16(&tmp.path().join("frame_1.png"), pattern16(1, 65535));
    let mut source = open(tmp.path(), &options()).unwrap();
    assert!(source.next_frame().unwrap().is_some());
    let error = source.next_frame().unwrap_err();
    assert!(
        matches!(error, CaptureError::Format { .. }) && error.to_string().contains("16-bit"),
        "{error}"
    );
}

#[test]
fn empty_directory_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("readme.txt"), "no frames here").unwrap();
    let error = open(tmp.path(), &options()).err().expect("an error");
    assert!(
        matches!(error, CaptureError::Format { .. })
            && error.to_string().contains("no PNG or TIFF frames"),
        "{error}"
    );
}

#[test]
fn corrupt_png_in_directory_is_a_format_error() {
    let tmp = tempfile::tempdir().unwrap();
    save_grey8(&tmp.path().join("frame_0.png"), W, H, pattern8(0));
    std::fs::write(tmp.path().join("frame_1.png"), b"\x89PNG\r\n\x1a\nbroken").unwrap();
    let mut source = open(tmp.path(), &options()).unwrap();
    assert!(source.next_frame().unwrap().is_some());
    let error = source.next_frame().unwrap_err();
    assert!(
        matches!(error, CaptureError::Decode { ref path, .. } if path.ends_with("frame_1.png"))
    );
}

#[test]
fn tiff_directory_8_and_16_bit_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let dir8 = tmp.path().join("t8");
    let dir16 = tmp.path().join("t16");
    std::fs::create_dir_all(&dir8).unwrap();
    std::fs::create_dir_all(&dir16).unwrap();
    for f in 0..4 {
        save_grey8(&dir8.join(format!("img_{f:04}.tif")), W, H, pattern8(f));
        save_grey16(&dir16.join(format!("img_{f:04}.tiff")), pattern16(f, 65535));
    }
    let mut source = open(&dir8, &options()).unwrap();
    assert_eq!(source.format().bit_depth, 8);
    let frames = read_all(source.as_mut()).unwrap();
    assert_eq!(frames.len(), 4);
    for (f, frame) in frames.iter().enumerate() {
        assert_eq!(u8s(frame), pattern8(f).as_slice());
    }
    let mut source = open(&dir16, &options()).unwrap();
    assert_eq!(source.format().bit_depth, 16);
    let frames = read_all(source.as_mut()).unwrap();
    assert_eq!(frames.len(), 4);
    for (f, frame) in frames.iter().enumerate() {
        assert_eq!(u16s(frame), pattern16(f, 65535).as_slice());
    }
}

// ---------------------------------------------------------------------------------------------
// Multi-page TIFF

fn write_tiff_stack<C: tiff::encoder::colortype::ColorType>(
    path: &Path,
    pages: &[(usize, usize, Vec<C::Inner>)],
) where
    [C::Inner]: tiff::encoder::TiffValue,
{
    let file = std::fs::File::create(path).unwrap();
    let mut encoder = tiff::encoder::TiffEncoder::new(std::io::BufWriter::new(file)).unwrap();
    for (w, h, data) in pages {
        encoder
            .write_image::<C>(*w as u32, *h as u32, data)
            .unwrap();
    }
}

#[test]
fn multi_page_tiff_16_bit_round_trips() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("stack.tif");
    let pages: Vec<_> = (0..6).map(|f| (W, H, pattern16(f, 65535))).collect();
    write_tiff_stack::<tiff::encoder::colortype::Gray16>(&path, &pages);
    let mut source = open(
        &path,
        &OpenOptions {
            fps: Some(60.0),
            raw: None,
        },
    )
    .unwrap();
    let format = source.format().clone();
    assert_eq!((format.width, format.height, format.bit_depth), (W, H, 16));
    assert_eq!(
        (format.black_level, format.white_level, format.fps),
        (0.0, 65535.0, 60.0)
    );
    let frames = read_all(source.as_mut()).unwrap();
    assert_eq!(frames.len(), 6);
    for (f, frame) in frames.iter().enumerate() {
        assert_eq!(frame.index, f);
        assert_eq!(u16s(frame), pattern16(f, 65535).as_slice(), "page {f}");
    }
    // The end of the stack stays the end.
    assert!(source.next_frame().unwrap().is_none());
}

#[test]
fn multi_page_tiff_8_bit_and_single_page_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("stack.tiff");
    let pages: Vec<_> = (0..3).map(|f| (W, H, pattern8(f))).collect();
    write_tiff_stack::<tiff::encoder::colortype::Gray8>(&path, &pages);
    let mut source = TiffStack::open(&path, 0.0).unwrap();
    assert_eq!(source.format().bit_depth, 8);
    let frames = read_all(&mut source).unwrap();
    assert_eq!(frames.len(), 3);
    for (f, frame) in frames.iter().enumerate() {
        assert_eq!(u8s(frame), pattern8(f).as_slice(), "page {f}");
    }
    let single = tmp.path().join("one.tif");
    write_tiff_stack::<tiff::encoder::colortype::Gray8>(&single, &pages[..1]);
    let frames = read_all(open(&single, &options()).unwrap().as_mut()).unwrap();
    assert_eq!(frames.len(), 1);
    assert_eq!(u8s(&frames[0]), pattern8(0).as_slice());
}

#[test]
fn multi_page_tiff_rgb_is_converted_to_luma() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("rgb.tif");
    let grey = pattern8(2);
    let neutral: Vec<u8> = grey.iter().flat_map(|&v| [v, v, v]).collect();
    let red: Vec<u8> = (0..W * H).flat_map(|_| [200, 0, 0]).collect();
    write_tiff_stack::<tiff::encoder::colortype::RGB8>(&path, &[(W, H, neutral), (W, H, red)]);
    let frames = read_all(open(&path, &options()).unwrap().as_mut()).unwrap();
    assert_eq!(frames.len(), 2);
    assert_eq!(u8s(&frames[0]), grey.as_slice());
    assert!(
        u8s(&frames[1]).iter().all(|&y| y == 43),
        "0.2126 × 200 = 42.5"
    );
}

#[test]
fn multi_page_tiff_with_a_page_of_another_size_is_a_size_error() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("bad.tif");
    let pages = vec![
        (W, H, pattern16(0, 65535)),
        (W, H, pattern16(1, 65535)),
        (16, 8, vec![7u16; 128]),
    ];
    write_tiff_stack::<tiff::encoder::colortype::Gray16>(&path, &pages);
    let mut source = open(&path, &options()).unwrap();
    assert!(source.next_frame().unwrap().is_some());
    assert!(source.next_frame().unwrap().is_some());
    let error = source.next_frame().unwrap_err();
    assert!(
        matches!(
            error,
            CaptureError::SizeMismatch {
                index: 2,
                got_width: 16,
                got_height: 8,
                ..
            }
        ),
        "{error}"
    );
}

#[test]
fn not_a_tiff_and_truncated_tiff_are_format_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let junk = tmp.path().join("junk.tif");
    std::fs::write(&junk, b"this is not a TIFF file at all").unwrap();
    let error = open(&junk, &options()).err().expect("an error");
    assert!(
        matches!(
            error,
            CaptureError::Format { .. } | CaptureError::Decode { .. }
        ),
        "{error}"
    );

    let path = tmp.path().join("cut.tif");
    let pages: Vec<_> = (0..4).map(|f| (W, H, pattern16(f, 65535))).collect();
    write_tiff_stack::<tiff::encoder::colortype::Gray16>(&path, &pages);
    let bytes = std::fs::read(&path).unwrap();
    // Cut into the last page's data (the encoder writes each page's data before its IFD).
    let cut = tmp.path().join("cut2.tif");
    std::fs::write(&cut, &bytes[..bytes.len() - 2 * W * H / 3]).unwrap();
    let result = open(&cut, &options()).and_then(|mut s| read_all(s.as_mut()));
    match result {
        Err(error) => assert!(
            matches!(
                error,
                CaptureError::Format { .. } | CaptureError::Decode { .. } | CaptureError::Io { .. }
            ),
            "{error}"
        ),
        Ok(frames) => {
            // A clean shorter stack is acceptable; garbage pages are not.
            assert!(frames.len() < 4);
            for (f, frame) in frames.iter().enumerate() {
                assert_eq!(u16s(frame), pattern16(f, 65535).as_slice());
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// y4m

fn y4m_file(header: &str, frames: &[Vec<u8>]) -> Vec<u8> {
    let mut bytes = format!("{header}\n").into_bytes();
    for frame in frames {
        bytes.extend_from_slice(b"FRAME\n");
        bytes.extend_from_slice(frame);
    }
    bytes
}

fn le_bytes(samples: &[u16]) -> Vec<u8> {
    samples.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Writes `count` frames of 8-bit 4:2:0 y4m (the test pattern, chroma 200) to `path`.
fn write_c420(path: &Path, count: usize) {
    let frames: Vec<Vec<u8>> = (0..count)
        .map(|f| {
            let mut bytes = pattern8(f);
            bytes.extend(std::iter::repeat_n(200u8, 2 * (W / 2) * (H / 2)));
            bytes
        })
        .collect();
    std::fs::write(
        path,
        y4m_file(&format!("YUV4MPEG2 W{W} H{H} F25:1 C420jpeg"), &frames),
    )
    .unwrap();
}

/// Writes `count` frames of 10-bit 4:2:0 y4m (the test pattern, chroma 512) to `path`.
fn write_c420p10(path: &Path, count: usize) {
    let frames: Vec<Vec<u8>> = (0..count)
        .map(|f| {
            let mut samples = pattern16(f, 1023);
            samples.extend(std::iter::repeat_n(512u16, 2 * (W / 2) * (H / 2)));
            le_bytes(&samples)
        })
        .collect();
    std::fs::write(
        path,
        y4m_file(&format!("YUV4MPEG2 W{W} H{H} F25:1 C420p10"), &frames),
    )
    .unwrap();
}

#[test]
fn y4m_8_bit_mono_round_trips_with_header_rate() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("a.y4m");
    let frames: Vec<Vec<u8>> = (0..4).map(pattern8).collect();
    std::fs::write(
        &path,
        y4m_file(
            &format!("YUV4MPEG2 W{W} H{H} F960000:1001 Ip A1:1 Cmono"),
            &frames,
        ),
    )
    .unwrap();
    let mut source = open(&path, &options()).unwrap();
    let format = source.format().clone();
    assert_eq!((format.width, format.height, format.bit_depth), (W, H, 8));
    assert_eq!((format.black_level, format.white_level), (0.0, 255.0));
    assert!((format.fps - 960000.0 / 1001.0).abs() < 1e-9);
    let got = read_all(source.as_mut()).unwrap();
    assert_eq!(got.len(), 4);
    for (f, frame) in got.iter().enumerate() {
        assert_eq!(u8s(frame), frames[f].as_slice());
    }
    // --fps overrides the header.
    let source = open(
        &path,
        &OpenOptions {
            fps: Some(120.0),
            raw: None,
        },
    )
    .unwrap();
    assert_eq!(source.format().fps, 120.0);
}

#[test]
fn y4m_16_bit_mono_round_trips() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("a16.y4m");
    let frames: Vec<Vec<u16>> = (0..3).map(|f| pattern16(f, 65535)).collect();
    let bytes: Vec<Vec<u8>> = frames.iter().map(|f| le_bytes(f)).collect();
    std::fs::write(
        &path,
        y4m_file(&format!("YUV4MPEG2 W{W} H{H} F30:1 Cmono16"), &bytes),
    )
    .unwrap();
    let mut source = Y4mSource::open(&path, None).unwrap();
    assert_eq!(source.format().bit_depth, 16);
    assert_eq!(source.format().white_level, 65535.0);
    assert_eq!(source.format().fps, 30.0);
    let got = read_all(&mut source).unwrap();
    assert_eq!(got.len(), 3);
    for (f, frame) in got.iter().enumerate() {
        assert_eq!(u16s(frame), frames[f].as_slice());
    }
}

#[test]
fn y4m_with_chroma_skips_it_between_frames() {
    let tmp = tempfile::tempdir().unwrap();
    // 8-bit 4:2:0: luma then two quarter-size chroma planes per frame.
    let path = tmp.path().join("c420.y4m");
    write_c420(&path, 3);
    let got = read_all(open(&path, &options()).unwrap().as_mut()).unwrap();
    assert_eq!(got.len(), 3);
    for (f, frame) in got.iter().enumerate() {
        assert_eq!(u8s(frame), pattern8(f).as_slice());
    }
    // 10-bit 4:2:0, two bytes per sample.
    let path = tmp.path().join("c420p10.y4m");
    write_c420p10(&path, 2);
    let mut source = open(&path, &options()).unwrap();
    assert_eq!(source.format().bit_depth, 10);
    assert_eq!(source.format().white_level, 1023.0);
    let got = read_all(source.as_mut()).unwrap();
    assert_eq!(got.len(), 2);
    for (f, frame) in got.iter().enumerate() {
        assert_eq!(u16s(frame), pattern16(f, 1023).as_slice());
    }
}

/// Reads every frame of `source` into one reused buffer; returns the frames (copies) and
/// whether every frame landed in the buffer's first storage (no allocation after the first).
fn read_reusing(source: &mut dyn FrameSource) -> (Vec<Samples>, bool) {
    let mut samples = Samples::U8(Vec::new());
    let mut frames = Vec::new();
    let mut storage: Option<*const u8> = None;
    let mut reused = true;
    while let Some(index) = source.read_frame_into(&mut samples).unwrap() {
        assert_eq!(index, frames.len());
        let address = match &samples {
            Samples::U8(v) => v.as_ptr(),
            Samples::U16(v) => v.as_ptr().cast(),
        };
        reused &= *storage.get_or_insert(address) == address;
        frames.push(samples.clone());
    }
    (frames, reused)
}

#[test]
fn y4m_and_raw_frames_are_read_into_the_same_storage() {
    let tmp = tempfile::tempdir().unwrap();
    // 8-bit 4:2:0 and 10-bit 4:2:0 y4m: luma into the reused frame, chroma skipped.
    let path = tmp.path().join("c420.y4m");
    write_c420(&path, 5);
    let (got, reused) = read_reusing(&mut Y4mSource::open(&path, None).unwrap());
    assert!(
        reused,
        "every 8-bit frame read into the first frame's storage"
    );
    let expected: Vec<Samples> = (0..5).map(|f| Samples::U8(pattern8(f))).collect();
    assert_eq!(got, expected);
    let path = tmp.path().join("c420p10.y4m");
    write_c420p10(&path, 4);
    let (got, reused) = read_reusing(&mut Y4mSource::open(&path, None).unwrap());
    assert!(
        reused,
        "every 10-bit frame read into the first frame's storage"
    );
    let expected: Vec<Samples> = (0..4).map(|f| Samples::U16(pattern16(f, 1023))).collect();
    assert_eq!(got, expected);
    // Raw 16-bit frames from a file.
    let path = tmp.path().join("frames.raw");
    let raw: Vec<u8> = (0..3)
        .flat_map(|f| le_bytes(&pattern16(f, 65535)))
        .collect();
    std::fs::write(&path, raw).unwrap();
    let layout = RawLayout {
        width: W,
        height: H,
        bit_depth: 16,
    };
    let mut source = open(
        &path,
        &OpenOptions {
            fps: None,
            raw: Some(layout),
        },
    )
    .unwrap();
    let (got, reused) = read_reusing(source.as_mut());
    assert!(
        reused,
        "every raw frame read into the first frame's storage"
    );
    let expected: Vec<Samples> = (0..3).map(|f| Samples::U16(pattern16(f, 65535))).collect();
    assert_eq!(got, expected);
}

/// Frames larger than a file's read buffer: the luma plane goes straight into the frame and the
/// chroma is seeked over in a file, read and dropped in a stream; both give the same frames, and
/// a file cut inside a frame's chroma names that frame.
#[test]
fn large_y4m_frames_read_the_same_from_a_file_and_a_stream() {
    const WIDE: usize = 400;
    const TALL: usize = 300;
    let luma = |f: usize| -> Vec<u8> {
        (0..WIDE * TALL)
            .map(|i| ((i % WIDE) * 3 + (i / WIDE) * 5 + f * 11) as u8)
            .collect()
    };
    let frames: Vec<Vec<u8>> = (0..4)
        .map(|f| {
            let mut bytes = luma(f);
            bytes.extend(std::iter::repeat_n(
                (90 + f) as u8,
                2 * (WIDE / 2) * (TALL / 2),
            ));
            bytes
        })
        .collect();
    let bytes = y4m_file(
        &format!("YUV4MPEG2 W{WIDE} H{TALL} F1000:1 C420jpeg"),
        &frames,
    );
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("large.y4m");
    std::fs::write(&path, &bytes).unwrap();
    let (from_file, reused) = read_reusing(&mut Y4mSource::open(&path, None).unwrap());
    assert!(reused, "every frame read into the first frame's storage");
    let expected: Vec<Samples> = (0..4).map(|f| Samples::U8(luma(f))).collect();
    assert_eq!(from_file, expected);
    let stream = std::io::BufReader::new(std::io::Cursor::new(bytes.clone()));
    let (from_stream, _) = read_reusing(&mut Y4mSource::from_reader(stream, &path, None).unwrap());
    assert_eq!(from_stream, expected);
    // Cut inside the chroma of the last frame (3).
    let mut cut = bytes;
    cut.truncate(cut.len() - (WIDE / 2) * (TALL / 2) - 7);
    std::fs::write(&path, &cut).unwrap();
    let mut source = Y4mSource::open(&path, None).unwrap();
    assert!(source.next_frame().unwrap().is_some());
    assert!(source.next_frame().unwrap().is_some());
    assert!(source.next_frame().unwrap().is_some());
    let error = source.next_frame().unwrap_err().to_string();
    assert!(error.contains("truncated inside frame 3"), "{error}");
}

#[test]
fn y4m_truncated_inside_chroma_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("cut.y4m");
    let frames: Vec<Vec<u8>> = (0..2)
        .map(|f| {
            let mut bytes = pattern8(f);
            bytes.extend(std::iter::repeat_n(128u8, 2 * (W / 2) * (H / 2)));
            bytes
        })
        .collect();
    let mut bytes = y4m_file(&format!("YUV4MPEG2 W{W} H{H} F25:1 C420jpeg"), &frames);
    bytes.truncate(bytes.len() - 5);
    std::fs::write(&path, bytes).unwrap();
    let mut source = open(&path, &options()).unwrap();
    assert!(source.next_frame().unwrap().is_some());
    let error = source.next_frame().unwrap_err();
    assert!(
        error.to_string().contains("truncated inside frame 1"),
        "{error}"
    );
}

#[test]
fn y4m_limited_range_header_sets_video_levels() {
    // FFmpeg writes `XCOLORRANGE=LIMITED` for tv-range video: full scale is 16..235.
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("tv.y4m");
    let frames = vec![vec![235u8; W * H], vec![16u8; W * H]];
    std::fs::write(
        &path,
        y4m_file(
            &format!("YUV4MPEG2 W{W} H{H} F30:1 Ip A0:0 Cmono XCOLORRANGE=LIMITED"),
            &frames,
        ),
    )
    .unwrap();
    let source = open(&path, &options()).unwrap();
    let format = source.format();
    assert_eq!((format.black_level, format.white_level), (16.0, 235.0));
    assert_eq!(format.to_fraction(235.0), 1.0);
    assert_eq!(format.to_fraction(16.0), 0.0);
    // 10-bit limited range scales the levels by 4; an explicit FULL keeps 0..1023.
    let path10 = tmp.path().join("tv10.y4m");
    std::fs::write(
        &path10,
        y4m_file(
            &format!("YUV4MPEG2 W{W} H{H} F30:1 Cmono10 XCOLORRANGE=LIMITED"),
            &[],
        ),
    )
    .unwrap();
    let format = open(&path10, &options()).unwrap().format().clone();
    assert_eq!((format.black_level, format.white_level), (64.0, 940.0));
    let full = tmp.path().join("pc.y4m");
    std::fs::write(
        &full,
        y4m_file(
            &format!("YUV4MPEG2 W{W} H{H} F30:1 Cmono XCOLORRANGE=FULL"),
            &frames,
        ),
    )
    .unwrap();
    let format = open(&full, &options()).unwrap().format().clone();
    assert_eq!((format.black_level, format.white_level), (0.0, 255.0));
}

#[test]
fn y4m_bad_headers_and_markers_are_format_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: [(&str, &[u8], &str); 7] = [
        ("notyuv.y4m", b"RIFF1234\n", "not a YUV4MPEG2"),
        (
            "deep.y4m",
            b"YUV4MPEG2 W4 H2 C420p99\n",
            "unsupported bit depth 99",
        ),
        (
            "zero.y4m",
            b"YUV4MPEG2 W4 H2 C420p0\n",
            "unsupported bit depth 0",
        ),
        (
            "huge.y4m",
            b"YUV4MPEG2 W4000000000000 H4000000000000 Cmono\n",
            "too large",
        ),
        (
            "nosize.y4m",
            b"YUV4MPEG2 F30:1 Cmono\n",
            "missing frame size",
        ),
        ("badwidth.y4m", b"YUV4MPEG2 Wx H4 Cmono\n", "bad width"),
        ("empty.y4m", b"", "not a YUV4MPEG2"),
    ];
    for (name, bytes, reason) in cases {
        let path = tmp.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let error = open(&path, &options()).err().expect("an error");
        assert!(
            matches!(error, CaptureError::Format { .. }) && error.to_string().contains(reason),
            "{name}: {error}"
        );
    }
    // A header promising enormous frames over a few bytes of data: truncated, not an abort.
    let path = tmp.path().join("big.y4m");
    std::fs::write(
        &path,
        y4m_file("YUV4MPEG2 W100000 H100000 Cmono16", &[vec![1u8; 64]]),
    )
    .unwrap();
    let error = open(&path, &options()).unwrap().next_frame().unwrap_err();
    assert!(
        error.to_string().contains("truncated inside frame 0"),
        "{error}"
    );
    let path = tmp.path().join("nomarker.y4m");
    let mut bytes = y4m_file("YUV4MPEG2 W4 H2 F30:1 Cmono", &[vec![1u8; 8]]);
    bytes.extend_from_slice(b"FRAMX\n12345678");
    std::fs::write(&path, bytes).unwrap();
    let mut source = open(&path, &options()).unwrap();
    assert!(source.next_frame().unwrap().is_some());
    let error = source.next_frame().unwrap_err();
    assert!(
        error.to_string().contains("missing FRAME marker"),
        "{error}"
    );
}

// ---------------------------------------------------------------------------------------------
// Raw frames

fn raw_options(bit_depth: u8) -> OpenOptions {
    OpenOptions {
        fps: Some(480.0),
        raw: Some(RawLayout {
            width: W,
            height: H,
            bit_depth,
        }),
    }
}

#[test]
fn raw_8_bit_round_trips() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("frames.bin");
    let frames: Vec<Vec<u8>> = (0..5).map(pattern8).collect();
    std::fs::write(&path, frames.concat()).unwrap();
    let mut source = open(&path, &raw_options(8)).unwrap();
    let format = source.format().clone();
    assert_eq!(
        (format.width, format.height, format.bit_depth, format.fps),
        (W, H, 8, 480.0)
    );
    assert_eq!(source.frame_count_hint(), Some(5));
    let got = read_all(source.as_mut()).unwrap();
    assert_eq!(got.len(), 5);
    for (f, frame) in got.iter().enumerate() {
        assert_eq!(u8s(frame), frames[f].as_slice());
    }
}

#[test]
fn raw_12_and_16_bit_round_trip_little_endian() {
    let tmp = tempfile::tempdir().unwrap();
    for (bits, max) in [(12u8, 4095u32), (16, 65535)] {
        let path = tmp.path().join(format!("frames{bits}.raw"));
        let frames: Vec<Vec<u16>> = (0..3).map(|f| pattern16(f, max)).collect();
        std::fs::write(
            &path,
            frames.iter().flat_map(|f| le_bytes(f)).collect::<Vec<_>>(),
        )
        .unwrap();
        let mut source = open(&path, &raw_options(bits)).unwrap();
        assert_eq!(source.format().bit_depth, bits);
        assert_eq!(source.format().white_level, max as f32);
        let got = read_all(source.as_mut()).unwrap();
        assert_eq!(got.len(), 3);
        for (f, frame) in got.iter().enumerate() {
            assert_eq!(u16s(frame), frames[f].as_slice(), "{bits}-bit frame {f}");
        }
    }
}

#[test]
fn raw_file_with_partial_frame_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("cut.raw");
    let mut bytes = [pattern8(0), pattern8(1)].concat();
    bytes.truncate(bytes.len() - 1);
    std::fs::write(&path, &bytes).unwrap();
    let error = open(&path, &raw_options(8)).err().expect("an error");
    assert!(
        matches!(error, CaptureError::Format { .. })
            && error.to_string().contains("not a whole number"),
        "{error}"
    );
    // Two-byte samples: an odd byte count is never whole frames either.
    let error = open(&path, &raw_options(16)).err().expect("an error");
    assert!(error.to_string().contains("not a whole number"), "{error}");
}

#[test]
fn raw_needs_a_valid_layout() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("frames.raw");
    std::fs::write(&path, pattern8(0)).unwrap();
    let error = open(&path, &options()).err().expect("an error");
    assert!(
        error.to_string().contains("raw frames need their layout"),
        "{error}"
    );
    for layout in [
        RawLayout {
            width: 0,
            height: H,
            bit_depth: 8,
        },
        RawLayout {
            width: W,
            height: H,
            bit_depth: 0,
        },
        RawLayout {
            width: W,
            height: H,
            bit_depth: 17,
        },
        RawLayout {
            width: usize::MAX / 2,
            height: 3,
            bit_depth: 16,
        },
    ] {
        let opts = OpenOptions {
            fps: None,
            raw: Some(layout),
        };
        assert!(open(&path, &opts).is_err(), "{layout:?}");
    }
}

#[test]
fn missing_input_is_an_io_error() {
    let tmp = tempfile::tempdir().unwrap();
    let error = open(&tmp.path().join("nothing.mp4"), &options())
        .err()
        .expect("an error");
    assert!(matches!(error, CaptureError::Io { .. }), "{error}");
}

// ---------------------------------------------------------------------------------------------
// Video containers through FFmpeg

/// Raw 4:2:0 frames: the given luma plane and neutral chroma.
fn yuv420_8(luma: &[u8]) -> Vec<u8> {
    let mut bytes = luma.to_vec();
    bytes.extend(std::iter::repeat_n(128u8, 2 * (W / 2) * (H / 2)));
    bytes
}

fn yuv420_10(luma: &[u16]) -> Vec<u8> {
    let mut samples = luma.to_vec();
    samples.extend(std::iter::repeat_n(512u16, 2 * (W / 2) * (H / 2)));
    le_bytes(&samples)
}

/// Encodes raw frames in `pix_fmt` with FFmpeg; `input_args` go before `-i`, `output_args`
/// after it. No pixel-format conversion happens: the encoder gets `pix_fmt` as it is.
fn encode(
    dir: &Path,
    name: &str,
    raw: &[u8],
    pix_fmt: &str,
    input_args: &[&str],
    output_args: &[&str],
) -> PathBuf {
    let input = dir.join(format!("{name}.input"));
    std::fs::write(&input, raw).unwrap();
    let out = dir.join(name);
    let status = Command::new("ffmpeg")
        .args(["-v", "error", "-nostdin", "-y"])
        .args(input_args)
        .args(["-f", "rawvideo", "-pix_fmt", pix_fmt, "-s"])
        .arg(format!("{W}x{H}"))
        .args(["-r", "30", "-i"])
        .arg(&input)
        .args(["-pix_fmt", pix_fmt])
        .args(output_args)
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success(), "ffmpeg failed to encode {name}");
    out
}

fn lossless_x264() -> Vec<&'static str> {
    vec!["-c:v", "libx264", "-qp", "0", "-preset", "ultrafast"]
}

#[test]
fn ffv1_gray_8_bit_round_trips() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let frames: Vec<Vec<u8>> = (0..8).map(pattern8).collect();
    let path = encode(
        tmp.path(),
        "g8.mkv",
        &frames.concat(),
        "gray",
        &[],
        &["-c:v", "ffv1"],
    );
    let mut source = FfmpegSource::open(&path, None).unwrap();
    let format = source.format().clone();
    assert_eq!((format.width, format.height, format.bit_depth), (W, H, 8));
    assert_eq!((format.black_level, format.white_level), (0.0, 255.0));
    assert!((format.fps - 30.0).abs() < 1e-6, "{}", format.fps);
    let got = read_all(&mut source).unwrap();
    assert_eq!(got.len(), 8);
    for (f, frame) in got.iter().enumerate() {
        assert_eq!(frame.index, f);
        assert_eq!(u8s(frame), frames[f].as_slice(), "frame {f}");
    }
}

#[test]
fn x264_lossless_8_bit_yuv420_round_trips_with_count_and_fps() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let frames: Vec<Vec<u8>> = (0..16).map(pattern8).collect();
    let raw: Vec<u8> = frames.iter().flat_map(|f| yuv420_8(f)).collect();
    let path = encode(tmp.path(), "x8.mp4", &raw, "yuv420p", &[], &lossless_x264());
    let mut source = open(&path, &options()).unwrap();
    assert_eq!(source.format().bit_depth, 8);
    assert!((source.format().fps - 30.0).abs() < 1e-6);
    assert_eq!(source.frame_count_hint(), Some(16));
    let first = source.next_frame().unwrap().unwrap();
    assert_eq!(source.frame_count_hint(), Some(15));
    let mut got = vec![first];
    got.extend(read_all(source.as_mut()).unwrap());
    assert_eq!(got.len(), 16);
    for (f, frame) in got.iter().enumerate() {
        assert_eq!(u8s(frame), frames[f].as_slice(), "frame {f}");
    }
    // --fps overrides the container's rate (phones store the playback rate).
    let source = open(
        &path,
        &OpenOptions {
            fps: Some(960.0),
            raw: None,
        },
    )
    .unwrap();
    assert_eq!(source.format().fps, 960.0);
    let probed = FfmpegSource::open(&path, None).unwrap();
    assert_eq!(probed.info().frames, Some(16));
    assert_eq!((probed.info().width, probed.info().height), (W, H));
}

#[test]
fn ffv1_gray10_and_x264_high10_round_trip() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let frames: Vec<Vec<u16>> = (0..6).map(|f| pattern16(f, 1023)).collect();
    let gray: Vec<u8> = frames.iter().flat_map(|f| le_bytes(f)).collect();
    let ffv1 = encode(
        tmp.path(),
        "g10.mkv",
        &gray,
        "gray10le",
        &[],
        &["-c:v", "ffv1"],
    );
    let yuv: Vec<u8> = frames.iter().flat_map(|f| yuv420_10(f)).collect();
    let x264 = encode(
        tmp.path(),
        "x10.mp4",
        &yuv,
        "yuv420p10le",
        &[],
        &lossless_x264(),
    );
    for path in [ffv1, x264] {
        let mut source = open(&path, &options()).unwrap();
        assert_eq!(source.format().bit_depth, 10, "{}", path.display());
        let got = read_all(source.as_mut()).unwrap();
        assert_eq!(got.len(), 6, "{}", path.display());
        for (f, frame) in got.iter().enumerate() {
            assert_eq!(
                u16s(frame),
                frames[f].as_slice(),
                "{} frame {f}",
                path.display()
            );
        }
    }
}

#[test]
fn nv12_8_bit_video_is_read_as_8_bit() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let frames: Vec<Vec<u8>> = (0..4).map(pattern8).collect();
    // NV12 has the same sizes as yuv420p: luma, then interleaved chroma.
    let raw: Vec<u8> = frames.iter().flat_map(|f| yuv420_8(f)).collect();
    let path = encode(
        tmp.path(),
        "nv12.nut",
        &raw,
        "nv12",
        &[],
        &["-c:v", "rawvideo"],
    );
    let mut source = open(&path, &options()).unwrap();
    assert_eq!(source.format().bit_depth, 8);
    let got = read_all(source.as_mut()).unwrap();
    assert_eq!(got.len(), 4);
    for (f, frame) in got.iter().enumerate() {
        assert_eq!(u8s(frame), frames[f].as_slice(), "frame {f}");
    }
}

/// Fractions of full scale the reader reports for every pixel of every frame.
fn fractions(path: &Path) -> (Vec<f32>, f32, f32) {
    let mut source = open(path, &options()).unwrap();
    let format = source.format().clone();
    let frames = read_all(source.as_mut()).unwrap();
    let values = frames
        .iter()
        .flat_map(|f| (0..f.samples.len()).map(|i| format.to_fraction(f.samples.code(i))))
        .collect();
    (values, format.black_level, format.white_level)
}

fn assert_same_fractions(full: &[f32], limited: &[f32], tolerance: f32, what: &str) {
    assert_eq!(full.len(), limited.len(), "{what}");
    let worst = full
        .iter()
        .zip(limited)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(
        worst <= tolerance,
        "{what}: fractions differ by up to {worst}"
    );
}

#[test]
fn limited_and_full_range_video_give_the_same_fractions() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    // The same light, once as full-range codes 0..255 and once as video codes 16..235.
    let full: Vec<Vec<u8>> = (0..4).map(pattern8).collect();
    let limited: Vec<Vec<u8>> = full
        .iter()
        .map(|f| {
            f.iter()
                .map(|&v| (16.0 + f32::from(v) * 219.0 / 255.0).round() as u8)
                .collect()
        })
        .collect();
    let tolerance = 0.5 / 219.0 + 1e-6;
    // H.264 4:2:0 with the range flag in the stream.
    let pc = encode(
        tmp.path(),
        "pc.mp4",
        &full.iter().flat_map(|f| yuv420_8(f)).collect::<Vec<_>>(),
        "yuv420p",
        &["-color_range", "pc"],
        &[lossless_x264(), vec!["-color_range", "pc"]].concat(),
    );
    let tv = encode(
        tmp.path(),
        "tv.mp4",
        &limited.iter().flat_map(|f| yuv420_8(f)).collect::<Vec<_>>(),
        "yuv420p",
        &["-color_range", "tv"],
        &[lossless_x264(), vec!["-color_range", "tv"]].concat(),
    );
    let (a, black, white) = fractions(&pc);
    assert_eq!((black, white), (0.0, 255.0));
    let (b, black, white) = fractions(&tv);
    assert_eq!((black, white), (16.0, 235.0));
    assert_same_fractions(&a, &b, tolerance, "x264 yuv420p");
    // Codes stay untouched: the tv file's brightest code is 235, not stretched to 255.
    assert!(b.iter().all(|&x| (-1e-6..=1.0 + 1e-6).contains(&x)));

    // FFV1 grey: the range flag, not the pixel format, decides.
    let pc = encode(
        tmp.path(),
        "pc.mkv",
        &full.concat(),
        "gray",
        &["-color_range", "pc"],
        &["-c:v", "ffv1", "-color_range", "pc"],
    );
    let tv = encode(
        tmp.path(),
        "tv.mkv",
        &limited.concat(),
        "gray",
        &["-color_range", "tv"],
        &["-c:v", "ffv1", "-color_range", "tv"],
    );
    let (a, black, white) = fractions(&pc);
    assert_eq!((black, white), (0.0, 255.0));
    let (b, black, white) = fractions(&tv);
    assert_eq!((black, white), (16.0, 235.0));
    assert_same_fractions(&a, &b, tolerance, "ffv1 gray");
}

#[test]
fn limited_range_10_bit_uses_64_to_940() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let full: Vec<Vec<u16>> = (0..3).map(|f| pattern16(f, 1023)).collect();
    let limited: Vec<Vec<u16>> = full
        .iter()
        .map(|f| {
            f.iter()
                .map(|&v| (64.0 + f32::from(v) * 876.0 / 1023.0).round() as u16)
                .collect()
        })
        .collect();
    let pc = encode(
        tmp.path(),
        "pc10.mp4",
        &full.iter().flat_map(|f| yuv420_10(f)).collect::<Vec<_>>(),
        "yuv420p10le",
        &["-color_range", "pc"],
        &[lossless_x264(), vec!["-color_range", "pc"]].concat(),
    );
    let tv = encode(
        tmp.path(),
        "tv10.mp4",
        &limited
            .iter()
            .flat_map(|f| yuv420_10(f))
            .collect::<Vec<_>>(),
        "yuv420p10le",
        &["-color_range", "tv"],
        &[lossless_x264(), vec!["-color_range", "tv"]].concat(),
    );
    let (a, black, white) = fractions(&pc);
    assert_eq!((black, white), (0.0, 1023.0));
    let (b, black, white) = fractions(&tv);
    assert_eq!((black, white), (64.0, 940.0));
    assert_same_fractions(&a, &b, 0.5 / 876.0 + 1e-6, "x264 10-bit");
}

#[test]
fn rotation_metadata_does_not_transpose_frames() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let frames: Vec<Vec<u8>> = (0..4).map(pattern8).collect();
    let raw: Vec<u8> = frames.iter().flat_map(|f| yuv420_8(f)).collect();
    let plain = encode(
        tmp.path(),
        "plain.mp4",
        &raw,
        "yuv420p",
        &[],
        &lossless_x264(),
    );
    // FFmpeg 5 drops `rotate` when encoding; a stream copy keeps it (as a display matrix).
    let path = tmp.path().join("rot.mp4");
    let status = Command::new("ffmpeg")
        .args(["-v", "error", "-nostdin", "-y", "-i"])
        .arg(&plain)
        .args(["-c", "copy", "-metadata:s:v:0", "rotate=90"])
        .arg(&path)
        .status()
        .unwrap();
    assert!(status.success());
    // The file really carries a rotation (otherwise this test would prove nothing).
    let probe = Command::new("ffprobe")
        .args(["-v", "error", "-show_streams", "-of", "json"])
        .arg(&path)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&probe.stdout);
    assert!(text.contains("rotat"), "no rotation written: {text}");
    let mut source = open(&path, &options()).unwrap();
    assert_eq!((source.format().width, source.format().height), (W, H));
    let got = read_all(source.as_mut()).unwrap();
    assert_eq!(got.len(), 4);
    for (f, frame) in got.iter().enumerate() {
        assert_eq!(u8s(frame), frames[f].as_slice(), "frame {f}");
    }
}

/// Reads a damaged file: an error, or a shorter stream of exactly the original frames.
fn read_truncated(path: &Path, originals: &[Vec<u8>]) -> Result<usize, CaptureError> {
    let mut source = open(path, &options())?;
    let mut count = 0;
    loop {
        match source.next_frame() {
            Ok(Some(frame)) => {
                assert_eq!(
                    u8s(&frame),
                    originals[count].as_slice(),
                    "{}: frame {count} is garbage",
                    path.display()
                );
                count += 1;
            }
            Ok(None) => return Ok(count),
            Err(error) => return Err(error),
        }
    }
}

fn noise_frames(n: usize) -> Vec<Vec<u8>> {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    (0..n)
        .map(|_| {
            (0..W * H)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    (state >> 56) as u8
                })
                .collect()
        })
        .collect()
}

#[test]
fn truncated_videos_are_errors_not_garbage() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    // Noise so every frame is large and a cut lands inside the frame data.
    let frames = noise_frames(16);
    let raw: Vec<u8> = frames.iter().flat_map(|f| yuv420_8(f)).collect();
    let mp4 = encode(
        tmp.path(),
        "fast.mp4",
        &raw,
        "yuv420p",
        &[],
        &[lossless_x264(), vec!["-movflags", "+faststart"]].concat(),
    );
    let plain_mp4 = encode(
        tmp.path(),
        "plain.mp4",
        &raw,
        "yuv420p",
        &[],
        &lossless_x264(),
    );
    let mkv = encode(
        tmp.path(),
        "n.mkv",
        &frames.concat(),
        "gray",
        &[],
        &["-c:v", "ffv1"],
    );
    for (path, must_fail) in [(mp4, true), (plain_mp4, true), (mkv, false)] {
        let bytes = std::fs::read(&path).unwrap();
        let cut = tmp.path().join(format!(
            "cut_{}",
            path.file_name().unwrap().to_string_lossy()
        ));
        std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).unwrap();
        match read_truncated(&cut, &frames) {
            Err(error) => assert!(
                matches!(error, CaptureError::Format { .. }),
                "{}: {error}",
                cut.display()
            ),
            Ok(count) => {
                assert!(
                    !must_fail,
                    "{}: no error after {count} frames",
                    cut.display()
                );
                assert!(count < 16, "{}: all frames from a cut file", cut.display());
            }
        }
    }
}

#[test]
fn garbage_with_a_video_extension_is_a_format_error() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("junk.mp4");
    std::fs::write(&path, vec![0x5au8; 4096]).unwrap();
    let error = open(&path, &options()).err().expect("an error");
    assert!(
        matches!(error, CaptureError::Format { .. }) && error.to_string().contains("ffprobe"),
        "{error}"
    );
}

#[test]
fn missing_ffmpeg_names_the_debian_package() {
    let tmp = tempfile::tempdir().unwrap();
    let empty_path = tmp.path().join("bin");
    std::fs::create_dir_all(&empty_path).unwrap();
    let video = tmp.path().join("x.mp4");
    std::fs::write(&video, b"not decoded: ffprobe is missing").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_meb"))
        .args(["decode"])
        .arg(&video)
        .args(["--leds", "4", "--out"])
        .arg(tmp.path().join("out"))
        .env("PATH", &empty_path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("Debian package `ffmpeg`") && stderr.contains("apt-get install ffmpeg"),
        "{stderr}"
    );
    assert!(!tmp.path().join("out").join("decode.json").exists());
}
