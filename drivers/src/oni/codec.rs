//! The .oni depth codecs: `NONE` (raw little-endian u16), `16zP` (16z delta stream) and `16zT` (16z over an embedded
//! table of the frame's distinct values), byte-compatible with OpenNI2's `XnStreamCompression.cpp`.
//!
//! # The 16z stream
//! - The first value is a little-endian u16.
//! - Each next value is coded by `diff = prev - cur` (wrapping 16-bit). `|diff| <= 6` becomes a nibble `diff + 6`,
//!   two nibbles per byte, high nibble first.
//! - A pair of zero diffs (byte `0x66`) is run-length coded: byte `0xE0 + n` (n = 1..=15) stands for n such pairs.
//! - Otherwise an escape: nibble `F` (low nibble, after a pending high nibble) or byte `0xFF` (when no nibble is
//!   pending), followed by one byte `diff + 192` if `|diff| <= 63`, else the absolute value as a **big-endian** u16
//!   that must be `< 0x8000` (its top bit tells the two forms apart).
//! - A trailing odd nibble is padded with `0xD`.
//!
//! One deliberate difference from OpenNI's encoder: at the end of a frame OpenNI writes the padded odd nibble *before*
//! a pending zero-pair run, which decodes wrongly when the last diff is non-zero (its decoder plays the run after the
//! nibble). We flush the run first, which both decoders read correctly; every other byte is identical.
//!
//! # Cost
//! Encoding and decoding are one pass over the frame with no allocation: callers pass buffers allocated once
//! (`16zT` also needs a 65536-entry index table, see [`TableEncoder`]). Decoders check every read and write against
//! the buffer bounds and report malformed input as [`CodecError`], never panic.

use core::fmt;

/// Why a payload could not be encoded or decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CodecError {
    /// The payload ended in the middle of a code (offset of the code that was cut).
    Truncated(usize),
    /// The payload decodes to more values than the frame has.
    TooManyValues,
    /// The payload decodes to fewer values than the frame has (values decoded).
    TooFewValues(usize),
    /// A `16zT` table index points past the table.
    BadTableIndex(u16),
    /// A `16zT` value table runs past the end of the payload.
    BadTable,
    /// A value cannot be coded: 16z absolute values must be `< 0x8000`; `16zT` values must be `< max_value`.
    Unencodable {
        /// Pixel index of the value.
        pixel: usize,
        /// The value.
        value: u16,
    },
    /// A raw (`NONE`) payload has the wrong size (bytes).
    WrongRawSize(usize),
}

impl fmt::Display for CodecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CodecError::Truncated(at) => write!(f, "16z payload cut inside the code at byte {at}"),
            CodecError::TooManyValues => f.write_str("16z payload holds more pixels than the frame"),
            CodecError::TooFewValues(n) => write!(f, "16z payload holds only {n} pixels"),
            CodecError::BadTableIndex(i) => write!(f, "16zT table index {i} is past the table"),
            CodecError::BadTable => f.write_str("16zT value table is malformed"),
            CodecError::Unencodable { pixel, value } => {
                write!(
                    f,
                    "pixel {pixel} has value {value}, which this codec cannot store"
                )
            }
            CodecError::WrongRawSize(n) => write!(f, "raw depth payload has {n} bytes, not 2 per pixel"),
        }
    }
}

impl std::error::Error for CodecError {}

/// Encode `values` (at least one) as a 16z stream appended to `out`.
///
/// `out` should have capacity for `3 * values.len()` bytes to avoid growing. Fails if a value that needs the
/// absolute escape is `>= 0x8000`.
pub fn encode_16z(values: &[u16], out: &mut Vec<u8>) -> Result<(), CodecError> {
    encode_16z_mapped(values, Ok, out)
}

/// Encode `values` mapped through `map` (the 16zT table lookup) as a 16z stream.
fn encode_16z_mapped(
    values: &[u16],
    map: impl Fn(u16) -> Result<u16, u16>,
    out: &mut Vec<u8>,
) -> Result<(), CodecError> {
    let Some((&first_raw, rest)) = values.split_first() else {
        return Ok(());
    };
    let first = map(first_raw).map_err(|value| CodecError::Unencodable { pixel: 0, value })?;
    out.extend_from_slice(&first.to_le_bytes());
    let mut last = first;
    let mut staged: Option<u8> = None; // pending high nibble, already shifted
    let mut zero_pairs: u8 = 0;
    for (i, &raw) in rest.iter().enumerate() {
        let cur = map(raw).map_err(|value| CodecError::Unencodable { pixel: i + 1, value })?;
        let diff = last.wrapping_sub(cur) as i16;
        let abs = diff.unsigned_abs();
        if abs <= 6 {
            let nibble = (diff + 6) as u8;
            match staged.take() {
                None => staged = Some(nibble << 4),
                Some(high) => {
                    let byte = high | nibble;
                    if byte == 0x66 {
                        zero_pairs += 1;
                        if zero_pairs == 15 {
                            out.push(0xEF);
                            zero_pairs = 0;
                        }
                    } else {
                        if zero_pairs != 0 {
                            out.push(0xE0 + zero_pairs);
                            zero_pairs = 0;
                        }
                        out.push(byte);
                    }
                }
            }
        } else {
            if zero_pairs != 0 {
                out.push(0xE0 + zero_pairs);
                zero_pairs = 0;
            }
            out.push(match staged.take() {
                None => 0xFF,
                Some(high) => high | 0x0F,
            });
            if abs <= 63 {
                out.push((diff + 192) as u8);
            } else {
                if cur >= 0x8000 {
                    return Err(CodecError::Unencodable {
                        pixel: i + 1,
                        value: raw,
                    });
                }
                out.extend_from_slice(&cur.to_be_bytes());
            }
        }
        last = cur;
    }
    // Flush the run before the padded nibble (see the module doc for why this differs from OpenNI).
    if zero_pairs != 0 {
        out.push(0xE0 + zero_pairs);
    }
    if let Some(high) = staged {
        out.push(high | 0x0D);
    }
    Ok(())
}

/// Decode a 16z stream into `out`, which must be filled exactly; values pass through `map` (the 16zT table).
fn decode_16z_mapped(
    input: &[u8],
    out: &mut [u16],
    map: impl Fn(u16) -> Result<u16, CodecError>,
) -> Result<(), CodecError> {
    let (Some(&b0), Some(&b1)) = (input.first(), input.get(1)) else {
        return Err(CodecError::Truncated(0));
    };
    let mut last = u16::from_le_bytes([b0, b1]);
    let mut o = 0usize;
    let mut emit = |v: u16, o: &mut usize| -> Result<(), CodecError> {
        let slot = out.get_mut(*o).ok_or(CodecError::TooManyValues)?;
        *slot = map(v)?;
        *o += 1;
        Ok(())
    };
    emit(last, &mut o)?;
    let mut i = 2usize;
    // Reads the escape operand at `at`: returns the new value and the input position after it.
    let escape = |at: usize, last: u16| -> Result<(u16, usize), CodecError> {
        let c3 = *input.get(at).ok_or(CodecError::Truncated(at))?;
        if c3 & 0x80 != 0 {
            let diff = c3 as i16 - 192;
            Ok((last.wrapping_sub(diff as u16), at + 1))
        } else {
            let lo = *input.get(at + 1).ok_or(CodecError::Truncated(at))?;
            Ok((u16::from_be_bytes([c3, lo]), at + 2))
        }
    };
    while i < input.len() {
        let c = input[i];
        if c < 0xE0 {
            let d1 = (c >> 4) as i16 - 6;
            last = last.wrapping_sub(d1 as u16);
            emit(last, &mut o)?;
            let d2 = c & 0x0F;
            if d2 == 0x0F {
                let (v, next) = escape(i + 1, last)?;
                last = v;
                emit(last, &mut o)?;
                i = next;
            } else {
                if d2 != 0x0D {
                    last = last.wrapping_sub((d2 as i16 - 6) as u16);
                    emit(last, &mut o)?;
                }
                i += 1;
            }
        } else if c == 0xFF {
            let (v, next) = escape(i + 1, last)?;
            last = v;
            emit(last, &mut o)?;
            i = next;
        } else {
            for _ in 0..2 * (c - 0xE0) {
                emit(last, &mut o)?;
            }
            i += 1;
        }
    }
    if o != out.len() {
        return Err(CodecError::TooFewValues(o));
    }
    Ok(())
}

/// Decode a `16zP` payload into `out` (exactly `out.len()` pixels).
pub fn decode_16z(input: &[u8], out: &mut [u16]) -> Result<(), CodecError> {
    decode_16z_mapped(input, out, Ok)
}

/// Decode a `16zT` payload (`u16 K`, `K` sorted values, then the 16z stream of indices) into `out`.
pub fn decode_16z_table(input: &[u8], out: &mut [u16]) -> Result<(), CodecError> {
    let (Some(&k0), Some(&k1)) = (input.first(), input.get(1)) else {
        return Err(CodecError::Truncated(0));
    };
    let k = u16::from_le_bytes([k0, k1]) as usize;
    let table_end = 2 + 2 * k;
    let table = input.get(2..table_end).ok_or(CodecError::BadTable)?;
    let lookup = |idx: u16| -> Result<u16, CodecError> {
        let at = 2 * idx as usize;
        match (table.get(at), table.get(at + 1)) {
            (Some(&lo), Some(&hi)) => Ok(u16::from_le_bytes([lo, hi])),
            _ => Err(CodecError::BadTableIndex(idx)),
        }
    };
    decode_16z_mapped(&input[table_end..], out, lookup).map_err(|e| match e {
        CodecError::Truncated(at) => CodecError::Truncated(at + table_end),
        other => other,
    })
}

/// Append a raw `NONE` payload (little-endian u16) for `values` to `out`.
pub fn encode_raw(values: &[u16], out: &mut Vec<u8>) {
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// Decode a raw `NONE` payload into `out`; the payload must be exactly two bytes per pixel.
pub fn decode_raw(input: &[u8], out: &mut [u16]) -> Result<(), CodecError> {
    if input.len() != out.len() * 2 {
        return Err(CodecError::WrongRawSize(input.len()));
    }
    for (dst, src) in out.iter_mut().zip(input.chunks_exact(2)) {
        *dst = u16::from_le_bytes([src[0], src[1]]);
    }
    Ok(())
}

/// A `16zT` encoder: owns the 65536-entry value→index table so that encoding a frame allocates nothing.
pub struct TableEncoder {
    max_value: u16,
    index_of: Vec<u16>,
    present: Vec<bool>,
}

impl fmt::Debug for TableEncoder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TableEncoder")
            .field("max_value", &self.max_value)
            .finish()
    }
}

impl TableEncoder {
    /// An encoder for values `< max_value` (the file's `xnDeviceMaxDepth`, as OpenNI's `Xn16zEmbTablesCodec`).
    pub fn new(max_value: u16) -> Self {
        TableEncoder {
            max_value,
            index_of: vec![0; max_value as usize],
            present: vec![false; max_value as usize],
        }
    }

    /// Append the `16zT` payload of `values` to `out`; fails on a value `>= max_value`.
    pub fn encode(&mut self, values: &[u16], out: &mut Vec<u8>) -> Result<(), CodecError> {
        self.present.fill(false);
        for (pixel, &v) in values.iter().enumerate() {
            match self.present.get_mut(v as usize) {
                Some(p) => *p = true,
                None => return Err(CodecError::Unencodable { pixel, value: v }),
            }
        }
        let k_at = out.len();
        out.extend_from_slice(&[0, 0]);
        let mut k: u16 = 0;
        for (value, (&present, index)) in self.present.iter().zip(self.index_of.iter_mut()).enumerate() {
            if present {
                *index = k;
                k += 1;
                out.extend_from_slice(&(value as u16).to_le_bytes());
            }
        }
        out[k_at..k_at + 2].copy_from_slice(&k.to_le_bytes());
        let index_of = &self.index_of;
        encode_16z_mapped(values, |v| Ok(index_of[v as usize]), out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn round_trip_16z(values: &[u16]) {
        let mut enc = Vec::new();
        encode_16z(values, &mut enc).unwrap();
        let mut dec = vec![0u16; values.len()];
        decode_16z(&enc, &mut dec).unwrap();
        assert_eq!(dec, values);
    }

    #[test]
    fn hand_coded_stream() {
        // 1000, 1000 (diff 0 -> nibble 6), 997 (diff 3 -> 9): byte 0x69.
        // 1000 (diff -3 -> 3), 1040 (diff -40 -> escape F, byte 152).
        // 5000 (diff -3960 -> escape 0xFF, BE 0x1388), then 5000 x 4 (two zero pairs -> 0xE2).
        let values = [1000, 1000, 997, 1000, 1040, 5000, 5000, 5000, 5000, 5000];
        let mut enc = Vec::new();
        encode_16z(&values, &mut enc).unwrap();
        assert_eq!(enc, [0xE8, 0x03, 0x69, 0x3F, 152, 0xFF, 0x13, 0x88, 0xE2]);
        round_trip_16z(&values);
    }

    #[test]
    fn odd_tail_is_padded_and_runs_flush_first() {
        let mut enc = Vec::new();
        encode_16z(&[7, 7, 7, 8], &mut enc).unwrap();
        // one zero pair (E1), then diff -1 -> nibble 5 padded with D.
        assert_eq!(enc, [7, 0, 0xE1, 0x5D]);
        round_trip_16z(&[7, 7, 7, 8]);
    }

    #[test]
    fn fifteen_zero_pairs_make_ef() {
        let values = [42u16; 31];
        let mut enc = Vec::new();
        encode_16z(&values, &mut enc).unwrap();
        assert_eq!(enc, [42, 0, 0xEF]);
        round_trip_16z(&values);
    }

    #[test]
    fn escape_boundaries() {
        for d in [6i32, 7, -6, -7, 63, 64, -63, -64] {
            let b = (1000 + d) as u16;
            round_trip_16z(&[1000, b]);
            round_trip_16z(&[1000, 1000, b]);
        }
        // Absolute values up to 0x7FFF work; 0x8000 and above cannot use the absolute escape.
        round_trip_16z(&[0, 0x7FFF, 0]);
        let mut enc = Vec::new();
        assert_eq!(
            encode_16z(&[0, 0x8000], &mut enc),
            Err(CodecError::Unencodable {
                pixel: 1,
                value: 0x8000
            })
        );
        // ...but small steps around them wrap correctly, like OpenNI's int16 diffs.
        round_trip_16z(&[0x9000, 0x9003, 0x8FC4]);
        round_trip_16z(&[0xFFFF, 2, 0xFFFE]);
    }

    #[test]
    fn decoder_rejects_malformed_input() {
        let mut out = [0u16; 4];
        assert_eq!(decode_16z(&[1], &mut out), Err(CodecError::Truncated(0)));
        assert_eq!(decode_16z(&[1, 0, 0xFF], &mut out), Err(CodecError::Truncated(3)));
        assert_eq!(
            decode_16z(&[1, 0, 0x6F, 0x10], &mut out),
            Err(CodecError::Truncated(3))
        );
        assert_eq!(
            decode_16z(&[1, 0, 0xE2], &mut out),
            Err(CodecError::TooManyValues)
        );
        assert_eq!(
            decode_16z(&[1, 0, 0x66], &mut out),
            Err(CodecError::TooFewValues(3))
        );
        assert_eq!(
            decode_16z_table(&[2, 0, 5, 0], &mut out),
            Err(CodecError::BadTable)
        );
        assert_eq!(
            decode_16z_table(&[1, 0, 5, 0, 1, 0], &mut out),
            Err(CodecError::BadTableIndex(1))
        );
        assert_eq!(decode_raw(&[0; 7], &mut out), Err(CodecError::WrongRawSize(7)));
    }

    #[test]
    fn table_codec_hand_coded() {
        let mut enc = TableEncoder::new(10000);
        let mut out = Vec::new();
        enc.encode(&[900, 0, 900, 0], &mut out).unwrap();
        // K=2, table [0, 900], then indices 1,0,1,0: first 1 LE, diffs 1,-1,1 -> nibbles 7,5,7 -> 0x75, 0x7D.
        assert_eq!(out, [2, 0, 0, 0, 0x84, 0x03, 1, 0, 0x75, 0x7D]);
        let mut dec = [0u16; 4];
        decode_16z_table(&out, &mut dec).unwrap();
        assert_eq!(dec, [900, 0, 900, 0]);
        assert_eq!(
            enc.encode(&[1, 10000], &mut Vec::new()),
            Err(CodecError::Unencodable {
                pixel: 1,
                value: 10000
            })
        );
    }

    fn depth_like() -> impl Strategy<Value = Vec<u16>> {
        // Runs of near-constant depth, jumps of every size class, zeros (no depth), values near 0x8000.
        let step = prop_oneof![
            4 => -6i32..=6,
            2 => prop_oneof![Just(7i32), Just(-7), Just(63), Just(-63), Just(64), Just(-64)],
            1 => -3000i32..3000,
        ];
        (
            prop_oneof![0u16..12000, 0x7FC0u16..0x8000],
            proptest::collection::vec((step, 0usize..20, any::<bool>()), 1..60),
        )
            .prop_map(|(start, steps)| {
                let mut v = vec![start];
                let mut cur = start as i32;
                for (d, repeat, hole) in steps {
                    cur = (cur + d).clamp(0, 0x7FFF);
                    for _ in 0..=repeat {
                        v.push(if hole && repeat == 3 { 0 } else { cur as u16 });
                    }
                }
                v
            })
    }

    proptest! {
        #[test]
        fn z16_round_trips(values in depth_like()) {
            round_trip_16z(&values);
        }

        #[test]
        fn z16t_round_trips(values in depth_like()) {
            let mut enc = TableEncoder::new(u16::MAX);
            let mut out = Vec::new();
            enc.encode(&values, &mut out).unwrap();
            let mut dec = vec![0u16; values.len()];
            decode_16z_table(&out, &mut dec).unwrap();
            prop_assert_eq!(dec, values);
        }

        #[test]
        fn arbitrary_u16_round_trip_or_refuse(values in proptest::collection::vec(any::<u16>(), 1..200)) {
            let mut enc = Vec::new();
            match encode_16z(&values, &mut enc) {
                Ok(()) => {
                    let mut dec = vec![0u16; values.len()];
                    decode_16z(&enc, &mut dec).unwrap();
                    prop_assert_eq!(dec, values);
                }
                Err(CodecError::Unencodable { value, .. }) => prop_assert!(value >= 0x8000),
                Err(e) => prop_assert!(false, "unexpected {e}"),
            }
        }

        #[test]
        fn decoder_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..64), n in 1usize..40) {
            let mut out = vec![0u16; n];
            let _ = decode_16z(&bytes, &mut out);
            let _ = decode_16z_table(&bytes, &mut out);
        }
    }
}
