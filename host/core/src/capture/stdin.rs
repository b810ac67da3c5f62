//! Frames on standard input: a y4m stream (recognised by its `YUV4MPEG2` signature) or raw
//! frames of a given layout, so a live camera works through FFmpeg, e.g.
//! `ffmpeg -f v4l2 -i /dev/video0 -f yuv4mpegpipe - | meb video - …`.
//!
//! The stream is read as it arrives and never held whole; a stream cut inside a frame delivers
//! every whole frame before it and then fails with an error naming the frame ([`super::y4m`],
//! [`super::raw`]).

use super::raw::{RawLayout, RawSource};
use super::y4m::Y4mSource;
use super::{CaptureError, FrameSource};
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// The name standard input goes by on the command line and in errors.
pub const STDIN_NAME: &str = "-";

/// Bytes read from standard input at a time.
const BUFFER_BYTES: usize = 1 << 20;

/// Opens a frame stream on `reader` (standard input, or a pipe in tests): raw frames when
/// `raw` gives their layout, else a y4m stream. `fps` overrides the y4m header's rate (raw
/// frames need it only for reporting the chip rate in Hz).
pub fn open_stream<R: Read + Send + 'static>(
    reader: R,
    raw: Option<RawLayout>,
    fps: Option<f64>,
) -> Result<Box<dyn FrameSource>, CaptureError> {
    let name = Path::new("standard input");
    let mut reader = BufReader::with_capacity(BUFFER_BYTES, reader);
    if let Some(layout) = raw {
        return Ok(Box::new(RawSource::from_stream(
            reader,
            name,
            layout,
            fps.unwrap_or(0.0),
        )?));
    }
    let start = reader.fill_buf().map_err(|source| CaptureError::Io {
        path: name.to_path_buf(),
        source,
    })?;
    if start.is_empty() {
        return Err(CaptureError::Format {
            path: name.to_path_buf(),
            reason: "the stream is empty (nothing arrived on standard input)".into(),
        });
    }
    if !b"YUV4MPEG2".iter().zip(start).all(|(a, b)| a == b) {
        return Err(CaptureError::Format {
            path: name.to_path_buf(),
            reason: "not a y4m stream (no YUV4MPEG2 signature): pipe y4m (ffmpeg … -f \
                     yuv4mpegpipe -) or give the layout of raw frames"
                .into(),
        });
    }
    Ok(Box::new(Y4mSource::from_reader(reader, name, fps)?))
}

/// Opens standard input as a frame stream ([`open_stream`]).
pub fn open_stdin(
    raw: Option<RawLayout>,
    fps: Option<f64>,
) -> Result<Box<dyn FrameSource>, CaptureError> {
    open_stream(std::io::stdin(), raw, fps)
}

/// Whether `path` names standard input (`-`).
pub fn is_stdin(path: &Path) -> bool {
    path.as_os_str() == STDIN_NAME
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::Samples;

    fn y4m(frames: &[Vec<u8>]) -> Vec<u8> {
        let mut bytes = b"YUV4MPEG2 W3 H2 F1000:1 Cmono\n".to_vec();
        for f in frames {
            bytes.extend_from_slice(b"FRAME\n");
            bytes.extend_from_slice(f);
        }
        bytes
    }

    #[test]
    fn y4m_on_a_stream_delivers_its_frames_then_ends() {
        let frames = vec![vec![1u8, 2, 3, 4, 5, 6], vec![7u8; 6]];
        let mut source = open_stream(std::io::Cursor::new(y4m(&frames)), None, None).unwrap();
        assert_eq!(source.format().fps, 1000.0);
        for (i, f) in frames.iter().enumerate() {
            let frame = source.next_frame().unwrap().unwrap();
            assert_eq!(
                (frame.index, frame.samples.clone()),
                (i, Samples::U8(f.clone()))
            );
        }
        assert!(source.next_frame().unwrap().is_none());
    }

    #[test]
    fn a_stream_cut_inside_a_frame_keeps_the_frames_before_and_names_the_cut() {
        let mut bytes = y4m(&[vec![9u8; 6], vec![8u8; 6]]);
        bytes.truncate(bytes.len() - 2);
        let mut source = open_stream(std::io::Cursor::new(bytes), None, None).unwrap();
        assert!(source.next_frame().unwrap().is_some());
        let error = source.next_frame().unwrap_err().to_string();
        assert!(
            error.contains("truncated inside frame 1: 10 of its 12 bytes"),
            "{error}"
        );
        // Cut inside the marker line.
        let mut bytes = y4m(&[vec![9u8; 6]]);
        bytes.extend_from_slice(b"FRA");
        let mut source = open_stream(std::io::Cursor::new(bytes), None, None).unwrap();
        assert!(source.next_frame().unwrap().is_some());
        let error = source.next_frame().unwrap_err().to_string();
        assert!(error.contains("inside frame 1: 3 of"), "{error}");
    }

    #[test]
    fn raw_frames_on_a_stream_and_a_cut_one() {
        let layout = RawLayout {
            width: 2,
            height: 2,
            bit_depth: 16,
        };
        let bytes: Vec<u8> = (0u8..20).collect();
        let mut source =
            open_stream(std::io::Cursor::new(bytes), Some(layout), Some(30.0)).unwrap();
        assert_eq!(source.frame_count_hint(), None);
        let first = source.next_frame().unwrap().unwrap();
        assert_eq!(
            first.samples,
            Samples::U16(vec![0x0100, 0x0302, 0x0504, 0x0706])
        );
        assert!(source.next_frame().unwrap().is_some());
        let error = source.next_frame().unwrap_err().to_string();
        assert!(
            error.contains("truncated inside frame 2: 4 of its 8 bytes"),
            "{error}"
        );
        let whole: Vec<u8> = (0u8..16).collect();
        let mut source = open_stream(std::io::Cursor::new(whole), Some(layout), None).unwrap();
        assert!(source.next_frame().unwrap().is_some());
        assert!(source.next_frame().unwrap().is_some());
        assert!(source.next_frame().unwrap().is_none());
    }

    #[test]
    fn empty_and_foreign_streams_are_refused_in_words() {
        let empty = open_stream(std::io::Cursor::new(Vec::new()), None, None)
            .err()
            .expect("an error")
            .to_string();
        assert!(empty.contains("empty"), "{empty}");
        let png = open_stream(std::io::Cursor::new(b"\x89PNG\r\n".to_vec()), None, None)
            .err()
            .expect("an error")
            .to_string();
        assert!(png.contains("not a y4m stream"), "{png}");
    }
}
