//! The live view of `meb video --live`: a local web page that shows each 3-D frame as its window
//! completes (the surface in three.js, shaded and depth pictures, the window's verdict, the 3-D
//! frame rate and the decode and reconstruction times), pushed with server-sent events.
//!
//! The pipeline never waits for a browser: [`LiveView::publish`] makes a small copy of the
//! window (its depth sampled down to at most [`LIVE_VERTICES`] points for the mesh and to
//! [`LIVE_PICTURE_WIDTH`] pixels wide for the pictures) and replaces the latest frame in a
//! `tokio::sync::watch` slot; nothing queues. The server turns the latest frame into an event
//! (mesh, PNG pictures, figures) only when a page is connected, on its own thread and runtime,
//! and sends each page only the newest frame it has not seen, at most one a second. It
//! serves fixed routes only (`/` the page, `/events` the event stream); every other path is 404
//! and no request reaches the file system. Dropping the [`LiveView`] stops the server.

mod page;
mod server;

use meb_core::types::DepthMap;
use meb_pipeline::video::{FrameStatus, VideoFrame, WindowVerdict};
use ndarray::{Array2, s};
use std::net::SocketAddr;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{SystemTime, UNIX_EPOCH};
use thiserror::Error;
use tokio::sync::{oneshot, watch};

/// Most points of the surface a live event carries; larger surfaces are sub-sampled.
pub const LIVE_VERTICES: usize = 8_000;

/// Largest width of a live event's shaded and depth pictures, pixels.
pub const LIVE_PICTURE_WIDTH: usize = 320;

/// The port `meb video --live` serves on unless told otherwise.
pub const DEFAULT_PORT: u16 = 8960;

/// Errors starting the live view.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum LiveError {
    /// The address could not be bound (e.g. the port is in use).
    #[error(
        "cannot serve the live view on {addr}: {source} (choose another with --port, or --port 0 for a free one)"
    )]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The server's thread or runtime could not be started.
    #[error("cannot start the live view's server: {0}")]
    Start(#[source] std::io::Error),
}

/// What a window's live event shows, copied out of the pipeline's frame (module docs).
#[derive(Debug, Clone)]
pub struct LiveFrame {
    /// 3-D frames done so far (this one included).
    pub done: usize,
    /// The window's 3-D frame number.
    pub index: usize,
    /// Camera frames read so far.
    pub camera_frames: usize,
    /// Camera frames in the stream, when known.
    pub total_frames: Option<usize>,
    /// What became of the window.
    pub status: FrameStatus,
    /// The decoder's verdict with the window's motion (`None` when decoding failed).
    pub verdict: Option<WindowVerdict>,
    /// Whether the object moved in the window.
    pub moving: bool,
    /// Why the window was skipped or failed.
    pub reason: Option<String>,
    /// 3-D frames per second of wall-clock time so far.
    pub frames_per_second: f64,
    /// Decoding time, ms.
    pub decode_ms: f64,
    /// Reconstruction time, ms.
    pub reconstruct_ms: f64,
    /// Depth RMSE against the truth, mm (with a ground truth).
    pub rmse_mm: Option<f64>,
    /// When the window completed, ms since the Unix epoch.
    pub timestamp_ms: u64,
    /// The reconstructed surface, sub-sampled to at most [`LIVE_VERTICES`] points.
    pub surface: Option<DepthMap>,
    /// The depth over the whole frame, every `factor`-th pixel (at most
    /// [`LIVE_PICTURE_WIDTH`] wide), with its grid pitch in mm.
    pub picture_depth: Option<(Array2<f32>, f64)>,
}

impl LiveFrame {
    /// The live copy of `frame`, the `done`-th 3-D frame after `seconds` of processing, on a
    /// frame grid of `pitch_mm` per pixel.
    pub fn of(frame: &VideoFrame, done: usize, seconds: f64, pitch_mm: f64) -> Self {
        let record = &frame.record;
        let reconstruction = frame
            .reconstruction
            .filter(|_| record.status == FrameStatus::Reconstructed);
        let points = record.reconstruction.as_ref().map(|r| r.object_pixels);
        let surface =
            reconstruction.map(|r| sub_sampled(&r.reconstruction().integration.depth, points));
        let picture_depth = reconstruction.map(|r| {
            let depth = r.depth_mm();
            let factor = depth.ncols().div_ceil(LIVE_PICTURE_WIDTH).max(1);
            (
                depth.slice(s![..;factor, ..;factor]).to_owned(),
                pitch_mm * factor as f64,
            )
        });
        Self {
            done,
            index: record.index,
            camera_frames: frame.camera_frames,
            total_frames: frame.total_frames,
            status: record.status,
            verdict: record.verdict,
            moving: record.motion.is_some_and(|m| m.moving),
            reason: record.reason.clone(),
            frames_per_second: done as f64 / seconds.max(1e-9),
            decode_ms: record.timing.decode_ms,
            reconstruct_ms: record.timing.reconstruct_ms,
            rmse_mm: record.accuracy.as_ref().and_then(|a| a.rmse_mm),
            timestamp_ms: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_millis() as u64),
            surface,
            picture_depth,
        }
    }
}

/// `depth` on every k-th row and column, k the smallest step that leaves at most
/// [`LIVE_VERTICES`] of its `points` finite values (counted when not given).
fn sub_sampled(depth: &DepthMap, points: Option<usize>) -> DepthMap {
    let points = points.unwrap_or_else(|| depth.depth_mm.iter().filter(|z| z.is_finite()).count());
    let step = (1..)
        .find(|k| points / (k * k) <= LIVE_VERTICES)
        .unwrap_or(1);
    DepthMap {
        depth_mm: depth.depth_mm.slice(s![..;step, ..;step]).to_owned(),
        pitch_mm: depth.pitch_mm * step as f64,
        perspective: depth.perspective.map(|p| p.every(step)),
    }
}

/// The latest frame, shared by the pipeline (writer) and the server (readers).
type Latest = Option<Arc<LiveFrame>>;

/// A running live view (module docs); dropping it stops the server.
pub struct LiveView {
    latest: watch::Sender<Latest>,
    addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl LiveView {
    /// Binds `addr` (port 0: a free one) and serves the live view on its own thread. Fails
    /// at once when the address cannot be bound.
    pub fn start(addr: SocketAddr) -> Result<Self, LiveError> {
        let listener =
            std::net::TcpListener::bind(addr).map_err(|source| LiveError::Bind { addr, source })?;
        let bound = listener
            .local_addr()
            .map_err(|source| LiveError::Bind { addr, source })?;
        listener
            .set_nonblocking(true)
            .map_err(|source| LiveError::Bind { addr, source })?;
        let (latest, receiver) = watch::channel(None);
        let (stop, stopped) = oneshot::channel();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()
            .map_err(LiveError::Start)?;
        let thread = std::thread::Builder::new()
            .name("meb-live-view".into())
            .spawn(move || server::run(runtime, listener, receiver, stopped))
            .map_err(LiveError::Start)?;
        Ok(Self {
            latest,
            addr: bound,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The address served.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The page's URL.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// Makes `frame` (the `done`-th 3-D frame, after `seconds` of processing, on a grid of
    /// `pitch_mm` per pixel) the latest one: a small copy replaces the one before, whether or
    /// not a page is watching.
    pub fn publish(&self, frame: &VideoFrame, done: usize, seconds: f64, pitch_mm: f64) {
        let live = LiveFrame::of(frame, done, seconds, pitch_mm);
        self.latest.send_replace(Some(Arc::new(live)));
    }
}

impl Drop for LiveView {
    /// Stops the server and waits for its thread.
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_large_surface_is_sub_sampled_to_the_live_limit() {
        let depth = DepthMap {
            depth_mm: Array2::from_elem((720, 1280), 400.0),
            pitch_mm: 0.25,
            perspective: None,
        };
        let small = sub_sampled(&depth, None);
        let points = small.depth_mm.len();
        assert!(points <= LIVE_VERTICES, "{points}");
        assert!(points > LIVE_VERTICES / 2, "{points}");
        let step = 1280_f64 / small.depth_mm.ncols() as f64;
        assert!((small.pitch_mm - 0.25 * step.ceil()).abs() < 1e-9);
        // A small one is kept whole.
        let whole = sub_sampled(&depth, Some(LIVE_VERTICES));
        assert_eq!(whole.depth_mm.dim(), (720, 1280));
    }

    #[test]
    fn a_port_in_use_is_an_error_naming_the_address() {
        let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = taken.local_addr().unwrap();
        let error = LiveView::start(addr).err().unwrap();
        assert!(matches!(error, LiveError::Bind { .. }));
        assert!(error.to_string().contains(&addr.to_string()), "{error}");
        let free = LiveView::start("127.0.0.1:0".parse().unwrap()).unwrap();
        assert_ne!(free.addr().port(), 0);
        assert!(free.url().starts_with("http://127.0.0.1:"));
    }
}
