//! [`FoxgloveOutputs`]: the `--record` file and the `--view` server behind one per-frame call, as `supine replay`
//! and `supine run` use them.
//!
//! The frame loop's share is small: when anyone takes frames (a recording, or a subscribed viewer) the frame is
//! copied into a recycled [`OwnedFrame`] (one pass over the depth image, no allocation once warm) and queued to the
//! outputs thread, which encodes it ([`encode_frame`], a few ms), appends it to the MCAP file and hands it to the
//! live view. [`Pace::DropWhenBusy`] (the service) never waits: with [`QUEUE_FRAMES`] frames waiting, a new one is
//! dropped and counted. [`Pace::Lossless`] (replay) waits instead, so every frame is recorded. A failing recording
//! stops (logged once; [`FoxgloveOutputs::finish`] reports it) and tracking goes on.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use supine_core::geometry::Isometry3;

use super::live::{LiveStats, LiveView};
use super::mcap_out::{McapRecorder, RecordError};
use super::owned::OwnedFrame;
use super::{FrameRecord, LogClock, encode_frame};

/// Frames waiting for the outputs thread before [`Pace::DropWhenBusy`] drops new ones.
pub const QUEUE_FRAMES: usize = 4;

/// What the frame loop does when the outputs thread is behind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pace {
    /// Wait for room: every frame is recorded (replay).
    Lossless,
    /// Drop the new frame and count it: the loop never waits (the real-time service).
    DropWhenBusy,
}

/// What the outputs did, reported by [`FoxgloveOutputs::finish`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OutputsReport {
    /// Frames written to the recording.
    pub recorded: u64,
    /// Frames dropped because the outputs thread was behind ([`Pace::DropWhenBusy`]).
    pub dropped: u64,
    /// The live view's counters, when it served.
    pub live: Option<LiveStats>,
}

struct Job {
    frame: OwnedFrame,
    log_ns: u64,
}

/// Where frames go besides the link.
pub struct FoxgloveOutputs {
    jobs: Option<SyncSender<Job>>,
    spares: Receiver<OwnedFrame>,
    spare: Option<OwnedFrame>,
    worker: Option<JoinHandle<Result<(), RecordError>>>,
    live: Option<Arc<LiveView>>,
    recording: Arc<AtomicBool>,
    recorded: Arc<AtomicU64>,
    clock: LogClock,
    pace: Pace,
    dropped: u64,
}

impl FoxgloveOutputs {
    /// Outputs to a recording in `record` (an open file) and/or a live view; `robot_base_from_camera` is the
    /// calibration, when the config has one.
    pub fn new(
        record: Option<File>,
        live: Option<LiveView>,
        robot_base_from_camera: Option<Isometry3>,
        pace: Pace,
    ) -> Result<Self, RecordError> {
        let recorder = match record {
            Some(f) => Some(McapRecorder::new(BufWriter::with_capacity(1 << 20, f))?),
            None => None,
        };
        let live = live.map(Arc::new);
        let recording = Arc::new(AtomicBool::new(recorder.is_some()));
        let recorded = Arc::new(AtomicU64::new(0));
        let (jobs, job_rx) = sync_channel::<Job>(QUEUE_FRAMES);
        // Spent frames come back for reuse: at most the queue plus the one being encoded are in flight.
        let (spare_tx, spares) = sync_channel::<OwnedFrame>(QUEUE_FRAMES + 2);
        let worker = {
            let (live, recording, recorded) = (live.clone(), Arc::clone(&recording), Arc::clone(&recorded));
            std::thread::Builder::new()
                .name("foxglove-out".into())
                .spawn(move || {
                    work(
                        job_rx,
                        spare_tx,
                        recorder,
                        live,
                        robot_base_from_camera,
                        &recording,
                        &recorded,
                    )
                })
                .map_err(|e| RecordError::new(format!("starting the outputs thread: {e}")))?
        };
        Ok(FoxgloveOutputs {
            jobs: Some(jobs),
            spares,
            spare: None,
            worker: Some(worker),
            live,
            recording,
            recorded,
            clock: LogClock::default(),
            pace,
            dropped: 0,
        })
    }

    /// Whether anything takes frames now (a recording still running, or a subscribed viewer).
    pub fn wanted(&self) -> bool {
        self.recording.load(Ordering::Relaxed) || self.live.as_ref().is_some_and(|l| l.has_subscribers())
    }

    /// The live view, when serving (e.g. to wait for a viewer).
    pub fn live(&self) -> Option<&LiveView> {
        self.live.as_deref()
    }

    /// Hand one frame to the outputs (see the module docs for what waits and what drops).
    pub fn frame(&mut self, record: &FrameRecord<'_>) {
        let log_ns = self.clock.log_ns(record.capture);
        if !self.wanted() {
            return;
        }
        let Some(jobs) = &self.jobs else { return };
        let mut frame = self
            .spare
            .take()
            .or_else(|| self.spares.try_recv().ok())
            .unwrap_or_default();
        frame.copy_from(record);
        let job = Job { frame, log_ns };
        let sent = match self.pace {
            Pace::Lossless => jobs.send(job).map_err(|e| Some(e.0)),
            Pace::DropWhenBusy => jobs.try_send(job).map_err(|e| match e {
                TrySendError::Full(job) => {
                    self.dropped += 1;
                    self.spare = Some(job.frame);
                    None
                }
                TrySendError::Disconnected(job) => Some(job),
            }),
        };
        if let Err(Some(_)) = sent {
            // The outputs thread is gone (it failed); finish() reports why.
            self.jobs = None;
            self.recording.store(false, Ordering::Relaxed);
        }
    }

    /// Drain the queue, finish the recording (summary, flush, fsync) and stop the live view.
    pub fn finish(mut self) -> Result<OutputsReport, RecordError> {
        drop(self.jobs.take());
        let result = match self.worker.take().map(JoinHandle::join) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(RecordError::new("the outputs thread panicked".into())),
            None => Ok(()),
        };
        let live = self.live.take().map(|l| l.stats());
        result.map(|()| OutputsReport {
            recorded: self.recorded.load(Ordering::Relaxed),
            dropped: self.dropped,
            live,
        })
    }
}

impl Drop for FoxgloveOutputs {
    fn drop(&mut self) {
        // finish() was not called (an early return): still end the thread; the recording is left unfinished.
        drop(self.jobs.take());
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

/// The outputs thread: encode, record, publish, recycle; at the end finish the file.
fn work(
    jobs: Receiver<Job>,
    spares: SyncSender<OwnedFrame>,
    mut recorder: Option<McapRecorder<BufWriter<File>>>,
    live: Option<Arc<LiveView>>,
    robot_base_from_camera: Option<Isometry3>,
    recording: &AtomicBool,
    recorded: &AtomicU64,
) -> Result<(), RecordError> {
    let mut failure = None;
    for job in jobs {
        let messages = encode_frame(&job.frame, job.log_ns, robot_base_from_camera.as_ref());
        let _ = spares.try_send(job.frame);
        if let Some(rec) = recorder.as_mut() {
            match rec.write(&messages) {
                Ok(()) => {
                    recorded.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => {
                    tracing::error!("recording stopped: {e}");
                    recorder = None;
                    recording.store(false, Ordering::Relaxed);
                    failure = Some(e);
                }
            }
        }
        if let Some(live) = &live
            && live.has_subscribers()
        {
            live.publish(messages);
        }
    }
    if let Some(e) = failure {
        return Err(RecordError::new(format!("the recording stopped early: {e}")));
    }
    if let Some(rec) = recorder {
        let mut out = rec.finish()?;
        let io = |e: std::io::Error| RecordError::new(format!("writing the MCAP recording: {e}"));
        out.flush().map_err(io)?;
        let file = out.into_inner().map_err(|e| io(e.into_error()))?;
        file.sync_all().map_err(io)?;
    }
    Ok(())
}
