//! `meb video - --live`: the live view served while a simulated y4m stream comes through a pipe,
//! opened in headless Chromium driven over the DevTools protocol (its WebSocket): the page's
//! frame counter and 3-D view advance, it measures the event latency, a screenshot shows the
//! surface, and a SIGINT mid-stream still leaves a complete folder. Every path but the page's
//! own is 404, a request naming another host than the loopback is 403, and a port in use is
//! refused before any processing.

use serde_json::{Value, json};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::names;
use crate::report_page::chromium;
use crate::video_run::{Clip, Feed, PATIENCE, VideoRun, s, temporaries, video_json};

/// Camera frames per window (`meb video`'s default).
const WINDOW: usize = 40;

/// `meb video - --rig RIG --out OUT --live --port 0`, fed `windows` windows of `clip` through
/// a pipe, one window every `pace`; the pipe stays open until the run is finished or dropped.
fn live_run(clip: Clip, out: &Path, windows: usize, pace: Duration) -> VideoRun {
    let args = [
        "video",
        "-",
        "--rig",
        &clip.rig,
        "--out",
        &s(out),
        "--live",
        "--port",
        "0",
    ]
    .map(String::from);
    let feed = Feed::Paced {
        clip,
        windows,
        window: WINDOW,
        pace,
    };
    VideoRun::start(&args, feed)
}

/// The live view's address, from the run's `live view: http://…/` line.
fn address(run: &mut VideoRun) -> SocketAddr {
    let line = run.wait_for_line("live view: http://");
    let url = line.split("http://").nth(1).unwrap_or_default();
    url.trim_end_matches('/').parse().unwrap()
}

/// A plain HTTP/1.1 GET of `path`: the status code and what arrived within a second.
fn get(addr: SocketAddr, path: &str) -> (u16, String) {
    get_as(addr, &addr.to_string(), path)
}

/// [`get`] naming `host` in the request's `Host` header.
fn get_as(addr: SocketAddr, host: &str, path: &str) -> (u16, String) {
    let mut stream = TcpStream::connect(addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(1)))
        .unwrap();
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut response = Vec::new();
    let mut buffer = [0u8; 65536];
    // Until the server closes, or the timeout of an endless stream (`/events`).
    while let Ok(n) = stream.read(&mut buffer) {
        if n == 0 {
            break;
        }
        response.extend_from_slice(&buffer[..n]);
    }
    let response = String::from_utf8_lossy(&response).into_owned();
    let status = response
        .split(' ')
        .nth(1)
        .and_then(|code| code.parse().ok())
        .unwrap_or_else(|| panic!("no HTTP status for {path}: {response:?}"));
    (status, response)
}

/// Headless Chromium showing `url`, driven over the DevTools protocol.
struct Browser {
    child: Child,
    socket: tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>,
    next: u64,
}

impl Browser {
    fn open(program: &str, profile: &Path, url: &str) -> Self {
        // Chromium's singleton-socket folder goes to TMPDIR: beside the profile, not in /tmp.
        let beside = profile.parent().unwrap_or(profile);
        let child = Command::new(program)
            .env("TMPDIR", beside)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--disable-background-timer-throttling",
                "--disable-renderer-backgrounding",
                "--no-first-run",
                "--enable-unsafe-swiftshader",
                "--use-angle=swiftshader",
                "--window-size=1200,900",
                "--remote-debugging-port=0",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg(url)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        // Chromium writes the port it chose into the profile.
        let start = Instant::now();
        let port: u16 = loop {
            let file = std::fs::read_to_string(profile.join("DevToolsActivePort"));
            if let Some(port) = file.ok().and_then(|f| f.lines().next()?.parse().ok()) {
                break port;
            }
            assert!(start.elapsed() < PATIENCE, "Chromium has no DevTools port");
            std::thread::sleep(Duration::from_millis(50));
        };
        let devtools = SocketAddr::from(([127, 0, 0, 1], port));
        let page = loop {
            let (_, response) = get(devtools, "/json/list");
            let targets: Value = response
                .split_once("\r\n\r\n")
                .and_then(|(_, body)| serde_json::from_str(body).ok())
                .unwrap_or(Value::Null);
            let page = targets.as_array().and_then(|targets| {
                targets
                    .iter()
                    .find(|t| t["type"] == "page" && t["url"] == url)
                    .and_then(|t| t["webSocketDebuggerUrl"].as_str().map(str::to_string))
            });
            if let Some(page) = page {
                break page;
            }
            assert!(start.elapsed() < PATIENCE, "no page target: {targets}");
            std::thread::sleep(Duration::from_millis(50));
        };
        let (socket, _) = tungstenite::connect(page.as_str()).unwrap();
        if let tungstenite::stream::MaybeTlsStream::Plain(stream) = socket.get_ref() {
            stream.set_read_timeout(Some(PATIENCE)).unwrap();
        }
        Self {
            child,
            socket,
            next: 0,
        }
    }

    /// Calls a DevTools method and returns its result.
    fn call(&mut self, method: &str, params: Value) -> Value {
        self.next += 1;
        let id = self.next;
        let request = json!({ "id": id, "method": method, "params": params });
        self.socket
            .send(tungstenite::Message::text(request.to_string()))
            .unwrap();
        loop {
            if let tungstenite::Message::Text(text) = self.socket.read().unwrap() {
                let reply: Value = serde_json::from_str(text.as_str()).unwrap();
                if reply["id"] == id {
                    assert!(reply.get("error").is_none(), "{method}: {reply}");
                    return reply["result"].clone();
                }
            }
        }
    }

    /// The `data-*` attributes of the page's `<body>`.
    fn body_data(&mut self) -> Value {
        let result = self.call(
            "Runtime.evaluate",
            json!({
                "expression": "JSON.stringify(document.body ? Object.assign({}, document.body.dataset) : {})",
                "returnByValue": true,
            }),
        );
        serde_json::from_str(result["result"]["value"].as_str().unwrap_or("{}")).unwrap()
    }

    /// Waits until `ready` holds for the body's data; returns that data.
    fn wait_for(&mut self, what: &str, ready: impl Fn(&Value) -> bool) -> Value {
        let start = Instant::now();
        loop {
            let data = self.body_data();
            if ready(&data) {
                return data;
            }
            assert!(start.elapsed() < PATIENCE, "no {what}: {data}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// A PNG screenshot of the page.
    fn screenshot(&mut self) -> Vec<u8> {
        use base64::Engine;
        let shot = self.call("Page.captureScreenshot", json!({ "format": "png" }));
        base64::engine::general_purpose::STANDARD
            .decode(shot["data"].as_str().unwrap_or(""))
            .unwrap()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A `data-*` attribute as a number (absent: −1).
fn number(data: &Value, key: &str) -> f64 {
    data[key]
        .as_str()
        .and_then(|v| v.parse().ok())
        .unwrap_or(-1.0)
}

/// Where the test keeps its screenshot: a folder of the test build's that outlives the test.
fn output_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("video_live");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn the_live_page_follows_the_stream_and_an_interrupt_still_writes_the_folder() {
    let Some(program) = chromium() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let clip = Clip::simulate(tmp.path(), 160);
    let out = tmp.path().join("live");
    // 200 windows, one every 0.3 s: longer than the test needs (however slowly Chromium
    // starts), so the interrupt comes mid-stream.
    let windows = 200;
    let mut run = live_run(clip, &out, windows, Duration::from_millis(300));
    let addr = address(&mut run);
    assert!(addr.ip().is_loopback(), "{addr}");
    let url = format!("http://{addr}/");
    let mut browser = Browser::open(program, &tmp.path().join("profile"), &url);

    // The page draws a 3-D frame, then later ones: the counter and the view advance.
    let first = browser.wait_for("first 3-D frame", |d| {
        d["viewer"] == "rendered" && number(d, "frames") >= 1.0
    });
    let later = browser.wait_for("later 3-D frames", |d| {
        number(d, "frames") >= number(&first, "frames") + 2.0
            && number(d, "meshes") > number(&first, "meshes")
            && number(d, "latencyMs") >= 0.0
    });
    assert_eq!(later["connection"], "open", "{later}");
    let latency = number(&later, "latencyMs");
    eprintln!(
        "live view: 3-D frames {} → {}, meshes {} → {} ({} skipped, {} ms to draw the last), \
         event latency {latency} ms",
        first["frames"],
        later["frames"],
        first["meshes"],
        later["meshes"],
        later["skipped"],
        later["drawMs"]
    );
    assert!(latency < 5000.0, "event latency {latency} ms");
    assert!(
        [
            "plausible",
            "motion",
            "forced",
            "skipped",
            "refused",
            "failed"
        ]
        .contains(&later["state"].as_str().unwrap_or("")),
        "{later}"
    );

    // The screenshot shows a shaded surface in the viewer's canvas.
    let png = browser.screenshot();
    let shot = output_dir().join("live_view.png");
    std::fs::write(&shot, &png).unwrap();
    eprintln!("live view screenshot: {}", shot.display());
    let image = image::load_from_memory(&png).unwrap().to_rgb8();
    // The canvas: the rows of the viewer's dark background left of the pictures.
    let background = [0x18u8, 0x1a, 0x20];
    let rows: Vec<u32> = (0..image.height())
        .filter(|&y| {
            (0..image.width().min(720))
                .filter(|&x| image.get_pixel(x, y).0 == background)
                .count()
                > 200
        })
        .collect();
    assert!(!rows.is_empty(), "no viewer canvas in the screenshot");
    // The surface's warm grey (not the background, nor the grey text).
    let mut surface = std::collections::HashSet::new();
    for y in rows[0]..=rows[rows.len() - 1] {
        for x in 0..image.width().min(720) {
            let p = image.get_pixel(x, y).0;
            if p != background && p[0] > 60 && p[0] > p[2].saturating_add(5) {
                surface.insert(p);
            }
        }
    }
    assert!(
        surface.len() > 30,
        "only {} surface colours in the screenshot",
        surface.len()
    );

    // A SIGINT mid-stream: the windows done are written and the folder put in place.
    run.interrupt();
    let (status, stderr) = run.finish();
    assert!(status.success(), "{status:?}: {stderr}");
    assert_eq!(temporaries(tmp.path()), Vec::<PathBuf>::new());
    let json = video_json(&out);
    assert_eq!(json["summary"]["end"], "interrupted", "{json}");
    let done = json["summary"]["windows"].as_u64().unwrap();
    assert!(
        done as f64 >= number(&later, "frames") && done < windows as u64,
        "{done} windows"
    );
    assert_eq!(json["frames"].as_array().unwrap().len() as u64, done);
    let depths = names(&out)
        .iter()
        .filter(|n| n.starts_with("depth_") && n.ends_with(".npy"))
        .count() as u64;
    assert_eq!(depths, json["outputs"]["frames_written"].as_u64().unwrap());

    // The server has stopped with the command: the page sees its stream closed.
    browser.wait_for("closed stream", |d| d["connection"] == "closed");
}

#[test]
fn the_live_view_serves_its_page_and_events_and_nothing_else() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = Clip::simulate(tmp.path(), 160);
    let out = tmp.path().join("live");
    let mut run = live_run(clip, &out, 4, Duration::ZERO);
    let addr = address(&mut run);
    let (status, page) = get(addr, "/");
    assert_eq!(status, 200, "{page}");
    assert!(page.contains("text/html") && page.contains("EventSource(\"/events\")"));
    let (status, events) = get(addr, "/events");
    assert_eq!(status, 200);
    assert!(events.contains("text/event-stream"), "{events}");
    for path in [
        "/../Cargo.toml",
        "/..%2f..%2fCargo.toml",
        "/etc/passwd",
        "//etc/passwd",
        "/video.json",
        "/depth_00000.npy",
        "/index.html",
        "/events/../../Cargo.toml",
        "/frame",
    ] {
        let (status, response) = get(addr, path);
        assert_eq!(status, 404, "{path}: {response}");
        assert!(!response.contains("[package]") && !response.contains("root:"));
    }
    // A page from elsewhere, through a DNS name rebound to 127.0.0.1, is refused; the view's
    // own names are answered.
    for host in ["evil.example", "evil.example:80", "localhost.evil.example"] {
        for path in ["/", "/events"] {
            let (status, response) = get_as(addr, host, path);
            assert_eq!(status, 403, "{host}{path}: {response}");
            assert!(!response.contains("EventSource") && !response.contains("event:"));
        }
    }
    let port = addr.port();
    for host in [format!("localhost:{port}"), format!("127.0.0.1:{port}")] {
        assert_eq!(get_as(addr, &host, "/").0, 200, "{host}");
    }
    run.interrupt();
    let (status, stderr) = run.finish();
    assert!(status.success(), "{status:?}: {stderr}");
    assert_eq!(video_json(&out)["summary"]["end"], "interrupted");
}

#[test]
fn a_port_in_use_is_refused_before_processing() {
    let tmp = tempfile::tempdir().unwrap();
    let taken = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let out = tmp.path().join("live");
    let rig = crate::common::dynamic_rig(tmp.path(), 160, 90);
    let output = Command::new(env!("CARGO_BIN_EXE_meb"))
        .args(["video", "-", "--rig", &rig, "--out"])
        .arg(&out)
        .args(["--live", "--port", &port])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!("cannot serve the live view on 127.0.0.1:{port}")),
        "{stderr}"
    );
    assert!(!out.exists());
    assert_eq!(temporaries(tmp.path()), Vec::<PathBuf>::new());
}
