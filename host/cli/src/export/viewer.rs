//! The interactive 3-D view of a reconstructed surface in `report.html`: the depth map's mesh
//! drawn with three.js (pinned in `host/viewer/package.json`, inlined by `build.rs`), so the
//! page stays one file that works offline. Drag to turn the surface, scroll to zoom.
//!
//! three.js is embedded as a base64 `data:` module and imported dynamically. A build without
//! npm has no copy to inline: the page then fetches the same pinned file from a CDN with
//! subresource integrity ([`THREE_JS_SHA384`]), so the view needs the network there and a
//! tampered or different file is refused by the browser. The mesh goes in the mesh goes in
//! as base64 little-endian float32 positions and uint32 indices. Large surfaces are drawn from
//! a sub-sampled grid so the page stays small. After its first frame the viewer sets
//! `data-viewer="rendered"` on `<body>` (or `data-viewer="error: …"`), which tests read.

use super::mesh::SurfaceMesh;
use base64::Engine;

/// three.js r170, the single-file ES module build (empty when the build had no npm).
const THREE_JS: &str = include_str!(concat!(env!("OUT_DIR"), "/three.module.min.js"));

/// Where the page fetches the pinned three.js when the build could not inline it.
pub const THREE_JS_CDN: &str =
    "https://cdn.jsdelivr.net/npm/three@0.170.0/build/three.module.min.js";

/// Subresource-integrity digest of the pinned `three.module.min.js` (three 0.170.0).
pub const THREE_JS_SHA384: &str =
    "sha384-IDC7sAMAIMB/TZ6dgKKPPAKZ2bXXXP8+FBMBC8cU319eBhKITx+PaalhfDkDNH28";

/// The JavaScript expression that imports three.js: the inlined module, or the CDN copy
/// checked against [`THREE_JS_SHA384`].
fn three_import() -> String {
    if THREE_JS.is_empty() {
        format!(
            r#"(async () => {{ const r = await fetch("{THREE_JS_CDN}", {{ integrity: "{THREE_JS_SHA384}" }}); if (!r.ok) throw new Error("three.js: HTTP " + r.status); return import(URL.createObjectURL(new Blob([await r.text()], {{ type: "text/javascript" }}))); }})()"#
        )
    } else {
        format!(
            r#"import("data:text/javascript;base64,{}")"#,
            base64::engine::general_purpose::STANDARD.encode(THREE_JS.as_bytes())
        )
    }
}

/// Most vertices the viewer draws; larger meshes are sub-sampled.
pub const MAX_VIEWER_VERTICES: usize = 120_000;

/// The script lines that turn a view's surface by dragging on its `canvas`: they change the
/// page's `yaw` and `pitch` and call its `draw()` (every viewer page declares those).
pub const TURN_BY_DRAG: &str = r#"  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    yaw += (e.clientX - drag[0]) * 0.01;
    pitch = Math.max(-1.5, Math.min(1.5, pitch + (e.clientY - drag[1]) * 0.01));
    drag = [e.clientX, e.clientY];
    draw();
  });"#;

/// The HTML (canvas + module script) of the 3-D view of `mesh`.
pub fn surface_viewer(mesh: &SurfaceMesh) -> String {
    let (positions, indices) = mesh_base64(mesh);
    format!(
        r#"<div id="meb-viewer" style="position:relative;width:720px;max-width:100%;height:480px;border:1px solid #ddd;background:#181a20">
<canvas id="meb-surface" style="width:100%;height:100%;display:block;cursor:grab"></canvas>
<div id="meb-viewer-note" style="position:absolute;left:8px;bottom:6px;color:#aaa;font-size:85%">drag to turn, scroll to zoom</div></div>
<script type="module">
const note = document.getElementById("meb-viewer-note");
try {{
  const THREE = await {three};
  const bytes = (s) => Uint8Array.from(atob(s), (c) => c.charCodeAt(0)).buffer;
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(bytes("{positions}")), 3));
  geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(bytes("{indices}")), 1));
  geometry.computeVertexNormals();
  geometry.computeBoundingSphere();
  const sphere = geometry.boundingSphere;
  geometry.translate(-sphere.center.x, -sphere.center.y, -sphere.center.z);
  const canvas = document.getElementById("meb-surface");
  const renderer = new THREE.WebGLRenderer({{ canvas, antialias: true, preserveDrawingBuffer: true }});
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x181a20);
  const surface = new THREE.Mesh(geometry, new THREE.MeshLambertMaterial({{ color: 0xd7cdbe, side: THREE.DoubleSide }}));
  const pivot = new THREE.Group();
  pivot.add(surface);
  scene.add(pivot);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x303040, 1.2));
  const camera = new THREE.PerspectiveCamera(35, 1, sphere.radius / 100, sphere.radius * 100);
  const light = new THREE.DirectionalLight(0xffffff, 2.0);
  light.position.set(-0.4, 0.5, 1.0);
  camera.add(light);
  scene.add(camera);
  let distance = sphere.radius * 3.2, yaw = -0.5, pitch = 0.35;
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
{turn}
  canvas.addEventListener("wheel", (e) => {{ e.preventDefault(); distance *= Math.exp(e.deltaY * 0.001); draw(); }}, {{ passive: false }});
  window.addEventListener("resize", draw);
  draw();
  document.body.dataset.viewer = "rendered";
}} catch (error) {{
  note.textContent = "3-D view unavailable: " + error;
  document.body.dataset.viewer = "error: " + error;
}}
</script>"#,
        three = three_import(),
        turn = TURN_BY_DRAG,
        positions = positions,
        indices = indices,
    )
}

/// The mesh the viewer draws for `depth`: the full grid, or every k-th row and column when it
/// would exceed [`MAX_VIEWER_VERTICES`].
pub fn viewer_mesh(depth: &meb_core::types::DepthMap) -> SurfaceMesh {
    let pixels = depth.depth_mm.iter().filter(|z| z.is_finite()).count();
    let step = (1..)
        .find(|k| pixels / (k * k) <= MAX_VIEWER_VERTICES)
        .unwrap_or(1);
    if step == 1 {
        return SurfaceMesh::from_depth(depth);
    }
    let coarse = depth
        .depth_mm
        .slice(ndarray::s![..;step, ..;step])
        .to_owned();
    SurfaceMesh::from_depth(&meb_core::types::DepthMap {
        depth_mm: coarse,
        pitch_mm: depth.pitch_mm * step as f64,
        perspective: depth.perspective.map(|p| p.every(step)),
    })
}

/// The awaitable JavaScript expression that imports three.js exactly as [`surface_viewer`]'s
/// script does (the inlined module, or the pinned CDN copy checked against
/// [`THREE_JS_SHA384`]), for other pages' 3-D views (`video.html`).
pub fn three_js_import() -> String {
    three_import()
}

/// `mesh` as the viewers take it: base64 of its little-endian float32 vertex positions (x, y,
/// z) and of its uint32 triangle indices.
pub fn mesh_base64(mesh: &SurfaceMesh) -> (String, String) {
    let b64 = |bytes: &[u8]| base64::engine::general_purpose::STANDARD.encode(bytes);
    let positions: Vec<u8> = mesh
        .vertices
        .iter()
        .flat_map(|v| v.iter().flat_map(|x| x.to_le_bytes()))
        .collect();
    let indices: Vec<u8> = mesh
        .triangles
        .iter()
        .flat_map(|t| t.iter().flat_map(|i| i.to_le_bytes()))
        .collect();
    (b64(&positions), b64(&indices))
}

/// Largest share of the wall time the live view spends drawing surfaces
/// ([`live_surface_viewer`]).
pub const LIVE_DRAW_SHARE: f64 = 0.03;

/// The HTML (canvas + module script) of a 3-D view whose surface is replaced as new ones come,
/// for the live view of `meb video --live`. A page shows a surface by setting
/// `window.mebSurface = { positions, indices }` (as [`mesh_base64`] encodes them) and
/// dispatching a `meb-surface` event on `window`; a surface set before three.js has loaded is
/// drawn once it has. The camera keeps the turn and zoom it is given; each surface is centred
/// on its bounding sphere, and the first one sets the distance.
///
/// The view keeps the browser's share of the machine small, since a browser without a GPU
/// draws in software on the cores the pipeline uses: drawing is not antialiased, the material
/// is Lambertian, and a surface is drawn only when the time spent on the last one (timed up
/// to a one-pixel read-back, which waits for the drawing) is at most [`LIVE_DRAW_SHARE`] of
/// the time since; a surface that comes sooner is skipped, and the next one after the pause is
/// drawn as it comes. With a GPU every surface is drawn. After each surface drawn the viewer
/// sets `data-viewer="rendered"`, `data-meshes` (surfaces drawn), `data-skipped` (surfaces
/// skipped) and `data-draw-ms` (the last one's drawing time) on `<body>`
/// (`data-viewer="error: …"` when three.js cannot load).
pub fn live_surface_viewer() -> String {
    format!(
        r#"<div id="meb-viewer" style="position:relative;width:720px;max-width:100%;height:480px;border:1px solid #ddd;background:#181a20">
<canvas id="meb-surface" style="width:100%;height:100%;display:block;cursor:grab"></canvas>
<div id="meb-viewer-note" style="position:absolute;left:8px;bottom:6px;color:#aaa;font-size:85%">waiting for the first 3-D frame</div></div>
<script type="module">
const note = document.getElementById("meb-viewer-note");
try {{
  const THREE = await {three};
  const bytes = (s) => {{ const b = atob(s); const a = new Uint8Array(b.length); for (let i = 0; i < b.length; i++) a[i] = b.charCodeAt(i); return a.buffer; }};
  const canvas = document.getElementById("meb-surface");
  const renderer = new THREE.WebGLRenderer({{ canvas, antialias: false, preserveDrawingBuffer: true }});
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x181a20);
  const surface = new THREE.Mesh(new THREE.BufferGeometry(), new THREE.MeshLambertMaterial({{ color: 0xd7cdbe, side: THREE.DoubleSide }}));
  const pivot = new THREE.Group();
  pivot.add(surface);
  scene.add(pivot);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x303040, 1.2));
  const camera = new THREE.PerspectiveCamera(35, 1, 0.1, 1e5);
  const light = new THREE.DirectionalLight(0xffffff, 2.0);
  light.position.set(-0.4, 0.5, 1.0);
  camera.add(light);
  scene.add(camera);
  let distance = null, yaw = -0.5, pitch = 0.35, shown = 0, skipped = 0, free = 0;
  const pixel = new Uint8Array(4);
  const draw = () => {{
    if (distance === null) return;
    const w = canvas.clientWidth, h = canvas.clientHeight;
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    pivot.rotation.set(pitch, yaw, 0);
    camera.position.set(0, 0, distance);
    camera.lookAt(0, 0, 0);
    renderer.render(scene, camera);
  }};
  const show = (mesh) => {{
    if (!mesh || !mesh.positions || !mesh.indices) return;
    const start = performance.now();
    if (start < free) {{
      skipped += 1;
      document.body.dataset.skipped = String(skipped);
      return;
    }}
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(bytes(mesh.positions)), 3));
    geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(bytes(mesh.indices)), 1));
    geometry.computeVertexNormals();
    geometry.computeBoundingSphere();
    const sphere = geometry.boundingSphere;
    if (!(sphere.radius > 0)) return;
    geometry.translate(-sphere.center.x, -sphere.center.y, -sphere.center.z);
    surface.geometry.dispose();
    surface.geometry = geometry;
    if (distance === null) {{
      distance = sphere.radius * 3.2;
      camera.near = sphere.radius / 100;
      camera.far = sphere.radius * 100;
      note.textContent = "drag to turn, scroll to zoom";
    }}
    draw();
    const gl = renderer.getContext();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
    const cost = performance.now() - start;
    free = performance.now() + cost / {share};
    shown += 1;
    document.body.dataset.drawMs = cost.toFixed(1);
    document.body.dataset.meshes = String(shown);
    document.body.dataset.viewer = "rendered";
  }};
{turn}
  canvas.addEventListener("wheel", (e) => {{ e.preventDefault(); if (distance !== null) {{ distance *= Math.exp(e.deltaY * 0.001); draw(); }} }}, {{ passive: false }});
  window.addEventListener("resize", draw);
  window.addEventListener("meb-surface", () => show(window.mebSurface));
  show(window.mebSurface);
}} catch (error) {{
  note.textContent = "3-D view unavailable: " + error;
  document.body.dataset.viewer = "error: " + error;
}}
</script>"#,
        three = three_import(),
        turn = TURN_BY_DRAG,
        share = LIVE_DRAW_SHARE,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use meb_core::types::DepthMap;
    use ndarray::Array2;

    #[test]
    fn the_viewer_embeds_three_js_and_the_mesh() {
        let depth = DepthMap {
            depth_mm: Array2::from_elem((3, 3), 1.0),
            pitch_mm: 1.0,
            perspective: None,
        };
        let html = surface_viewer(&viewer_mesh(&depth));
        assert!(html.contains("data-viewer") || html.contains("dataset.viewer"));
        if THREE_JS.is_empty() {
            assert!(
                std::env::var_os("CI").is_none(),
                "three.js was not inlined (the build had no npm); CI must install it"
            );
            assert!(html.contains(THREE_JS_CDN) && html.contains(THREE_JS_SHA384));
        } else {
            assert!(THREE_JS.contains("REVISION") || THREE_JS.contains("\"170\""));
            assert!(html.contains("data:text/javascript;base64,"));
            // The CDN fallback must load exactly the file a build with npm inlines.
            use sha2::Digest;
            let digest = sha2::Sha384::digest(THREE_JS.as_bytes());
            let digest = base64::engine::general_purpose::STANDARD.encode(digest);
            assert_eq!(THREE_JS_SHA384, format!("sha384-{digest}"));
        }
    }

    #[test]
    fn the_live_viewer_loads_the_same_three_js_and_takes_encoded_meshes() {
        let html = live_surface_viewer();
        assert!(html.contains(&three_import()));
        assert!(html.contains("meb-surface") && html.contains("dataset.meshes"));
        let mesh = SurfaceMesh {
            vertices: vec![[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],
            triangles: vec![[0, 1, 2]],
        };
        let (positions, indices) = mesh_base64(&mesh);
        let decode = |s: &str| base64::engine::general_purpose::STANDARD.decode(s).unwrap();
        assert_eq!(decode(&positions).len(), 9 * 4);
        assert_eq!(
            decode(&indices),
            [0u32, 1, 2].map(u32::to_le_bytes).concat()
        );
    }

    #[test]
    fn large_surfaces_are_sub_sampled() {
        let depth = DepthMap {
            depth_mm: Array2::from_elem((720, 1280), 1.0),
            pitch_mm: 0.1,
            perspective: None,
        };
        let mesh = viewer_mesh(&depth);
        assert!(
            mesh.vertices.len() <= MAX_VIEWER_VERTICES,
            "{}",
            mesh.vertices.len()
        );
        assert!(mesh.vertices.len() > MAX_VIEWER_VERTICES / 5);
    }
}
