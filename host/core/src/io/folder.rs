//! Atomic output folders: every `meb` command that writes a folder builds it in a temporary
//! folder beside the destination and replaces the destination whole, in one rename, when
//! everything is written and on disk.
//!
//! The life of an [`OutputFolder`]:
//! 1. [`OutputFolder::create`] checks the destination: missing, empty, or an earlier output of
//!    the same command (recognised by its [`MARKER`] file) may be replaced; anything else only
//!    with [`Replace::Anything`] (the CLI's `--force`). It removes stale temporary folders of
//!    dead processes, then creates `.NAME.meb-partial-PID-RANDOM` beside the destination and
//!    holds an exclusive lock on a file inside it for as long as the folder is being written.
//! 2. The caller writes into [`OutputFolder::path`].
//! 3. [`OutputFolder::commit`] writes the marker, fsyncs every file and folder of the tree,
//!    and moves it into place: `renameat2(RENAME_NOREPLACE)` when the destination is missing,
//!    `renameat2(RENAME_EXCHANGE)` when it exists (Linux ≥ 3.15; the two folders swap
//!    atomically and the old one, now under the temporary name, is deleted), then fsyncs the
//!    parent folder. Two runs into one destination therefore each leave a whole folder, the
//!    later one winning; a reader never sees a mix.
//! 4. Dropping an uncommitted folder deletes it; [`remove_temporaries_on_signal`] does the same
//!    for SIGINT, SIGTERM and SIGHUP, leaving the previous output untouched. A process killed
//!    outright leaves its temporary folder behind, unlocked: the next run into the same
//!    destination deletes it.
//!
//! One exception, for a command that records a live stream (`meb video -`): while it holds an
//! [`InterruptHook`] from [`on_first_interrupt`], the first SIGINT or SIGTERM does not delete
//! anything; the signal thread calls the hook instead (which ends the stream, e.g. through a
//! [`crate::stop::StopSignal`]) and the command goes on to finish and commit its folder as after
//! a natural end. A second SIGINT or SIGTERM, or any SIGHUP, deletes the temporary folders and
//! ends the process as before; so does the first interrupt once the hook is dropped (the stream
//! has ended). The hook is the one place that decides: no stage polls for signals.

use super::FilesError;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// Name of the marker file that identifies a folder as a `meb` command's output.
pub const MARKER: &str = ".meb-output.json";
/// Name of the lock file inside a temporary folder while it is being written.
const LOCK: &str = ".meb-writing.lock";
/// Name of the lock file before it is locked (only [`LOCK`] is ever probed by other runs).
const LOCK_STARTING: &str = ".meb-writing.lock.starting";
/// Infix of temporary folder names: `.NAME.meb-partial-PID-RANDOM`.
const PARTIAL: &str = ".meb-partial-";

/// What [`OutputFolder::create`] may replace.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replace {
    /// A missing or empty folder, or an earlier output of the same command.
    EarlierOutput,
    /// Any folder (never a file).
    Anything,
}

/// Contents of the [`MARKER`] file.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct OutputMarker {
    /// The command that wrote the folder, e.g. `decode` or `simulate dataset`.
    pub command: String,
    /// Version of the `meb` that wrote it.
    pub version: String,
}

/// A folder being written that replaces its destination atomically on [`Self::commit`].
#[derive(Debug)]
pub struct OutputFolder {
    target: PathBuf,
    temp: PathBuf,
    command: String,
    replace: Replace,
    lock: Option<File>,
    committed: bool,
}

/// Temporary folders of this process that a signal must delete.
static PENDING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn pending() -> MutexGuard<'static, Vec<PathBuf>> {
    PENDING
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// What is at the destination.
#[derive(Debug, PartialEq, Eq)]
enum Existing {
    Missing,
    Empty,
    Output(String),
    Foreign,
    NotAFolder,
}

fn inspect(target: &Path) -> Result<Existing, FilesError> {
    let meta = match std::fs::metadata(target) {
        Ok(meta) => meta,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Existing::Missing),
        Err(source) => return Err(FilesError::read(target, source)),
    };
    if !meta.is_dir() {
        return Ok(Existing::NotAFolder);
    }
    let mut entries = std::fs::read_dir(target).map_err(|e| FilesError::read(target, e))?;
    if entries.next().is_none() {
        return Ok(Existing::Empty);
    }
    let marker = std::fs::read_to_string(target.join(MARKER))
        .ok()
        .and_then(|text| serde_json::from_str::<OutputMarker>(&text).ok());
    Ok(marker.map_or(Existing::Foreign, |m| Existing::Output(m.command)))
}

impl OutputFolder {
    /// Starts an output of `command` (e.g. `decode`) that will replace `target`; refuses a
    /// destination that `replace` does not allow before any work is done.
    pub fn create(target: &Path, command: &str, replace: Replace) -> Result<Self, FilesError> {
        let target = std::path::absolute(target).map_err(|e| FilesError::read(target, e))?;
        let (Some(parent), Some(name)) = (target.parent(), target.file_name()) else {
            return Err(FilesError::BadOutputPath { path: target });
        };
        let name = name.to_string_lossy().into_owned();
        check_replaceable(&target, command, replace)?;
        std::fs::create_dir_all(parent).map_err(|e| FilesError::write(parent, e))?;
        remove_stale_temporaries(parent, &name);
        let mut pending = pending();
        let temp = tempfile::Builder::new()
            .prefix(&format!(".{name}{PARTIAL}{}-", std::process::id()))
            .tempdir_in(parent)
            .map_err(|e| FilesError::write(parent, e))?
            .keep();
        pending.push(temp.clone());
        drop(pending);
        let mut folder = Self {
            target,
            temp,
            command: command.to_string(),
            replace,
            lock: None,
            committed: false,
        };
        // The lock file is locked under a private name and only then renamed to LOCK: a
        // concurrent run that looks for stale folders must never find it unlocked (it would
        // take this folder for a dead writer's and delete it, or hold the lock while this one
        // tries to take it).
        let (unlocked, lock_path) = (folder.temp.join(LOCK_STARTING), folder.temp.join(LOCK));
        let lock = File::create(&unlocked).map_err(|e| FilesError::write(&unlocked, e))?;
        lock.try_lock().map_err(|e| {
            let source = match e {
                std::fs::TryLockError::Error(e) => e,
                std::fs::TryLockError::WouldBlock => std::io::ErrorKind::WouldBlock.into(),
            };
            FilesError::write(&unlocked, source)
        })?;
        std::fs::rename(&unlocked, &lock_path).map_err(|e| FilesError::write(&lock_path, e))?;
        folder.lock = Some(lock);
        Ok(folder)
    }

    /// The folder to write into (the temporary one).
    pub fn path(&self) -> &Path {
        &self.temp
    }

    /// The destination.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Moves the finished folder to the destination (module docs) and returns its path.
    pub fn commit(mut self) -> Result<PathBuf, FilesError> {
        std::fs::remove_file(self.temp.join(LOCK)).map_err(|e| FilesError::write(&self.temp, e))?;
        let marker = OutputMarker {
            command: self.command.clone(),
            version: env!("CARGO_PKG_VERSION").to_string(),
        };
        let marker_path = self.temp.join(MARKER);
        let text = serde_json::to_vec_pretty(&marker).map_err(|e| FilesError::Encode {
            path: marker_path.clone(),
            source: Box::new(e),
        })?;
        std::fs::write(&marker_path, text).map_err(|e| FilesError::write(&marker_path, e))?;
        sync_tree(&self.temp)?;
        // Signals wait until the folder is in place (or this fails), so they never delete a
        // folder that is half renamed.
        let mut pending = pending();
        self.move_into_place()?;
        pending.retain(|p| p != &self.temp);
        self.committed = true;
        drop(pending);
        if let Some(parent) = self.target.parent() {
            sync_path(parent)?;
        }
        Ok(self.target.clone())
    }

    fn move_into_place(&self) -> Result<(), FilesError> {
        // A concurrent run may create the destination between the check and the rename: then
        // the no-replace rename fails and the next round swaps instead.
        for _ in 0..8 {
            match check_replaceable(&self.target, &self.command, self.replace)? {
                Existing::Missing => match rename_no_replace(&self.temp, &self.target) {
                    Ok(()) => return Ok(()),
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                    Err(e) => return Err(FilesError::write(&self.target, e)),
                },
                _ => {
                    exchange(&self.temp, &self.target)
                        .map_err(|e| FilesError::write(&self.target, e))?;
                    // The temporary name now holds the previous output.
                    return std::fs::remove_dir_all(&self.temp)
                        .map_err(|e| FilesError::write(&self.temp, e));
                }
            }
        }
        Err(FilesError::write(
            &self.target,
            std::io::Error::other("the destination keeps changing under concurrent runs"),
        ))
    }
}

impl Drop for OutputFolder {
    fn drop(&mut self) {
        if !self.committed {
            let mut pending = pending();
            let _ = std::fs::remove_dir_all(&self.temp);
            pending.retain(|p| p != &self.temp);
        }
    }
}

/// What is at `target`, or an error when `replace` does not allow replacing it.
fn check_replaceable(
    target: &Path,
    command: &str,
    replace: Replace,
) -> Result<Existing, FilesError> {
    let existing = inspect(target)?;
    match (&existing, replace) {
        (Existing::NotAFolder, _) => Err(FilesError::OutputIsAFile {
            path: target.to_path_buf(),
        }),
        (Existing::Output(c), Replace::EarlierOutput) if c != command => {
            Err(FilesError::OutputNotEmpty {
                path: target.to_path_buf(),
                command: command.to_string(),
                found: Some(c.clone()),
            })
        }
        (Existing::Foreign, Replace::EarlierOutput) => Err(FilesError::OutputNotEmpty {
            path: target.to_path_buf(),
            command: command.to_string(),
            found: None,
        }),
        _ => Ok(existing),
    }
}

/// Deletes `.NAME.meb-partial-*` folders in `parent` whose writer is gone (its lock is free,
/// or it never took one and its process has exited), and legacy `.NAME.partial-PID` folders
/// of exited processes. Failures are ignored: a stale folder is litter, not an error.
fn remove_stale_temporaries(parent: &Path, name: &str) {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    let current = format!(".{name}{PARTIAL}");
    let legacy = format!(".{name}.partial-");
    for entry in entries.flatten() {
        let file_name = entry.file_name().to_string_lossy().into_owned();
        let path = entry.path();
        let stale = if let Some(rest) = file_name.strip_prefix(&current) {
            match File::open(path.join(LOCK)) {
                Ok(lock) => lock.try_lock().is_ok(),
                // No lock file: being created, or committing. Trust the process id.
                Err(_) => pid_prefix(rest).is_some_and(|pid| !process_alive(pid)),
            }
        } else if let Some(rest) = file_name.strip_prefix(&legacy) {
            rest.parse().is_ok_and(|pid| !process_alive(pid))
        } else {
            false
        };
        if stale && path.is_dir() {
            let _ = std::fs::remove_dir_all(&path);
        }
    }
}

/// The process id at the start of `PID-RANDOM`.
fn pid_prefix(rest: &str) -> Option<u32> {
    rest.split('-').next()?.parse().ok()
}

/// Whether a process with this id exists.
fn process_alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    #[cfg(unix)]
    {
        match i32::try_from(pid) {
            Ok(pid) => !matches!(
                nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), None),
                Err(nix::errno::Errno::ESRCH)
            ),
            Err(_) => false,
        }
    }
    #[cfg(not(unix))]
    {
        true
    }
}

/// fsyncs every file and folder below `dir`, and `dir` itself.
fn sync_tree(dir: &Path) -> Result<(), FilesError> {
    let entries = std::fs::read_dir(dir).map_err(|e| FilesError::read(dir, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| FilesError::read(dir, e))?;
        let path = entry.path();
        let kind = entry.file_type().map_err(|e| FilesError::read(&path, e))?;
        if kind.is_dir() {
            sync_tree(&path)?;
        } else if kind.is_file() {
            sync_path(&path)?;
        }
    }
    sync_path(dir)
}

/// fsyncs one file or folder.
fn sync_path(path: &Path) -> Result<(), FilesError> {
    File::open(path)
        .and_then(|f| f.sync_all())
        .map_err(|e| FilesError::write(path, e))
}

#[cfg(target_os = "linux")]
fn rename_no_replace(from: &Path, to: &Path) -> std::io::Result<()> {
    use nix::fcntl::{AT_FDCWD, RenameFlags, renameat2};
    match renameat2(AT_FDCWD, from, AT_FDCWD, to, RenameFlags::RENAME_NOREPLACE) {
        Ok(()) => Ok(()),
        // File systems without renameat2 flags: a plain rename (replaces an empty folder).
        Err(nix::errno::Errno::EINVAL | nix::errno::Errno::ENOSYS) => std::fs::rename(from, to),
        Err(e) => Err(e.into()),
    }
}

#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use nix::fcntl::{AT_FDCWD, RenameFlags, renameat2};
    match renameat2(AT_FDCWD, a, AT_FDCWD, b, RenameFlags::RENAME_EXCHANGE) {
        Ok(()) => Ok(()),
        Err(nix::errno::Errno::EINVAL | nix::errno::Errno::ENOSYS) => exchange_in_two_steps(a, b),
        Err(e) => Err(e.into()),
    }
}

#[cfg(not(target_os = "linux"))]
fn rename_no_replace(from: &Path, to: &Path) -> std::io::Result<()> {
    if to.exists() {
        return Err(std::io::ErrorKind::AlreadyExists.into());
    }
    std::fs::rename(from, to)
}

#[cfg(not(target_os = "linux"))]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    exchange_in_two_steps(a, b)
}

/// Swaps two folders through a third name where the kernel cannot swap them in one step (a
/// reader may then briefly find the destination missing, never mixed).
fn exchange_in_two_steps(a: &Path, b: &Path) -> std::io::Result<()> {
    let mut aside = a.as_os_str().to_owned();
    aside.push(".old");
    let aside = PathBuf::from(aside);
    std::fs::rename(b, &aside)?;
    if let Err(e) = std::fs::rename(a, b) {
        let _ = std::fs::rename(&aside, b);
        return Err(e);
    }
    std::fs::rename(&aside, a)
}

/// What the first SIGINT or SIGTERM calls instead of ending the process ([`on_first_interrupt`]).
type FirstInterrupt = Box<dyn FnOnce(i32) + Send>;

/// The registered first-interrupt hook and the id of its [`InterruptHook`].
static FIRST_INTERRUPT: Mutex<Option<(u64, FirstInterrupt)>> = Mutex::new(None);

/// Ids of [`InterruptHook`]s.
static NEXT_HOOK: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

fn first_interrupt() -> MutexGuard<'static, Option<(u64, FirstInterrupt)>> {
    FIRST_INTERRUPT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A registered first-interrupt hook ([`on_first_interrupt`]); dropping it unregisters the hook
/// if it has not run, so the next interrupt deletes the temporary folders again.
#[derive(Debug)]
#[must_use = "the hook is unregistered when this is dropped"]
pub struct InterruptHook {
    id: u64,
}

impl Drop for InterruptHook {
    fn drop(&mut self) {
        let mut slot = first_interrupt();
        if slot.as_ref().is_some_and(|(id, _)| *id == self.id) {
            *slot = None;
        }
    }
}

/// Makes the next SIGINT or SIGTERM call `hook` (with the signal's number, on the signal
/// thread) instead of deleting the temporary folders and ending the process (module docs); the
/// interrupt after it does both as usual. The hook runs at most once, must not block, and is
/// registered until the returned [`InterruptHook`] is dropped; a later registration replaces
/// an earlier one. Without [`remove_temporaries_on_signal`] installed it is never called.
pub fn on_first_interrupt(hook: impl FnOnce(i32) + Send + 'static) -> InterruptHook {
    let id = NEXT_HOOK.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    *first_interrupt() = Some((id, Box::new(hook)));
    InterruptHook { id }
}

/// Runs and unregisters the first-interrupt hook for `signal` when there is one and the signal
/// is SIGINT or SIGTERM; whether it did (else the signal ends the process).
#[cfg(unix)]
fn divert_to_hook(signal: i32) -> bool {
    use signal_hook::consts::{SIGINT, SIGTERM};
    if signal != SIGINT && signal != SIGTERM {
        return false;
    }
    // Taken out before it runs: a hook that blocks cannot hold up the next signal's lock.
    let hook = first_interrupt().take();
    match hook {
        Some((_, hook)) => {
            hook(signal);
            true
        }
        None => false,
    }
}

/// Installs a handler that deletes this process's uncommitted output folders on SIGINT,
/// SIGTERM and SIGHUP and then lets the signal take its default effect (the process ends with
/// it, i.e. exit status 128 + the signal in a shell), except for a first interrupt that an
/// [`on_first_interrupt`] hook takes. Call once, early in `main`.
pub fn remove_temporaries_on_signal() -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?;
        std::thread::Builder::new()
            .name("meb-signal-cleanup".into())
            .spawn(move || {
                for signal in signals.forever() {
                    if divert_to_hook(signal) {
                        continue;
                    }
                    let mut pending = pending();
                    for path in pending.drain(..) {
                        let _ = std::fs::remove_dir_all(&path);
                    }
                    // Keep the lock: no new folder starts while the process ends.
                    let _ = signal_hook::low_level::emulate_default_handler(signal);
                    std::process::exit(128 + signal);
                }
            })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(folder: &OutputFolder, name: &str, text: &str) {
        std::fs::write(folder.path().join(name), text).unwrap();
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn commit_replaces_an_earlier_output_whole() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        let first = OutputFolder::create(&out, "decode", Replace::EarlierOutput).unwrap();
        write(&first, "led1.npy", "1");
        write(&first, "led2.npy", "2");
        first.commit().unwrap();
        let second = OutputFolder::create(&out, "decode", Replace::EarlierOutput).unwrap();
        write(&second, "led1.npy", "new");
        second.commit().unwrap();
        assert_eq!(names(&out), [MARKER, "led1.npy"]);
        assert_eq!(
            std::fs::read_to_string(out.join("led1.npy")).unwrap(),
            "new"
        );
        assert_eq!(names(tmp.path()), ["out"], "no temporary folder is left");
    }

    #[test]
    fn foreign_and_other_commands_folders_are_refused_unless_forced() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        std::fs::create_dir(&out).unwrap();
        std::fs::write(out.join("thesis.tex"), "precious").unwrap();
        let err = OutputFolder::create(&out, "decode", Replace::EarlierOutput).unwrap_err();
        assert!(
            matches!(err, FilesError::OutputNotEmpty { found: None, .. }),
            "{err}"
        );
        let forced = OutputFolder::create(&out, "decode", Replace::Anything).unwrap();
        forced.commit().unwrap();
        assert_eq!(names(&out), [MARKER]);
        let err = OutputFolder::create(&out, "reconstruct", Replace::EarlierOutput).unwrap_err();
        assert!(err.to_string().contains("`meb decode`"), "{err}");
        let file = tmp.path().join("file");
        std::fs::write(&file, "x").unwrap();
        let err = OutputFolder::create(&file, "decode", Replace::Anything).unwrap_err();
        assert!(matches!(err, FilesError::OutputIsAFile { .. }), "{err}");
    }

    #[test]
    fn a_dropped_folder_leaves_the_previous_output_and_no_temporary() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        let first = OutputFolder::create(&out, "integrate", Replace::EarlierOutput).unwrap();
        write(&first, "depth.npy", "old");
        first.commit().unwrap();
        let second = OutputFolder::create(&out, "integrate", Replace::EarlierOutput).unwrap();
        write(&second, "depth.npy", "half");
        drop(second);
        assert_eq!(
            std::fs::read_to_string(out.join("depth.npy")).unwrap(),
            "old"
        );
        assert_eq!(names(tmp.path()), ["out"]);
    }

    #[test]
    fn stale_temporaries_of_dead_writers_are_removed_and_live_ones_kept() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        // A writer that died: unlocked lock file. A legacy folder of a process that cannot
        // exist (pid above the kernel's maximum). A live writer: this process's own folder.
        let dead = tmp.path().join(format!(".out{PARTIAL}1-abc"));
        std::fs::create_dir(&dead).unwrap();
        std::fs::write(dead.join(LOCK), "").unwrap();
        let legacy = tmp.path().join(".out.partial-4194305");
        std::fs::create_dir(&legacy).unwrap();
        let live = OutputFolder::create(&out, "simulate", Replace::EarlierOutput).unwrap();
        assert!(!dead.exists() && !legacy.exists());
        let other = OutputFolder::create(&out, "simulate", Replace::EarlierOutput).unwrap();
        assert!(live.path().exists(), "a locked folder is kept");
        other.commit().unwrap();
        live.commit().unwrap();
        assert_eq!(names(tmp.path()), ["out"]);
    }

    #[cfg(unix)]
    #[test]
    fn a_first_interrupt_hook_takes_one_interrupt_until_dropped() {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        use std::sync::Arc;
        use std::sync::atomic::{AtomicI32, Ordering};
        assert!(
            !divert_to_hook(SIGINT),
            "no hook: the signal ends the process"
        );
        let seen = Arc::new(AtomicI32::new(0));
        let hook = {
            let seen = seen.clone();
            on_first_interrupt(move |signal| seen.store(signal, Ordering::SeqCst))
        };
        assert!(!divert_to_hook(SIGHUP), "a hang-up is never diverted");
        assert!(divert_to_hook(SIGTERM));
        assert_eq!(seen.load(Ordering::SeqCst), SIGTERM);
        assert!(
            !divert_to_hook(SIGINT),
            "the second interrupt ends the process"
        );
        drop(hook);
        // A dropped hook no longer takes the first interrupt, and dropping an old guard does
        // not unregister a newer hook.
        let old = on_first_interrupt(|_| {});
        drop(old);
        assert!(!divert_to_hook(SIGINT));
        let old = on_first_interrupt(|_| {});
        let new = on_first_interrupt(|_| {});
        drop(old);
        assert!(divert_to_hook(SIGINT));
        drop(new);
    }

    #[test]
    fn concurrent_commits_each_leave_a_whole_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        for round in 0..20 {
            let handles: Vec<_> = (0..2)
                .map(|writer| {
                    let out = out.clone();
                    std::thread::spawn(move || {
                        let folder =
                            OutputFolder::create(&out, "decode", Replace::EarlierOutput).unwrap();
                        for file in 0..4 + 2 * writer {
                            write(&folder, &format!("led{file}.npy"), &format!("{writer}"));
                        }
                        folder.commit().unwrap();
                    })
                })
                .collect();
            for h in handles {
                h.join().unwrap();
            }
            let files: Vec<String> = names(&out).into_iter().filter(|n| n != MARKER).collect();
            let writers: Vec<String> = files
                .iter()
                .map(|f| std::fs::read_to_string(out.join(f)).unwrap())
                .collect();
            let writer = &writers[0];
            assert!(
                writers.iter().all(|w| w == writer),
                "round {round}: mixed {writers:?}"
            );
            let expected = if writer == "0" { 4 } else { 6 };
            assert_eq!(files.len(), expected, "round {round}: {files:?}");
        }
        assert_eq!(names(tmp.path()), ["out"]);
    }
}
