//! `meb.video`: 3-D video as an iterator of 3-D frames, from
//! [`meb_pipeline::video::process`] (the pipeline of `meb video`) running on a thread of its
//! own and handing each frame over as it is done.

use crate::decode::{led_count, linearize};
use crate::errors::{MebError, meb_error};
use crate::json::to_python;
use crate::rig::rig_of;
use meb_core::capture::memory::MemorySource;
use meb_core::capture::{Frame, FrameFormat, FrameSource, OpenOptions, Samples, open};
use meb_core::stop::StopSignal;
use meb_pipeline::demod::LedCount;
use meb_pipeline::video::{
    FrameRecord, VideoConfig, VideoError, VideoFrame as RustVideoFrame, VideoSummary,
    WindowReconstruction, WindowSchedule, process_until,
};
use ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyStopIteration, PyTypeError, PyValueError};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::mpsc::{Receiver, RecvTimeoutError, sync_channel};
use std::thread::JoinHandle;
use std::time::Duration;

/// How often a wait for the next 3-D frame lets Python handle its signals (Ctrl-C).
const SIGNAL_POLL: Duration = Duration::from_millis(100);

/// What the pipeline thread hands over: a 3-D frame, or the end of the run.
enum Item {
    Frame(Box<Owned>),
    End(Result<VideoSummary, VideoError>),
}

/// One 3-D frame's record and arrays, owned.
struct Owned {
    record: FrameRecord,
    depth: Option<Array2<f32>>,
    normals: Option<Array3<f32>>,
    camera_frames: usize,
}

/// The arrays of a video frame, taken from the library's borrowed frame.
fn owned(frame: &RustVideoFrame<'_>) -> Owned {
    let (depth, normals) = match frame.reconstruction {
        Some(WindowReconstruction::Frame(r)) => (
            Some(r.integration.depth.depth_mm.clone()),
            Some(r.photometric.field.normals.clone()),
        ),
        Some(WindowReconstruction::Region { depth_mm, .. }) => (Some(depth_mm.clone()), None),
        None => (None, None),
    };
    Owned {
        record: frame.record.clone(),
        depth,
        normals,
        camera_frames: frame.camera_frames,
    }
}

/// One 3-D frame of a video: its record (window, status, timing, motion) and, when it was
/// reconstructed, its depth (and normals, for a window reconstructed whole).
#[pyclass(module = "meb", frozen, get_all)]
pub struct VideoFrame {
    /// 3-D frame number, from 0.
    pub index: usize,
    /// "ok", "skipped" or "failed" (the record's status).
    pub status: Py<PyAny>,
    /// The frame's record, as in `video.json`.
    pub record: Py<PyAny>,
    /// H×W float32 depth in mm (NaN where not reconstructed), or None.
    pub depth: Py<PyAny>,
    /// H×W×3 float32 normals for a window reconstructed whole, else None.
    pub normals: Py<PyAny>,
    /// Camera frames read so far.
    pub camera_frames: usize,
}

#[pymethods]
impl VideoFrame {
    fn __repr__(&self, py: Python<'_>) -> String {
        format!("VideoFrame({}, {})", self.index, self.status.bind(py))
    }
}

/// An iterator of 3-D frames; `summary` holds the run's summary once it is exhausted.
///
/// A wait for the next frame handles Python's signals every [`SIGNAL_POLL`]: Ctrl-C raises
/// `KeyboardInterrupt` from `next()` while the pipeline goes on; `stop()` then ends the stream
/// as `meb video`'s first Ctrl-C does (the windows the frames already read complete are still
/// yielded, and the summary's `end` is `"interrupted"`), `close()` drops the rest.
#[pyclass(module = "meb")]
pub struct Video {
    receiver: Mutex<Option<Receiver<Item>>>,
    worker: Option<JoinHandle<()>>,
    summary: Option<Py<PyAny>>,
    stop: StopSignal,
}

#[pymethods]
impl Video {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<VideoFrame> {
        // The receiver leaves its lock while waiting, so that `close` from another thread
        // is not blocked behind a wait.
        let receiver = self
            .receiver
            .lock()
            .map_err(|_| MebError::new_err("the video iterator failed earlier"))?
            .take();
        let Some(receiver) = receiver else {
            return Err(PyStopIteration::new_err(()));
        };
        let mut receiver = receiver;
        let waited = loop {
            let (waited, back) = py.detach(move || (receiver.recv_timeout(SIGNAL_POLL), receiver));
            receiver = back;
            match waited {
                Ok(item) => break Ok(Some(item)),
                Err(RecvTimeoutError::Disconnected) => break Ok(None),
                Err(RecvTimeoutError::Timeout) => {
                    if let Err(interrupt) = py.check_signals() {
                        break Err(interrupt);
                    }
                }
            }
        };
        if let Ok(mut guard) = self.receiver.lock() {
            *guard = Some(receiver);
        }
        match waited? {
            Some(Item::Frame(frame)) => {
                let frame = *frame;
                Ok(VideoFrame {
                    index: frame.record.index,
                    status: to_python(py, &frame.record.status)?,
                    record: to_python(py, &frame.record)?,
                    depth: frame
                        .depth
                        .map_or_else(|| py.None(), |d| d.into_pyarray(py).into_any().unbind()),
                    normals: frame
                        .normals
                        .map_or_else(|| py.None(), |n| n.into_pyarray(py).into_any().unbind()),
                    camera_frames: frame.camera_frames,
                })
            }
            Some(Item::End(result)) => {
                self.finish(py);
                match result {
                    Ok(summary) => {
                        self.summary = Some(to_python(py, &summary)?);
                        Err(PyStopIteration::new_err(()))
                    }
                    Err(e) => Err(meb_error(Some("cannot make a 3-D video"), &e)),
                }
            }
            None => {
                self.finish(py);
                Err(MebError::new_err(
                    "the video pipeline stopped without a summary",
                ))
            }
        }
    }

    /// The run's summary (`video.json`'s): frames read, windows, reconstructed, skipped,
    /// failed, wall time; None until the iterator is exhausted.
    #[getter]
    fn summary(&self, py: Python<'_>) -> Option<Py<PyAny>> {
        self.summary.as_ref().map(|s| s.clone_ref(py))
    }

    /// Ends the stream as `meb video`'s first Ctrl-C does: the pipeline reads no more camera
    /// frames, the windows the frames already read complete are still yielded, and the
    /// summary's `end` is `"interrupted"`.
    fn stop(&self) {
        self.stop.stop();
    }

    /// Stops the pipeline (the frames not yet taken are dropped).
    fn close(&mut self, py: Python<'_>) {
        self.finish(py);
    }
}

impl Video {
    /// Drops the receiver (the pipeline's next hand-over fails and it stops) and joins the
    /// thread.
    fn finish(&mut self, py: Python<'_>) {
        if let Ok(mut guard) = self.receiver.lock() {
            guard.take();
        }
        if let Some(worker) = self.worker.take() {
            // A panicking pipeline thread has already reported through the channel's close.
            let _ = py.detach(|| worker.join());
        }
    }
}

impl Drop for Video {
    fn drop(&mut self) {
        if let Ok(mut guard) = self.receiver.lock() {
            guard.take();
        }
    }
}

/// The frames of `source`: a file, or a frame array (copied into the pipeline's own frame
/// queue, which outlives the call).
fn frame_source(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    fps: Option<f64>,
) -> PyResult<Box<dyn FrameSource>> {
    if let Ok(array) = source.cast::<numpy::PyUntypedArray>() {
        let shape = array.shape().to_vec();
        let [count, height, width] = shape[..] else {
            return Err(PyValueError::new_err(format!(
                "frames must be a 3-D array (frames, height, width), got shape {shape:?}"
            )));
        };
        let fps = fps.unwrap_or(0.0);
        let frames: Vec<Samples> = if let Ok(a) = array.cast::<numpy::PyArray3<u8>>() {
            let a = a.readonly();
            let view = a.as_array();
            view.outer_iter()
                .map(|f| Samples::U8(f.iter().copied().collect()))
                .collect()
        } else if let Ok(a) = array.cast::<numpy::PyArray3<u16>>() {
            let a = a.readonly();
            let view = a.as_array();
            view.outer_iter()
                .map(|f| Samples::U16(f.iter().copied().collect()))
                .collect()
        } else {
            return Err(PyTypeError::new_err(format!(
                "frames must be uint8 or uint16 code values, got {}",
                array.dtype()
            )));
        };
        let bits = if matches!(frames.first(), Some(Samples::U16(_))) {
            16
        } else {
            8
        };
        let format = FrameFormat::full_range(width, height, bits, fps);
        let frames = frames
            .into_iter()
            .enumerate()
            .map(|(index, samples)| Frame { index, samples })
            .collect::<Vec<_>>();
        debug_assert_eq!(frames.len(), count);
        let source = MemorySource::new(format, frames)
            .map_err(|e| meb_error(Some("cannot read the frames"), &e))?;
        return Ok(Box::new(source));
    }
    let path: PathBuf = source.extract().map_err(|_| {
        PyTypeError::new_err(
            "source must be a frame array (frames, height, width) or a path to a capture",
        )
    })?;
    let options = OpenOptions { fps, raw: None };
    py.detach(|| open(&path, &options))
        .map_err(|e| meb_error(Some(&format!("cannot open {}", path.display())), &e))
}

/// Reconstructs a video window by window (see the package's `video`).
#[pyfunction]
#[pyo3(signature = (
    source, rig, *, window = 40, drop = 4, hop = None, leds = None, fps = None, bin = 1,
    linearize = "none", integrator = "least-squares", max_frames = None, force = false
))]
#[allow(clippy::too_many_arguments)]
pub fn video(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    rig: &Bound<'_, PyAny>,
    window: usize,
    drop: usize,
    hop: Option<usize>,
    leds: Option<&Bound<'_, PyAny>>,
    fps: Option<f64>,
    bin: usize,
    linearize: &str,
    integrator: &str,
    max_frames: Option<usize>,
    force: bool,
) -> PyResult<Video> {
    let rig = rig_of(rig)?.inner;
    let leds = leds
        .map(led_count)
        .transpose()?
        .unwrap_or(LedCount::Fixed(rig.leds.len()));
    if bin == 0 {
        return Err(PyValueError::new_err("bin must be at least 1"));
    }
    let mut config = VideoConfig::thesis(rig.leds.len());
    config.schedule = WindowSchedule {
        window,
        drop,
        hop: hop.unwrap_or(window),
    };
    config.decode.leds = leds;
    config.decode.fps = fps;
    config.decode.linearize = self::linearize_of(linearize)?;
    if force {
        config.decode.on_implausible = meb_pipeline::demod::OnImplausible::Keep;
    }
    config.reconstruct.integrate.integrator = crate::reconstruct::integrator(integrator)?;
    config.bin = bin;
    config.max_frames = max_frames;
    let source = frame_source(py, source, fps)?;
    let (sender, receiver) = sync_channel::<Item>(1);
    let stop = StopSignal::new();
    let stopped = stop.clone();
    let worker = std::thread::Builder::new()
        .name("meb-video".into())
        .spawn(move || {
            let result = process_until(source, &rig, &config, None, &stopped, &mut |frame| {
                sender
                    .send(Item::Frame(Box::new(owned(frame))))
                    .map_err(|_| VideoError::Encode("the Python iterator was closed".into()))
            });
            // The receiver may be gone (iterator closed): nothing to report to.
            let _ = sender.send(Item::End(result));
        })
        .map_err(|e| meb_error(Some("cannot start the video thread"), &e))?;
    Ok(Video {
        receiver: Mutex::new(Some(receiver)),
        worker: Some(worker),
        summary: None,
        stop,
    })
}

/// The linearisation of `name` (as `decode`'s).
fn linearize_of(name: &str) -> PyResult<meb_pipeline::demod::Linearize> {
    linearize(name)
}
