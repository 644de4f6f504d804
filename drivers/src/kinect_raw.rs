//! Kinect v1 raw depth: bit unpacking (V4L2 `Y10B`, libfreenect 11-bit packed) and disparity→millimetre conversion.
//!
//! # Formats
//! - `Y10B` (gspca_kinect in depth mode, kernel doc `pixfmt-y10b.rst`): an MSB-first bit stream of 10-bit values,
//!   4 pixels in 5 bytes, 800 bytes per 640-pixel line. [`unpack_y10b`].
//! - 11-bit packed (libfreenect `FREENECT_DEPTH_11BIT_PACKED`, `convert_packed11_to_16bit` in `src/cameras.c`): MSB
//!   first, 8 pixels in 11 bytes. [`unpack_11bit`].
//!
//! # Raw → mm
//! The 11-bit value is the PS1080 "shift" (disparity), and the official conversion is [`Ps1080Params::shift_to_mm`]
//! (`XnShiftToDepth.cpp` = libfreenect `freenect_raw_to_mm`); 2047 means no measurement.
//!
//! The 10-bit value V4L2 delivers is a coarser, **undocumented** disparity: neither the kernel nor libfreenect gives a
//! conversion. Disparity is affine in inverse depth, so we model `1 / z = a · raw + b` and calibrate `a`, `b` per
//! device ([`DisparityCalibration::fit`]). How to calibrate (also in `drivers/README.md`):
//! 1. Point the Kinect straight at a flat wall; measure the wall distance `z` (tape or laser meter, metres, along the
//!    optical axis) at three or more distances spanning the working range (e.g. 0.8, 1.2, 1.6, 2.0 m).
//! 2. At each distance record the median raw value of a central patch (`supine record --source v4l2:/dev/videoN`
//!    with the nominal curve, then invert it, or read raw frames directly).
//! 3. Fit `a`, `b` by least squares on `1/z` with [`DisparityCalibration::fit`]; the residual RMS tells the quality.
//! 4. Store the two coefficients in the config as the string `"a,b"` (`DisparityCalibration`'s `Display`/`FromStr`,
//!    e.g. `v4l2_calibration = "-0.0061422,3.33095"`); [`DisparityTable`] expands them into a 1024-entry lookup table
//!    at open.
//!
//! Without a calibration the V4L2 source uses [`DisparityCalibration::NOMINAL_10BIT`], which assumes the 10-bit
//! value is the 11-bit shift halved (the kinect register 0x12 selects 10 vs 11 bit output) and uses the OpenKinect
//! fit `1/z = -0.0030711016 · raw11 + 3.3309495161`. It is an assumption, not a measurement: calibrate.
//!
//! # Cost
//! Unpacking is a few shifts per pixel; conversion is one table lookup per pixel. Nothing allocates except building a
//! table (once, at open).

use std::fmt;
use std::str::FromStr;

/// Bytes of one 640x480 `Y10B` frame (800 bytes per line).
pub const Y10B_FRAME_BYTES: usize = 640 * 480 * 10 / 8;
/// Bytes of one 640x480 11-bit packed frame.
pub const PACKED11_FRAME_BYTES: usize = 640 * 480 * 11 / 8;
/// The 11-bit raw value that marks "no measurement".
pub const RAW11_NO_VALUE: u16 = 2047;
/// The depth limit of the conversions: they return less than this, anything else is 0 (no depth), like libfreenect's
/// clamp; it is also the .oni writer's max depth, which 16zT needs every value to stay under.
pub const MAX_DEPTH_MM: u16 = 10_000;

/// Unpack `Y10B` (4 pixels per 5 bytes, MSB first) into `out`; unpacks `min(out.len(), packed.len() * 4 / 5)` pixels
/// in whole groups of 4 and returns how many.
pub fn unpack_y10b(packed: &[u8], out: &mut [u16]) -> usize {
    let mut n = 0;
    for (b, o) in packed.chunks_exact(5).zip(out.chunks_exact_mut(4)) {
        let (b0, b1, b2, b3, b4) = (b[0] as u16, b[1] as u16, b[2] as u16, b[3] as u16, b[4] as u16);
        o[0] = (b0 << 2) | (b1 >> 6);
        o[1] = ((b1 & 0x3F) << 4) | (b2 >> 4);
        o[2] = ((b2 & 0x0F) << 6) | (b3 >> 2);
        o[3] = ((b3 & 0x03) << 8) | b4;
        n += 4;
    }
    n
}

/// Unpack 11-bit packed depth (8 pixels per 11 bytes, MSB first) into `out`; returns the pixels unpacked.
pub fn unpack_11bit(packed: &[u8], out: &mut [u16]) -> usize {
    let mut n = 0;
    for (r, o) in packed.chunks_exact(11).zip(out.chunks_exact_mut(8)) {
        let r: [u16; 11] = core::array::from_fn(|i| r[i] as u16);
        o[0] = (r[0] << 3) | (r[1] >> 5);
        o[1] = ((r[1] << 6) | (r[2] >> 2)) & 0x7FF;
        o[2] = ((r[2] << 9) | (r[3] << 1) | (r[4] >> 7)) & 0x7FF;
        o[3] = ((r[4] << 4) | (r[5] >> 4)) & 0x7FF;
        o[4] = ((r[5] << 7) | (r[6] >> 1)) & 0x7FF;
        o[5] = ((r[6] << 10) | (r[7] << 2) | (r[8] >> 6)) & 0x7FF;
        o[6] = ((r[8] << 5) | (r[9] >> 3)) & 0x7FF;
        o[7] = ((r[9] << 8) | r[10]) & 0x7FF;
        n += 8;
    }
    n
}

/// The PS1080 shift→depth parameters (per device; libfreenect reads them with `freenect_fetch_zero_plane_info`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ps1080Params {
    /// Zero-plane distance, mm (ZPD).
    pub zpd: f64,
    /// Zero-plane pixel size, mm (ZPPS).
    pub zpps: f64,
    /// Emitter to depth-CMOS distance, cm (LDDIS).
    pub lddis: f64,
    /// Constant shift offset (ConstShift).
    pub const_shift: f64,
    /// Parameter coefficient (ParamCoeff).
    pub param_coeff: f64,
    /// Shift scale (ShiftScale).
    pub shift_scale: f64,
    /// Pixel size factor (PSF; 1 at VGA).
    pub pixel_size_factor: f64,
}

impl Ps1080Params {
    /// Typical Kinect v1 values (reference §4): ZPD 120, ZPPS 0.1042, LDDIS 7.5, ConstShift 200, ParamCoeff 4,
    /// ShiftScale 10, PSF 1.
    pub const TYPICAL: Ps1080Params = Ps1080Params {
        zpd: 120.0,
        zpps: 0.1042,
        lddis: 7.5,
        const_shift: 200.0,
        param_coeff: 4.0,
        shift_scale: 10.0,
        pixel_size_factor: 1.0,
    };

    /// Depth in mm for an 11-bit shift; `None` for "no value" (2047) or shifts that map outside (0, 10000] mm.
    pub fn shift_to_mm(&self, raw: u16) -> Option<f64> {
        if raw >= RAW11_NO_VALUE {
            return None;
        }
        let x = (raw as f64 - self.param_coeff * self.const_shift / self.pixel_size_factor)
            / self.param_coeff
            - 0.375;
        let m = x * self.zpps * self.pixel_size_factor;
        if m >= self.lddis {
            return None;
        }
        let mm = self.shift_scale * (m * self.zpd / (self.lddis - m) + self.zpd);
        // Strictly below: 16zT recordings (and OpenNI2) need every value under the stream's max depth.
        (mm > 0.0 && mm < MAX_DEPTH_MM as f64).then_some(mm)
    }

    /// The 2048-entry shift→mm table (0 = no depth) for per-pixel conversion of 11-bit frames.
    pub fn table(&self) -> Vec<u16> {
        (0..2048u16)
            .map(|raw| self.shift_to_mm(raw).map_or(0, |mm| mm.round() as u16))
            .collect()
    }
}

/// Calibration of an uncalibrated disparity (V4L2 10-bit): inverse depth `1 / z[m] = a · raw + b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisparityCalibration {
    /// Slope, 1/m per raw unit (negative for the Kinect: depth grows with raw).
    pub a: f64,
    /// Intercept, 1/m.
    pub b: f64,
}

/// Why a calibration could not be fitted or parsed.
#[derive(Debug, Clone, PartialEq)]
pub enum CalibrationError {
    /// Fewer than three samples with distinct raw values.
    TooFewSamples(usize),
    /// A distance is not positive and finite.
    BadDistance(f64),
    /// The string is not `"a,b"` with two finite numbers.
    Parse(String),
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CalibrationError::TooFewSamples(n) => {
                write!(
                    f,
                    "need at least 3 wall distances with different raw values, got {n}"
                )
            }
            CalibrationError::BadDistance(z) => write!(f, "wall distance {z} m is not a positive number"),
            CalibrationError::Parse(s) => write!(
                f,
                "bad disparity calibration {s:?}: expected \"a,b\" (two numbers)"
            ),
        }
    }
}

impl std::error::Error for CalibrationError {}

/// The result of a least-squares fit: the calibration and how well it fits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationFit {
    /// The fitted coefficients.
    pub calibration: DisparityCalibration,
    /// RMS of the depth residuals over the samples, mm.
    pub rms_mm: f64,
}

impl DisparityCalibration {
    /// The nominal, **uncalibrated** curve for 10-bit V4L2 values: assumes raw10 = raw11 / 2 and the OpenKinect fit.
    pub const NOMINAL_10BIT: DisparityCalibration = DisparityCalibration {
        a: -0.003_071_101_6 * 2.0,
        b: 3.330_949_516_1,
    };

    /// Depth in metres for `raw`, or `None` where the model gives no positive depth.
    pub fn depth_m(&self, raw: f64) -> Option<f64> {
        let inv = self.a * raw + self.b;
        (inv > 0.0 && inv.is_finite()).then(|| 1.0 / inv)
    }

    /// Fit `1/z = a·raw + b` by least squares on inverse depth to `(raw, z metres)` wall samples (at least 3 distinct
    /// raw values).
    pub fn fit(samples: &[(f64, f64)]) -> Result<CalibrationFit, CalibrationError> {
        for &(_, z) in samples {
            if !(z.is_finite() && z > 0.0) {
                return Err(CalibrationError::BadDistance(z));
            }
        }
        let mut distinct: Vec<f64> = samples.iter().map(|s| s.0).collect();
        distinct.sort_by(f64::total_cmp);
        distinct.dedup();
        if distinct.len() < 3 {
            return Err(CalibrationError::TooFewSamples(distinct.len()));
        }
        let n = samples.len() as f64;
        let mean_x = samples.iter().map(|s| s.0).sum::<f64>() / n;
        let mean_y = samples.iter().map(|s| 1.0 / s.1).sum::<f64>() / n;
        let sxx: f64 = samples.iter().map(|s| (s.0 - mean_x).powi(2)).sum();
        let sxy: f64 = samples
            .iter()
            .map(|s| (s.0 - mean_x) * (1.0 / s.1 - mean_y))
            .sum();
        let a = sxy / sxx;
        let calibration = DisparityCalibration {
            a,
            b: mean_y - a * mean_x,
        };
        let sq: f64 = samples
            .iter()
            .map(|&(raw, z)| calibration.depth_m(raw).map_or(z * z, |fit| (fit - z).powi(2)))
            .sum();
        Ok(CalibrationFit {
            calibration,
            rms_mm: (sq / n).sqrt() * 1000.0,
        })
    }
}

impl fmt::Display for DisparityCalibration {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{}", self.a, self.b)
    }
}

impl FromStr for DisparityCalibration {
    type Err = CalibrationError;
    fn from_str(s: &str) -> Result<Self, CalibrationError> {
        let err = || CalibrationError::Parse(s.to_owned());
        let (a, b) = s.split_once(',').ok_or_else(err)?;
        let a: f64 = a.trim().parse().map_err(|_| err())?;
        let b: f64 = b.trim().parse().map_err(|_| err())?;
        if !(a.is_finite() && b.is_finite()) {
            return Err(err());
        }
        Ok(DisparityCalibration { a, b })
    }
}

/// A 1024-entry 10-bit raw → mm table built from a calibration; raw 1023 (all ones) and values the model cannot map
/// into (0, 10000] mm give 0 (no depth).
#[derive(Clone)]
pub struct DisparityTable {
    mm: Box<[u16; 1024]>,
}

impl fmt::Debug for DisparityTable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("DisparityTable")
            .field("raw_512_mm", &self.mm[512])
            .finish()
    }
}

impl DisparityTable {
    /// Expand `calibration` into the lookup table.
    pub fn new(calibration: &DisparityCalibration) -> Self {
        let mut mm = Box::new([0u16; 1024]);
        for (raw, slot) in mm.iter_mut().enumerate().take(1023) {
            if let Some(z) = calibration.depth_m(raw as f64) {
                let v = (z * 1000.0).round();
                if v > 0.0 && v < MAX_DEPTH_MM as f64 {
                    *slot = v as u16;
                }
            }
        }
        DisparityTable { mm }
    }

    /// Millimetres for a 10-bit raw value (0 = no depth; bits above 10 are ignored).
    pub fn mm(&self, raw: u16) -> u16 {
        self.mm[(raw & 0x3FF) as usize]
    }

    /// Convert raw values in place to millimetres.
    pub fn convert_in_place(&self, values: &mut [u16]) {
        for v in values {
            *v = self.mm(*v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A generic MSB-first bit packer, independent of the unpack formulas.
    fn pack_msb(values: &[u16], bits: u32) -> Vec<u8> {
        let mut out = Vec::new();
        let (mut acc, mut n) = (0u64, 0u32);
        for &v in values {
            acc = (acc << bits) | (v as u64 & ((1 << bits) - 1));
            n += bits;
            while n >= 8 {
                out.push((acc >> (n - 8)) as u8);
                n -= 8;
            }
        }
        out
    }

    #[test]
    fn y10b_hand_packed() {
        // 0x3FF, 0x000, 0x155, 0x2AA: 11111111 11000000 00000101 01010110 10101010
        let packed = [0xFF, 0xC0, 0x05, 0x56, 0xAA];
        let mut out = [0u16; 4];
        assert_eq!(unpack_y10b(&packed, &mut out), 4);
        assert_eq!(out, [0x3FF, 0x000, 0x155, 0x2AA]);
        // 1, 2, 3, 4: 00000000 01000000 00100000 00001100 00000100
        let mut out = [0u16; 4];
        unpack_y10b(&[0x00, 0x40, 0x20, 0x0C, 0x04], &mut out);
        assert_eq!(out, [1, 2, 3, 4]);
    }

    #[test]
    fn eleven_bit_hand_packed() {
        // 2047 then seven zeros: the first 11 bits set.
        let mut packed = [0u8; 11];
        packed[0] = 0xFF;
        packed[1] = 0xE0;
        let mut out = [9u16; 8];
        assert_eq!(unpack_11bit(&packed, &mut out), 8);
        assert_eq!(out, [2047, 0, 0, 0, 0, 0, 0, 0]);
        // ...and the last pixel only: low 11 bits of the group.
        let mut packed = [0u8; 11];
        packed[9] = 0x07;
        packed[10] = 0xFF;
        unpack_11bit(&packed, &mut out);
        assert_eq!(out, [0, 0, 0, 0, 0, 0, 0, 2047]);
    }

    #[test]
    fn short_buffers_unpack_whole_groups_only() {
        let mut out = [0u16; 8];
        assert_eq!(unpack_y10b(&[0xFF; 9], &mut out), 4);
        assert_eq!(unpack_11bit(&[0xFF; 10], &mut out), 0);
        assert_eq!(Y10B_FRAME_BYTES, 384_000);
        assert_eq!(PACKED11_FRAME_BYTES, 422_400);
    }

    proptest! {
        #[test]
        fn y10b_matches_generic_packer(v in proptest::collection::vec(0u16..1024, 4..64)) {
            let v = &v[..v.len() / 4 * 4];
            let mut out = vec![0u16; v.len()];
            prop_assert_eq!(unpack_y10b(&pack_msb(v, 10), &mut out), v.len());
            prop_assert_eq!(&out[..], v);
        }

        #[test]
        fn eleven_bit_matches_generic_packer(v in proptest::collection::vec(0u16..2048, 8..80)) {
            let v = &v[..v.len() / 8 * 8];
            let mut out = vec![0u16; v.len()];
            prop_assert_eq!(unpack_11bit(&pack_msb(v, 11), &mut out), v.len());
            prop_assert_eq!(&out[..], v);
        }
    }

    #[test]
    fn ps1080_formula_matches_reference_table() {
        let p = Ps1080Params::TYPICAL;
        for (raw, mm) in [(600u16, 706.0), (800, 1194.0), (1000, 3864.0)] {
            let got = p.shift_to_mm(raw).unwrap();
            assert!((got - mm).abs() < 1.0, "raw {raw}: {got} mm, reference {mm}");
        }
        assert_eq!(p.shift_to_mm(RAW11_NO_VALUE), None);
        assert_eq!(p.shift_to_mm(1500), None, "beyond the emitter baseline: no depth");
        let t = p.table();
        assert_eq!(t.len(), 2048);
        assert_eq!(t[800], 1194);
        assert_eq!(t[2047], 0);
        // Monotone where valid.
        let valid: Vec<u16> = t.iter().copied().filter(|&d| d > 0).collect();
        assert!(valid.windows(2).all(|w| w[0] <= w[1]));
    }

    #[test]
    fn fit_recovers_known_coefficients() {
        let truth = DisparityCalibration { a: -0.0061, b: 3.33 };
        let samples: Vec<(f64, f64)> = [300.0, 350.0, 400.0, 420.0]
            .iter()
            .map(|&raw| (raw, truth.depth_m(raw).unwrap()))
            .collect();
        let fit = DisparityCalibration::fit(&samples).unwrap();
        assert!((fit.calibration.a - truth.a).abs() < 1e-9, "{fit:?}");
        assert!((fit.calibration.b - truth.b).abs() < 1e-7, "{fit:?}");
        assert!(fit.rms_mm < 1e-3);
    }

    #[test]
    fn fit_with_noise_reports_residuals() {
        let truth = DisparityCalibration { a: -0.0061, b: 3.33 };
        let samples: Vec<(f64, f64)> = [(300.0, 5.0), (350.0, -8.0), (400.0, 6.0), (430.0, -4.0)]
            .iter()
            .map(|&(raw, noise_mm)| (raw, truth.depth_m(raw).unwrap() + noise_mm / 1000.0))
            .collect();
        let fit = DisparityCalibration::fit(&samples).unwrap();
        assert!(fit.rms_mm > 1.0 && fit.rms_mm < 20.0, "{fit:?}");
        assert!((fit.calibration.a - truth.a).abs() < 1e-4, "{fit:?}");
    }

    #[test]
    fn fit_needs_three_distinct_distances() {
        assert_eq!(
            DisparityCalibration::fit(&[(300.0, 1.0), (300.0, 1.01), (350.0, 1.5)]),
            Err(CalibrationError::TooFewSamples(2))
        );
        assert_eq!(
            DisparityCalibration::fit(&[(300.0, 1.0), (310.0, 0.0), (350.0, 1.5)]),
            Err(CalibrationError::BadDistance(0.0))
        );
    }

    #[test]
    fn calibration_string_round_trips() {
        let c = DisparityCalibration {
            a: -0.0061422032,
            b: 3.3309495161,
        };
        assert_eq!(c.to_string().parse::<DisparityCalibration>().unwrap(), c);
        assert!("1;2".parse::<DisparityCalibration>().is_err());
        assert!("x,2".parse::<DisparityCalibration>().is_err());
    }

    #[test]
    fn table_follows_the_calibration() {
        let c = DisparityCalibration::NOMINAL_10BIT;
        let t = DisparityTable::new(&c);
        // raw10 = 400 is raw11 = 800: 1/(−0.0030711016·800 + 3.3309495161) m = 1144 mm (reference table).
        assert_eq!(t.mm(400), 1144);
        assert_eq!(t.mm(1023), 0);
        assert_eq!(t.mm(0), 300, "1 / 3.331 m");
        assert_eq!(t.mm(600), 0, "past the model's range (a·raw + b <= 0): no depth");
        let mut v = [400u16, 1023];
        t.convert_in_place(&mut v);
        assert_eq!(v, [1144, 0]);
    }
}
