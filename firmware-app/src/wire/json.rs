//! JSON form of wire messages, shared by `supine wire sample --format json` and `supine wire decode`.
//!
//! One object per message: `kind` (snake_case kind name), `seq`, `timestamp_us`, then the kind's fields. Lengths
//! are integer millimetres (`*_mm`), as on the wire. Fixed-point values appear twice: raw (`*_q14`,
//! `coefficients_milli`, `frame_rate_chz`, `*_id`) and in physical units (`orientation` [w, x, y, z],
//! `normal`, `coefficients` in standard deviations, `frame_rate_hz`, enum names), so scripts can compare either.
//! Salient points are an object keyed by point name (`head`, `left_shoulder`, ...).

use serde_json::{Map, Value, json};
use supine_core::salient::SalientPoint;
use supine_core::wire::{Body, Command, Message};

/// The JSON object for one message.
pub fn message(m: &Message) -> Value {
    let mut obj = Map::new();
    obj.insert("kind".into(), json!(m.kind().name()));
    obj.insert("seq".into(), json!(m.seq));
    obj.insert("timestamp_us".into(), json!(m.timestamp.as_us()));
    let fields = match &m.body {
        Body::TorsoPose(p) => json!({
            "position_mm": p.position_mm,
            "orientation_q14": p.orientation.raw(),
            "orientation": p.orientation.to_f32(),
            "confidence_pct": p.confidence.percent(),
        }),
        Body::SalientPoints(sp) => {
            let mut points = Map::new();
            for (id, p) in SalientPoint::ALL.iter().zip(sp.points.iter()) {
                points.insert(
                    id.name().into(),
                    json!({ "position_mm": p.position_mm, "confidence_pct": p.confidence.percent() }),
                );
            }
            json!({ "points": points })
        }
        Body::Probe(p) => json!({
            "tip_mm": p.tip_mm,
            "nearest_mm": p.nearest_mm,
            "normal_q14": p.normal.raw(),
            "normal": p.normal.to_f32(),
            "signed_distance_mm": p.signed_distance_mm,
            "region": p.region.name(),
            "region_id": u8::from(p.region),
        }),
        Body::BodyShape(s) => json!({
            "revision": s.revision,
            "coefficients_milli": s.coefficients_milli,
            "coefficients": s.coefficients_milli.map(|c| f64::from(c) / 1000.0),
        }),
        Body::Health(h) => json!({
            "state": h.state.name(),
            "state_id": u8::from(h.state),
            "frame_rate_chz": h.frame_rate_chz,
            "frame_rate_hz": f64::from(h.frame_rate_chz) / 100.0,
            "latency_us": h.latency_us,
            "budget_overruns": h.budget_overruns,
            "dropped_frames": h.dropped_frames,
        }),
        Body::ArmState(a) => json!({
            "position_mm": a.position_mm,
            "orientation_q14": a.orientation.raw(),
            "orientation": a.orientation.to_f32(),
        }),
        Body::Command(c) => {
            let (code, arg) = c.to_code_arg();
            let mode = match c {
                Command::SetShapeMode(m) => json!(m.name()),
                _ => Value::Null,
            };
            json!({ "command": c.name(), "command_id": code, "arg": arg, "shape_mode": mode })
        }
        // A kind added to core but not yet here: still say what it is rather than drop it.
        _ => json!({}),
    };
    if let Value::Object(f) = fields {
        obj.extend(f);
    }
    Value::Object(obj)
}
