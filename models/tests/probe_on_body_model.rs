//! Probe mapping on the committed body model's shaped torso surface: a tip placed a known distance out along the
//! surface normal over a surface point maps back onto that point, at that distance, with the region of the body
//! part there. Shapes come from the calibrated population with a fixed seed.

use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use supine_core::geometry::{Point3, Vector3};
use supine_core::probe::map_tip;
use supine_core::torso::{TorsoBuffers, TorsoSurface};
use supine_core::wire::BodyRegion;
use supine_models::body::BodyModel;

#[test]
fn tips_along_the_normal_map_back_onto_the_surface() {
    let model = BodyModel::load_default().expect("the committed body model");
    let view = model.view();
    let n = view.counts().subset;
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let (mut worst_point, mut worst_distance, mut checked) = (0.0f32, 0.0f32, 0);
    for _ in 0..3 {
        let shape = model.sample_shape(&mut rng);
        let mut vertices = vec![Point3::origin(); n];
        let mut normals = vec![Vector3::zeros(); n];
        let mut regions = vec![BodyRegion::OffBody; n];
        let surface = TorsoSurface::build(
            &view,
            &shape.coeffs,
            TorsoBuffers {
                vertices: &mut vertices,
                normals: &mut normals,
                regions: &mut regions,
            },
        )
        .unwrap();
        for t in (0..surface.triangle_count()).step_by(97) {
            let [a, b, c] = surface.triangle(t);
            let v = surface.vertices();
            let centroid = Point3::from((v[a].coords + v[b].coords + v[c].coords) / 3.0);
            let face = (v[b] - v[a]).cross(&(v[c] - v[a])).normalize();
            // Skip places where the surface folds within 3 cm (the neck, armpits): another face is nearer there.
            let tip = centroid + face * 0.03;
            let m = map_tip(&surface, &tip).unwrap();
            if (m.nearest - centroid).norm() > 0.005 {
                continue;
            }
            checked += 1;
            worst_point = worst_point.max((m.nearest - centroid).norm());
            worst_distance = worst_distance.max((m.signed_distance - 0.03).abs());
            assert!(
                m.normal.dot(&face) > 0.8,
                "normal {:?} vs face {face:?}",
                m.normal
            );
            assert_ne!(m.region, BodyRegion::OffBody);
        }
        // Over the navel region, out of the belly: the abdomen.
        let belly =
            Point3::from(view.salient_point(supine_core::salient::SalientPoint::Belly, &shape.coeffs));
        let belly_torso = surface.body_from_torso().inverse_transform_point(&belly);
        let m = map_tip(&surface, &(belly_torso + Vector3::z() * 0.05)).unwrap();
        assert_eq!(m.region, BodyRegion::Abdomen, "over the navel: {m:?}");
        assert!(m.signed_distance > 0.03 && m.signed_distance < 0.07, "{m:?}");
    }
    eprintln!(
        "{checked} tips: nearest-point error {worst_point:.2e} m, distance error {worst_distance:.2e} m"
    );
    assert!(checked > 30, "only {checked} tips checked");
    assert!(
        worst_distance < 0.002,
        "signed distance off by {worst_distance} m"
    );
}
