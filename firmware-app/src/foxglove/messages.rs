//! [`FrameRecord`](super::FrameRecord) → the JSON messages of one frame (see the [module docs](super) for the channels and cost).

use serde_json::{Value, json};
use supine_core::geometry::{Isometry3, Point3};
use supine_core::salient::SalientPoint;

use super::owned::OwnedFrame;
use super::{FrameMessages, Topic};
use crate::wire::json as wire_json;

/// The camera's frame id (optical frame: x right, y down, z forward).
pub const CAMERA_FRAME: &str = "camera";
/// The torso frame id.
pub const TORSO_FRAME: &str = "torso";
/// The robot base frame id.
pub const ROBOT_BASE_FRAME: &str = "robot_base";

/// Encode one frame's messages at log time `log_ns`; `robot_base_from_camera` places the camera when calibrated.
pub fn encode_frame(
    record: &OwnedFrame,
    log_ns: u64,
    robot_base_from_camera: Option<&Isometry3>,
) -> FrameMessages {
    let stamp = time(log_ns);
    let mut items = Vec::with_capacity(6 + record.packets.len());
    let mut push = |topic: Topic, v: Value| items.push((topic, v.to_string().into_bytes()));
    push(Topic::Depth, depth_image(record, &stamp));
    push(Topic::Calibration, calibration(record, &stamp));
    push(Topic::Scene, scene(record, &stamp));
    push(
        Topic::Transforms,
        transforms(record, &stamp, robot_base_from_camera),
    );
    for m in &record.packets {
        push(Topic::Packets, wire_json::message(m));
    }
    push(
        Topic::Tracker,
        json!({
            "timestamp": stamp,
            "frame": record.index,
            "capture_us": record.capture.as_us(),
            "state": record.state.map(|s| s.name()),
            "packets": record.packets.len(),
        }),
    );
    FrameMessages { log_ns, items }
}

fn time(ns: u64) -> Value {
    json!({ "sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000 })
}

fn xyz(p: &Point3) -> Value {
    json!({ "x": p.x, "y": p.y, "z": p.z })
}

fn identity_pose() -> Value {
    json!({ "position": { "x": 0.0, "y": 0.0, "z": 0.0 }, "orientation": { "x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0 } })
}

fn rgba(r: f32, g: f32, b: f32, a: f32) -> Value {
    json!({ "r": r, "g": g, "b": b, "a": a })
}

fn depth_image(record: &OwnedFrame, stamp: &Value) -> Value {
    let px = &record.depth_mm;
    let mut bytes = Vec::with_capacity(px.len() * 2);
    for d in px {
        bytes.extend_from_slice(&d.to_le_bytes());
    }
    json!({
        "timestamp": stamp,
        "frame_id": CAMERA_FRAME,
        "width": record.width,
        "height": record.height,
        "encoding": "16UC1",
        "step": record.width as u32 * 2,
        "data": base64(&bytes),
    })
}

fn calibration(record: &OwnedFrame, stamp: &Value) -> Value {
    let k = &record.intrinsics;
    let (fx, fy, cx, cy) = (k.fx as f64, k.fy as f64, k.cx as f64, k.cy as f64);
    json!({
        "timestamp": stamp,
        "frame_id": CAMERA_FRAME,
        "width": k.width,
        "height": k.height,
        "distortion_model": "plumb_bob",
        "D": [0.0, 0.0, 0.0, 0.0, 0.0],
        "K": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "P": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    })
}

/// An entity with every primitive list present (Foxglove's JSON reader expects them).
fn entity(
    stamp: &Value,
    frame_id: &str,
    id: &str,
    spheres: Vec<Value>,
    lines: Vec<Value>,
    triangles: Vec<Value>,
) -> Value {
    json!({
        "timestamp": stamp,
        "frame_id": frame_id,
        "id": id,
        "lifetime": { "sec": 0, "nsec": 0 },
        "frame_locked": true,
        "metadata": [],
        "arrows": [], "cubes": [], "spheres": spheres, "cylinders": [], "lines": lines,
        "triangles": triangles, "texts": [], "models": [],
    })
}

fn sphere(p: &Point3, diameter_m: f32, color: Value) -> Value {
    json!({
        "pose": { "position": xyz(p), "orientation": { "x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0 } },
        "size": { "x": diameter_m, "y": diameter_m, "z": diameter_m },
        "color": color,
    })
}

/// A colour per salient point, in [`SalientPoint::ALL`] order (head, shoulders, belly, hips).
const SALIENT_RGB: [(f32, f32, f32); SalientPoint::COUNT] = [
    (1.0, 1.0, 0.2),
    (0.2, 0.6, 1.0),
    (1.0, 0.4, 0.2),
    (0.9, 0.2, 0.9),
    (0.2, 0.9, 0.9),
    (1.0, 0.6, 0.0),
];

fn scene(record: &OwnedFrame, stamp: &Value) -> Value {
    let mut entities = Vec::new();
    if let Some(torso) = &record.torso {
        let points: Vec<Value> = torso.vertices.iter().map(xyz).collect();
        let indices: Vec<u32> = torso.triangles.iter().flatten().copied().collect();
        let mesh = json!({
            "pose": identity_pose(),
            "points": points,
            "color": rgba(0.3, 0.8, 0.4, 0.6),
            "colors": [],
            "indices": indices,
        });
        entities.push(entity(stamp, TORSO_FRAME, "torso", vec![], vec![], vec![mesh]));
    }
    if let Some(points) = record.salient {
        let spheres = points
            .iter()
            .zip(SALIENT_RGB)
            .map(|(p, (r, g, b))| sphere(p, 0.04, rgba(r, g, b, 1.0)))
            .collect();
        entities.push(entity(
            stamp,
            CAMERA_FRAME,
            "salient_points",
            spheres,
            vec![],
            vec![],
        ));
    }
    if let Some(probe) = &record.probe {
        let mut spheres = vec![sphere(&probe.tip, 0.02, rgba(1.0, 0.1, 0.1, 1.0))];
        let mut lines = Vec::new();
        if let Some(q) = &probe.surface_point {
            spheres.push(sphere(q, 0.015, rgba(0.1, 1.0, 0.1, 1.0)));
            lines.push(json!({
                "type": 0,
                "pose": identity_pose(),
                "thickness": 0.004,
                "scale_invariant": false,
                "points": [xyz(&probe.tip), xyz(q)],
                "color": rgba(1.0, 1.0, 1.0, 1.0),
                "colors": [],
                "indices": [],
            }));
        }
        entities.push(entity(stamp, CAMERA_FRAME, "probe", spheres, lines, vec![]));
    }
    // Everything is redrawn each frame: what the tracker lost this frame disappears.
    json!({
        "deletions": [{ "timestamp": stamp, "type": 1, "id": "" }],
        "entities": entities,
    })
}

fn transform(stamp: &Value, parent: &str, child: &str, parent_from_child: &Isometry3) -> Value {
    let t = parent_from_child.translation.vector;
    let q = parent_from_child.rotation;
    json!({
        "timestamp": stamp,
        "parent_frame_id": parent,
        "child_frame_id": child,
        "translation": { "x": t.x, "y": t.y, "z": t.z },
        "rotation": { "x": q.i, "y": q.j, "z": q.k, "w": q.w },
    })
}

fn transforms(record: &OwnedFrame, stamp: &Value, robot_base_from_camera: Option<&Isometry3>) -> Value {
    let mut list = Vec::new();
    if let Some(t) = robot_base_from_camera {
        list.push(transform(stamp, ROBOT_BASE_FRAME, CAMERA_FRAME, t));
    }
    if let Some(torso) = &record.torso {
        list.push(transform(
            stamp,
            CAMERA_FRAME,
            TORSO_FRAME,
            &torso.camera_from_torso,
        ));
    }
    json!({ "transforms": list })
}

/// Standard base64 with padding (RFC 4648), what JSON schemas' `contentEncoding: base64` means.
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}
