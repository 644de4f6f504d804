//! The documented sample messages: one of each kind with realistic values, for `supine wire sample`, the golden
//! byte tests, the DBC and peer checks, and the arm-consumer example. A `const` table, so every value was
//! validated at compile time and costs nothing at run time.
//!
//! The scene: a patient lies on a bed beside the robot, `robot_base` z up, the bed surface about 0.75 m high.
//! The tracker frame captured at 1 234 567 890 µs (20 min 34.6 s after the tracker started) yields the torso pose,
//! salient points (the right hip half hidden by the arm, hence its low confidence), a probe report with the
//! probe 14 mm above the abdomen, the periodic body-shape repeat and a health report. The arm reports its
//! probe-tip pose (probe pointing down, slightly tilted) and asks for continuous shape refinement.

use super::message::{
    ArmState, Body, BodyShape, Command, Health, Message, ProbeReport, SalientPointReport, SalientPoints,
    TorsoPose,
};
use super::types::{BodyRegion, Confidence, NormalQ14, ShapeMode, Timestamp, TrackerState, UnitQuatQ14};

/// Unwrap a validated constructor inside a `const`: a bad constant fails the build, never a run.
macro_rules! valid {
    ($e:expr) => {
        match $e {
            Some(v) => v,
            None => panic!("invalid sample constant"),
        }
    };
}

/// Capture time of the sample depth frame.
pub const CAPTURE: Timestamp = valid!(Timestamp::from_us(1_234_567_890));

const fn point(position_mm: [i32; 3], confidence: u8) -> SalientPointReport {
    SalientPointReport {
        position_mm,
        confidence: valid!(Confidence::new(confidence)),
    }
}

/// The sample messages, one per kind, in the order `supine wire sample` prints them.
pub const MESSAGES: [Message; 7] = [
    Message {
        seq: 1042,
        timestamp: CAPTURE,
        body: Body::TorsoPose(TorsoPose {
            position_mm: [645, -148, 788],
            // About 90 degrees about z (the patient's head points along robot_base +x), slightly rolled.
            orientation: valid!(UnitQuatQ14::new_checked([11539, 420, -310, 11619])),
            confidence: valid!(Confidence::new(93)),
        }),
    },
    Message {
        seq: 1042,
        timestamp: CAPTURE,
        body: Body::SalientPoints(SalientPoints {
            points: [
                point([1395, -160, 842], 97),
                point([1180, 25, 835], 91),
                point([1190, -340, 830], 88),
                point([890, -150, 870], 95),
                point([640, -30, 790], 84),
                point([650, -265, 785], 62),
            ],
        }),
    },
    Message {
        seq: 1042,
        timestamp: CAPTURE,
        body: Body::Probe(ProbeReport {
            tip_mm: [35, 210, 118],
            nearest_mm: [31, 212, 104],
            // (4, -2, 14) normalised: the tip lies along the outward normal, 14.7 mm away (14 mm rounded).
            normal: valid!(NormalQ14::new_checked([4459, -2230, 15607])),
            signed_distance_mm: 14,
            region: BodyRegion::Abdomen,
        }),
    },
    Message {
        seq: 7,
        timestamp: CAPTURE,
        body: Body::BodyShape(BodyShape {
            revision: 3,
            coefficients_milli: [
                1250, -430, 820, 95, -1310, 240, -75, 510, -220, 30, 145, -60, 12, -95, 40, 8, -22, 17, -5, 3,
            ],
        }),
    },
    Message {
        seq: 208,
        timestamp: CAPTURE,
        body: Body::Health(Health {
            state: TrackerState::Tracking,
            frame_rate_chz: 2994,
            latency_us: 18_420,
            budget_overruns: 3,
            dropped_frames: 11,
        }),
    },
    Message {
        seq: 5121,
        timestamp: valid!(Timestamp::from_us(1_234_571_200)),
        body: Body::ArmState(ArmState {
            position_mm: [690, -120, 905],
            // About 180 degrees about x (probe pointing down), tilted by a few degrees.
            orientation: valid!(UnitQuatQ14::new_checked([819, 16353, 328, -492])),
        }),
    },
    Message {
        seq: 12,
        timestamp: valid!(Timestamp::from_us(1_234_580_000)),
        body: Body::Command(Command::SetShapeMode(ShapeMode::Continuous)),
    },
];

/// The sample messages (see [`MESSAGES`]).
pub fn messages() -> [Message; 7] {
    MESSAGES
}
