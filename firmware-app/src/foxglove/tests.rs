//! The Foxglove outputs on the committed demo recording with overlays made from its ground truth: the messages, an
//! MCAP file read back with the `mcap` crate, and the live view read by a WebSocket client.

use std::io::Cursor;
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde_json::Value;
use supine_core::body_model::BodyModelView;
use supine_core::geometry::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use supine_core::time::Timestamp;
use supine_core::torso::{TorsoBuffers, TorsoSurface};
use supine_core::wire::{Body, Health, Message, TrackerState};
use supine_drivers::source::{DepthSource, SourceErrorKind};

use super::live::LiveView;
use super::mcap_out::McapRecorder;
use super::messages::base64;
use super::owned::OwnedFrame;
use super::*;

/// [`encode_frame`] of a borrowed record, as the outputs thread does after the copy.
fn encode(r: &FrameRecord<'_>, log_ns: u64, base: Option<&Isometry3>) -> FrameMessages {
    let mut owned = OwnedFrame::default();
    owned.copy_from(r);
    encode_frame(&owned, log_ns, base)
}

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

#[test]
fn base64_matches_rfc_4648_vectors() {
    for (plain, coded) in [
        ("", ""),
        ("f", "Zg=="),
        ("fo", "Zm8="),
        ("foo", "Zm9v"),
        ("foob", "Zm9vYg=="),
        ("fooba", "Zm9vYmE="),
        ("foobar", "Zm9vYmFy"),
    ] {
        assert_eq!(base64(plain.as_bytes()), coded);
    }
    assert_eq!(base64(&[0xff, 0xfe, 0x00]), "//4A");
}

#[test]
fn log_times_stay_increasing_when_capture_steps_back() {
    let mut clock = LogClock::default();
    let t = |us| Timestamp::from_us(us).unwrap();
    assert_eq!(clock.log_ns(t(1000)), 1_000_000);
    assert_eq!(clock.log_ns(t(34_333)), 34_333_000);
    // A looping file starts again at 0: one frame period after the last, then the same spacing.
    assert_eq!(clock.log_ns(t(0)), 34_333_000 + 33_333_333);
    assert_eq!(clock.log_ns(t(33_333)), 34_333_000 + 33_333_333 + 33_333_000);
}

/// Ground truth of the demo recording, one line per frame.
struct Truth {
    salient: [Point3; 6],
    camera_from_torso: Isometry3,
    probe_tip: Point3,
}

fn isometry(rows: &Value) -> Isometry3 {
    let m = |r: usize, c: usize| rows[r][c].as_f64().unwrap() as f32;
    let rot = Matrix3::new(
        m(0, 0),
        m(0, 1),
        m(0, 2),
        m(1, 0),
        m(1, 1),
        m(1, 2),
        m(2, 0),
        m(2, 1),
        m(2, 2),
    );
    Isometry3::from_parts(
        Translation3::new(m(0, 3), m(1, 3), m(2, 3)),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rot)),
    )
}

fn demo_truth() -> Vec<Truth> {
    let text = std::fs::read_to_string(repo("models/artifacts/demo/truth.jsonl")).unwrap();
    text.lines()
        .map(|line| {
            let v: Value = serde_json::from_str(line).unwrap();
            let p = |i: usize| {
                let a = &v["salient_camera"][i];
                Point3::new(
                    a[0].as_f64().unwrap() as f32,
                    a[1].as_f64().unwrap() as f32,
                    a[2].as_f64().unwrap() as f32,
                )
            };
            Truth {
                salient: [p(0), p(1), p(2), p(3), p(4), p(5)],
                camera_from_torso: isometry(&v["camera_from_torso"]),
                probe_tip: Point3::from(isometry(&v["camera_from_probe"]).translation.vector),
            }
        })
        .collect()
}

/// Frames of the demo recording with the truth as the overlays a tracker would give: salient points, the torso
/// shaped with the true coefficients, the probe tip and its nearest torso vertex, a health packet; every 10th frame
/// has no torso (as when the tracker loses it), so entities must disappear and come back.
fn record_demo(mut each: impl FnMut(&FrameRecord<'_>)) -> usize {
    let body = std::fs::read(repo("models/artifacts/body.sbm")).unwrap();
    let view = BodyModelView::parse(&body).unwrap();
    let seq: Value =
        serde_json::from_str(&std::fs::read_to_string(repo("models/artifacts/demo/sequence.json")).unwrap())
            .unwrap();
    let shape: Vec<f32> = seq["shape"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_f64().unwrap() as f32)
        .collect();
    let n = view.counts().subset;
    let (mut vertices, mut normals) = (vec![Point3::origin(); n], vec![Vector3::zeros(); n]);
    let mut regions = vec![supine_core::wire::BodyRegion::Chest; n];
    let surface = TorsoSurface::build(
        &view,
        &shape[..view.component_count()],
        TorsoBuffers {
            vertices: &mut vertices,
            normals: &mut normals,
            regions: &mut regions,
        },
    )
    .unwrap();
    let truth = demo_truth();
    let mut src = supine_drivers::source::open(&supine_drivers::SourceSpec::File {
        path: repo("models/artifacts/demo/sequence.oni"),
    })
    .unwrap();
    let k = src.intrinsics();
    let mut frames = 0;
    loop {
        let frame = match src.next_frame(Duration::ZERO) {
            Ok(f) => f,
            Err(e) if e.kind() == SourceErrorKind::EndOfStream => break,
            Err(e) => panic!("{e}"),
        };
        let t = &truth[frame.index as usize % truth.len()];
        let has_torso = frames % 10 != 9;
        let torso_from_camera = t.camera_from_torso.inverse();
        let tip_in_torso = torso_from_camera * t.probe_tip;
        let nearest = surface
            .vertices()
            .iter()
            .min_by(|a, b| (*a - tip_in_torso).norm().total_cmp(&(*b - tip_in_torso).norm()))
            .map(|v| t.camera_from_torso * v);
        let packets = [Message {
            seq: frames as u16,
            timestamp: frame.capture,
            body: Body::Health(Health {
                state: if has_torso {
                    TrackerState::Tracking
                } else {
                    TrackerState::Occluded
                },
                frame_rate_chz: 3000,
                latency_us: 1500,
                budget_overruns: 0,
                dropped_frames: 0,
            }),
        }];
        let record = FrameRecord {
            salient: Some(&t.salient),
            torso: has_torso.then_some(TorsoOverlay {
                surface,
                camera_from_torso: t.camera_from_torso,
            }),
            probe: Some(ProbeOverlay {
                tip: t.probe_tip,
                surface_point: nearest.filter(|_| has_torso),
            }),
            packets: &packets,
            state: Some(if has_torso {
                TrackerState::Tracking
            } else {
                TrackerState::Occluded
            }),
            ..FrameRecord::depth_only(frame, k)
        };
        each(&record);
        frames += 1;
    }
    frames
}

fn robot_base_from_camera() -> Isometry3 {
    Isometry3::from_parts(
        Translation3::new(0.4, 0.0, 1.6),
        UnitQuaternion::from_euler_angles(3.0, 0.0, 0.0),
    )
}

#[test]
fn frame_messages_carry_the_foxglove_fields() {
    let mut seen = 0;
    record_demo(|r| {
        if seen > 0 {
            return;
        }
        seen += 1;
        let m = encode(r, 5_000_000_123, Some(&robot_base_from_camera()));
        let get = |t: Topic| -> Value {
            let (_, data) = m.items.iter().find(|(topic, _)| *topic == t).unwrap();
            serde_json::from_slice(data).unwrap()
        };
        let img = get(Topic::Depth);
        assert_eq!(img["timestamp"], serde_json::json!({ "sec": 5, "nsec": 123 }));
        assert_eq!(
            (img["width"].as_u64(), img["height"].as_u64()),
            (Some(640), Some(480))
        );
        assert_eq!(img["encoding"], "16UC1");
        assert_eq!(img["step"], 1280);
        assert_eq!(
            img["data"].as_str().unwrap().len(),
            640 * 480 * 2 * 4 / 3 + 4 * ((640 * 480 * 2) % 3 != 0) as usize
        );
        let scene = get(Topic::Scene);
        let ids: Vec<&str> = scene["entities"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["id"].as_str().unwrap())
            .collect();
        assert_eq!(ids, ["torso", "salient_points", "probe"]);
        let mesh = &scene["entities"][0]["triangles"][0];
        let points = mesh["points"].as_array().unwrap().len();
        let indices = mesh["indices"].as_array().unwrap();
        assert!(points > 100 && indices.len() % 3 == 0 && !indices.is_empty());
        assert!(indices.iter().all(|i| (i.as_u64().unwrap() as usize) < points));
        assert_eq!(scene["entities"][1]["spheres"].as_array().unwrap().len(), 6);
        let tf = get(Topic::Transforms);
        let pairs: Vec<(String, String)> = tf["transforms"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| {
                (
                    t["parent_frame_id"].as_str().unwrap().into(),
                    t["child_frame_id"].as_str().unwrap().into(),
                )
            })
            .collect();
        assert_eq!(
            pairs,
            [
                ("robot_base".into(), "camera".into()),
                ("camera".into(), "torso".into())
            ]
        );
        let packet = get(Topic::Packets);
        assert_eq!(packet["kind"], "health");
        assert_eq!(packet["state"], "tracking");
        assert_eq!(get(Topic::Tracker)["state"], "tracking");
        let k = get(Topic::Calibration)["K"].as_array().unwrap().clone();
        assert!(k[0].as_f64().unwrap() > 500.0 && k[8] == 1.0);
    });
    assert_eq!(seen, 1);
}

/// Writes the demo with overlays to an MCAP file; `SUPINE_KEEP_MCAP=PATH` keeps a copy for tests/check_mcap.py.
#[test]
fn mcap_recording_of_the_demo_reads_back_with_schemas_counts_and_monotonic_times() {
    let mut recorder = McapRecorder::new(Cursor::new(Vec::new())).unwrap();
    let mut clock = LogClock::default();
    let base = robot_base_from_camera();
    let frames = record_demo(|r| {
        let m = encode(r, clock.log_ns(r.capture), Some(&base));
        recorder.write(&m).unwrap();
    });
    assert_eq!(frames, 60);
    let bytes = recorder.finish().unwrap().into_inner();
    if let Some(path) = std::env::var_os("SUPINE_KEEP_MCAP") {
        std::fs::write(&path, &bytes).unwrap();
    }
    let mut counts = std::collections::BTreeMap::<String, usize>::new();
    let mut last = 0u64;
    for msg in mcap::MessageStream::new(&bytes).unwrap() {
        let msg = msg.unwrap();
        assert!(msg.log_time >= last, "log time went back");
        last = msg.log_time;
        let schema = msg.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "jsonschema");
        assert_eq!(msg.channel.message_encoding, "json");
        let topic = Topic::ALL.iter().find(|t| t.name() == msg.channel.topic).unwrap();
        assert_eq!(schema.name, topic.schema_name());
        // Every payload is JSON.
        let _: Value = serde_json::from_slice(&msg.data).unwrap();
        *counts.entry(msg.channel.topic.clone()).or_default() += 1;
    }
    for t in Topic::ALL {
        assert_eq!(counts.get(t.name()), Some(&60), "{}", t.name());
    }
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.stats.unwrap().message_count, 360);
}

fn temp_file(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("supine-foxglove-{}-{name}", std::process::id()))
}

#[test]
fn outputs_record_every_frame_losslessly_on_their_own_thread() {
    use super::outputs::{FoxgloveOutputs, Pace};
    let path = temp_file("lossless.mcap");
    let file = std::fs::File::create(&path).unwrap();
    let mut outputs =
        FoxgloveOutputs::new(Some(file), None, Some(robot_base_from_camera()), Pace::Lossless).unwrap();
    assert!(outputs.wanted());
    let frames = record_demo(|r| outputs.frame(r));
    let report = outputs.finish().unwrap();
    assert_eq!((report.recorded, report.dropped), (frames as u64, 0));
    let bytes = std::fs::read(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    // Five per-frame channels plus one health packet per frame.
    assert_eq!(summary.stats.unwrap().message_count, 6 * frames as u64);
}

#[test]
fn outputs_for_the_service_drop_frames_instead_of_waiting() {
    use super::outputs::{FoxgloveOutputs, Pace, QUEUE_FRAMES};
    let path = temp_file("drop.mcap");
    let file = std::fs::File::create(&path).unwrap();
    let mut outputs = FoxgloveOutputs::new(Some(file), None, None, Pace::DropWhenBusy).unwrap();
    // The demo 3 times over as fast as the copies go: the encoder (a few ms a frame) cannot keep up, so frames
    // drop; every frame is either recorded or counted as dropped.
    let mut handed = 0u64;
    for _ in 0..3 {
        record_demo(|r| {
            outputs.frame(r);
            handed += 1;
        });
    }
    let report = outputs.finish().unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!(report.recorded + report.dropped, handed, "{report:?}");
    assert!(report.recorded >= QUEUE_FRAMES as u64, "{report:?}");
}

#[test]
fn outputs_with_nobody_watching_encode_nothing() {
    use super::outputs::{FoxgloveOutputs, Pace};
    let live = LiveView::bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let mut outputs = FoxgloveOutputs::new(None, Some(live), None, Pace::DropWhenBusy).unwrap();
    assert!(!outputs.wanted());
    record_demo(|r| outputs.frame(r));
    let report = outputs.finish().unwrap();
    assert_eq!(report.recorded, 0);
    assert_eq!(report.live.unwrap().queued, 0);
}

#[test]
fn a_recording_refuses_log_times_that_go_back() {
    let mut recorder = McapRecorder::new(Cursor::new(Vec::new())).unwrap();
    let frame = |log_ns| FrameMessages {
        log_ns,
        items: vec![(Topic::Tracker, b"{}".to_vec())],
    };
    recorder.write(&frame(10)).unwrap();
    let e = recorder.write(&frame(9)).unwrap_err();
    assert!(e.to_string().contains("before the previous frame"), "{e}");
}

fn read_json(ws: &mut tungstenite::WebSocket<TcpStream>) -> Value {
    loop {
        match ws.read().unwrap() {
            tungstenite::Message::Text(t) => return serde_json::from_str(&t).unwrap(),
            tungstenite::Message::Binary(_) => panic!("binary before the JSON expected"),
            _ => continue,
        }
    }
}

#[test]
fn live_view_serves_subscribed_channels_and_drops_for_slow_clients() {
    let live = LiveView::bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let url = format!("ws://{}", live.local_addr());
    let stream = TcpStream::connect(live.local_addr()).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let mut request = tungstenite::client::IntoClientRequest::into_client_request(url.as_str()).unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", live::SUBPROTOCOL.parse().unwrap());
    let (mut ws, response) = tungstenite::client(request, stream).unwrap();
    assert_eq!(response.headers()["Sec-WebSocket-Protocol"], live::SUBPROTOCOL);
    assert_eq!(read_json(&mut ws)["op"], "serverInfo");
    let adv = read_json(&mut ws);
    assert_eq!(adv["op"], "advertise");
    let channels = adv["channels"].as_array().unwrap();
    assert_eq!(channels.len(), Topic::ALL.len());
    let depth = channels.iter().find(|c| c["topic"] == "/depth").unwrap();
    assert_eq!(depth["schemaName"], "foxglove.RawImage");
    let subscribe = serde_json::json!({
        "op": "subscribe",
        "subscriptions": [{ "id": 7, "channelId": depth["id"] }, { "id": 8, "channelId": Topic::Tracker.id() }]
    });
    ws.send(tungstenite::Message::text(subscribe.to_string()))
        .unwrap();
    assert!(live.wait_for_subscriber(Duration::from_secs(20)));

    // Publish the whole recording at once: the client reads nothing meanwhile, so most frames are dropped for it,
    // and publish never waits. The frames are made first: made between publishes (the tracker under qemu on a
    // loaded machine), they took longer than the server's 5 s write timeout, which then let the client go.
    let mut clock = LogClock::default();
    let mut frames = Vec::new();
    record_demo(|r| frames.push(encode(r, clock.log_ns(r.capture), None)));
    let started = std::time::Instant::now();
    for frame in frames {
        live.publish(frame);
    }
    let publish_time = started.elapsed();
    let stats = live.stats();
    assert_eq!(stats.queued + stats.dropped, 60, "{stats:?}");
    assert!(stats.dropped > 0, "{stats:?}");
    assert!(publish_time < Duration::from_secs(60));

    let mut by_sub = std::collections::BTreeMap::<u32, Vec<u64>>::new();
    while by_sub.values().map(Vec::len).sum::<usize>() < 2 * stats.queued as usize {
        match ws.read().unwrap() {
            tungstenite::Message::Binary(b) => {
                assert_eq!(b[0], 1, "message data opcode");
                let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
                let payload: Value = serde_json::from_slice(&b[13..]).unwrap();
                if sub == 7 {
                    assert_eq!(payload["encoding"], "16UC1");
                } else {
                    assert_eq!(sub, 8);
                    assert!(payload["frame"].is_u64());
                }
                by_sub.entry(sub).or_default().push(t);
            }
            tungstenite::Message::Text(t) => panic!("unexpected text {t}"),
            _ => {}
        }
    }
    for times in by_sub.values() {
        assert!(times.windows(2).all(|w| w[0] < w[1]), "{times:?}");
    }
    ws.close(None).unwrap();
}

#[test]
fn live_view_refuses_clients_without_the_subprotocol() {
    let live = LiveView::bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let stream = TcpStream::connect(live.local_addr()).unwrap();
    let url = format!("ws://{}", live.local_addr());
    let e = tungstenite::client(url.as_str(), stream).err().unwrap();
    assert!(e.to_string().contains("400"), "{e}");
}

#[test]
fn view_addresses_parse_as_port_or_host_port() {
    assert_eq!(live::parse_addr("8765").unwrap().to_string(), "0.0.0.0:8765");
    assert_eq!(
        live::parse_addr("127.0.0.1:9").unwrap().to_string(),
        "127.0.0.1:9"
    );
    assert!(live::parse_addr("localhost").unwrap_err().contains("HOST:PORT"));
}
