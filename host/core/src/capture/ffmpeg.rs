//! Video containers (MP4/MOV/AVI/MKV; H.264, HEVC, 8- and 10-bit) through the `ffmpeg` and
//! `ffprobe` command-line tools (Debian package `ffmpeg`).
//!
//! The luma plane is read untouched: `ffmpeg -v error -nostdin -noautorotate -i IN -map 0:v:0
//! -vf extractplanes=y -fps_mode passthrough -f rawvideo -pix_fmt gray|gray10le|gray12le -`.
//! Grey output formats would otherwise rescale and clip video-range luma, rotation metadata
//! would transpose frames, and a variable frame rate would pad with duplicates. Limited
//! ("tv") range video keeps its codes; its black and white levels (16·2^(b−8) and
//! 235·2^(b−8)) go into the [`FrameFormat`], so decoded images do not depend on the range.

use super::clock::{FrameClock, TimestampGap};
use super::{CaptureError, Frame, FrameFormat, FrameSource, LossyCompression, Samples};
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::thread::JoinHandle;

/// What `ffprobe` reports about the first video stream.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoInfo {
    /// Coded width.
    pub width: usize,
    /// Coded height.
    pub height: usize,
    /// Luma bits per sample.
    pub bit_depth: u8,
    /// Whether the stream is limited ("tv") range.
    pub limited_range: bool,
    /// Frame rate from the container.
    pub fps: f64,
    /// Frame count when the container states it.
    pub frames: Option<usize>,
    /// Codec name (`h264`, `hevc`, `ffv1`, …).
    pub codec: String,
    /// The stream's bit rate (bits/s) when the container states it.
    pub bit_rate: Option<u64>,
}

/// FFmpeg's names of the lossless video codecs a capture may come in; every other codec is
/// taken as lossy.
const LOSSLESS_CODECS: [&str; 14] = [
    "rawvideo", "ffv1", "huffyuv", "ffvhuff", "png", "apng", "utvideo", "magicyuv", "qtrle",
    "v210", "v410", "r210", "tiff", "zlib",
];

impl VideoInfo {
    /// The stream's lossy compression (`None` for a lossless codec).
    pub fn lossy_compression(&self) -> Option<LossyCompression> {
        if LOSSLESS_CODECS.contains(&self.codec.as_str()) {
            return None;
        }
        let pixels = (self.width * self.height) as f64 * self.fps;
        Some(LossyCompression {
            codec: self.codec.clone(),
            bits_per_pixel: self
                .bit_rate
                .filter(|_| pixels > 0.0)
                .map(|rate| rate as f64 / pixels),
        })
    }
}

/// Error for a missing FFmpeg tool.
fn missing_tool(tool: &str, error: &std::io::Error) -> CaptureError {
    CaptureError::Other(format!(
        "cannot run `{tool}` ({error}): video files need FFmpeg — install the Debian package \
         `ffmpeg` (sudo apt-get install ffmpeg) or convert the video to PNG/TIFF frames"
    ))
}

/// Parses "num/den" rates.
fn parse_rate(value: Option<&serde_json::Value>) -> Option<f64> {
    let text = value?.as_str()?;
    let (num, den) = text.split_once('/').unwrap_or((text, "1"));
    let (num, den): (f64, f64) = (num.parse().ok()?, den.parse().ok()?);
    (den > 0.0 && num > 0.0).then_some(num / den)
}

/// Luma bits per sample of an FFmpeg pixel format name: `yuv420p10le` → 10, `gray12le` → 12,
/// `p010le` → 10; `yuv420p`, `nv12`, `yuv410p` and anything unknown → 8.
fn pix_fmt_bit_depth(pix_fmt: &str) -> u8 {
    let base = pix_fmt
        .strip_suffix("le")
        .or_else(|| pix_fmt.strip_suffix("be"))
        .unwrap_or(pix_fmt);
    let (stem, digits) = base.split_at(base.trim_end_matches(|c: char| c.is_ascii_digit()).len());
    let bits: Option<u8> =
        if stem == "gray" || stem == "ya" || (stem.starts_with("yuv") && stem.ends_with('p')) {
            digits.parse().ok()
        } else if stem == "p" && digits.len() == 3 {
            // Semi-planar high depth: p010, p012, p016, p210, p410, …
            digits[1..].parse().ok()
        } else {
            None
        };
    bits.filter(|b| (9..=16).contains(b)).unwrap_or(8)
}

/// Whether a stream is limited ("tv") range: the container's flag decides; without one, JPEG
/// (`yuvj*`) and grey formats are full range and video formats are limited.
fn is_limited_range(color_range: Option<&str>, pix_fmt: &str) -> bool {
    match color_range {
        Some("tv" | "mpeg") => true,
        Some("pc" | "jpeg") => false,
        _ => !(pix_fmt.starts_with("yuvj") || pix_fmt.starts_with("gray")),
    }
}

/// Runs `ffprobe -v error -select_streams v:0 ENTRIES -of json` on `path`; its JSON output.
fn ffprobe_json(path: &Path, entries: &[&str]) -> Result<serde_json::Value, CaptureError> {
    let output = Command::new("ffprobe")
        .args(["-v", "error", "-select_streams", "v:0"])
        .args(entries)
        .args(["-of", "json"])
        .arg(path)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| missing_tool("ffprobe", &e))?;
    let bad = |reason: String| CaptureError::Format {
        path: path.to_path_buf(),
        reason,
    };
    if !output.status.success() {
        return Err(bad(format!(
            "ffprobe failed: {}",
            String::from_utf8_lossy(&output.stderr).trim()
        )));
    }
    serde_json::from_slice(&output.stdout)
        .map_err(|e| bad(format!("unreadable ffprobe output: {e}")))
}

/// Runs `ffprobe` on `path`.
pub fn probe(path: &Path) -> Result<VideoInfo, CaptureError> {
    let json = ffprobe_json(path, &["-show_streams"])?;
    let bad = |reason: String| CaptureError::Format {
        path: path.to_path_buf(),
        reason,
    };
    let stream = json
        .get("streams")
        .and_then(|s| s.get(0))
        .ok_or_else(|| bad("no video stream".into()))?;
    let number = |key: &str| stream.get(key).and_then(serde_json::Value::as_u64);
    let width = number("width").ok_or_else(|| bad("video stream has no width".into()))? as usize;
    let height = number("height").ok_or_else(|| bad("video stream has no height".into()))? as usize;
    let pix_fmt = stream.get("pix_fmt").and_then(|v| v.as_str()).unwrap_or("");
    let bit_depth = pix_fmt_bit_depth(pix_fmt);
    let range = stream.get("color_range").and_then(|v| v.as_str());
    let limited_range = is_limited_range(range, pix_fmt);
    let frames = stream
        .get("nb_frames")
        .and_then(|v| v.as_str())
        .and_then(|s| s.parse().ok());
    let fps = parse_rate(stream.get("avg_frame_rate"))
        .or_else(|| parse_rate(stream.get("r_frame_rate")))
        .unwrap_or(0.0);
    let codec = stream
        .get("codec_name")
        .and_then(|v| v.as_str())
        .unwrap_or("unknown")
        .to_string();
    let bit_rate = stream
        .get("bit_rate")
        .and_then(|v| v.as_str())
        .and_then(|s| s.parse().ok());
    Ok(VideoInfo {
        width,
        height,
        bit_depth,
        limited_range,
        fps,
        frames,
        codec,
        bit_rate,
    })
}

/// The presentation times (seconds, sorted) of the first video stream's packets in `path`
/// and the seconds per tick of its time base (0 when unknown), from `ffprobe`.
pub fn frame_times(path: &Path) -> Result<(Vec<f64>, f64), CaptureError> {
    let json = ffprobe_json(path, &["-show_entries", "stream=time_base:packet=pts"])?;
    let tick = json
        .get("streams")
        .and_then(|s| s.get(0))
        .and_then(|s| s.get("time_base"))
        .and_then(|t| t.as_str())
        .and_then(|t| {
            let (n, d) = t.split_once('/')?;
            let (n, d) = (n.parse::<f64>().ok()?, d.parse::<f64>().ok()?);
            (n > 0.0 && d > 0.0).then_some(n / d)
        })
        .unwrap_or(0.0);
    let mut times: Vec<f64> = json
        .get("packets")
        .and_then(|p| p.as_array())
        .map(|packets| {
            packets
                .iter()
                .filter_map(|p| p.get("pts").and_then(serde_json::Value::as_i64))
                .map(|pts| pts as f64 * tick)
                .collect()
        })
        .unwrap_or_default();
    if tick == 0.0 {
        times.clear();
    }
    times.sort_by(f64::total_cmp);
    Ok((times, tick))
}

/// A video decoded by an `ffmpeg` child process, one frame at a time from its pipe.
pub struct FfmpegSource {
    format: FrameFormat,
    info: VideoInfo,
    gaps: Vec<TimestampGap>,
    path: PathBuf,
    child: Child,
    stdout: BufReader<ChildStdout>,
    stderr: Option<JoinHandle<String>>,
    index: usize,
    done: bool,
}

impl FfmpegSource {
    /// Probes and starts decoding `path`; `fps` overrides the container's rate. Without it,
    /// the container's timestamps are judged ([`FrameClock`]): a variable frame rate is
    /// refused, and frames missing between them are kept as [`FrameSource::timestamp_gaps`].
    pub fn open(path: &Path, fps: Option<f64>) -> Result<Self, CaptureError> {
        let info = probe(path)?;
        let gaps = if fps.is_some() {
            Vec::new()
        } else {
            let (times, tick) = frame_times(path)?;
            match FrameClock::judge(&times, tick) {
                FrameClock::Regular => Vec::new(),
                FrameClock::Gaps(gaps) => gaps,
                FrameClock::Irregular {
                    frame,
                    periods,
                    period_s,
                } => {
                    return Err(CaptureError::IrregularFrameTimes {
                        path: path.to_path_buf(),
                        frame,
                        periods,
                        period_ms: period_s * 1e3,
                    });
                }
            }
        };
        let pix_fmt = match info.bit_depth {
            8 => "gray",
            10 => "gray10le",
            12 => "gray12le",
            _ => "gray16le",
        };
        let mut child = Command::new("ffmpeg")
            .args(["-v", "error", "-nostdin", "-noautorotate", "-i"])
            .arg(path)
            .args([
                "-map",
                "0:v:0",
                "-vf",
                "extractplanes=y",
                "-fps_mode",
                "passthrough",
            ])
            .args(["-f", "rawvideo", "-pix_fmt", pix_fmt, "-"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| missing_tool("ffmpeg", &e))?;
        let (Some(stdout), Some(mut stderr)) = (child.stdout.take(), child.stderr.take()) else {
            return Err(CaptureError::Other("ffmpeg pipes unavailable".into()));
        };
        let stderr = std::thread::spawn(move || {
            let mut text = String::new();
            let _ = stderr.read_to_string(&mut text);
            text
        });
        let scale = f32::from(1u16 << (info.bit_depth.min(16) - 8).min(8));
        let mut format = FrameFormat::full_range(
            info.width,
            info.height,
            info.bit_depth,
            fps.unwrap_or(info.fps),
        );
        if info.limited_range {
            format.black_level = 16.0 * scale;
            format.white_level = 235.0 * scale;
        }
        Ok(Self {
            format,
            info,
            gaps,
            path: path.to_path_buf(),
            child,
            stdout: BufReader::with_capacity(1 << 20, stdout),
            stderr: Some(stderr),
            index: 0,
            done: false,
        })
    }

    /// What ffprobe reported.
    pub fn info(&self) -> &VideoInfo {
        &self.info
    }

    /// Reads exactly `buf.len()` bytes; returns the count read before end of stream.
    fn fill(&mut self, buf: &mut [u8]) -> Result<usize, CaptureError> {
        super::read_up_to(&mut self.stdout, buf, &self.path)
    }

    /// Ends the stream: checks ffmpeg's exit status and error output.
    fn finish(&mut self, partial: usize) -> Result<(), CaptureError> {
        self.done = true;
        let status = self.child.wait().map_err(|source| CaptureError::Io {
            path: self.path.clone(),
            source,
        })?;
        let messages = self
            .stderr
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default();
        let first_line = messages.lines().next().unwrap_or("").trim().to_string();
        let bad = |reason: String| CaptureError::Format {
            path: self.path.clone(),
            reason,
        };
        if !status.success() {
            return Err(bad(format!("ffmpeg failed ({status}): {first_line}")));
        }
        if partial > 0 {
            return Err(bad(format!(
                "video is truncated: frame {} ends after {partial} bytes",
                self.index
            )));
        }
        if !first_line.is_empty() {
            return Err(bad(format!(
                "video is truncated or corrupt after {} frames: {first_line}",
                self.index
            )));
        }
        if let Some(expected) = self.info.frames
            && self.index < expected
        {
            return Err(bad(format!(
                "video is truncated: {} of {expected} frames decoded",
                self.index
            )));
        }
        Ok(())
    }
}

impl FrameSource for FfmpegSource {
    fn format(&self) -> &FrameFormat {
        &self.format
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
        if self.done {
            return Ok(None);
        }
        let pixels = self.format.pixels();
        let mut bytes = vec![0u8; Samples::bytes_per_sample(self.format.bit_depth) * pixels];
        let got = self.fill(&mut bytes)?;
        if got < bytes.len() {
            self.finish(got)?;
            return Ok(None);
        }
        let samples = Samples::from_le_bytes(bytes, self.format.bit_depth);
        let frame = Frame {
            index: self.index,
            samples,
        };
        self.index += 1;
        Ok(Some(frame))
    }

    fn frame_count_hint(&self) -> Option<usize> {
        self.info.frames.map(|n| n.saturating_sub(self.index))
    }

    fn lossy_compression(&self) -> Option<LossyCompression> {
        self.info.lossy_compression()
    }

    fn timestamp_gaps(&self) -> Vec<TimestampGap> {
        self.gaps.clone()
    }
}

impl Drop for FfmpegSource {
    fn drop(&mut self) {
        if !self.done {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{is_limited_range, pix_fmt_bit_depth};

    #[test]
    fn bit_depth_from_pixel_format_names() {
        for (name, bits) in [
            ("yuv420p", 8),
            ("yuvj420p", 8),
            ("yuv410p", 8),
            ("nv12", 8),
            ("nv21", 8),
            ("gray", 8),
            ("yuv420p10le", 10),
            ("yuv422p10be", 10),
            ("yuv444p12le", 12),
            ("yuva444p16le", 16),
            ("gray10le", 10),
            ("gray12le", 12),
            ("gray16be", 16),
            ("p010le", 10),
            ("p016le", 16),
            ("rgb24", 8),
            ("", 8),
        ] {
            assert_eq!(pix_fmt_bit_depth(name), bits, "{name}");
        }
    }

    #[test]
    fn range_flag_wins_over_pixel_format() {
        assert!(is_limited_range(Some("tv"), "gray"));
        assert!(is_limited_range(Some("tv"), "yuvj420p"));
        assert!(!is_limited_range(Some("pc"), "yuv420p"));
        assert!(is_limited_range(None, "yuv420p10le"));
        assert!(is_limited_range(Some("unknown"), "nv12"));
        assert!(!is_limited_range(Some("unknown"), "gray10le"));
        assert!(!is_limited_range(None, "yuvj420p"));
    }
}
