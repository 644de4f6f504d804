//! The six salient points of the upper body (paper §3.3): one enum for the body model's rows, the joint forest's
//! outputs, the wire's salient-points message and every report. Its discriminant is the wire id and the storage
//! order everywhere, and [`SalientPoint::name`] is the snake_case key of JSON reports and the DBC.

/// One of the six salient points, in storage (and wire) order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[repr(u8)]
pub enum SalientPoint {
    /// Midpoint of the neck base and the skull base joints.
    Head = 0,
    /// Left glenohumeral joint (the patient's left).
    LeftShoulder = 1,
    /// Right glenohumeral joint.
    RightShoulder = 2,
    /// The navel (a surface point: it follows the belly).
    Belly = 3,
    /// Left hip joint.
    LeftHip = 4,
    /// Right hip joint.
    RightHip = 5,
}

impl SalientPoint {
    /// Number of salient points.
    pub const COUNT: usize = 6;

    /// All six, in storage order.
    pub const ALL: [SalientPoint; SalientPoint::COUNT] = [
        SalientPoint::Head,
        SalientPoint::LeftShoulder,
        SalientPoint::RightShoulder,
        SalientPoint::Belly,
        SalientPoint::LeftHip,
        SalientPoint::RightHip,
    ];

    /// Index into arrays in storage order (equal to the wire id).
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The point with this wire id (= index), if any.
    pub const fn from_u8(id: u8) -> Option<Self> {
        if (id as usize) < Self::COUNT {
            Some(Self::ALL[id as usize])
        } else {
            None
        }
    }

    /// The snake_case name used in reports, JSON and the DBC (`head`, `left_shoulder`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            SalientPoint::Head => "head",
            SalientPoint::LeftShoulder => "left_shoulder",
            SalientPoint::RightShoulder => "right_shoulder",
            SalientPoint::Belly => "belly",
            SalientPoint::LeftHip => "left_hip",
            SalientPoint::RightHip => "right_hip",
        }
    }

    /// The point called `name` (the inverse of [`SalientPoint::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// The mirror-image point (left and right swapped), for flipped training images and symmetry checks.
    pub const fn mirrored(self) -> Self {
        match self {
            SalientPoint::LeftShoulder => SalientPoint::RightShoulder,
            SalientPoint::RightShoulder => SalientPoint::LeftShoulder,
            SalientPoint::LeftHip => SalientPoint::RightHip,
            SalientPoint::RightHip => SalientPoint::LeftHip,
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_names_and_order_agree() {
        for (i, p) in SalientPoint::ALL.into_iter().enumerate() {
            assert_eq!(p.index(), i);
            assert_eq!(SalientPoint::from_u8(i as u8), Some(p));
            assert_eq!(SalientPoint::from_name(p.name()), Some(p));
            assert_eq!(p.mirrored().mirrored(), p);
        }
        assert_eq!(SalientPoint::from_u8(6), None);
        assert_eq!(SalientPoint::from_name("knee"), None);
        assert_eq!(SalientPoint::LeftHip.mirrored(), SalientPoint::RightHip);
    }
}
