//! A request to stop, shared between threads: the CLI sets it (on the first interrupt of a live
//! stream, [`crate::io::folder::on_first_interrupt`]) and a library stage that can end early
//! looks at it (the video pipeline's frame reader ends the stream there).
//!
//! A stage that may be blocked waiting when the request comes (a thread asleep on a channel
//! whose producer is itself blocked in a `read()` on standard input) registers a waker with
//! [`StopSignal::on_stop`]: [`StopSignal::stop`] calls it, on the stopping thread, after the
//! flag is set, so the stage never has to wake up to poll the flag.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

/// What [`StopSignal::stop`] calls to wake a stage.
type Waker = Box<dyn FnOnce() + Send>;

/// A shared stop request (module docs). Clones share one request; a new one is not stopped.
#[derive(Clone, Default)]
pub struct StopSignal {
    inner: Arc<Inner>,
}

#[derive(Default)]
struct Inner {
    stopped: AtomicBool,
    wakers: Mutex<Vec<Waker>>,
}

impl StopSignal {
    /// A request that has not been made.
    pub fn new() -> Self {
        Self::default()
    }

    /// Makes the request: sets the flag, then calls (once each, on this thread) the wakers
    /// registered so far. Later calls do nothing more.
    pub fn stop(&self) {
        let wakers = {
            let mut wakers = self.wakers();
            self.inner.stopped.store(true, Ordering::SeqCst);
            std::mem::take(&mut *wakers)
        };
        for waker in wakers {
            waker();
        }
    }

    /// Whether the request has been made.
    pub fn is_stopped(&self) -> bool {
        self.inner.stopped.load(Ordering::SeqCst)
    }

    /// Calls `waker` when the request is made, or now (on this thread) if it has been. A
    /// waker must not block: it runs on the thread that stops (e.g. the signal thread).
    pub fn on_stop(&self, waker: impl FnOnce() + Send + 'static) {
        let mut wakers = self.wakers();
        if self.is_stopped() {
            drop(wakers);
            waker();
        } else {
            wakers.push(Box::new(waker));
        }
    }

    fn wakers(&self) -> std::sync::MutexGuard<'_, Vec<Waker>> {
        self.inner
            .wakers
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }
}

impl std::fmt::Debug for StopSignal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StopSignal")
            .field("stopped", &self.is_stopped())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    #[test]
    fn wakers_run_once_when_stopped_or_at_once_after() {
        let stop = StopSignal::new();
        let calls = Arc::new(AtomicUsize::new(0));
        let counter = calls.clone();
        stop.on_stop(move || {
            counter.fetch_add(1, Ordering::SeqCst);
        });
        let clone = stop.clone();
        assert!(!clone.is_stopped());
        assert_eq!(calls.load(Ordering::SeqCst), 0);
        clone.stop();
        clone.stop();
        assert!(stop.is_stopped());
        assert_eq!(calls.load(Ordering::SeqCst), 1);
        let counter = calls.clone();
        stop.on_stop(move || {
            counter.fetch_add(10, Ordering::SeqCst);
        });
        assert_eq!(calls.load(Ordering::SeqCst), 11);
    }

    #[test]
    fn a_stop_from_another_thread_wakes_a_blocked_receiver() {
        let stop = StopSignal::new();
        let (sender, receiver) = std::sync::mpsc::sync_channel::<()>(1);
        stop.on_stop(move || {
            let _ = sender.try_send(());
        });
        let stopper = stop.clone();
        let thread = std::thread::spawn(move || stopper.stop());
        receiver.recv().unwrap();
        assert!(stop.is_stopped());
        thread.join().unwrap();
    }
}
