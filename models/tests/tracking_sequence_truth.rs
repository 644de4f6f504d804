//! A short tracking sequence of the statistical body with the sweep, the full occlusion and a shift: the parked arm
//! hides over 90 % of the torso, the true torso surface is the body model's torso ICP subset, the sweeping probe
//! rests 3 mm outside it, the truth scores itself as zero, and the rigid floor is zero for the true torso moved
//! rigidly and the error in place for a shrunk one. Seed 131 is used by no other test or tuning.

use supine_core::wire::BodyRegion;
use supine_models::eval::tracking_truth::TrackingTruth;
use supine_models::scene::model_body::{BodyKind, open_source};
use supine_models::sequence::episodes::{EpisodeFrames, MotionKind};
use supine_models::sequence::{SequenceConfig, generate};

#[test]
fn body_model_sequence_with_every_episode_has_consistent_truth() {
    let source = open_source(BodyKind::Model, None).expect("the committed body model");
    let subset = source.torso_subset().expect("the body model has a torso subset");
    let dir = std::env::temp_dir().join(format!("supine-track-seq-{}", std::process::id()));
    let cfg = SequenceConfig {
        full_occlusion: true,
        motion: Some(MotionKind::Shift),
        episode_frames: EpisodeFrames {
            transit: 2,
            full_occlusion: 4,
            motion: 4,
        },
        sweep_period_s: 0.6,
        ..SequenceConfig::new(20, 131, true)
    };
    generate(source.as_ref(), &cfg, &dir, &mut |_, _| {}).unwrap();
    let t = TrackingTruth::load(&dir).unwrap();
    assert_eq!(t.torso.vertex_count(), subset.len());
    assert_eq!(t.meta.torso_surface.as_ref().unwrap().selection, "torso_subset");
    let o = t.episodes().full_occlusion.unwrap();
    assert!(
        o.torso_occluded_fraction_min > 0.9,
        "the parked arm hides {:.2} of the torso",
        o.torso_occluded_fraction_min
    );
    let m = t.episodes().motion.unwrap();
    assert_eq!(m.kind, MotionKind::Shift);
    // The shift moves the hips by its 10 cm (plus the slow drift, a few mm over these frames).
    let hips = |f: usize| {
        let s = &t.frames[f].salient_world;
        nalgebra::Vector3::new(s[4][0] + s[5][0], s[4][1] + s[5][1], s[4][2] + s[5][2]) * 0.5
    };
    let moved = (hips(19) - hips(m.start as usize - 1)).norm();
    assert!((moved - 0.1).abs() < 0.01, "hips moved {moved} m");
    let mut on_skin = 0;
    for f in 0..20u32 {
        let v = t.torso.frame(f as usize).unwrap();
        assert!(t.torso_surface_error_mm(v, f).unwrap() < 1e-3);
        // The rigid floor: nothing for the true torso moved anywhere rigidly; for a torso 4 % smaller about its
        // centroid, whose best rigid pose is where it stands, its error there.
        let pose = nalgebra::Isometry3::new(
            nalgebra::Vector3::new(0.3, -0.2, 0.5),
            nalgebra::Vector3::new(0.2, -0.4, 1.1),
        );
        let moved: Vec<_> = v.iter().map(|p| pose * nalgebra::Point3::from(*p)).collect();
        let floor = t.rigid_floor_mm(&moved, f).unwrap().unwrap();
        assert!(floor < 0.05, "frame {f}: floor {floor} mm of the true torso");
        let c = v
            .iter()
            .fold(nalgebra::Vector3::zeros(), |c, p| c + nalgebra::Vector3::from(*p))
            / v.len() as f32;
        let smaller: Vec<_> = v
            .iter()
            .map(|p| nalgebra::Point3::from(c + (nalgebra::Vector3::from(*p) - c) * 0.96))
            .collect();
        let floor = t.rigid_floor_mm(&smaller, f).unwrap().unwrap();
        let flat: Vec<[f32; 3]> = smaller.iter().map(|p| p.coords.into()).collect();
        let here = t.torso_surface_error_mm(&flat, f).unwrap();
        assert!(
            here > 0.5 && (floor - here).abs() < 0.05,
            "frame {f}: floor {floor} mm, in place {here} mm"
        );
        assert_eq!(t.rigid_floor_mm(&smaller[1..], f).unwrap(), None);
        let sweeping = f < o.approach_start || f >= o.leave_end;
        if let Some(p) = t.frames[f as usize]
            .probe_truth
            .as_ref()
            .filter(|p| p.near_body && sweeping)
        {
            on_skin += 1;
            assert!(
                (p.signed_distance_m - 0.003).abs() < 0.001,
                "frame {f}: the tip is {} m from the skin",
                p.signed_distance_m
            );
            // The truth scores itself as zero, and reports how far the tip hovers (the contact-range figure).
            let e = t
                .probe_error(p.nearest_camera, p.signed_distance_m, BodyRegion::OffBody, f)
                .unwrap()
                .expect("a scored frame");
            assert!(e.position_mm < 1e-3 && e.signed_distance_mm < 1e-3, "{e:?}");
            assert!((e.true_distance_mm - 3.0).abs() < 1.0, "{e:?}");
        }
    }
    assert!(on_skin >= 8, "{on_skin} sweep frames with the tip on the torso");
    std::fs::remove_dir_all(&dir).ok();
}
