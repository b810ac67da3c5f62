//! One 3-D frame of `meb video` at the thesis' dynamic set-up: 40 camera frames of 1280×720
//! (the 100×60×60 mm ellipsoid turning at 7.5 rpm, 1000 fps, out-of-plane LEDs) already in
//! memory → decode the middle 32 → near-field photometric stereo → integration. Target: one
//! 3-D frame ≤ 40 ms (25 3-D frames per second) on 2 cores.
//!
//! `window` runs the whole pipeline as `meb video` does ([`meb_pipeline::video::process`] over one
//! window: reader thread, decode, motion check, reconstruction); the other cases time its
//! stages. `decode_carried_timing` decodes with the exposure and rate ratio carried from an
//! earlier window, as every window after the first few does; `decode_region` does so in a
//! 514×311 region of interest around the object (`meb decode --roi`). `reconstruct` is the
//! first window from scratch (cold); `window_warm` reconstructs the second window (frames
//! 44..76) started from the first window's result, as `meb video` does for every window after
//! the first ([`meb_pipeline::reconstruct::WarmStart`]). `frame_warm` is the one 3-D frame from
//! frames in memory: decode (carried timing) and warm reconstruction of the second window in series;
//! `frame_warm_bin2` bins its 32 frames first; `frame_warm_region` decodes and reconstructs in
//! the region around the object, as `meb video` does once its timing has settled
//! ([`meb_pipeline::reconstruct::from_decoded_region`]). The bench first prints both per-stage profiles and
//! how far the warm result lies from a cold reconstruction of the same window.
//!
//! Warm starts, first measurement (the stage profile this bench prints, one run at a load
//! average of 10–12 on 2 cores, so every figure is ~5× a quiet machine's): the cold first
//! window ran 4 passes, 6.2 s (photometric stereo 330–530 ms, integration 620–1520 ms, offset
//! search 100–370 ms per pass); the warm second window, with the passes then stopped on the RMS
//! depth change, ran 3 passes, 3.4 s (photometric stereo 320–450 ms, integration 560–780 ms,
//! offset search 45–93 ms per pass: the ±4 mm bracket and 5 000 pixels instead of the 13-sample
//! scan of ±60 mm over 20 000). The RMS never settled below 0.05 mm because the steep rim's
//! depths swing by millimetres from pass to pass; the passes now stop on the median change.
//! That does not settle either: on the 320×180 ellipsoid of `video_cli` the warm windows still
//! ran 4, 4 and 3 passes, because each pass's offset search moves the whole part by a few
//! tenths of a mm, and successive windows' offsets differ by a median 3.2–3.9 mm (one window in
//! five left the ±4 mm bracket and was redone cold). Per pass the warm offset search is about
//! half the cold one's (5.6–11 ms against 10–26 ms there); photometric stereo and integration
//! cost the same warm or cold, so a warm window was not faster yet. The passes now stop on the
//! change of shape (the median change after removing the median shift): `meb video` on a
//! 640×360, 240-frame turning ellipsoid (windows of 40, drop 4; `meb` test build, load ≈ 4)
//! ran its five warm windows in 3, 3, 2, 2, 3 passes (median-change stop: 3 each), 112–194 ms
//! of reconstruction each (median-change stop 209–317 ms, cold 354–692 ms in the same run), at
//! the same per-frame RMSE (0.248–0.475 mm warm, 0.298–0.473 mm cold). Next: keep the offset
//! per part from window to window unless the misfit clearly prefers another. Criterion figures
//! with the final code were not taken.
//!
//! Measured on the shared 2-core machine while other helpers were building (criterion, 10
//! samples; medians with the low–high estimates), far from the 40 ms target:
//!
//! | case                   | before          | after m = 1 falloff without powf |
//! |------------------------|-----------------|----------------------------------|
//! | window (whole 3-D frame)| 1.46 s (1.22–1.69) | 0.96 s (0.89–1.05)            |
//! | decode                 | 21.6 ms         | 19.8 ms                          |
//! | decode_carried_timing  | 26.7 ms         | 19.0 ms                          |
//! | reconstruct            | 1.54 s (1.48–1.60) | 1.08 s (0.90–1.28)            |
//!
//! (The machine's load fell between the two runs, so part of the change is load.) Where the
//! time goes (perf, `meb video` on the 1280×720 ellipsoid): the near-field loop — light
//! vectors per pixel and LED (`Led::light_vector_at`, `Lights::at`, and before the change
//! `pow` at 20 % of all samples), the per-pixel solve (`solve_pixel`, 10–13 %) and the
//! closures of the depth-offset search — ≈ 70 %; integration (multigrid) ≈ 5 %; decoding
//! ≈ 3 %; per pass, the offset search costs 220–280 ms against 60–100 ms of integration.
//!
//! The bench prints the per-stage profile of one reconstruction first. A later round (light
//! vectors from a prepared projection and LED emitters, the offset search gathering its pixels
//! once, background pixels decided before light vectors, early passes with capped two-LED
//! alternations) was measured only at a load average of 10–11 on 2 cores, where `reconstruct`
//! took 11.9 s (11.1–12.7) against 11.6 s (8.3–14.9) for the code before it in the same run:
//! load, not code, set those numbers. At a load of 4–9 the two measured 2.08–2.40 s (after)
//! and 2.14 s (before): no speed-up is shown yet. Per pass (after) the offset search took
//! 87–100 ms, photometric stereo 71–100 ms and integration 145–290 ms; re-measure on a quiet
//! machine.
//!
//! End to end (`meb video` release build, 1280×720 mono y4m of the turning ellipsoid, windows of
//! 40, drop 4; `/usr/bin/time -v`, `perf record`). The simulator rendered only ~0.4 frames/s at a
//! load of 10–15, so the clip is 400 rendered frames (10 windows); the 2000-frame clip (those
//! frames five times, 1.84 GB) was started with the code before and stopped after 12 windows
//! (21 s each at load 11; it would have taken ~18 min). Every figure is at a load average of
//! 10–15 on 2 cores, so the reconstruction is 10–25× a quiet machine's; compare shares, not times.
//!
//! | 400 frames, windows of 40       | before (main 430946e) | after (threads overlap)   |
//! |---------------------------------|-----------------------|---------------------------|
//! | wall, 3-D fps                   | 135.7 s, 0.074        | 81.4 s, 0.123 (more CPU)  |
//! | Σ reconstruct (the core)        | 130.3 s               | 79.8 s                    |
//! | Σ decode / motion / write / read| 3.55 / 0.29 / 0.61 / 0.58 s, in series | 4.14 / 0.26 / 1.38 / 0.23 s, overlapped |
//! | wall outside the reconstruction | 5.4 s (4.0 %)         | 1.65 s (2.0 %): 0.96 s first decode, ~0.6 s closing |
//! | CPU (user + sys), share of a CPU| 36.0 s, 25 %          | 34.1 s, 40 %              |
//! | peak RSS                        | 325 MB                | 402 MB                    |
//!
//! Where the CPU goes (perf, after): photometric stereo ≈ 22 %, integration ≈ 23 %, kernel 15 %
//! (1.06 M minor page faults per 10 windows before and after: the core's fresh `from_elem`
//! arrays), inlined closures of the core ≈ 20 %, the reader thread 1.0 %, the writer 0.4 %,
//! FFmpeg 1.7 % (mostly its start-up). The reader's cost is one copy of each luma plane
//! (`_copy_to_iter`); a file's chroma is seeked over. With `--hop 8` (120 frames, 11 windows,
//! load 15, 10 % of a CPU): 306.7 s, 0.036 3-D fps, 2.9 s of CPU per window (3.4 s for windows of
//! 40: the warm starts are closer), 2.3 s (0.7 %) of the wall outside the reconstruction, peak
//! RSS 371 MB. End to end is the reconstruction's rate: ≥ 25 3-D fps waits for a ~40 ms core.
//!
//! Photometric stereo with a one-byte outcome map (the full per-pixel solutions took 74 MB per
//! solve at 1280×720), the object's pieces and holes labelled inside its bounding box, lit-LED
//! sets walked by their set bits and one ray per pixel; warm windows keep the carried offset
//! unless a t-test over bands of the part clearly prefers another, and stop once the depth lies
//! within 1 mm (median) of the one their light vectors came from. The profile this bench
//! prints, before and after in the same hour at a load average of 11–15 on 2 cores (four
//! helpers building; every figure is 10–20× a quiet machine's): photometric stereo per pass
//! 1070–2100 ms before, 105–260 ms after (cold and warm alike); the warm second window ran 3
//! passes before (offset search 280–370 ms each) and 2 after (77 ms each); integration
//! (unchanged code) 1.7–4.2 s before and 0.75–1.7 s after per pass, load alone.
//!
//! A prior across windows ([`meb_pipeline::reconstruct::WARM_OFFSET_GAIN`]): at main bcea852 (load 5)
//! the warm second window ran 2 passes (`moved_mm` 3.9: its misfit clearly preferred an offset
//! ~4 mm from the carried one, near the ±4 mm bracket's edge, and pass 1 jumped there):
//! photometric stereo 66 + 56 ms, integration 189 + 191 ms, offset search 30 + 34 ms, 565 ms.
//! A warm start now moves 0.24 of the way to a clearly preferred offset (≤ 0.96 mm), under the
//! 1 mm stop, so such a window stops after 1 pass. On the 320×180 turning ellipsoid of
//! `video_cli` the t-test never prefers another offset, so its per-frame RMSE is unchanged
//! (warm 0.404/0.506/0.418/0.407/0.402 mm, cold 0.404/0.422/0.449/0.257/0.587 mm).
//!
//! Session 23, criterion on the quiet machine (load ≈ 1), main bcea852 → after the damped
//! offset, the wider warm bracket ([`meb_pipeline::reconstruct::WARM_WIDE_BRACKET_MM`]), the faster
//! decode and integration hole filling: `window_warm` 432 ms (421–443) → **181 ms** (173–190),
//! 1 pass instead of 2 (photometric stereo 30 ms, integration 99 ms, offset search 14 ms);
//! `window` 1.11 s → 0.83 s; `reconstruct` (cold) 1.12 s → 0.83 s; `decode` 26.4 → 19.6 ms;
//! `decode_carried_timing` 24.6 → 17.0 ms. The bench's warm result now lies a median 3.5 mm
//! from the cold one (0.36 mm before): the damped offset, not the shape. Against ground truth
//! on a 1280×720 turning-ellipsoid clip the damped offsets are the closer ones: `meb video`,
//! 2000 frames (49 windows of 40, release build, quiet): absolute depth offset from the truth
//! mean 0.52 → −0.11 mm, standard deviation 2.41 → 1.07 mm, worst 5.14 → 2.12 mm; depth RMSE
//! (offset removed) median 0.79 → 0.70 mm, worst 1.58 → 1.20 mm; cold redos 17 → 0; wall
//! 29.4 s → 14.5 s (1.7 → 3.4 3-D frames/s), reconstruction 579 → 281 ms per window, peak RSS
//! 338 → 323 MB. Still ~7× from 25 3-D frames/s: integration (≈ 100 ms warm) is next.
//!
//! Session 24 (issue #14): the multigrid aggregation is kept across the solves on one mask and
//! only the Galerkin operators are recomputed (`Multigrid::reweight`), the bilateral energy no
//! longer sums side weights it does not use, and the offset search gathers its model once for
//! both warm brackets and evaluates the carried offset's misfit once. The warm window's depth
//! is byte-identical before and after (53 857 pixels, checked through the `meb` test build).
//!
//! Session 27 (2026-12-03), photometric stereo: the per-LED noise gains (a serial pass over every
//! image, a third of the stage) read the images as slices, two at a time against one pass over
//! the noise map, gathering the negative readings without a branch per reading and advancing
//! the images' sums side by side (same additions in the same order); the automatic mask reads
//! the brightest LED only at usable pixels instead of building a full-frame map; the final
//! assembly visits only solved and two-LED pixels; whether the object holds a usable pixel is
//! known from the region instead of a full-frame scan. Every output is bit-identical (normals, albedo, masks, LED
//! counts, planes and gains hashed over the cold and warm windows and three direct calls).
//! Stage profile of this bench, before/after binaries alternated, 3 runs each, at a load
//! average of 4 (another build on the 2 cores): "photometric stereo, warm (pass 1)" 59.1 /
//! 116.1 / 85.0 ms → 50.5 / 52.0 / 86.7 ms (medians 85.0 → 52.0); median of all nine PS
//! stages per run 51.1 / 87.0 / 85.9 → 36.9 / 38.5 / 49.6 ms. Direct calls run back to back
//! (median of 3 before, 5 after): warm depth, no mask 63.1 → 44.9 ms; with the object mask
//! (passes 2–4) 44.0 → 32.1 ms. Left: the parallel per-pixel solve (≈ 40 % of the stage),
//! the speck and hole labelling (`regions`) and the fresh full-frame NaN arrays.
//!
//! Session 27, integration (`benches/integrate.rs` has the details): red–black Gauss–Seidel
//! in the V-cycle (15 CG iterations instead of 17 for the warm window), a band Cholesky factor
//! on the coarsest level, and the per-node loops of every pass in parallel bands. With the
//! photometric-stereo change above, criterion on a quiet machine (load 1.5–1.9), main a529b3b
//! and this code alternated, two runs each: `window_warm` 170 / 169 ms → **153 / 142 ms**;
//! `window` (cold, whole pipeline with the decoder overlapping) 939 ms / 1.00 s → 806 / 844 ms.
//! The warm window's stage profile, one run each: photometric stereo 46–53 → 30 ms,
//! integration 124–133 → 88–102 ms, offset search 13–15 ms either way. Still ≈ 4× from the
//! 40 ms target.
//!
//! Session 28 (2026-12-03), a region of interest for warm windows
//! ([`meb_pipeline::reconstruct::ROI_MARGIN_PX`]): a warm window is reconstructed inside the previous
//! depth's bounding box grown by 32 px (here 247 × 450 of the 720 × 1280 frame) on a camera
//! cut to it, and pasted back; an object that reaches the region's edge is reconstructed on the
//! full frame. Criterion at a load average of 3–4 (a helper building), main fe2c89c and this
//! code alternated: `window_warm` 198 / 182 ms → **150 / 166 ms**. Stage profile of the warm
//! window, one run each: photometric stereo 40 / 80 → 9 / 22 ms, offset search 27 / 36 →
//! 10 / 21 ms, integration unchanged (it already worked in the object's box), plus 0.6 ms to cut
//! the region and 6–7 ms to paste the results back into full-frame arrays. The warm result
//! covers the same 53 857 pixels and lies as far from the cold one as before (median 3.494 mm
//! against 3.492 mm). `meb video` (release) on a 260-frame 1280×720 turning ellipsoid rendered
//! with truth every 20 frames (6 windows of 40): wall 2.41 → 2.08 s, warm windows 131–376 →
//! 147–259 ms, per-frame depth RMSE median 0.653 → 0.654 mm, the five warm windows 0.653 /
//! 0.532 / 0.532 / 0.535 / 0.742 → 0.654 / 0.515 / 0.532 / 0.535 / 0.797 mm (the last one
//! stopped after 1 pass instead of 2); on the 320×180 `clip820` (41 windows, `--hop 20`, 20
//! scored) the median RMSE is 0.3790 → 0.3787 mm, worst 0.712 mm either way. Integration
//! (≈ 88 ms warm) is now nearly all of the window; the inpainting and edge equations lost 7.7 %
//! of its instructions this session (`benches/integrate.rs`).
//!
//! Session 29 (2026-12-03), binning (`meb video --bin 2`, [`meb_core::capture::binning`]): every
//! frame is binned 2×2 as it is read and the window is reconstructed at 640×360 for the binned
//! camera. Criterion at a load average of ≈ 2, one run each: `window_warm` 145 ms (the full
//! resolution, with this session's conjugate-gradient changes: unchanged within the noise),
//! `window_warm_bin2` **88 ms** (integration 47 ms, offset search 24 ms, photometric stereo
//! 4.6 ms), `decode_bin2` 18 ms against `decode_carried_timing` 40–45 ms, `bin_frames` 37 ms
//! for 40 frames (on the reader thread). `meb video` (release) on the 260-frame 1280×720
//! ellipsoid with truth every 20 frames: wall 2.3 → 1.0 s, warm windows 131–291 → 38–100 ms,
//! and the per-frame depth RMSE falls from 0.515–0.797 mm to 0.281–0.575 mm (a binned pixel
//! sums four, so its noise is halved relative to its signal, and the smooth surface loses
//! nothing at 640×360). On a 2000-frame clip (those frames' first 160 looped, 50 windows of 40):
//! 4.2 3-D frames/s at full resolution (reconstruct median 199 ms, 334 MB peak memory),
//! **10.1 3-D frames/s** binned (median 87 ms, 120 MB); binned with `--hop 8` over 400 frames,
//! 7.4 3-D frames/s. The target of 25 is not reached: at 640×360 the integration's fixed costs
//! (its passes, set-up and output) and the offset search, whose cost does not fall with the
//! pixel count, dominate.
//!
//! Session 31 (2026-12-04, quiet machine, load < 0.1): the decoder reads a window where it lies in
//! the stream's ring ([`meb_pipeline::demod::decode_frames`]; it copied all 32 frames into a frame source
//! first, 17 % of `decode_bin2`'s samples were that `memmove`), and the offset search refines by
//! Brent's method (golden-section and parabolic steps: a median 8 evaluations of the misfit instead
//! of 16–22). Criterion, main ea733ad and this code alternated, two runs each (medians):
//! `decode_carried_timing` 12.9 / 12.4 → **8.5 / 10.1 ms**, `decode_bin2` 6.3 / 5.9 → **4.2 /
//! 4.3 ms**, `window_warm` 64.8 / 61.3 → **58.7 / 59.4 ms** (warm offset search 8.0 / 8.2 → 4.9 /
//! 6.8 ms), `window_warm_bin2` 33.6 / 33.9 → **29.2 / 30.7 ms**. One full-resolution 3-D frame from
//! frames in memory is thus ≈ 67 ms (decode + warm reconstruction), a binned one ≈ 41 ms (binning
//! 32 frames ≈ 7 ms on the reader thread, decode, reconstruction). `meb video` (release) on a
//! continuously rendered 2000-frame 1280×720 turning ellipsoid (not a looped one: the loop's jump
//! back made every fourth window take 2 passes, so s29's looped clip understated the rate): `--bin
//! 2` 24.6 / 24.7 → **26.2 / 27.2 3-D frames/s** (1.95 s wall, 2.7 s user, 105 MB peak), full
//! resolution 7.6 → 8.4 3-D frames/s (300–340 MB). Per-frame depth RMSE against truth every 20
//! frames (400-frame clip, 10 windows) is unchanged to 0.1 µm: full resolution 0.515–0.797 mm
//! (median 0.645), binned 0.201–0.575 mm (median 0.330); `meb demo` unchanged (sphere 0.15 mm /
//! 1.54°, cube 0.26 mm / 0.79°). Where the binned pipeline's CPU went before (perf, a whole `meb
//! video --bin 2` run): the decode thread and the rayon workers 49 % (the per-pixel photometric
//! solve of the offset search's misfit alone 10.6 %, light vectors 4.2 %, the matched filter
//! 3.2 %), the reconstruction's own thread 17 %, the reader 16 % (binning 9 %, the kernel's copy
//! 3 %), FFmpeg 12 % (x264 4 %, its start-up 2.5 %), the writer 5.5 %.
//!
//! Then the usable LED images (the decoder's flagged pixels as NaN, made for every window on the
//! full frame) in one pass per image instead of a copy overwritten, the images in parallel:
//! `window_warm` 61.5 / 62.2 → 57.7 / 61.6 ms (within the noise), `window_warm_bin2` unchanged;
//! `meb video` on the 2000-frame clip, alternated, two runs each: full resolution 9.2 / 8.9 →
//! **10.0 / 9.7 3-D frames/s**, `--bin 2` 28.3 / 26.2 → 28.0 / 28.5 (the same within the noise).
//! With `--hop 8` (246 3-D frames): **29.8 3-D frames/s** binned (8.3 s, 91 MB), 12.5 at full
//! resolution (19.6 s, 275 MB).
//!
//! The one 3-D frame as a case of its own (`frame_warm`: decode with carried timing and
//! warm reconstruction in series, frames already in memory), four runs on the quiet machine: 70.9 /
//! 84.0 / 81.4 / 77.5 ms at full resolution (`window_warm` alone 68 ms and `decode_carried_timing`
//! 9.5 ms in the same hour); `frame_warm_bin2` (binning the 32 frames too) 39.1 / 50.1 / 48.1 /
//! 44.8 ms. The ≤ 40 ms target is met only once, binned.
//!
//! Session 32 (2026-12-04, quiet machine but for one build): a warm pass integrates with one
//! two-LED alternation and a 10⁻⁴ solve ([`meb_pipeline::reconstruct::pass_integration`]; the warm start
//! already takes the two-LED slopes from the previous depth: CG iterations per warm window, 400
//! frames, median 13 → 6); `meb` keeps freed memory for reuse ([`meb_core::memory`]: glibc handed
//! every window's ≈ 45 MB of pasted full-frame arrays back to the kernel and faulted them in
//! afresh, 566 000 → 126 000 page faults over the 2000-frame clip; this bench calls it too); the
//! region's results are pasted into the frame side by side; and a warm window stops once its
//! depth lies within 1.5 mm of the one its light vectors came from (was 1 mm: 10 of the 49 warm
//! windows of the 2000-frame clip ran 2–3 passes, now none). Criterion, main 27fe128 and this
//! code alternated, two runs each (the last change not included): `window_warm` 64.6 / 67.3 →
//! **46.0 / 44.8 ms**, `frame_warm` 71.6 / 72.4 → **51.6 / 54.3 ms**, `window_warm_bin2` 31.7 /
//! 31.8 → **19.2 / 18.7 ms**, `frame_warm_bin2` 43.2 / 42.5 → **33.2 / 33.7 ms** (the ≤ 40 ms
//! target is met binned, not at full resolution). The warm window's stages now: photometric
//! stereo 7.6–13 ms, integration 22.6 ms (was 35–52), offset search 4.5 ms, paste 4.4 ms (was 6).
//! `meb video`, the continuously rendered 2000-frame 1280×720 ellipsoid, alternated: with truth
//! scoring every 20 frames, full resolution 8.3 / 8.2 → **11.3 / 11.0 3-D frames/s** (peak memory
//! 305 → 372 MB: freed pages are kept), `--bin 2` 15.9 / 18.4 → **21.2 / 20.6**; without truth,
//! full resolution 6.1 / 5.3 s → **4.4 / 4.3 s** wall (≈ 12 3-D frames/s), `--bin 2` 2.05 / 2.31 →
//! 1.81 / 2.09 s (24.9–28.6 3-D frames/s). Per-frame depth RMSE over all 50 windows (truth every
//! 20 frames): full resolution median 0.678 → 0.669 mm (0.419–1.195 mm; before 0.432–1.291), binned
//! 0.427 → 0.422 mm (0.145–1.102 mm); a turning blobby object (640×360, 10 windows) is unchanged
//! to the µm (median 0.434 mm). Where the full-resolution run's CPU goes now (perf, threads): the
//! rayon workers (decode and the reconstruction's parallel parts) 50 %, the reader 22 % (15 % is the
//! kernel copying the file's pages into the window ring), the reconstruction's own thread 14 %, the
//! writer 8 %, FFmpeg 7 %. In `frame_warm`: the matched filter 10 %, the per-pixel photometric
//! solve 9.5 % and its light vectors 4.7 %, the inpainting of two-LED and hole slopes 7.4 %, the
//! usable LED images 2.6 % (now made for the warm window's region alone: `from_decoded_warm`).
//! With every change of the session (the machine noisier by then: `frame_warm` 56–76 ms before
//! and 58–78 ms after the region-only images, four alternated runs each), `meb video` on the
//! 2000-frame clip without truth: full resolution **14.1 / 12.8 3-D frames/s** (3.7 / 4.0 s,
//! 346 MB), `--bin 2` **27.6 / 24.4**; `--hop 8` (246 3-D frames) **33.1** binned (7.5 s, 112 MB)
//! and **15.5** at full resolution (15.9 s, 333 MB), against 29.8 and 12.5 before. Next: decode
//! only the region of a warm window (the decoder runs ahead of the reconstruction that knows the
//! region, and a window whose object leaves it needs its frames again), and read the file
//! without the kernel's copy.
//!
//! Session 33: decoding only a warm window's region, tried. A 514×311 region around the
//! object (17 % of the frame) decoded in 25.8–30.5 ms, 2.5× the whole frame's 11.0 ms: the
//! frames were cut to it by cloning each whole frame and collecting the region's rows one
//! small vector at a time. Cut straight into one allocation per frame, in parallel:
//! `decode_region` **7.1–7.2 ms** (`decode_carried_timing` unchanged, 11.0 ms; two alternated
//! runs each). Only 4 ms less than the whole frame, because most of a carried-timing decode
//! does not scale with the pixels (the sample's gathering and timing fit, the LED check and the
//! fit quality, twice). And in `meb video` on a 400-frame clip of the ellipsoid, the carried
//! timing fitted the region's shifts wrongly in 5 of 7 focused windows (median σ 0.043 against
//! 0.005, verdict implausible): the shift seeds of an LED the region's signal space holds
//! poorly. The seeds now include each LED's rival shifts (`demod::seed`, `RIVAL_SHARE`), which
//! decodes 12 of 14 such region windows right (0 of 6 before); decoding warm windows around
//! the object stays out, for it saves 3 ms and still falls back now and then.
//!
//! Session 35: where a warm frame's wall time goes on 2 cores. Perf over 10 s of `frame_warm`:
//! the calling thread alone (serial work, the pool idle) is 24 % of the samples, ≈ 20 ms of a
//! 60 ms frame, and the pool's two workers were busy 1.5 cores' worth in the parallel parts.
//! The serial part is a long tail of ≤ 2 ms items: the matched filter's output planes zeroed by
//! `calloc` (memory kept for reuse must be cleared: a serial memset of ≈ 20 MB), the multigrid's
//! small levels and CG's vector updates, the speck and hole labelling of the object mask, the
//! pieces and parts labellings, the region's bounding box, the depth-change medians. Now the
//! output planes are written once by the rows' kernels into unzeroed memory, the region's
//! arrays are pasted row by row in parallel into unfilled memory, the labelling floods on
//! row-major indices, the pieces and the bilateral parts are labelled side by side, and the
//! bounding box is found by rows in parallel. Every output is byte-identical (`meb video` on a
//! 200-frame 1280×720 turning ellipsoid: every depth, normals and albedo file and every
//! non-timing field of `video.json`). Measured with a loop of 100 warm frames (decode with
//! carried timing + warm reconstruction of the second window, as `frame_warm`), main 8adb532
//! and this code alternated, two runs each: frame minimum 50.3 / 50.4 → **47.1 / 46.5 ms**,
//! median 59.8 / 57.2 → **54.1 / 54.2 ms**; decode minimum 9.7 / 9.6 → 8.2 / 8.2 ms; warm
//! reconstruction minimum 40.5 / 40.1 → 38.5 / 38.2 ms. Criterion medians on this (shared)
//! machine scatter by ±10 % from run to run, more than these changes. The warm window's stages
//! in steady state (minimum / median of 60): integration 21.4 / 26.2 ms, photometric stereo
//! 6.9 / 8.4 ms, offset search 5.9 / 7.4 ms, paste 1.8 / 2.2 ms (the 5.4 ms this bench prints
//! first is its first, cold-cache call). Tried and dropped: a coarser Brent tolerance for warm
//! windows (0.1 mm instead of 0.01 mm) made the offset search slower (8.5–9.9 ms against
//! 5.9–7.7 ms): its minimum then more often lay clearly below the carried offset's misfit, which
//! costs the band t-test's two extra evaluations.
//!
//! Session 36: the warm integration (21 ms of a 47 ms frame) by its steps (minimum / median of
//! 64 windows): push–pull inpainting 3.9 / 4.4 ms, of which each fill's 30 Gauss–Seidel sweeps
//! took 3.1 ms for the s_x, s_y pairs and as long for the albedo alone (12 405 pixels to fill):
//! in raster order each update waited for its left neighbour's, so the sweep was bound by that
//! chain, not by arithmetic. Conjugate gradients 6.0 / 8.0 ms (5 iterations), edge equations
//! 2.0 / 2.5, hierarchy 1.4 / 1.5, pieces and anchoring 1.0 / 1.4, pixel classes 1.1 / 1.2,
//! output 1.1 / 1.2. Now the sweeps go in red–black order (each colour's updates independent:
//! a fill 3.1 → 1.5 ms, inpainting 2.0 / 2.1 ms); a warm pass's solve stops at a relative
//! residual of 10⁻³ (3 iterations instead of 5; 3.5 / 4.1 ms); the pixel classes (0.7 / 0.8)
//! and the output (0.6 / 0.7) go by rows in parallel; CG's vector updates by fixed bands; the
//! pieces are labelled beside the hierarchy's set-up (pieces and anchoring 0.4 / 0.5 ms); and a
//! misfit evaluation of the offset search runs in ten tasks of 512 pixels instead of five of
//! 1 024 (offset search median 6.3 → 5.9 ms). Loop of 100 warm frames, main 6423012 and this
//! code alternated, two runs each: frame minimum 46.7 / 46.2 → **40.9 / 42.0 ms**, median
//! 58.3 / 50.4 → 49.9 / 48.5 ms; warm integration minimum 21.5 / 21.1 → 16.1 / 16.2 ms; warm
//! reconstruction minimum 38.2 / 37.8 → 32.7 / 33.3 ms. Criterion (one run): `window_warm`
//! 37.3 ms (36.9–37.9), `frame_warm` 48.1 ms (46.6–50.7), `frame_warm_bin2` 38.5 ms. The
//! red–black fill is not bit-identical to the raster one (the other changes are, up to the
//! order of CG's sums): on a 600-frame 1280×720 turning ellipsoid (15 windows against truth
//! every 20 frames) the per-window depth RMSE moved by +0.1 to +3.1 µm (median +1.7 µm) with
//! it and by −1.1 to +2.4 µm (median +0.6 µm) with the looser solve, on RMSEs of 0.51–0.80 mm. `meb video` on 2000 frames (that clip's first 200
//! repeated ten times; windows of 40, no `--save`): 9.9 / 12.6 → 13.2 / 13.8 3-D frames/s, the
//! mean warm reconstruction in the video 97 / 76 → 72 / 69 ms (decoder, reader, writer and
//! FFmpeg share the cores). Tried and dropped: 10 sweeps instead of 30 (the cold window's RMSE
//! 0.734 → 0.755 mm); 2 500 pixels instead of 5 000 for the warm offset search (every warm
//! window's RMSE 48–96 µm worse); multigrid levels of 8 192 nodes and more in parallel (was
//! 16 384: no change); the decoding thread in a rayon pool of its own at nice 10 (no change end
//! to end; perf over the whole run: the cores ≈ 81 % busy, FFmpeg, writer and reader ≈ 17 % of
//! the samples).
//!
//! Session 37: a warm offset search evaluated the misfit 11 times: once at the carried offset,
//! about eight times in Brent's method, and twice more for the t-test's per-pixel terms at the
//! carried offset and at the minimum, both evaluated already. Every evaluation now keeps its
//! terms for the t-test (bit-identical), and Brent's method starts at the carried offset, whose
//! misfit is known (one evaluation fewer; over 200 random brackets 1 369 evaluations instead of
//! 1 543; the per-window depth RMSE of a 200-frame 1280×720 clip unchanged to 0.1 µm). A warm
//! pass's depth change from the warm start is computed once and gathered in parallel, as are
//! the offset search's pixels. The object mask's specks and holes are labelled by row runs
//! with union–find instead of a pixel flood fill ([`meb_pipeline::regions::label`], same labels), and
//! its per-pixel test runs by rows in parallel: object region 2.05 → 1.07 ms, photometric
//! stereo 7.2 → 6.2 ms. Loop of 100 warm frames, main 956dc70 and this code alternated, two
//! runs each: frame minimum 40.1 / 39.7 → **36.9 / 36.9 ms**, median 43.4 / 42.1 → **39.7 /
//! 41.3 ms**; warm reconstruction median 33.9 / 33.4 → 31.3 / 30.6 ms; warm offset search
//! minimum 5.6 → 4.5 ms. End to end, `meb video`'s writer spent most of its time in the kernel
//! copying each 3.7 MB depth array into fresh page-cache pages, which on these virtual
//! machines fault on the host (free page reporting): 50 such files took 1.2 s of CPU buffered
//! and 0.02 s written past the page cache ([`meb_core::io::direct`], `O_DIRECT`). On 2000
//! frames (a 200-frame clip repeated ten times; windows of 40, no `--save`), alternated: 9.7 /
//! 12.9 → **15.1 / 15.2 3-D frames/s**, system time 3.9 / 1.8 → 0.9 / 0.8 s, the writer's mean
//! 56 / 35 → 17 / 16 ms per window; with `--hop 8` 15.8 → 18.5 3-D frames/s.
//!
//! Session 38: profiled end to end (perf, frame pointers), the matched filter over the whole
//! 1280×720 frame was 8.6 % of the run's CPU while the turning ellipsoid fills a tenth of it, and
//! the cold first window took 0.41–0.54 s of a 3.4 s run. Once the timing carry settles, a window
//! is now decoded only around the object (the box of the previous window's lit pixels grown by
//! 32 px, [`meb_pipeline::video::focus`]) and reconstructed there; the decoder's pixel sample and the
//! motion test's sample lie on the whole frame's grid, so a region's fit and motion score are the
//! whole frame's (a region sampled on its own, denser grid kept the moving silhouette's pixels
//! and fitted one LED's shift 7 chips off in one window). A window with nothing to start from
//! starts from its own reconstruction binned 2×2 ([`meb_pipeline::reconstruct::ReconstructConfig`]'s
//! `coarse_start`): first window 0.41–0.54 → 0.23–0.30 s, its depth RMSE 0.734 → 0.706 mm. The
//! preview videos are encoded with x264's `ultrafast` preset. On 2000 frames (a 200-frame clip
//! repeated ten times, windows of 40, no `--save`), main ce1b9d1 and this code alternated:
//! 13.6 / 14.8 → **17.7 / 17.0 3-D frames/s**, user CPU 4.67 / 4.57 → 3.85 / 3.88 s; the matched
//! filter 8.6 → 2.6 % of the samples, motion detection 3.7 → 1.6 ms per window. With `--hop 8`
//! 8.7 → 10.5 3-D frames/s: 36 of the 246 windows straddle the clip's repeats, where the object
//! jumps back, and are redone (0.34 s each). Per-window RMSE of the 200-frame clip: 0.7064,
//! 0.7011, 0.5165, 0.5318, 0.5381 mm (before 0.7344, 0.7087, 0.5160, 0.5318, 0.5381).
//!
//! Session 39: per thread (perf), the reconstruction took 58 % of the CPU, decoding 19 %, FFmpeg
//! 9 %, the reader 7.5 % and the writer 6 %; the decoding stage's parallel loops queued in the
//! shared pool between the reconstruction's. Decoding now runs in a pool of its own with one
//! thread ([`meb_pipeline::video::process`]), which first needed a decode that does not depend on the
//! number of threads (its partial sums are merged in order; with one thread a cube clip of
//! `video_cli` decoded differently and was refused). A window decoded around the object keeps
//! its reconstruction in the region and pastes only its depth into the frame
//! ([`meb_pipeline::video::WindowReconstruction`]): 2.2 → 0.25 ms per window. On a continuous 2000-frame
//! clip of the turning ellipsoid (1280×720, windows of 40, no `--save`; main cb3b830 and this
//! code alternated six times, the first run of main after an idle spell at 11.4 left out):
//! **18.3 → 20.7 3-D frames/s** (means; medians 18.4 → 20.9), reconstruction 46.8 → 41.2 ms and
//! decoding 28.5 → 22.6 ms per window, user CPU 3.56 → 3.38 s; per-window depth RMSE against
//! the truth unchanged (median 0.677, mean 0.743, worst 1.195 mm over 50 windows). The 200-frame
//! clip repeated ten times: 15.2 / 16.2 → 17.6 / 18.0 / 19.1. With `--hop 8` on the continuous
//! clip (246 windows): **22.9 → 25.4 3-D frames/s**.
//!
//! Session 40: per-thread samples (`perf script`, 20 ms buckets) showed the two cores 81–83 %
//! busy in the steady state. Where they idled, the reconstruction was in a serial stretch while
//! decoding waited for it (its queue full), and the first 50 ms were half idle while FFmpeg's
//! two processes started (≈ 60 ms of CPU each, most of it dynamic linking of 215 libraries).
//! Six changes: each window's reconstruction runs inside a pool of its own, so its hundreds of
//! parallel loops are split by a worker instead of being injected from the pipeline's thread
//! (system CPU 0.80 → 0.58 s); the first window is decoded on that pool while it is idle; one
//! FFmpeg process writes both preview videos; a warm window of a whole-frame decode keeps its
//! region's results (11–12 ms of pasting less in each of the first three windows and every
//! tenth); the coarse start's binned passes stop once settled (the first window's reconstruction
//! 205–230 → 175–195 ms); and the shaded preview's normals come from the depths alone. On the
//! continuous 2000-frame clip (main 4b40081 and this code alternated, five pairs after a first
//! one left out): **20.3 → 21.9 3-D frames/s** (means; this machine ran main at 20.3 where
//! session 39 measured 20.7), the first 3-D frame reconstructed 0.34 → 0.28 s after the start,
//! steady reconstruction 41.9 → 39.0 ms per window; with `--hop 8`: 23.4 → 24.9 (two runs each,
//! 23.6/23.2 → 26.0/23.7). Per-window depth RMSE: median 0.675, mean 0.742, worst 1.195 mm (50 windows;
//! the first windows 0.7054, 0.7012, 0.5111 mm against 0.7064, 0.7011, 0.5165 mm before: the
//! coarse start's settled pass leaves a slightly better first depth).
//!
//! Session 41: the per-pixel solve of the near-field stages. The normal equations' inverse
//! comes from the symmetric adjugate with one reciprocal instead of nalgebra's nine divisions
//! after a separate determinant, the decisions are taken on G = ρn with ρ and n formed once,
//! the χ² limits are tabulated, and a Lambertian emitter's light vector needs no square root
//! (`model_misfit_at_one_offset` in the reconstruct bench 1.61 → 1.39 ms). On the continuous
//! 2000-frame clip, eight rounds alternated with main: 22.2 → 22.6 3-D frames/s (means; the
//! runs spread 18.6–24.2). The per-window depth RMSE against the truth is unchanged to 0.1 µm
//! (median 0.6755, mean 0.7416, worst 1.1949 mm over 50 windows). Of a run's wall time, all
//! but the first window's wait is reconstruction on the pipeline's thread (`wait_ms` 0.0 after
//! the first window); the first, cold window takes ≈ 0.2 s of it.
//!
//! Tried and not kept: reading, decoding and writing at nice 19, so that the reconstruction,
//! which bounds the rate, keeps both cores in its parallel loops and the other stages fill its
//! serial stretches. On an idle machine: 22.2 → 24.3 3-D frames/s (eight rounds), 29.6 with
//! `--hop 8` (28.0 before). But a thread cannot raise its priority again, and next to two busy
//! processes at normal priority the decoder starved: 11.2 3-D frames/s at nice 0, 6.2 at nice
//! 10, 0.9 at nice 19 (two runs each). A tool that becomes twelve times slower beside a build
//! is worse than one 9 % slower alone.
//!
//! Session 42, on a machine ≈ 1.7× slower than session 41's (main's 22.2 3-D frames/s measured
//! 7–13 on the same clip): the coarse start is a pyramid (a 1280×720 window starts from
//! 320×180 through one warm pass at 640×360; the first window's binned stages ≈ 150–230 → ≈ 70
//! ms, its whole reconstruction ≈ 340 → ≈ 270 ms, means of nineteen runs each), and each
//! window's truth is read by the decoding stage and scored in one parallel pass without an
//! error map. Throughput did not change measurably: 11.5 → 12.1 3-D frames/s over twelve
//! rounds alternated with main, 10.85 → 10.96 over seven more (means; the runs spread
//! 7.1–13.4). The per-window depth RMSE against the truth: median 0.6755 → 0.6837, mean 0.7416
//! → 0.7448, worst 1.1949 → 1.1953 mm (the first window's surface lies 0.39 mm from the cold
//! one's instead of 0.27 mm, and later windows start from it). The run is bound by the CPU as
//! a whole (≈ 87 % of both cores busy): reading the truth off the pipeline's thread shortened
//! its serial path by the read (≈ 3–4 ms per window, 8–9 ms with the files out of the page
//! cache), but the read now meets the reconstruction's parallel loops (median reconstruction
//! per window ≈ 73 → ≈ 78 ms).
//!
//! Session 43 (callgrind instruction counts: the wall clock of this machine drifted by 1.5×
//! within the session). Main's whole 2000-frame run: 29.8 G instructions, 595 M per window;
//! reconstruction 60 % (integration 31 %, photometric stereo 15 %, depth-offset search 12 %),
//! decoding stage 26 % (the decoder 19.5 %, of it the LED-count probe 9.6 %; the focus's lit
//! test 4.7 %), the scores against the truth 5.8 %, the writer 5.7 %. Three costs proportional
//! to the whole frame rather than the object were cut, results unchanged (same per-window
//! RMSE to 10⁻⁴ mm): the score reads rows as slices instead of through `ArrayView1`
//! iterators, the lit test and the object mask share a vectorised brightest-LED row kernel
//! (`LedImages::brightest_in_row`), and the two output pictures are drawn in the object's box.
//! The first 480 frames (12 windows): 9.10 G → 8.33 G instructions (−8.4 %): score 281 → 97 M,
//! lit test 568 → 334 M (171 M of it the speck removal), pictures 360 → 223 M. Five rounds
//! alternated with main on the whole clip: 8.9 → 9.8 3-D frames/s, CPU 9.8 → 9.2 s per run
//! (means, on the slow machine). Not kept: skipping the LED-count probe in region windows
//! saved only 0.6 % — the probe's 5-LED fit (300 M over the run) had seeded the 4-LED fit, and
//! the fit without it cost 241 M.
//!
//! Session 44 (callgrind, the whole 2000-frame clip with `--ground-truth`): 27.10 G → 24.35 G
//! instructions (−10 %), 542 → 487 M per window; every depth file byte-identical, so the
//! per-window RMSE is unchanged (median 0.6837, mean 0.7448, worst 1.1953 mm). The timing
//! carry also carries the rolling-shutter line delay, a property of the sensor like the
//! exposure (0 for a global shutter), so a carried window's timing fit skips the band-wise and
//! row-wise rolling-shutter test: the LED-count check's fit 505 → 252 M on the first 480
//! frames (12 windows, three of them fitted freely), 8.28 → 8.04 G in all. The check's fit of
//! as many LEDs as are decoded now serves the decode with its quality, which was measured a
//! second time on the same sample (decoding 4.01 → 3.60 G over the clip). Small regions are
//! cleared by their runs instead of through a label per pixel (`regions::remove_small` 204 →
//! 55 M on 480 frames), the two pictures come from one sampling of the depth, and the direct
//! writes copy each block once instead of zeroing it first (7.816 → 7.770 G on 480 frames).
//! Where the instructions go now (inclusive; rayon's workers blur the split): integration
//! 29 %, photometric stereo 11 %, depth-offset search 9 %, the decoding stage 19 % (matched
//! filter 6.1 %, timing fit and its quality 4.7 %, pixel sample 3.4 %), writer 3.7 %, the first
//! window's coarse start 2.5 %, lit test 1.9 %, motion 1.7 %, scores 1.3 %. Wall clock without
//! the truth, eight rounds alternated with main (plus only the pictures change), the machine's
//! speed drifting by 1.4× across them: 12.1 → 12.8 3-D frames/s (means), user CPU 6.6 → 6.1 s;
//! with `--hop 8`, two rounds: 12.4 → 13.6 3-D frames/s, user CPU 32.3 → 29.1 s.
//! Session 45 (callgrind, the first 480 frames with `--ground-truth`): 7.769 → 7.571 G
//! instructions (−2.5 %), every depth file byte-identical. The albedo of two-LED pixels is
//! known at the same pixels as the slopes (all measured pixels have a positive albedo), so it
//! fills in with them as a third channel over one pyramid and stencil instead of building
//! its own. Wall clock without the truth, five rounds alternated: 15.4–16.0 3-D frames/s
//! either way while the machine was steady (reconstruction median 54–57 ms a window,
//! integration 29–31 ms); the gain is below this machine's noise. Updating each colour of the
//! fill's red–black sweeps in parallel (tried, not kept) did not shorten the reconstruction
//! (62 against 60 ms a window, the mean of four rounds' medians): the whole run keeps only
//! 1.45 of the two cores busy (user CPU 4.7 s in 3.3 s), and the reconstruction's second
//! worker competes with the decoding and writing threads.
//!
//! Session 46 (`perf record` of the whole 2000-frame run, samples per thread, FFmpeg
//! included): 6.6 s of CPU in 3.8 s under `perf`; without it (`time`, children included)
//! user + system 5.5–5.7 s in 3.5–3.6 s, 1.6 of the two cores (session 45's 1.45 counted user
//! time only). Per window: reconstruction pool 78 ms, decoding 25 ms (the matched filter
//! 9), FFmpeg 12 ms, the reader 10 ms (the kernel's copy out of the page cache), the writer
//! 6 ms. 25 3-D frames/s needs all of it below 80 ms, so every stage's CPU counts, not only
//! the reconstruction's. Changes: the two-LED projection clamps its angle without atan2, sin
//! and cos; the previews reach FFmpeg as one yuv420p frame converted here (FFmpeg's samples
//! 431–506 → 299–312 over the run, the writer's 214–257 → 279–364: about 2.4 ms of CPU a
//! window less, and half the bytes through the pipe); the warm offset search stops at the
//! tolerance divided by the carried-offset gain (11 % fewer misfit evaluations) and on 2 500
//! pixels instead of 5 000 (`WARM_MISFIT_PIXELS`; 5.4 → 2.8 ms a window). Callgrind, the first
//! 480 frames with `--ground-truth`: 7.560 G (before) → 7.485 G (projection) → 7.492 G (with
//! the tolerance and the 123 M of the yuv420p conversion that FFmpeg did before) → 7.180 G
//! (2 500 pixels): −5.0 %, FFmpeg's share not counted. The first three left every window's
//! RMSE within 0.1 µm; the fewer pixels move single windows by −0.04 to +0.07 mm, without a
//! trend (whole clip median 0.684 → 0.673, mean 0.745 → 0.751, worst 1.195 → 1.194 mm). Wall
//! clock, three rounds alternated before the 2 500 pixels: 15.1–15.3 → 15.4–15.8 3-D frames/s,
//! user + system CPU (FFmpeg included) 5.55–5.68 → 5.44–5.54 s; with them, while disk waits
//! slowed both: 9.5–14.6 → 13.8–14.1 3-D frames/s. Both within this machine's noise.
//! `--hop 8`: 17.7 3-D frames/s (246 windows, RMSE median 0.732, worst 1.614 mm); `--bin 2`:
//! 25.7–26.7 3-D frames/s.
//!
//! Session 49, on a machine about 1.8× faster than sessions 46–48's (the same code measured
//! 13.7–13.9 3-D frames/s in session 47): `meb video` on the 2000-frame clip without the truth,
//! five runs in a row: 16.5 (the first, reading the clip from disk: 2.5 s of system time),
//! 25.1, 25.9, 27.0 and 26.8 3-D frames/s (1.91–2.05 s wall, user 2.4–2.5 s, system
//! 0.64–0.75 s, peak RSS 243–265 MB); with the truth every 20 frames 21.9 / 24.2. Per window
//! (means): reconstruction 34.4–37.2 ms (photometric stereo 10.4, integration 20.1, offset
//! search 2.1), decoding 13–15 ms, writing 11–14 ms. `perf` by thread (one run): the
//! reconstruction pool's two workers 39 % and 20 % of the samples, decoding 16 %, the reader
//! 13 % (the kernel's copy out of the page cache 9.7 %), the writer 5.7 %, FFmpeg 5.1 %: the
//! run keeps 1.6 of the two cores busy. Criterion: `window_warm` 41.0 ms, `frame_warm` 50.5 ms
//! (52.6 in the run before), of which 13 ms paste the region's arrays into the frame (the
//! stage "full frame from the region, warm", which `meb video` leaves to its writer);
//! `frame_warm_region`, the 3-D frame as `meb video` runs it (decoded and reconstructed in
//! the 514×311 region around the object, inside a pool of both cores), **34.1 ms** (33.8–34.4)
//! and 36.8 ms (36.6–37.0) in two runs; called from outside a pool, as at first, 40.9 ms
//! (40.2–41.6). `decode_region` 3.9 ms; `frame_warm_bin2` 27.8 ms, `window_warm_bin2` 11.8 ms.
//! With the truth every 20 frames: 24.9 3-D frames/s, per-window depth RMSE median 0.680,
//! mean 0.750, best 0.419, worst 1.194 mm (the thesis: 4.8–11 mm on 21 of 200 positions);
//! `--hop 8` 29.5 3-D frames/s (246 windows, median 0.725, worst 1.626 mm). The first run
//! after a build read the clip from disk (15.0 and 16.5 3-D frames/s): the build's files had
//! pushed the 1.8 GB clip out of the page cache.
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use meb_core::capture::binning::Binning;
use meb_core::capture::memory::MemorySource;
use meb_core::capture::{Frame, FrameFormat, FrameSource, Samples};
use meb_core::rig::Rig;
use meb_pipeline::demod::DecodeConfig;
use meb_pipeline::demod::decode_frames;
use meb_pipeline::reconstruct::{WarmStart, from_decoded, from_decoded_region, from_decoded_warm};
use meb_pipeline::video::{VideoConfig, process};
use std::hint::black_box;

mod common;

/// 80 frames (two thesis windows) of the turning ellipsoid on the thesis-dynamic rig.
fn clip() -> Option<(Rig, FrameFormat, Vec<Frame>)> {
    let rig = Rig::preset("thesis-dynamic")?;
    let (format, frames) = common::turning_ellipsoid(&rig, 80)?;
    Some((rig, format, frames))
}

fn bench(c: &mut Criterion) {
    // As `meb` does first thing: windows reuse their arrays' pages.
    // SAFETY: criterion calls this on its main thread before any other thread starts (the
    // clip is simulated below).
    unsafe { meb_core::memory::keep_freed_memory() };
    let Some((rig, format, frames)) = clip() else {
        eprintln!("cannot simulate the clip");
        return;
    };
    let config = VideoConfig::thesis(rig.leds.len());
    let decoded_frames: Vec<Samples> = frames[4..36].iter().map(|f| f.samples.clone()).collect();
    let Ok(decoded) = decode_frames(&decoded_frames, &format, &config.decode) else {
        eprintln!("the clip does not decode");
        return;
    };
    let carried = DecodeConfig {
        rate_ratio: Some(decoded.report.rate_ratio),
        exposure: Some(decoded.report.exposure),
        ..config.decode.clone()
    };
    let second_frames: Vec<Samples> = frames[44..76].iter().map(|f| f.samples.clone()).collect();
    let Ok(second) = decode_frames(&second_frames, &format, &carried) else {
        eprintln!("the second window does not decode");
        return;
    };
    // The per-stage profile of one reconstruction, cold and warm, printed once (criterion times
    // the whole).
    let Ok(first) = from_decoded(&decoded, &rig, None, &config.reconstruct) else {
        eprintln!("the first window does not reconstruct");
        return;
    };
    let warm = WarmStart::of(&first);
    let profile = |name: &str, reconstruction: &meb_pipeline::reconstruct::Reconstruction| {
        eprintln!("{name}: {:?}", reconstruction.start);
        for stage in &reconstruction.timings {
            eprintln!("stage {:>8.1} ms  {}", stage.ms, stage.stage);
        }
    };
    profile("first window, cold", &first);
    let warm_second = from_decoded_warm(&second, &rig, None, &config.reconstruct, Some(&warm));
    let cold_second = from_decoded(&second, &rig, None, &config.reconstruct);
    if let (Ok(warm_second), Ok(cold_second)) = (&warm_second, &cold_second) {
        profile("second window, warm", warm_second);
        profile("second window, cold", cold_second);
        // How far the warm result lies from the cold one (the accuracy is 0.5–1 mm).
        let (a, b) = (
            &warm_second.integration.depth.depth_mm,
            &cold_second.integration.depth.depth_mm,
        );
        let mut diff: Vec<f32> = a
            .iter()
            .zip(b)
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| (x - y).abs())
            .collect();
        diff.sort_by(f32::total_cmp);
        if !diff.is_empty() {
            let rms = (diff.iter().map(|d| d * d).sum::<f32>() / diff.len() as f32).sqrt();
            eprintln!(
                "warm vs cold, second window: median {:.3} mm, 90 % {:.3} mm, RMS {rms:.3} mm over {} pixels",
                diff[diff.len() / 2],
                diff[diff.len() * 9 / 10],
                diff.len()
            );
        }
    }
    let mut group = c.benchmark_group("video_1280x720");
    group.sample_size(10);
    group.bench_function("window", |b| {
        b.iter_batched(
            || -> Box<dyn FrameSource> {
                Box::new(
                    MemorySource::new(format.clone(), frames[..40].to_vec()).expect("frames fit"),
                )
            },
            |source| black_box(process(source, &rig, &config, None, &mut |_| Ok(())).ok()),
            BatchSize::PerIteration,
        )
    });
    group.bench_function("decode", |b| {
        b.iter(|| black_box(decode_frames(&decoded_frames, &format, &config.decode).ok()))
    });
    group.bench_function("decode_carried_timing", |b| {
        b.iter(|| black_box(decode_frames(&decoded_frames, &format, &carried).ok()))
    });
    // A decoder's region of interest around the object (`meb decode --roi`, `meb video` with
    // a region): the frames are cut to it first.
    let around_object = DecodeConfig {
        roi: Some(meb_pipeline::demod::Roi {
            x: 383,
            y: 180,
            width: 514,
            height: 311,
        }),
        ..carried.clone()
    };
    group.bench_function("decode_region", |b| {
        b.iter(|| black_box(decode_frames(&second_frames, &format, &around_object).ok()))
    });
    group.bench_function("reconstruct", |b| {
        b.iter(|| black_box(from_decoded(&decoded, &rig, None, &config.reconstruct).ok()))
    });
    group.bench_function("window_warm", |b| {
        b.iter(|| {
            black_box(from_decoded_warm(&second, &rig, None, &config.reconstruct, Some(&warm)).ok())
        })
    });
    // The one 3-D frame: decode (carried timing) and warm reconstruction in series.
    group.bench_function("frame_warm", |b| {
        b.iter(|| {
            let decoded = decode_frames(&second_frames, &format, &carried).ok()?;
            black_box(
                from_decoded_warm(&decoded, &rig, None, &config.reconstruct, Some(&warm)).ok(),
            )
        })
    });
    // The same 3-D frame as `meb video` runs it after its first window: decoded in the region
    // around the object and reconstructed there, the result kept in the region (the writer
    // pastes it into the frame's files on its own thread), inside a pool of every core (from
    // outside a pool each of a window's parallel loops would be injected into the global pool
    // with the caller asleep).
    let Ok(pool) = rayon::ThreadPoolBuilder::new().build() else {
        eprintln!("cannot start a thread pool");
        return;
    };
    group.bench_function("frame_warm_region", |b| {
        b.iter(|| {
            pool.install(|| {
                let decoded = decode_frames(&second_frames, &format, &around_object).ok()?;
                let roi = around_object.roi?;
                black_box(
                    from_decoded_region(&decoded, roi, &rig, &config.reconstruct, Some(&warm)).ok(),
                )
            })
        })
    });
    binned(&mut group, &rig, &format, &frames, &config);
    group.finish();
}

/// The same window with every frame binned 2×2 (`meb video --bin 2`: 640×360 3-D frames):
/// `bin_frames` bins the 40 frames of a window (the reader thread's extra work),
/// `decode_bin2` decodes 32 binned frames with carried timing, `window_warm_bin2` reconstructs
/// the binned second window warm-started from the binned first, and `window_bin2` is the whole
/// pipeline over one window as `window` is.
fn binned(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    rig: &Rig,
    format: &FrameFormat,
    frames: &[Frame],
    config: &VideoConfig,
) {
    let Ok(binning) = Binning::new(format, 2) else {
        eprintln!("cannot bin the clip");
        return;
    };
    let bin = |f: &Frame| {
        let mut out = Samples::U8(Vec::new());
        binning.bin(&f.samples, f.index, &mut out).map(|_| out)
    };
    let Ok(binned) = frames.iter().map(bin).collect::<Result<Vec<Samples>, _>>() else {
        eprintln!("cannot bin the clip");
        return;
    };
    let (binned_rig, binned_format) = (rig.binned(2), binning.format().clone());
    let Ok(first) = decode_frames(&binned[4..36], &binned_format, &config.decode) else {
        eprintln!("the binned clip does not decode");
        return;
    };
    let carried = DecodeConfig {
        rate_ratio: Some(first.report.rate_ratio),
        exposure: Some(first.report.exposure),
        ..config.decode.clone()
    };
    let (Ok(second), Ok(first)) = (
        decode_frames(&binned[44..76], &binned_format, &carried),
        from_decoded(&first, &binned_rig, None, &config.reconstruct),
    ) else {
        eprintln!("the binned clip does not reconstruct");
        return;
    };
    let warm = WarmStart::of(&first);
    if let Ok(warm_second) =
        from_decoded_warm(&second, &binned_rig, None, &config.reconstruct, Some(&warm))
    {
        eprintln!("second window binned 2x2, warm: {:?}", warm_second.start);
        for stage in &warm_second.timings {
            eprintln!("stage {:>8.1} ms  {}", stage.ms, stage.stage);
        }
    }
    group.bench_function("bin_frames", |b| {
        b.iter(|| black_box(frames[..40].iter().map(bin).count()))
    });
    group.bench_function("decode_bin2", |b| {
        b.iter(|| black_box(decode_frames(&binned[4..36], &binned_format, &carried).ok()))
    });
    group.bench_function("frame_warm_bin2", |b| {
        b.iter(|| {
            let binned_frames = frames[44..76]
                .iter()
                .map(bin)
                .collect::<Result<Vec<_>, _>>();
            let decoded = decode_frames(&binned_frames.ok()?, &binned_format, &carried).ok()?;
            black_box(
                from_decoded_warm(
                    &decoded,
                    &binned_rig,
                    None,
                    &config.reconstruct,
                    Some(&warm),
                )
                .ok(),
            )
        })
    });
    group.bench_function("window_warm_bin2", |b| {
        b.iter(|| {
            black_box(
                from_decoded_warm(&second, &binned_rig, None, &config.reconstruct, Some(&warm))
                    .ok(),
            )
        })
    });
    let binned_config = VideoConfig {
        bin: 2,
        ..config.clone()
    };
    group.bench_function("window_bin2", |b| {
        b.iter_batched(
            || -> Box<dyn FrameSource> {
                Box::new(
                    MemorySource::new(format.clone(), frames[..40].to_vec()).expect("frames fit"),
                )
            },
            |source| black_box(process(source, rig, &binned_config, None, &mut |_| Ok(())).ok()),
            BatchSize::PerIteration,
        )
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
