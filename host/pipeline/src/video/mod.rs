//! Dynamic imaging: 3-D video from long or live captures (thesis Ch. 5).
//!
//! The thesis filmed a turning ellipsoid at 1 kfps and decoded 32 of every 40 frames into one 3-D
//! frame (25 3-D frames per second), about three minutes of processing each. Here a clip or a live
//! stream is cut into windows ([`schedule`]: thesis windows, or sliding ones), read on its own
//! thread with memory bounded by the window whatever its length ([`stream`]), each window decoded
//! by the demodulator where it lies in that ring ([`crate::demod::decode_frames`]), checked for
//! motion ([`motion`]) and reconstructed by the one decoded → reconstruction path
//! ([`crate::reconstruct::reconstruct`]), warm-started from the previous reconstructed window
//! ([`crate::reconstruct::WarmStart`]: the object moves little in 40 ms; a warm result that strays
//! is redone; a window with nothing to start from starts from its own reconstruction at half
//! the resolution, [`crate::reconstruct::ReconstructConfig::coarse_start`]); with ground truth
//! ([`truth`]) each 3-D frame is scored. The caller gets every
//! window's [`VideoFrame`] as soon as it is done (the CLI writes it with [`output`] on its own
//! thread, [`writer`]: per-frame arrays, a colour-mapped depth video and a shaded-render video,
//! `video.json`).
//!
//! Three threads overlap so that only the reconstruction sets the pace: the reader (frames
//! into the window ring), the decoding stage (decode, motion, placement of window k + 1) and
//! the reconstruction of window k on the caller's thread; the CLI's writer is a fourth. Each
//! hand-over is a bounded queue, so memory stays bounded by a few windows.
//!
//! Once the timing carry has settled, a window is decoded only around the object (the box of
//! the previous window's lit pixels grown by [`FOCUS_MARGIN_PX`], [`focus`]) and reconstructed
//! there ([`crate::reconstruct::Request::region`]; its arrays stay the region's and only
//! the depth is pasted into the frame, [`WindowReconstruction`]); a window whose object leaves
//! that box is decoded whole, as is every [`VideoConfig::full_frame_every`]-th window, so an
//! object that appears elsewhere is found.
//!
//! With [`VideoConfig::bin`] every camera frame is binned into k×k pixel blocks as it is read
//! ([`meb_core::capture::binning`]) and the 3-D frames are reconstructed for the binned camera
//! ([`meb_core::rig::Rig::binned`]) and scored against the truth's block means
//! ([`truth::BinnedTruth`]): a live preview at 1/k² of the cost.
//!
//! A window that cannot be decoded or reconstructed (the object left the view, a dark moment)
//! is recorded as failed with the reason and the video goes on; a run in which no window
//! succeeds is an error. A stream that ends inside a frame ends the video after the windows
//! before the cut, and [`VideoSummary::input_error`] says where.
//!
//! A live stream has no end of its own: [`process_until`] also ends it when a
//! [`StopSignal`] is set (the CLI sets it on the first interrupt; this crate handles no
//! signal). The reader takes no frame after it, the windows the frames already read complete
//! are processed, and the run ends as at a natural end, with [`EndKind::Interrupted`]
//! ([`stream`]).

pub mod carry;
mod decode_stage;
pub mod encode;
pub mod focus;
pub mod judge;
pub mod motion;
pub mod output;
mod reconstruct_stage;
pub mod records;
pub mod render;
pub mod schedule;
pub mod stream;
pub mod truth;
pub mod window;
pub mod writer;
mod yuv;

pub use carry::{TimingCarry, TimingSource};
pub use focus::{FOCUS_MARGIN_PX, Focus, FocusRegion, LitBox, lit_box};
pub use judge::WindowVerdict;
pub use motion::{MotionConfig, MotionEstimate, MotionPolicy, PeriodFrames, detect_motion};
pub use records::{
    DecodeQuality, EndKind, FrameAccuracy, FrameRecord, FrameStatus, FrameTiming,
    ReconstructionQuality, VideoFrame, VideoSummary,
};
pub use schedule::{ScheduleError, WindowSchedule};
pub use stream::{FrameStream, StreamEnd};
pub use truth::{BinnedTruth, TruthDepth, TruthSource};
pub use window::WindowReconstruction;

use crate::demod::{
    CodeMap, DecodeConfig, Decoded, DemodError, Linearize, OnImplausible, Roi, VerdictStatus,
};
use crate::reconstruct::{
    AbsoluteDepth, ReconstructConfig, Reconstruction, Request, Source, Start, WarmStart,
    reconstruct_extent,
};
use meb_core::capture::binning::BinnedSource;
use meb_core::capture::{CaptureError, FrameSource};
use meb_core::metrics::{MetricsError, score_depth};
use meb_core::rig::Rig;
use meb_core::stop::StopSignal;
use meb_core::timing::StageTiming;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::mpsc::{SyncSender, sync_channel};
use std::time::Instant;
use thiserror::Error;

use decode_stage::{Chosen, DecodeStage};
use reconstruct_stage::reconstruct_window;

/// Everything [`process`] needs besides the frames, the rig and the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoConfig {
    /// How camera frames are cut into 3-D frames.
    pub schedule: WindowSchedule,
    /// Decoder settings (`start` frames are skipped once; `frames` is ignored). An implausible
    /// window is judged with its motion ([`judge`]): put down to motion, or refused unless
    /// `on_implausible` is [`OnImplausible::Keep`].
    pub decode: DecodeConfig,
    /// Reconstruction settings.
    pub reconstruct: ReconstructConfig,
    /// Motion detection and what to do about it.
    pub motion: MotionConfig,
    /// Frames the reader may run ahead of the processing (default: one hop, at most one
    /// window).
    pub read_ahead: Option<usize>,
    /// Stop after this many camera frames (a live stream).
    pub max_frames: Option<usize>,
    /// Decode windows with the exposure and rate ratio of the best fit so far ([`carry`]);
    /// `false` fits every window on its own.
    pub carry_timing: bool,
    /// Start each window's reconstruction from the previous reconstructed window's depth
    /// ([`crate::reconstruct::WarmStart`]); `false` reconstructs every window cold.
    pub warm_start: bool,
    /// Bin every camera frame into `bin`×`bin` blocks before decoding
    /// ([`meb_core::capture::binning`]): the 3-D frames have 1/`bin` of the camera's width and
    /// height (the camera of [`meb_core::rig::Rig::binned`]) and cost about 1/`bin`² as much;
    /// 1 keeps the camera's resolution.
    pub bin: usize,
    /// Decode every this many windows the whole frame and the others only around the object
    /// ([`focus`]); 1 decodes every window whole. Without effect with a decoding region
    /// (`decode.roi`), which is always decoded whole.
    pub full_frame_every: usize,
}

/// Windows from one decoded whole to the next by default ([`VideoConfig::full_frame_every`]):
/// an object that appears away from the one followed is found within 0.4 s at 1 kfps with the
/// thesis' windows.
pub const FULL_FRAME_EVERY: usize = 10;

impl VideoConfig {
    /// The thesis' windows (40 frames, 4 dropped at each end) for a rig of `leds` LEDs, with
    /// the decoded-capture reconstruction settings.
    pub fn thesis(leds: usize) -> Self {
        Self {
            schedule: WindowSchedule::THESIS,
            decode: DecodeConfig {
                leds: crate::demod::LedCount::Fixed(leds),
                ..DecodeConfig::default()
            },
            reconstruct: ReconstructConfig {
                coarse_start: true,
                ..ReconstructConfig::decoded_capture()
            },
            motion: MotionConfig::default(),
            read_ahead: None,
            max_frames: None,
            carry_timing: true,
            warm_start: true,
            bin: 1,
            full_frame_every: FULL_FRAME_EVERY,
        }
    }
}

/// Errors of a video run.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum VideoError {
    /// The window schedule cannot work.
    #[error(transparent)]
    Schedule(#[from] ScheduleError),
    /// The frames cannot be read.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// A decoder setting is wrong for this stream (not a property of one window).
    #[error(transparent)]
    Decode(DemodError),
    /// The rig does not fit the stream.
    #[error("rig: {0}")]
    Rig(String),
    /// The clip ended before its first window was whole.
    #[error(
        "the clip ended after {frames} frames, before its first window (frames {first}..{end}) \
         was whole{}",
        cut.as_ref().map(|c| format!(": {c}")).unwrap_or_default()
    )]
    ClipTooShort {
        /// Camera frames read.
        frames: usize,
        /// First frame of the first window.
        first: usize,
        /// End of the first window.
        end: usize,
        /// The read error that ended the clip, when it did not simply end.
        cut: Option<String>,
    },
    /// Every window failed.
    #[error("none of the {windows} windows could be reconstructed; the first failed with: {first}")]
    NoFrames {
        /// Windows tried.
        windows: usize,
        /// Why the first one failed.
        first: String,
    },
    /// The ground truth cannot be used.
    #[error("ground truth: {0}")]
    Truth(String),
    /// Comparing with the ground truth failed.
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    /// Writing the outputs failed.
    #[error(transparent)]
    Files(#[from] meb_core::io::FilesError),
    /// Encoding an output video failed.
    #[error("{0}")]
    Encode(String),
}

/// Runs the video pipeline over `source` (module docs), calling `sink` with every window as
/// soon as it is done; `truth` scores the 3-D frames.
///
/// Two stages overlap: a decoding thread (with a pool of its own, \[`DECODING_THREADS`\]) reads
/// each window ([`FrameStream`]), decodes it with the carried timing ([`carry`]), measures its
/// motion and, with [`MotionPolicy::Place`], places it, and reads the truth for the chosen
/// window; the calling thread reconstructs the chosen windows in order (each warm-started from the one before, in a pool on every core,
/// \[`stage_pool`\]), scores them and hands them to `sink`. At most [`DECODED_AHEAD`] decoded
/// windows wait between the two, so memory stays bounded by a few windows.
pub fn process(
    source: Box<dyn FrameSource>,
    rig: &Rig,
    config: &VideoConfig,
    truth: Option<&mut dyn TruthSource>,
    sink: &mut dyn FnMut(&VideoFrame) -> Result<(), VideoError>,
) -> Result<VideoSummary, VideoError> {
    process_until(source, rig, config, truth, &StopSignal::new(), sink)
}

/// [`process`] over a stream that also ends when `stop` is set (a live stream ended by the
/// user): the reader takes no frame after it, the windows that the frames already read
/// complete are processed (a window they leave incomplete is dropped) and the summary's `end`
/// is [`EndKind::Interrupted`]; a stop before the first window is whole is
/// [`VideoError::ClipTooShort`]. `stop` may be set from any thread at any time, also while the
/// reader is blocked waiting for a frame that never comes ([`stream`]).
pub fn process_until(
    source: Box<dyn FrameSource>,
    rig: &Rig,
    config: &VideoConfig,
    truth: Option<&mut dyn TruthSource>,
    stop: &StopSignal,
    sink: &mut dyn FnMut(&VideoFrame) -> Result<(), VideoError>,
) -> Result<VideoSummary, VideoError> {
    let started = Instant::now();
    if rig.leds.len() < 3 {
        return Err(VideoError::Rig(format!(
            "photometric stereo needs at least 3 LEDs, the rig has {}",
            rig.leds.len()
        )));
    }
    let schedule = WindowSchedule::new(
        config.schedule.window,
        config.schedule.drop,
        config.schedule.hop,
        1usize << (rig.leds.len() + 1),
    )?;
    // Binned frames are seen by the binned camera and scored against binned truth.
    if config.bin > 1 && config.decode.linearize != Linearize::None {
        return Err(VideoError::Decode(DemodError::InvalidConfig(format!(
            "binning by {} sums code values, which is exact only for linear codes: decode with \
             no linearisation, or do not bin",
            config.bin
        ))));
    }
    let source: Box<dyn FrameSource> = if config.bin > 1 {
        Box::new(BinnedSource::new(source, config.bin)?)
    } else {
        source
    };
    let binned_rig = rig.binned(config.bin);
    let rig = &binned_rig;
    // A decoding region is given in camera pixels.
    let binned_config = VideoConfig {
        decode: DecodeConfig {
            roi: config.decode.roi.map(|r| Roi {
                x: r.x / config.bin.max(1),
                y: r.y / config.bin.max(1),
                width: r.width / config.bin.max(1),
                height: r.height / config.bin.max(1),
            }),
            ..config.decode.clone()
        },
        ..config.clone()
    };
    let config = &binned_config;
    let mut binned_truth = truth.map(|inner| BinnedTruth::new(inner, config.bin));
    let truth = binned_truth.as_mut().map(|t| t as &mut dyn TruthSource);
    let mut format = source.format().clone();
    if let Some(fps) = config.decode.fps {
        format.fps = fps;
    }
    let read_ahead = config
        .read_ahead
        .unwrap_or(schedule.hop.min(schedule.window));
    let stream = FrameStream::until(source, read_ahead, config.max_frames, stop)?;
    let code_map = CodeMap::new(&format, config.decode.linearize).map_err(VideoError::Decode)?;
    let mut summary = VideoSummary {
        camera_frames: 0,
        windows: 0,
        reconstructed: 0,
        skipped: 0,
        failed: 0,
        moving: 0,
        focused: 0,
        end: EndKind::Complete,
        input_error: None,
        wall_s: 0.0,
        frames_per_second: 0.0,
    };
    let mut first_failure: Option<String> = None;
    let mut warm: Option<WarmStart> = None;
    let reconstruction_pool = stage_pool("reconstruct", rayon::current_num_threads())?;
    let decoding = DecodeStage {
        schedule,
        format: &format,
        code_map: &code_map,
        config,
        first_pool: &reconstruction_pool,
    };
    let (sender, receiver) = sync_channel::<Result<Chosen, VideoError>>(DECODED_AHEAD);
    let decoding_pool = stage_pool("decode", DECODING_THREADS)?;
    let (stream_end, reconstructed) = std::thread::scope(|scope| {
        let decoder = std::thread::Builder::new()
            .name("meb-video-decode".into())
            .spawn_scoped(scope, move || {
                decoding_pool.install(|| decoding.run(stream, &sender, truth))
            })
            .map_err(|e| {
                VideoError::Capture(CaptureError::Other(format!(
                    "cannot start the decoding thread: {e}"
                )))
            })?;
        let reconstructed = (|| -> Result<(), VideoError> {
            loop {
                let waited = Instant::now();
                let Ok(chosen) = receiver.recv() else {
                    return Ok(());
                };
                let mut chosen = chosen?;
                chosen.timing.wait_ms = waited.elapsed().as_secs_f64() * 1e3;
                let outcome = reconstruct_window(
                    chosen.attempt,
                    chosen.scheduled,
                    chosen.index,
                    &schedule,
                    &format,
                    rig,
                    config,
                    chosen.truth,
                    chosen.timing,
                    warm.as_ref().filter(|_| config.warm_start),
                    &reconstruction_pool,
                )?;
                summary.windows += 1;
                match outcome.record.status {
                    FrameStatus::Reconstructed => summary.reconstructed += 1,
                    FrameStatus::Skipped => summary.skipped += 1,
                    FrameStatus::Failed => {
                        summary.failed += 1;
                        if first_failure.is_none() {
                            first_failure = outcome.record.reason.clone();
                        }
                    }
                }
                if outcome.record.motion.is_some_and(|m| m.moving) {
                    summary.moving += 1;
                }
                if outcome.record.decode_region.is_some() {
                    summary.focused += 1;
                }
                sink(&VideoFrame {
                    record: outcome.record,
                    decoded: outcome.decoded.as_ref(),
                    reconstruction: outcome.reconstruction.as_ref(),
                    camera_frames: chosen.camera_frames,
                    total_frames: chosen.total_frames,
                })?;
                // The next window starts from this one's depth, moved rather than copied.
                if let Some(reconstruction) = outcome.reconstruction {
                    let glossy = crate::photometric::highlights::looks_glossy(
                        &reconstruction.reconstruction().photometric,
                    );
                    warm = Some(WarmStart {
                        depth_mm: reconstruction.into_depth_mm(),
                        glossy,
                    });
                }
            }
        })();
        // Hanging up stops the decoding thread at its next window.
        drop(receiver);
        let stream_end = decoder.join().map_err(|_| {
            VideoError::Capture(CaptureError::Other("the decoding thread panicked".into()))
        })?;
        Ok::<_, VideoError>((stream_end, reconstructed))
    })?;
    reconstructed?;
    summary.camera_frames = stream_end.received;
    match stream_end.end {
        Some(StreamEnd::Cut(error)) => {
            summary.end = EndKind::Cut;
            summary.input_error = Some(error.to_string());
        }
        Some(StreamEnd::Limit) => summary.end = EndKind::Limit,
        Some(StreamEnd::Stopped) => summary.end = EndKind::Interrupted,
        Some(StreamEnd::Complete) | None => {}
    }
    if summary.reconstructed == 0 && summary.failed > 0 {
        return Err(VideoError::NoFrames {
            windows: summary.windows,
            first: first_failure.unwrap_or_default(),
        });
    }
    summary.wall_s = started.elapsed().as_secs_f64();
    summary.frames_per_second = summary.windows as f64 / summary.wall_s.max(1e-9);
    Ok(summary)
}

/// A pool of `threads` named `meb-video-{stage}-N` for one stage of the pipeline.
///
/// Each window's reconstruction runs inside the reconstruction stage's pool (`install`), so its
/// parallel loops are split by a worker and stolen by the others. Called from the pipeline's
/// thread, outside any pool, each of the hundreds of parallel loops of a window was injected
/// into the global pool with the caller asleep until it finished: two thread switches and a
/// wake-up per loop.
/// `meb video`, 2000 frames of 1280×720 in windows of 40, four runs alternated: 21.1 → 22.6
/// 3-D frames/s (means), reconstruction 39.7 → 37.2 ms per window, system CPU 0.80 → 0.58 s.
fn stage_pool(stage: &str, threads: usize) -> Result<rayon::ThreadPool, VideoError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name({
            let stage = stage.to_string();
            move |i| format!("meb-video-{stage}-{i}")
        })
        .build()
        .map_err(|e| {
            VideoError::Capture(CaptureError::Other(format!(
                "cannot start the {stage} stage's threads: {e}"
            )))
        })
}

/// Decoded windows that may wait for the reconstruction (each holds its LED images).
pub const DECODED_AHEAD: usize = 1;

/// Threads of the decoding stage's own pool: its parallel loops run there instead of in the
/// shared pool, where they queued between the reconstruction's. The reconstruction bounds the
/// rate (≈ 44 ms per window at 1280×720 against ≈ 22 ms of decoding), so it keeps the shared
/// pool's workers on both cores and decoding runs in series beside it. `meb video`, 2000
/// frames of 1280×720 in windows of 40, six runs alternated with the shared pool: 17.7 → 19.2
/// 3-D frames/s (means), decoding 30.5 → 22.7 ms per window, user CPU 3.83 → 3.69 s.
const DECODING_THREADS: usize = 1;
