//! How each message maps onto a group of classic CAN frames (the table in SPEC.md and `supine.dbc`).
//!
//! A message of kind `k` is the group of frames at ids `base + 0x10·k + i`, `i = 0..group_len(k)`. Frame 0
//! (`*_HEAD`) carries the full sequence number and up to 4 bytes of the kind's small fields, frame 1 (`*_TIME`)
//! the 48-bit capture timestamp, the rest one signal group each (a position `x, y, z`, a quaternion half, ...).
//! Every frame's counter is the message's `seq & 0xF`, which ties the group together. Signals are little-endian
//! (Intel) and byte-aligned; reserved bytes are sent as 0 and ignored on receipt. Positions and distances are i16
//! mm on CAN (±32.767 m): encoding refuses, rather than clamps, a value outside that range.
//!
//! Cost: encoding or decoding a group is a few dozen byte moves plus one 9-byte CRC per frame; no allocation.

use heapless::Vec;

use super::can::{self, CanBase, CanFrame, CanId, field};
use super::error::{DecodeError, EncodeError};
use super::message::{
    ArmState, Body, BodyShape, Command, Health, Kind, Message, ProbeReport, SalientPointReport,
    SalientPoints, TorsoPose,
};
use super::types::{BodyRegion, Confidence, NormalQ14, Timestamp, TrackerState, UnitQuatQ14};
use crate::body_model::SHAPE_COMPONENTS;
use crate::salient::SalientPoint;

/// The six signal bytes of one frame.
pub type Signals = [u8; field::SIGNAL_LEN];

/// The most frames any message needs (salient points and body shape).
pub const MAX_GROUP_FRAMES: usize = 9;

/// The frames of one message, in index order.
pub type CanGroup = Vec<CanFrame, MAX_GROUP_FRAMES>;

/// Frame names per kind, in index order (the DBC's message names).
const NAMES: [&[&str]; 7] = [
    &["CMD_HEAD", "CMD_TIME"],
    &["ARM_HEAD", "ARM_TIME", "ARM_POS", "ARM_ROT_A", "ARM_ROT_B"],
    &[
        "TORSO_HEAD",
        "TORSO_TIME",
        "TORSO_POS",
        "TORSO_ROT_A",
        "TORSO_ROT_B",
    ],
    &[
        "PROBE_HEAD",
        "PROBE_TIME",
        "PROBE_TIP",
        "PROBE_NEAREST",
        "PROBE_NORMAL",
    ],
    &[
        "POINTS_HEAD",
        "POINTS_TIME",
        "POINT_HEAD",
        "POINT_L_SHOULDER",
        "POINT_R_SHOULDER",
        "POINT_BELLY",
        "POINT_L_HIP",
        "POINT_R_HIP",
        "POINTS_CONF",
    ],
    &[
        "HEALTH_HEAD",
        "HEALTH_TIME",
        "HEALTH_LATENCY",
        "HEALTH_OVERRUNS",
        "HEALTH_DROPPED",
    ],
    &[
        "SHAPE_HEAD",
        "SHAPE_TIME",
        "SHAPE_COEF_0",
        "SHAPE_COEF_1",
        "SHAPE_COEF_2",
        "SHAPE_COEF_3",
        "SHAPE_COEF_4",
        "SHAPE_COEF_5",
        "SHAPE_COEF_6",
    ],
];

/// Frames in a group of this kind.
pub fn group_len(kind: Kind) -> usize {
    NAMES.get(kind as usize).map_or(0, |n| n.len())
}

/// The DBC name of frame `index` of a kind's group.
pub fn frame_name(kind: Kind, index: usize) -> Option<&'static str> {
    NAMES.get(kind as usize)?.get(index).copied()
}

/// Kind and index of the frame at `offset` from the base, if that offset is a supine frame.
pub fn locate(offset: u8) -> Option<(Kind, usize)> {
    let kind = Kind::from_u8(offset >> 4)?;
    let index = usize::from(offset & 0x0F);
    if index < group_len(kind) {
        Some((kind, index))
    } else {
        None
    }
}

/// Offset from the base of frame `index` of a kind's group.
pub const fn offset(kind: Kind, index: usize) -> u8 {
    ((kind as u8) << 4) | (index as u8 & 0x0F)
}

fn put(s: &mut Signals, at: usize, bytes: &[u8]) {
    if let Some(dst) = s.get_mut(at..at + bytes.len()) {
        dst.copy_from_slice(bytes);
    }
}

fn get<const N: usize>(s: &Signals, at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    if let Some(src) = s.get(at..at + N) {
        out.copy_from_slice(src);
    }
    out
}

fn get_i16(s: &Signals, at: usize) -> i16 {
    i16::from_le_bytes(get(s, at))
}

fn get_u16(s: &Signals, at: usize) -> u16 {
    u16::from_le_bytes(get(s, at))
}

fn get_u32(s: &Signals, at: usize) -> u32 {
    u32::from_le_bytes(get(s, at))
}

fn mm16(v: i32) -> Result<i16, EncodeError> {
    i16::try_from(v).map_err(|_| EncodeError::NotRepresentable)
}

fn xyz_mm(v: [i32; 3]) -> Result<Signals, EncodeError> {
    xyz_raw([mm16(v[0])?, mm16(v[1])?, mm16(v[2])?])
}

fn xyz_raw(v: [i16; 3]) -> Result<Signals, EncodeError> {
    let mut s = Signals::default();
    for (i, c) in v.iter().enumerate() {
        put(&mut s, 2 * i, &c.to_le_bytes());
    }
    Ok(s)
}

fn read_xyz(s: &Signals) -> [i16; 3] {
    [get_i16(s, 0), get_i16(s, 2), get_i16(s, 4)]
}

fn read_xyz_mm(s: &Signals) -> [i32; 3] {
    read_xyz(s).map(i32::from)
}

/// Quaternion halves: `[w, x, y]` in the first frame, `z` (bytes 0..2) in the second.
fn quat_frames(q: UnitQuatQ14) -> Result<[Signals; 2], EncodeError> {
    let [w, x, y, z] = q.raw();
    let mut b = Signals::default();
    put(&mut b, 0, &z.to_le_bytes());
    Ok([xyz_raw([w, x, y])?, b])
}

fn read_quat(a: &Signals, b: &Signals) -> Result<UnitQuatQ14, DecodeError> {
    let [w, x, y] = read_xyz(a);
    UnitQuatQ14::new_checked([w, x, y, get_i16(b, 0)]).ok_or(DecodeError::InvalidValue)
}

/// The signal bytes of every frame of `msg`'s group, and how many frames it has.
fn to_signals(msg: &Message) -> Result<([Signals; MAX_GROUP_FRAMES], usize), EncodeError> {
    let mut s = [Signals::default(); MAX_GROUP_FRAMES];
    put(&mut s[0], 0, &msg.seq.to_le_bytes());
    put(&mut s[1], 0, &msg.timestamp.as_us().to_le_bytes()[..6]);
    match &msg.body {
        Body::Command(c) => {
            let (code, arg) = c.to_code_arg();
            put(&mut s[0], 2, &[code, arg]);
        }
        Body::ArmState(a) => {
            s[2] = xyz_mm(a.position_mm)?;
            [s[3], s[4]] = quat_frames(a.orientation)?;
        }
        Body::TorsoPose(t) => {
            put(&mut s[0], 2, &[t.confidence.percent()]);
            s[2] = xyz_mm(t.position_mm)?;
            [s[3], s[4]] = quat_frames(t.orientation)?;
        }
        Body::Probe(p) => {
            put(&mut s[0], 2, &[u8::from(p.region)]);
            put(&mut s[0], 4, &mm16(p.signed_distance_mm)?.to_le_bytes());
            s[2] = xyz_mm(p.tip_mm)?;
            s[3] = xyz_mm(p.nearest_mm)?;
            s[4] = xyz_raw(p.normal.raw())?;
        }
        Body::SalientPoints(sp) => {
            for (i, p) in sp.points.iter().enumerate() {
                s[2 + i] = xyz_mm(p.position_mm)?;
                put(&mut s[8], i, &[p.confidence.percent()]);
            }
        }
        Body::Health(h) => {
            put(&mut s[0], 2, &[u8::from(h.state)]);
            put(&mut s[0], 4, &h.frame_rate_chz.to_le_bytes());
            put(&mut s[2], 0, &h.latency_us.to_le_bytes());
            put(&mut s[3], 0, &h.budget_overruns.to_le_bytes());
            put(&mut s[4], 0, &h.dropped_frames.to_le_bytes());
        }
        Body::BodyShape(b) => {
            put(&mut s[0], 2, &[b.revision]);
            for (i, c) in b.coefficients_milli.iter().enumerate() {
                put(&mut s[2 + i / 3], 2 * (i % 3), &c.to_le_bytes());
            }
        }
    }
    Ok((s, group_len(msg.kind())))
}

/// Rebuild a message of `kind` from the signal bytes of its complete group (frames in index order).
pub fn from_signals(kind: Kind, s: &[Signals; MAX_GROUP_FRAMES]) -> Result<Message, DecodeError> {
    let [h, t, f2, f3, f4, f5, f6, f7, f8] = s;
    let seq = get_u16(h, 0);
    let mut ts = [0u8; 8];
    ts[..6].copy_from_slice(&t[..]);
    let timestamp = Timestamp::from_us(u64::from_le_bytes(ts)).ok_or(DecodeError::InvalidValue)?;
    let bad = DecodeError::InvalidValue;
    let body = match kind {
        Kind::Command => Body::Command(Command::from_code_arg(h[2], h[3]).ok_or(bad)?),
        Kind::ArmState => Body::ArmState(ArmState {
            position_mm: read_xyz_mm(f2),
            orientation: read_quat(f3, f4)?,
        }),
        Kind::TorsoPose => Body::TorsoPose(TorsoPose {
            position_mm: read_xyz_mm(f2),
            orientation: read_quat(f3, f4)?,
            confidence: Confidence::new(h[2]).ok_or(bad)?,
        }),
        Kind::Probe => Body::Probe(ProbeReport {
            tip_mm: read_xyz_mm(f2),
            nearest_mm: read_xyz_mm(f3),
            normal: NormalQ14::new_checked(read_xyz(f4)).ok_or(bad)?,
            signed_distance_mm: i32::from(get_i16(h, 4)),
            region: BodyRegion::from_u8(h[2]).ok_or(bad)?,
        }),
        Kind::SalientPoints => {
            let frames = [f2, f3, f4, f5, f6, f7];
            let mut points = [SalientPointReport {
                position_mm: [0; 3],
                confidence: Confidence::default(),
            }; SalientPoint::COUNT];
            for ((p, f), &c) in points.iter_mut().zip(frames).zip(f8.iter()) {
                *p = SalientPointReport {
                    position_mm: read_xyz_mm(f),
                    confidence: Confidence::new(c).ok_or(bad)?,
                };
            }
            Body::SalientPoints(SalientPoints { points })
        }
        Kind::Health => Body::Health(Health {
            state: TrackerState::from_u8(h[2]).ok_or(bad)?,
            frame_rate_chz: get_u16(h, 4),
            latency_us: get_u32(f2, 0),
            budget_overruns: get_u32(f3, 0),
            dropped_frames: get_u32(f4, 0),
        }),
        Kind::BodyShape => {
            let coefficients_milli: [i16; SHAPE_COMPONENTS] =
                core::array::from_fn(|i| s.get(2 + i / 3).map_or(0, |f| get_i16(f, 2 * (i % 3))));
            Body::BodyShape(BodyShape {
                revision: h[2],
                coefficients_milli,
            })
        }
    };
    Ok(Message { seq, timestamp, body })
}

/// Encode `msg` as its group of CAN frames at `base`.
pub fn encode_group(msg: &Message, base: CanBase) -> Result<CanGroup, EncodeError> {
    let (signals, n) = to_signals(msg)?;
    let kind = msg.kind();
    let counter = (msg.seq & 0x0F) as u8;
    let mut group = CanGroup::new();
    for (i, s) in signals.iter().enumerate().take(n) {
        let off = offset(kind, i);
        let id = base.id_at(off).ok_or(EncodeError::NotRepresentable)?;
        let data = can::seal(can::data_id(off), counter, s);
        let frame = CanFrame::new(CanId::Standard(id), &data).ok_or(EncodeError::BufferTooSmall)?;
        group.push(frame).map_err(|_| EncodeError::BufferTooSmall)?;
    }
    Ok(group)
}
