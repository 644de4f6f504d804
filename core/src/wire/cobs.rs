//! Consistent Overhead Byte Stuffing (Cheshire & Baker 1999): removes every 0x00 from a frame so that 0x00 can
//! delimit frames. Costs one pass over the bytes and at most one extra byte per 254; decoding works in place.
//!
//! Written here rather than taken from postcard's accumulator so that every failure (a block running past the end,
//! a zero inside a frame) is an explicit, counted error and the buffer handling is in one place the fuzzer sees.

/// Bytes COBS may add to `n` bytes of input: one code byte per started block of 254.
pub(crate) const fn max_overhead(n: usize) -> usize {
    n / 254 + 1
}

/// COBS-encode `input` into `out` (no delimiter); the encoded length, or `None` if `out` is too small.
pub(crate) fn encode(input: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut code_at = 0usize;
    let mut w = 1usize;
    let mut code = 1u8;
    for &b in input {
        if b == 0 {
            *out.get_mut(code_at)? = code;
            code_at = w;
            w += 1;
            code = 1;
        } else {
            *out.get_mut(w)? = b;
            w += 1;
            code += 1;
            if code == 0xFF {
                *out.get_mut(code_at)? = code;
                code_at = w;
                w += 1;
                code = 1;
            }
        }
    }
    *out.get_mut(code_at)? = code;
    Some(w)
}

/// COBS-decode `buf` (one frame, no delimiter) in place; the decoded length, or `None` if the framing is broken.
///
/// The write index never passes the read index, so decoding in place is safe.
pub(crate) fn decode_in_place(buf: &mut [u8]) -> Option<usize> {
    let len = buf.len();
    let mut r = 0usize;
    let mut w = 0usize;
    while r < len {
        let code = *buf.get(r)?;
        if code == 0 {
            return None;
        }
        r += 1;
        let n = usize::from(code) - 1;
        let end = r.checked_add(n).filter(|&e| e <= len)?;
        if buf.get(r..end)?.contains(&0) {
            return None;
        }
        buf.copy_within(r..end, w);
        w += n;
        r = end;
        // A block shorter than 254 data bytes stands for its data plus a zero, except at the very end.
        if code != 0xFF && r < len {
            *buf.get_mut(w)? = 0;
            w += 1;
        }
    }
    Some(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(input: &[u8], expect: &[u8]) {
        let mut out = [0u8; 600];
        let n = encode(input, &mut out).unwrap();
        assert_eq!(&out[..n], expect);
        assert!(!out[..n].contains(&0));
        let d = decode_in_place(&mut out[..n]).unwrap();
        assert_eq!(&out[..d], input);
    }

    #[test]
    fn wikipedia_examples() {
        round_trip(&[], &[0x01]);
        round_trip(&[0x00], &[0x01, 0x01]);
        round_trip(&[0x00, 0x00], &[0x01, 0x01, 0x01]);
        round_trip(&[0x00, 0x11, 0x00], &[0x01, 0x02, 0x11, 0x01]);
        round_trip(&[0x11, 0x22, 0x00, 0x33], &[0x03, 0x11, 0x22, 0x02, 0x33]);
        round_trip(&[0x11, 0x00, 0x00, 0x00], &[0x02, 0x11, 0x01, 0x01, 0x01]);
    }

    #[test]
    fn long_runs() {
        let data: [u8; 254] = core::array::from_fn(|i| (i + 1) as u8);
        let mut expect = [0u8; 256];
        expect[0] = 0xFF;
        expect[1..255].copy_from_slice(&data);
        expect[255] = 0x01;
        round_trip(&data, &expect);
        let mut big = [0u8; 300];
        for (i, b) in big.iter_mut().enumerate() {
            *b = (i % 7) as u8;
        }
        let mut out = [0u8; 310];
        let n = encode(&big, &mut out).unwrap();
        assert!(n <= big.len() + max_overhead(big.len()));
        let d = decode_in_place(&mut out[..n]).unwrap();
        assert_eq!(&out[..d], &big[..]);
    }

    #[test]
    fn broken_framing_is_rejected() {
        assert_eq!(decode_in_place(&mut [0x05, 0x11, 0x22]), None);
        assert_eq!(decode_in_place(&mut [0x02, 0x00]), None);
        assert_eq!(decode_in_place(&mut [0x00]), None);
        assert_eq!(decode_in_place(&mut [0x03, 0x11, 0x00]), None);
    }

    #[test]
    fn small_output_is_an_error_not_a_panic() {
        let mut out = [0u8; 3];
        assert_eq!(encode(&[1, 2, 3, 4], &mut out), None);
        assert_eq!(encode(&[1, 2], &mut out), Some(3));
    }
}
