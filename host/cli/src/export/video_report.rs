//! `video.html`: the self-contained page of a `meb video` folder. It shows the 3-D frames in one
//! three.js view (the import of [`super::viewer`]) with a scrubber and a play button that steps
//! through the windows at the 3-D frame rate, and a table of every window of `video.json`: what
//! became of it (reconstructed and the decoder's verdict, skipped, failed, with the reason), its
//! motion, its depth RMSE against the truth when one was given, and its stage timings, with
//! their means.
//!
//! The meshes are decimated ([`VideoMeshes`]): each 3-D frame keeps the pixels of a regular
//! grid over the box of its reconstructed pixels, every `step`-th row and column with `step`
//! the smallest that leaves at most [`FRAME_CELLS`] grid points, each point as its scene
//! position (x right, y up, z towards the camera, mm: [`Projection::ray`] at the pixel's depth)
//! quantised to three int16 values over the frame's own bounding box (a resolution of 1/65534
//! of the box; −32768 marks a point without depth). When the meshes together would pass
//! [`MESH_BYTES`] (a long run, or a window per camera frame), every frame keeps every second
//! row and column of its grid, and later frames start from a quarter of the points, so the page
//! stays under about 25 MB whatever the run's length. The page triangulates each grid as the
//! surface meshes are (two triangles per grid square whose corners have a depth) when its
//! frame is shown.
//!
//! The page marks `<body>` with `data-viewer="rendered"` after its first frame (or
//! `data-viewer="error: …"`), `data-open-ms` with the milliseconds from the start of the
//! page's navigation to that frame, and `data-frame="K"` for the 3-D frame K shown; `#frame=K`
//! in the address shows K first, and `#play` (or `#frame=K&play`) starts playing, counting
//! the frames stepped to in `data-played`. Windows without a 3-D frame show their verdict in
//! place of the surface.

use super::ExportError;
use super::viewer;
use base64::Engine;
use meb_core::io::FilesError;
use meb_core::rig::Projection;
use meb_pipeline::video::output::{MeanTiming, WrittenVideo};
use meb_pipeline::video::{FrameRecord, FrameStatus, FrameTiming, VideoSummary};
use ndarray::Array2;
use serde::Deserialize;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Most grid points a 3-D frame's mesh starts with (a 1280×720 frame: every 6th pixel).
pub const FRAME_CELLS: usize = 32_768;

/// Most bytes of quantised meshes the page holds (before base64); past it every frame is
/// thinned.
pub const MESH_BYTES: usize = 16 << 20;

/// The int16 value of a grid point without depth.
const NO_DEPTH: i16 = i16::MIN;

/// Grows the box `bounds` (smallest and largest coordinates) to hold the box `other`.
fn grow(bounds: &mut [[f64; 3]; 2], other: &[[f64; 3]; 2]) {
    let [lo, hi] = bounds;
    for ((l, h), (ol, oh)) in lo
        .iter_mut()
        .zip(hi.iter_mut())
        .zip(other[0].iter().zip(&other[1]))
    {
        *l = l.min(*ol);
        *h = h.max(*oh);
    }
}

/// One 3-D frame's decimated mesh (module docs).
#[derive(Debug, Clone)]
struct FrameMesh {
    /// Grid rows and columns.
    rows: usize,
    cols: usize,
    /// Pixels from one grid point to the next.
    step: usize,
    /// Scene position of the quantised value 0, mm (the box's centre).
    origin: [f64; 3],
    /// mm per quantised unit.
    scale: [f64; 3],
    /// Smallest and largest scene coordinate of the frame's points, mm.
    bounds: [[f64; 3]; 2],
    /// x, y, z per grid point, row by row.
    xyz: Vec<i16>,
}

impl FrameMesh {
    /// The mesh of `depth`'s reconstructed pixels on a grid of at most `cells` points, or
    /// `None` when no pixel has a depth.
    fn of(depth: &Array2<f32>, projection: &Projection, cells: usize) -> Option<Self> {
        let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
        for ((r, c), z) in depth.indexed_iter() {
            if z.is_finite() {
                lo = [lo[0].min(r), lo[1].min(c)];
                hi = [hi[0].max(r), hi[1].max(c)];
            }
        }
        if lo[0] == usize::MAX {
            return None;
        }
        let (height, width) = (hi[0] - lo[0] + 1, hi[1] - lo[1] + 1);
        let step = (1..)
            .find(|k| height.div_ceil(*k) * width.div_ceil(*k) <= cells.max(1))
            .unwrap_or(1);
        let (rows, cols) = (height.div_ceil(step), width.div_ceil(step));
        let mut points = Vec::with_capacity(rows * cols);
        for i in 0..rows {
            for j in 0..cols {
                let (r, c) = (lo[0] + i * step, lo[1] + j * step);
                points.push(
                    depth
                        .get((r, c))
                        .copied()
                        .filter(|z| z.is_finite())
                        .map(|z| {
                            let p = projection.ray(r as f64, c as f64).at(f64::from(z));
                            [p.x, p.y, p.z]
                        }),
                );
            }
        }
        let mut bounds = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
        for p in points.iter().flatten() {
            grow(&mut bounds, &[*p, *p]);
        }
        let origin = [0, 1, 2].map(|a| (bounds[0][a] + bounds[1][a]) / 2.0);
        let scale = [0, 1, 2].map(|a| ((bounds[1][a] - bounds[0][a]) / 65534.0).max(1e-9));
        let mut xyz = Vec::with_capacity(3 * points.len());
        for p in &points {
            match p {
                Some(p) => xyz.extend((0..3).map(|a| {
                    ((p[a] - origin[a]) / scale[a])
                        .round()
                        .clamp(-32767.0, 32767.0) as i16
                })),
                None => xyz.extend([NO_DEPTH; 3]),
            }
        }
        Some(Self {
            rows,
            cols,
            step,
            origin,
            scale,
            bounds,
            xyz,
        })
    }

    /// Every second row and column of the grid.
    fn thinned(&self) -> Self {
        let (rows, cols) = (self.rows.div_ceil(2), self.cols.div_ceil(2));
        let mut xyz = Vec::with_capacity(3 * rows * cols);
        for i in 0..rows {
            for j in 0..cols {
                let at = 3 * (2 * i * self.cols + 2 * j);
                xyz.extend_from_slice(&self.xyz[at..at + 3]);
            }
        }
        Self {
            rows,
            cols,
            step: self.step * 2,
            xyz,
            ..self.clone()
        }
    }

    /// Bytes of its quantised points.
    fn bytes(&self) -> usize {
        2 * self.xyz.len()
    }

    /// The page's JSON of the mesh: grid size, step, origin and scale, and the points as
    /// base64 little-endian int16.
    fn json(&self) -> serde_json::Value {
        let bytes: Vec<u8> = self.xyz.iter().flat_map(|v| v.to_le_bytes()).collect();
        serde_json::json!({
            "rows": self.rows,
            "cols": self.cols,
            "step": self.step,
            "origin": self.origin,
            "scale": self.scale,
            "xyz": base64::engine::general_purpose::STANDARD.encode(bytes),
        })
    }
}

/// The decimated meshes of a run's 3-D frames, gathered as the windows come (module docs).
#[derive(Debug, Clone)]
pub struct VideoMeshes {
    /// How pixels and depths map to scene points.
    projection: Projection,
    /// Grid points a new frame may have.
    cells: usize,
    /// Each 3-D frame's mesh by window number.
    frames: HashMap<usize, FrameMesh>,
    /// Bytes of all meshes.
    bytes: usize,
}

impl VideoMeshes {
    /// No meshes yet, for 3-D frames seen through `projection` (the camera of the 3-D frames,
    /// binned as they are).
    pub fn new(projection: Projection) -> Self {
        Self {
            projection,
            cells: FRAME_CELLS,
            frames: HashMap::new(),
            bytes: 0,
        }
    }

    /// Adds window `index`'s depth (mm over the whole frame, NaN where none), thinning every
    /// mesh when they would pass [`MESH_BYTES`].
    pub fn add(&mut self, index: usize, depth: &Array2<f32>) {
        let Some(mesh) = FrameMesh::of(depth, &self.projection, self.cells) else {
            return;
        };
        self.bytes += mesh.bytes();
        if let Some(old) = self.frames.insert(index, mesh) {
            self.bytes -= old.bytes();
        }
        while self.bytes > MESH_BYTES && self.cells > 1 {
            self.cells = (self.cells / 4).max(1);
            for mesh in self.frames.values_mut() {
                *mesh = mesh.thinned();
            }
            self.bytes = self.frames.values().map(FrameMesh::bytes).sum();
        }
    }

    /// 3-D frames with a mesh.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether no 3-D frame has a mesh.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Bytes of the quantised meshes (before base64).
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// Centre and radius (mm) of the box around every frame's points.
    fn sphere(&self) -> ([f64; 3], f64) {
        let mut bounds = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
        for mesh in self.frames.values() {
            grow(&mut bounds, &mesh.bounds);
        }
        if !bounds[0][0].is_finite() {
            return ([0.0; 3], 100.0);
        }
        let centre = [0, 1, 2].map(|a| (bounds[0][a] + bounds[1][a]) / 2.0);
        let radius = (0..3)
            .map(|a| (bounds[1][a] - bounds[0][a]).powi(2))
            .sum::<f64>()
            .sqrt()
            / 2.0;
        (centre, radius.max(1.0))
    }
}

/// The parts of `video.json` the page shows.
#[derive(Debug, Deserialize)]
struct VideoJson {
    settings: serde_json::Value,
    summary: VideoSummary,
    outputs: WrittenVideo,
    mean_timing_ms: MeanTiming,
    #[serde(default)]
    accuracy: serde_json::Value,
    frames: Vec<FrameRecord>,
}

/// Writes `video.html` into `dir` from its `video.json` and `meshes`; returns its path.
pub fn write_video_report(dir: &Path, meshes: &VideoMeshes) -> Result<PathBuf, ExportError> {
    let json_path = dir.join("video.json");
    let text = std::fs::read_to_string(&json_path).map_err(|e| FilesError::read(&json_path, e))?;
    let video: VideoJson = serde_json::from_str(&text).map_err(|e| FilesError::Encode {
        path: json_path.clone(),
        source: Box::new(e),
    })?;
    let page = html_page(&video, meshes)?;
    let path = dir.join("video.html");
    std::fs::write(&path, page.as_bytes()).map_err(|e| FilesError::write(&path, e))?;
    Ok(path)
}

/// Escapes text for HTML.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The lower-case name serde gives a value (`"skipped"`, `"plausible"` …).
fn name_of<T: serde::Serialize>(value: &T) -> String {
    serde_json::to_value(value)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default()
}

/// A window's verdict in words: `reconstructed (plausible)`, `skipped: …`, `failed: …`.
fn verdict(record: &FrameRecord) -> String {
    let reason = record.reason.as_deref().unwrap_or("");
    match record.status {
        FrameStatus::Reconstructed => {
            let mut text = String::from("reconstructed");
            if let Some(v) = &record.verdict {
                let _ = write!(text, " ({})", name_of(v));
            }
            if !reason.is_empty() {
                let _ = write!(text, ": {reason}");
            }
            text
        }
        _ if reason.is_empty() => name_of(&record.status),
        _ => format!("{}: {reason}", name_of(&record.status)),
    }
}

/// A window's motion in words: `moving (12.3 %)`, `still (0.4 %)` or `–`.
fn motion(record: &FrameRecord) -> String {
    match &record.motion {
        Some(m) => format!(
            "{} ({:.1} %)",
            if m.moving { "moving" } else { "still" },
            100.0 * m.score
        ),
        None => "–".to_string(),
    }
}

/// The timing columns' cells.
fn timing_cells(t: &FrameTiming) -> String {
    [
        t.read_ms,
        t.decode_ms,
        t.motion_ms,
        t.wait_ms,
        t.reconstruct_ms,
        t.compare_ms,
        t.write_ms,
    ]
    .iter()
    .map(|ms| format!("<td class=\"n\">{ms:.1}</td>"))
    .collect()
}

/// The page.
fn html_page(video: &VideoJson, meshes: &VideoMeshes) -> Result<String, ExportError> {
    let (centre, radius) = meshes.sphere();
    let fps = video
        .settings
        .get("rate_3d_fps")
        .and_then(serde_json::Value::as_f64)
        .filter(|r| r.is_finite() && *r > 0.0)
        .unwrap_or(25.0);
    let mut rows = String::new();
    let mut windows = Vec::with_capacity(video.frames.len());
    for record in &video.frames {
        let k = record.index;
        let status = name_of(&record.status);
        let rmse = record
            .accuracy
            .as_ref()
            .and_then(|a| a.rmse_mm)
            .map_or("–".to_string(), |r| format!("{r:.2}"));
        let time = record.time_s.map_or("–".to_string(), |t| format!("{t:.3}"));
        let _ = writeln!(
            rows,
            "<tr id=\"frame-{k}\" class=\"window\" data-status=\"{status}\"><td class=\"n\">{k}</td>\
             <td>{}–{}</td><td class=\"n\">{time}</td><td class=\"verdict\">{}</td><td>{}</td>\
             <td class=\"n\">{rmse}</td>{}</tr>",
            record.decoded.0,
            record.decoded.1,
            escape(&verdict(record)),
            escape(&motion(record)),
            timing_cells(&record.timing),
        );
        windows.push(serde_json::json!({
            "k": k,
            "label": format!("3-D frame {k}: {}, {}, RMSE {rmse} mm", verdict(record), motion(record)),
            "mesh": meshes.frames.get(&k).map(FrameMesh::json),
        }));
    }
    let data = serde_json::json!({
        "fps": fps,
        "centre": centre,
        "radius": radius,
        "windows": windows,
    });
    let data = serde_json::to_string(&data)
        .map_err(|e| FilesError::Encode {
            path: PathBuf::from("video.html"),
            source: Box::new(e),
        })?
        // `<` only occurs in strings: as \u003c no text can end or open a tag in the script.
        .replace('<', "\\u003c");
    let s = &video.summary;
    let mut summary = format!(
        "{} 3-D frames from {} camera frames ({}) in {:.1} s, {:.2} 3-D frames/s: {} reconstructed, \
         {} skipped, {} failed, {} with motion; shown at {fps:.1} 3-D frames/s.",
        s.windows,
        s.camera_frames,
        name_of(&s.end),
        s.wall_s,
        s.frames_per_second,
        s.reconstructed,
        s.skipped,
        s.failed,
        s.moving
    );
    if let Some(error) = &s.input_error {
        let _ = write!(summary, " Input error: {error}.");
    }
    if let (Some(lo), Some(mid), Some(hi)) = (
        video.accuracy.get("rmse_mm_min").and_then(|v| v.as_f64()),
        video
            .accuracy
            .get("rmse_mm_median")
            .and_then(|v| v.as_f64()),
        video.accuracy.get("rmse_mm_max").and_then(|v| v.as_f64()),
    ) {
        let _ = write!(
            summary,
            " Depth RMSE against the truth: median {mid:.2} mm (from {lo:.2} to {hi:.2} mm)."
        );
    }
    let files: String = [&video.outputs.depth_video, &video.outputs.shaded_video]
        .into_iter()
        .flatten()
        .map(|f| format!(" <a href=\"{0}\">{0}</a>", escape(f)))
        .collect();
    let files = if files.is_empty() {
        " none".to_string()
    } else {
        files
    };
    let input = video
        .settings
        .get("input")
        .and_then(|v| v.as_str())
        .unwrap_or("");
    Ok(format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>meb video: {title}</title>\n<style>\n\
         body{{font-family:system-ui,sans-serif;margin:2em;background:#fafafa;color:#222}}\n\
         table{{border-collapse:collapse;margin:1em 0;font-size:90%}} th,td{{padding:3px 8px;border-bottom:1px solid #ddd;text-align:left}}\n\
         td.n{{text-align:right;font-variant-numeric:tabular-nums}} tr.current{{background:#ffe9a8}}\n\
         td.verdict{{min-width:16em}} tr[data-status=skipped] td.verdict{{color:#8a6d00}} tr[data-status=failed] td.verdict{{color:#b00020}}\n\
         #meb-controls{{display:flex;gap:12px;align-items:center;margin:8px 0;width:720px;max-width:100%}} #meb-scrub{{flex:1}}\n\
         </style></head><body>\n\
         <h1>meb video: {title}</h1>\n<p>{summary}</p>\n<p>Videos:{files}; per-frame depth in depth_NNNNN.npy, every figure in video.json.</p>\n\
         <h2>3-D frames</h2>\n\
         <div id=\"meb-viewer\" style=\"position:relative;width:720px;max-width:100%;height:480px;border:1px solid #ddd;background:#181a20\">\n\
         <canvas id=\"meb-surface\" style=\"width:100%;height:100%;display:block;cursor:grab\"></canvas>\n\
         <div id=\"meb-frame-note\" style=\"position:absolute;left:8px;top:6px;right:8px;color:#ddd;font-size:85%\"></div>\n\
         <div id=\"meb-viewer-note\" style=\"position:absolute;left:8px;bottom:6px;color:#aaa;font-size:85%\">drag to turn, scroll to zoom</div></div>\n\
         <div id=\"meb-controls\"><button id=\"meb-play\" type=\"button\">play</button>\
         <input id=\"meb-scrub\" type=\"range\" min=\"0\" max=\"{last}\" step=\"1\" value=\"0\" aria-label=\"3-D frame\">\
         <span id=\"meb-frame-label\"></span></div>\n\
         <p style=\"font-size:85%;color:#555\">Meshes decimated to at most {cells} grid points per frame, positions quantised to 16 bits; the .npy files hold every pixel.</p>\n\
         <h2>Windows</h2>\n<table id=\"meb-windows\"><thead><tr><th>3-D frame</th><th>camera frames</th><th>time (s)</th><th>verdict</th><th>motion</th><th>RMSE (mm)</th>\
         <th>read (ms)</th><th>decode</th><th>motion</th><th>wait</th><th>reconstruct</th><th>compare</th><th>write</th></tr></thead>\n<tbody>\n{rows}</tbody>\n\
         <tfoot><tr id=\"mean-timing\"><th colspan=\"6\">mean of {mean_windows} windows (ms)</th>{mean}</tr></tfoot></table>\n\
         <script type=\"application/json\" id=\"meb-frames\">{data}</script>\n\
         <script type=\"module\">\n{script}</script>\n</body></html>\n",
        title = escape(input),
        files = files,
        last = video.frames.len().saturating_sub(1),
        cells = FRAME_CELLS.min(meshes.cells),
        mean_windows = video.mean_timing_ms.windows,
        mean = timing_cells(&video.mean_timing_ms.mean),
        script = script(),
    ))
}

/// The page's module script: three.js, the meshes, the scrubber and the play button.
fn script() -> String {
    format!(
        r#"const note = document.getElementById("meb-viewer-note");
try {{
  const THREE = await {three};
  const data = JSON.parse(document.getElementById("meb-frames").textContent);
  const windows = data.windows;
  const bytes = (s) => Uint8Array.from(atob(s), (c) => c.charCodeAt(0)).buffer;
  const geometries = new Map();
  const build = (m) => {{
    const q = new Int16Array(bytes(m.xyz));
    const n = m.rows * m.cols;
    const index = new Int32Array(n).fill(-1);
    let count = 0;
    for (let i = 0; i < n; i++) if (q[3 * i] !== -32768) index[i] = count++;
    const positions = new Float32Array(3 * count);
    for (let i = 0; i < n; i++) {{
      const v = index[i];
      if (v < 0) continue;
      for (let a = 0; a < 3; a++) positions[3 * v + a] = m.origin[a] + q[3 * i + a] * m.scale[a] - data.centre[a];
    }}
    const triangles = [];
    for (let r = 0; r + 1 < m.rows; r++) {{
      for (let c = 0; c + 1 < m.cols; c++) {{
        const a = index[r * m.cols + c], b = index[r * m.cols + c + 1];
        const d = index[(r + 1) * m.cols + c], e = index[(r + 1) * m.cols + c + 1];
        if (a >= 0 && d >= 0 && b >= 0) triangles.push(a, d, b);
        if (b >= 0 && d >= 0 && e >= 0) triangles.push(b, d, e);
      }}
    }}
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(positions, 3));
    geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(triangles), 1));
    geometry.computeVertexNormals();
    return geometry;
  }};
  const geometryOf = (i) => {{
    let geometry = geometries.get(i);
    if (!geometry) {{
      geometry = build(windows[i].mesh);
      geometries.set(i, geometry);
      if (geometries.size > 16) {{
        const [oldest, old] = geometries.entries().next().value;
        geometries.delete(oldest);
        old.dispose();
      }}
    }}
    return geometry;
  }};
  const canvas = document.getElementById("meb-surface");
  const renderer = new THREE.WebGLRenderer({{ canvas, antialias: true, preserveDrawingBuffer: true }});
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x181a20);
  const surface = new THREE.Mesh(new THREE.BufferGeometry(), new THREE.MeshStandardMaterial({{ color: 0xd7cdbe, roughness: 0.85, side: THREE.DoubleSide }}));
  const pivot = new THREE.Group();
  pivot.add(surface);
  scene.add(pivot);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x303040, 1.2));
  const radius = data.radius;
  const camera = new THREE.PerspectiveCamera(35, 1, radius / 100, radius * 100);
  const light = new THREE.DirectionalLight(0xffffff, 2.0);
  light.position.set(-0.4, 0.5, 1.0);
  camera.add(light);
  scene.add(camera);
  let distance = radius * 3.2, yaw = -0.5, pitch = 0.35;
  const draw = () => {{
    const w = canvas.clientWidth, h = canvas.clientHeight;
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    pivot.rotation.set(pitch, yaw, 0);
    camera.position.set(0, 0, distance);
    camera.lookAt(0, 0, 0);
    renderer.render(scene, camera);
  }};
  const scrub = document.getElementById("meb-scrub");
  const label = document.getElementById("meb-frame-label");
  const frameNote = document.getElementById("meb-frame-note");
  let current = 0;
  const show = (i) => {{
    if (windows.length === 0) return;
    current = Math.max(0, Math.min(windows.length - 1, i));
    const w = windows[current];
    scrub.value = String(current);
    label.textContent = (current + 1) + " / " + windows.length;
    frameNote.textContent = w.label;
    if (w.mesh) {{
      surface.geometry = geometryOf(current);
      surface.visible = true;
    }} else {{
      surface.visible = false;
    }}
    for (const row of document.querySelectorAll("tr.current")) row.classList.remove("current");
    const row = document.getElementById("frame-" + w.k);
    if (row) row.classList.add("current");
    document.body.dataset.frame = String(w.k);
    draw();
  }};
  scrub.addEventListener("input", () => show(Number(scrub.value)));
  const play = document.getElementById("meb-play");
  let timer = null, shown = 0;
  const toggle = () => {{
    if (timer !== null) {{
      clearInterval(timer);
      timer = null;
      play.textContent = "play";
      return;
    }}
    play.textContent = "pause";
    timer = setInterval(() => {{
      show((current + 1) % windows.length);
      document.body.dataset.played = String(++shown);
    }}, 1000 / data.fps);
  }};
  play.addEventListener("click", toggle);
{turn}
  canvas.addEventListener("wheel", (e) => {{ e.preventDefault(); distance *= Math.exp(e.deltaY * 0.001); draw(); }}, {{ passive: false }});
  window.addEventListener("resize", draw);
  const wanted = /frame=(\d+)/.exec(location.hash);
  const first = wanted ? windows.findIndex((w) => w.k === Number(wanted[1])) : -1;
  show(first >= 0 ? first : Math.max(0, windows.findIndex((w) => w.mesh)));
  document.body.dataset.openMs = String(Math.round(performance.now()));
  document.body.dataset.viewer = "rendered";
  if (/(^#|&)play(&|$)/.test(location.hash)) toggle();
}} catch (error) {{
  note.textContent = "3-D view unavailable: " + error;
  document.body.dataset.viewer = "error: " + error;
}}
"#,
        three = viewer::three_js_import(),
        turn = viewer::TURN_BY_DRAG,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn projection() -> Projection {
        Projection::Orthographic {
            pitch_mm: 0.5,
            axis: (640.0, 360.0),
        }
    }

    fn sphere_depth() -> Array2<f32> {
        Array2::from_shape_fn((720, 1280), |(r, c)| {
            let (x, y) = (c as f32 - 640.0, r as f32 - 360.0);
            let d2 = 300.0f32.powi(2) - x * x - y * y;
            if d2 > 0.0 { 0.5 * d2.sqrt() } else { f32::NAN }
        })
    }

    #[test]
    fn a_full_frame_is_decimated_to_the_budget_and_points_stay_within_a_unit() {
        let depth = sphere_depth();
        let mesh = FrameMesh::of(&depth, &projection(), FRAME_CELLS).unwrap();
        assert!(mesh.rows * mesh.cols <= FRAME_CELLS);
        assert!(mesh.rows * mesh.cols > FRAME_CELLS / 4);
        // The grid spans the sphere's box (600×600 pixels around the centre).
        assert_eq!(mesh.rows, 599usize.div_ceil(mesh.step));
        // A point decodes to its pixel's scene position within half a quantisation unit.
        let (i, j) = (mesh.rows / 2, mesh.cols / 2);
        let (r, c) = (61 + i * mesh.step, 341 + j * mesh.step);
        let p = projection()
            .ray(r as f64, c as f64)
            .at(f64::from(depth[(r, c)]));
        let at = 3 * (i * mesh.cols + j);
        for (a, want) in [p.x, p.y, p.z].into_iter().enumerate() {
            let got = mesh.origin[a] + f64::from(mesh.xyz[at + a]) * mesh.scale[a];
            assert!(
                (got - want).abs() <= mesh.scale[a],
                "axis {a}: {got} vs {want}"
            );
        }
        // Corners of the box lie off the sphere.
        assert_eq!(mesh.xyz[0], NO_DEPTH);
    }

    /// A `video.json` of three windows: reconstructed with a mesh, skipped, failed.
    fn three_windows() -> VideoJson {
        let record = |k: usize, status: &str, reason: Option<&str>| {
            serde_json::json!({
                "index": k, "frames": [40 * k, 40 * k + 40], "decoded": [40 * k + 4, 40 * k + 36],
                "time_s": 0.02 + 0.04 * k as f64, "status": status, "reason": reason,
                "placed_by": 0, "verdict": if status == "failed" { None } else { Some("plausible") },
                "timing_source": "fitted",
                "motion": { "score": 0.25, "moving": status == "skipped", "lit_pixels": 100,
                            "moving_pixels": 25 },
                "accuracy": (status == "reconstructed").then(|| serde_json::json!({
                    "rmse_mm": 1.234, "nrmse": 0.01, "reconstructed_fraction": 0.9,
                    "truth_frame": 20.0 })),
                "timing": { "read_ms": 1.0, "wait_ms": 2.0, "decode_ms": 30.0, "motion_ms": 4.0,
                            "reconstruct_ms": 55.5, "compare_ms": 6.0, "write_ms": 7.0 },
            })
        };
        serde_json::from_value(serde_json::json!({
            "settings": { "input": "a<b>.y4m", "rate_3d_fps": 25.0 },
            "summary": { "camera_frames": 120, "windows": 3, "reconstructed": 1, "skipped": 1,
                         "failed": 1, "moving": 1, "end": "complete", "input_error": null,
                         "wall_s": 1.0, "frames_per_second": 3.0 },
            "outputs": { "depth_video": "depth.mp4", "shaded_video": "shaded.mp4",
                         "depth_range_mm": null, "frames_written": 1, "video_container": "mp4" },
            "mean_timing_ms": { "windows": 3, "read_ms": 1.0, "wait_ms": 2.0, "decode_ms": 30.0,
                                "motion_ms": 4.0, "reconstruct_ms": 18.5, "compare_ms": 2.0,
                                "write_ms": 7.0 },
            "accuracy": { "frames": 1, "rmse_mm_min": 1.234, "rmse_mm_median": 1.234,
                          "rmse_mm_max": 1.234 },
            "frames": [
                record(0, "reconstructed", None),
                record(1, "skipped", Some("the object moved")),
                record(2, "failed", Some("decoding failed: no <signal>")),
            ],
        }))
        .unwrap()
    }

    #[test]
    fn the_page_shows_each_windows_verdict_reason_and_timings() {
        let mut meshes = VideoMeshes::new(projection());
        meshes.add(0, &sphere_depth());
        let html = html_page(&three_windows(), &meshes).unwrap();
        assert_eq!(html.matches("<tr id=\"frame-").count(), 3);
        assert!(html.contains("data-status=\"skipped\"><td class=\"n\">1</td>"));
        assert!(html.contains("reconstructed (plausible)"));
        assert!(html.contains("skipped: the object moved"));
        assert!(
            html.contains("failed: decoding failed: no &lt;signal&gt;"),
            "escaped"
        );
        assert!(html.contains("moving (25.0 %)") && html.contains("still (25.0 %)"));
        assert!(html.contains(">1.23<") && html.contains(">55.5<") && html.contains(">18.5<"));
        assert!(html.contains("median 1.23 mm"));
        assert!(html.contains("meb video: a&lt;b&gt;.y4m"));
        // One mesh, for the reconstructed window; the data cannot end its script early.
        assert_eq!(html.matches("\"xyz\":\"").count(), 1);
        let data = html.split("id=\"meb-frames\">").nth(1).unwrap();
        let data = data.split("</script>").next().unwrap();
        assert!(!data.contains('<'));
        let data: serde_json::Value = serde_json::from_str(data).unwrap();
        assert_eq!(data["windows"].as_array().unwrap().len(), 3);
        assert_eq!(data["fps"], 25.0);
        assert!(data["windows"][2]["mesh"].is_null());
    }

    #[test]
    fn many_frames_are_thinned_to_the_page_budget() {
        let depth = sphere_depth();
        let mut meshes = VideoMeshes::new(projection());
        for k in 0..200 {
            meshes.add(k, &depth);
            assert!(meshes.bytes() <= MESH_BYTES, "{k}: {}", meshes.bytes());
        }
        assert_eq!(meshes.len(), 200);
        // 50 full frames fit without thinning.
        let mut fifty = VideoMeshes::new(projection());
        for k in 0..50 {
            fifty.add(k, &depth);
        }
        assert_eq!(fifty.cells, FRAME_CELLS);
        assert!(meshes.cells < FRAME_CELLS);
        let empty = Array2::from_elem((4, 4), f32::NAN);
        meshes.add(500, &empty);
        assert_eq!(meshes.len(), 200);
    }
}
