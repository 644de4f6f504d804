//! Fuzz the model-file container and the body-model view: any bytes must parse to a validated view or a clear
//! error, never a panic, and every accessor of an accepted view must stay in range. The fuzzer's input is parsed
//! twice: as it is, and with its CRC field recomputed, so mutations reach the section table and the body model's
//! semantic checks instead of stopping at the checksum.
#![no_main]

use libfuzzer_sys::fuzz_target;
use supine_core::body_model::{self, BodyModelView};
use supine_core::crc::crc32c_update;
use supine_core::model_file::ModelFile;
use supine_core::salient::SalientPoint;

fn exercise(bytes: &[u8]) {
    if let Ok(file) = ModelFile::parse(bytes, body_model::KIND, body_model::FORMAT_VERSION) {
        for i in 0..file.section_count() {
            let _ = file.section_at(i);
        }
    }
    let Ok(v) = BodyModelView::parse(bytes) else {
        return;
    };
    let c = v.counts();
    let s = [0.5f32; body_model::SHAPE_COMPONENTS];
    for vtx in 0..c.vertices.min(64) {
        let _ = v.shape_vertex(vtx, &s);
        let _ = v.part_of_vertex(vtx);
        for i in 0..c.max_influences {
            let _ = v.skin_influence(vtx, i);
        }
    }
    for j in 0..c.joints.min(64) {
        let _ = v.joint(j, &s);
        let _ = v.joint_name(j);
    }
    for b in 0..c.bones {
        let _ = (v.bone_parent(b), v.bone_joints(b), v.bone_roll(b), v.bone_name(b));
    }
    for p in SalientPoint::ALL {
        let _ = v.salient_point(p, &s);
    }
    if c.subset <= 4096 {
        let mut buf = [[0.0f32; 3]; 4096];
        assert!(v.shape_torso_subset(&s, &mut buf[..c.subset]).is_ok());
    }
}

fuzz_target!(|data: &[u8]| {
    exercise(data);
    if data.len() >= 32 && data.len() <= 1 << 20 {
        let mut fixed = data.to_vec();
        let state = crc32c_update(0xFFFF_FFFF, &fixed[..24]);
        let crc = crc32c_update(state, &fixed[28..]) ^ 0xFFFF_FFFF;
        fixed[24..28].copy_from_slice(&crc.to_le_bytes());
        exercise(&fixed);
    }
});
