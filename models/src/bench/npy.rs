//! Minimal NumPy `.npy` (format 1.0, little-endian, C order) writer for the benchmark problems that Python peers
//! read; f32, f64, i16 and u16 arrays only. Cost: one write of the array.

use anyhow::{Context, Result, ensure};
use std::io::Write;
use std::path::Path;

/// An element type `.npy` can name.
pub trait NpyElem: Copy {
    /// The NumPy `descr` string.
    const DESCR: &'static str;
    /// Little-endian bytes of one element.
    fn put(self, out: &mut Vec<u8>);
}

impl NpyElem for f32 {
    const DESCR: &'static str = "<f4";
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl NpyElem for f64 {
    const DESCR: &'static str = "<f8";
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl NpyElem for i16 {
    const DESCR: &'static str = "<i2";
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

impl NpyElem for u16 {
    const DESCR: &'static str = "<u2";
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

/// The `.npy` bytes of `data` with `shape` (the product of `shape` must be `data.len()`).
pub fn to_bytes<T: NpyElem>(shape: &[usize], data: &[T]) -> Result<Vec<u8>> {
    ensure!(
        shape.iter().product::<usize>() == data.len(),
        "npy: shape {shape:?} does not hold {} elements",
        data.len()
    );
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {tuple}, }}",
        T::DESCR
    );
    // Magic (6) + version (2) + length (2) + header + '\n' is padded to a multiple of 64 bytes.
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + data.len() * 4);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for &x in data {
        x.put(&mut out);
    }
    Ok(out)
}

/// Write `data` with `shape` to `path` as `.npy`.
pub fn write<T: NpyElem>(path: &Path, shape: &[usize], data: &[T]) -> Result<()> {
    let bytes = to_bytes(shape, data)?;
    let mut f = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    f.write_all(&bytes)
        .with_context(|| format!("writing {}", path.display()))
}

/// Write rows of 3-vectors as an `(n, 3)` f32 array.
pub fn write_points(path: &Path, rows: &[[f32; 3]]) -> Result<()> {
    let flat: Vec<f32> = rows.iter().flatten().copied().collect();
    write(path, &[rows.len(), 3], &flat)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_aligned_and_names_shape() {
        let b = to_bytes(&[2, 3], &[1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        assert_eq!(&b[..8], b"\x93NUMPY\x01\x00");
        let hl = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + hl) % 64, 0);
        let h = std::str::from_utf8(&b[10..10 + hl]).unwrap();
        assert!(h.contains("'shape': (2, 3)") && h.contains("'<f4'") && h.ends_with('\n'));
        assert_eq!(b.len(), 10 + hl + 24);
        assert_eq!(&b[10 + hl..10 + hl + 4], &1.0f32.to_le_bytes());
        let one = to_bytes(&[3], &[1u16, 2, 3]).unwrap();
        assert!(std::str::from_utf8(&one[10..]).unwrap().contains("(3,)"));
        assert!(to_bytes(&[2, 2], &[1.0f32]).is_err());
    }
}
