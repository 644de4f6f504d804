//! The combined fit's options: the coarse-to-fine correspondence distance (`FitParams::fine_distance_m`: the first
//! round pairs points up to `icp.max_distance_m` apart, later rounds only up to the fine distance), and the starts
//! along the body (`fit_shape_along_axis`: it keeps the lowest-residual fit of the starts it is given, and without
//! offsets it is the single fit).

use std::path::PathBuf;
use supine_core::depth::DepthFrame;
use supine_core::fit::{AXIS_STARTS_M, FitError, FitParams, fit_shape, fit_shape_along_axis, initial_pose};
use supine_core::geometry::Vector3;
use supine_core::icp::{IcpError, IcpParams};
use supine_core::time::Timestamp;
use supine_models::body::BodyModel;
use supine_models::shape::data::{ShapeFrame, frames_of, intrinsics, small_dataset};

/// The first view of the first test body of a small dataset in a directory of its own (removed on drop), and the
/// body model.
struct Setup {
    dir: PathBuf,
    model: BodyModel,
    k: supine_core::camera::Intrinsics,
    f: ShapeFrame,
}

impl Setup {
    fn new(name: &str) -> Setup {
        let dir = std::env::temp_dir().join(format!("supine-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let ds = small_dataset(&dir, 4, 1, 5).unwrap();
        let k = intrinsics(&ds);
        let rec = ds.read_body(ds.test[0]).unwrap();
        let f = frames_of(&rec, &k, 1, 0.03).swap_remove(0);
        Setup {
            dir,
            model: BodyModel::load_default().unwrap(),
            k,
            f,
        }
    }
}

impl Drop for Setup {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

#[test]
fn the_fine_distance_applies_from_the_second_round_on() {
    let s = Setup::new("fit-distance");
    let (body, k, f) = (s.model.view(), s.k, &s.f);
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
}

#[test]
fn the_fit_along_the_body_keeps_its_lowest_residual_start() {
    let s = Setup::new("fit-axis");
    let (body, k, f) = (s.model.view(), s.k, &s.f);
    let frame = DepthFrame::new(&f.depth, k.width, k.height, Timestamp::default(), 0).unwrap();
    let mut points = vec![[0.0f32; 3]; body.counts().subset];
    let mut normals = points.clone();
    // The single fits' own scratch: `along` holds the first.
    let (mut points1, mut normals1) = (points.clone(), points.clone());
    let z0 = [0.0f32; 20];
    let p = FitParams::combined(IcpParams::new(f.mattress), &[0, 3]);
    let start = initial_pose(&body, &z0, &f.noisy_points, &f.mattress.normal()).unwrap();
    let mut fit = |from| fit_shape(&body, &frame, &k, &z0, from, &p, &mut points1, &mut normals1);
    let single = fit(start).unwrap();
    let mut along = |offsets: &[f32], from| {
        fit_shape_along_axis(
            &body,
            &frame,
            &k,
            &z0,
            from,
            offsets,
            &p,
            &mut points,
            &mut normals,
        )
    };
    // No offsets, or only 0: the single fit, bit for bit.
    assert_eq!(along(&[], start).unwrap(), single);
    assert_eq!(along(&[0.0], start).unwrap(), single);
    // Each offset is a fit from the start moved along the model's long axis (hip centre to shoulder centre, which
    // the start turns onto the observed body's); the lowest residual wins.
    let m = body.salient_points(&[0.0; 20]).map(Vector3::from);
    let axis = start.rotation * ((m[1] + m[2]) * 0.5 - (m[4] + m[5]) * 0.5).normalize();
    let each: Vec<_> = AXIS_STARTS_M
        .iter()
        .map(|&d| {
            let mut s = start;
            s.translation.vector += axis * d;
            fit(s).unwrap()
        })
        .collect();
    let best = along(&AXIS_STARTS_M, start).unwrap();
    assert!(each.contains(&best));
    assert!(
        each.iter()
            .all(|r| best.association.rms_m() <= r.association.rms_m()),
        "{best:?}"
    );
    assert!(best.association.rms_m() <= single.association.rms_m());
    // A start 10 cm down the body, moved back by its one offset, fits as the start itself.
    let mut low = start;
    low.translation.vector -= axis * 0.1;
    let back = along(&[0.1], low).unwrap();
    assert!((back.association.rms_m() - single.association.rms_m()).abs() < 1e-5);
    // When no start pairs the body, the error says why.
    let empty = vec![0u16; f.depth.len()];
    let nothing = DepthFrame::new(&empty, k.width, k.height, Timestamp::default(), 0).unwrap();
    let none = fit_shape_along_axis(
        &body,
        &nothing,
        &k,
        &z0,
        start,
        &AXIS_STARTS_M,
        &p,
        &mut points1,
        &mut normals1,
    );
    assert!(
        matches!(none, Err(FitError::Icp(IcpError::TooFewPairs { .. }))),
        "{none:?}"
    );
}
