//! Tests of the canonical view, the masked projection, the forest and the `SHAP` file view.

use super::canonical::{CanonicalCamera, HeightReference, NO_VALUE, body_frame, canonical_view};
use super::*;
use crate::fixture::{self, SHAPE_H, SHAPE_LEAF_SCALE, SHAPE_LEAVES, SHAPE_W, TINY_SHAPE_LEN};
use crate::geometry::Vector3;
use crate::time::Timestamp;

const W: usize = 160;
const H: usize = 120;

fn intrinsics() -> Intrinsics {
    Intrinsics {
        fx: 140.0,
        fy: 140.0,
        cx: 80.0,
        cy: 60.0,
        width: W as u16,
        height: H as u16,
    }
}

/// Hips at 1.5 m on the optical axis, shoulders along +x of the camera, the mattress 0.1 m behind the hips facing
/// the camera: body z = −camera z, body y = camera x, body x = camera y.
fn scene_points() -> ([Point3; SalientPoint::COUNT], Plane) {
    let pts = [
        Point3::new(0.6, 0.0, 1.5),
        Point3::new(0.5, 0.15, 1.5),
        Point3::new(0.5, -0.15, 1.5),
        Point3::new(0.2, 0.0, 1.4),
        Point3::new(0.0, 0.12, 1.5),
        Point3::new(0.0, -0.12, 1.5),
    ];
    (pts, Plane::through(Vector3::new(0.0, 0.0, 1.6), -Vector3::z()))
}

#[test]
fn the_body_frame_follows_hips_shoulders_and_bed() {
    let (pts, bed) = scene_points();
    let t = body_frame(&pts, &bed.normal()).unwrap();
    let p = t * Point3::new(0.1, 0.2, 0.3);
    // body (x, y, z) → camera (y, x, 1.5 − z).
    assert!((p - Point3::new(0.2, 0.1, 1.2)).norm() < 1e-5, "{p:?}");
    let mut flat = pts;
    flat[1] = flat[4];
    flat[2] = flat[5];
    assert!(body_frame(&flat, &bed.normal()).is_err());
}

#[test]
fn canonical_view_of_a_plane_and_a_box_is_exact() {
    let (pts, bed) = scene_points();
    let k = intrinsics();
    // A plane 5 cm above the hips (1450 mm) with a box whose top is 15 cm above them (1350 mm) over pixel columns
    // 90..120, rows 40..80.
    let mut depth = [1450u16; W * H];
    for v in 40..80 {
        for u in 90..120 {
            depth[v * W + u] = 1350;
        }
    }
    let frame = DepthFrame::new(&depth, W as u16, H as u16, Timestamp::default(), 0).unwrap();
    // The mattress lies 0.1 m below the hips: heights above it are those above the hips plus 0.1 m.
    for (reference, offset) in [
        (HeightReference::HipCentre, 0.0f32),
        (HeightReference::Mattress, 0.1),
    ] {
        let mut cam = CanonicalCamera::with_pitch(0.05, 1);
        cam.height_reference = reference;
        check_plane_and_box(&frame, &k, &pts, &bed, &cam, offset);
    }
}

/// The canonical view of the plane-and-box frame shows exactly the plane and the box (heights shifted by `offset`).
fn check_plane_and_box(
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    pts: &[Point3; SalientPoint::COUNT],
    bed: &Plane,
    cam: &CanonicalCamera,
    offset: f32,
) {
    let t = body_frame(pts, &bed.normal()).unwrap();
    let mut out = [0.0f32; 28 * 20];
    assert_eq!(cam.pixels(), out.len());
    let visible = canonical_view(frame, k, &t, bed, cam, &mut out).unwrap();
    assert!(visible > 200, "visible {visible}");
    let (mut on_box, mut on_plane) = (0, 0);
    for cv in 0..cam.height as usize {
        for cu in 0..cam.width as usize {
            let x = out[cv * cam.width as usize + cu];
            if x == NO_VALUE {
                continue;
            }
            assert!(
                (x - 0.05 - offset).abs() < 1e-4 || (x - 0.15 - offset).abs() < 1e-4,
                "pixel ({cu}, {cv}) = {x}"
            );
            // Where the pixel centre of either surface lands in the depth image decides what it must show.
            let seen = |h: f32| {
                let z = cam.distance_m - h;
                let pb = Point3::new(
                    (cv as f32 - cam.cy) * z / cam.focal_px,
                    (cu as f32 - cam.cx) * z / cam.focal_px,
                    h,
                );
                k.project(&(t * pb)).unwrap()
            };
            let b = seen(0.15);
            let inside = |uv: crate::geometry::Point2, m: f32| {
                uv.x > 90.0 + m && uv.x < 119.0 - m && uv.y > 40.0 + m && uv.y < 79.0 - m
            };
            if inside(b, 5.0) {
                assert!((x - 0.15 - offset).abs() < 1e-4, "box pixel ({cu}, {cv}) = {x}");
                on_box += 1;
            }
            if !inside(seen(0.05), -5.0) && !inside(b, -5.0) {
                assert!((x - 0.05 - offset).abs() < 1e-4, "plane pixel ({cu}, {cv}) = {x}");
                on_plane += 1;
            }
        }
    }
    assert!(on_box >= 4 && on_plane > 100, "box {on_box}, plane {on_plane}");
    // The wrong buffer size is an error.
    assert!(canonical_view(frame, k, &t, bed, cam, &mut out[..10]).is_err());
}

fn tiny() -> ([u8; TINY_SHAPE_LEN], usize) {
    let mut buf = [0u8; TINY_SHAPE_LEN];
    let n = fixture::tiny_shape_model(&mut buf).unwrap();
    (buf, n)
}

#[test]
fn masked_projection_recovers_known_coefficients() {
    let (buf, n) = tiny();
    let m = ShapeModelView::parse(&buf[..n]).unwrap();
    assert_eq!(m.pixels(), SHAPE_W * SHAPE_H);
    let s = m.subspace();
    let mut c = [0.0f32; SUBSPACE_DIM];
    for (k, x) in c.iter_mut().enumerate() {
        *x = 0.3 * (k as f32 - 9.5) / 10.0;
    }
    let mut img = [0.0f32; SHAPE_W * SHAPE_H];
    for (i, x) in img.iter_mut().enumerate() {
        *x = s.reconstruct_at(i, &c);
    }
    // Hide a quarter of the pixels (as an occluder would): the visible ones still determine c.
    for i in (0..img.len()).step_by(4) {
        img[i] = NO_VALUE;
    }
    let (got, visible) = s.project(&img).unwrap();
    assert_eq!(visible, 36);
    for k in 0..SUBSPACE_DIM {
        assert!((got[k] - c[k]).abs() < 2e-3, "c[{k}] {} vs {}", got[k], c[k]);
    }
    // Fewer visible pixels than unknowns is an error, not a guess.
    let mut few = [NO_VALUE; SHAPE_W * SHAPE_H];
    few[..10].fill(0.1);
    assert_eq!(s.project(&few), Err(ProjectError::TooFewPixels { visible: 10 }));
}

#[test]
fn the_forest_averages_its_trees_leaves() {
    let (buf, n) = tiny();
    let m = ShapeModelView::parse(&buf[..n]).unwrap();
    assert_eq!(m.forest().tree_count(), 2);
    let mut c = [0.0f32; SUBSPACE_DIM];
    c[0] = -1.0;
    let left = m.forest().predict(&c);
    c[0] = 1.0;
    let right = m.forest().predict(&c);
    for k in 0..SHAPE_COMPONENTS {
        let want_l = (SHAPE_LEAVES[0][k] + SHAPE_LEAVES[2][k]) as f32 * SHAPE_LEAF_SCALE / 2.0;
        let want_r = (SHAPE_LEAVES[1][k] + SHAPE_LEAVES[2][k]) as f32 * SHAPE_LEAF_SCALE / 2.0;
        assert!((left[k] - want_l).abs() < 1e-6 && (right[k] - want_r).abs() < 1e-6);
    }
}

#[test]
fn damaged_shape_files_are_errors_not_panics() {
    let (buf, n) = tiny();
    for at in 0..n {
        let mut bad = buf;
        bad[at] ^= 0x5A;
        assert!(
            ShapeModelView::parse(&bad[..n]).is_err(),
            "flip at byte {at} accepted"
        );
    }
    for len in (0..n).step_by(7) {
        assert!(
            ShapeModelView::parse(&buf[..len]).is_err(),
            "truncated to {len} accepted"
        );
    }
    let mut body = [0u8; fixture::TINY_BODY_LEN];
    let b = fixture::tiny_body_model(&mut body).unwrap();
    assert!(matches!(
        ShapeModelView::parse(&body[..b]),
        Err(ModelFileError::WrongKind { .. })
    ));
}

#[test]
fn a_forest_whose_child_points_backwards_is_rejected() {
    // Re-write the fixture with node 0's left child pointing at itself: valid container, invalid forest.
    let (buf, n) = tiny();
    let file = ModelFile::parse(&buf[..n], KIND, FORMAT_VERSION).unwrap();
    let mut sections = [None; 12];
    for (i, s) in sections.iter_mut().enumerate() {
        *s = file.section_at(i);
    }
    let mut nchl = [0u8; 16];
    nchl[4..8].copy_from_slice(&0u32.to_le_bytes());
    nchl[8..12].copy_from_slice(&1u32.to_le_bytes());
    nchl[12..16].copy_from_slice(&2u32.to_le_bytes());
    let data = sections.map(|s| {
        let s = s.unwrap();
        crate::model_file::SectionData {
            tag: s.tag,
            elem: s.elem,
            bytes: if &s.tag == b"NCHL" { &nchl } else { s.bytes },
        }
    });
    let mut out = [0u8; TINY_SHAPE_LEN];
    let m = crate::model_file::write(KIND, FORMAT_VERSION, &data, &mut out).unwrap();
    assert!(matches!(
        ShapeModelView::parse(&out[..m]),
        Err(ModelFileError::InvalidData { .. })
    ));
}

#[test]
fn the_height_reference_is_read_and_an_unknown_one_rejected() {
    let mut buf = [0u8; TINY_SHAPE_LEN];
    let n = fixture::tiny_shape_model_with_reference(&mut buf, None).unwrap();
    let m = ShapeModelView::parse(&buf[..n]).unwrap();
    assert_eq!(m.camera().height_reference, HeightReference::HipCentre);
    let n = fixture::tiny_shape_model_with_reference(&mut buf, Some(1)).unwrap();
    let m = ShapeModelView::parse(&buf[..n]).unwrap();
    assert_eq!(m.camera().height_reference, HeightReference::Mattress);
    let n = fixture::tiny_shape_model_with_reference(&mut buf, Some(7)).unwrap();
    assert!(matches!(
        ShapeModelView::parse(&buf[..n]),
        Err(ModelFileError::InvalidData { tag, .. }) if tag == *b"CREF"
    ));
}

/// `values` as little-endian f32 bytes into `out` (four bytes each).
fn le_f32(values: &[f32], out: &mut [u8]) {
    for (b, v) in out.chunks_exact_mut(4).zip(values) {
        b.copy_from_slice(&v.to_le_bytes());
    }
}

/// The fixture re-written with the `extra` sections (tag, f32 little-endian bytes) appended.
fn with_linear(extra: &[(&[u8; 4], &[u8])], out: &mut [u8]) -> usize {
    use crate::model_file::{ElemType, SectionData};
    let (buf, n) = tiny();
    let file = ModelFile::parse(&buf[..n], KIND, FORMAT_VERSION).unwrap();
    let count = file.section_count();
    let mut sections = [SectionData {
        tag: *b"LINR",
        elem: ElemType::F32,
        bytes: &[],
    }; 16];
    for (i, d) in sections.iter_mut().enumerate().take(count) {
        let s = file.section_at(i).unwrap();
        *d = SectionData {
            tag: s.tag,
            elem: s.elem,
            bytes: s.bytes,
        };
    }
    for (d, (tag, bytes)) in sections[count..].iter_mut().zip(extra) {
        d.tag = **tag;
        d.bytes = bytes;
    }
    crate::model_file::write(KIND, FORMAT_VERSION, &sections[..count + extra.len()], out).unwrap()
}

#[test]
fn a_linear_regression_section_replaces_the_forest_and_bad_ones_are_rejected() {
    use super::linear::LINEAR_LEN;
    // s_j = 2 c_j + j / 10 for j < 20 (the identity times two plus a bias).
    let mut w = [0.0f32; LINEAR_LEN];
    for j in 0..SHAPE_COMPONENTS {
        w[j * SHAPE_COMPONENTS + j] = 2.0;
        w[SUBSPACE_DIM * SHAPE_COMPONENTS + j] = j as f32 / 10.0;
    }
    let mut bytes = [0u8; LINEAR_LEN * 4];
    le_f32(&w, &mut bytes);
    let mut out = [0u8; 8192];
    let n = with_linear(&[(b"LINR", &bytes)], &mut out);
    let m = ShapeModelView::parse(&out[..n]).unwrap();
    let mut c = [0.0f32; SUBSPACE_DIM];
    c[3] = 0.5;
    let pts = salient_square();
    let s = m.regress(&c, &pts);
    assert!(m.linear().is_some_and(|l| !l.uses_points()));
    for (j, sj) in s.iter().enumerate() {
        let want = if j == 3 { 1.0 } else { 0.0 } + j as f32 / 10.0;
        assert!((sj - want).abs() < 1e-6, "s[{j}] {sj} vs {want}");
    }
    // Far outside the training views the affine map is held at ±3σ.
    c[3] = 100.0;
    assert_eq!(m.regress(&c, &pts)[3], linear::LINEAR_BOUND);
    c[3] = 0.5;
    // Without the section the forest answers.
    let (buf, k) = tiny();
    let plain = ShapeModelView::parse(&buf[..k]).unwrap();
    assert!(plain.linear().is_none());
    assert_eq!(plain.regress(&c, &pts), plain.forest().predict(&c));
    // A non-finite weight or a wrong length is a clear error.
    bytes[8..12].copy_from_slice(&f32::NAN.to_le_bytes());
    let n = with_linear(&[(b"LINR", &bytes)], &mut out);
    assert!(matches!(
        ShapeModelView::parse(&out[..n]),
        Err(ModelFileError::InvalidData { tag, .. }) if tag == *b"LINR"
    ));
    let n = with_linear(&[(b"LINR", &bytes[..40])], &mut out);
    assert!(ShapeModelView::parse(&out[..n]).is_err());
}

/// Salient points of a 0.4 m wide, 0.3 m hip-wide torso 0.5 m long with the head 0.25 m above the shoulders,
/// 1 m from the camera.
fn salient_square() -> [Point3; SalientPoint::COUNT] {
    [
        Point3::new(0.0, -0.25, 1.0),
        Point3::new(0.2, 0.0, 1.0),
        Point3::new(-0.2, 0.0, 1.0),
        Point3::new(0.0, 0.25, 1.0),
        Point3::new(0.15, 0.5, 1.0),
        Point3::new(-0.15, 0.5, 1.0),
    ]
}

#[test]
fn the_point_features_are_the_salient_points_spacing() {
    let f = linear::point_features(&salient_square());
    for (got, want) in f.iter().zip([0.4, 0.3, 0.5, 0.25]) {
        assert!((got - want).abs() < 1e-6, "{f:?}");
    }
}

#[test]
fn a_linear_regression_on_points_reads_the_point_features() {
    use super::linear::{LINEAR_INPUTS, LINEAR_POINTS_LEN};
    // s_0 = 10 (shoulder width) - 1 + 0 c; s_j = c_j for the rest.
    let mut w = [0.0f32; LINEAR_POINTS_LEN];
    for j in 1..SHAPE_COMPONENTS {
        w[j * SHAPE_COMPONENTS + j] = 1.0;
    }
    w[SUBSPACE_DIM * SHAPE_COMPONENTS] = 10.0;
    w[LINEAR_INPUTS * SHAPE_COMPONENTS] = -1.0;
    let mut bytes = [0u8; LINEAR_POINTS_LEN * 4];
    le_f32(&w, &mut bytes);
    let mut out = [0u8; 8192];
    let n = with_linear(&[(b"LINP", &bytes)], &mut out);
    let m = ShapeModelView::parse(&out[..n]).unwrap();
    assert!(m.linear().is_some_and(|l| l.uses_points()));
    let mut c = [0.0f32; SUBSPACE_DIM];
    c[2] = 0.7;
    let s = m.regress(&c, &salient_square());
    assert!((s[0] - 3.0).abs() < 1e-5, "{}", s[0]);
    assert!((s[2] - 0.7).abs() < 1e-6);
    // Beside a LINR map the LINP one is the estimate's; `coefficients_only` takes the LINR one, or the forest.
    assert_eq!(
        m.coefficients_only().regress(&c, &salient_square()),
        m.forest().predict(&c)
    );
    let mut r = [0.0f32; LINEAR_LEN];
    r[SUBSPACE_DIM * SHAPE_COMPONENTS] = 2.5;
    let mut r_bytes = [0u8; LINEAR_LEN * 4];
    le_f32(&r, &mut r_bytes);
    let mut both_out = [0u8; 12288];
    let n = with_linear(&[(b"LINR", &r_bytes), (b"LINP", &bytes)], &mut both_out);
    let both = ShapeModelView::parse(&both_out[..n]).unwrap();
    assert_eq!(both.regress(&c, &salient_square()), s);
    let coeffs = both.coefficients_only();
    assert!(coeffs.linear().is_some_and(|l| !l.uses_points()));
    assert_eq!(coeffs.regress(&c, &salient_square())[0], 2.5);
    // A wrong length or a non-finite weight in LINP is refused as in LINR.
    let n = with_linear(&[(b"LINP", &bytes[..LINEAR_POINTS_LEN * 4 - 4])], &mut out);
    assert!(ShapeModelView::parse(&out[..n]).is_err());
    bytes[4..8].copy_from_slice(&f32::INFINITY.to_le_bytes());
    let n = with_linear(&[(b"LINP", &bytes)], &mut out);
    assert!(matches!(
        ShapeModelView::parse(&out[..n]),
        Err(ModelFileError::InvalidData { tag, .. }) if tag == *b"LINP"
    ));
}
