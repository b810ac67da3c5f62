//! What `meb video` records of each window and of the run: the window's status, decode and
//! reconstruction quality, accuracy against the truth, stage timings (`video.json`), and the
//! 3-D frame handed to the caller.

use super::*;
use crate::demod::nuisance::RoomReport;

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
    /// What the decoder found of the room in the window (flicker, exposure drift, frames the
    /// camera dropped or repeated, with frames counted from the window's first decoded frame);
    /// absent when it found nothing.
    #[serde(default, skip_serializing_if = "RoomReport::is_quiet")]
    pub room: RoomReport,
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
            room: report.room.clone(),
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
    /// A stop request ended a live stream ([`super::process_until`]; `meb video`: the first
    /// interrupt).
    Interrupted,
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
