//! Validated field types of the wire protocol: fixed-point quaternions and normals, confidences and the
//! enumerations ([`Timestamp`] is core's own, from [`crate::time`]; salient point ids are [`crate::salient`]'s).
//! Each newtype can only hold values its documentation allows, so a decoded message is valid by construction. Validation is a few integer operations per field; nothing allocates.
//!
//! Enumerations are written as their `u8` value (the same number on serial, on CAN and in the DBC's VAL_ tables),
//! so that appending a variant never renumbers the others.

use serde::{Deserialize, Serialize};

use super::error::RangeError;
pub use crate::time::Timestamp;

/// Q14 fixed point: 1.0 is 16384, so ±1.0 (and every unit-vector component) is exactly representable in an i16.
pub const Q14_ONE: i16 = 1 << 14;

/// Tolerance on the squared norm of a Q14 unit vector, in Q28 units: 2^20 / 2^28 = 1/256 relative. Rounding each
/// component to Q14 costs at most about 1.2e-4, so any honest encoder passes and garbage almost never does.
const UNIT_NORM_TOLERANCE_Q28: i64 = 1 << 20;

const fn is_unit_q14(c: &[i16]) -> bool {
    // A `while` loop rather than iterators so that constant messages (the samples) are validated at compile time.
    let mut n2 = 0i64;
    let mut i = 0;
    while i < c.len() {
        n2 += c[i] as i64 * c[i] as i64;
        i += 1;
    }
    (n2 - (1i64 << 28)).abs() <= UNIT_NORM_TOLERANCE_Q28
}

fn to_q14(v: f32) -> i16 {
    let scaled = libm::roundf(v * f32::from(Q14_ONE));
    // Saturate instead of wrapping: a component of exactly 1.0 rounds to 16384, far from the i16 limit anyway.
    scaled.clamp(f32::from(i16::MIN), f32::from(i16::MAX)) as i16
}

/// A confidence in whole percent, 0 (no information) to 100 (certain).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize)]
#[serde(try_from = "u8", into = "u8")]
pub struct Confidence(u8);

impl Confidence {
    /// Full confidence.
    pub const FULL: Confidence = Confidence(100);

    /// A confidence of `percent`; `None` above 100.
    pub const fn new(percent: u8) -> Option<Self> {
        if percent <= 100 {
            Some(Confidence(percent))
        } else {
            None
        }
    }

    /// The confidence from a fraction in 0..=1, rounded and clamped.
    pub fn from_fraction(f: f32) -> Self {
        Confidence(libm::roundf(f.clamp(0.0, 1.0) * 100.0) as u8)
    }

    /// Whole percent, 0..=100.
    pub const fn percent(self) -> u8 {
        self.0
    }
}

impl TryFrom<u8> for Confidence {
    type Error = RangeError;
    fn try_from(v: u8) -> Result<Self, RangeError> {
        Confidence::new(v).ok_or(RangeError)
    }
}

impl From<Confidence> for u8 {
    fn from(c: Confidence) -> u8 {
        c.0
    }
}

/// A unit quaternion `[w, x, y, z]` in Q14 (1.0 = 16384, resolution 6.1e-5, about 0.007 degrees).
///
/// Valid when the squared norm is within 1/256 of one; `q` and `-q` are the same rotation and both are accepted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "[i16; 4]", into = "[i16; 4]")]
pub struct UnitQuatQ14([i16; 4]);

impl UnitQuatQ14 {
    /// The identity rotation.
    pub const IDENTITY: UnitQuatQ14 = UnitQuatQ14([Q14_ONE, 0, 0, 0]);

    /// The quaternion with these raw Q14 components `[w, x, y, z]`; `None` unless it is a unit quaternion.
    pub const fn new_checked(wxyz: [i16; 4]) -> Option<Self> {
        if is_unit_q14(&wxyz) {
            Some(UnitQuatQ14(wxyz))
        } else {
            None
        }
    }

    /// Quantise a float quaternion `[w, x, y, z]` (normalised first); `None` for a zero or non-finite input.
    pub fn from_f32(wxyz: [f32; 4]) -> Option<Self> {
        let n = libm::sqrtf(wxyz.iter().map(|v| v * v).sum());
        if !n.is_finite() || n < 1e-6 {
            return None;
        }
        Self::new_checked(wxyz.map(|v| to_q14(v / n)))
    }

    /// Raw Q14 components `[w, x, y, z]`.
    pub const fn raw(self) -> [i16; 4] {
        self.0
    }

    /// Components `[w, x, y, z]` as floats.
    pub fn to_f32(self) -> [f32; 4] {
        self.0.map(|v| f32::from(v) / f32::from(Q14_ONE))
    }
}

impl TryFrom<[i16; 4]> for UnitQuatQ14 {
    type Error = RangeError;
    fn try_from(v: [i16; 4]) -> Result<Self, RangeError> {
        UnitQuatQ14::new_checked(v).ok_or(RangeError)
    }
}

impl From<UnitQuatQ14> for [i16; 4] {
    fn from(q: UnitQuatQ14) -> [i16; 4] {
        q.0
    }
}

/// A surface normal `[x, y, z]` in Q14: a unit vector, or all zeros when no surface was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "[i16; 3]", into = "[i16; 3]")]
pub struct NormalQ14([i16; 3]);

impl NormalQ14 {
    /// The "no surface" normal.
    pub const NONE: NormalQ14 = NormalQ14([0, 0, 0]);

    /// The normal with these raw Q14 components; `None` unless unit length or all zero.
    pub const fn new_checked(xyz: [i16; 3]) -> Option<Self> {
        let zero = xyz[0] == 0 && xyz[1] == 0 && xyz[2] == 0;
        if zero || is_unit_q14(&xyz) {
            Some(NormalQ14(xyz))
        } else {
            None
        }
    }

    /// Quantise a float direction (normalised first); `None` for a zero or non-finite input.
    pub fn from_f32(xyz: [f32; 3]) -> Option<Self> {
        let n = libm::sqrtf(xyz.iter().map(|v| v * v).sum());
        if !n.is_finite() || n < 1e-6 {
            return None;
        }
        Self::new_checked(xyz.map(|v| to_q14(v / n)))
    }

    /// Raw Q14 components `[x, y, z]`.
    pub const fn raw(self) -> [i16; 3] {
        self.0
    }

    /// Components as floats.
    pub fn to_f32(self) -> [f32; 3] {
        self.0.map(|v| f32::from(v) / f32::from(Q14_ONE))
    }
}

impl TryFrom<[i16; 3]> for NormalQ14 {
    type Error = RangeError;
    fn try_from(v: [i16; 3]) -> Result<Self, RangeError> {
        NormalQ14::new_checked(v).ok_or(RangeError)
    }
}

impl From<NormalQ14> for [i16; 3] {
    fn from(n: NormalQ14) -> [i16; 3] {
        n.0
    }
}

/// An enumeration carried as its `u8` value, with a stable snake_case name for JSON and the DBC's VAL_ tables.
macro_rules! wire_enum {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $var:ident = $val:literal => $text:literal,)+ }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
        #[serde(try_from = "u8", into = "u8")]
        #[non_exhaustive]
        #[repr(u8)]
        pub enum $name {
            $($(#[$vm])* $var = $val,)+
        }

        impl $name {
            /// Every variant, in wire-value order.
            pub const ALL: &'static [$name] = &[$($name::$var,)+];

            /// The variant with this wire value, if any.
            pub const fn from_u8(v: u8) -> Option<Self> {
                match v {
                    $($val => Some($name::$var),)+
                    _ => None,
                }
            }

            /// The snake_case name used in JSON and in the DBC's VAL_ table.
            pub const fn name(self) -> &'static str {
                match self {
                    $($name::$var => $text,)+
                }
            }

            /// The variant that [`Self::name`] spells `name`, if any.
            pub fn from_name(name: &str) -> Option<Self> {
                Self::ALL.iter().copied().find(|v| v.name() == name)
            }
        }

        impl TryFrom<u8> for $name {
            type Error = RangeError;
            fn try_from(v: u8) -> Result<Self, RangeError> {
                $name::from_u8(v).ok_or(RangeError)
            }
        }

        impl From<$name> for u8 {
            fn from(v: $name) -> u8 {
                v as u8
            }
        }
    };
}

wire_enum! {
    /// What the tracker is doing, as reported by the health message.
    TrackerState {
        /// Init phase: bed planes and body shape are being estimated; no pose yet.
        Initialising = 0 => "initialising",
        /// Tracking normally.
        Tracking = 1 => "tracking",
        /// Tracking, but a large part of the torso is hidden (by the arm, usually); poses lean on the prior.
        Occluded = 2 => "occluded",
        /// The patient was lost; poses are not sent until re-acquired or re-initialised.
        Lost = 3 => "lost",
        /// Tracking while cutting work to keep the frame budget (fewer ICP iterations, skipped refinement).
        Degraded = 4 => "degraded",
        /// The depth sensor stopped delivering frames or delivers unusable ones.
        SensorFault = 5 => "sensor_fault",
        /// Init done (bed and shape known), looking for the patient's torso for the first time; no pose yet.
        Acquiring = 6 => "acquiring",
        /// After a loss, looking for the torso again from the forest alone; no pose yet.
        Reacquiring = 7 => "reacquiring",
    }
}

impl TrackerState {
    /// Whether the tracker has a pose in this state (and sends it): tracking, occluded or degraded.
    pub fn has_pose(self) -> bool {
        matches!(
            self,
            TrackerState::Tracking | TrackerState::Degraded | TrackerState::Occluded
        )
    }
}

wire_enum! {
    /// The body region under a probe report's nearest surface point.
    BodyRegion {
        /// The probe is not over the patient's body (or no surface was found).
        OffBody = 0 => "off_body",
        /// Head.
        Head = 1 => "head",
        /// Neck.
        Neck = 2 => "neck",
        /// Left shoulder (the patient's left).
        LeftShoulder = 3 => "left_shoulder",
        /// Right shoulder.
        RightShoulder = 4 => "right_shoulder",
        /// Chest.
        Chest = 5 => "chest",
        /// Abdomen.
        Abdomen = 6 => "abdomen",
        /// Left flank.
        LeftFlank = 7 => "left_flank",
        /// Right flank.
        RightFlank = 8 => "right_flank",
        /// Pelvis.
        Pelvis = 9 => "pelvis",
    }
}

wire_enum! {
    /// How the tracker estimates the patient's body shape (set by a command).
    ShapeMode {
        /// Keep the current shape; never re-estimate.
        Frozen = 0 => "frozen",
        /// Estimate once at the next (re-)initialisation, then freeze.
        Once = 1 => "once",
        /// Keep refining the shape while tracking.
        Continuous = 2 => "continuous",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confidence_range() {
        assert_eq!(Confidence::new(100), Some(Confidence::FULL));
        assert_eq!(Confidence::new(101), None);
        assert_eq!(Confidence::from_fraction(0.874).percent(), 87);
        assert_eq!(Confidence::from_fraction(7.0).percent(), 100);
        assert_eq!(Confidence::from_fraction(f32::NAN).percent(), 0);
    }

    #[test]
    fn quaternion_validation() {
        assert!(UnitQuatQ14::new_checked([Q14_ONE, 0, 0, 0]).is_some());
        assert!(UnitQuatQ14::new_checked([-Q14_ONE, 0, 0, 0]).is_some());
        assert!(UnitQuatQ14::new_checked([0, 0, 0, 0]).is_none());
        assert!(UnitQuatQ14::new_checked([Q14_ONE, Q14_ONE, 0, 0]).is_none());
        let q = UnitQuatQ14::from_f32([0.5, 0.5, 0.5, 0.5]).unwrap();
        assert_eq!(q.raw(), [8192; 4]);
        assert!(UnitQuatQ14::from_f32([0.0; 4]).is_none());
        assert!(UnitQuatQ14::from_f32([f32::NAN, 0.0, 0.0, 1.0]).is_none());
    }

    #[test]
    fn normal_validation() {
        assert!(NormalQ14::new_checked([0, 0, 0]).is_some());
        assert!(NormalQ14::new_checked([0, 0, Q14_ONE]).is_some());
        assert!(NormalQ14::new_checked([0, 1, 0]).is_none());
        assert_eq!(
            NormalQ14::from_f32([0.0, 3.0, 4.0]).unwrap().raw(),
            [0, 9830, 13107]
        );
    }

    #[test]
    fn enums_round_trip_their_wire_values() {
        for &s in TrackerState::ALL {
            assert_eq!(TrackerState::from_u8(u8::from(s)), Some(s));
        }
        for &r in BodyRegion::ALL {
            assert_eq!(BodyRegion::from_u8(u8::from(r)), Some(r));
        }
        assert_eq!(TrackerState::from_u8(8), None);
        assert_eq!(BodyRegion::from_u8(10), None);
        assert_eq!(ShapeMode::from_u8(3), None);
        assert_eq!(TrackerState::SensorFault.name(), "sensor_fault");
    }

    #[test]
    fn enums_round_trip_their_names() {
        for &m in ShapeMode::ALL {
            assert_eq!(ShapeMode::from_name(m.name()), Some(m));
        }
        for &r in BodyRegion::ALL {
            assert_eq!(BodyRegion::from_name(r.name()), Some(r));
        }
        assert_eq!(ShapeMode::from_name("continuous"), Some(ShapeMode::Continuous));
        assert_eq!(ShapeMode::from_name("Continuous"), None);
        assert_eq!(TrackerState::from_name(""), None);
    }
}
