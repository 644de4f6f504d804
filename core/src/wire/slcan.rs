//! SLCAN (Lawicel ASCII) frame lines, as serial CAN adapters and python-can's `slcan` interface speak them.
//!
//! Output is strict: `t` + 3 hex id + DLC digit + data, or `T` + 8 hex id (extended), `r`/`R` for remote frames;
//! upper-case hex; terminated by a single `\r` (never `\r\n`: python-can 4.6 prefixes a stray `\n` to the next
//! line and drops that frame). Input is tolerant where no ambiguity arises: lower-case hex, a trailing `\r`
//! and/or `\n`, and a 4-digit Lawicel timestamp (`Z1` mode) after the data, which is returned. Everything else
//! (bad hex, an id out of range, a DLC above 8, too few or too many digits) is an error, never a panic.
//! Cost per line: one pass over at most 31 bytes; [`SlcanReader`] holds one line in a fixed buffer.

use super::can::{CanFrame, CanId, ExtendedId, StandardId};

/// Longest line [`encode`] writes: `T` + 8 id digits + DLC + 16 data digits + `\r`.
pub const MAX_LINE: usize = 1 + 8 + 1 + 16 + 1;

/// Why a line is not an SLCAN frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum SlcanError {
    /// The line is another SLCAN command or reply (`z`, `V1013`, ...), not a frame.
    NotAFrame(u8),
    /// The id has bad hex digits or is out of range.
    BadId,
    /// The DLC is not a digit 0..=8.
    BadDlc,
    /// A data or timestamp digit is not hex.
    BadHex,
    /// The number of digits after the DLC is neither 2·DLC nor 2·DLC + 4.
    BadLength,
    /// The line is longer than the reader's buffer.
    LineTooLong,
    /// The adapter sent BEL (`\a`): it rejected a command.
    DeviceError,
}

impl core::error::Error for SlcanError {}

impl core::fmt::Display for SlcanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SlcanError::NotAFrame(c) => write!(f, "not a frame line (command byte 0x{c:02X})"),
            SlcanError::BadId => f.write_str("bad SLCAN id"),
            SlcanError::BadDlc => f.write_str("bad SLCAN DLC"),
            SlcanError::BadHex => f.write_str("bad hex digit in SLCAN line"),
            SlcanError::BadLength => f.write_str("SLCAN data length does not match the DLC"),
            SlcanError::LineTooLong => f.write_str("SLCAN line too long"),
            SlcanError::DeviceError => f.write_str("SLCAN adapter signalled an error (BEL)"),
        }
    }
}

/// A parsed SLCAN frame line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlcanFrame {
    /// The frame.
    pub frame: CanFrame,
    /// The adapter's timestamp in ms (0..=0xEA5F when the adapter counts a minute), if the line had one.
    pub timestamp_ms: Option<u16>,
}

const HEX: &[u8; 16] = b"0123456789ABCDEF";

pub(crate) fn hex_val(b: u8) -> Option<u8> {
    match b {
        b'0'..=b'9' => Some(b - b'0'),
        b'A'..=b'F' => Some(b - b'A' + 10),
        b'a'..=b'f' => Some(b - b'a' + 10),
        _ => None,
    }
}

fn parse_hex(digits: &[u8]) -> Option<u32> {
    if digits.is_empty() || digits.len() > 8 {
        return None;
    }
    digits
        .iter()
        .try_fold(0u32, |acc, &d| Some((acc << 4) | u32::from(hex_val(d)?)))
}

struct Writer<'a> {
    out: &'a mut [u8],
    n: usize,
}

impl Writer<'_> {
    fn byte(&mut self, b: u8) -> Option<()> {
        *self.out.get_mut(self.n)? = b;
        self.n += 1;
        Some(())
    }

    fn hex(&mut self, v: u32, digits: u32) -> Option<()> {
        for i in (0..digits).rev() {
            self.byte(*HEX.get(((v >> (4 * i)) & 0xF) as usize)?)?;
        }
        Some(())
    }
}

/// Write `frame` as one `\r`-terminated SLCAN line into `out`; the length, or `None` if `out` is too small
/// ([`MAX_LINE`] always suffices).
pub fn encode(frame: &CanFrame, out: &mut [u8]) -> Option<usize> {
    let mut w = Writer { out, n: 0 };
    let (cmd, digits) = match (frame.id(), frame.is_remote()) {
        (CanId::Standard(_), false) => (b't', 3),
        (CanId::Standard(_), true) => (b'r', 3),
        (CanId::Extended(_), false) => (b'T', 8),
        (CanId::Extended(_), true) => (b'R', 8),
    };
    w.byte(cmd)?;
    w.hex(frame.id().raw(), digits)?;
    w.hex(u32::from(frame.dlc()), 1)?;
    for &b in frame.data() {
        w.hex(u32::from(b), 2)?;
    }
    w.byte(b'\r')?;
    Some(w.n)
}

/// Parse one SLCAN line (with or without its terminator).
pub fn parse(line: &[u8]) -> Result<SlcanFrame, SlcanError> {
    let mut line = line;
    while let [rest @ .., b'\r' | b'\n'] = line {
        line = rest;
    }
    let (&cmd, rest) = line.split_first().ok_or(SlcanError::NotAFrame(b'\r'))?;
    let (extended, remote) = match cmd {
        b't' => (false, false),
        b'T' => (true, false),
        b'r' => (false, true),
        b'R' => (true, true),
        other => return Err(SlcanError::NotAFrame(other)),
    };
    let id_len = if extended { 8 } else { 3 };
    let id_digits = rest.get(..id_len).ok_or(SlcanError::BadId)?;
    let raw = parse_hex(id_digits).ok_or(SlcanError::BadId)?;
    let id = if extended {
        CanId::Extended(ExtendedId::new(raw).ok_or(SlcanError::BadId)?)
    } else {
        CanId::Standard(
            u16::try_from(raw)
                .ok()
                .and_then(StandardId::new)
                .ok_or(SlcanError::BadId)?,
        )
    };
    let rest = rest.get(id_len..).unwrap_or(&[]);
    let (&dlc_digit, rest) = rest.split_first().ok_or(SlcanError::BadDlc)?;
    let dlc = match dlc_digit {
        b'0'..=b'8' => dlc_digit - b'0',
        _ => return Err(SlcanError::BadDlc),
    };
    let data_digits = if remote { 0 } else { 2 * usize::from(dlc) };
    let data_hex = rest.get(..data_digits).ok_or(SlcanError::BadLength)?;
    let mut data = [0u8; 8];
    for (dst, pair) in data.iter_mut().zip(data_hex.chunks_exact(2)) {
        let (hi, lo) = match pair {
            [h, l] => (hex_val(*h), hex_val(*l)),
            _ => (None, None),
        };
        *dst = (hi.ok_or(SlcanError::BadHex)? << 4) | lo.ok_or(SlcanError::BadHex)?;
    }
    let timestamp_ms = match rest.get(data_digits..).unwrap_or(&[]) {
        [] => None,
        ts @ [_, _, _, _] => Some(parse_hex(ts).ok_or(SlcanError::BadHex)? as u16),
        _ => return Err(SlcanError::BadLength),
    };
    let frame = if remote {
        CanFrame::new_remote(id, dlc)
    } else {
        CanFrame::new(id, data.get(..usize::from(dlc)).unwrap_or(&[]))
    }
    .ok_or(SlcanError::BadDlc)?;
    Ok(SlcanFrame { frame, timestamp_ms })
}

/// Counters of what an [`SlcanReader`] has seen. Each counter saturates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SlcanStats {
    /// Frame lines parsed.
    pub frames: u32,
    /// Lines that were other commands or replies (not errors for a monitor, but not frames either).
    pub not_frames: u32,
    /// Frame lines that did not parse (bad id, DLC, hex or length).
    pub bad_lines: u32,
    /// Lines longer than the buffer (discarded to the next terminator).
    pub too_long: u32,
    /// BEL bytes from the adapter.
    pub device_errors: u32,
}

impl SlcanStats {
    /// All errors together (`not_frames` excluded).
    pub fn errors(&self) -> u32 {
        self.bad_lines
            .saturating_add(self.too_long)
            .saturating_add(self.device_errors)
    }
}

/// Splits an SLCAN byte stream into lines (`\r`, `\n` or BEL terminated) and parses them; `N` bytes per line.
#[derive(Debug, Clone)]
pub struct SlcanReader<const N: usize = 40> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
    stats: SlcanStats,
}

impl<const N: usize> Default for SlcanReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> SlcanReader<N> {
    /// An empty reader.
    pub const fn new() -> Self {
        SlcanReader {
            buf: [0; N],
            len: 0,
            overflow: false,
            stats: SlcanStats {
                frames: 0,
                not_frames: 0,
                bad_lines: 0,
                too_long: 0,
                device_errors: 0,
            },
        }
    }

    /// What the reader has seen so far.
    pub const fn stats(&self) -> &SlcanStats {
        &self.stats
    }

    /// Take one byte; a frame or error when it ended a non-empty line.
    pub fn push(&mut self, byte: u8) -> Option<Result<SlcanFrame, SlcanError>> {
        let st = &mut self.stats;
        match byte {
            b'\r' | b'\n' | 0x07 => {
                let len = core::mem::replace(&mut self.len, 0);
                let overflowed = core::mem::replace(&mut self.overflow, false);
                // BEL is the adapter's error reply; count it even when it ends an over-long line.
                if byte == 0x07 {
                    st.device_errors = st.device_errors.saturating_add(1);
                    return Some(Err(SlcanError::DeviceError));
                }
                if overflowed {
                    return None;
                }
                if len == 0 {
                    return None;
                }
                let result = parse(self.buf.get(..len).unwrap_or(&[]));
                let c = match result {
                    Ok(_) => &mut st.frames,
                    Err(SlcanError::NotAFrame(_)) => &mut st.not_frames,
                    Err(_) => &mut st.bad_lines,
                };
                *c = c.saturating_add(1);
                Some(result)
            }
            _ if self.overflow => None,
            _ => match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                    None
                }
                None => {
                    self.len = 0;
                    self.overflow = true;
                    st.too_long = st.too_long.saturating_add(1);
                    Some(Err(SlcanError::LineTooLong))
                }
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn std_id(raw: u16) -> CanId {
        CanId::Standard(StandardId::new(raw).unwrap())
    }

    fn line(frame: &CanFrame) -> ([u8; MAX_LINE], usize) {
        let mut out = [0u8; MAX_LINE];
        let n = encode(frame, &mut out).unwrap();
        (out, n)
    }

    #[test]
    fn encodes_upper_case_with_cr() {
        let f = CanFrame::new(std_id(0x321), &[1, 2, 3, 4, 5, 6, 7, 0xAB]).unwrap();
        let (out, n) = line(&f);
        assert_eq!(&out[..n], &b"t321801020304050607AB\r"[..]);
        let ext = CanFrame::new(
            CanId::Extended(ExtendedId::new(0x18FF50E5).unwrap()),
            &[0x20, 0x0F],
        )
        .unwrap();
        let (out, n) = line(&ext);
        assert_eq!(&out[..n], &b"T18FF50E52200F\r"[..]);
        let rtr = CanFrame::new_remote(std_id(0x100), 2).unwrap();
        let (out, n) = line(&rtr);
        assert_eq!(&out[..n], &b"r1002\r"[..]);
        assert_eq!(encode(&f, &mut [0u8; 10]), None);
    }

    #[test]
    fn parses_what_python_can_accepts() {
        let f = parse(b"t1238DEADBEEF00112233").unwrap().frame;
        assert_eq!(
            (f.id().raw(), f.data()),
            (0x123, &[0xDE, 0xAD, 0xBE, 0xEF, 0x00, 0x11, 0x22, 0x33][..])
        );
        let f = parse(b"T1ABCDEF081122334455667788\r").unwrap().frame;
        assert_eq!(f.id(), CanId::Extended(ExtendedId::new(0x1ABCDEF0).unwrap()));
        assert_eq!(parse(b"t7FF0").unwrap().frame.dlc(), 0);
        assert!(parse(b"r1002").unwrap().frame.is_remote());
        let lower = parse(b"t3212ffff\r\n").unwrap();
        assert_eq!(lower.frame.data(), &[0xFF, 0xFF]);
        assert_eq!(lower.timestamp_ms, None);
        let stamped = parse(b"t3212FFFF1234").unwrap();
        assert_eq!(
            (stamped.frame.data(), stamped.timestamp_ms),
            (&[0xFF, 0xFF][..], Some(0x1234))
        );
    }

    #[test]
    fn rejects_what_python_can_chokes_on() {
        assert_eq!(parse(b"t12ZZ"), Err(SlcanError::BadId));
        assert_eq!(parse(b"t123Z"), Err(SlcanError::BadDlc));
        assert_eq!(parse(b"t1232ZZ00"), Err(SlcanError::BadHex));
        assert_eq!(parse(b"t1234AABB"), Err(SlcanError::BadLength));
        assert_eq!(parse(b"t1239AABB"), Err(SlcanError::BadDlc));
        assert_eq!(parse(b"t8001AA"), Err(SlcanError::BadId));
        assert_eq!(parse(b"T2000000001AA"), Err(SlcanError::BadId));
        assert_eq!(parse(b"t1231AAB"), Err(SlcanError::BadLength));
        assert_eq!(parse(b"z"), Err(SlcanError::NotAFrame(b'z')));
        assert_eq!(parse(b""), Err(SlcanError::NotAFrame(b'\r')));
        assert_eq!(parse(b"t12"), Err(SlcanError::BadId));
    }

    #[test]
    fn reader_splits_and_counts() {
        let mut r: SlcanReader = SlcanReader::new();
        let mut frames = 0;
        for &b in b"\rt1230\rz\rt12ZZ\r\x07t1232AABB\n".iter() {
            if let Some(Ok(_)) = r.push(b) {
                frames += 1;
            }
        }
        assert_eq!(frames, 2);
        let s = r.stats();
        assert_eq!(
            (s.frames, s.not_frames, s.bad_lines, s.device_errors),
            (2, 1, 1, 1)
        );
        let mut small: SlcanReader<5> = SlcanReader::new();
        let events: usize = b"t1232AABB\rt1230\r"
            .iter()
            .filter_map(|&b| small.push(b))
            .count();
        assert_eq!(events, 1 + 1);
        assert_eq!(small.stats().too_long, 1);
        assert_eq!(small.stats().frames, 1);
        // An adapter error (BEL) that ends an over-long line is still counted.
        let mut small: SlcanReader<5> = SlcanReader::new();
        let errors = b"t1232AABB\x07"
            .iter()
            .filter_map(|&b| small.push(b))
            .filter(|e| *e == Err(SlcanError::DeviceError))
            .count();
        assert_eq!((errors, small.stats().device_errors), (1, 1));
    }
}
