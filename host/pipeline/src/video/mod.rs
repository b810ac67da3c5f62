//! Dynamic imaging: 3-D video from long or live captures (thesis Ch. 5).
//!
//! The thesis filmed a turning ellipsoid at 1 kfps and decoded 32 of every 40 frames into one 3-D
//! frame (25 3-D frames per second), about three minutes of processing each. Here a clip or a live
//! stream is cut into windows ([`schedule`]: thesis windows, or sliding ones), read on its own
//! thread with memory bounded by the window whatever its length ([`stream`]), each window decoded
//! by the demodulator where it lies in that ring ([`crate::demod::decode_frames`]), checked for
//! motion ([`motion`]) and reconstructed by the one decoded → reconstruction path
//! ([`crate::reconstruct::from_decoded`]), warm-started from the previous reconstructed window
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
//! there ([`crate::reconstruct::from_decoded_region`]; its arrays stay the region's and only
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

pub mod carry;
pub mod encode;
pub mod focus;
pub mod judge;
pub mod motion;
pub mod output;
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
pub use schedule::{ScheduleError, WindowSchedule};
pub use stream::{FrameStream, StreamEnd};
pub use truth::{BinnedTruth, TruthDepth, TruthSource};
pub use window::WindowReconstruction;

use crate::demod::{
    CodeMap, DecodeConfig, Decoded, DemodError, Linearize, OnImplausible, Roi, VerdictStatus,
};
use crate::reconstruct::{
    AbsoluteDepth, ReconstructConfig, Reconstruction, Start, WarmStart, from_decoded_extent,
    from_decoded_region,
};
use meb_core::capture::binning::BinnedSource;
use meb_core::capture::{CaptureError, FrameSource};
use meb_core::metrics::{MetricsError, score_depth};
use meb_core::rig::Rig;
use meb_core::timing::StageTiming;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::sync::mpsc::{SyncSender, sync_channel};
use std::time::Instant;
use thiserror::Error;

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

/// What became of a window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameStatus {
    /// Decoded and reconstructed.
    Reconstructed,
    /// Left out on purpose (motion, [`MotionPolicy::Skip`]).
    Skipped,
    /// Decoding or reconstruction failed; `reason` says why.
    Failed,
}

/// The decoder's view of a window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DecodeQuality {
    /// Chips per camera frame.
    pub rate_ratio: f64,
    /// Exposure, fraction of the frame period.
    pub exposure: f64,
    /// Rolling-shutter line delay, frame periods per row (0 for a global shutter).
    #[serde(default)]
    pub line_delay_frames: f64,
    /// RMS residual of the waveform fit to the mean signal, fraction of full scale.
    pub fit_residual: f64,
    /// Median per-frame pixel noise σ, fraction of full scale.
    pub median_noise: f64,
    /// Signal-to-noise ratio of each LED image, dB.
    pub led_snr_db: Vec<f64>,
    /// The decoder's quality verdict (an implausible window is refused unless `--force`).
    pub verdict: crate::demod::quality::Verdict,
}

impl DecodeQuality {
    /// The figures of a decode report.
    pub fn of(decoded: &Decoded) -> Self {
        let report = &decoded.report;
        Self {
            rate_ratio: report.rate_ratio,
            exposure: report.exposure,
            line_delay_frames: report.line_delay_frames,
            fit_residual: report.fit_residual,
            median_noise: report.median_noise,
            led_snr_db: report.per_led.iter().map(|l| l.snr_db).collect(),
            verdict: report.verdict.clone(),
        }
    }
}

/// The reconstruction's view of a window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReconstructionQuality {
    /// Pixels with a normal.
    pub object_pixels: usize,
    /// Fraction of the integrated surface kept by the artefact filter.
    pub kept_fraction: f64,
    /// Integration iterations of the last pass.
    pub iterations: usize,
    /// Whether the reconstruction started from the previous window's (warm) or from scratch.
    pub start: Start,
    /// Share of the reconstructed pixels measured by three or more LEDs
    /// ([`crate::reconstruct::Support`]).
    #[serde(default)]
    pub measured_share: f64,
    /// Whether the depth's distance from the camera was measured: judged only where a window's
    /// offsets were scanned for from scratch (a warm or coarse start carries them, unjudged).
    #[serde(default)]
    pub absolute_depth: AbsoluteDepth,
    /// What the reconstruction's support check found wrong (empty when plausible).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub implausible: Vec<String>,
}

impl ReconstructionQuality {
    /// The figures of a reconstruction.
    pub fn of(reconstruction: &Reconstruction) -> Self {
        Self {
            object_pixels: reconstruction
                .photometric
                .field
                .mask
                .iter()
                .filter(|&&m| m)
                .count(),
            kept_fraction: reconstruction.integration.kept_fraction,
            iterations: reconstruction.integration.iterations,
            start: reconstruction.start.clone(),
            measured_share: reconstruction.support.measured_share,
            absolute_depth: reconstruction.support.absolute_depth,
            implausible: reconstruction.support.verdict.problems.clone(),
        }
    }
}

/// A 3-D frame against the ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameAccuracy {
    /// Depth RMSE after removing the best constant offset, mm (`None` when no reconstructed
    /// pixel lies on the true surface).
    pub rmse_mm: Option<f64>,
    /// RMSE over the true depth range.
    pub nrmse: Option<f64>,
    /// Fraction of the true surface reconstructed.
    pub reconstructed_fraction: f64,
    /// Camera frame (fractional) the truth describes.
    pub truth_frame: f64,
}

/// Wall-clock time of a window's stages, ms.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameTiming {
    /// The decoding stage waiting for the reader (reading, when it is the bottleneck).
    pub read_ms: f64,
    /// The reconstruction waiting for the decoding stage (reading and decoding, when they
    /// are the bottleneck).
    #[serde(default)]
    pub wait_ms: f64,
    /// Decoding (every try, with [`MotionPolicy::Place`]).
    pub decode_ms: f64,
    /// Motion detection.
    pub motion_ms: f64,
    /// Reconstruction.
    pub reconstruct_ms: f64,
    /// Reading the truth (in the decoding stage) and comparing with it (after the
    /// reconstruction).
    pub compare_ms: f64,
    /// Writing the outputs (filled in by the writer).
    pub write_ms: f64,
    /// The reconstruction's own stages.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stages: Vec<StageTiming>,
}

/// Everything recorded about one window (an entry of `video.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// 3-D frame number (window k of the schedule).
    pub index: usize,
    /// Camera frames of the window, after placement (start, end).
    pub frames: (usize, usize),
    /// Camera frames decoded (start, end).
    pub decoded: (usize, usize),
    /// Camera time of the decoded frames' middle, s (when the frame rate is known).
    pub time_s: Option<f64>,
    /// What became of the window.
    pub status: FrameStatus,
    /// Why it was skipped or failed.
    pub reason: Option<String>,
    /// Frames the window was moved to find the object still ([`MotionPolicy::Place`]).
    pub placed_by: usize,
    /// The region of the frame the window was decoded in, around the object ([`focus`]);
    /// `None`: the whole frame (or the decoding region given).
    #[serde(default)]
    pub decode_region: Option<Roi>,
    /// Whether a region was chosen for the window but given up for the whole frame (its decode
    /// failed, it held no lit pixel, or the object reached its edge).
    #[serde(default)]
    pub widened: bool,
    /// What the decoder's verdict came to with the window's motion ([`judge`]; `None` when
    /// decoding failed).
    #[serde(default)]
    pub verdict: Option<WindowVerdict>,
    /// Where the decoder's waveform timing came from.
    pub timing_source: TimingSource,
    /// Motion in the decoded frames.
    pub motion: Option<MotionEstimate>,
    /// Decoder figures.
    pub decode: Option<DecodeQuality>,
    /// Reconstruction figures.
    pub reconstruction: Option<ReconstructionQuality>,
    /// Accuracy against the ground truth.
    pub accuracy: Option<FrameAccuracy>,
    /// Stage timings.
    pub timing: FrameTiming,
}

/// One window as handed to the caller.
#[derive(Debug)]
pub struct VideoFrame<'a> {
    /// What was recorded.
    pub record: FrameRecord,
    /// The decoded LED images (when decoding succeeded): of the whole frame, or of the region
    /// around the object the record names ([`FrameRecord::decode_region`]).
    pub decoded: Option<&'a Decoded>,
    /// The reconstruction (when it succeeded): of the whole frame, or of the decode region
    /// ([`WindowReconstruction`]).
    pub reconstruction: Option<&'a WindowReconstruction>,
    /// Camera frames read so far.
    pub camera_frames: usize,
    /// Camera frames in the stream, when known.
    pub total_frames: Option<usize>,
}

/// How the stream ended, for the record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EndKind {
    /// The source had no more frames.
    Complete,
    /// The source failed part-way (see the input error).
    Cut,
    /// The frame limit was reached.
    Limit,
}

/// The outcome of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VideoSummary {
    /// Camera frames read.
    pub camera_frames: usize,
    /// Windows processed.
    pub windows: usize,
    /// Windows reconstructed.
    pub reconstructed: usize,
    /// Windows skipped.
    pub skipped: usize,
    /// Windows that failed.
    pub failed: usize,
    /// Windows in which the object moved.
    pub moving: usize,
    /// Windows decoded in a region around the object ([`focus`]).
    #[serde(default)]
    pub focused: usize,
    /// How the stream ended.
    pub end: EndKind,
    /// The read error that cut the stream.
    pub input_error: Option<String>,
    /// Wall-clock time of the run, s.
    pub wall_s: f64,
    /// Windows per second of wall-clock time.
    pub frames_per_second: f64,
}

/// A window's frames decoded around the object or whole ([`focus`]).
struct Decode {
    decoded: Result<Decoded, DemodError>,
    source: TimingSource,
    /// The region decoded (`None`: the whole frame).
    region: Option<FocusRegion>,
    /// The lit pixels, when the video decodes around the object.
    lit: Option<LitBox>,
    /// Whether a region was chosen but given up for the whole frame.
    widened: bool,
}

/// One decoded try of a window (several with [`MotionPolicy::Place`]).
struct Try {
    start: usize,
    decode: Decode,
    motion: Option<MotionEstimate>,
    verdict: Option<WindowVerdict>,
}

impl Try {
    /// The camera frames the try decoded: its window without the dropped ends.
    fn decoded_frames(&self, schedule: &WindowSchedule) -> Range<usize> {
        self.start + schedule.drop..self.start + schedule.window - schedule.drop
    }

    /// Whether the try decoded and the decoder's verdict calls it plausible.
    fn is_plausible(&self) -> bool {
        self.verdict == Some(WindowVerdict::Plausible)
    }

    /// Whether the object moved during the try, by its motion estimate.
    fn moving(&self) -> bool {
        self.motion.is_some_and(|m| m.moving)
    }

    /// Why a decoded try is not reconstructed, if it is not: its verdict refuses it, or
    /// `policy` skips it for motion.
    fn left_out(&self, policy: MotionPolicy) -> Option<LeftOut> {
        if self.verdict == Some(WindowVerdict::Refused) {
            Some(LeftOut::Refused)
        } else if policy == MotionPolicy::Skip && self.moving() {
            Some(LeftOut::Skipped)
        } else {
            None
        }
    }

    /// Whether the try goes on to a reconstruction: it decoded and is not left out
    /// ([`Try::left_out`]). The decoding stage reads the truth only for such tries.
    fn would_reconstruct(&self, policy: MotionPolicy) -> bool {
        self.decode.decoded.is_ok() && self.left_out(policy).is_none()
    }
}

/// Why [`reconstruct_window`] does not reconstruct a decoded try.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum LeftOut {
    /// The decode is implausible and motion does not explain it.
    Refused,
    /// The object moved and the policy is [`MotionPolicy::Skip`].
    Skipped,
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
    let stream = FrameStream::new(source, read_ahead, config.max_frames)?;
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
                    warm = Some(WarmStart {
                        depth_mm: reconstruction.into_depth_mm(),
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

/// A window chosen by the decoding stage, on its way to the reconstruction.
struct Chosen {
    /// 3-D frame number.
    index: usize,
    /// First camera frame the schedule gave the window.
    scheduled: usize,
    /// The chosen try.
    attempt: Try,
    /// Timing so far (reading, decoding, motion).
    timing: FrameTiming,
    /// Camera frames read when it was chosen.
    camera_frames: usize,
    /// Camera frames in the stream, when known.
    total_frames: Option<usize>,
    /// The true depth for the decoded frames, when there is truth and the try goes on to a
    /// reconstruction ([`Try::would_reconstruct`]).
    truth: Option<TruthDepth>,
}

/// Where the decoding stage left the stream.
struct StreamState {
    /// Camera frames read.
    received: usize,
    /// How the stream ended.
    end: Option<StreamEnd>,
}

/// The decoding stage: windows read, decoded, checked for motion and placed.
#[derive(Clone, Copy)]
struct DecodeStage<'a> {
    schedule: WindowSchedule,
    format: &'a meb_core::capture::FrameFormat,
    code_map: &'a CodeMap,
    config: &'a VideoConfig,
    /// The reconstruction's pool, idle until the first window is decoded: that window is
    /// decoded there, on every core (a decode does not depend on its thread count). The first
    /// window's decode, 2000 frames of 1280×720: 71 → 56 ms.
    first_pool: &'a rayon::ThreadPool,
}

impl DecodeStage<'_> {
    /// Sends every window's chosen try to `sender`, with the truth for it when there is a
    /// `truth` source and the try goes on to a reconstruction ([`Try::would_reconstruct`]),
    /// until the stream ends, an error (sent too) or the reconstruction hangs up; returns
    /// where the stream was left. The truth is read here, off the reconstruction's thread:
    /// reading a 1280×720 depth file took ≈ 3–4 ms of each window.
    fn run(
        self,
        mut stream: FrameStream,
        sender: &SyncSender<Result<Chosen, VideoError>>,
        mut truth: Option<&mut dyn TruthSource>,
    ) -> StreamState {
        let mut carry = TimingCarry::new(self.config.carry_timing);
        let mut focus = Focus::new(
            self.config.full_frame_every,
            (self.format.width, self.format.height),
        );
        for k in 0.. {
            let window = if k == 0 {
                self.first_pool
                    .install(|| self.window(&mut stream, &mut carry, &mut focus, k))
            } else {
                self.window(&mut stream, &mut carry, &mut focus, k)
            };
            let window = window.and_then(|chosen| match (chosen, truth.as_deref_mut()) {
                (Some(mut chosen), Some(truth))
                    if chosen.attempt.would_reconstruct(self.config.motion.policy) =>
                {
                    let time = Instant::now();
                    chosen.truth =
                        truth.depth_for(chosen.attempt.decoded_frames(&self.schedule))?;
                    chosen.timing.compare_ms += time.elapsed().as_secs_f64() * 1e3;
                    Ok(Some(chosen))
                }
                (chosen, _) => Ok(chosen),
            });
            match window {
                Ok(Some(chosen)) => {
                    if sender.send(Ok(chosen)).is_err() {
                        break;
                    }
                }
                Ok(None) => break,
                Err(error) => {
                    let _ = sender.send(Err(error));
                    break;
                }
            }
        }
        StreamState {
            received: stream.received(),
            end: stream.take_end(),
        }
    }

    /// Whether windows are decoded around the object ([`focus`]).
    fn focusing(&self) -> bool {
        self.config.full_frame_every > 1 && self.config.decode.roi.is_none()
    }

    /// Decodes a window's `frames` in the region `focus` chose for window `k` once the carry
    /// has settled, or whole; a region whose decode fails, that holds no lit pixel (the object
    /// jumped away) or whose lit pixels reach its edge is given up for the whole frame.
    fn decode_try(
        &self,
        frames: &[meb_core::capture::Samples],
        carry: &mut TimingCarry,
        focus: &Focus,
        k: usize,
        config: &DecodeConfig,
    ) -> Decode {
        let frame = (self.format.width, self.format.height);
        let mask = &self.config.reconstruct.photometric.mask;
        let region = focus
            .region(k)
            .filter(|_| self.focusing() && carry.settled());
        if let Some(region) = region {
            let in_region = DecodeConfig {
                roi: Some(region.roi),
                ..config.clone()
            };
            let (decoded, source) =
                carry.decode_region(frames, self.format, &in_region, region.reference_noise);
            let lit = decoded
                .as_ref()
                .ok()
                .map(|d| lit_box(d, Some(region.roi), frame, mask));
            // The object must be in the region, and not reach out of it.
            if let Some(lit) = lit.filter(|l| l.bounds.is_some() && !l.reaches_edge) {
                return Decode {
                    decoded,
                    source,
                    region: Some(region),
                    lit: Some(lit),
                    widened: false,
                };
            }
        }
        let (decoded, source) = carry.decode(frames, self.format, config);
        let lit = decoded
            .as_ref()
            .ok()
            .filter(|_| self.focusing())
            .map(|d| lit_box(d, None, frame, mask));
        Decode {
            decoded,
            source,
            region: None,
            lit,
            widened: region.is_some(),
        }
    }

    /// Window `k`: decoded where the schedule puts it (or, placing, where the object is
    /// still); `None` when the stream ends first.
    fn window(
        &self,
        stream: &mut FrameStream,
        carry: &mut TimingCarry,
        focus: &mut Focus,
        k: usize,
    ) -> Result<Option<Chosen>, VideoError> {
        let (config, schedule, format) = (self.config, &self.schedule, self.format);
        let base = config.decode.start;
        let decoded_len = schedule.decoded();
        // The verdict is applied here, with the window's motion ([`judge`]).
        let force = config.decode.on_implausible == OnImplausible::Keep;
        let decode_config = DecodeConfig {
            on_implausible: OnImplausible::Keep,
            ..config.decode.clone()
        };
        let place_step = config.motion.place_step.max(1);
        let scheduled = base + k * schedule.hop;
        let mut timing = FrameTiming::default();
        let mut best: Option<Try> = None;
        let mut offset = 0;
        loop {
            let start = scheduled + offset;
            // The whole window: the dropped frames serve the period-difference motion test.
            let needed = start..start + schedule.window;
            let Some(window) = stream.window(needed)? else {
                if k == 0 && best.is_none() {
                    return Err(too_short(stream, base, *schedule));
                }
                break;
            };
            let time = Instant::now();
            let decoded_frames = schedule.drop..schedule.drop + decoded_len;
            let mut decode = self.decode_try(
                &window.samples[decoded_frames],
                carry,
                focus,
                k,
                &decode_config,
            );
            timing.decode_ms += time.elapsed().as_secs_f64() * 1e3;
            // A setting wrong for the stream fails every window alike: stop at once.
            decode.decoded = match decode.decoded {
                Err(error @ (DemodError::InvalidConfig(_) | DemodError::Capture(_))) => {
                    return Err(VideoError::Decode(error));
                }
                other => other,
            };
            let time = Instant::now();
            let motion = decode.decoded.as_ref().ok().map(|d| {
                let frames = PeriodFrames {
                    frames: window.samples,
                    map: self.code_map,
                    width: format.width,
                    roi: decode.region.map(|r| r.roi).or(config.decode.roi),
                    period: 1usize << (d.report.leds + 1),
                };
                detect_motion(d, Some(&frames), &config.motion)
            });
            let verdict = decode
                .decoded
                .as_ref()
                .ok()
                .map(|d| judge::judge(d, motion.as_ref(), force));
            timing.motion_ms += time.elapsed().as_secs_f64() * 1e3;
            timing.read_ms += stream.take_waited().as_secs_f64() * 1e3;
            let attempt = Try {
                start,
                decode,
                motion,
                verdict,
            };
            // A window cut across a sudden change of pose raises every pixel's residual alike,
            // so its relative motion score can look still: only a plausible decode counts.
            let plausible = attempt.is_plausible();
            let still = plausible && attempt.motion.is_some_and(|m| !m.moving);
            // Placing keeps the scheduled try unless a later one is still: a try that is only
            // "least moving" is no better placed than where the schedule put it.
            let better = best.is_none() || still;
            if better {
                best = Some(attempt);
            }
            let can_move =
                config.motion.policy == MotionPolicy::Place && offset + place_step < schedule.hop;
            if still || !can_move {
                break;
            }
            offset += place_step;
        }
        if self.focusing() {
            let learnt = best.as_ref().and_then(|b| {
                let decoded = b.decode.decoded.as_ref().ok()?;
                Some((decoded, b.decode.lit?))
            });
            focus.learn(learnt, best.as_ref().and_then(|b| b.decode.region));
        }
        Ok(best.map(|attempt| Chosen {
            index: k,
            scheduled,
            attempt,
            timing,
            camera_frames: stream.received(),
            total_frames: stream.total_hint(),
            truth: None,
        }))
    }
}

/// The error for a stream that ended before its first window.
fn too_short(stream: &mut FrameStream, base: usize, schedule: WindowSchedule) -> VideoError {
    let cut = match stream.take_end() {
        Some(StreamEnd::Cut(error)) => Some(error.to_string()),
        _ => None,
    };
    VideoError::ClipTooShort {
        frames: stream.received(),
        first: base,
        end: base + schedule.window,
        cut,
    }
}

/// A finished window: its record and what was computed.
struct Outcome {
    record: FrameRecord,
    decoded: Option<Decoded>,
    reconstruction: Option<WindowReconstruction>,
}

/// Applies the motion policy to the chosen try, reconstructs it and scores it.
#[allow(clippy::too_many_arguments)]
fn reconstruct_window(
    chosen: Try,
    scheduled: usize,
    index: usize,
    schedule: &WindowSchedule,
    format: &meb_core::capture::FrameFormat,
    rig: &Rig,
    config: &VideoConfig,
    truth: Option<TruthDepth>,
    mut timing: FrameTiming,
    warm: Option<&WarmStart>,
    pool: &rayon::ThreadPool,
) -> Result<Outcome, VideoError> {
    let decoded_range = chosen.decoded_frames(schedule);
    let time_s = (format.fps > 0.0)
        .then(|| (decoded_range.start + decoded_range.end) as f64 / (2.0 * format.fps));
    let mut record = FrameRecord {
        index,
        frames: (chosen.start, chosen.start + schedule.window),
        decoded: (decoded_range.start, decoded_range.end),
        time_s,
        status: FrameStatus::Failed,
        reason: None,
        placed_by: chosen.start - scheduled,
        decode_region: chosen.decode.region.map(|r| r.roi),
        widened: chosen.decode.widened,
        verdict: chosen.verdict,
        timing_source: chosen.decode.source,
        motion: chosen.motion,
        decode: None,
        reconstruction: None,
        accuracy: None,
        timing: FrameTiming::default(),
    };
    let (moving, left_out) = (chosen.moving(), chosen.left_out(config.motion.policy));
    let decoded = match chosen.decode.decoded {
        Ok(decoded) => decoded,
        Err(error) => {
            record.reason = Some(format!("decoding failed: {error}"));
            record.timing = timing;
            return Ok(Outcome {
                record,
                decoded: None,
                reconstruction: None,
            });
        }
    };
    let mut quality = DecodeQuality::of(&decoded);
    // The decoder kept every decode for the judgement; record what it came to.
    quality.verdict.status = match chosen.verdict {
        Some(WindowVerdict::Plausible) => VerdictStatus::Plausible,
        Some(WindowVerdict::Forced) => VerdictStatus::Overridden,
        _ => VerdictStatus::Implausible,
    };
    record.decode = Some(quality);
    let shape = decoded.leds.shape().unwrap_or((0, 0));
    let expected = chosen
        .decode
        .region
        .map_or((rig.camera.height, rig.camera.width), |r| {
            (r.roi.height, r.roi.width)
        });
    if shape != expected {
        return Err(VideoError::Rig(format!(
            "the rig's camera is {}x{} but the decoded images are {}x{} (use a rig of the \
             frames' or the region's size)",
            rig.camera.width, rig.camera.height, shape.1, shape.0
        )));
    }
    record.reason = match (moving, chosen.verdict) {
        (_, Some(WindowVerdict::Forced)) => Some(format!(
            "the decode is implausible ({}) and was kept on request (--force)",
            decoded.report.verdict.problems.join("; ")
        )),
        (true, Some(WindowVerdict::Motion)) => Some(
            "the object moved during the window (the modulation its decode leaves unexplained \
             is within the motion's energy)"
                .into(),
        ),
        (true, _) => Some("the object moved during the window".into()),
        (false, _) => None,
    };
    if let Some(left_out) = left_out {
        match left_out {
            LeftOut::Refused => {
                let verdict = &decoded.report.verdict;
                record.reason = Some(format!(
                    "the decode is implausible and the window's motion does not explain it: {} \
                     (try: {}; --force keeps such windows)",
                    verdict.problems.join("; "),
                    verdict.advice.join("; ")
                ));
            }
            LeftOut::Skipped => record.status = FrameStatus::Skipped,
        }
        record.timing = timing;
        return Ok(Outcome {
            record,
            decoded: Some(decoded),
            reconstruction: None,
        });
    }
    let time = Instant::now();
    let reconstruction = pool.install(|| match chosen.decode.region {
        Some(region) => from_decoded_region(&decoded, region.roi, rig, &config.reconstruct, warm)
            .map(WindowReconstruction::of_region),
        None => from_decoded_extent(&decoded, rig, None, &config.reconstruct, warm)
            .map(WindowReconstruction::of_extent),
    });
    timing.reconstruct_ms = time.elapsed().as_secs_f64() * 1e3;
    let reconstruction = match reconstruction {
        Ok(r) => r,
        Err(error) => {
            record.reason = Some(format!("reconstruction failed: {error}"));
            record.timing = timing;
            return Ok(Outcome {
                record,
                decoded: Some(decoded),
                reconstruction: None,
            });
        }
    };
    record.reconstruction = Some(ReconstructionQuality::of(reconstruction.reconstruction()));
    timing.stages = reconstruction.reconstruction().timings.clone();
    let support = &reconstruction.reconstruction().support.verdict;
    if !support.is_plausible() {
        let problems = support.problems.join("; ");
        if config.decode.on_implausible != OnImplausible::Keep {
            record.reason = Some(format!(
                "the reconstruction is implausible: {problems} (try: {}; --force keeps such \
                 windows)",
                support.advice.join("; ")
            ));
            record.timing = timing;
            return Ok(Outcome {
                record,
                decoded: Some(decoded),
                reconstruction: None,
            });
        }
        let kept = format!(
            "the reconstruction is implausible ({problems}) and was kept on request (--force)"
        );
        record.reason = Some(match record.reason.take() {
            Some(reason) => format!("{reason}; {kept}"),
            None => kept,
        });
    }
    record.status = FrameStatus::Reconstructed;
    if let Some(truth) = truth {
        let time = Instant::now();
        record.accuracy = Some(score(&reconstruction, &truth, pool)?);
        timing.compare_ms += time.elapsed().as_secs_f64() * 1e3;
    }
    record.timing = timing;
    Ok(Outcome {
        record,
        decoded: Some(decoded),
        reconstruction: Some(reconstruction),
    })
}

/// The accuracy of a reconstruction against its window's `truth` (none where the two do not
/// overlap); its rows are summed in `pool`, the reconstruction's.
fn score(
    reconstruction: &WindowReconstruction,
    truth: &TruthDepth,
    pool: &rayon::ThreadPool,
) -> Result<FrameAccuracy, VideoError> {
    match pool.install(|| score_depth(reconstruction.depth_mm(), &truth.depth_mm, None)) {
        Ok(score) => Ok(FrameAccuracy {
            rmse_mm: Some(score.rmse_mm),
            nrmse: score.nrmse,
            reconstructed_fraction: score.reconstructed_fraction,
            truth_frame: truth.frame,
        }),
        Err(MetricsError::NoOverlap) => Ok(FrameAccuracy {
            rmse_mm: None,
            nrmse: None,
            reconstructed_fraction: 0.0,
            truth_frame: truth.frame,
        }),
        Err(error) => Err(error.into()),
    }
}
