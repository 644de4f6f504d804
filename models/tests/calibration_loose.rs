//! The guess-free calibration on a sequence whose refined pass locks onto wrong tips (seed 1005, a still patient,
//! seen as held-out in an earlier round): the second pass's poses agree only loosely, and
//! `calib_host::settle_passes` runs further passes until a tight consensus comes back. Without it the 10-pose
//! extrinsic was 33.9 mm / 1.27° off; with it 4.45 mm / 0.28° (docs/calibration.md, "Loose passes settle").
//! Cost: rendering 240 frames and three sessions per pose count, about 20 s.

use supine_models::eval::calibration::evaluate_sequence;
use supine_models::scene::model_body::{BodyKind, open_source};
use supine_models::sequence::SequenceConfig;
use supine_models::sequence::calibration::{CalibrationConfig, generate_calibration};

#[test]
fn a_loose_refined_pass_settles_on_a_tight_consensus() {
    let dir = std::env::temp_dir().join(format!("supine-cal-loose-{}", std::process::id()));
    let source = open_source(BodyKind::Model, None).expect("the committed body model");
    let cfg = SequenceConfig::new(240, 1005, false);
    let cal = CalibrationConfig {
        patient: true,
        ..Default::default()
    };
    generate_calibration(source.as_ref(), &cfg, &cal, &dir, &mut |_, _| {}).unwrap();
    let outcomes = evaluate_sequence(&dir, false).unwrap();
    let ten = outcomes
        .iter()
        .find(|o| o.poses == 10)
        .expect("a 10-pose outcome");
    let (te, re) = (
        ten.translation_error_mm.expect("solved"),
        ten.rotation_error_deg.expect("solved"),
    );
    // Measured 4.45 mm / 0.277°; the loose consensus the passes leave behind is 25-35 mm off.
    assert!(te < 8.0 && re < 0.5, "{te} mm, {re} deg");
    std::fs::remove_dir_all(&dir).ok();
}
