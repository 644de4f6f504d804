//! Body model tests that run from the committed artifact (`models/artifacts/body.sbm`): file validation, the core
//! view against the host model, basis orthonormality, LBS identities, the T-pose, bed poses and determinism.

use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use supine_core::body_model::{BodyModelView, BodyPart};
use supine_core::model_file::ModelFileError;
use supine_core::salient::SalientPoint;
use supine_models::body::file::{BodyFileData, quantise_basis, write_body_model};
use supine_models::body::{BodyModel, COMPONENTS, PopulationMember, Shape};
use supine_models::pose::bed::{COMBINATIONS, pose_on_bed};
use supine_models::pose::{BedPoseSampler, Lying, Pose, Rest};

fn model() -> BodyModel {
    BodyModel::load_default().expect("committed artifact loads")
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[test]
fn artifact_has_the_documented_shape() {
    let m = model();
    let v = m.view();
    assert_eq!(v.vertex_count(), 13380);
    assert_eq!(v.component_count(), COMPONENTS);
    assert_eq!(m.bones.len(), 36);
    assert_eq!(m.bones[0].name, "root");
    assert_eq!(m.triangles.len(), 2 * 13378);
    assert!(
        v.torso_subset().len() > 500,
        "torso subset {}",
        v.torso_subset().len()
    );
    assert!(!m.population.is_empty());
    // Components ordered by variance.
    for k in 1..COMPONENTS {
        assert!(m.sigma[k] <= m.sigma[k - 1]);
    }
    // Compact enough to commit.
    assert!(m.file_bytes().len() < 4_000_000);
}

#[test]
fn mean_body_is_a_plausible_adult() {
    let m = model();
    let rest = m.rest_vertices(&Shape::MEAN);
    let (lo, hi) = rest
        .iter()
        .fold(([f32::MAX; 3], [f32::MIN; 3]), |(mut lo, mut hi), p| {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
            (lo, hi)
        });
    let height = hi[2] - lo[2];
    let mean_pop: f32 = m.population.iter().map(|p| p.height_m).sum::<f32>() / m.population.len() as f32;
    assert!(
        (height - mean_pop).abs() < 0.03,
        "mean body {height} m vs population mean {mean_pop} m"
    );
    let s = m.rest_salient_points(&Shape::MEAN);
    let (ls, rs) = (
        s[SalientPoint::LeftShoulder as usize],
        s[SalientPoint::RightShoulder as usize],
    );
    assert!(
        ls[0] > 0.1 && rs[0] < -0.1 && (ls[0] + rs[0]).abs() < 1e-3,
        "shoulders {ls:?} {rs:?}"
    );
    let belly = s[SalientPoint::Belly as usize];
    let hip = s[SalientPoint::LeftHip as usize];
    let head = s[SalientPoint::Head as usize];
    // Navel in front of (more -y than) the hips, between hips and shoulders; head above the shoulders.
    assert!(
        belly[1] < hip[1] - 0.05 && belly[2] > hip[2] && belly[2] < ls[2],
        "belly {belly:?}"
    );
    assert!(head[2] > ls[2] + 0.05);
}

#[test]
fn dequantised_basis_is_orthonormal() {
    let m = model();
    let rows = m.mean.len();
    for a in 0..COMPONENTS {
        for b in a..COMPONENTS {
            let dot: f64 = (0..3 * rows)
                .map(|i| m.basis[i * COMPONENTS + a] as f64 * m.basis[i * COMPONENTS + b] as f64)
                .sum();
            let want = if a == b { 1.0 } else { 0.0 };
            assert!((dot - want).abs() < 1e-3, "<V{a}, V{b}> = {dot}");
        }
    }
}

#[test]
fn core_view_matches_host_model() {
    let m = model();
    let v = m.view();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let shape = m.sample_shape(&mut rng);
    let mut buf = vec![[0.0f32; 3]; v.torso_subset().len()];
    v.shape_torso_subset(&shape.coeffs, &mut buf).unwrap();
    for (p, i) in buf.iter().zip(v.torso_subset().iter()) {
        assert!(dist(*p, m.row(i as usize, &shape)) < 1e-5);
    }
    assert!(v.shape_torso_subset(&shape.coeffs, &mut buf[1..]).is_err());
    let a = v.salient_points(&shape.coeffs);
    let b = m.rest_salient_points(&shape);
    for i in 0..6 {
        assert!(dist(a[i], b[i]) < 1e-5);
    }
    // The belly salient point is the navel vertex (its own row of the same linear model).
    assert!(dist(b[SalientPoint::Belly as usize], m.row(4116, &shape)) < 1e-5);
    let mut jac = [[0.0f32; 3]; COMPONENTS];
    assert_eq!(v.row_basis(100, &mut jac), COMPONENTS);
    assert!((jac[3][1] - m.basis[(3 * 100 + 1) * COMPONENTS + 3]).abs() < 1e-9);
}

#[test]
fn corrupted_files_give_distinct_errors_never_panics() {
    let m = model();
    let good = m.file_bytes().to_vec();
    let mut bad = good.clone();
    bad[0] = b'X';
    assert_eq!(BodyModelView::parse(&bad).unwrap_err(), ModelFileError::BadMagic);
    let mut bad = good.clone();
    bad[16] = 99; // kind format version
    assert!(matches!(
        BodyModelView::parse(&bad),
        Err(ModelFileError::UnsupportedKindVersion { found: 99, .. })
    ));
    assert!(matches!(
        BodyModelView::parse(&good[..good.len() - 7]),
        Err(ModelFileError::Truncated { .. })
    ));
    assert!(matches!(
        BodyModelView::parse(&good[..10]),
        Err(ModelFileError::Truncated { .. })
    ));
    let mut bad = good.clone();
    let mid = good.len() / 2;
    bad[mid] ^= 0x40;
    assert!(matches!(
        BodyModelView::parse(&bad),
        Err(ModelFileError::ChecksumMismatch { .. })
    ));
    // Host loader reports the same, as an error, not a panic.
    assert!(
        BodyModel::from_bytes(bad)
            .unwrap_err()
            .to_string()
            .contains("CRC")
    );
    // Flip bytes all over the file: always an error, never a panic.
    let mut rng = 0x9E37_79B9u32;
    for _ in 0..200 {
        rng ^= rng << 13;
        rng ^= rng >> 17;
        rng ^= rng << 5;
        let mut bad = good.clone();
        let i = rng as usize % bad.len();
        bad[i] = bad[i].wrapping_add(1 + (rng >> 24) as u8 % 255);
        assert!(BodyModelView::parse(&bad).is_err(), "flip at {i} accepted");
    }
}

fn tiny_file(parent_of_1: Option<usize>) -> BodyFileData {
    // 3 vertices, 2 joints, 2 bones, K = 20; the basis has distinct values to check the layout.
    let rows = 3 + 2 + 6;
    BodyFileData {
        n_vertices: 3,
        n_joints: 2,
        mean: (0..3 * rows).map(|i| i as f32 * 0.01).collect(),
        basis: (0..3 * rows * COMPONENTS)
            .map(|i| ((i * 7919) % 101) as f64 * 1e-3 - 0.05)
            .collect(),
        sigma: (0..COMPONENTS).map(|k| 1.0 / (k + 1) as f32).collect(),
        subset: vec![0, 2],
        subset_triangles: vec![[0, 1, 0]],
        triangles: vec![[0, 1, 2]],
        bones: vec![
            ("root".into(), None, 0, 1, 0.0),
            ("b1".into(), parent_of_1, 1, 0, 0.5),
        ],
        joint_names: vec!["j0".into(), "j1".into()],
        skin: vec![vec![(0, 1.0)], vec![(0, 0.3), (1, 0.7)], vec![(1, 1.0)]],
        max_influences: 2,
        parts: vec![0, 2, 4],
        population: vec![PopulationMember {
            shape: Shape {
                coeffs: [0.5; COMPONENTS],
            },
            male: true,
            age_years: 40.0,
            height_m: 1.8,
            bmi: 27.0,
            waist_m: 0.95,
        }],
        info_json: "{}".into(),
    }
}

#[test]
fn writer_round_trip_and_semantic_validation() {
    let d = tiny_file(Some(0));
    let bytes = write_body_model(&d).unwrap();
    let v = BodyModelView::parse(&bytes).unwrap();
    assert_eq!(v.bone_name(1), "b1");
    assert_eq!(v.joint_name(1), "j1");
    assert_eq!(v.bone_parent(1), Some(0));
    assert_eq!(v.skin_influence(1, 1).0, 1);
    assert!((v.skin_influence(1, 1).1 - 0.7).abs() < 1e-4);
    let (_, scale) = quantise_basis(&d.basis, COMPONENTS);
    for i in 0..3 * 11 {
        for (k, &step) in scale.iter().enumerate().take(COMPONENTS) {
            let want = d.basis[i * COMPONENTS + k];
            assert!((v.basis(i / 3, i % 3, k) as f64 - want).abs() <= step as f64 * 0.5 + 1e-9);
        }
    }
    let host = BodyModel::from_bytes(bytes.clone()).unwrap();
    assert_eq!(host.population.len(), 1);
    assert_eq!(host.population[0].bmi, 27.0);
    // Same input, same bytes.
    assert_eq!(write_body_model(&d).unwrap(), bytes);
    // A bone whose parent does not precede it is refused by the writer's own validation.
    assert!(
        write_body_model(&tiny_file(Some(1)))
            .unwrap_err()
            .to_string()
            .contains("BPAR")
    );
}

#[test]
fn rest_pose_is_the_identity() {
    let m = model();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..3 {
        let shape = m.sample_shape(&mut rng);
        let rest = m.rest_vertices(&shape);
        let posed = m.pose(&shape, &Pose::rest_for(&m));
        let worst = rest
            .iter()
            .zip(&posed.vertices)
            .map(|(a, b)| dist(*a, *b))
            .fold(0.0, f32::max);
        assert!(worst < 1e-5, "rest pose moved a vertex by {worst} m");
        let s = m.rest_salient_points(&shape);
        for (a, b) in s.iter().zip(&posed.salient_points) {
            assert!(dist(*a, *b) < 1e-5);
        }
    }
}

/// Bone rotations of MakeHuman's `poses/default_fk/t-pose.json` (MPFB2, CC0) for the bones of the reduced rig.
const T_POSE: [(&str, [f32; 3]); 12] = [
    ("clavicle.L", [0.0, 0.0, 0.174_532_92]),
    ("clavicle.R", [0.0, 0.0, -0.174_532_92]),
    ("shoulder01.L", [0.0, 0.0, 0.139_626_34]),
    ("shoulder01.R", [0.0, 0.0, -0.139_626_34]),
    ("upperarm01.L", [0.0, 0.0, std::f32::consts::FRAC_PI_6]),
    ("upperarm01.R", [0.0, 0.0, -std::f32::consts::FRAC_PI_6]),
    ("lowerarm01.L", [-0.645_771_8, 0.0, 0.0]),
    ("lowerarm01.R", [-0.645_771_8, 0.0, 0.0]),
    ("upperleg01.L", [0.0, 0.0, 0.052_359_88]),
    ("upperleg01.R", [0.0, 0.0, -0.052_359_88]),
    ("pelvis.L", [0.034_906_58, 0.0, 0.0]),
    ("pelvis.R", [0.034_906_58, 0.0, 0.0]),
];

#[test]
fn t_pose_puts_the_arms_horizontal() {
    let m = model();
    let mut pose = Pose::rest_for(&m);
    for (b, r) in T_POSE {
        assert!(pose.set(&m, b, r), "no bone {b}");
    }
    let posed = m.pose(&Shape::MEAN, &pose);
    let j = |n: &str| posed.joints[m.joint_index(n).unwrap()];
    for side in ["l", "r"] {
        let (s, e, w) = (
            j(&format!("joint-{side}-shoulder")),
            j(&format!("joint-{side}-elbow")),
            j(&format!("joint-{side}-hand")),
        );
        for (a, b, what) in [(s, e, "upper arm"), (e, w, "forearm")] {
            let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let elev = (d[2] / (d[0] * d[0] + d[1] * d[1]).sqrt()).atan().to_degrees();
            // The notes measure 1.3° / 0.5° on MakeHuman's default body; our population mean is heavier, and the
            // MEAN-with-tights joints of the default rig tilt a little with girth, hence ~2° here.
            assert!(elev.abs() < 2.5, "{side} {what} {elev:.2}° from horizontal");
            assert!(d[0].abs() > 0.9 * dist(a, b), "{side} {what} not sideways: {d:?}");
        }
    }
}

#[test]
fn bed_poses_cover_750_combinations_and_are_deterministic() {
    let m = model();
    let sampler = BedPoseSampler::new(&m);
    assert_eq!(COMBINATIONS, 750);
    let mut seen = std::collections::HashSet::new();
    for i in 0..COMBINATIONS {
        seen.insert(format!("{:?}", BedPoseSampler::combination(i)));
    }
    assert_eq!(seen.len(), 750);
    let draw = |seed| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..5)
            .map(|_| (m.sample_shape(&mut rng), sampler.sample(&mut rng)))
            .collect::<Vec<_>>()
    };
    let a = draw(42);
    assert_eq!(a, draw(42));
    assert_ne!(a, draw(43));
    for (shape, bed) in &a {
        let on_bed = pose_on_bed(&m, shape, bed, Rest::LowestPoint);
        assert!(on_bed.vertices.iter().all(|v| v.iter().all(|c| c.is_finite())));
        let (lo, hi) = on_bed.bounds();
        assert!(lo[2].abs() < 1e-4, "lowest point on the mattress: {lo:?}");
        // Lying along the bed: the long extent is y.
        assert!(hi[1] - lo[1] > 1.3, "{lo:?} {hi:?}");
        let s = on_bed.salient_points;
        assert!(s[SalientPoint::Head as usize][1] > s[SalientPoint::LeftHip as usize][1] + 0.4);
        assert_eq!(on_bed.part_of_triangle().len(), on_bed.triangles.len());
    }
}

#[test]
fn canonical_sub_poses_do_what_they_say() {
    let m = model();
    let sampler = BedPoseSampler::new(&m);
    let find = |want: &str| {
        (0..COMBINATIONS)
            .find(|&i| format!("{:?}", BedPoseSampler::combination(i)) == want)
            .unwrap()
    };
    let flat = Lying::SUPINE;
    let posed = |i| pose_on_bed(&m, &Shape::MEAN, &sampler.canonical(i, flat), Rest::Trunk);
    let wrist = |p: &supine_models::body::PosedBody<'_>, side: &str| {
        p.joints[m.joint_index(&format!("joint-{side}-hand")).unwrap()]
    };
    // Supine on the bed frame: the chest is above the mattress and the front faces +z.
    let neutral = posed(find("(Neutral, AtSide, AtSide, Straight)"));
    let lw = wrist(&neutral, "l");
    let ls = neutral.salient_points[SalientPoint::LeftShoulder as usize];
    assert!(
        lw[1] < ls[1] - 0.4 && lw[0] > 0.1,
        "arm at the side: wrist {lw:?} shoulder {ls:?}"
    );
    // Left hand on the chest: the left wrist is near the midline, above (in front of) the chest.
    let chest = posed(find("(Neutral, HandOnChest, AtSide, Straight)"));
    let w = wrist(&chest, "l");
    assert!(w[0].abs() < 0.2 && w[2] > ls[2], "hand on chest: wrist {w:?}");
    // Raised right arm: wrist well above the body (toward the ceiling).
    let raised = posed(find("(Neutral, AtSide, Raised, Straight)"));
    assert!(wrist(&raised, "r")[2] > 0.45, "raised: {:?}", wrist(&raised, "r"));
    // Supporting the head: the wrist is near the head.
    let sup = posed(find("(Neutral, SupportingHead, AtSide, Straight)"));
    let head = sup.salient_points[SalientPoint::Head as usize];
    assert!(
        dist(wrist(&sup, "l"), head) < 0.25,
        "supporting head: {:?} head {head:?}",
        wrist(&sup, "l")
    );
    // Knee up: the left knee rises above the mattress.
    let knee = posed(find("(Neutral, AtSide, AtSide, LeftKneeUp)"));
    let k = |p: &supine_models::body::PosedBody<'_>, s: &str| {
        p.joints[m.joint_index(&format!("joint-{s}-knee")).unwrap()]
    };
    assert!(k(&knee, "l")[2] > k(&knee, "r")[2] + 0.15);
    // Raised head end: the head is higher than when flat, the legs stay low.
    let raise = Lying {
        tilt_rad: 0.0,
        head_raise_rad: 30f32.to_radians(),
    };
    let up = pose_on_bed(
        &m,
        &Shape::MEAN,
        &sampler.canonical(find("(Neutral, AtSide, AtSide, Straight)"), raise),
        Rest::Trunk,
    );
    let flat_head = neutral.salient_points[SalientPoint::Head as usize][2];
    assert!(up.salient_points[SalientPoint::Head as usize][2] > flat_head + 0.2);
    assert!(
        k(&up, "l")[2] < 0.2,
        "legs flat on a raised bed: knee {:?}",
        k(&up, "l")
    );
}

#[test]
fn a_hand_under_the_head_does_not_hold_the_back_off_the_mattress() {
    let m = model();
    let sampler = BedPoseSampler::new(&m);
    let i = (0..COMBINATIONS)
        .find(|&i| {
            format!("{:?}", BedPoseSampler::combination(i)) == "(Neutral, SupportingHead, AtSide, Straight)"
        })
        .unwrap();
    let bed = sampler.canonical(i, Lying::SUPINE);
    // Of a few bodies, the one whose hand reaches lowest under its head (on the mean body it is level with the back).
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let posed = (0..12)
        .map(|_| m.pose(&m.sample_shape(&mut rng), &bed.pose))
        .max_by(|p, q| {
            let drop = |b: &supine_models::body::PosedBody<'_>| {
                let t = bed.lying.bed_from_trunk(b);
                let hand = b.joints[m.joint_index("joint-l-hand").unwrap()];
                -(t * nalgebra::Point3::from(hand)).z
            };
            drop(p).total_cmp(&drop(q))
        })
        .unwrap();
    let lowest = |t: &nalgebra::Isometry3<f32>, arms: bool| {
        posed
            .vertices
            .iter()
            .zip(posed.part_of_vertex.iter())
            .filter(|&(_, &p)| arms || !BodyPart::from_u8(p).is_some_and(BodyPart::is_arm))
            .map(|(v, _)| (t * nalgebra::Point3::from(*v)).z)
            .fold(f32::INFINITY, f32::min)
    };
    let by_body = bed.lying.bed_from_body(&posed);
    let by_trunk = bed.lying.bed_from_trunk(&posed);
    assert_eq!(bed.lying.bed_from(&posed, Rest::LowestPoint), by_body);
    assert_eq!(bed.lying.bed_from(&posed, Rest::Trunk), by_trunk);
    // The hand under the head is the body's lowest point: resting on it holds the back up; resting on the trunk
    // puts the back on the mattress and the hand into it.
    assert!(lowest(&by_body, true).abs() < 1e-4);
    let held_up = lowest(&by_body, false);
    assert!(held_up > 0.01, "the back {held_up} m above the mattress");
    assert!(lowest(&by_trunk, false).abs() < 1e-4);
    assert!((lowest(&by_trunk, true) + held_up).abs() < 1e-4);
    // Only the height differs.
    assert_eq!(by_body.rotation, by_trunk.rotation);
    let d = by_body.translation.vector - by_trunk.translation.vector;
    assert!(d.x == 0.0 && d.y == 0.0 && (d.z - held_up).abs() < 1e-4, "{d:?}");
}

#[test]
fn a_sequence_patient_moves_the_arms_and_keeps_the_trunk_where_it_lies() {
    use supine_models::body::PosedBody;
    use supine_models::scene::body::BodySource;
    let source = supine_models::scene::model_body::ModelBodySource::load(None).expect("default body model");
    let lowest = |b: &PosedBody<'_>, arms: bool| {
        b.vertices
            .iter()
            .zip(b.part_of_vertex.iter())
            .filter(|&(_, &p)| BodyPart::from_u8(p).is_some_and(BodyPart::is_arm) == arms)
            .map(|(v, _)| v[2])
            .fold(f32::INFINITY, f32::min)
    };
    // A patient whose hand goes below the back at one end of the blend (under the head, or beside a raised back).
    let (a, b) = (0..60)
        .map(|s| {
            let at = |t| source.sample_motion(s, s + 100, s + 200, t).expect("sample").body;
            (at(0.0), at(1.0))
        })
        .find(|(a, b)| lowest(a, true).min(lowest(b, true)) < -0.01)
        .expect("a hand below the back in 60 patients");
    let arm_moved = a
        .vertices
        .iter()
        .zip(&b.vertices)
        .zip(a.part_of_vertex.iter())
        .filter(|&(_, &p)| BodyPart::from_u8(p).is_some_and(BodyPart::is_arm))
        .map(|((x, y), _)| dist(*x, *y))
        .fold(0.0f32, f32::max);
    assert!(
        arm_moved > 0.1,
        "the arms blend to other sub-poses: {arm_moved} m"
    );
    // The back stays on the mattress and the hips stay put, whatever the hand does.
    for body in [&a, &b] {
        assert!(
            lowest(body, false).abs() < 1e-4,
            "trunk {} m off the mattress",
            lowest(body, false)
        );
    }
    for s in [SalientPoint::LeftHip, SalientPoint::RightHip] {
        assert_eq!(a.salient_points[s as usize], b.salient_points[s as usize]);
    }
}
