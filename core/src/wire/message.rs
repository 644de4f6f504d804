//! The messages (Repr side): what the tracker sends the arm controller and what the arm controller sends back.
//! Plain `Copy` structs of validated fields; the largest ([`SalientPoints`]) is under 100 bytes in memory.
//!
//! Frames: positions of [`TorsoPose`], [`SalientPoints`] and [`ArmState`] are in `robot_base`, those of
//! [`ProbeReport`] in `torso`. Every length is in millimetres.

use serde::{Deserialize, Serialize};

use super::error::RangeError;
use super::types::{BodyRegion, Confidence, NormalQ14, ShapeMode, Timestamp, TrackerState, UnitQuatQ14};
use crate::body_model::SHAPE_COMPONENTS;
use crate::salient::SalientPoint;

/// One message: the envelope every kind shares, and the kind's body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Message {
    /// Sequence number, counted per message kind by the sender, wrapping at 2^16 (about 36 min at 30 Hz).
    pub seq: u16,
    /// Tracker → arm: capture time of the depth frame the message was computed from. Arm → tracker: the arm's
    /// sample time of the state it reports (or the send time of a command).
    pub timestamp: Timestamp,
    /// What the message says.
    pub body: Body,
}

/// The body of a message, one variant per kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Body {
    /// Tracker → arm: the torso frame in `robot_base`.
    TorsoPose(TorsoPose),
    /// Tracker → arm: the six salient points in `robot_base`.
    SalientPoints(SalientPoints),
    /// Tracker → arm: where the probe tip is relative to the body surface.
    Probe(ProbeReport),
    /// Tracker → arm: the patient's body-shape coefficients (on change and periodically).
    BodyShape(BodyShape),
    /// Tracker → arm: tracker state and timing.
    Health(Health),
    /// Arm → tracker: the end-effector (probe-tip) pose in `robot_base`.
    ArmState(ArmState),
    /// Arm → tracker: a command.
    Command(Command),
}

impl Body {
    /// This body's kind.
    pub const fn kind(&self) -> Kind {
        match self {
            Body::TorsoPose(_) => Kind::TorsoPose,
            Body::SalientPoints(_) => Kind::SalientPoints,
            Body::Probe(_) => Kind::Probe,
            Body::BodyShape(_) => Kind::BodyShape,
            Body::Health(_) => Kind::Health,
            Body::ArmState(_) => Kind::ArmState,
            Body::Command(_) => Kind::Command,
        }
    }
}

impl Message {
    /// This message's kind.
    pub const fn kind(&self) -> Kind {
        self.body.kind()
    }
}

/// Message kinds with their wire value (the serial kind byte, and the CAN id block `base + 0x10 * kind`).
///
/// Lower values win CAN arbitration, so commands and arm state come first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[non_exhaustive]
#[repr(u8)]
pub enum Kind {
    /// [`Command`], arm → tracker.
    Command = 0,
    /// [`ArmState`], arm → tracker.
    ArmState = 1,
    /// [`TorsoPose`], tracker → arm.
    TorsoPose = 2,
    /// [`ProbeReport`], tracker → arm.
    Probe = 3,
    /// [`SalientPoints`], tracker → arm.
    SalientPoints = 4,
    /// [`Health`], tracker → arm.
    Health = 5,
    /// [`BodyShape`], tracker → arm.
    BodyShape = 6,
}

impl Kind {
    /// Every kind, in wire-value order.
    pub const ALL: [Kind; 7] = [
        Kind::Command,
        Kind::ArmState,
        Kind::TorsoPose,
        Kind::Probe,
        Kind::SalientPoints,
        Kind::Health,
        Kind::BodyShape,
    ];

    /// The kind with this wire value, if any.
    pub const fn from_u8(v: u8) -> Option<Kind> {
        match v {
            0 => Some(Kind::Command),
            1 => Some(Kind::ArmState),
            2 => Some(Kind::TorsoPose),
            3 => Some(Kind::Probe),
            4 => Some(Kind::SalientPoints),
            5 => Some(Kind::Health),
            6 => Some(Kind::BodyShape),
            _ => None,
        }
    }

    /// The snake_case name used in JSON (`kind` field).
    pub const fn name(self) -> &'static str {
        match self {
            Kind::Command => "command",
            Kind::ArmState => "arm_state",
            Kind::TorsoPose => "torso_pose",
            Kind::Probe => "probe",
            Kind::SalientPoints => "salient_points",
            Kind::Health => "health",
            Kind::BodyShape => "body_shape",
        }
    }

    /// True for the kinds the tracker sends, false for those the arm controller sends.
    pub const fn is_from_tracker(self) -> bool {
        !matches!(self, Kind::Command | Kind::ArmState)
    }
}

/// The torso frame's pose in `robot_base`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TorsoPose {
    /// Origin of the torso frame (hip centre), mm, `robot_base`.
    pub position_mm: [i32; 3],
    /// Rotation `robot_base_from_torso`.
    pub orientation: UnitQuatQ14,
    /// How much the tracker trusts this pose.
    pub confidence: Confidence,
}

/// One salient point as the wire reports it (which one is its index in [`SalientPoints::points`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SalientPointReport {
    /// Position, mm, `robot_base`.
    pub position_mm: [i32; 3],
    /// How much the tracker trusts this point (low while occluded).
    pub confidence: Confidence,
}

/// The six salient points, indexed by [`SalientPoint`] (head, left shoulder, right
/// shoulder, belly, left hip, right hip).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SalientPoints {
    /// The points in [`SalientPoint`] order.
    pub points: [SalientPointReport; SalientPoint::COUNT],
}

/// Where the probe tip is relative to the patient's body surface, in the `torso` frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProbeReport {
    /// Probe tip, mm, `torso` (from the newest arm state mapped through the newest torso pose).
    pub tip_mm: [i32; 3],
    /// Nearest point of the body surface model, mm, `torso`.
    pub nearest_mm: [i32; 3],
    /// Outward surface normal at that point (zero when no surface was found).
    pub normal: NormalQ14,
    /// Signed distance from the surface to the tip along the normal, mm: positive outside the body, negative
    /// when the tip is pressed into the (model) surface.
    pub signed_distance_mm: i32,
    /// Body region under the nearest point.
    pub region: BodyRegion,
}

/// The patient's body shape: coefficients of the statistical body model's shape subspace.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct BodyShape {
    /// Incremented (wrapping) each time the estimate changes, so the arm can tell a periodic repeat from a change.
    pub revision: u8,
    /// The [`SHAPE_COMPONENTS`] (20) coefficients in thousandths of a standard deviation of each principal component (±32.767 sd).
    pub coefficients_milli: [i16; SHAPE_COMPONENTS],
}

/// Tracker state and timing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Health {
    /// What the tracker is doing.
    pub state: TrackerState,
    /// Depth frames processed per second over the last second, in 0.01 Hz (3000 = 30 Hz).
    pub frame_rate_chz: u16,
    /// Processing latency of the newest frame (capture to packets out), µs.
    pub latency_us: u32,
    /// Frames since start whose processing exceeded the frame budget (cumulative, wrapping).
    pub budget_overruns: u32,
    /// Depth frames since start that were dropped unprocessed (cumulative, wrapping).
    pub dropped_frames: u32,
}

/// The arm's end-effector (probe-tip) pose in `robot_base`; the message timestamp is the arm's sample time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ArmState {
    /// Probe-tip position, mm, `robot_base`.
    pub position_mm: [i32; 3],
    /// Rotation `robot_base_from_probe`.
    pub orientation: UnitQuatQ14,
}

/// A command from the arm controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "CommandWire", into = "CommandWire")]
#[non_exhaustive]
pub enum Command {
    /// Drop the current track and run the init phase again (bed planes, shape unless frozen).
    Reinitialise,
    /// Resume sending tracker messages.
    Start,
    /// Pause sending tracker messages; tracking goes on (a start resumes with the current pose and shape).
    Stop,
    /// Set the shape-estimation mode.
    SetShapeMode(ShapeMode),
}

impl Command {
    /// Wire form: command code and argument byte (0 for commands without an argument).
    pub fn to_code_arg(self) -> (u8, u8) {
        match self {
            Command::Reinitialise => (1, 0),
            Command::Start => (2, 0),
            Command::Stop => (3, 0),
            Command::SetShapeMode(m) => (4, u8::from(m)),
        }
    }

    /// The command with this code and argument; `None` for an unknown code, a bad argument, or a non-zero
    /// argument to a command that takes none.
    pub fn from_code_arg(code: u8, arg: u8) -> Option<Command> {
        match (code, arg) {
            (1, 0) => Some(Command::Reinitialise),
            (2, 0) => Some(Command::Start),
            (3, 0) => Some(Command::Stop),
            (4, a) => ShapeMode::from_u8(a).map(Command::SetShapeMode),
            _ => None,
        }
    }

    /// The snake_case name used in JSON and the DBC's VAL_ table.
    pub const fn name(self) -> &'static str {
        match self {
            Command::Reinitialise => "reinitialise",
            Command::Start => "start",
            Command::Stop => "stop",
            Command::SetShapeMode(_) => "set_shape_mode",
        }
    }
}

#[derive(Clone, Copy, Serialize, Deserialize)]
struct CommandWire {
    code: u8,
    arg: u8,
}

impl TryFrom<CommandWire> for Command {
    type Error = RangeError;
    fn try_from(w: CommandWire) -> Result<Self, RangeError> {
        Command::from_code_arg(w.code, w.arg).ok_or(RangeError)
    }
}

impl From<Command> for CommandWire {
    fn from(c: Command) -> CommandWire {
        let (code, arg) = c.to_code_arg();
        CommandWire { code, arg }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_round_trip_and_are_ordered_by_priority() {
        for (i, k) in Kind::ALL.iter().enumerate() {
            assert_eq!(*k as usize, i);
            assert_eq!(Kind::from_u8(i as u8), Some(*k));
        }
        assert_eq!(Kind::from_u8(7), None);
        assert!(Kind::Command < Kind::TorsoPose);
        assert!(!Kind::ArmState.is_from_tracker());
        assert!(Kind::Health.is_from_tracker());
    }

    #[test]
    fn command_codes() {
        for c in [
            Command::Reinitialise,
            Command::Start,
            Command::Stop,
            Command::SetShapeMode(ShapeMode::Continuous),
        ] {
            let (code, arg) = c.to_code_arg();
            assert_eq!(Command::from_code_arg(code, arg), Some(c));
        }
        assert_eq!(Command::from_code_arg(2, 1), None);
        assert_eq!(Command::from_code_arg(4, 9), None);
        assert_eq!(Command::from_code_arg(0, 0), None);
    }
}
