//! The outputs written on their own thread, so that writing arrays, drawing the pictures and
//! feeding FFmpeg overlap the next window's reconstruction.
//!
//! [`OutputThread::add`] copies a window's record and arrays (depth, and the normals and albedo
//! when they are saved) and queues them; at most [`QUEUED_FRAMES`] wait, so memory stays bounded
//! and a writer slower than the reconstruction slows the run down instead of piling frames up.
//! The first error stops the writer; the next [`OutputThread::add`] or the
//! [`OutputThread::finish`] returns it.

use super::output::{FrameArrays, VideoOutput};
use super::{FrameRecord, FrameStatus, VideoError, VideoFrame};
use ndarray::{Array2, Array3};
use std::sync::mpsc::{SyncSender, sync_channel};
use std::thread::JoinHandle;

/// Windows that may wait for the writer.
pub const QUEUED_FRAMES: usize = 2;

/// A window's record and arrays, owned, on their way to the writer.
struct OwnedArrays {
    record: FrameRecord,
    depth: Option<Array2<f32>>,
    normals: Option<Array3<f32>>,
    albedo: Option<Array2<f32>>,
}

/// A [`VideoOutput`] written on its own thread (module docs).
pub struct OutputThread {
    sender: Option<SyncSender<OwnedArrays>>,
    handle: Option<JoinHandle<Result<VideoOutput, VideoError>>>,
    normals: bool,
    albedo: bool,
}

impl OutputThread {
    /// Starts writing into `output` on a new thread.
    pub fn start(mut output: VideoOutput) -> Result<Self, VideoError> {
        let (normals, albedo) = (output.options().normals, output.options().albedo);
        let (sender, receiver) = sync_channel::<OwnedArrays>(QUEUED_FRAMES);
        let handle = std::thread::Builder::new()
            .name("meb-video-writer".into())
            .spawn(move || {
                for frame in receiver {
                    output.add_arrays(FrameArrays {
                        record: frame.record,
                        depth: frame.depth.as_ref(),
                        normals: frame.normals.as_ref(),
                        albedo: frame.albedo.as_ref(),
                    })?;
                }
                Ok(output)
            })
            .map_err(|e| VideoError::Encode(format!("cannot start the output writer: {e}")))?;
        Ok(Self {
            sender: Some(sender),
            handle: Some(handle),
            normals,
            albedo,
        })
    }

    /// Queues one window's outputs (waits while [`QUEUED_FRAMES`] are queued); returns the
    /// writer's error when it has stopped.
    pub fn add(&mut self, frame: &VideoFrame) -> Result<(), VideoError> {
        let reconstruction = frame
            .reconstruction
            .filter(|_| frame.record.status == FrameStatus::Reconstructed);
        let arrays = OwnedArrays {
            record: frame.record.clone(),
            depth: reconstruction.map(|r| r.depth_mm().clone()),
            normals: reconstruction
                .filter(|_| self.normals)
                .map(|r| r.normals().into_owned()),
            albedo: reconstruction
                .filter(|_| self.albedo)
                .map(|r| r.albedo().into_owned()),
        };
        let sent = match &self.sender {
            Some(sender) => sender.send(arrays).is_ok(),
            None => false,
        };
        if sent {
            return Ok(());
        }
        // The writer stopped: its error says why.
        self.join().map(|_| ())
    }

    /// Waits for the queued windows to be written and returns the output, to be finished.
    pub fn finish(mut self) -> Result<VideoOutput, VideoError> {
        self.join()
    }

    /// Closes the queue and waits for the writer.
    fn join(&mut self) -> Result<VideoOutput, VideoError> {
        self.sender = None;
        match self.handle.take() {
            Some(handle) => handle
                .join()
                .map_err(|_| VideoError::Encode("the output writer panicked".into()))?,
            None => Err(VideoError::Encode("the output writer has stopped".into())),
        }
    }
}

impl Drop for OutputThread {
    /// Lets the writer end (its FFmpeg process with it) before the folder goes away.
    fn drop(&mut self) {
        let _ = self.join();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::video::encode::VideoContainer;
    use crate::video::output::OutputOptions;
    use crate::video::{EndKind, FrameTiming, TimingSource, VideoSummary};

    fn record(index: usize) -> FrameRecord {
        FrameRecord {
            index,
            frames: (40 * index, 40 * index + 40),
            decoded: (40 * index + 4, 40 * index + 36),
            time_s: None,
            status: FrameStatus::Failed,
            reason: Some("test".into()),
            placed_by: 0,
            decode_region: None,
            widened: false,
            verdict: None,
            timing_source: TimingSource::Fitted,
            motion: None,
            decode: None,
            reconstruction: None,
            accuracy: None,
            timing: FrameTiming::default(),
        }
    }

    fn frame(index: usize) -> VideoFrame<'static> {
        VideoFrame {
            record: record(index),
            decoded: None,
            reconstruction: None,
            camera_frames: 40 * index + 40,
            total_frames: None,
        }
    }

    fn output(dir: &std::path::Path) -> VideoOutput {
        let options = OutputOptions {
            container: VideoContainer::Apng,
            ..OutputOptions::default()
        };
        VideoOutput::create(dir, 8, 6, 1.0, options).unwrap()
    }

    fn summary(windows: usize) -> VideoSummary {
        VideoSummary {
            camera_frames: 40 * windows,
            windows,
            reconstructed: 0,
            skipped: 0,
            failed: windows,
            moving: 0,
            focused: 0,
            end: EndKind::Complete,
            input_error: None,
            wall_s: 1.0,
            frames_per_second: windows as f64,
        }
    }

    #[test]
    fn every_queued_window_is_written_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let mut thread = OutputThread::start(output(dir.path())).unwrap();
        for k in 0..7 {
            thread.add(&frame(k)).unwrap();
        }
        let output = thread.finish().unwrap();
        assert_eq!(output.timing().windows, 7);
        let written = output.finish(serde_json::json!({}), &summary(7)).unwrap();
        assert_eq!(written.frames_written, 0);
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("video.json")).unwrap()).unwrap();
        let indices: Vec<u64> = json["frames"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f["index"].as_u64().unwrap())
            .collect();
        assert_eq!(indices, (0..7).collect::<Vec<_>>());
    }

    #[test]
    fn a_failed_write_is_reported_not_lost() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir(&out).unwrap();
        let mut thread = OutputThread::start(output(&out)).unwrap();
        // The folder disappears under the writer: the pictures cannot be stored.
        std::fs::remove_dir_all(&out).unwrap();
        let mut error = None;
        for k in 0..2 * QUEUED_FRAMES + 2 {
            if let Err(e) = thread.add(&frame(k)) {
                error = Some(e);
                break;
            }
        }
        let error = match error {
            Some(e) => e,
            None => thread.finish().err().expect("the writer's error"),
        };
        assert!(error.to_string().contains("out"), "{error}");
    }
}
