//! [`Recording`]: a [`DepthSource`] wrapper that writes every frame it passes through to an .oni file.
//!
//! Used by the service's `--record` option and by anything that wants a replayable copy of a live session. Frames go
//! through unchanged. A write failure (disk full, non-monotonic device timestamps) stops the recording, is logged
//! once and kept in [`Recording::recording_error`]; the frames keep flowing, because tracking matters more than the
//! copy. Per-frame cost: one encode and one buffered write (see [`crate::oni`]); no allocation beyond the writer's
//! seek index.

use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;
use std::time::Duration;

use supine_core::camera::Intrinsics;
use supine_core::depth::DepthFrame;

use crate::oni::{Codec, OniWriter, OniWriterConfig};
use crate::source::{DepthSource, SourceError};

/// Passes frames of `S` through while recording them.
pub struct Recording<S, W: Write + Seek = BufWriter<File>> {
    inner: S,
    writer: Option<OniWriter<W>>,
    error: Option<SourceError>,
}

impl<S: DepthSource> Recording<S> {
    /// Record `inner` to `path` with `codec`, using the source's intrinsics for the file's FOV and size.
    pub fn create(inner: S, path: impl AsRef<Path>, codec: Codec) -> Result<Self, SourceError> {
        let writer = OniWriter::create(path, &inner.intrinsics(), codec)?;
        Ok(Recording {
            inner,
            writer: Some(writer),
            error: None,
        })
    }
}

impl<S: DepthSource, W: Write + Seek> Recording<S, W> {
    /// Record `inner` into `out` (any seekable writer).
    pub fn new(inner: S, out: W, codec: Codec) -> Result<Self, SourceError> {
        let writer = OniWriter::new(out, OniWriterConfig::new(&inner.intrinsics(), codec))?;
        Ok(Recording {
            inner,
            writer: Some(writer),
            error: None,
        })
    }

    /// Frames recorded so far.
    pub fn frames_recorded(&self) -> u32 {
        self.writer.as_ref().map_or(0, |w| w.frames_written())
    }

    /// Why recording stopped, if it did.
    pub fn recording_error(&self) -> Option<&SourceError> {
        self.error.as_ref()
    }

    /// Finish the file and give back the source and the writer's target.
    pub fn finish(mut self) -> Result<(S, W), SourceError> {
        if let Some(e) = self.error.take() {
            return Err(e.context("recording stopped earlier"));
        }
        let writer = self.writer.take();
        let out = match writer {
            Some(w) => w.finish()?,
            None => {
                return Err(SourceError::new(
                    crate::source::SourceErrorKind::Other,
                    "recording already finished",
                ));
            }
        };
        Ok((self.inner, out))
    }
}

impl<S: DepthSource, W: Write + Seek> DepthSource for Recording<S, W> {
    fn next_frame(&mut self, timeout: Duration) -> Result<DepthFrame<'_>, SourceError> {
        let frame = self.inner.next_frame(timeout)?;
        if let Some(writer) = self.writer.as_mut()
            && let Err(e) = writer.write(&frame)
        {
            tracing::error!("recording stopped: {e}");
            self.writer = None; // dropping finishes the file up to the last good frame
            self.error = Some(e);
        }
        Ok(frame)
    }

    fn intrinsics(&self) -> Intrinsics {
        self.inner.intrinsics()
    }

    fn describe(&self) -> String {
        format!("{} (recording)", self.inner.describe())
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;
    use crate::oni::OniReader;
    use crate::source::SourceErrorKind;

    fn source_file(frames: u32) -> Vec<u8> {
        let k = Intrinsics::from_fov(8, 6, 1.0, 0.8);
        let mut w = OniWriter::new(Cursor::new(Vec::new()), OniWriterConfig::new(&k, Codec::None)).unwrap();
        for i in 0..frames {
            let px: Vec<u16> = (0..48).map(|p| (p * 10 + i) as u16).collect();
            w.write_frame(&px, 100 + i as u64 * 33_333).unwrap();
        }
        w.finish().unwrap().into_inner()
    }

    #[test]
    fn records_what_passes_through() {
        let input = OniReader::new(Cursor::new(source_file(4)), "in").unwrap();
        let mut rec = Recording::new(input, Cursor::new(Vec::new()), Codec::Z16Table).unwrap();
        let mut seen = Vec::new();
        loop {
            match rec.next_frame(Duration::ZERO) {
                Ok(f) => seen.push((f.depth_mm().to_vec(), f.capture.as_us())),
                Err(e) => {
                    assert_eq!(e.kind(), SourceErrorKind::EndOfStream);
                    break;
                }
            }
        }
        assert_eq!(rec.frames_recorded(), 4);
        let (_, out) = rec.finish().unwrap();
        let mut copy = OniReader::new(Cursor::new(out.into_inner()), "copy").unwrap();
        assert_eq!(copy.info().codec, Codec::Z16Table);
        for (px, ts) in &seen {
            let f = copy.read_frame().unwrap();
            assert_eq!(f.depth_mm(), &px[..]);
            assert_eq!(f.capture.as_us(), *ts);
        }
        assert_eq!(
            copy.read_frame().unwrap_err().kind(),
            SourceErrorKind::EndOfStream
        );
    }
}
