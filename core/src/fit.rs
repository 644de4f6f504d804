//! Shape refinement by model fitting (paper §3.4, Eq. 7): alternate rigid ICP of the torso ICP subset against the
//! depth frame with a shape step on the body model's coefficients, for a fixed number of rounds with an early stop.
//!
//! Shape step: with the current pairs (model vertex `i`, observed point `C_i` and normal `n_i`, both taken into the
//! model frame) the energy
//! `E(z) = λ/2 ‖z‖² + ½ (z − z₀)ᵀ Λ (z − z₀) + 1/(2 N_p) Σ_i (n_iᵀ (C_i − M_i − V_i diag(σ) z) / u)²`
//! is quadratic in the σ-normalised coefficients `z`, so one Gauss-Newton step is its exact minimiser: a 20x20
//! Cholesky solve. Two choices the paper leaves open: the data term is point-to-plane (the distance to the observed
//! surface, which is what projective pairs measure; point-to-point would pull vertices along the viewing ray), and
//! residuals are in units of `u = length_unit_m` (1 cm by default), which sets how strongly λ and Λ pull against
//! the data (chosen on validation bodies; see `docs/shape-eval.md`).
//!
//! Cost per round: shaping the subset (`3·n·20` multiply-adds), `icp_steps` ICP steps and one association with a
//! 20x20 outer product per pair: about 1 ms for 1.2 k points on one desktop core; nothing allocates (the caller
//! lends the shaped-subset buffer).

use crate::body_model::{BodyModelView, BodyPart, SHAPE_COMPONENTS};
use crate::camera::Intrinsics;
use crate::depth::DepthFrame;
use crate::error::BufferLenError;
use crate::geometry::{Isometry3, Point3, Vector3};
use crate::icp::{self, Association, IcpError, IcpParams};
use crate::salient::SalientPoint;
use crate::shape::canonical::{self, DegenerateFrame};
use crate::spd::solve_spd;

/// Fitting parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitParams {
    /// Alternation rounds at most (rigid ICP then shape step).
    pub rounds: u8,
    /// Rigid ICP steps per round.
    pub icp_steps: u8,
    /// Eq. 7's λ (pull toward the mean body).
    pub lambda: f32,
    /// Eq. 7's Λ diagonal (pull toward the prior `z₀`), per coefficient.
    pub prior_weight: [f32; SHAPE_COMPONENTS],
    /// Residual unit `u` (metres).
    pub length_unit_m: f32,
    /// Stop when no coefficient moved more than this (σ units) in a round.
    pub stop_change: f32,
    /// Use every `stride`-th subset vertex.
    pub stride: u16,
    /// Association parameters.
    pub icp: IcpParams,
    /// Coarse to fine: from the second round on, pairs farther apart than this are dropped (at most
    /// `icp.max_distance_m`, which the first round uses); `None` keeps `icp.max_distance_m` throughout.
    pub fine_distance_m: Option<f32>,
}

/// Eq. 7's Λ on the coefficients the combined fit leaves nearly free (the paper's "small"): 0.1, chosen on the
/// validation bodies among 1e-3 to 1 (`eval shape --split validation --free-weight W`, docs/shape-eval.md); with
/// 1e-3 the fit moved s3 away from a better regression estimate.
pub const FREE_PRIOR_WEIGHT: f32 = 0.1;

impl FitParams {
    /// The paper's combined setting: λ = 0.1, Λ = [`FREE_PRIOR_WEIGHT`] on `torso` coefficients and 1 on the
    /// others.
    pub fn combined(icp: IcpParams, torso: &[usize]) -> FitParams {
        Self::combined_with(icp, torso, FREE_PRIOR_WEIGHT)
    }

    /// [`Self::combined`] with Λ = `free_weight` on the `torso` coefficients.
    pub fn combined_with(icp: IcpParams, torso: &[usize], free_weight: f32) -> FitParams {
        let mut prior_weight = [1.0; SHAPE_COMPONENTS];
        for &t in torso {
            if t < SHAPE_COMPONENTS {
                prior_weight[t] = free_weight;
            }
        }
        FitParams {
            rounds: 10,
            icp_steps: 3,
            lambda: 0.1,
            prior_weight,
            length_unit_m: 0.01,
            stop_change: 0.01,
            stride: 1,
            icp,
            fine_distance_m: None,
        }
    }

    /// Plain model fitting (no prior shape: Λ = 0).
    pub fn plain(icp: IcpParams) -> FitParams {
        FitParams {
            prior_weight: [0.0; SHAPE_COMPONENTS],
            ..FitParams::combined(icp, &[])
        }
    }
}

/// The outcome of a fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitResult {
    /// Shape coefficients (σ units).
    pub shape: [f32; SHAPE_COMPONENTS],
    /// Rigid pose of the model's body frame in the camera frame.
    pub camera_from_model: Isometry3,
    /// Rounds run (fewer than `rounds` after an early stop).
    pub rounds: u8,
    /// The last association (pairs, occluded points, residual).
    pub association: Association,
}

/// Why a fit failed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FitError {
    /// The shaped-subset buffer has the wrong length.
    Buffer(BufferLenError),
    /// The initial pose could not be built from the salient points.
    Frame(DegenerateFrame),
    /// ICP failed.
    Icp(IcpError),
    /// The shape system was singular.
    Singular,
}

impl core::fmt::Display for FitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FitError::Buffer(e) => write!(f, "fit scratch: {e}"),
            FitError::Frame(e) => e.fmt(f),
            FitError::Icp(e) => e.fmt(f),
            FitError::Singular => f.write_str("shape system is singular"),
        }
    }
}

impl core::error::Error for FitError {}

fn raw(body: &BodyModelView<'_>, z: &[f32; SHAPE_COMPONENTS]) -> [f32; SHAPE_COMPONENTS] {
    let mut s = [0.0; SHAPE_COMPONENTS];
    for (k, x) in s.iter_mut().enumerate() {
        *x = z[k] * body.sigma(k);
    }
    s
}

/// The rigid start: the model's rest-pose body frame (shape `z`, hip centre, shoulders up, facing −y) placed on the
/// body frame of the observed salient points and the mattress normal (camera frame).
pub fn initial_pose(
    body: &BodyModelView<'_>,
    z: &[f32; SHAPE_COMPONENTS],
    observed: &[Point3; SalientPoint::COUNT],
    mattress_up: &Vector3,
) -> Result<Isometry3, DegenerateFrame> {
    let (hip, sh) = hip_and_shoulder_centres(body, z);
    let model_from_frame = canonical::frame_from_axes(hip, sh - hip, -Vector3::y())?;
    let camera_from_frame = canonical::body_frame(observed, mattress_up)?;
    Ok(camera_from_frame * model_from_frame.inverse())
}

/// The hip centre and the shoulder centre of the model shaped `z` (σ units), model frame.
fn hip_and_shoulder_centres(body: &BodyModelView<'_>, z: &[f32; SHAPE_COMPONENTS]) -> (Vector3, Vector3) {
    let m = body.salient_points(&raw(body, z)).map(Vector3::from);
    let hip = (m[SalientPoint::LeftHip.index()] + m[SalientPoint::RightHip.index()]) * 0.5;
    let sh = (m[SalientPoint::LeftShoulder.index()] + m[SalientPoint::RightShoulder.index()]) * 0.5;
    (hip, sh)
}

/// Offsets along the model's long axis (hip centre to shoulder centre) that [`fit_shape_along_axis`] starts from,
/// metres. The joint forest's points, 5 cm off, move the start mostly along the body, where the torso's front, close
/// to a cylinder along it, holds a rigid fit least, and the shape steps take up the shift. Seven starts 3 cm apart,
/// chosen on the validation bodies with the forest's points: combined 10.01 -> 9.60 mm (three 5 cm apart 9.66, five
/// 4 or 5 cm apart 9.66, seven 5 cm apart 9.77; docs/shape-eval.md, round 13).
pub const AXIS_STARTS_M: [f32; 7] = [-0.09, -0.06, -0.03, 0.0, 0.03, 0.06, 0.09];

/// [`fit_shape`] from `camera_from_model` moved along the model's long axis by each of `offsets_m` (none: from
/// `camera_from_model` alone), keeping the fit with the lowest RMS residual (the earlier one when tied); the last
/// start's error when none succeeds. Cost: one fit per offset.
#[allow(clippy::too_many_arguments)] // as fit_shape, plus the offsets
pub fn fit_shape_along_axis(
    body: &BodyModelView<'_>,
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    z0: &[f32; SHAPE_COMPONENTS],
    camera_from_model: Isometry3,
    offsets_m: &[f32],
    params: &FitParams,
    points: &mut [[f32; 3]],
    normals: &mut [[f32; 3]],
) -> Result<FitResult, FitError> {
    let (hip, sh) = hip_and_shoulder_centres(body, z0);
    let axis = camera_from_model.rotation * (sh - hip).try_normalize(1e-6).unwrap_or_else(Vector3::y);
    let offsets = if offsets_m.is_empty() {
        &[0.0][..]
    } else {
        offsets_m
    };
    let mut best: Option<FitResult> = None;
    let mut last = None;
    for &d in offsets {
        let mut start = camera_from_model;
        start.translation.vector += axis * d;
        match fit_shape(body, frame, k, z0, start, params, points, normals) {
            Ok(r) if best.is_none_or(|b| r.association.rms_m() < b.association.rms_m()) => best = Some(r),
            Ok(_) => {}
            Err(e) => last = Some(e),
        }
    }
    best.ok_or(last.unwrap_or(FitError::Singular))
}

/// Area-weighted outward vertex normals of the shaped torso subset (from its triangles), normalised.
pub fn subset_normals(body: &BodyModelView<'_>, points: &[[f32; 3]], normals: &mut [[f32; 3]]) {
    crate::torso::vertex_normals(body.torso_subset_triangles(), points, normals, Vector3::zeros());
}

/// The bed-contact term of [`fit_shape_on_bed`]: the patient's back rests on the mattress, so the lowest torso
/// vertex (chest, abdomen, pelvis) of the shaped, rigidly placed model is held at `height_m` above the mattress
/// plane of [`IcpParams::mattress`]. The front surface alone cannot tell a thick body from a thin one shifted toward
/// the camera (rigid ICP absorbs thickness as a translation); the bed pins the back, so the front's height above it
/// is the body's thickness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BedContact {
    /// Weight of the contact residual against the data term (which is a mean over pairs: 1 weighs the contact like
    /// one average pair of the whole term).
    pub weight: f32,
    /// Height above the mattress plane at which the lowest torso vertex rests (metres; 0 = touching).
    pub height_m: f32,
}

impl Default for BedContact {
    fn default() -> Self {
        BedContact {
            weight: 1.0,
            height_m: 0.0,
        }
    }
}

/// The lowest torso vertex of shape `s` (raw) placed by `camera_from_model` and its height above `mattress`.
fn lowest_torso_vertex(
    body: &BodyModelView<'_>,
    s: &[f32; SHAPE_COMPONENTS],
    camera_from_model: &Isometry3,
    mattress: &crate::geometry::Plane,
) -> Option<(usize, f32)> {
    let mut best: Option<(usize, f32)> = None;
    for v in 0..body.vertex_count() {
        if !matches!(
            body.part_of_vertex(v),
            BodyPart::Chest | BodyPart::Abdomen | BodyPart::Pelvis
        ) {
            continue;
        }
        let p = *camera_from_model * Point3::from(body.shape_vertex(v, s));
        let h = mattress.signed_distance(&p);
        if best.is_none_or(|(_, b)| h < b) {
            best = Some((v, h));
        }
    }
    best
}

/// Alternate rigid ICP and Eq. 7 shape steps from shape `z0` (σ units, also the prior) and pose
/// `camera_from_model`. `points` and `normals` are scratch for the shaped torso subset and its outward normals
/// (`body.counts().subset` entries each).
#[allow(clippy::too_many_arguments)] // the frame, its camera, the model, the start and the scratch are all needed
pub fn fit_shape(
    body: &BodyModelView<'_>,
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    z0: &[f32; SHAPE_COMPONENTS],
    camera_from_model: Isometry3,
    params: &FitParams,
    points: &mut [[f32; 3]],
    normals: &mut [[f32; 3]],
) -> Result<FitResult, FitError> {
    fit_shape_with(
        body,
        frame,
        k,
        z0,
        camera_from_model,
        params,
        None,
        points,
        normals,
    )
}

/// [`fit_shape`] with the bed-contact term: after each round's ICP steps the model is moved along the mattress
/// normal until its lowest torso vertex rests at `contact.height_m`, and the shape step holds that vertex there
/// (one more residual, weighted by `contact.weight`). Extra cost: shaping the torso vertices once per round.
#[allow(clippy::too_many_arguments)] // as fit_shape, plus the contact
pub fn fit_shape_on_bed(
    body: &BodyModelView<'_>,
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    z0: &[f32; SHAPE_COMPONENTS],
    camera_from_model: Isometry3,
    params: &FitParams,
    contact: &BedContact,
    points: &mut [[f32; 3]],
    normals: &mut [[f32; 3]],
) -> Result<FitResult, FitError> {
    fit_shape_with(
        body,
        frame,
        k,
        z0,
        camera_from_model,
        params,
        Some(contact),
        points,
        normals,
    )
}

/// [`fit_shape`] with the bed contact when `contact` is given ([`fit_shape_on_bed`]), without it otherwise.
#[allow(clippy::too_many_arguments)] // see fit_shape
pub fn fit_shape_with(
    body: &BodyModelView<'_>,
    frame: &DepthFrame<'_>,
    k: &Intrinsics,
    z0: &[f32; SHAPE_COMPONENTS],
    camera_from_model: Isometry3,
    params: &FitParams,
    contact: Option<&BedContact>,
    points: &mut [[f32; 3]],
    normals: &mut [[f32; 3]],
) -> Result<FitResult, FitError> {
    if normals.len() != points.len() {
        return Err(FitError::Buffer(BufferLenError {
            expected: points.len(),
            found: normals.len(),
        }));
    }
    let subset = body.torso_subset();
    let stride = params.stride.max(1) as usize;
    let mut z = *z0;
    let mut pose = camera_from_model;
    let mut rounds = 0;
    let mut last = Association::default();
    let u = params.length_unit_m;
    let mut icp_params = params.icp;
    for round in 0..params.rounds {
        if round == 1
            && let Some(d) = params.fine_distance_m
        {
            icp_params.max_distance_m = icp_params.max_distance_m.min(d);
        }
        rounds += 1;
        body.shape_torso_subset(&raw(body, &z), points)
            .map_err(FitError::Buffer)?;
        subset_normals(body, points, normals);
        for _ in 0..params.icp_steps {
            pose = icp::point_to_plane_step(frame, k, points, Some(normals), stride, &pose, &icp_params)
                .map_err(FitError::Icp)?
                .0;
        }
        let bed = params.icp.mattress;
        let lowest = match contact {
            Some(c) => {
                let found = lowest_torso_vertex(body, &raw(body, &z), &pose, &bed);
                if let Some((_, h)) = found {
                    pose.translation.vector += bed.normal() * (c.height_m - h);
                }
                found.map(|(v, _)| (v, c))
            }
            None => None,
        };
        let model_from_camera = pose.inverse();
        let mut a = [[0.0f32; SHAPE_COMPONENTS]; SHAPE_COMPONENTS];
        let mut b = [0.0f32; SHAPE_COMPONENTS];
        let mut basis = [[0.0f32; 3]; SHAPE_COMPONENTS];
        last = icp::associate(
            frame,
            k,
            points,
            Some(normals),
            stride,
            &pose,
            &icp_params,
            |i, _, o, n| {
                let v = subset.at(i) as usize;
                let c = model_from_camera * o;
                let n = model_from_camera.rotation * n;
                let m = Vector3::from(body.shape_row(v, &[]));
                body.row_basis(v, &mut basis);
                let r = n.dot(&(c.coords - m)) / u;
                let mut j = [0.0f32; SHAPE_COMPONENTS];
                for (q, jq) in j.iter_mut().enumerate() {
                    *jq = n.dot(&Vector3::from(basis[q])) * body.sigma(q) / u;
                }
                // Whole rows, though the solve reads only the lower triangle: its sums are the same products in
                // the same order (the same bits), and a fixed-length row vectorises where the triangle did not.
                for x in 0..SHAPE_COMPONENTS {
                    b[x] += j[x] * r;
                    for (ay, jy) in a[x].iter_mut().zip(&j) {
                        *ay += j[x] * jy;
                    }
                }
            },
        );
        if last.pairs < SHAPE_COMPONENTS {
            return Err(FitError::Icp(IcpError::TooFewPairs { pairs: last.pairs }));
        }
        let inv_n = 1.0 / last.pairs as f32;
        for x in 0..SHAPE_COMPONENTS {
            b[x] = b[x] * inv_n + params.prior_weight[x] * z0[x];
            for ay in a[x].iter_mut().take(x + 1) {
                *ay *= inv_n;
            }
            a[x][x] += params.lambda + params.prior_weight[x];
        }
        if let Some((v, c)) = lowest {
            // Residual (target height − height of the mean-shape vertex) / u, linear in z like the pairs'.
            let n = pose.rotation.inverse() * bed.normal();
            let m = Point3::from(body.shape_vertex(v, &[]));
            let r = (c.height_m - bed.signed_distance(&(pose * m))) / u;
            body.row_basis(v, &mut basis);
            let mut j = [0.0f32; SHAPE_COMPONENTS];
            for (q, jq) in j.iter_mut().enumerate() {
                *jq = n.dot(&Vector3::from(basis[q])) * body.sigma(q) / u;
            }
            for x in 0..SHAPE_COMPONENTS {
                b[x] += c.weight * j[x] * r;
                for y in 0..=x {
                    a[x][y] += c.weight * j[x] * j[y];
                }
            }
        }
        if !solve_spd(&mut a, &mut b) {
            return Err(FitError::Singular);
        }
        let change = b
            .iter()
            .zip(&z)
            .map(|(n, o)| (n - o).abs())
            .fold(0.0f32, f32::max);
        z = b;
        if change < params.stop_change {
            break;
        }
    }
    Ok(FitResult {
        shape: z,
        camera_from_model: pose,
        rounds,
        association: last,
    })
}
