//! Camera frames streamed into windows with memory bounded by the window, whatever the clip
//! length.
//!
//! A reader thread pulls frames from the [`FrameSource`] (a file, FFmpeg's pipe, standard
//! input, the simulator) and hands them over through a bounded channel, so reading overlaps
//! decoding and reconstruction; the consumer keeps only the frames of the window it is
//! decoding (a ring). At most `read_ahead` frames wait in the channel and `window` sit in the
//! ring: memory is bounded by those two, never by the clip. Frames between windows (a hop
//! longer than the window) are dropped as they arrive. A frame's storage, once dropped, goes
//! back to the reader thread, which reads the next frame straight into it
//! ([`FrameSource::read_frame_into`]): after the first window no frame is allocated.
//!
//! Requests must move forward in time: [`FrameStream::window`] may not ask for a frame it has
//! already dropped.
//!
//! A live stream has no end of its own: [`FrameStream::until`] ends it when a [`StopSignal`] is
//! set (the CLI sets it on the first interrupt). The reader takes no frame after the request
//! (it looks at it before each read); the frames it had already read are still handed out, so a
//! window that they complete is decoded; then the stream ends with [`StreamEnd::Stopped`] as
//! if the source had ended. The reader may then be blocked in a `read()` that will not return
//! (standard input with nothing coming): the consumer does not wait for it. The stop's waker
//! posts a wake-up message into the channel, so a consumer asleep on the channel wakes at
//! once, and a consumer that sees the request takes only what is already queued. The blocked
//! reader thread is left behind, detached; it holds nothing but the source and ends with the
//! process (or at its next frame, which it drops).

use meb_core::capture::{CaptureError, Frame, FrameFormat, FrameSource, Samples};
use meb_core::stop::StopSignal;
use std::collections::VecDeque;
use std::ops::Range;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, SyncSender, channel, sync_channel};
use std::time::{Duration, Instant};

/// How a stream ended.
#[derive(Debug)]
pub enum StreamEnd {
    /// The source had no more frames.
    Complete,
    /// The source failed (a cut or corrupt stream) after delivering the frames before it.
    Cut(CaptureError),
    /// The frame limit was reached.
    Limit,
    /// The stop request ended the stream ([`FrameStream::until`]); a read error after it is
    /// put down to the stop (the pipe feeding a live stream is cut by the same interrupt).
    Stopped,
}

/// What the reader thread hands over.
enum Message {
    /// The next frame.
    Frame(Frame),
    /// The source failed; nothing follows.
    Failed(CaptureError),
    /// The source has no more frames.
    End,
    /// The stop request (posted by its waker, not by the reader).
    Stopped,
}

/// A window's frames in the ring.
#[derive(Debug)]
pub struct WindowFrames<'a> {
    /// Camera frames (stream indices) of the window.
    pub frames: Range<usize>,
    /// Their samples, in order.
    pub samples: &'a [Samples],
}

/// Frames of a source streamed into windows (module docs).
pub struct FrameStream {
    format: FrameFormat,
    receiver: Receiver<Message>,
    /// Storage of dropped frames, back to the reader for reuse.
    recycle: Sender<Samples>,
    ring: VecDeque<Samples>,
    /// Stream index of `ring[0]`.
    ring_start: usize,
    /// Frames received so far (stream index of the next one).
    received: usize,
    limit: Option<usize>,
    stop: StopSignal,
    end: Option<StreamEnd>,
    waited: Duration,
    total_hint: Option<usize>,
}

impl FrameStream {
    /// Starts reading `source` on its own thread, at most `read_ahead` frames ahead of the
    /// consumer, stopping after `limit` frames when given.
    pub fn new(
        source: Box<dyn FrameSource>,
        read_ahead: usize,
        limit: Option<usize>,
    ) -> Result<Self, CaptureError> {
        Self::until(source, read_ahead, limit, &StopSignal::new())
    }

    /// [`Self::new`] for a stream that also ends when `stop` is set (module docs).
    pub fn until(
        source: Box<dyn FrameSource>,
        read_ahead: usize,
        limit: Option<usize>,
        stop: &StopSignal,
    ) -> Result<Self, CaptureError> {
        let format = source.format().clone();
        let total_hint = match (source.frame_count_hint(), limit) {
            (Some(n), Some(l)) => Some(n.min(l)),
            (n, None) => n,
            (None, l) => l,
        };
        let (sender, receiver) = sync_channel(read_ahead.max(1));
        let (recycle, recycled) = channel();
        // The reader owns the only strong reference to the sender, so the channel still hangs
        // up when the reader ends; the waker posts through a weak one while the reader lives
        // (never blocking: a full channel wakes the consumer by itself).
        let sender = Arc::new(sender);
        let waker = Arc::downgrade(&sender);
        let reader_stop = stop.clone();
        std::thread::Builder::new()
            .name("meb-video-reader".into())
            .spawn(move || read_frames(source, &sender, &recycled, limit, &reader_stop))
            .map_err(|e| CaptureError::Other(format!("cannot start the frame reader: {e}")))?;
        stop.on_stop(move || {
            if let Some(sender) = waker.upgrade() {
                let _ = sender.try_send(Message::Stopped);
            }
        });
        Ok(Self {
            format,
            receiver,
            recycle,
            ring: VecDeque::new(),
            ring_start: 0,
            received: 0,
            limit,
            stop: stop.clone(),
            end: None,
            waited: Duration::ZERO,
            total_hint,
        })
    }

    /// The stream's format.
    pub fn format(&self) -> &FrameFormat {
        &self.format
    }

    /// Frames in the stream when the source knows (or the limit), for progress reports.
    pub fn total_hint(&self) -> Option<usize> {
        self.total_hint
    }

    /// Frames received so far.
    pub fn received(&self) -> usize {
        self.received
    }

    /// Frames held in the ring now.
    pub fn held(&self) -> usize {
        self.ring.len()
    }

    /// Time spent waiting for the reader since the last call (reading, when it is the
    /// bottleneck).
    pub fn take_waited(&mut self) -> Duration {
        std::mem::take(&mut self.waited)
    }

    /// How the stream ended, once it has.
    pub fn end(&self) -> Option<&StreamEnd> {
        self.end.as_ref()
    }

    /// Takes the end of the stream (`None` while it runs).
    pub fn take_end(&mut self) -> Option<StreamEnd> {
        self.end.take()
    }

    /// The frames `frames` (stream indices), reading as far as needed and dropping every
    /// earlier frame; `None` when the stream ends first ([`Self::end`] says how).
    pub fn window(
        &mut self,
        frames: Range<usize>,
    ) -> Result<Option<WindowFrames<'_>>, CaptureError> {
        if frames.start < self.ring_start {
            return Err(CaptureError::Other(format!(
                "frame {} was requested after it was dropped (windows must move forward)",
                frames.start
            )));
        }
        let keep_from = frames.start.min(self.received);
        while self.ring_start < keep_from {
            if let Some(samples) = self.ring.pop_front() {
                self.reuse(samples);
            }
            self.ring_start += 1;
        }
        if self.ring.is_empty() {
            self.ring_start = self.received;
        }
        while self.received < frames.end {
            let Some(samples) = self.receive()? else {
                return Ok(None);
            };
            let index = self.received;
            self.received += 1;
            if index < frames.start {
                self.ring_start = self.received;
                self.reuse(samples);
                continue;
            }
            self.ring.push_back(samples);
        }
        let offset = frames.start - self.ring_start;
        let len = frames.end - frames.start;
        let samples = &self.ring.make_contiguous()[offset..offset + len];
        Ok(Some(WindowFrames { frames, samples }))
    }

    /// Gives a dropped frame's storage back to the reader (lost if the reader has ended).
    fn reuse(&self, samples: Samples) {
        let _ = self.recycle.send(samples);
    }

    /// The next frame's samples, or `None` at the end of the stream (recorded in `end`).
    fn receive(&mut self) -> Result<Option<Samples>, CaptureError> {
        if self.end.is_some() {
            return Ok(None);
        }
        if self.limit.is_some_and(|limit| self.received >= limit) {
            self.end = Some(StreamEnd::Limit);
            return Ok(None);
        }
        let message = if self.stop.is_stopped() {
            // Only what the reader has already read; its next read may never return.
            self.receiver.try_recv().unwrap_or(Message::Stopped)
        } else {
            let started = Instant::now();
            let message = self.receiver.recv();
            self.waited += started.elapsed();
            // A reader gone without a word (it panicked) ends the stream as before.
            message.unwrap_or(Message::End)
        };
        match message {
            Message::Frame(frame) => {
                if frame.samples.len() != self.format.pixels() {
                    self.end = Some(StreamEnd::Cut(CaptureError::Other(format!(
                        "frame {} has {} samples, expected {}x{}",
                        self.received,
                        frame.samples.len(),
                        self.format.width,
                        self.format.height
                    ))));
                    return Ok(None);
                }
                Ok(Some(frame.samples))
            }
            Message::Failed(_) | Message::Stopped if self.stop.is_stopped() => {
                self.end = Some(StreamEnd::Stopped);
                Ok(None)
            }
            Message::Failed(error) => {
                self.end = Some(StreamEnd::Cut(error));
                Ok(None)
            }
            // A stale wake-up cannot come without the request; ended all the same.
            Message::Stopped => {
                self.end = Some(StreamEnd::Stopped);
                Ok(None)
            }
            Message::End => {
                self.end = Some(StreamEnd::Complete);
                Ok(None)
            }
        }
    }
}

/// The reader thread: frames into the channel until the source ends, fails, reaches
/// `limit`, `stop` is set (looked at before each read) or the consumer hangs up; each frame is
/// read into the storage of a dropped one from `recycled` when there is one.
fn read_frames(
    mut source: Box<dyn FrameSource>,
    sender: &SyncSender<Message>,
    recycled: &Receiver<Samples>,
    limit: Option<usize>,
    stop: &StopSignal,
) {
    let mut read = 0usize;
    while limit.is_none_or(|limit| read < limit) && !stop.is_stopped() {
        let mut samples = recycled.try_recv().unwrap_or(Samples::U8(Vec::new()));
        let message = match source.read_frame_into(&mut samples) {
            Ok(Some(index)) => Message::Frame(Frame { index, samples }),
            Ok(None) => Message::End,
            Err(error) => Message::Failed(error),
        };
        let last = !matches!(message, Message::Frame(_));
        if sender.send(message).is_err() || last {
            return;
        }
        read += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meb_core::capture::memory::MemorySource;

    fn source(frames: usize) -> Box<dyn FrameSource> {
        let format = FrameFormat::full_range(2, 1, 8, 100.0);
        let frames = (0..frames)
            .map(|i| Frame {
                index: i,
                samples: Samples::U8(vec![i as u8, 0]),
            })
            .collect();
        Box::new(MemorySource::new(format, frames).unwrap())
    }

    fn first_samples(window: &WindowFrames) -> Vec<u8> {
        window
            .samples
            .iter()
            .map(|s| match s {
                Samples::U8(v) => v[0],
                Samples::U16(v) => v[0] as u8,
            })
            .collect()
    }

    #[test]
    fn windows_hold_their_frames_and_memory_stays_at_one_window() {
        let mut stream = FrameStream::new(source(100), 4, None).unwrap();
        for k in 0..12 {
            // Sliding: 8-frame windows every 3 frames, decoding frames 1..7 of each.
            let range = 3 * k + 1..3 * k + 7;
            let window = stream.window(range.clone()).unwrap().unwrap();
            assert_eq!(
                first_samples(&window),
                range.map(|i| i as u8).collect::<Vec<_>>()
            );
            assert!(stream.held() <= 6, "{} frames held", stream.held());
        }
        // Gaps (hop longer than the window) are skipped as they arrive.
        let window = stream.window(60..64).unwrap().unwrap();
        assert_eq!(first_samples(&window), vec![60, 61, 62, 63]);
        assert_eq!(stream.held(), 4);
        assert!(stream.window(10..12).is_err(), "frames already dropped");
        assert!(stream.window(98..102).unwrap().is_none());
        assert!(matches!(stream.end(), Some(StreamEnd::Complete)));
        assert_eq!(stream.received(), 100);
    }

    /// Frames of two samples that count how often a frame needed new storage.
    struct CountingSource {
        format: FrameFormat,
        next: usize,
        frames: usize,
        allocations: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    }

    impl FrameSource for CountingSource {
        fn format(&self) -> &FrameFormat {
            &self.format
        }

        fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
            meb_core::capture::next_frame_from_storage(self)
        }

        fn read_frame_into(
            &mut self,
            samples: &mut Samples,
        ) -> Result<Option<usize>, CaptureError> {
            if self.next == self.frames {
                return Ok(None);
            }
            match samples {
                Samples::U8(v) if v.capacity() >= 2 => {
                    v.clear();
                    v.extend([self.next as u8, 0]);
                }
                _ => {
                    self.allocations
                        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    *samples = Samples::U8(vec![self.next as u8, 0]);
                }
            }
            self.next += 1;
            Ok(Some(self.next - 1))
        }
    }

    #[test]
    fn dropped_frames_lend_their_storage_to_the_next() {
        let allocations = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let source = CountingSource {
            format: FrameFormat::full_range(2, 1, 8, 100.0),
            next: 0,
            frames: 200,
            allocations: allocations.clone(),
        };
        let mut stream = FrameStream::new(Box::new(source), 4, None).unwrap();
        for k in 0..24 {
            let range = 8 * k..8 * k + 8;
            let window = stream.window(range.clone()).unwrap().unwrap();
            assert_eq!(
                first_samples(&window),
                range.map(|i| i as u8).collect::<Vec<_>>()
            );
        }
        let made = allocations.load(std::sync::atomic::Ordering::Relaxed);
        // One window in the ring, the read-ahead in the channel, one being read.
        assert!(made <= 8 + 4 + 2, "{made} frames allocated for 192 read");
    }

    /// A source that delivers `frames` frames and then, in its next read, says so on `blocked`
    /// and blocks until `release` hangs up, like standard input with nothing coming.
    struct BlockingSource {
        format: FrameFormat,
        next: usize,
        frames: usize,
        blocked: std::sync::mpsc::Sender<()>,
        release: std::sync::mpsc::Receiver<()>,
    }

    impl FrameSource for BlockingSource {
        fn format(&self) -> &FrameFormat {
            &self.format
        }

        fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
            if self.next == self.frames {
                let _ = self.blocked.send(());
                let _ = self.release.recv();
                return Ok(None);
            }
            self.next += 1;
            Ok(Some(Frame {
                index: self.next - 1,
                samples: Samples::U8(vec![(self.next - 1) as u8, 0]),
            }))
        }
    }

    /// A stream of ten frames whose reader then blocks; the receiver says when it does, the
    /// sender releases it when dropped.
    fn blocking_stream(
        stop: &StopSignal,
    ) -> (
        FrameStream,
        std::sync::mpsc::Receiver<()>,
        std::sync::mpsc::Sender<()>,
    ) {
        let (blocked, is_blocked) = std::sync::mpsc::channel();
        let (release, released) = std::sync::mpsc::channel();
        let source = BlockingSource {
            format: FrameFormat::full_range(2, 1, 8, 100.0),
            next: 0,
            frames: 10,
            blocked,
            release: released,
        };
        let stream = FrameStream::until(Box::new(source), 16, None, stop).unwrap();
        (stream, is_blocked, release)
    }

    #[test]
    fn a_stop_hands_out_the_frames_already_read_and_then_ends_the_stream() {
        let stop = StopSignal::new();
        let (mut stream, is_blocked, release) = blocking_stream(&stop);
        // All ten frames are queued and the reader waits in its eleventh read.
        is_blocked.recv().unwrap();
        stop.stop();
        assert_eq!(
            first_samples(&stream.window(2..8).unwrap().unwrap()),
            vec![2, 3, 4, 5, 6, 7]
        );
        assert!(stream.window(6..12).unwrap().is_none());
        assert!(matches!(stream.end(), Some(StreamEnd::Stopped)));
        assert_eq!(stream.received(), 10);
        drop(release);
    }

    #[test]
    fn a_stop_wakes_a_consumer_waiting_on_a_blocked_reader() {
        let stop = StopSignal::new();
        let (mut stream, _is_blocked, release) = blocking_stream(&stop);
        assert!(stream.window(0..10).unwrap().is_some());
        // The consumer waits for frame 10, which never comes, until the stop wakes it from
        // another thread (the signal thread in `meb video`).
        let stopper = stop.clone();
        let stopping = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(50));
            stopper.stop();
        });
        assert!(stream.window(8..12).unwrap().is_none());
        assert!(matches!(stream.end(), Some(StreamEnd::Stopped)));
        assert_eq!(stream.received(), 10);
        stopping.join().unwrap();
        drop(release);
    }

    #[test]
    fn a_stop_before_the_stream_starts_ends_it_at_once() {
        let stop = StopSignal::new();
        stop.stop();
        let mut stream = FrameStream::until(source(100), 4, None, &stop).unwrap();
        assert!(stream.window(0..8).unwrap().is_none());
        assert!(matches!(stream.end(), Some(StreamEnd::Stopped)));
        assert!(stream.received() < 8);
    }

    #[test]
    fn a_limit_stops_the_stream() {
        let mut stream = FrameStream::new(source(100), 2, Some(10)).unwrap();
        assert_eq!(stream.total_hint(), Some(10));
        assert!(stream.window(0..8).unwrap().is_some());
        assert!(stream.window(4..12).unwrap().is_none());
        assert!(matches!(stream.end(), Some(StreamEnd::Limit)));
    }
}
