//! The per-frame shape path (canonical view, Eq. 1, forest, alternating ICP + Eq. 7 fit) allocates nothing: a
//! counting global allocator watches it on real frames of the statistical body model with a tiny trained model.
//! The bed-contact fit too, and it leaves the torso's back on the mattress.

use supine_core::body_model::BodyPart;
use supine_core::depth::DepthFrame;
use supine_core::fit::{
    AXIS_STARTS_M, BedContact, FitParams, fit_shape_along_axis, fit_shape_on_bed, initial_pose,
};
use supine_core::geometry::Point3;
use supine_core::icp::IcpParams;
use supine_core::shape::ShapeModelView;
use supine_core::time::Timestamp;
use supine_models::body::BodyModel;
use supine_models::shape::data::{frames_of, intrinsics, small_dataset};
use supine_models::shape::train::{TrainConfig, train};
use supine_tests::alloc_count::{Counting, count_allocations, counter_is_installed};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_shape_path_allocates_nothing_per_frame() {
    let dir = std::env::temp_dir().join(format!("supine-shape-alloc-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let ds = small_dataset(&dir, 10, 3, 9).unwrap();
    let cfg = TrainConfig {
        pitch_m: 0.025,
        stride: 2,
        seed: 1,
        point_noise_m: 0.03,
        pixel_noise_m: 0.01,
        trees: 2,
        em_rounds: 0,
        holdout_validation: false,
        hip_heights: false,
    };
    let trained = train(&ds, &cfg, None).unwrap();
    let shape = ShapeModelView::parse(&trained.bytes).unwrap();
    let model = BodyModel::load_default().unwrap();
    let body = model.view();
    let k = intrinsics(&ds);
    let rec = ds.read_body(ds.test[0]).unwrap();
    let frames = frames_of(&rec, &k, 2, 0.03);
    let mut canonical = vec![0.0f32; shape.pixels()];
    let mut points = vec![[0.0f32; 3]; body.counts().subset];
    let mut normals = points.clone();
    let mut fitted = 0;
    let mut fitted_on_bed = 0;
    assert!(counter_is_installed());
    for f in &frames {
        let frame = DepthFrame::new(&f.depth, k.width, k.height, Timestamp::default(), 0).unwrap();
        let icp = IcpParams::new(f.mattress);
        let params = FitParams::combined(icp, &[0, 3]);
        let (fit, allocations) = count_allocations(|| {
            let est = shape.estimate(&frame, &k, &f.noisy_points, &f.mattress, &mut canonical);
            est.ok().and_then(|e| {
                let pose = initial_pose(&body, &e.shape, &f.noisy_points, &f.mattress.normal()).ok()?;
                // The combined fit as `eval shape` runs it: from each start along the body.
                fit_shape_along_axis(
                    &body,
                    &frame,
                    &k,
                    &e.shape,
                    pose,
                    &AXIS_STARTS_M,
                    &params,
                    &mut points,
                    &mut normals,
                )
                .ok()
            })
        });
        assert_eq!(allocations, 0, "the shape path allocated");
        fitted += fit.is_some() as usize;
        // The bed-contact variant allocates nothing either, and leaves the back on the mattress.
        let Some(start) = fit else { continue };
        let contact = BedContact::default();
        let pose = initial_pose(&body, &start.shape, &f.noisy_points, &f.mattress.normal()).unwrap();
        let (on_bed, allocations) = count_allocations(|| {
            fit_shape_on_bed(
                &body,
                &frame,
                &k,
                &start.shape,
                pose,
                &params,
                &contact,
                &mut points,
                &mut normals,
            )
        });
        assert_eq!(allocations, 0, "the bed-contact fit allocated");
        let r = on_bed.unwrap();
        let raw: Vec<f32> = (0..20).map(|q| r.shape[q] * body.sigma(q)).collect();
        let lowest = (0..body.vertex_count())
            .filter(|&v| {
                matches!(
                    body.part_of_vertex(v),
                    BodyPart::Chest | BodyPart::Abdomen | BodyPart::Pelvis
                )
            })
            .map(|v| {
                let p = r.camera_from_model * Point3::from(body.shape_vertex(v, &raw));
                f.mattress.signed_distance(&p)
            })
            .fold(f32::INFINITY, f32::min);
        assert!(
            lowest.abs() < 0.02,
            "lowest torso vertex {lowest} m from the mattress"
        );
        fitted_on_bed += 1;
    }
    assert!(fitted_on_bed > 0, "no frame was fitted on the bed");
    assert!(fitted > 0, "no frame was fitted, so nothing was measured");
    let _ = std::fs::remove_dir_all(&dir);
}
