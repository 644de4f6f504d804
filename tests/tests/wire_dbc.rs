//! The encoder and `supine.dbc` agree: a small DBC parser (BO_, SG_, VAL_ and GenMsgCycleTime lines) decodes
//! every CAN frame of every sample message, and each signal must equal the value computed here, independently of
//! the encoder, from the typed message fields.

use std::collections::BTreeMap;

use supine_core::crc::crc8_sae_j1850;
use supine_core::wire::can::CanBase;
use supine_core::wire::sample::MESSAGES;
use supine_core::wire::{Body, DBC, Kind, Message, can_map};

#[derive(Debug)]
struct Signal {
    name: String,
    start: u32,
    len: u32,
    signed: bool,
    factor: f64,
    offset: f64,
}

#[derive(Debug)]
struct DbcMessage {
    name: String,
    len: usize,
    signals: Vec<Signal>,
}

#[derive(Debug, Default)]
struct Dbc {
    messages: BTreeMap<u32, DbcMessage>,
    values: BTreeMap<(u32, String), BTreeMap<i64, String>>,
    cycle_ms: BTreeMap<u32, u32>,
}

fn parse_dbc(text: &str) -> Dbc {
    let mut dbc = Dbc::default();
    let mut current: Option<u32> = None;
    for line in text.lines() {
        let t = line.trim();
        if let Some(rest) = t.strip_prefix("BO_ ") {
            // BO_ 288 NAME: 8 SENDER
            let mut it = rest.split_whitespace();
            let id: u32 = it.next().unwrap().parse().unwrap();
            let name = it.next().unwrap().trim_end_matches(':').to_string();
            let len: usize = it.next().unwrap().parse().unwrap();
            dbc.messages.insert(
                id,
                DbcMessage {
                    name,
                    len,
                    signals: Vec::new(),
                },
            );
            current = Some(id);
        } else if let Some(rest) = t.strip_prefix("SG_ ") {
            // SG_ Name : 16|16@1- (0.001,0) [min|max] "unit" RECEIVER
            let (name, spec) = rest.split_once(" : ").unwrap();
            let mut it = spec.split_whitespace();
            let layout = it.next().unwrap();
            let (start, rest) = layout.split_once('|').unwrap();
            let (len, order_sign) = rest.split_once('@').unwrap();
            assert!(
                order_sign.starts_with('1'),
                "{name}: only Intel (little-endian) signals are used"
            );
            let scale = it.next().unwrap().trim_matches(|c| c == '(' || c == ')');
            let (factor, offset) = scale.split_once(',').unwrap();
            let msg = dbc.messages.get_mut(&current.unwrap()).unwrap();
            msg.signals.push(Signal {
                name: name.trim().to_string(),
                start: start.parse().unwrap(),
                len: len.parse().unwrap(),
                signed: order_sign.ends_with('-'),
                factor: factor.parse().unwrap(),
                offset: offset.parse().unwrap(),
            });
        } else if let Some(rest) = t.strip_prefix("VAL_ ") {
            // VAL_ 336 State 0 "initialising" 1 "tracking" ;
            let mut it = rest.splitn(3, ' ');
            let id: u32 = it.next().unwrap().parse().unwrap();
            let sig = it.next().unwrap().to_string();
            let mut table = BTreeMap::new();
            let mut pairs = it.next().unwrap().trim_end_matches(';').split('"');
            while let (Some(v), Some(name)) = (pairs.next(), pairs.next()) {
                table.insert(v.trim().parse().unwrap(), name.to_string());
            }
            dbc.values.insert((id, sig), table);
        } else if let Some(rest) = t.strip_prefix("BA_ \"GenMsgCycleTime\" BO_ ") {
            let mut it = rest.trim_end_matches(';').split_whitespace();
            let id = it.next().unwrap().parse().unwrap();
            dbc.cycle_ms.insert(id, it.next().unwrap().parse().unwrap());
        }
    }
    dbc
}

/// Raw value of a little-endian signal.
fn raw(data: &[u8], s: &Signal) -> i64 {
    let word = data.iter().rev().fold(0u64, |a, &b| (a << 8) | u64::from(b));
    let mask = if s.len == 64 {
        u64::MAX
    } else {
        (1u64 << s.len) - 1
    };
    let v = (word >> s.start) & mask;
    if s.signed && s.len < 64 && v >> (s.len - 1) == 1 {
        (v | !mask) as i64
    } else {
        v as i64
    }
}

/// A signal's expected value: physical for scaled signals, or an enum name for VAL_ signals.
#[derive(Debug, PartialEq)]
enum Want {
    Num(f64),
    Name(&'static str),
}

const Q14: f64 = 1.0 / 16384.0;

fn xyz(frame: &'static str, prefix: &str, v: [i32; 3], out: &mut Vec<(&'static str, String, Want)>) {
    for (axis, c) in ["X", "Y", "Z"].iter().zip(v) {
        out.push((frame, format!("{prefix}{axis}"), Want::Num(f64::from(c))));
    }
}

fn quat(prefix: &'static str, q: [i16; 4], out: &mut Vec<(&'static str, String, Want)>) {
    let (a, b): (&'static str, &'static str) = if prefix == "ARM" {
        ("ARM_ROT_A", "ARM_ROT_B")
    } else {
        ("TORSO_ROT_A", "TORSO_ROT_B")
    };
    for (i, n) in ["RotW", "RotX", "RotY"].iter().enumerate() {
        out.push((a, n.to_string(), Want::Num(f64::from(q[i]) * Q14)));
    }
    out.push((b, "RotZ".into(), Want::Num(f64::from(q[3]) * Q14)));
}

/// Every signal of every frame of `m`, computed from the typed fields (not from the encoder).
fn expected(m: &Message) -> Vec<(&'static str, String, Want)> {
    let mut out = Vec::new();
    let kind = m.kind();
    let head = can_map::frame_name(kind, 0).unwrap();
    let time = can_map::frame_name(kind, 1).unwrap();
    for i in 0..can_map::group_len(kind) {
        let f = can_map::frame_name(kind, i).unwrap();
        out.push((f, "Counter".into(), Want::Num(f64::from(m.seq & 0xF))));
    }
    out.push((head, "Seq".into(), Want::Num(f64::from(m.seq))));
    out.push((time, "TimestampUs".into(), Want::Num(m.timestamp.as_us() as f64)));
    match &m.body {
        Body::TorsoPose(p) => {
            out.push((
                "TORSO_HEAD",
                "Confidence".into(),
                Want::Num(f64::from(p.confidence.percent())),
            ));
            xyz("TORSO_POS", "Pos", p.position_mm, &mut out);
            quat("TORSO", p.orientation.raw(), &mut out);
        }
        Body::ArmState(a) => {
            xyz("ARM_POS", "Pos", a.position_mm, &mut out);
            quat("ARM", a.orientation.raw(), &mut out);
        }
        Body::SalientPoints(sp) => {
            let frames = [
                "POINT_HEAD",
                "POINT_L_SHOULDER",
                "POINT_R_SHOULDER",
                "POINT_BELLY",
                "POINT_L_HIP",
                "POINT_R_HIP",
            ];
            let conf = [
                "ConfHead",
                "ConfLShoulder",
                "ConfRShoulder",
                "ConfBelly",
                "ConfLHip",
                "ConfRHip",
            ];
            for ((f, c), p) in frames.iter().zip(conf).zip(sp.points.iter()) {
                xyz(f, "Pos", p.position_mm, &mut out);
                out.push((
                    "POINTS_CONF",
                    c.into(),
                    Want::Num(f64::from(p.confidence.percent())),
                ));
            }
        }
        Body::Probe(p) => {
            out.push(("PROBE_HEAD", "Region".into(), Want::Name(p.region.name())));
            out.push((
                "PROBE_HEAD",
                "SignedDistance".into(),
                Want::Num(f64::from(p.signed_distance_mm)),
            ));
            xyz("PROBE_TIP", "Tip", p.tip_mm, &mut out);
            xyz("PROBE_NEAREST", "Nearest", p.nearest_mm, &mut out);
            for (axis, c) in ["X", "Y", "Z"].iter().zip(p.normal.raw()) {
                out.push((
                    "PROBE_NORMAL",
                    format!("Normal{axis}"),
                    Want::Num(f64::from(c) * Q14),
                ));
            }
        }
        Body::Health(h) => {
            out.push(("HEALTH_HEAD", "State".into(), Want::Name(h.state.name())));
            out.push((
                "HEALTH_HEAD",
                "FrameRate".into(),
                Want::Num(f64::from(h.frame_rate_chz) / 100.0),
            ));
            out.push((
                "HEALTH_LATENCY",
                "LatencyUs".into(),
                Want::Num(f64::from(h.latency_us)),
            ));
            out.push((
                "HEALTH_OVERRUNS",
                "BudgetOverruns".into(),
                Want::Num(f64::from(h.budget_overruns)),
            ));
            out.push((
                "HEALTH_DROPPED",
                "DroppedFrames".into(),
                Want::Num(f64::from(h.dropped_frames)),
            ));
        }
        Body::BodyShape(s) => {
            out.push(("SHAPE_HEAD", "Revision".into(), Want::Num(f64::from(s.revision))));
            let names = [
                "SHAPE_COEF_0",
                "SHAPE_COEF_1",
                "SHAPE_COEF_2",
                "SHAPE_COEF_3",
                "SHAPE_COEF_4",
                "SHAPE_COEF_5",
                "SHAPE_COEF_6",
            ];
            for (i, c) in s.coefficients_milli.iter().enumerate() {
                out.push((
                    names[i / 3],
                    format!("Coef{i}"),
                    Want::Num(f64::from(*c) / 1000.0),
                ));
            }
        }
        Body::Command(c) => {
            let (_code, arg) = c.to_code_arg();
            let name = c.name();
            out.push(("CMD_HEAD", "Command".into(), Want::Name(name)));
            let mode = ["frozen", "once", "continuous"][usize::from(arg)];
            out.push(("CMD_HEAD", "ShapeMode".into(), Want::Name(mode)));
        }
        other => panic!("no DBC expectation for {other:?}"),
    }
    out
}

#[test]
fn dbc_describes_exactly_the_frames_the_encoder_sends() {
    let dbc = parse_dbc(DBC);
    let mut want = BTreeMap::new();
    for k in Kind::ALL {
        for i in 0..can_map::group_len(k) {
            let id = 0x100 + u32::from(can_map::offset(k, i));
            want.insert(id, can_map::frame_name(k, i).unwrap().to_string());
        }
    }
    let got: BTreeMap<u32, String> = dbc.messages.iter().map(|(id, m)| (*id, m.name.clone())).collect();
    assert_eq!(got, want);
    for (id, m) in &dbc.messages {
        assert_eq!(m.len, 8, "{}", m.name);
        assert!(
            dbc.cycle_ms.contains_key(id) || m.name.starts_with("CMD_"),
            "{} has no cycle time",
            m.name
        );
        let mut bits = 0u64;
        for s in &m.signals {
            let mask = (if s.len == 64 {
                u64::MAX
            } else {
                (1u64 << s.len) - 1
            }) << s.start;
            assert_eq!(bits & mask, 0, "{}.{} overlaps", m.name, s.name);
            assert!(s.start + s.len <= 64, "{}.{} runs past the frame", m.name, s.name);
            bits |= mask;
        }
    }
}

#[test]
fn every_sample_frame_decodes_through_the_dbc_to_the_typed_values() {
    let dbc = parse_dbc(DBC);
    let mut checked = 0;
    for m in &MESSAGES {
        let mut want = expected(m);
        for frame in can_map::encode_group(m, CanBase::DEFAULT).unwrap() {
            let id = frame.id().raw();
            let msg = dbc
                .messages
                .get(&id)
                .unwrap_or_else(|| panic!("id 0x{id:X} not in the DBC"));
            assert_eq!(frame.data().len(), msg.len);
            for s in &msg.signals {
                let r = raw(frame.data(), s);
                if s.name == "Crc" {
                    let d = frame.data();
                    let data_id = (0x0100u16 | (id as u16 - 0x100)).to_le_bytes();
                    let mut covered = vec![data_id[0], data_id[1]];
                    covered.extend_from_slice(&d[1..]);
                    assert_eq!(r, i64::from(crc8_sae_j1850(&covered)), "{}.Crc", msg.name);
                    continue;
                }
                let pos = want
                    .iter()
                    .position(|(f, n, _)| *f == msg.name && *n == s.name)
                    .unwrap_or_else(|| panic!("{}.{} has no expected value", msg.name, s.name));
                let (_, _, w) = want.remove(pos);
                match (w, dbc.values.get(&(id, s.name.clone()))) {
                    (Want::Name(name), Some(table)) => {
                        assert_eq!(
                            table.get(&r).map(String::as_str),
                            Some(name),
                            "{}.{}",
                            msg.name,
                            s.name
                        )
                    }
                    (Want::Num(v), None) => {
                        let phys = r as f64 * s.factor + s.offset;
                        assert!(
                            (phys - v).abs() < 1e-9,
                            "{}.{}: dbc {phys} typed {v}",
                            msg.name,
                            s.name
                        );
                    }
                    (w, t) => panic!("{}.{}: expected {w:?} but VAL_ table {t:?}", msg.name, s.name),
                }
                checked += 1;
            }
        }
        assert!(want.is_empty(), "expected signals missing from the DBC: {want:?}");
    }
    assert!(checked > 100, "only {checked} signals compared");
}
