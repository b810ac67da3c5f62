//! The live view's HTTP server: `/` (the page), `/events` (server-sent events, one per new
//! 3-D frame) and 404 for every other path. Each event is built from the latest frame only when
//! a page asks for it, once for all pages, off the server's async thread.
//!
//! Served on a loopback address, it answers only requests whose `Host` names a loopback host
//! (`localhost`, `127.0.0.1`, `[::1]`, with any port), and 403 to others: a web page from
//! elsewhere cannot read the view through a DNS name rebound to 127.0.0.1. Served on another
//! address (`--listen`), it answers every host.

use super::{Latest, LiveFrame, page};
use crate::export::mesh::SurfaceMesh;
use crate::export::viewer::mesh_base64;
use axum::Router;
use axum::extract::{Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::middleware::{Next, from_fn_with_state};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use base64::Engine;
use futures_util::stream::Stream;
use meb_pipeline::video::render::{PictureSize, depth_range, pictures};
use meb_pipeline::video::{FrameStatus, WindowVerdict};
use std::convert::Infallible;
use std::future::IntoFuture;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};
use std::time::{Duration, Instant};
use tokio::sync::{oneshot, watch};

/// The shortest time between two events to a page (at most 1 a second): the browser often runs
/// on the pipeline's cores without a GPU, where repainting the page for one event costs it
/// 40–100 ms of CPU (docs/live-view.md).
const EVENT_INTERVAL: Duration = Duration::from_millis(1000);

/// What the handlers share.
struct Shared {
    /// The page, built once.
    page: String,
    /// The latest frame.
    latest: watch::Receiver<Latest>,
    /// The event of the latest frame built so far: (3-D frames done, event data).
    event: Mutex<Option<(usize, Arc<str>)>>,
    /// Depth range of the depth pictures, mm: that of the first 3-D frame, so colours stay.
    range: OnceLock<(f32, f32)>,
    /// Whether only requests naming a loopback host are answered (module docs).
    loopback: bool,
}

/// Serves on `listener` until `stopped` fires (or its sender is dropped), then drops every
/// connection.
pub(super) fn run(
    runtime: tokio::runtime::Runtime,
    listener: std::net::TcpListener,
    latest: watch::Receiver<Latest>,
    stopped: oneshot::Receiver<()>,
) {
    runtime.block_on(async move {
        let listener = match tokio::net::TcpListener::from_std(listener) {
            Ok(listener) => listener,
            Err(e) => {
                eprintln!("live view stopped: {e}");
                return;
            }
        };
        // An address that cannot be read is treated as loopback: the check then stays on.
        let loopback = listener.local_addr().map_or(true, |a| a.ip().is_loopback());
        let shared = Arc::new(Shared {
            page: page::html(),
            latest,
            event: Mutex::new(None),
            range: OnceLock::new(),
            loopback,
        });
        let serve = axum::serve(listener, router(shared)).into_future();
        tokio::select! {
            served = serve => {
                if let Err(e) = served {
                    eprintln!("live view stopped: {e}");
                }
            }
            _ = stopped => {}
        }
    });
    runtime.shutdown_timeout(Duration::from_millis(500));
}

/// The fixed routes; anything else is 404; on a loopback address, a request naming another
/// host is 403.
fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/events", get(events))
        .fallback(not_found)
        .layer(from_fn_with_state(shared.clone(), loopback_host))
        .with_state(shared)
}

/// Refuses (403) a request whose `Host` is not a loopback host when serving on loopback.
async fn loopback_host(
    State(shared): State<Arc<Shared>>,
    request: Request,
    next: Next,
) -> Response {
    if shared.loopback && !names_loopback(request.headers()) {
        let refusal = "forbidden: this live view answers only localhost, 127.0.0.1 or [::1]\n";
        return (StatusCode::FORBIDDEN, refusal).into_response();
    }
    next.run(request).await
}

/// Whether the request's `Host` (without its port) is `localhost` or a loopback address.
fn names_loopback(headers: &HeaderMap) -> bool {
    let Some(host) = headers.get(header::HOST).and_then(|h| h.to_str().ok()) else {
        return false;
    };
    let name = match host.strip_prefix('[') {
        Some(bracketed) => bracketed.split_once(']').map_or("", |(ip, _)| ip),
        None => host.split_once(':').map_or(host, |(name, _)| name),
    };
    name.eq_ignore_ascii_case("localhost")
        || name
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

async fn index(State(shared): State<Arc<Shared>>) -> impl IntoResponse {
    (
        [(header::CACHE_CONTROL, "no-store")],
        Html(shared.page.clone()),
    )
}

async fn not_found() -> impl IntoResponse {
    (StatusCode::NOT_FOUND, "not found\n")
}

/// The event stream of one page: the latest frame at once (event type `current`), then the
/// newest one as frames come (type `frame`), at most one per [`EVENT_INTERVAL`]: after a
/// pause the next frame to come is sent as it comes, and the one that came during the pause
/// only if no other follows within an interval; frames that came while the page was still
/// receiving an older one are passed over.
async fn events(
    State(shared): State<Arc<Shared>>,
) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let mut latest = shared.latest.clone();
    let replay = latest.borrow().is_some();
    latest.mark_changed();
    let stream = futures_util::stream::unfold(
        (latest, shared, replay, None::<Instant>),
        |(mut latest, shared, replay, sent)| async move {
            loop {
                // The pipeline has ended when the sender is gone.
                latest.changed().await.ok()?;
                // At most one event per EVENT_INTERVAL. A frame that came during the pause is
                // passed over for the next one, sent as soon as it comes, so that a page shows
                // frames when they are new; only when none comes within another interval (a
                // slow or ended stream) is the one that waited sent.
                if let Some(ready) = sent.map(|sent| sent + EVENT_INTERVAL)
                    && Instant::now() < ready
                {
                    tokio::time::sleep_until(ready.into()).await;
                    latest.borrow_and_update();
                    // Timed out, or the stream ended: the waiting frame is the newest there is.
                    let _ = tokio::time::timeout(EVENT_INTERVAL, latest.changed()).await;
                }
                let Some(frame) = latest.borrow_and_update().clone() else {
                    continue;
                };
                let data = shared.event_data(frame).await;
                let kind = if replay { "current" } else { "frame" };
                let event = Event::default().event(kind).data(&*data);
                return Some((Ok(event), (latest, shared, false, Some(Instant::now()))));
            }
        },
    );
    Sse::new(stream).keep_alive(KeepAlive::default())
}

impl Shared {
    /// The event of `frame`, built once for every page.
    async fn event_data(self: &Arc<Self>, frame: Arc<LiveFrame>) -> Arc<str> {
        let cached = self
            .event
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .as_ref()
            .filter(|(done, _)| *done == frame.done)
            .map(|(_, data)| data.clone());
        if let Some(data) = cached {
            return data;
        }
        let done = frame.done;
        let shared = self.clone();
        let data: Arc<str> = match tokio::task::spawn_blocking(move || shared.build(&frame)).await {
            Ok(data) => data.into(),
            Err(e) => serde_json::json!({ "done": done, "error": e.to_string() })
                .to_string()
                .into(),
        };
        *self.event.lock().unwrap_or_else(PoisonError::into_inner) = Some((done, data.clone()));
        data
    }

    /// The event data of `frame`: its figures, its surface as a mesh and its pictures as PNG.
    fn build(&self, frame: &LiveFrame) -> String {
        let mesh = frame.surface.as_ref().map(|depth| {
            let mesh = SurfaceMesh::from_depth(depth);
            let (positions, indices) = mesh_base64(&mesh);
            serde_json::json!({
                "positions": positions,
                "indices": indices,
                "vertices": mesh.vertices.len(),
                "triangles": mesh.triangles.len(),
            })
        });
        let mut shaded = None;
        let mut coloured = None;
        if let Some((depth, pitch_mm)) = &frame.picture_depth {
            if self.range.get().is_none()
                && let Some(range) = depth_range(depth)
            {
                let _ = self.range.set(range);
            }
            let (lo, hi) = self.range.get().copied().unwrap_or((0.0, 1.0));
            let size = PictureSize::fit(depth.ncols(), depth.nrows(), 0);
            let drawn = pictures(depth, size, *pitch_mm, lo, hi);
            shaded = png_data_url(&drawn.shaded);
            coloured = png_data_url(&drawn.depth);
        }
        serde_json::json!({
            "done": frame.done,
            "index": frame.index,
            "camera_frames": frame.camera_frames,
            "total_frames": frame.total_frames,
            "state": state(frame),
            "status": frame.status,
            "verdict": frame.verdict,
            "moving": frame.moving,
            "reason": frame.reason,
            "frames_per_second": frame.frames_per_second,
            "decode_ms": frame.decode_ms,
            "reconstruct_ms": frame.reconstruct_ms,
            "rmse_mm": frame.rmse_mm,
            "timestamp_ms": frame.timestamp_ms,
            "depth_range_mm": self.range.get(),
            "mesh": mesh,
            "shaded": shaded,
            "depth": coloured,
        })
        .to_string()
    }
}

/// One word for what became of the window: `plausible`, `motion`, `forced` (reconstructed, by
/// the decoder's verdict with the window's motion), `skipped`, `refused` or `failed`.
fn state(frame: &LiveFrame) -> &'static str {
    match (frame.status, frame.verdict) {
        (FrameStatus::Skipped, _) => "skipped",
        (FrameStatus::Failed, Some(WindowVerdict::Refused)) => "refused",
        (FrameStatus::Failed, _) => "failed",
        (FrameStatus::Reconstructed, Some(WindowVerdict::Motion)) => "motion",
        (FrameStatus::Reconstructed, Some(WindowVerdict::Forced)) => "forced",
        (FrameStatus::Reconstructed, _) if frame.moving => "motion",
        (FrameStatus::Reconstructed, _) => "plausible",
    }
}

/// `picture` as a `data:image/png;base64,…` URL (`None` if it cannot be encoded).
fn png_data_url(picture: &image::RgbImage) -> Option<String> {
    let mut png = Vec::new();
    picture
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .ok()?;
    Some(format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(png)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn host(value: &str) -> HeaderMap {
        let mut headers = HeaderMap::new();
        headers.insert(header::HOST, value.parse().unwrap());
        headers
    }

    #[test]
    fn only_loopback_hosts_name_the_loopback_view() {
        for name in [
            "localhost",
            "LOCALHOST:8960",
            "127.0.0.1",
            "127.0.0.1:8960",
            "127.1.2.3:80",
            "[::1]",
            "[::1]:8960",
        ] {
            assert!(names_loopback(&host(name)), "{name}");
        }
        for name in [
            "evil.example",
            "evil.example:8960",
            "localhost.evil.example",
            "192.168.1.20:8960",
            "[2001:db8::1]:8960",
            "[::1",
            "",
        ] {
            assert!(!names_loopback(&host(name)), "{name}");
        }
        assert!(!names_loopback(&HeaderMap::new()));
    }
}
