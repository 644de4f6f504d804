//! Helpers shared by the link tests: pty pairs with a link on each end, and receive loops with deadlines.
#![allow(dead_code)]

use std::time::{Duration, Instant};

use supine_core::wire::{Message, sample};
use supine_drivers::link::serial::{PtyMaster, SerialCodec, SerialPort, open_pty};
use supine_drivers::link::{Codec, Link, PacketLink};

/// A pty pair: the slave path for the link under test, the master wrapped as the "device" side link.
pub struct PtyPeer<C> {
    /// Path of the slave end (what `serial:`/`slcan:` opens).
    pub slave_path: std::path::PathBuf,
    /// The master end as a link with codec `C`.
    pub device: PacketLink<SerialPort, C>,
}

/// A new pty whose master end is a link with `codec`.
pub fn pty_peer<C: Codec>(codec: C) -> PtyPeer<C> {
    let PtyMaster { fd, slave_path } = open_pty().expect("openpty (posix_openpt) failed");
    let port = SerialPort::from_fd(fd, "pty master").expect("pty master port");
    PtyPeer {
        slave_path,
        device: PacketLink::new("pty-master", port, codec, 256, true),
    }
}

/// A new pty whose master end speaks the serial framing.
pub fn serial_peer() -> PtyPeer<SerialCodec> {
    pty_peer(SerialCodec::new())
}

/// Receive from `link` until `want` messages arrived or `timeout` passed, polling `other` (the sender) too.
pub fn collect(link: &mut dyn Link, other: &mut dyn Link, want: usize, timeout: Duration) -> Vec<Message> {
    let deadline = Instant::now() + timeout;
    let mut got = Vec::new();
    while got.len() < want && Instant::now() < deadline {
        other.poll();
        match link.receive() {
            Ok(Some(m)) => got.push(m),
            Ok(None) => link.wait_readable(Duration::from_millis(5)),
            Err(e) => panic!("receive failed: {e}"),
        }
    }
    got
}

/// The sample message `i % 7` with sequence number `seq`.
pub fn numbered(i: usize, seq: u16) -> Message {
    let mut m = sample::messages()[i % 7];
    m.seq = seq;
    m
}
