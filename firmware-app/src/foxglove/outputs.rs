//! [`FoxgloveOutputs`]: the `--record` file and the `--view` server behind one per-frame call, as `supine replay`
//! and `supine run` use them. A frame is encoded only when someone takes it (a recording, or a subscribed viewer).
//! A failing recording stops (logged once; [`FoxgloveOutputs::finish`] reports it) and tracking goes on.

use std::fs::File;
use std::io::{BufWriter, Write};

use supine_core::geometry::Isometry3;

use super::live::{LiveStats, LiveView};
use super::mcap_out::{McapRecorder, RecordError};
use super::{FrameRecord, LogClock, encode_frame};

/// Where frames go besides the link.
pub struct FoxgloveOutputs {
    recorder: Option<McapRecorder<BufWriter<File>>>,
    live: Option<LiveView>,
    clock: LogClock,
    robot_base_from_camera: Option<Isometry3>,
    record_error: Option<RecordError>,
}

impl FoxgloveOutputs {
    /// Outputs to a recording in `record` (an open file) and/or a live view; `robot_base_from_camera` is the
    /// calibration, when the config has one.
    pub fn new(
        record: Option<File>,
        live: Option<LiveView>,
        robot_base_from_camera: Option<Isometry3>,
    ) -> Result<Self, RecordError> {
        let recorder = match record {
            Some(f) => Some(McapRecorder::new(BufWriter::with_capacity(1 << 20, f))?),
            None => None,
        };
        Ok(FoxgloveOutputs {
            recorder,
            live,
            clock: LogClock::default(),
            robot_base_from_camera,
            record_error: None,
        })
    }

    /// Whether anything wants frames now.
    pub fn wanted(&self) -> bool {
        self.recorder.is_some() || self.live.as_ref().is_some_and(LiveView::has_subscribers)
    }

    /// Record and publish one frame (never blocks on a viewer; see [`LiveView::publish`]).
    pub fn frame(&mut self, record: &FrameRecord<'_>) {
        let log_ns = self.clock.log_ns(record.capture);
        if !self.wanted() {
            return;
        }
        let messages = encode_frame(record, log_ns, self.robot_base_from_camera.as_ref());
        if let Some(rec) = self.recorder.as_mut()
            && let Err(e) = rec.write(&messages)
        {
            tracing::error!("recording stopped: {e}");
            self.recorder = None;
            self.record_error = Some(e);
        }
        if let Some(live) = &self.live
            && live.has_subscribers()
        {
            live.publish(messages);
        }
    }

    /// Frames recorded so far.
    pub fn frames_recorded(&self) -> u64 {
        self.recorder.as_ref().map_or(0, McapRecorder::frames)
    }

    /// Finish the recording (summary, flush, fsync) and stop the live view; returns the view's counters.
    pub fn finish(mut self) -> Result<Option<LiveStats>, RecordError> {
        let stats = self.live.as_ref().map(LiveView::stats);
        drop(self.live.take());
        if let Some(e) = self.record_error.take() {
            return Err(RecordError::new(format!("the recording stopped early: {e}")));
        }
        if let Some(rec) = self.recorder.take() {
            let mut out = rec.finish()?;
            out.flush()
                .map_err(|e| RecordError::new(format!("writing the MCAP recording: {e}")))?;
            let file = out
                .into_inner()
                .map_err(|e| RecordError::new(format!("writing the MCAP recording: {}", e.error())))?;
            file.sync_all()
                .map_err(|e| RecordError::new(format!("writing the MCAP recording: {e}")))?;
        }
        Ok(stats)
    }
}
