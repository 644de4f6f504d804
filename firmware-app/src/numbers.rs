//! Parsers for counted arguments (`--frames`, `--count`): a number out of range says "out of range" and the allowed
//! range in plain decimals, the same way for every flag.

use std::fmt::Display;
use std::str::FromStr;

/// A count of at least 1 that fits a `u32`.
pub fn positive_u32(s: &str) -> Result<u32, String> {
    positive(s, u32::MAX)
}

/// A count of at least 1 that fits a `u64`.
pub fn positive_u64(s: &str) -> Result<u64, String> {
    positive(s, u64::MAX)
}

fn positive<T: FromStr + Display + PartialEq + From<u8>>(s: &str, max: T) -> Result<T, String> {
    let out_of_range = || format!("{s} is out of range (1 to {max})");
    let t = s.trim();
    if t.is_empty() || !t.bytes().all(|b| b.is_ascii_digit() || b == b'-' || b == b'+') {
        return Err(format!("{s} is not a whole number (1 to {max})"));
    }
    // Digits that do not fit, or a sign: the number is out of range rather than malformed.
    match t.parse::<T>() {
        Ok(v) if v == T::from(0) => Err(out_of_range()),
        Ok(v) => Ok(v),
        Err(_)
            if t.trim_start_matches(['+', '-'])
                .bytes()
                .all(|b| b.is_ascii_digit()) =>
        {
            Err(out_of_range())
        }
        Err(_) => Err(format!("{s} is not a whole number (1 to {max})")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_in_and_out_of_range() {
        assert_eq!(positive_u32("1"), Ok(1));
        assert_eq!(positive_u32("4294967295"), Ok(u32::MAX));
        assert_eq!(
            positive_u32("0"),
            Err("0 is out of range (1 to 4294967295)".into())
        );
        assert_eq!(
            positive_u32("4294967296"),
            Err("4294967296 is out of range (1 to 4294967295)".into())
        );
        assert_eq!(
            positive_u32("-3"),
            Err("-3 is out of range (1 to 4294967295)".into())
        );
        assert_eq!(
            positive_u64("0"),
            Err("0 is out of range (1 to 18446744073709551615)".into())
        );
        assert_eq!(
            positive_u32("ten"),
            Err("ten is not a whole number (1 to 4294967295)".into())
        );
    }
}
