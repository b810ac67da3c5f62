//! Object masks in the PS camera's pixels from a ToF range map (thesis §6.6.1,
//! docs/maths/tof.md#layers-and-masks).
//!
//! A *layer* is a set of ToF pixels: either every pixel whose range lies in an interval (the
//! thesis' selection, e.g. [0.24 m, 0.31 m]) or, with [`segment`], a connected region of the
//! range map without range jumps above `jump_mm` between 4-neighbours (a surface without depth
//! discontinuities). Pixels straddling an edge measure a blend of both ranges; they join the
//! neighbouring layer whose range is nearest.
//!
//! A layer becomes a camera mask by inverse mapping: camera pixel p is traced back to the ToF
//! image with the calibration's homography at the layer's own range (the front-most range s
//! at which the layer's range map, sampled where p lands at s, equals s), the layer's
//! indicator is interpolated
//! bilinearly there, and p belongs to the layer where that exceeds 1/2 (with several layers,
//! to the one with the largest share). Clean-up replaces the thesis' MATLAB active contour:
//! morphological opening and closing, holes filled, the largest connected part kept, and —
//! when a camera image is given — the boundary snapped to the image's edges within a band of
//! ±one ToF pixel by marker-controlled watershed (Meyer's flooding, as OpenCV's `watershed`).

use super::TofError;
use super::calibration::Calibration;
use ndarray::Array2;
use rayon::prelude::*;

/// Settings of layer finding and mask clean-up.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MaskConfig {
    /// Neighbouring ToF pixels whose ranges differ by more belong to different layers, mm.
    pub jump_mm: f64,
    /// Layers with fewer ToF pixels are ignored.
    pub min_tof_pixels: usize,
    /// Clean up masks (opening, closing, holes, largest part).
    pub clean: bool,
}

impl Default for MaskConfig {
    fn default() -> Self {
        Self {
            jump_mm: 30.0,
            min_tof_pixels: 12,
            clean: true,
        }
    }
}

/// A set of ToF pixels belonging to one surface.
#[derive(Debug, Clone, PartialEq)]
pub struct Layer {
    /// Its ToF pixels.
    pub tof_mask: Array2<bool>,
    /// Range of its pixels: [1st, 99th] percentile, mm.
    pub range_mm: [f64; 2],
    /// Median range, mm.
    pub median_mm: f64,
    /// Number of ToF pixels.
    pub tof_pixels: usize,
    /// Whether it touches the ToF image border (a background wall usually does).
    pub touches_border: bool,
}

impl Layer {
    /// A layer from a ToF pixel set; `None` if it is empty.
    fn from_mask(tof_mask: Array2<bool>, range: &Array2<f32>) -> Option<Self> {
        let mut values: Vec<f64> = tof_mask
            .indexed_iter()
            .filter(|(p, m)| **m && range[*p].is_finite())
            .map(|(p, _)| f64::from(range[p]))
            .collect();
        if values.is_empty() {
            return None;
        }
        values.sort_by(f64::total_cmp);
        let q = |p: f64| values[((values.len() - 1) as f64 * p).round() as usize];
        let (rows, cols) = tof_mask.dim();
        let touches_border = tof_mask
            .indexed_iter()
            .any(|((r, c), &m)| m && (r == 0 || c == 0 || r + 1 == rows || c + 1 == cols));
        Some(Self {
            range_mm: [q(0.01), q(0.99)],
            median_mm: q(0.5),
            tof_pixels: values.len(),
            touches_border,
            tof_mask,
        })
    }
}

/// The thesis' selection: ToF pixels with range in [`lo`, `hi`] mm.
pub fn interval_layer(range: &Array2<f32>, lo: f64, hi: f64) -> Result<Layer, TofError> {
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(TofError::Invalid {
            field: "range".into(),
            reason: format!("{lo}..{hi} is not an interval A..B with A < B (mm)"),
        });
    }
    let mask = range.mapv(|r| r.is_finite() && f64::from(r) >= lo && f64::from(r) <= hi);
    Layer::from_mask(mask, range).ok_or_else(|| {
        let valid: Vec<f32> = range.iter().copied().filter(|r| r.is_finite()).collect();
        let (a, b) = valid
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &r| {
                (a.min(r), b.max(r))
            });
        TofError::Empty(format!(
            "no ToF pixel has a range in {lo}..{hi} mm (measured ranges span {a:.0}..{b:.0} mm)"
        ))
    })
}

/// Splits the range map into layers without internal range jumps (module docs), nearest first.
pub fn segment(range: &Array2<f32>, config: &MaskConfig) -> Result<Vec<Layer>, TofError> {
    let (rows, cols) = range.dim();
    let valid = |p: (usize, usize)| range[p].is_finite();
    let neighbours = |(r, c): (usize, usize)| {
        [
            (r.wrapping_sub(1), c),
            (r + 1, c),
            (r, c.wrapping_sub(1)),
            (r, c + 1),
        ]
        .into_iter()
        .filter(move |&(a, b)| a < rows && b < cols)
    };
    let mut label = Array2::from_elem((rows, cols), usize::MAX);
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for seed in (0..rows).flat_map(|r| (0..cols).map(move |c| (r, c))) {
        if !valid(seed) || label[seed] != usize::MAX {
            continue;
        }
        let id = sizes.len();
        label[seed] = id;
        stack.push(seed);
        let mut size = 0;
        while let Some(p) = stack.pop() {
            size += 1;
            for q in neighbours(p) {
                if valid(q)
                    && label[q] == usize::MAX
                    && f64::from((range[p] - range[q]).abs()) <= config.jump_mm
                {
                    label[q] = id;
                    stack.push(q);
                }
            }
        }
        sizes.push(size);
    }
    let kept: Vec<bool> = sizes.iter().map(|&s| s >= config.min_tof_pixels).collect();
    // Edge pixels (small leftovers) join the kept neighbour of nearest range.
    let mut joined = label.clone();
    for ((r, c), &l) in label.indexed_iter() {
        if l == usize::MAX || kept[l] {
            continue;
        }
        let best = neighbours((r, c))
            .filter(|&q| label[q] != usize::MAX && kept[label[q]])
            .min_by(|&a, &b| {
                (range[a] - range[(r, c)])
                    .abs()
                    .total_cmp(&(range[b] - range[(r, c)]).abs())
            });
        joined[(r, c)] = best.map_or(usize::MAX, |q| label[q]);
    }
    let mut layers: Vec<Layer> = (0..sizes.len())
        .filter(|&id| kept[id])
        .filter_map(|id| Layer::from_mask(joined.mapv(|l| l == id), range))
        .collect();
    if layers.is_empty() {
        return Err(TofError::Empty(format!(
            "no surface of at least {} ToF pixels in the range map ({} pixels have a range)",
            config.min_tof_pixels,
            range.iter().filter(|r| r.is_finite()).count()
        )));
    }
    layers.sort_by(|a, b| a.median_mm.total_cmp(&b.median_mm));
    Ok(layers)
}

/// Share of each camera pixel covered by `layer` (module docs), on a `camera_size` = [width,
/// height] grid.
pub fn layer_coverage(
    layer: &Layer,
    range: &Array2<f32>,
    calibration: &Calibration,
    camera_size: [usize; 2],
) -> Result<Array2<f32>, TofError> {
    let (rows, cols) = range.dim();
    calibration.check_sizes([cols, rows], camera_size)?;
    let [width, height] = camera_size;
    // The layer's ToF bounding box, one pixel wider: camera pixels mapping outside it are out.
    let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
    for ((r, c), &m) in layer.tof_mask.indexed_iter() {
        if m {
            (r0, r1, c0, c1) = (r0.min(r), r1.max(r), c0.min(c), c1.max(c));
        }
    }
    let indicator = |r: usize, c: usize| Some(if layer.tof_mask[(r, c)] { 1.0 } else { 0.0 });
    let rows_out: Vec<Vec<f32>> = (0..height)
        .into_par_iter()
        .map(|row| {
            (0..width)
                .map(|col| {
                    let (u, _) = trace_to_tof(layer, range, calibration, [col as f64, row as f64]);
                    let inside_box = u[1] >= r0 as f64 - 1.0
                        && u[1] <= r1 as f64 + 1.0
                        && u[0] >= c0 as f64 - 1.0
                        && u[0] <= c1 as f64 + 1.0;
                    if !inside_box {
                        return 0.0;
                    }
                    bilinear(u, (rows, cols), &indicator).unwrap_or(0.0) as f32
                })
                .collect()
        })
        .collect();
    Ok(Array2::from_shape_fn((height, width), |(r, c)| {
        rows_out[r][c]
    }))
}

/// Bilinear interpolation at ToF position `u` = (x, y) of the defined `values` among the four
/// neighbours (weights renormalised; `None` when none is defined or `u` is off the grid).
pub(crate) fn bilinear(
    u: [f64; 2],
    (rows, cols): (usize, usize),
    values: &dyn Fn(usize, usize) -> Option<f64>,
) -> Option<f64> {
    let [x, y] = u;
    if !(x > -1.0 && y > -1.0 && x < cols as f64 && y < rows as f64) {
        return None;
    }
    let (xf, yf) = (x.floor(), y.floor());
    let (fx, fy) = (x - xf, y - yf);
    let (mut sum, mut weight) = (0.0, 0.0);
    for (dy, wy) in [(0, 1.0 - fy), (1, fy)] {
        for (dx, wx) in [(0, 1.0 - fx), (1, fx)] {
            let (rr, cc) = (yf as i64 + dy, xf as i64 + dx);
            if rr < 0 || cc < 0 || rr >= rows as i64 || cc >= cols as i64 {
                continue;
            }
            if let Some(v) = values(rr as usize, cc as usize) {
                sum += wx * wy * v;
                weight += wx * wy;
            }
        }
    }
    (weight > 0.0).then_some(sum / weight)
}

/// ToF position (x, y) seen at camera pixel `p` = (x, y) by `layer`'s surface, and the range
/// used there.
///
/// The camera pixel's ray, at ToF range s, lands on ToF position u(s) (the calibration's
/// homography at s). Walking s from near to far over the layer's ranges (widened by half their
/// spread), the first s where the layer's interpolated range R(u(s)) falls from beyond s to
/// at or before it is where the ray meets the layer's surface: the front-most crossing, as the
/// camera sees it; R(u(s)) = s is solved there by linear interpolation between the two steps,
/// which advance u by at most a quarter ToF pixel. A fixed point started at the layer's median
/// range would land off the layer wherever the surface lies far from the median (the parallax
/// between the two cameras moves u by a few ToF pixels across a deep object's range) and
/// never recover. Without a crossing (the ray misses the layer), the homography at the range
/// sampled there (the median's, then twice the range found) is used.
pub(crate) fn trace_to_tof(
    layer: &Layer,
    range: &Array2<f32>,
    calibration: &Calibration,
    p: [f64; 2],
) -> ([f64; 2], f64) {
    let layer_range = |r: usize, c: usize| {
        (layer.tof_mask[(r, c)] && range[(r, c)].is_finite()).then(|| f64::from(range[(r, c)]))
    };
    let [lo, hi] = layer.range_mm;
    let margin = 0.5 * (hi - lo) + TRACE_MARGIN_MM;
    let (near, far) = (lo - margin, hi + margin);
    let (u_near, u_far) = (
        calibration.camera_to_tof(p, Some(near)),
        calibration.camera_to_tof(p, Some(far)),
    );
    let sweep = (u_far[0] - u_near[0]).hypot(u_far[1] - u_near[1]);
    if sweep.is_finite() {
        let steps = (sweep / TRACE_STEP_TOF_PIXELS).ceil().max(1.0) as usize;
        let mut previous: Option<(f64, f64)> = None;
        for i in 0..=steps {
            let s = near + (far - near) * i as f64 / steps as f64;
            let u = calibration.camera_to_tof(p, Some(s));
            let gap = bilinear(u, range.dim(), &layer_range).map(|v| v - s);
            if let (Some((s0, g0)), Some(g)) = (previous, gap)
                && g0 > 0.0
                && g <= 0.0
            {
                let crossing = s0 + (s - s0) * g0 / (g0 - g);
                return (calibration.camera_to_tof(p, Some(crossing)), crossing);
            }
            previous = gap.map(|g| (s, g));
        }
    }
    let mut s = layer.median_mm;
    let mut u = calibration.camera_to_tof(p, Some(s));
    for _ in 0..2 {
        if let Some(v) = bilinear(u, range.dim(), &layer_range) {
            s = v;
        }
        u = calibration.camera_to_tof(p, Some(s));
    }
    (u, s)
}

/// Range beyond the layer's own spread (each side) that [`trace_to_tof`] searches, mm.
const TRACE_MARGIN_MM: f64 = 10.0;

/// Largest move of the traced ToF position between two steps of [`trace_to_tof`], ToF pixels.
const TRACE_STEP_TOF_PIXELS: f64 = 0.25;

/// Camera masks of `layers` (sorted nearest first, as [`segment`] gives them): each pixel goes
/// to the nearest layer covering over half of it. Nearest, not most: the camera sees the near
/// surface where it stands in front of a far one, while the far layer, traced at its own range,
/// may cover the same pixel too (the two cameras see past the near object differently).
pub fn camera_masks(
    layers: &[Layer],
    range: &Array2<f32>,
    calibration: &Calibration,
    camera_size: [usize; 2],
) -> Result<Vec<Array2<bool>>, TofError> {
    let coverage: Vec<Array2<f32>> = layers
        .iter()
        .map(|l| layer_coverage(l, range, calibration, camera_size))
        .collect::<Result<_, _>>()?;
    let [width, height] = camera_size;
    let mut masks = vec![Array2::from_elem((height, width), false); layers.len()];
    for r in 0..height {
        for c in 0..width {
            if let Some(k) = coverage.iter().position(|cov| cov[(r, c)] > 0.5) {
                masks[k][(r, c)] = true;
            }
        }
    }
    Ok(masks)
}

/// Radius (camera pixels) of the clean-up's opening and closing: a quarter of a ToF pixel.
pub fn clean_radius(camera_pixels_per_tof_pixel: f64) -> usize {
    (0.25 * camera_pixels_per_tof_pixel).round() as usize
}

/// The thesis' selection mapped into the camera: ToF pixels with range in [`lo`, `hi`] mm
/// ([`interval_layer`]), their camera pixels ([`camera_masks`]), cleaned when `clean_up`.
pub fn interval_mask(
    range: &Array2<f32>,
    lo: f64,
    hi: f64,
    calibration: &Calibration,
    clean_up: bool,
) -> Result<(Layer, Array2<bool>), TofError> {
    let (rows, cols) = range.dim();
    calibration.check_sizes([cols, rows], calibration.camera_size)?;
    let layer = interval_layer(range, lo, hi)?;
    let mut masks = camera_masks(
        std::slice::from_ref(&layer),
        range,
        calibration,
        calibration.camera_size,
    )?;
    let mut mask = masks.pop().unwrap_or_default();
    if clean_up {
        let scale = camera_pixels_per_tof_pixel(calibration, Some(layer.median_mm));
        mask = clean(&mask, clean_radius(scale))?;
    }
    if !mask.iter().any(|&m| m) {
        return Err(TofError::Empty(format!(
            "the {} ToF pixels in {lo}..{hi} mm cover no camera pixel (is the calibration for this scene?)",
            layer.tof_pixels
        )));
    }
    Ok((layer, mask))
}

/// Camera pixels per ToF pixel (side length), from the calibration at `range_mm`.
pub fn camera_pixels_per_tof_pixel(calibration: &Calibration, range_mm: Option<f64>) -> f64 {
    let [w, h] = calibration.tof_size;
    let centre = [w as f64 / 2.0, h as f64 / 2.0];
    let a = calibration.tof_to_camera(centre, range_mm);
    let b = calibration.tof_to_camera([centre[0] + 1.0, centre[1]], range_mm);
    let c = calibration.tof_to_camera([centre[0], centre[1] + 1.0], range_mm);
    0.5 * ((b[0] - a[0]).hypot(b[1] - a[1]) + (c[0] - a[0]).hypot(c[1] - a[1]))
}

/// Half-widths of the rows of a disc of `radius` pixels: row dy ∈ [−r, r] spans columns
/// [−w, w] with w = round(√(r² − dy²)) (the digital ellipse of OpenCV's `MORPH_ELLIPSE`).
fn disc_half_widths(radius: usize) -> Vec<usize> {
    let r = radius as f64;
    (0..=2 * radius)
        .map(|i| {
            let dy = i as f64 - r;
            (r * r - dy * dy).max(0.0).sqrt().round() as usize
        })
        .collect()
}

/// Erosion (`erode`) or dilation of `mask` by a disc of `radius`; pixels outside the image
/// count as background for both, so erosion also eats in from the image border.
fn morph(mask: &Array2<bool>, radius: usize, erode: bool) -> Array2<bool> {
    let (rows, cols) = mask.dim();
    // Row-wise prefix counts: a disc row is a run of columns, tested in O(1).
    let mut prefix = Array2::<u32>::zeros((rows, cols + 1));
    for r in 0..rows {
        for c in 0..cols {
            prefix[(r, c + 1)] = prefix[(r, c)] + u32::from(mask[(r, c)]);
        }
    }
    let widths = disc_half_widths(radius);
    Array2::from_shape_fn((rows, cols), |(r, c)| {
        let mut rows_hit = widths.iter().enumerate().map(|(i, &w)| {
            let rr = r as i64 + i as i64 - radius as i64;
            let (lo, hi) = (c as i64 - w as i64, c as i64 + w as i64);
            if rr < 0 || rr >= rows as i64 {
                return (0, hi - lo + 1);
            }
            let (a, b) = (lo.max(0) as usize, (hi.min(cols as i64 - 1) + 1) as usize);
            (
                i64::from(prefix[(rr as usize, b)] - prefix[(rr as usize, a)]),
                hi - lo + 1,
            )
        });
        if erode {
            rows_hit.all(|(ones, len)| ones == len)
        } else {
            rows_hit.any(|(ones, _)| ones > 0)
        }
    })
}

/// Morphological opening then closing with a disc of `radius` pixels.
fn open_close(mask: &Array2<bool>, radius: usize) -> Array2<bool> {
    if radius == 0 {
        return mask.clone();
    }
    let opened = morph(&morph(mask, radius, true), radius, false);
    morph(&morph(&opened, radius, false), radius, true)
}

/// Label of a watershed line in [`watershed`].
const WATERSHED_LINE: i32 = -1;
/// Label of a pixel waiting in [`watershed`]'s queue.
const IN_QUEUE: i32 = -2;

/// Marker-controlled watershed by Meyer's flooding (F. Meyer, "Color image segmentation",
/// ICIP 1992; the variant of OpenCV's `watershed`, on any number of channels): `markers` (row-major, `cols` wide) hold
/// region labels > 0 and 0 for unknown pixels; `channels` are 8-bit image planes of the same
/// size. Unknown pixels are flooded from the markers in
/// order of the largest channel difference to the pixel they are reached from (256 FIFO
/// levels); a pixel reached by two regions, and the image's outermost ring, become
/// [`WATERSHED_LINE`].
fn watershed(channels: &[Vec<u8>], cols: usize, markers: &mut [i32]) {
    let rows = markers.len() / cols.max(1);
    if rows < 3 || cols < 3 {
        markers.fill(WATERSHED_LINE);
        return;
    }
    let diff = |i: usize, j: usize| {
        channels
            .iter()
            .map(|plane| plane[i].abs_diff(plane[j]))
            .max()
            .unwrap_or(0) as usize
    };
    for c in 0..cols {
        markers[c] = WATERSHED_LINE;
        markers[(rows - 1) * cols + c] = WATERSHED_LINE;
    }
    let mut queues: Vec<std::collections::VecDeque<usize>> = vec![Default::default(); 256];
    for r in 1..rows - 1 {
        markers[r * cols] = WATERSHED_LINE;
        markers[r * cols + cols - 1] = WATERSHED_LINE;
        for c in 1..cols - 1 {
            let i = r * cols + c;
            if markers[i] < 0 {
                markers[i] = 0;
            }
            if markers[i] != 0 {
                continue;
            }
            let level = [i - 1, i + 1, i - cols, i + cols]
                .into_iter()
                .filter(|&j| markers[j] > 0)
                .map(|j| diff(i, j))
                .min();
            if let Some(level) = level {
                queues[level].push_back(i);
                markers[i] = IN_QUEUE;
            }
        }
    }
    let mut active = 0;
    loop {
        while active < 256 && queues[active].is_empty() {
            active += 1;
        }
        let Some(i) = queues.get_mut(active).and_then(|q| q.pop_front()) else {
            break;
        };
        let neighbours = [i - 1, i + 1, i - cols, i + cols];
        let mut label = 0;
        for &j in &neighbours {
            let t = markers[j];
            if t > 0 {
                if label == 0 {
                    label = t;
                } else if t != label {
                    label = WATERSHED_LINE;
                }
            }
        }
        markers[i] = label;
        if label == WATERSHED_LINE {
            continue;
        }
        for &j in &neighbours {
            if markers[j] == 0 {
                let level = diff(i, j);
                queues[level].push_back(j);
                active = active.min(level);
                markers[j] = IN_QUEUE;
            }
        }
    }
}

/// Component labels (4-connectivity) of `mask`; returns labels (`usize::MAX` outside) and sizes.
fn components(mask: &Array2<bool>) -> (Array2<usize>, Vec<usize>) {
    let (rows, cols) = mask.dim();
    let mut label = Array2::from_elem((rows, cols), usize::MAX);
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for seed in (0..rows).flat_map(|r| (0..cols).map(move |c| (r, c))) {
        if !mask[seed] || label[seed] != usize::MAX {
            continue;
        }
        label[seed] = sizes.len();
        stack.push(seed);
        let mut size = 0;
        while let Some((r, c)) = stack.pop() {
            size += 1;
            for q in [
                (r.wrapping_sub(1), c),
                (r + 1, c),
                (r, c.wrapping_sub(1)),
                (r, c + 1),
            ] {
                if q.0 < rows && q.1 < cols && mask[q] && label[q] == usize::MAX {
                    label[q] = sizes.len();
                    stack.push(q);
                }
            }
        }
        sizes.push(size);
    }
    (label, sizes)
}

/// Opening + closing with a disc of `radius`, holes filled, only the largest part kept.
pub fn clean(mask: &Array2<bool>, radius: usize) -> Result<Array2<bool>, TofError> {
    let smoothed = open_close(mask, radius);
    let (label, sizes) = components(&smoothed);
    let Some(largest) = (0..sizes.len()).max_by_key(|&k| sizes[k]) else {
        return Ok(smoothed);
    };
    let kept = label.mapv(|l| l == largest);
    // Holes: background parts not connected to the image border.
    let (background, _) = components(&kept.mapv(|m| !m));
    let (rows, cols) = kept.dim();
    let mut border = std::collections::HashSet::new();
    for r in 0..rows {
        for c in [0, cols - 1] {
            border.insert(background[(r, c)]);
        }
    }
    for c in 0..cols {
        for r in [0, rows - 1] {
            border.insert(background[(r, c)]);
        }
    }
    Ok(Array2::from_shape_fn((rows, cols), |p| {
        kept[p] || (background[p] != usize::MAX && !border.contains(&background[p]))
    }))
}

/// Snaps the boundaries of disjoint `masks` to the edges of `image` (H×W×channels, any scale)
/// within `band` pixels of each boundary, by marker-controlled watershed (module docs).
/// Pixels of no mask stay outside every mask.
pub fn snap_to_edges(
    masks: &[Array2<bool>],
    image: &[Array2<f32>],
    band: usize,
) -> Result<Vec<Array2<bool>>, TofError> {
    let Some(first) = masks.first() else {
        return Ok(Vec::new());
    };
    let (rows, cols) = first.dim();
    if image.is_empty()
        || image.iter().any(|c| c.dim() != (rows, cols))
        || masks.iter().any(|m| m.dim() != (rows, cols))
    {
        return Err(TofError::Shape {
            what: "edge image".into(),
            detail: format!("needs at least one channel of the masks' size {cols}x{rows}"),
        });
    }
    // Markers: each mask's core (eroded by the band), the background's core, the rest unknown.
    let owner = Array2::from_shape_fn((rows, cols), |p| {
        masks
            .iter()
            .position(|m| m[p])
            .map_or(0i32, |k| k as i32 + 1)
    });
    let unsure = boundary_band(&owner, band);
    let markers: Vec<i32> = owner
        .indexed_iter()
        .map(|(p, &o)| if unsure[p] { 0 } else { o + 1 })
        .collect();
    // One 8-bit plane per image channel (each scaled to its 99th percentile): every LED image
    // counts, since an object's edge may show in one light only.
    let scaled: Vec<Vec<u8>> = image
        .iter()
        .map(|c| {
            let mut v: Vec<f32> = c.iter().copied().filter(|x| x.is_finite()).collect();
            let top = if v.is_empty() {
                1.0
            } else {
                let k = ((v.len() - 1) as f64 * 0.99) as usize;
                v.select_nth_unstable_by(k, f32::total_cmp)
                    .1
                    .max(f32::MIN_POSITIVE)
            };
            c.iter()
                .map(|&x| {
                    if x.is_finite() {
                        (x / top * 255.0).clamp(0.0, 255.0) as u8
                    } else {
                        0
                    }
                })
                .collect()
        })
        .collect();
    let mut labels = markers;
    watershed(&scaled, cols, &mut labels);
    // Watershed lines (−1) join the neighbouring region of the most similar colour.
    let distance = |i: usize, j: usize| {
        scaled
            .iter()
            .map(|plane| i32::from(plane[i].abs_diff(plane[j])))
            .sum::<i32>()
    };
    let resolved: Vec<i32> = (0..rows * cols)
        .map(|i| {
            if labels[i] != -1 {
                return labels[i];
            }
            let (r, c) = (i / cols, i % cols);
            [
                (r.wrapping_sub(1), c),
                (r + 1, c),
                (r, c.wrapping_sub(1)),
                (r, c + 1),
            ]
            .into_iter()
            .filter(|&(rr, cc)| rr < rows && cc < cols)
            .map(|(rr, cc)| rr * cols + cc)
            .filter(|&j| labels[j] > 0)
            .min_by_key(|&j| distance(i, j))
            .map_or(1, |j| labels[j])
        })
        .collect();
    Ok((0..masks.len())
        .map(|k| {
            Array2::from_shape_fn((rows, cols), |(r, c)| {
                resolved[r * cols + c] == k as i32 + 2
            })
        })
        .collect())
}

/// Pixels within `band` (Chebyshev distance) of a pixel with a different owner.
fn boundary_band(owner: &Array2<i32>, band: usize) -> Array2<bool> {
    let (rows, cols) = owner.dim();
    let edge = Array2::from_shape_fn((rows, cols), |(r, c)| {
        let o = owner[(r, c)];
        (r > 0 && owner[(r - 1, c)] != o)
            || (r + 1 < rows && owner[(r + 1, c)] != o)
            || (c > 0 && owner[(r, c - 1)] != o)
            || (c + 1 < cols && owner[(r, c + 1)] != o)
    });
    // Separable max filter of the edge indicator.
    let mut horizontal = Array2::from_elem((rows, cols), false);
    for r in 0..rows {
        for c in 0..cols {
            let lo = c.saturating_sub(band);
            let hi = (c + band).min(cols - 1);
            horizontal[(r, c)] = (lo..=hi).any(|cc| edge[(r, cc)]);
        }
    }
    Array2::from_shape_fn((rows, cols), |(r, c)| {
        let lo = r.saturating_sub(band);
        let hi = (r + band).min(rows - 1);
        (lo..=hi).any(|rr| horizontal[(rr, c)])
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tof::calibration::CalibrationPlane;

    fn identity_scaled(scale: f64) -> Calibration {
        Calibration {
            tof_size: [40, 30],
            camera_size: [160, 120],
            board: "9x6".into(),
            square_mm: None,
            planes: vec![CalibrationPlane {
                range_mm: None,
                homography: [[scale, 0.0, 1.5], [0.0, scale, 1.5], [0.0, 0.0, 1.0]],
                rms_px: 0.0,
                max_px: 0.0,
                corners: 54,
            }],
        }
    }

    /// A disc at 800 mm in front of a wall at 1100 mm, with a ring of blended edge pixels.
    fn scene() -> Array2<f32> {
        Array2::from_shape_fn((30, 40), |(r, c)| {
            let d = ((r as f64 - 14.0).powi(2) + (c as f64 - 18.0).powi(2)).sqrt();
            if d < 7.5 {
                800.0 + 0.3 * d as f32
            } else if d < 8.5 {
                950.0
            } else {
                1100.0
            }
        })
    }

    #[test]
    fn segments_disc_and_wall_and_maps_them_to_the_camera() {
        let range = scene();
        let layers = segment(&range, &MaskConfig::default()).unwrap();
        assert_eq!(layers.len(), 2);
        assert!(layers[0].median_mm < 810.0 && !layers[0].touches_border);
        assert!(layers[1].touches_border);
        let cal = identity_scaled(4.0);
        let masks = camera_masks(&layers, &range, &cal, [160, 120]).unwrap();
        let disc = &masks[0];
        // The disc's camera pixels: radius ≈ 8 ToF px = 32 camera px around (58.5, 73.5).
        let area = disc.iter().filter(|&&m| m).count() as f64;
        let expected = std::f64::consts::PI * 32.0f64.powi(2);
        assert!((area / expected - 1.0).abs() < 0.12, "{area} vs {expected}");
        assert!(masks[1].iter().zip(disc).all(|(&a, &b)| !(a && b)));
        let cleaned = clean(disc, 2).unwrap();
        assert!((cleaned.iter().filter(|&&m| m).count() as f64 - area).abs() < 0.05 * area);
    }

    #[test]
    fn empty_intervals_and_sizes_are_refused() {
        let range = scene();
        let err = interval_layer(&range, 300.0, 400.0).unwrap_err();
        assert!(err.to_string().contains("800..1100"), "{err}");
        assert!(interval_layer(&range, 900.0, 800.0).is_err());
        let layer = interval_layer(&range, 790.0, 820.0).unwrap();
        let cal = identity_scaled(4.0);
        let err = layer_coverage(&layer, &range, &cal, [320, 240]).unwrap_err();
        assert!(matches!(err, TofError::CalibrationMismatch(_)), "{err}");
    }

    #[test]
    fn watershed_snaps_a_too_small_mask_to_the_image_edge() {
        let (rows, cols) = (80, 80);
        let inside = |r: usize, c: usize| (r as f64 - 40.0).hypot(c as f64 - 40.0) < 20.0;
        let image =
            Array2::from_shape_fn((rows, cols), |(r, c)| if inside(r, c) { 0.8 } else { 0.3 });
        let rough = Array2::from_shape_fn((rows, cols), |(r, c)| {
            (r as f64 - 40.0).hypot(c as f64 - 40.0) < 17.0
        });
        let snapped = snap_to_edges(&[rough], &[image], 5).unwrap();
        let wrong = (0..rows)
            .flat_map(|r| (0..cols).map(move |c| (r, c)))
            .filter(|&(r, c)| snapped[0][(r, c)] != inside(r, c))
            .count();
        assert!(wrong < 40, "{wrong} pixels off the true disc");
    }

    /// The disc is OpenCV's `MORPH_ELLIPSE` of the same size (its 5×5 and 7×7 elements, whose
    /// openings and closings matched OpenCV's pixel for pixel on 40 random masks before the
    /// switch to this code), and opening/closing remove specks and fill gaps smaller than it.
    #[test]
    fn disc_opening_and_closing_remove_specks_and_fill_gaps() {
        assert_eq!(disc_half_widths(2), [0, 2, 2, 2, 0]);
        assert_eq!(disc_half_widths(3), [0, 2, 3, 3, 3, 2, 0]);
        let mut mask = Array2::from_shape_fn((30, 40), |(r, c)| {
            (5..25).contains(&r) && (5..30).contains(&c)
        });
        mask[(1, 35)] = true; // a speck
        for r in 5..25 {
            mask[(r, 17)] = false; // a one-pixel crack
        }
        let cleaned = open_close(&mask, 2);
        assert!(!cleaned[(1, 35)]);
        assert!((7..23).all(|r| cleaned[(r, 17)]));
        assert!(cleaned[(5, 5)] || cleaned[(6, 6)]);
        assert!(!cleaned[(2, 2)] && !cleaned[(27, 35)]);
        // Erosion treats the outside as background: a full image loses its border ring.
        let full = Array2::from_elem((10, 10), true);
        let eroded = morph(&full, 1, true);
        assert!(!eroded[(0, 5)] && eroded[(1, 5)] && eroded[(5, 5)]);
        // The radius-1 disc is a cross: dilating back restores all but the four corners.
        let dilated = morph(&eroded, 1, false);
        assert!(dilated[(0, 5)] && dilated[(5, 0)] && dilated[(9, 5)] && !dilated[(0, 0)]);
        assert_eq!(dilated.iter().filter(|&&m| !m).count(), 4);
    }

    /// Two markers either side of a bright ridge: the flood meets on the ridge, which becomes
    /// the watershed line; the image's outer ring is line too.
    #[test]
    fn watershed_floods_from_markers_and_meets_on_the_ridge() {
        let (rows, cols) = (9, 12);
        let plane: Vec<u8> = (0..rows * cols)
            .map(|i| if i % cols == 6 { 200 } else { 20 })
            .collect();
        let colour = vec![plane.clone(), plane.clone(), plane];
        let mut markers = vec![0; rows * cols];
        markers[4 * cols + 2] = 1;
        markers[4 * cols + 10] = 2;
        watershed(&colour, cols, &mut markers);
        for r in 1..rows - 1 {
            assert!((1..6).all(|c| markers[r * cols + c] == 1), "row {r}");
            assert_eq!(markers[r * cols + 6], WATERSHED_LINE, "row {r}");
            assert!((7..cols - 1).all(|c| markers[r * cols + c] == 2), "row {r}");
        }
        assert!((0..cols).all(|c| markers[c] == WATERSHED_LINE));
    }
}
