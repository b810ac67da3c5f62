//! [`meb_core::memory::keep_freed_memory`] in a process of its own: mallopt(3) is MT-Unsafe (it
//! changes settings that other threads' allocations read), so it runs as the only test of this
//! binary, with no other test thread allocating meanwhile, as `meb` calls it before it starts
//! any thread.

#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[test]
fn glibc_takes_the_settings() {
    // SAFETY: the only test of this binary: no other thread allocates meanwhile.
    assert!(unsafe { meb_core::memory::keep_freed_memory() });
}
