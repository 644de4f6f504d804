//! The fits' coarse-to-fine correspondence distance (`FitParams::fine_distance_m`): the first round pairs points
//! up to `icp.max_distance_m` apart, later rounds only up to the fine distance.

use supine_core::depth::DepthFrame;
use supine_core::fit::{FitError, FitParams, fit_shape, initial_pose};
use supine_core::icp::{IcpError, IcpParams};
use supine_core::time::Timestamp;
use supine_models::body::BodyModel;
use supine_models::shape::data::{frames_of, intrinsics, small_dataset};

#[test]
fn the_fine_distance_applies_from_the_second_round_on() {
    let dir = std::env::temp_dir().join(format!("supine-fit-distance-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let ds = small_dataset(&dir, 4, 1, 5).unwrap();
    let model = BodyModel::load_default().unwrap();
    let body = model.view();
    let k = intrinsics(&ds);
    let rec = ds.read_body(ds.test[0]).unwrap();
    let f = &frames_of(&rec, &k, 1, 0.03)[0];
    let frame = DepthFrame::new(&f.depth, k.width, k.height, Timestamp::default(), 0).unwrap();
    let mut points = vec![[0.0f32; 3]; body.counts().subset];
    let mut normals = points.clone();
    let z0 = [0.0f32; 20];
    let start = initial_pose(&body, &z0, &f.noisy_points, &f.mattress.normal()).unwrap();
    let mut fit = |rounds: u8, fine: Option<f32>| {
        let mut p = FitParams::combined(IcpParams::new(f.mattress), &[0, 3]);
        p.rounds = rounds;
        p.stop_change = 0.0;
        p.fine_distance_m = fine;
        fit_shape(&body, &frame, &k, &z0, start, &p, &mut points, &mut normals)
    };
    let coarse = fit(3, None).expect("the coarse fit pairs the body");
    // At the first round's distance the fine stage changes nothing, bit for bit.
    assert_eq!(fit(3, Some(0.1)).unwrap(), coarse);
    // One round is all coarse: a fine distance no pair can meet does not matter yet...
    assert_eq!(fit(1, Some(1e-5)).unwrap(), fit(1, None).unwrap());
    // ...but from the second round on it drops every pair.
    assert!(matches!(
        fit(3, Some(1e-5)),
        Err(FitError::Icp(IcpError::TooFewPairs { .. }))
    ));
    // A fine distance between the two keeps fewer pairs than the coarse fit's last round.
    let fine = fit(3, Some(0.01)).unwrap();
    assert!(
        fine.association.pairs < coarse.association.pairs,
        "{fine:?} vs {coarse:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
