//! Scheduling priority of `meb video`'s background stages.
//!
//! The reconstruction bounds the pipeline's rate: per window it needs about twice the CPU of
//! decoding and more than reading, writing and FFmpeg together, and it alternates parallel
//! loops on every core with serial stretches on one. The other stages wait on their bounded
//! queues most of the time; at the reconstruction's priority they still took cores from its
//! parallel loops while, in its serial stretches, a core idled (the cores were 81–85 % busy).
//! At the lowest priority (nice 19) they run where the reconstruction leaves a core free: in its
//! serial stretches and while it waits for them. Nothing waits longer than before on a stage it
//! needs, since a stage whose output the reconstruction waits for has the cores to itself.
//!
//! On Linux the nice value belongs to a thread, so lowering it leaves the rest of the process
//! (the reconstruction's pool, the pipeline's own thread) where it was. Elsewhere this is a
//! no-op: there it would lower the whole process.

/// The nice value of the background stages (the lowest priority of normal scheduling).
pub const BACKGROUND_NICE: i32 = 19;

/// Lowers the calling thread to [`BACKGROUND_NICE`] (module docs). A thread may always lower
/// its own priority, so this cannot fail short of a kernel refusing the call; a stage left at
/// normal priority only runs slower, so the error is ignored.
pub fn lower_this_thread() {
    #[cfg(target_os = "linux")]
    {
        let tid = rustix::thread::gettid();
        let _ = rustix::process::setpriority_process(Some(tid), BACKGROUND_NICE);
    }
}

/// The calling thread's nice value (`None` where it is not per thread, or unknown).
pub fn this_thread_nice() -> Option<i32> {
    #[cfg(target_os = "linux")]
    {
        rustix::process::getpriority_process(Some(rustix::thread::gettid())).ok()
    }
    #[cfg(not(target_os = "linux"))]
    {
        None
    }
}

/// The nice values of this process's threads whose name starts with `name` (Linux names are cut
/// to 15 bytes), from `/proc/self/task`.
#[cfg(all(test, target_os = "linux"))]
pub(crate) fn nice_of_threads(name: &str) -> Vec<i32> {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return Vec::new();
    };
    tasks
        .flatten()
        .filter_map(|task| {
            let comm = std::fs::read_to_string(task.path().join("comm")).ok()?;
            if !name.starts_with(comm.trim_end()) && !comm.starts_with(name) {
                return None;
            }
            // Field 19 of stat is the nice value; fields 3 on follow the name's ')'.
            let stat = std::fs::read_to_string(task.path().join("stat")).ok()?;
            let after_name = &stat[stat.rfind(')')? + 1..];
            after_name.split_whitespace().nth(16)?.parse().ok()
        })
        .collect()
}

/// Waits up to two seconds for the threads named `name` to exist and all run at
/// [`BACKGROUND_NICE`]; their nice values.
#[cfg(all(test, target_os = "linux"))]
pub(crate) fn wait_for_background_threads(name: &str) -> Vec<i32> {
    let started = std::time::Instant::now();
    loop {
        let nice = nice_of_threads(name);
        let lowered = !nice.is_empty() && nice.iter().all(|&n| n == BACKGROUND_NICE);
        if lowered || started.elapsed() > std::time::Duration::from_secs(2) {
            return nice;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    #[test]
    fn a_lowered_thread_leaves_the_rest_of_the_process_at_its_priority() {
        let before = this_thread_nice();
        assert!(before.is_some());
        let lowered = std::thread::Builder::new()
            .name("meb-test-lowered".into())
            .spawn(|| {
                lower_this_thread();
                this_thread_nice()
            })
            .unwrap()
            .join()
            .unwrap();
        assert_eq!(lowered, Some(BACKGROUND_NICE));
        assert_eq!(this_thread_nice(), before);
    }

    #[test]
    fn thread_nice_values_are_read_from_proc() {
        let (ready, wait) = std::sync::mpsc::channel();
        let (done, finish) = std::sync::mpsc::channel::<()>();
        let handle = std::thread::Builder::new()
            .name("meb-test-proc-nice".into())
            .spawn(move || {
                lower_this_thread();
                ready.send(()).unwrap();
                let _ = finish.recv();
            })
            .unwrap();
        wait.recv().unwrap();
        assert_eq!(nice_of_threads("meb-test-proc-nice"), vec![BACKGROUND_NICE]);
        assert!(nice_of_threads("meb-test-no-such-thread").is_empty());
        done.send(()).unwrap();
        handle.join().unwrap();
    }
}
