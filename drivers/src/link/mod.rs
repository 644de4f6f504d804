//! Packet links: carry `supine_core::wire` messages to and from the arm controller over a serial port (COBS
//! frames), an SLCAN adapter, SocketCAN, a capture file or stdout, without ever blocking the frame loop.
//!
//! # For pipeline authors
//! Open a link once with [`open`] from a [`LinkSpec`] string, then per frame:
//! - [`Link::send`] encodes a message into a pre-allocated slot of a bounded queue and writes what the device
//!   takes now (non-blocking). When the queue is full the **newest message wins**: the oldest message not yet
//!   started is dropped and counted in [`LinkCounters::dropped`].
//! - [`Link::receive`] returns one decoded incoming message (arm state, command, or any other valid message) or
//!   `None`; call it until `None`. It also drives the writer and reconnects.
//! - If a frame sends nothing, call [`Link::poll`] once so queued bytes keep flowing.
//!
//! # Timing
//! There is no background thread: the writer runs inside `send`/`poll`/`receive`. Each call costs one encode
//! (a few µs) plus at most a few non-blocking `write(2)`/`read(2)` syscalls; nothing sleeps or waits. Bytes the
//! device cannot take yet wait in the queue (default 32 messages) and go out on the next call, so at 30 Hz a
//! message waits at most one frame longer than the line needs to carry it. A 115200-baud UART carries ~380 bytes
//! per 33 ms frame; a pose, probe report and health message fit, the salient points and body shape are spread by
//! the queue. Only [`Link::close`] (flush with a deadline) and [`Link::wait_readable`] block, by design.
//!
//! # Reconnects
//! A serial port that hangs up, returns EIO or end of file is closed and reopened at the same path with
//! exponential back-off (50 ms doubling to 2 s), counted in [`LinkCounters::disconnects`]/`reconnects`. After
//! each (re)connect the codec's preamble goes out first (the SLCAN open sequence; serial frames need none, since
//! each starts with its own `0x00`), the partly written message restarts from its first byte, and the decoder is reset.
//!
//! # Allocation
//! Everything is allocated in [`open`]: queue slots, the receive buffer, the preamble buffer. `send` and
//! `receive` allocate nothing (errors on these paths carry `&'static str`).

mod backoff;
pub mod can;
pub mod codec;
mod error;
pub mod fault;
pub mod file;
pub mod port;
mod queue;
pub mod seq;
pub mod serial;
pub mod signal;
mod spec;

use std::time::{Duration, Instant};

use supine_core::wire::Message;

pub use backoff::{Backoff, INITIAL_DELAY as RECONNECT_INITIAL_DELAY, MAX_DELAY as RECONNECT_MAX_DELAY};
pub use codec::{Codec, Decoded, Framing, RxError, RxErrorCounts};
pub use error::{Error, LinkError, LinkErrorKind, kind_of_io};
pub use fault::{FaultCounters, FaultyLink, LinkFaultConfig};
pub use file::FileMode;
pub use port::{LinkState, Port, PortCounters};
pub use queue::TxQueue;
pub use seq::SequenceAccounting;
pub use spec::{DEFAULT_BAUD, LinkSpec, MAX_IFACE_LEN};

/// Messages the transmit queue holds by default.
pub const DEFAULT_QUEUE_CAPACITY: usize = 32;
/// Receive buffer size: one read takes at most this many bytes.
pub const RX_BUFFER_BYTES: usize = 4096;
/// Most port reads one `receive` call makes before returning `None`, bounding its time under a flood.
pub const MAX_READS_PER_RECEIVE: usize = 16;

/// Counters every link keeps; cheap to copy, for periodic reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkCounters {
    /// Messages accepted by `send` (queued).
    pub queued: u64,
    /// Messages completely handed to the device.
    pub sent: u64,
    /// Bytes handed to the device (including preambles).
    pub sent_bytes: u64,
    /// Messages dropped: evicted from a full queue (newest wins) or left unsent at close.
    pub dropped: u64,
    /// Messages that could not be encoded (value out of range of a CAN signal, too large).
    pub encode_errors: u64,
    /// Units received: serial frames, CAN frames, SLCAN lines, good or bad.
    pub rx_frames: u64,
    /// Messages decoded.
    pub rx_messages: u64,
    /// Receive errors by class.
    pub rx_errors: RxErrorCounts,
    /// CAN frames of other nodes (outside the supine id block): not errors.
    pub rx_foreign: u64,
    /// Times the device went away.
    pub disconnects: u64,
    /// Successful reopens after a disconnect.
    pub reconnects: u64,
    /// Failed reopen attempts.
    pub reconnect_failures: u64,
    /// Other I/O errors (counted and survived).
    pub io_errors: u64,
    /// CAN bus-off reports.
    pub bus_off: u64,
    /// Faults injected by a [`FaultyLink`] wrapper (zero otherwise).
    pub faults: FaultCounters,
}

/// The encoded bytes of one message, lent to a tamper hook before they are queued (fault injection, tests).
#[derive(Debug)]
pub struct Encoded<'a> {
    /// What the bytes are.
    pub framing: Framing,
    /// The bytes; they may be edited in place but not resized.
    pub bytes: &'a mut [u8],
}

/// A hook that edits a message's encoded bytes before they are queued.
pub type Tamper<'a> = &'a mut dyn FnMut(&mut Encoded<'_>);

/// A bidirectional, non-blocking packet link to the arm controller (see the module docs for timing).
pub trait Link {
    /// Encode `msg` and queue it (newest wins when the queue is full), letting `tamper` edit the encoded bytes
    /// first. Writes nothing; [`Link::send`] is `enqueue` + [`Link::poll`].
    fn enqueue(&mut self, msg: &Message, tamper: Option<Tamper<'_>>) -> Result<(), LinkError>;

    /// Queue `msg` and write what the device takes now. Never blocks. Fails only if the message cannot be
    /// encoded (kind [`LinkErrorKind::Encode`]) or the link was closed.
    fn send(&mut self, msg: &Message) -> Result<(), LinkError> {
        self.enqueue(msg, None)?;
        self.poll();
        Ok(())
    }

    /// Drive reconnects and the writer. Never blocks.
    fn poll(&mut self);

    /// The next decoded incoming message, or `None` if none is complete now. Never blocks; damaged input is
    /// counted in [`LinkCounters::rx_errors`], never returned as an error. Fails only on a send-only link
    /// ([`LinkErrorKind::Unsupported`]).
    fn receive(&mut self) -> Result<Option<Message>, LinkError>;

    /// Block up to `timeout` until input may be available (for idle loops such as `supine wire listen`; never
    /// call it in the frame loop).
    fn wait_readable(&mut self, timeout: Duration);

    /// The counters so far.
    fn counters(&self) -> LinkCounters;

    /// Where the link stands.
    fn state(&self) -> LinkState;

    /// Drop the connection now; it comes back with back-off like after an unplug (fault injection, operator).
    fn disconnect(&mut self);

    /// Flush the queue for up to `timeout`, send the framing's close sequence (SLCAN `C\r`), and release the
    /// device. Messages still queued at the deadline are counted as dropped and the result is
    /// [`LinkErrorKind::Timeout`]. Blocks; call it once at shutdown.
    fn close(&mut self, timeout: Duration) -> Result<(), LinkError>;

    /// The framing of this link's bytes.
    fn framing(&self) -> Framing;

    /// A description for logs: the spec string it was opened from.
    fn describe(&self) -> &str;

    /// The first OS error a write failed with, in words (`No space left on device (os error 28)`), if any: a send
    /// path that failed is reported once, by the caller, instead of per retry.
    fn last_io_error(&self) -> Option<String> {
        None
    }
}

impl<L: Link + ?Sized> Link for Box<L> {
    fn enqueue(&mut self, msg: &Message, tamper: Option<Tamper<'_>>) -> Result<(), LinkError> {
        (**self).enqueue(msg, tamper)
    }
    fn send(&mut self, msg: &Message) -> Result<(), LinkError> {
        (**self).send(msg)
    }
    fn poll(&mut self) {
        (**self).poll()
    }
    fn receive(&mut self) -> Result<Option<Message>, LinkError> {
        (**self).receive()
    }
    fn wait_readable(&mut self, timeout: Duration) {
        (**self).wait_readable(timeout)
    }
    fn counters(&self) -> LinkCounters {
        (**self).counters()
    }
    fn state(&self) -> LinkState {
        (**self).state()
    }
    fn disconnect(&mut self) {
        (**self).disconnect()
    }
    fn close(&mut self, timeout: Duration) -> Result<(), LinkError> {
        (**self).close(timeout)
    }
    fn framing(&self) -> Framing {
        (**self).framing()
    }
    fn describe(&self) -> &str {
        (**self).describe()
    }
    fn last_io_error(&self) -> Option<String> {
        (**self).last_io_error()
    }
}

/// The one link implementation: a [`Port`] (bytes or frames) under a [`Codec`] (messages), with the bounded
/// transmit queue, the receive buffer and the counters.
#[derive(Debug)]
pub struct PacketLink<P, C> {
    name: String,
    port: P,
    codec: C,
    queue: TxQueue,
    preamble: Vec<u8>,
    preamble_written: usize,
    rx_buf: Box<[u8]>,
    rx_start: usize,
    rx_end: usize,
    receives: bool,
    counters: LinkCounters,
    epoch: Instant,
    closed: bool,
}

impl<P: Port, C: Codec> PacketLink<P, C> {
    /// A link named `name` over `port` with `codec` and a queue of `queue_capacity` messages. `receives` is false
    /// for send-only links (stdout, a capture being written).
    pub fn new(name: impl Into<String>, port: P, codec: C, queue_capacity: usize, receives: bool) -> Self {
        let slot = codec.max_encoded_len();
        PacketLink {
            name: name.into(),
            port,
            codec,
            queue: TxQueue::new(queue_capacity, slot),
            preamble: Vec::with_capacity(64),
            preamble_written: 0,
            rx_buf: vec![0u8; RX_BUFFER_BYTES].into_boxed_slice(),
            rx_start: 0,
            rx_end: 0,
            receives,
            counters: LinkCounters::default(),
            epoch: Instant::now(),
            closed: false,
        }
    }

    /// The port underneath (for tests and `supine info`).
    pub fn port(&self) -> &P {
        &self.port
    }

    /// Messages waiting in the transmit queue.
    pub fn queued_len(&self) -> usize {
        self.queue.len()
    }

    fn service(&mut self) {
        if self.closed {
            return;
        }
        if self.port.maintain(Instant::now()) {
            self.preamble.clear();
            self.codec.preamble(&mut self.preamble);
            self.preamble_written = 0;
            self.queue.rewind_front();
            self.codec.reset_rx();
            self.rx_start = 0;
            self.rx_end = 0;
        }
        self.pump_tx();
    }

    fn pump_tx(&mut self) {
        let unit = self.port.unit();
        // Bounded: each iteration writes at least one unit or stops.
        for _ in 0..256 {
            if self.preamble_written < self.preamble.len() {
                let n = self.port.write(&self.preamble[self.preamble_written..]);
                if n == 0 {
                    return;
                }
                self.preamble_written += n;
                self.counters.sent_bytes += n as u64;
                continue;
            }
            let Some(front) = self.queue.front() else { return };
            let chunk = if unit > 1 {
                &front[..unit.min(front.len())]
            } else {
                front
            };
            let n = self.port.write(chunk);
            if n == 0 {
                return;
            }
            self.counters.sent_bytes += n as u64;
            if self.queue.advance(n) {
                self.counters.sent += 1;
            }
        }
    }

    fn now_us(&self) -> u64 {
        self.epoch.elapsed().as_micros() as u64
    }
}

impl<P: Port, C: Codec> Link for PacketLink<P, C> {
    fn enqueue(&mut self, msg: &Message, tamper: Option<Tamper<'_>>) -> Result<(), LinkError> {
        if self.closed {
            return Err(LinkError::new(
                LinkErrorKind::Disconnected,
                "send on a closed link",
            ));
        }
        let framing = self.codec.framing();
        let codec = &mut self.codec;
        let result = self.queue.push_with(|slot| {
            codec.encode(msg, slot)?;
            if let Some(tamper) = tamper {
                tamper(&mut Encoded {
                    framing,
                    bytes: slot.as_mut_slice(),
                });
            }
            Ok::<(), LinkError>(())
        });
        match result {
            Ok(()) => {
                self.counters.queued += 1;
                Ok(())
            }
            Err(e) => {
                self.counters.encode_errors += 1;
                Err(e)
            }
        }
    }

    fn poll(&mut self) {
        self.service();
    }

    fn receive(&mut self) -> Result<Option<Message>, LinkError> {
        if !self.receives {
            return Err(LinkError::new(LinkErrorKind::Unsupported, "this link only sends"));
        }
        self.service();
        if self.closed {
            return Ok(None);
        }
        let now_us = self.now_us();
        let mut reads = 0;
        loop {
            let (used, out) = self
                .codec
                .decode(&self.rx_buf[self.rx_start..self.rx_end], now_us);
            self.rx_start += used.min(self.rx_end - self.rx_start);
            match out {
                Decoded::NeedMore => {
                    // The decoder keeps what it needs of a partial unit; the buffer is free again.
                    self.rx_start = 0;
                    self.rx_end = 0;
                    if reads == MAX_READS_PER_RECEIVE {
                        return Ok(None);
                    }
                    reads += 1;
                    let unit = self.port.unit();
                    let want = if unit > 1 { unit } else { self.rx_buf.len() };
                    let n = self.port.read(&mut self.rx_buf[..want]);
                    if n == 0 {
                        return Ok(None);
                    }
                    self.rx_end = n;
                }
                Decoded::Unit => self.counters.rx_frames += 1,
                Decoded::Ignored => {}
                Decoded::Foreign => {
                    self.counters.rx_frames += 1;
                    self.counters.rx_foreign += 1;
                }
                Decoded::Error(e) => {
                    self.counters.rx_frames += 1;
                    self.counters.rx_errors.add(e);
                }
                Decoded::Message(m) => {
                    self.counters.rx_frames += 1;
                    self.counters.rx_messages += 1;
                    return Ok(Some(m));
                }
            }
        }
    }

    fn wait_readable(&mut self, timeout: Duration) {
        if self.rx_start < self.rx_end {
            return;
        }
        self.port.wait_readable(timeout);
    }

    fn counters(&self) -> LinkCounters {
        let p = self.port.counters();
        LinkCounters {
            dropped: self.counters.dropped + self.queue.evicted(),
            disconnects: p.disconnects,
            reconnects: p.reconnects,
            reconnect_failures: p.reconnect_failures,
            io_errors: p.io_errors,
            bus_off: p.bus_off,
            ..self.counters
        }
    }

    fn state(&self) -> LinkState {
        if self.closed {
            LinkState::Ended
        } else {
            self.port.state()
        }
    }

    fn disconnect(&mut self) {
        self.port.disconnect();
    }

    fn close(&mut self, timeout: Duration) -> Result<(), LinkError> {
        if self.closed {
            return Ok(());
        }
        let deadline = Instant::now() + timeout;
        let mut result = Ok(());
        loop {
            self.service();
            if self.queue.is_empty() && self.preamble_written >= self.preamble.len() {
                break;
            }
            let now = Instant::now();
            if now >= deadline || self.port.state() == LinkState::Ended {
                let left = self.queue.clear();
                self.counters.dropped += left as u64;
                result = Err(LinkError::new(
                    LinkErrorKind::Timeout,
                    "closing link: queue not flushed before the deadline",
                ));
                break;
            }
            self.port
                .wait_writable((deadline - now).min(Duration::from_millis(10)));
        }
        let mut tail = std::mem::take(&mut self.preamble);
        tail.clear();
        self.codec.postamble(&mut tail);
        let mut written = 0;
        while written < tail.len() && self.port.state() == LinkState::Up {
            let n = self.port.write(&tail[written..]);
            written += n;
            self.counters.sent_bytes += n as u64;
            let now = Instant::now();
            if n == 0 {
                if now >= deadline {
                    break;
                }
                self.port
                    .wait_writable((deadline - now).min(Duration::from_millis(10)));
            }
        }
        self.port
            .drain(deadline.saturating_duration_since(Instant::now()));
        self.port.shutdown();
        self.closed = true;
        result
    }

    fn framing(&self) -> Framing {
        self.codec.framing()
    }

    fn describe(&self) -> &str {
        &self.name
    }

    fn last_io_error(&self) -> Option<String> {
        self.port.write_error().map(str::to_owned)
    }
}

/// Options of [`open`] beyond the spec string.
#[derive(Clone, Debug)]
pub struct LinkOptions {
    /// Transmit queue capacity in messages.
    pub queue_capacity: usize,
    /// Whether a `file:` link writes a capture or reads one.
    pub file_mode: FileMode,
    /// CAN bit rate for the SLCAN open sequence (`Sn`), bit/s.
    pub can_bitrate: u32,
}

impl Default for LinkOptions {
    fn default() -> Self {
        LinkOptions {
            queue_capacity: DEFAULT_QUEUE_CAPACITY,
            file_mode: FileMode::Write,
            can_bitrate: 500_000,
        }
    }
}

/// Open the link a spec names. Errors name the spec and the failing step; a kernel without SocketCAN gives
/// [`LinkErrorKind::NotFound`] with that said in words.
pub fn open(spec: &LinkSpec, options: &LinkOptions) -> Result<Box<dyn Link + Send>, LinkError> {
    let name = spec.to_string();
    let cap = options.queue_capacity;
    Ok(match spec {
        LinkSpec::Stdout => Box::new(PacketLink::new(
            name,
            file::StdoutPort::new(),
            serial::SerialCodec::new(),
            cap,
            false,
        )),
        LinkSpec::File { path } => {
            let port = file::FilePort::open(path, options.file_mode)?;
            let receives = options.file_mode == FileMode::Read;
            Box::new(PacketLink::new(
                name,
                port,
                serial::SerialCodec::new(),
                cap,
                receives,
            ))
        }
        LinkSpec::Serial { path, baud } => {
            let port = serial::SerialPort::open(path, *baud)?;
            Box::new(PacketLink::new(name, port, serial::SerialCodec::new(), cap, true))
        }
        LinkSpec::Slcan { path, baud } => {
            let codec = can::SlcanCodec::new(options.can_bitrate)?;
            let port = serial::SerialPort::open(path, *baud)?;
            Box::new(PacketLink::new(name, port, codec, cap, true))
        }
        LinkSpec::Can { iface } => {
            let port = can::socketcan::SocketCanPort::open(iface)?;
            Box::new(PacketLink::new(name, port, can::SocketCanCodec::new(), cap, true))
        }
    })
}

/// Parse a spec string and [`open`] it.
pub fn open_str(spec: &str, options: &LinkOptions) -> Result<Box<dyn Link + Send>, LinkError> {
    open(&spec.parse()?, options)
}
