//! The SLCAN link over a real pty pair: the Lawicel open sequence, strict `t…\r` lines equal to the wire module's
//! CAN mapping, messages rebuilt from frame groups on the other side, adapter chatter ignored, damaged lines
//! counted, `C\r` on close, and fault injection with exact sequence accounting.

mod link_common;

use std::time::{Duration, Instant};

use link_common::{collect, numbered, pty_peer};
use supine_core::wire::can::CanBase;
use supine_core::wire::slcan::{self, MAX_LINE};
use supine_core::wire::{can_map, sample};
use supine_drivers::link::can::SlcanCodec;
use supine_drivers::link::serial::{SerialPort, open_pty};
use supine_drivers::link::{
    FaultyLink, Link, LinkFaultConfig, PacketLink, Port, RxError, SequenceAccounting,
};

fn slcan_link(path: &std::path::Path) -> PacketLink<SerialPort, SlcanCodec> {
    let port = SerialPort::open(path, 115_200).expect("open pty slave");
    PacketLink::new("slcan", port, SlcanCodec::new(500_000).unwrap(), 32, true)
}

fn read_all(port: &mut SerialPort, until: &[u8], timeout: Duration) -> Vec<u8> {
    let deadline = Instant::now() + timeout;
    let mut out = Vec::new();
    let mut buf = [0u8; 512];
    while !out.ends_with(until) && Instant::now() < deadline {
        let n = port.read(&mut buf);
        if n == 0 {
            port.wait_readable(Duration::from_millis(5));
        }
        out.extend_from_slice(&buf[..n]);
    }
    out
}

#[test]
fn open_sequence_lines_and_close_are_exact() {
    let pty = open_pty().unwrap();
    let slave = pty.slave_path.clone();
    let mut master = SerialPort::from_fd(pty.fd, "master").unwrap();
    let mut link = slcan_link(&slave);
    let mut expected = b"\rC\rS6\rO\r".to_vec();
    for m in sample::messages() {
        link.send(&m).unwrap();
        for frame in can_map::encode_group(&m, CanBase::DEFAULT).unwrap().iter() {
            let mut line = [0u8; MAX_LINE];
            let n = slcan::encode(frame, &mut line).unwrap();
            expected.extend_from_slice(&line[..n]);
        }
    }
    link.close(Duration::from_secs(1)).unwrap();
    expected.extend_from_slice(b"C\r");
    let got = read_all(
        &mut master,
        &expected[expected.len() - 4..],
        Duration::from_secs(2),
    );
    assert_eq!(String::from_utf8_lossy(&got), String::from_utf8_lossy(&expected));
    assert!(!got.contains(&b'\n'), "SLCAN lines must end in a bare CR");
}

#[test]
fn messages_flow_both_ways_and_open_sequence_is_not_an_error() {
    let mut peer = pty_peer(SlcanCodec::new(500_000).unwrap());
    let mut link = slcan_link(&peer.slave_path);
    for m in sample::messages() {
        link.send(&m).unwrap();
    }
    // The device side also sees our open sequence: commands, not frames, so not errors.
    let got = collect(&mut peer.device, &mut link, 7, Duration::from_secs(3));
    assert_eq!(got, sample::messages());
    let c = peer.device.counters();
    assert_eq!(c.rx_errors.total(), 0, "{c:?}");

    // Arm side back to the tracker.
    let arm = sample::messages()[5];
    let cmd = sample::messages()[6];
    peer.device.send(&arm).unwrap();
    peer.device.send(&cmd).unwrap();
    let got = collect(&mut link, &mut peer.device, 2, Duration::from_secs(3));
    assert_eq!(got, [arm, cmd]);
}

#[test]
fn junk_from_the_adapter_is_counted_not_fatal() {
    let pty = open_pty().unwrap();
    let slave = pty.slave_path.clone();
    let mut master = SerialPort::from_fd(pty.fd, "master").unwrap();
    let mut link = slcan_link(&slave);
    let arm = sample::messages()[5];
    let mut bytes = b"\r\rC\rS6\r\rO\rO\r\x07t12ZZ\rt7FF0\rT1ABCDEF0811223344\rV1013\r".to_vec();
    for frame in can_map::encode_group(&arm, CanBase::DEFAULT).unwrap().iter() {
        let mut line = [0u8; MAX_LINE];
        let n = slcan::encode(frame, &mut line).unwrap();
        bytes.extend_from_slice(&line[..n]);
    }
    assert_eq!(master.write(&bytes), bytes.len());
    let deadline = Instant::now() + Duration::from_secs(3);
    let mut got = None;
    while got.is_none() && Instant::now() < deadline {
        got = link.receive().unwrap();
        if got.is_none() {
            link.wait_readable(Duration::from_millis(5));
        }
    }
    assert_eq!(got, Some(arm));
    let c = link.counters();
    assert_eq!(c.rx_errors.get(RxError::Adapter), 1, "{c:?}");
    // `t12ZZ` and the extended line with the wrong digit count.
    assert_eq!(c.rx_errors.get(RxError::Syntax), 2, "{c:?}");
    assert_eq!(c.rx_foreign, 1, "t7FF0 is another node's frame: {c:?}");
}

#[test]
fn fault_injection_over_slcan_accounting_is_exact() {
    const N: u16 = 300;
    let mut peer = pty_peer(SlcanCodec::new(500_000).unwrap());
    let _keep = SerialPort::open(&peer.slave_path, 115_200).unwrap();
    let config = LinkFaultConfig {
        seed: 42,
        drop: 0.02,
        corrupt: 0.10,
        disconnect_at: Some(u64::from(N / 3)),
        ..LinkFaultConfig::default()
    };
    let mut link = FaultyLink::new(slcan_link(&peer.slave_path), config);
    let mut acct = SequenceAccounting::new();
    let mut last = None;
    let observe = |m: supine_core::wire::Message, acct: &mut SequenceAccounting| {
        assert_eq!(m, numbered(2, m.seq), "damaged frames must never decode");
        acct.observe(&m);
        m.seq
    };
    for seq in 0..N {
        if seq == N - 1 {
            link.set_active(false);
        }
        link.send(&numbered(2, seq)).unwrap();
        while let Some(m) = peer.device.receive().unwrap() {
            last = Some(observe(m, &mut acct));
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    while last != Some(N - 1) && Instant::now() < deadline {
        link.poll();
        match peer.device.receive().unwrap() {
            Some(m) => last = Some(observe(m, &mut acct)),
            None => peer.device.wait_readable(Duration::from_millis(5)),
        }
    }
    let faults = link.faults();
    let rx = peer.device.counters();
    assert_eq!(last, Some(N - 1));
    assert_eq!(
        acct.received() + acct.lost(),
        u64::from(N),
        "received + lost == sent; {faults:?} {rx:?}"
    );
    assert!(faults.corrupted > 10, "{faults:?}");
    // A changed data digit is a burst of at most 4 bits: CRC-8 catches every one.
    assert!(rx.rx_errors.get(RxError::Crc) >= 1, "{rx:?}");
    let tx = link.counters();
    assert_eq!(faults.dropped + tx.dropped + tx.sent, u64::from(N), "{tx:?}");
}
