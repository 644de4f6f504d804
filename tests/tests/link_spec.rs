//! Link specs and open errors through the public API: every CLI form parses, bad strings name the bad part, and
//! devices that are missing give clear, typed errors rather than panics.

use supine_drivers::link::{self, Error, FileMode, LinkErrorKind, LinkOptions, LinkSpec, LinkState};

#[test]
fn every_cli_form_parses() {
    for (text, kind) in [
        ("stdout", "stdout"),
        ("serial:/dev/ttyUSB0", "serial"),
        ("serial:/dev/ttyUSB0@921600", "serial"),
        ("slcan:/dev/ttyACM0@115200", "slcan"),
        ("can:can0", "can"),
        ("file:/tmp/capture.cobs", "file"),
    ] {
        let spec: LinkSpec = text.parse().unwrap_or_else(|e| panic!("{text}: {e}"));
        assert_eq!(spec.kind_name(), kind);
    }
}

#[test]
fn bad_specs_are_invalid_spec_errors_naming_the_part() {
    for (text, needle) in [
        ("serial:/dev/x@9k6", "9k6"),
        ("udp:1234", "udp"),
        ("can:", "empty"),
    ] {
        let err = link::open_str(text, &LinkOptions::default()).err().expect(text);
        assert_eq!(err.kind(), LinkErrorKind::InvalidSpec, "{text}");
        assert!(err.to_string().contains(needle), "{text}: {err}");
    }
}

#[test]
fn missing_serial_device_is_not_found() {
    let err = link::open_str("serial:/dev/does-not-exist-supine", &LinkOptions::default())
        .err()
        .unwrap();
    assert_eq!(err.kind(), LinkErrorKind::NotFound);
    assert!(err.to_string().contains("/dev/does-not-exist-supine"), "{err}");
}

#[test]
fn a_regular_file_is_not_a_serial_port() {
    let dir = std::env::temp_dir().join(format!("supine-link-spec-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("plain.txt");
    std::fs::write(&path, b"x").unwrap();
    let err = link::open_str(&format!("serial:{}", path.display()), &LinkOptions::default())
        .err()
        .unwrap();
    assert!(err.to_string().contains("not a terminal"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// This kernel has no SocketCAN (`CONFIG_CAN` unset: `socket(AF_CAN)` fails with EAFNOSUPPORT). On a kernel with
/// CAN but without a `vcan0`, the error is a missing interface instead. Either way: NotFound, clear words, no panic.
#[test]
fn socketcan_open_error_is_clear() {
    match link::open_str("can:vcan0", &LinkOptions::default()) {
        Err(err) => {
            assert_eq!(err.kind(), LinkErrorKind::NotFound, "{err}");
            let text = err.to_string();
            assert!(
                text.contains("this kernel has no SocketCAN support")
                    || text.contains("no network interface named"),
                "{text}"
            );
            assert!(text.contains("can:vcan0"), "{text}");
        }
        Ok(link) => {
            // A machine with a vcan0: the link must at least be up.
            assert_eq!(link.state(), LinkState::Up);
        }
    }
}

#[test]
fn stdout_cannot_receive() {
    let mut link = link::open_str("stdout", &LinkOptions::default()).unwrap();
    assert_eq!(link.receive().unwrap_err().kind(), LinkErrorKind::Unsupported);
}

#[test]
fn slcan_bitrate_must_be_standard() {
    let options = LinkOptions {
        can_bitrate: 123_456,
        ..LinkOptions::default()
    };
    let err = link::open_str("slcan:/dev/null", &options).err().unwrap();
    assert_eq!(err.kind(), LinkErrorKind::InvalidSpec);
    assert!(err.to_string().contains("123456"), "{err}");
}

#[test]
fn file_link_writes_a_capture_that_reads_back() {
    use supine_core::wire::sample;
    let dir = std::env::temp_dir().join(format!("supine-link-file-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("capture.cobs");
    let spec = format!("file:{}", path.display());
    let mut out = link::open_str(&spec, &LinkOptions::default()).unwrap();
    for m in sample::messages() {
        out.send(&m).unwrap();
    }
    out.close(std::time::Duration::from_secs(1)).unwrap();
    assert_eq!(out.counters().sent, 7);

    // Byte-exact: the capture is the concatenation of the serial frames.
    let mut expected = Vec::new();
    for m in sample::messages() {
        let mut buf = [0u8; supine_core::wire::serial::MAX_WIRE_LEN];
        let n = m.encode_serial(&mut buf).unwrap();
        expected.extend_from_slice(&buf[..n]);
    }
    assert_eq!(std::fs::read(&path).unwrap(), expected);

    let mut back = link::open_str(
        &spec,
        &LinkOptions {
            file_mode: FileMode::Read,
            ..LinkOptions::default()
        },
    )
    .unwrap();
    let mut got = Vec::new();
    while let Some(m) = back.receive().unwrap() {
        got.push(m);
    }
    assert_eq!(got, sample::messages());
    assert_eq!(back.receive().unwrap(), None);
    assert_eq!(back.state(), LinkState::Ended);
    assert_eq!(back.counters().rx_errors.total(), 0);
    std::fs::remove_dir_all(&dir).unwrap();
}
