//! can-utils log lines, `(1436509052.249713) can0 123#0102030405060708`: what `candump -L` writes, `canplayer`
//! replays and `cantools decode` reads.
//!
//! Output: upper-case hex, 3 id digits for standard and 8 for extended ids, `R` (plus the DLC when not 0) for
//! remote frames, microsecond timestamps. Input also takes lower-case hex, `.` between data bytes (as can-utils
//! allows), and surrounding whitespace; CAN FD lines (`##`) are rejected as unsupported. One pass per line, no
//! allocation.

use core::fmt::{self, Write};

use super::can::{CanFrame, CanId, ExtendedId, StandardId};
use super::slcan::hex_val;

/// Why a line is not a candump log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum CandumpError {
    /// The `(seconds.fraction)` timestamp is missing or malformed.
    BadTimestamp,
    /// The interface name is missing or not printable ASCII.
    BadInterface,
    /// The id is not 3 or 8 hex digits, or out of range.
    BadId,
    /// The data is not an even number of hex digits up to 16, or the remote DLC is bad.
    BadData,
    /// A CAN FD frame (`##`): classic CAN only.
    Unsupported,
}

impl core::error::Error for CandumpError {}

impl fmt::Display for CandumpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CandumpError::BadTimestamp => "bad candump timestamp",
            CandumpError::BadInterface => "bad candump interface name",
            CandumpError::BadId => "bad candump CAN id",
            CandumpError::BadData => "bad candump data",
            CandumpError::Unsupported => "CAN FD candump lines are not supported",
        })
    }
}

/// A parsed candump log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CandumpLine<'a> {
    /// Log time, µs.
    pub timestamp_us: u64,
    /// Interface name as written (`can0`, `vcan0`, ...).
    pub interface: &'a str,
    /// The frame.
    pub frame: CanFrame,
}

/// Write `frame` as a candump log line (no newline) logged at `timestamp_us` on `interface`.
pub fn encode(frame: &CanFrame, timestamp_us: u64, interface: &str, out: &mut impl Write) -> fmt::Result {
    write!(
        out,
        "({}.{:06}) {} ",
        timestamp_us / 1_000_000,
        timestamp_us % 1_000_000,
        interface
    )?;
    match frame.id() {
        CanId::Standard(id) => write!(out, "{:03X}#", id.as_raw())?,
        CanId::Extended(id) => write!(out, "{:08X}#", id.as_raw())?,
    }
    if frame.is_remote() {
        out.write_char('R')?;
        if frame.dlc() != 0 {
            write!(out, "{}", frame.dlc())?;
        }
        return Ok(());
    }
    for b in frame.data() {
        write!(out, "{b:02X}")?;
    }
    Ok(())
}

fn parse_timestamp(t: &[u8]) -> Option<u64> {
    let dot = t.iter().position(|&b| b == b'.')?;
    let (sec, frac) = (t.get(..dot)?, t.get(dot + 1..)?);
    if sec.is_empty() || sec.len() > 12 || frac.is_empty() || frac.len() > 9 {
        return None;
    }
    let digits = |d: &[u8]| {
        d.iter().try_fold(0u64, |a, &c| {
            c.is_ascii_digit().then(|| a * 10 + u64::from(c - b'0'))
        })
    };
    let s = digits(sec)?;
    let mut us = digits(frac.get(..frac.len().min(6))?)?;
    for _ in frac.len()..6 {
        us *= 10;
    }
    digits(frac)?;
    s.checked_mul(1_000_000)?.checked_add(us)
}

fn parse_hex_id(d: &[u8]) -> Option<u32> {
    d.iter()
        .try_fold(0u32, |a, &c| Some((a << 4) | u32::from(hex_val(c)?)))
}

/// Parse one candump log line (surrounding whitespace, including `\r\n`, is ignored).
pub fn parse(line: &[u8]) -> Result<CandumpLine<'_>, CandumpError> {
    let line = line.trim_ascii();
    let mut parts = line.split(|&b| b == b' ' || b == b'\t').filter(|p| !p.is_empty());
    let ts = parts.next().ok_or(CandumpError::BadTimestamp)?;
    let ts = ts
        .strip_prefix(b"(")
        .and_then(|t| t.strip_suffix(b")"))
        .ok_or(CandumpError::BadTimestamp)?;
    let timestamp_us = parse_timestamp(ts).ok_or(CandumpError::BadTimestamp)?;
    let iface = parts.next().ok_or(CandumpError::BadInterface)?;
    if iface.len() > 15 || !iface.iter().all(|b| b.is_ascii_graphic()) {
        return Err(CandumpError::BadInterface);
    }
    let interface = core::str::from_utf8(iface).map_err(|_| CandumpError::BadInterface)?;
    let body = parts.next().ok_or(CandumpError::BadId)?;
    if parts.next().is_some() {
        return Err(CandumpError::BadData);
    }
    let hash = body.iter().position(|&b| b == b'#').ok_or(CandumpError::BadId)?;
    let (id_digits, data) = (
        body.get(..hash).unwrap_or(&[]),
        body.get(hash + 1..).unwrap_or(&[]),
    );
    if data.first() == Some(&b'#') {
        return Err(CandumpError::Unsupported);
    }
    let raw = parse_hex_id(id_digits).ok_or(CandumpError::BadId)?;
    let id = match id_digits.len() {
        3 => CanId::Standard(
            u16::try_from(raw)
                .ok()
                .and_then(StandardId::new)
                .ok_or(CandumpError::BadId)?,
        ),
        8 => CanId::Extended(ExtendedId::new(raw).ok_or(CandumpError::BadId)?),
        _ => return Err(CandumpError::BadId),
    };
    let frame = match data {
        [b'R' | b'r'] => CanFrame::new_remote(id, 0),
        [b'R' | b'r', d @ b'0'..=b'8'] => CanFrame::new_remote(id, d - b'0'),
        _ => {
            let mut bytes = [0u8; 8];
            let mut n = 0usize;
            let mut digits = data.iter().filter(|&&b| b != b'.');
            while let Some(&hi) = digits.next() {
                let lo = *digits.next().ok_or(CandumpError::BadData)?;
                let v = (hex_val(hi).ok_or(CandumpError::BadData)? << 4)
                    | hex_val(lo).ok_or(CandumpError::BadData)?;
                *bytes.get_mut(n).ok_or(CandumpError::BadData)? = v;
                n += 1;
            }
            CanFrame::new(id, bytes.get(..n).unwrap_or(&[]))
        }
    }
    .ok_or(CandumpError::BadData)?;
    Ok(CandumpLine {
        timestamp_us,
        interface,
        frame,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Buf {
        b: [u8; 64],
        n: usize,
    }

    impl Write for Buf {
        fn write_str(&mut self, s: &str) -> fmt::Result {
            let dst = self.b.get_mut(self.n..self.n + s.len()).ok_or(fmt::Error)?;
            dst.copy_from_slice(s.as_bytes());
            self.n += s.len();
            Ok(())
        }
    }

    fn enc(f: &CanFrame, t: u64) -> Buf {
        let mut b = Buf { b: [0; 64], n: 0 };
        encode(f, t, "can0", &mut b).unwrap();
        b
    }

    #[test]
    fn encodes_can_utils_format() {
        let id = CanId::Standard(StandardId::new(0x123).unwrap());
        let b = enc(&CanFrame::new(id, &[0x01, 0xAB]).unwrap(), 1_436_509_052_249_713);
        assert_eq!(&b.b[..b.n], b"(1436509052.249713) can0 123#01AB");
        let b = enc(&CanFrame::new(id, &[]).unwrap(), 5);
        assert_eq!(&b.b[..b.n], b"(0.000005) can0 123#");
        let ext = CanId::Extended(ExtendedId::new(0x1301).unwrap());
        let b = enc(&CanFrame::new_remote(ext, 3).unwrap(), 0);
        assert_eq!(&b.b[..b.n], b"(0.000000) can0 00001301#R3");
    }

    #[test]
    fn parses_variants() {
        let l = parse(b"(1436509052.249713) vcan0 120#2efb3702010859b0\r\n").unwrap();
        assert_eq!((l.timestamp_us, l.interface), (1_436_509_052_249_713, "vcan0"));
        assert_eq!(l.frame.data(), &[0x2E, 0xFB, 0x37, 0x02, 0x01, 0x08, 0x59, 0xB0]);
        assert_eq!(
            parse(b"(0.0) can0 123#11.22").unwrap().frame.data(),
            &[0x11, 0x22]
        );
        assert_eq!(parse(b"(1.5) can0 123#").unwrap().timestamp_us, 1_500_000);
        assert!(parse(b"(1.5) can0 123#R").unwrap().frame.is_remote());
        assert_eq!(parse(b"(1.5) can0 12345678#R8").unwrap().frame.dlc(), 8);
    }

    #[test]
    fn rejects_malformed() {
        assert_eq!(parse(b"can0 123#00").unwrap_err(), CandumpError::BadTimestamp);
        assert_eq!(
            parse(b"(1.x) can0 123#00").unwrap_err(),
            CandumpError::BadTimestamp
        );
        assert_eq!(parse(b"(1.0)").unwrap_err(), CandumpError::BadInterface);
        assert_eq!(parse(b"(1.0) can0 1234#00").unwrap_err(), CandumpError::BadId);
        assert_eq!(parse(b"(1.0) can0 800#00").unwrap_err(), CandumpError::BadId);
        assert_eq!(parse(b"(1.0) can0 123#001").unwrap_err(), CandumpError::BadData);
        assert_eq!(
            parse(b"(1.0) can0 123#001122334455667788").unwrap_err(),
            CandumpError::BadData
        );
        assert_eq!(
            parse(b"(1.0) can0 123##1").unwrap_err(),
            CandumpError::Unsupported
        );
        assert_eq!(parse(b"(1.0) can0 123#R9").unwrap_err(), CandumpError::BadData);
        assert_eq!(
            parse(b"(99999999999999.0) can0 123#").unwrap_err(),
            CandumpError::BadTimestamp
        );
    }
}
