//! One frame's joint estimate: sample kept pixels, descend every tree, turn the reached leaves into votes
//! (Eq. 5: sample position plus the summed refined leaf weights, weighted by Eq. 6's summed confidences; or the
//! baseline's per-tree modes), and run the weighted mean-shift per point with its optional prior.
//! All working memory is the caller's [`Workspace`]; nothing allocates. Deterministic for a seed.
//! Cost: samples x trees x depth node tests, then per point one vote pass and one mean-shift.

use crate::camera::Intrinsics;
use crate::forest::feature::{DepthImage, ProbeOrigin, ProbeScale};
use crate::forest::meanshift::{Prior, Vote, VoteBuffer, mean_shift};
use crate::forest::model::{ForestModel, Node, decode_node};
use crate::forest::sample::{Ceiling, Clip, SamplePixel, sample_pixels};
use crate::forest::{MAX_SAMPLES, MAX_TREES, MAX_VOTES, MODES};
use crate::geometry::{Plane, Point3};
use crate::salient::SalientPoint;

const P: usize = SalientPoint::COUNT;

/// Which leaves vote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Girshick et al. 2011: per tree, up to two modes per leaf, vote length threshold.
    Baseline,
    /// The paper's global refinement: one summed vote per sample (Eq. 5) with Eq. 6 weights.
    Refined,
}

/// One point's estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointEstimate {
    /// Position, camera frame, metres.
    pub position: Point3,
    /// Share of the vote weight (prior included) within the kernel at the mode, 0..1.
    pub confidence: f32,
}

/// Working memory of one inference (about 170 KiB; keep one per tracker, e.g. in a static or a box).
pub struct Workspace {
    samples: [SamplePixel; MAX_SAMPLES],
    leaves: [[u32; MAX_TREES]; MAX_SAMPLES],
    order: [u16; MAX_SAMPLES],
    votes: VoteBuffer<MAX_VOTES>,
    /// Samples of the last [`estimate`], which [`reestimate`] reads again.
    last: usize,
}

impl Default for Workspace {
    fn default() -> Self {
        Self::new()
    }
}

impl Workspace {
    /// Zeroed working memory.
    pub const fn new() -> Self {
        Workspace {
            samples: [SamplePixel {
                x: 0,
                y: 0,
                d_mm: 0,
                p: [0.0; 3],
            }; MAX_SAMPLES],
            leaves: [[0; MAX_TREES]; MAX_SAMPLES],
            order: [0; MAX_SAMPLES],
            votes: VoteBuffer::new(),
            last: 0,
        }
    }

    /// The samples of the last inference.
    pub fn samples(&self, n: usize) -> &[SamplePixel] {
        &self.samples[..n.min(MAX_SAMPLES)]
    }
}

/// Options of one inference.
#[derive(Clone, Copy, Debug)]
pub struct InferConfig {
    /// Samples to draw (at most [`MAX_SAMPLES`]).
    pub samples: usize,
    /// Seed of the pixel sampling.
    pub seed: u64,
    /// Which leaves vote.
    pub method: Method,
}

/// The leaf tree `tree` of `model` gives the sample at (x, y) of depth `d_mm`.
#[inline]
pub fn descend<M: ForestModel + ?Sized, D: DepthImage + ?Sized>(
    model: &M,
    tree: usize,
    img: &D,
    x: i32,
    y: i32,
    d_mm: u16,
) -> u32 {
    let s = ProbeScale::new(d_mm);
    let mut i = 0u32;
    loop {
        match model.node(tree, i) {
            Node::Leaf(l) => return l,
            // Branch-free child choice: the test's outcome is a coin flip the predictor cannot learn.
            Node::Split { test, left } => i = left + u32::from(!test.goes_left(img, x, y, s)),
        }
    }
}

/// Samples descended together by [`descend_samples`] (with the trees, up to `GROUP * MAX_TREES` load chains in flight).
const GROUP: usize = 8;
/// Rows per band of the descent order (samples of one band probe overlapping rows of the image).
const BAND_ROWS: u16 = 8;
/// Bands of a frame at most (480 rows; taller frames share the last band).
const BANDS: usize = 64;

/// Order of `samples` by 8-row band (a stable counting sort, O(n)): consecutive samples then probe nearby pixels and
/// mostly take the same upper nodes, so the descent's depth and node loads hit the cache.
fn band_order(samples: &[SamplePixel], order: &mut [u16]) {
    let band = |s: &SamplePixel| ((s.y / BAND_ROWS) as usize).min(BANDS - 1);
    let mut start = [0u16; BANDS + 1];
    for s in samples {
        start[band(s) + 1] += 1;
    }
    for b in 0..BANDS {
        start[b + 1] += start[b];
    }
    for (i, s) in samples.iter().enumerate() {
        let b = band(s);
        order[start[b] as usize] = i as u16;
        start[b] += 1;
    }
}

/// The leaves of every sample in every tree (`leaves[i][..trees]` for `samples[i]`, the same leaves as [`descend`]):
/// samples are taken in band order, [`GROUP`] at a time, and all their trees descended in lockstep, a lane that
/// reached its leaf staying there until the group's deepest lane is done, so that up to `GROUP * trees` independent
/// chains of node and depth loads overlap and the loop's only branch, the leaf test, is well predicted. A lane carries
/// its node's record ([`ForestModel::record`]) and loads both children's with the node's probes, so a level costs
/// the slower of the two loads, not their sum (about 0.8x the time of descending by child index,
/// `docs/joint-forest.md`).
fn descend_samples<M: ForestModel + ?Sized, D: DepthImage + ?Sized>(
    model: &M,
    trees: usize,
    img: &D,
    samples: &[SamplePixel],
    order: &mut [u16],
    leaves: &mut [[u32; MAX_TREES]],
) {
    // The tree count as a constant: the lockstep loop then unrolls over the trees without a count check per lane.
    // The last arm is exactly MAX_TREES trees (callers pass at most that).
    const _: () = assert!(MAX_TREES == 4, "descend_samples dispatches on 1-4 trees");
    match trees {
        0 => {}
        1 => descend_samples_n::<1, M, D>(model, img, samples, order, leaves),
        2 => descend_samples_n::<2, M, D>(model, img, samples, order, leaves),
        3 => descend_samples_n::<3, M, D>(model, img, samples, order, leaves),
        _ => descend_samples_n::<MAX_TREES, M, D>(model, img, samples, order, leaves),
    }
}

/// [`descend_samples`] for `T` trees.
fn descend_samples_n<const T: usize, M: ForestModel + ?Sized, D: DepthImage + ?Sized>(
    model: &M,
    img: &D,
    samples: &[SamplePixel],
    order: &mut [u16],
    leaves: &mut [[u32; MAX_TREES]],
) {
    let trees = T;
    let order = &mut order[..samples.len()];
    band_order(samples, order);
    let roots: [u64; T] = core::array::from_fn(|t| model.record(t, 0));
    for group in order.chunks(GROUP) {
        let mut at = [[0u64; MAX_TREES]; GROUP];
        for a in at.iter_mut() {
            a[..T].copy_from_slice(&roots);
        }
        let mut px = [ProbeOrigin::new(0, 0, ProbeScale::new(0)); GROUP];
        for (g, &i) in group.iter().enumerate() {
            let s = &samples[i as usize];
            px[g] = ProbeOrigin::new(s.x as i32, s.y as i32, ProbeScale::new(s.d_mm));
        }
        loop {
            let mut done = true;
            for (a, &p) in at.iter_mut().zip(&px).take(group.len()) {
                for (t, r) in a.iter_mut().enumerate().take(trees) {
                    if let Node::Split { test, left } = decode_node(*r) {
                        // Both children load while the probes are read: the next level's node does not wait on
                        // this level's depths. The choice is a select, branch-free on the test's outcome, which the
                        // predictor cannot learn.
                        let kids = model.child_records(t, left);
                        *r = if test.goes_left_from(img, p) {
                            kids[0]
                        } else {
                            kids[1]
                        };
                        done = false;
                    }
                }
            }
            if done {
                break;
            }
        }
        for (a, &i) in at.iter().zip(group.iter()) {
            for t in 0..trees {
                if let Node::Leaf(l) = decode_node(a[t]) {
                    leaves[i as usize][t] = l;
                }
            }
        }
    }
}

/// Votes for `point` from samples at `positions` that reached `leaves` (one row per sample, the first
/// `model.tree_count()` entries used), weighted by `prior`; returns how many votes were written to `votes`.
pub fn collect_votes<M: ForestModel + ?Sized>(
    model: &M,
    method: Method,
    point: usize,
    positions: impl Iterator<Item = [f32; 3]>,
    leaves: &[[u32; MAX_TREES]],
    prior: Option<&Prior>,
    votes: &mut [Vote],
) -> usize {
    let mut n = 0;
    for_each_vote(model, method, point, positions, leaves, prior, |v| {
        if n >= votes.len() {
            return false;
        }
        votes[n] = v;
        n += 1;
        true
    });
    n
}

/// Every vote of [`collect_votes`] in order, handed to `sink` until it returns false (full).
#[inline]
fn for_each_vote<M: ForestModel + ?Sized>(
    model: &M,
    method: Method,
    point: usize,
    positions: impl Iterator<Item = [f32; 3]>,
    leaves: &[[u32; MAX_TREES]],
    prior: Option<&Prior>,
    mut sink: impl FnMut(Vote) -> bool,
) {
    let trees = model.tree_count();
    let params = model.params(point);
    let max_len2 = params.vote_length_m * params.vote_length_m;
    // Returns false once the sink is full.
    let mut push = |p: [f32; 3], w: f32| {
        if w <= 0.0 {
            return true;
        }
        let w = match prior {
            Some(pr) => w * pr.weight(&p),
            None => w,
        };
        w <= 0.0 || sink(Vote { p, w })
    };
    for (p, row) in positions.zip(leaves) {
        match method {
            Method::Refined => {
                let mut o = [0.0f32; 3];
                let mut w = 0.0f32;
                for &l in &row[..trees] {
                    let v = model.refined(l, point);
                    for a in 0..3 {
                        o[a] += v.offset[a];
                    }
                    w += v.weight;
                }
                if !push([p[0] + o[0], p[1] + o[1], p[2] + o[2]], w) {
                    return;
                }
            }
            Method::Baseline => {
                for &l in &row[..trees] {
                    for m in 0..MODES {
                        let v = model.baseline(l, point, m);
                        let o = v.offset;
                        if o[0] * o[0] + o[1] * o[1] + o[2] * o[2] > max_len2 {
                            continue;
                        }
                        // Girshick et al. weight votes by depth squared (the pixel's world area).
                        let w = v.weight * p[2] * p[2];
                        if !push([p[0] + o[0], p[1] + o[1], p[2] + o[2]], w) {
                            return;
                        }
                    }
                }
            }
        }
    }
}

/// Mean-shift of every point from samples whose leaves are known (`leaves[i]` for `positions[i]`).
pub fn estimate_from_leaves<M: ForestModel + ?Sized>(
    model: &M,
    method: Method,
    positions: &[[f32; 3]],
    leaves: &[[u32; MAX_TREES]],
    priors: &[Option<Prior>; P],
    votes: &mut [Vote],
) -> [Option<PointEstimate>; P] {
    let mut out = [None; P];
    for (point, slot) in out.iter_mut().enumerate() {
        let prior = priors[point].as_ref();
        let n = collect_votes(
            model,
            method,
            point,
            positions.iter().copied(),
            leaves,
            prior,
            votes,
        );
        let pp = model.params(point);
        let h = match method {
            Method::Refined => pp.refined_bandwidth_m,
            Method::Baseline => pp.baseline_bandwidth_m,
        };
        *slot = mean_shift(&votes[..n], h, prior.map(|p| p.mean)).map(|m| PointEstimate {
            position: Point3::from(m.p),
            confidence: m.confidence,
        });
    }
    out
}

/// One frame: warm the clip's rows, sample `cfg.samples` kept pixels of `img` (clip `clip`, intrinsics `k`), descend
/// the trees, vote and mean-shift each point (with `priors[point]` where given). A point without any vote is `None`.
pub fn estimate<M: ForestModel + ?Sized, D: DepthImage + ?Sized>(
    model: &M,
    img: &D,
    k: &Intrinsics,
    clip: &Clip<'_>,
    cfg: &InferConfig,
    priors: &[Option<Prior>; P],
    ws: &mut Workspace,
) -> [Option<PointEstimate>; P] {
    sample_and_descend(model, img, k, clip, cfg, ws);
    reestimate(model, cfg.method, priors, ws)
}

/// [`estimate`] up to the leaves: warm the clip's rows, sample `cfg.samples` kept pixels and descend every tree,
/// into `ws` for [`reestimate`]; returns how many samples were drawn.
pub fn sample_and_descend<M: ForestModel + ?Sized, D: DepthImage + ?Sized>(
    model: &M,
    img: &D,
    k: &Intrinsics,
    clip: &Clip<'_>,
    cfg: &InferConfig,
    ws: &mut Workspace,
) -> usize {
    let want = cfg.samples.min(MAX_SAMPLES);
    img.warm_rows(clip.region.v0, clip.region.v1.min(k.height));
    let n = sample_pixels(img, k, clip, cfg.seed, &mut ws.samples[..want]);
    let trees = model.tree_count().min(MAX_TREES);
    descend_samples(
        model,
        trees,
        img,
        &ws.samples[..n],
        &mut ws.order,
        &mut ws.leaves[..n],
    );
    ws.last = n;
    n
}

/// One frame as the tracker reads it: [`estimate`] over the whole image above the bed `planes`
/// ([`Clip::over_image`]), through the height ceiling of `ceiling_m` over them when it is positive ([`Ceiling`]: what
/// lies higher, the arm's links, reads as no depth).
#[allow(clippy::too_many_arguments)] // estimate's arguments, with the planes and the ceiling instead of the clip
pub fn estimate_above<M: ForestModel + ?Sized, D: DepthImage + ?Sized, const N: usize>(
    model: &M,
    img: &D,
    k: &Intrinsics,
    planes: &[Plane; N],
    ceiling_m: f32,
    cfg: &InferConfig,
    priors: &[Option<Prior>; P],
    ws: &mut Workspace,
) -> [Option<PointEstimate>; P] {
    let clip = Clip::over_image(planes, k);
    if ceiling_m > 0.0 {
        estimate(
            model,
            &Ceiling::new(img, k, planes, ceiling_m),
            k,
            &clip,
            cfg,
            priors,
            ws,
        )
    } else {
        estimate(model, img, k, &clip, cfg, priors, ws)
    }
}

/// The six points again from the last [`estimate`]'s samples and leaves in `ws`, with `priors` (which may differ
/// from that estimate's): the votes and the mean-shift alone, no sampling or descent; [`estimate`]'s own last step.
pub fn reestimate<M: ForestModel + ?Sized>(
    model: &M,
    method: Method,
    priors: &[Option<Prior>; P],
    ws: &mut Workspace,
) -> [Option<PointEstimate>; P] {
    let n = ws.last;
    let mut out = [None; P];
    let (samples, leaves, votes) = (&ws.samples[..n], &ws.leaves[..n], &mut ws.votes);
    for (point, slot) in out.iter_mut().enumerate() {
        let prior = priors[point].as_ref();
        votes.clear();
        for_each_vote(
            model,
            method,
            point,
            samples.iter().map(|s| s.p),
            leaves,
            prior,
            |v| votes.push(v),
        );
        let pp = model.params(point);
        let h = match method {
            Method::Refined => pp.refined_bandwidth_m,
            Method::Baseline => pp.baseline_bandwidth_m,
        };
        *slot = votes.mean_shift(h, prior.map(|p| p.mean)).map(|m| PointEstimate {
            position: Point3::from(m.p),
            confidence: m.confidence,
        });
    }
    out
}
