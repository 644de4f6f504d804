//! The serial link over a real pty pair: raw mode (bytes 0x00, 0x0d, 0x11, 0x0a pass untouched both ways),
//! byte-exact COBS frames, messages both ways, reconnect after the device side disappears, and a seeded
//! fault-injection run whose sequence accounting on the receiving side is exact.

mod link_common;

use std::os::fd::AsFd;
use std::time::{Duration, Instant};

use link_common::{collect, numbered, serial_peer};
use supine_core::wire::serial::MAX_WIRE_LEN;
use supine_core::wire::{Kind, sample};
use supine_drivers::link::serial::{SerialCodec, SerialPort, open_pty, tty_mode};
use supine_drivers::link::{
    self, FaultyLink, Link, LinkFaultConfig, LinkOptions, LinkState, PacketLink, Port, SequenceAccounting,
};

fn serial_link(path: &std::path::Path) -> PacketLink<SerialPort, SerialCodec> {
    let port = SerialPort::open(path, 921_600).expect("open pty slave");
    PacketLink::new(path.display().to_string(), port, SerialCodec::new(), 32, true)
}

fn read_exact_from(port: &mut SerialPort, n: usize, timeout: Duration) -> Vec<u8> {
    let deadline = Instant::now() + timeout;
    let mut out = Vec::new();
    let mut buf = [0u8; 256];
    while out.len() < n && Instant::now() < deadline {
        let k = port.read(&mut buf);
        if k == 0 {
            port.wait_readable(Duration::from_millis(5));
        }
        out.extend_from_slice(&buf[..k]);
    }
    out
}

#[test]
fn raw_mode_survives_control_bytes_both_ways() {
    let pty = open_pty().unwrap();
    let slave_path = pty.slave_path.clone();
    let mut master = SerialPort::from_fd(pty.fd, "master").unwrap();
    let mut slave = SerialPort::open(&slave_path, 115_200).unwrap();

    let mode = slave.mode().expect("termios readable");
    assert!(
        mode.noncanonical && mode.no_echo && mode.no_input_translation && mode.no_output_processing,
        "{mode:?}"
    );
    assert!(mode.eight_n_one, "{mode:?}");
    assert_eq!(mode.baud, 115_200);

    // The exact sequence a cooked tty mangles: CR→NL, XON swallowed, echo, line buffering.
    let tricky = [
        0x41, 0x0d, 0x42, 0x11, 0x43, 0x0a, 0x00, 0x13, 0x03, 0x7f, 0x04, 0xff,
    ];
    assert_eq!(master.write(&tricky), tricky.len());
    assert_eq!(
        read_exact_from(&mut slave, tricky.len(), Duration::from_secs(2)),
        tricky
    );
    assert_eq!(slave.write(&tricky), tricky.len());
    assert_eq!(
        read_exact_from(&mut master, tricky.len(), Duration::from_secs(2)),
        tricky
    );
    // No echo came back to the writer.
    assert_eq!(
        read_exact_from(&mut slave, 1, Duration::from_millis(50)),
        Vec::<u8>::new()
    );
}

#[test]
fn non_standard_baud_goes_through_termios2() {
    let pty = open_pty().unwrap();
    let port = SerialPort::open(&pty.slave_path, 123_457).unwrap();
    assert_eq!(port.mode().unwrap().baud, 123_457);
    // The master end of a pty is a tty too; its mode is readable but is not ours to change.
    assert!(tty_mode(pty.fd.as_fd()).is_ok());
}

#[test]
fn frames_are_byte_exact() {
    let pty = open_pty().unwrap();
    let slave_path = pty.slave_path.clone();
    let mut master = SerialPort::from_fd(pty.fd, "master").unwrap();
    let mut link = serial_link(&slave_path);
    let mut expected = Vec::new();
    for m in sample::messages() {
        link.send(&m).unwrap();
        let mut buf = [0u8; MAX_WIRE_LEN];
        let n = m.encode_serial(&mut buf).unwrap();
        expected.extend_from_slice(&buf[..n]);
    }
    link.close(Duration::from_secs(1)).unwrap();
    assert_eq!(
        read_exact_from(&mut master, expected.len(), Duration::from_secs(2)),
        expected
    );
    assert_eq!(link.counters().sent, 7);
    assert_eq!(link.counters().sent_bytes, expected.len() as u64);
    assert_eq!(link.state(), LinkState::Ended);
}

#[test]
fn messages_flow_both_ways() {
    let mut peer = serial_peer();
    let mut link = serial_link(&peer.slave_path);
    for m in sample::messages() {
        link.send(&m).unwrap();
    }
    let got = collect(&mut peer.device, &mut link, 7, Duration::from_secs(3));
    assert_eq!(got, sample::messages());
    assert_eq!(peer.device.counters().rx_errors.total(), 0);

    // The arm controller's side: arm state and command back to the tracker.
    let incoming: Vec<_> = sample::messages()
        .into_iter()
        .filter(|m| matches!(m.kind(), Kind::ArmState | Kind::Command))
        .collect();
    for m in &incoming {
        peer.device.send(m).unwrap();
    }
    let got = collect(
        &mut link,
        &mut peer.device,
        incoming.len(),
        Duration::from_secs(3),
    );
    assert_eq!(got, incoming);
    assert_eq!(link.counters().rx_messages, incoming.len() as u64);
}

/// An idle line is not a hang-up: polling a port with nothing to read for a while must not disconnect it (with
/// `VMIN = 0` a tty read returns 0 for "no data", which once made the port reconnect every 50 ms and lose the frames
/// that arrived while it was closed), and a message arriving after the idle spell is received.
#[test]
fn an_idle_port_stays_up_and_loses_nothing() {
    let mut peer = serial_peer();
    let mut link = serial_link(&peer.slave_path);
    let idle_until = Instant::now() + Duration::from_millis(300);
    while Instant::now() < idle_until {
        assert_eq!(link.receive().unwrap(), None);
        link.wait_readable(Duration::from_millis(5));
    }
    assert_eq!(
        link.counters().disconnects,
        0,
        "an idle port was taken for a hang-up"
    );
    assert_eq!(link.state(), LinkState::Up);
    let m = sample::messages()[0];
    peer.device.send(&m).unwrap();
    let got = collect(&mut link, &mut peer.device, 1, Duration::from_secs(3));
    assert_eq!(got, vec![m]);
    assert_eq!(link.counters().disconnects, 0);
}

#[test]
fn garbage_is_counted_never_fatal() {
    let pty = open_pty().unwrap();
    let slave_path = pty.slave_path.clone();
    let mut master = SerialPort::from_fd(pty.fd, "master").unwrap();
    let mut link = serial_link(&slave_path);
    let mut noise = Vec::new();
    let mut x: u32 = 0x1234_5678;
    for _ in 0..4000 {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        noise.push(x as u8);
    }
    let mut frame = [0u8; MAX_WIRE_LEN];
    let n = sample::messages()[5].encode_serial(&mut frame).unwrap();
    noise.extend_from_slice(&frame[..n]);
    let mut off = 0;
    let deadline = Instant::now() + Duration::from_secs(3);
    let mut got = Vec::new();
    while Instant::now() < deadline && got.is_empty() {
        off += master.write(&noise[off..]);
        if let Some(m) = link.receive().unwrap() {
            got.push(m);
        }
    }
    assert_eq!(got, [sample::messages()[5]]);
    assert!(link.counters().rx_errors.total() > 0);
}

#[test]
fn reconnects_after_the_device_disappears() {
    let dir = std::env::temp_dir().join(format!("supine-link-reconnect-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let stable = dir.join("ttyARM");
    let first = serial_peer();
    std::os::unix::fs::symlink(&first.slave_path, &stable).unwrap();
    let mut peer = first;
    let mut link = serial_link(&stable);

    let m0 = numbered(0, 1);
    link.send(&m0).unwrap();
    assert_eq!(
        collect(&mut peer.device, &mut link, 1, Duration::from_secs(2)),
        [m0]
    );

    // Unplug: close the master. The link sees EIO, goes down and starts reconnecting.
    drop(peer);
    let deadline = Instant::now() + Duration::from_secs(2);
    while link.state() == LinkState::Up && Instant::now() < deadline {
        let _ = link.receive().unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
    assert_eq!(link.state(), LinkState::Reconnecting);
    assert_eq!(link.counters().disconnects, 1);

    // Sends while down are queued, newest wins.
    let m1 = numbered(0, 2);
    link.send(&m1).unwrap();

    // Plug in again: a new pty at the same path.
    let mut peer = serial_peer();
    std::fs::remove_file(&stable).unwrap();
    std::os::unix::fs::symlink(&peer.slave_path, &stable).unwrap();
    let got = collect(&mut peer.device, &mut link, 1, Duration::from_secs(5));
    assert_eq!(got, [m1], "the queued message goes out after the reconnect");
    assert_eq!(link.state(), LinkState::Up);
    let c = link.counters();
    assert_eq!((c.disconnects, c.reconnects), (1, 1));

    let m2 = numbered(3, 3);
    link.send(&m2).unwrap();
    assert_eq!(
        collect(&mut peer.device, &mut link, 1, Duration::from_secs(2)),
        [m2]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// 10 % of frames corrupted, 2 % dropped, stalls, and one forced disconnect of the serial port half way: nothing
/// panics, every damaged frame is caught, and on the receiving side received + lost (by sequence gaps) equals
/// exactly what the sender sent.
#[test]
fn fault_injection_accounting_is_exact() {
    const N: u16 = 600;
    let mut peer = serial_peer();
    // Hold a second slave fd open so the master never sees "no slave" (EIO) while the link reconnects.
    let _keep = SerialPort::open(&peer.slave_path, 115_200).unwrap();
    let config = LinkFaultConfig {
        seed: 0x5EED,
        drop: 0.02,
        corrupt: 0.10,
        stall: 0.01,
        stall_calls: 3,
        disconnect: 0.0,
        disconnect_at: Some(u64::from(N / 2)),
    };
    let mut link = FaultyLink::new(serial_link(&peer.slave_path), config);
    let mut acct = SequenceAccounting::new();
    let mut received = Vec::new();
    for seq in 0..N {
        if seq == N - 1 {
            // The last message must arrive for trailing losses to be visible.
            link.set_active(false);
        }
        link.send(&numbered(0, seq)).unwrap();
        // Drain the receiver as we go, like a real peer.
        while let Some(m) = peer.device.receive().unwrap() {
            assert_eq!(
                m,
                numbered(0, m.seq),
                "a damaged frame decoded into a wrong message"
            );
            acct.observe(&m);
            received.push(m.seq);
        }
        if seq % 2 == 0 {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    while received.last() != Some(&(N - 1)) && Instant::now() < deadline {
        link.poll();
        match peer.device.receive().unwrap() {
            Some(m) => {
                assert_eq!(
                    m,
                    numbered(0, m.seq),
                    "a damaged frame decoded into a wrong message"
                );
                acct.observe(&m);
                received.push(m.seq);
            }
            None => peer.device.wait_readable(Duration::from_millis(5)),
        }
    }
    let faults = link.faults();
    let tx = link.counters();
    let rx = peer.device.counters();
    eprintln!(
        "faults {faults:?}\ntx {tx:?}\nrx {rx:?}\nacct received {} lost {}",
        acct.received(),
        acct.lost()
    );
    assert_eq!(received.last(), Some(&(N - 1)), "the final clean message arrived");
    assert_eq!(
        acct.received() + acct.lost(),
        u64::from(N),
        "received + lost == sent"
    );
    assert_eq!(acct.out_of_order(), 0);
    assert!(
        faults.corrupted >= 30 && faults.dropped > 0 && faults.disconnects == 1,
        "{faults:?}"
    );
    assert_eq!((tx.disconnects, tx.reconnects), (1, 1));
    // The sender's own books balance: every message was sent, dropped on purpose, or evicted (newest wins while
    // the port was down).
    assert_eq!(faults.dropped + tx.dropped + tx.sent, u64::from(N), "{tx:?}");
    // Damage was caught by the CRC (or broke the framing), never decoded into a wrong message.
    assert!(rx.rx_errors.total() > 0, "{rx:?}");
    assert!(received.windows(2).all(|w| w[0] < w[1]));
    // What left the sender arrived either intact or as (at least one) counted receive error.
    assert_eq!(rx.rx_messages, acct.received());
    assert!(rx.rx_messages + rx.rx_errors.total() >= tx.sent, "{rx:?}");
}

#[test]
fn open_via_spec_string() {
    let mut peer = serial_peer();
    let spec = format!("serial:{}@57600", peer.slave_path.display());
    let mut link = link::open_str(&spec, &LinkOptions::default()).unwrap();
    assert_eq!(link.describe(), spec);
    let m = sample::messages()[0];
    link.send(&m).unwrap();
    let got = collect(&mut peer.device, &mut link, 1, Duration::from_secs(2));
    assert_eq!(got, [m]);
}
