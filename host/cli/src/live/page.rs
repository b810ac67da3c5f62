//! The live view's page: the latest 3-D frame in the three.js view
//! ([`live_surface_viewer`]), its shaded and depth pictures, the window's verdict, the 3-D
//! frame rate, the decode and reconstruction times and the event latency, updated from
//! `/events`.
//!
//! The page marks `<body>` for tests and tools: `data-frames` (3-D frames done, as of the last
//! event), `data-events` (events received), `data-index` (the last one's 3-D frame number),
//! `data-state` (its verdict), `data-latency-ms` (receipt time − the event's timestamp of the
//! last new frame, ms; the frame already done when the page connects is not counted),
//! `data-connection` (`open` or `closed`), and the viewer's `data-viewer`, `data-meshes`,
//! `data-skipped` and `data-draw-ms`.

use crate::export::viewer::live_surface_viewer;

/// The page's HTML.
pub(super) fn html() -> String {
    format!(
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>meb video: live view</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 16px; color: #222; }}
h1 {{ font-size: 130%; margin: 0 0 8px; }}
.row {{ display: flex; gap: 16px; flex-wrap: wrap; align-items: flex-start; }}
.side {{ flex: 0 0 340px; }}
table {{ border-collapse: collapse; }}
td {{ padding: 2px 10px 2px 0; }}
td:first-child {{ color: #666; }}
#state {{ font-weight: bold; }}
.pictures img {{ width: 320px; image-rendering: pixelated; background: #222; display: block; margin-bottom: 6px; }}
</style></head>
<body data-frames="0" data-events="0" data-connection="connecting">
<h1>meb video: live view</h1>
<div class="row">
{viewer}
<div class="side">
<table>
<tr><td>3-D frame</td><td id="index">waiting</td></tr>
<tr><td>verdict</td><td id="state">–</td></tr>
<tr><td>reason</td><td id="reason">–</td></tr>
<tr><td>3-D frames done</td><td id="frames">0</td></tr>
<tr><td>camera frames</td><td id="camera">–</td></tr>
<tr><td>3-D frames/s</td><td id="fps">–</td></tr>
<tr><td>decode</td><td id="decode">–</td></tr>
<tr><td>reconstruction</td><td id="reconstruct">–</td></tr>
<tr><td>depth RMSE</td><td id="rmse">–</td></tr>
<tr><td>event latency</td><td id="latency">–</td></tr>
<tr><td>connection</td><td id="connection">connecting</td></tr>
</table>
<div class="pictures">
<p id="pictures-of">shaded and depth pictures of the latest surface</p>
<img id="shaded" alt="shaded surface">
<img id="depth" alt="colour-mapped depth">
</div>
</div>
</div>
<script>
(() => {{
  const body = document.body;
  const set = (id, text) => {{ const e = document.getElementById(id); if (e.textContent !== text) e.textContent = text; }};
  const ms = (x) => (typeof x === "number" ? x.toFixed(1) + " ms" : "–");
  let received = 0;
  const update = (live) => (event) => {{
    const now = Date.now();
    let f;
    try {{ f = JSON.parse(event.data); }} catch (error) {{ set("state", "bad event: " + error); return; }}
    received += 1;
    body.dataset.events = String(received);
    if (f.error) {{ set("state", "error: " + f.error); return; }}
    body.dataset.frames = String(f.done);
    body.dataset.index = String(f.index);
    body.dataset.state = f.state;
    if (live) {{
      const latency = now - f.timestamp_ms;
      body.dataset.latencyMs = String(latency);
      set("latency", latency + " ms");
    }}
    set("index", String(f.index));
    set("state", f.state);
    set("reason", f.reason || "–");
    set("frames", String(f.done));
    set("camera", f.total_frames ? f.camera_frames + " / " + f.total_frames : String(f.camera_frames));
    set("fps", f.frames_per_second.toFixed(2));
    set("decode", ms(f.decode_ms));
    set("reconstruct", ms(f.reconstruct_ms));
    set("rmse", typeof f.rmse_mm === "number" ? f.rmse_mm.toFixed(2) + " mm" : "–");
    if (f.shaded && f.depth) {{
      document.getElementById("shaded").src = f.shaded;
      document.getElementById("depth").src = f.depth;
      const range = f.depth_range_mm ? ", depth " + f.depth_range_mm[0].toFixed(0) + "–" + f.depth_range_mm[1].toFixed(0) + " mm" : "";
      set("pictures-of", "3-D frame " + f.index + range);
    }}
    if (f.mesh) {{
      window.mebSurface = f.mesh;
      window.dispatchEvent(new Event("meb-surface"));
    }}
  }};
  const source = new EventSource("/events");
  source.addEventListener("current", update(false));
  source.addEventListener("frame", update(true));
  source.onopen = () => {{ body.dataset.connection = "open"; set("connection", "open"); }};
  source.onerror = () => {{
    body.dataset.connection = "closed";
    set("connection", "closed (the run has ended, or meb stopped)");
    source.close();
  }};
}})();
</script>
</body></html>
"#,
        viewer = live_surface_viewer(),
    )
}
