//! How the process's allocator keeps freed memory.
//!
//! `meb video` allocates and frees the same large arrays for every window: the LED images, the
//! full-frame results (≈ 45 MB per window at 1280×720 when a window's region results were all
//! pasted into the frame; now its depth alone), the next window's frames. glibc returns a freed
//! block of more than its mmap threshold to the kernel at once, and trims a thread arena's top
//! once more than its trim threshold is free, so each window faulted its arrays' pages in
//! afresh and the kernel zeroed them: 566 000 page faults and a third of the CPU time in the
//! kernel over a 2000-frame 1280×720 clip. Keeping freed memory for reuse
//! ([`keep_freed_memory`]) lets later windows reuse the pages (126 000 page faults over that
//! clip) at the price of a higher peak resident memory, since freed pages stay in the process
//! (305 → 372 MB at 1280×720, 107 → 132 MB binned 2×2).

/// Largest block glibc serves from its arenas (its ceiling for `M_MMAP_THRESHOLD` on 64-bit
/// systems); larger ones are mapped and unmapped on their own.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MMAP_THRESHOLD_BYTES: i32 = 32 << 20;

/// Keeps freed memory in the process for reuse instead of handing it back to the kernel
/// (glibc: blocks up to 32 MB from the arenas, arenas never trimmed); without effect on other
/// C libraries. Returns whether the allocator took the settings.
///
/// # Safety
///
/// mallopt(3) is MT-Unsafe: it changes settings that every allocation reads. Call this first
/// thing in `main`, before any other thread starts.
pub unsafe fn keep_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        use nix::libc::{M_MMAP_THRESHOLD, M_TRIM_THRESHOLD, mallopt};
        // SAFETY: both values are in the ranges mallopt(3) documents, and no other thread
        // allocates meanwhile (this function's contract).
        unsafe {
            mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
                && mallopt(M_TRIM_THRESHOLD, i32::MAX) == 1
        }
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}
