//! Writing sequences of pictures as videos: H.264 MP4 through the `ffmpeg` program, or
//! animated PNGs (APNG, the `png` crate) when FFmpeg is not installed.
//!
//! A [`VideoEncoder`] writes several videos of the same picture size side by side, one picture
//! of each per step. MP4: one FFmpeg process takes them all, stacked one above the other as
//! one raw `yuv420p` frame (converted here, \[`super::yuv`\]), and splits and crops them back
//! into one `libx264` MP4 each (`-filter_complex split,crop`; no conversion in FFmpeg). Each
//! picture is piped as it is made, so nothing accumulates in memory, and the process starts
//! once: FFmpeg's start-up (dynamic linking of its 200-odd libraries) costs about 60 ms of CPU,
//! which a second process would pay again while the first window is being read and decoded.
//! APNG needs its frame count before the first frame, which a stream does not know: each
//! picture is stored as a PNG under a hidden folder as it comes, and [`VideoEncoder::finish`]
//! assembles them one at a time into the animation and deletes them.

use super::VideoError;
use image::RgbImage;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::thread::JoinHandle;

/// Which container to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VideoContainer {
    /// MP4 when FFmpeg runs, else APNG.
    #[default]
    Auto,
    /// Animated PNG.
    Apng,
}

/// Pictures stored for one APNG.
pub struct ApngStore {
    /// The video file.
    pub path: PathBuf,
    /// Folder of the stored pictures.
    pub frames: PathBuf,
}

/// Videos being written, one picture of each per step.
pub enum VideoEncoder {
    /// Pictures piped to one FFmpeg, stacked.
    Mp4 {
        /// The video files, in the order of the pictures.
        paths: Vec<PathBuf>,
        /// FFmpeg.
        child: Child,
        /// Its standard input.
        stdin: Option<BufWriter<ChildStdin>>,
        /// Its error output, collected on a thread.
        stderr: Option<JoinHandle<String>>,
        /// Picture size.
        size: (u32, u32),
        /// The stacked 4:2:0 frame being piped (storage reused).
        frame: Vec<u8>,
    },
    /// Pictures stored for APNGs.
    Apng {
        /// One store per video.
        stores: Vec<ApngStore>,
        /// Steps stored.
        count: usize,
        /// Picture size.
        size: (u32, u32),
        /// Display rate, pictures per second.
        fps: f64,
        /// Why MP4 was not written, when it was asked for (FFmpeg missing).
        fallback: Option<String>,
    },
}

/// FFmpeg's filter graph that splits `videos` pictures stacked in one frame of `width` ×
/// (`videos` · `height`) into outputs `[v0]`, `[v1]` …
fn unstack_filter(videos: usize, width: u32, height: u32) -> String {
    let split: String = (0..videos).map(|k| format!("[s{k}]")).collect();
    let crops: Vec<String> = (0..videos)
        .map(|k| format!("[s{k}]crop={width}:{height}:0:{}[v{k}]", k as u32 * height))
        .collect();
    format!("[0:v]split={videos}{split};{}", crops.join(";"))
}

impl VideoEncoder {
    /// Starts one video per stem, `stem.mp4` (or `stem.png` as APNG), of `width` × `height`
    /// pictures shown at `fps`.
    pub fn create(
        stems: &[PathBuf],
        width: u32,
        height: u32,
        fps: f64,
        container: VideoContainer,
    ) -> Result<Self, VideoError> {
        if stems.is_empty() {
            return Err(VideoError::Encode("no video to write".into()));
        }
        let fps = if fps.is_finite() && fps > 0.0 {
            fps
        } else {
            25.0
        };
        if container == VideoContainer::Auto {
            if !width.is_multiple_of(2) || !height.is_multiple_of(2) {
                return Err(VideoError::Encode(format!(
                    "{width}×{height} pictures cannot be stored as 4:2:0 H.264 (odd size)"
                )));
            }
            let paths: Vec<PathBuf> = stems.iter().map(|s| s.with_extension("mp4")).collect();
            let stacked = height
                .checked_mul(paths.len() as u32)
                .ok_or_else(|| VideoError::Encode(format!("{height}-row pictures are too tall")))?;
            let mut command = Command::new("ffmpeg");
            command
                .args(["-hide_banner", "-loglevel", "error", "-nostdin", "-y"])
                .args(["-f", "rawvideo", "-pix_fmt", "yuv420p"])
                .args(["-s", &format!("{width}x{stacked}")])
                .args(["-framerate", &format!("{fps}"), "-i", "-"])
                .args([
                    "-filter_complex",
                    &unstack_filter(paths.len(), width, height),
                ]);
            for (k, path) in paths.iter().enumerate() {
                command
                    .args(["-map", &format!("[v{k}]")])
                    .args(["-c:v", "libx264", "-preset", "ultrafast", "-crf", "18"])
                    .args(["-pix_fmt", "yuv420p", "-movflags", "+faststart"])
                    .arg(path);
            }
            let spawned = command
                .stdin(Stdio::piped())
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn();
            let fallback = match spawned {
                Ok(mut child) => {
                    let stdin = child.stdin.take().map(BufWriter::new);
                    let stderr = child.stderr.take().map(|mut pipe| {
                        std::thread::spawn(move || {
                            let mut text = String::new();
                            let _ = pipe.read_to_string(&mut text);
                            text
                        })
                    });
                    return Ok(Self::Mp4 {
                        paths,
                        child,
                        stdin,
                        stderr,
                        size: (width, height),
                        frame: Vec::new(),
                    });
                }
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    Some("ffmpeg was not found on PATH: animated PNG instead of MP4".to_string())
                }
                Err(e) => return Err(VideoError::Encode(format!("cannot run ffmpeg: {e}"))),
            };
            return Self::apng(stems, width, height, fps, fallback);
        }
        Self::apng(stems, width, height, fps, None)
    }

    /// Starts one APNG `stem.png` per stem; `fallback` says why they replace MP4s.
    fn apng(
        stems: &[PathBuf],
        width: u32,
        height: u32,
        fps: f64,
        fallback: Option<String>,
    ) -> Result<Self, VideoError> {
        let mut stores = Vec::with_capacity(stems.len());
        for stem in stems {
            let name = stem
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let frames = stem.with_file_name(format!(".{name}-frames"));
            std::fs::create_dir_all(&frames)
                .map_err(|e| meb_core::io::FilesError::write(&frames, e))?;
            stores.push(ApngStore {
                path: stem.with_extension("png"),
                frames,
            });
        }
        Ok(Self::Apng {
            stores,
            count: 0,
            size: (width, height),
            fps,
            fallback,
        })
    }

    /// The container being written: `"mp4"` or `"apng"`.
    pub fn container(&self) -> &'static str {
        match self {
            Self::Mp4 { .. } => "mp4",
            Self::Apng { .. } => "apng",
        }
    }

    /// Why an MP4 that was asked for is written as APNG instead (`None` when it is not).
    pub fn fallback(&self) -> Option<&str> {
        match self {
            Self::Mp4 { .. } => None,
            Self::Apng { fallback, .. } => fallback.as_deref(),
        }
    }

    /// How many videos are written.
    fn videos(&self) -> usize {
        match self {
            Self::Mp4 { paths, .. } => paths.len(),
            Self::Apng { stores, .. } => stores.len(),
        }
    }

    /// Adds one picture (of the videos' size) to each video, in the order of their stems.
    pub fn push(&mut self, pictures: &[&RgbImage]) -> Result<(), VideoError> {
        if pictures.len() != self.videos() {
            return Err(VideoError::Encode(format!(
                "{} pictures for {} videos",
                pictures.len(),
                self.videos()
            )));
        }
        match self {
            Self::Mp4 {
                stdin,
                size,
                paths,
                frame,
                ..
            } => {
                for picture in pictures {
                    check_size(picture, *size)?;
                }
                let Some(stdin) = stdin.as_mut() else {
                    return Err(VideoError::Encode("ffmpeg's input is closed".into()));
                };
                super::yuv::stacked_420(pictures, frame);
                stdin.write_all(frame).map_err(|e| {
                    VideoError::Encode(format!(
                        "ffmpeg stopped taking frames for {} ({e})",
                        listed(paths)
                    ))
                })
            }
            Self::Apng {
                stores,
                count,
                size,
                ..
            } => {
                for picture in pictures {
                    check_size(picture, *size)?;
                }
                for (store, picture) in stores.iter().zip(pictures) {
                    let file = store.frames.join(format!("{count:08}.png"));
                    write_png(&file, picture, png::Compression::Fast)?;
                }
                *count += 1;
                Ok(())
            }
        }
    }

    /// Ends the videos and returns their paths in the order of their stems (`None` for an
    /// APNG without pictures).
    pub fn finish(self) -> Result<Vec<Option<PathBuf>>, VideoError> {
        match self {
            Self::Mp4 {
                paths,
                mut child,
                stdin,
                stderr,
                ..
            } => {
                if let Some(mut stdin) = stdin {
                    stdin
                        .flush()
                        .map_err(|e| VideoError::Encode(format!("ffmpeg stopped early ({e})")))?;
                }
                let status = child
                    .wait()
                    .map_err(|e| VideoError::Encode(format!("waiting for ffmpeg: {e}")))?;
                let messages = stderr.and_then(|h| h.join().ok()).unwrap_or_default();
                if !status.success() {
                    return Err(VideoError::Encode(format!(
                        "ffmpeg could not write {} ({status}): {}",
                        listed(&paths),
                        messages.trim()
                    )));
                }
                Ok(paths.into_iter().map(Some).collect())
            }
            Self::Apng {
                stores,
                count,
                size,
                fps,
                ..
            } => {
                let mut written = Vec::with_capacity(stores.len());
                let mut first_error = None;
                // Every store's folder goes, whether or not its animation could be written.
                for store in stores {
                    let result = if count == 0 {
                        Ok(None)
                    } else {
                        assemble_apng(&store.path, &store.frames, count, size, fps)
                            .map(|()| Some(store.path.clone()))
                    };
                    let removed = std::fs::remove_dir_all(&store.frames).map_err(|e| {
                        VideoError::from(meb_core::io::FilesError::write(&store.frames, e))
                    });
                    match result.and_then(|path| removed.map(|()| path)) {
                        Ok(path) => written.push(path),
                        Err(error) => {
                            first_error.get_or_insert(error);
                        }
                    }
                }
                match first_error {
                    Some(error) => Err(error),
                    None => Ok(written),
                }
            }
        }
    }
}

/// The video files, for messages: "a.mp4, b.mp4".
fn listed(paths: &[PathBuf]) -> String {
    let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    names.join(", ")
}

/// A picture of the wrong size is a bug in the caller, reported instead of encoded.
fn check_size(picture: &RgbImage, size: (u32, u32)) -> Result<(), VideoError> {
    if picture.dimensions() != size {
        return Err(VideoError::Encode(format!(
            "picture is {:?}, the video is {size:?}",
            picture.dimensions()
        )));
    }
    Ok(())
}

/// Writes an RGB picture as a PNG.
fn write_png(
    path: &Path,
    picture: &RgbImage,
    compression: png::Compression,
) -> Result<(), VideoError> {
    let file = std::fs::File::create(path).map_err(|e| meb_core::io::FilesError::write(path, e))?;
    let mut encoder = png::Encoder::new(BufWriter::new(file), picture.width(), picture.height());
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(compression);
    let encode = |e: png::EncodingError| VideoError::Encode(format!("{}: {e}", path.display()));
    let mut writer = encoder.write_header().map_err(encode)?;
    writer.write_image_data(picture.as_raw()).map_err(encode)?;
    writer.finish().map_err(encode)
}

/// Writes the `count` stored pictures in `frames` as one APNG at `path`.
fn assemble_apng(
    path: &Path,
    frames: &Path,
    count: usize,
    size: (u32, u32),
    fps: f64,
) -> Result<(), VideoError> {
    let encode = |e: png::EncodingError| VideoError::Encode(format!("{}: {e}", path.display()));
    let file = std::fs::File::create(path).map_err(|e| meb_core::io::FilesError::write(path, e))?;
    let mut encoder = png::Encoder::new(BufWriter::new(file), size.0, size.1);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Balanced);
    let frames_u32 = u32::try_from(count)
        .map_err(|_| VideoError::Encode(format!("{count} pictures are too many for an APNG")))?;
    encoder.set_animated(frames_u32, 0).map_err(encode)?;
    // Delay 1/fps s as a fraction of 16-bit integers (1000/fps ms, rounded).
    let delay_ms = (1000.0 / fps).round().clamp(1.0, f64::from(u16::MAX)) as u16;
    encoder.set_frame_delay(delay_ms, 1000).map_err(encode)?;
    let mut writer = encoder.write_header().map_err(encode)?;
    let mut buffer = Vec::new();
    for k in 0..count {
        let file = frames.join(format!("{k:08}.png"));
        let decode = |e: png::DecodingError| {
            VideoError::Encode(format!("stored picture {}: {e}", file.display()))
        };
        let reader = std::io::BufReader::new(
            std::fs::File::open(&file).map_err(|e| meb_core::io::FilesError::read(&file, e))?,
        );
        let mut reader = png::Decoder::new(reader).read_info().map_err(decode)?;
        buffer.resize(reader.output_buffer_size().unwrap_or(0), 0);
        reader.next_frame(&mut buffer).map_err(decode)?;
        writer.write_image_data(&buffer).map_err(encode)?;
    }
    writer.finish().map_err(encode)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two MP4s from one FFmpeg: each decodes to its own pictures, in order, within H.264's
    /// loss at CRF 18. FFmpeg is part of the set-up (`scripts/setup.sh`): without it the
    /// encoder falls back to APNG and this test fails.
    #[test]
    fn stacked_mp4s_decode_to_their_own_pictures() {
        let dir = tempfile::tempdir().unwrap();
        let stems = [dir.path().join("depth"), dir.path().join("shaded")];
        let (width, height) = (32u32, 16u32);
        let mut video = VideoEncoder::create(&stems, width, height, 25.0, VideoContainer::Auto)
            .expect("encoder");
        assert_eq!(video.container(), "mp4", "{:?}", video.fallback());
        let colours = |k: u8| {
            (
                image::Rgb([200, 40 * k, 30]),
                image::Rgb([20, 90, 60 * k + 10]),
            )
        };
        for k in 0..3u8 {
            let (a, b) = colours(k);
            let (a, b) = (
                RgbImage::from_pixel(width, height, a),
                RgbImage::from_pixel(width, height, b),
            );
            video.push(&[&a, &b]).unwrap();
        }
        let paths = video.finish().unwrap();
        for (which, path) in paths.into_iter().enumerate() {
            let path = path.unwrap();
            let decoded = std::process::Command::new("ffmpeg")
                .args(["-v", "error", "-i"])
                .arg(&path)
                .args(["-f", "rawvideo", "-pix_fmt", "rgb24", "-"])
                .output()
                .expect("ffmpeg decodes");
            assert!(decoded.status.success(), "{path:?}");
            let picture_bytes = (3 * width * height) as usize;
            assert_eq!(decoded.stdout.len(), 3 * picture_bytes, "{path:?}");
            for (k, picture) in decoded.stdout.chunks_exact(picture_bytes).enumerate() {
                let (a, b) = colours(k as u8);
                let want = if which == 0 { a.0 } else { b.0 };
                for pixel in picture.chunks_exact(3) {
                    for (got, expected) in pixel.iter().zip(want) {
                        assert!(
                            got.abs_diff(expected) <= 4,
                            "{path:?} picture {k}: {pixel:?} vs {want:?}"
                        );
                    }
                }
            }
        }
        assert!(VideoEncoder::create(&stems, 5, 4, 25.0, VideoContainer::Auto).is_err());
    }

    #[test]
    fn an_apng_holds_every_picture_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let mut video = VideoEncoder::create(
            &[dir.path().join("depth")],
            4,
            2,
            25.0,
            VideoContainer::Apng,
        )
        .unwrap();
        for k in 0..3u8 {
            video
                .push(&[&RgbImage::from_pixel(
                    4,
                    2,
                    image::Rgb([k * 50, 0, 255 - k]),
                )])
                .unwrap();
        }
        assert!(video.push(&[&RgbImage::new(2, 2)]).is_err());
        let path = video.finish().unwrap().remove(0).unwrap();
        assert_eq!(path, dir.path().join("depth.png"));
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "the stored pictures are gone");
        let mut reader =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()))
                .read_info()
                .unwrap();
        let control = reader.info().animation_control.unwrap();
        assert_eq!(control.num_frames, 3);
        let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
        for k in 0..3u8 {
            reader.next_frame(&mut buffer).unwrap();
            assert_eq!(&buffer[..3], &[k * 50, 0, 255 - k]);
            let fctl = reader.info().frame_control.unwrap();
            assert_eq!((fctl.delay_num, fctl.delay_den), (40, 1000));
        }
    }
}
