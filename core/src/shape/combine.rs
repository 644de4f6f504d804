//! Several frames' shape estimates made one (the init phase's multi-frame estimate): the per-coefficient mean (the
//! tracker's default) or the per-coefficient median, with which a frame whose salient points were grossly off (the
//! arm taken for a shoulder) moves the estimate no more than a frame slightly off (the shape evaluation's
//! multi-frame estimate). Caller-held estimates, no allocation. Cost: 20 sums, or 20 sorts of at most
//! [`MAX_SHAPE_FRAMES`] values; a few µs, once per init phase.

use crate::body_model::SHAPE_COMPONENTS;

/// Most frames one combination reads (the init phase keeps at most this many estimates).
pub const MAX_SHAPE_FRAMES: usize = 64;

/// How the init phase combines its frames' shape estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShapeCombine {
    /// The per-coefficient mean ([`mean_shape`]; the tracker's default).
    Mean,
    /// The per-coefficient median ([`median_shape`]).
    Median,
}

/// Per-coefficient median of `views` (the mean of the two middle values for an even count; only the first
/// [`MAX_SHAPE_FRAMES`] views are read); all zeros for no views.
pub fn median_shape(views: &[[f32; SHAPE_COMPONENTS]]) -> [f32; SHAPE_COMPONENTS] {
    let views = &views[..views.len().min(MAX_SHAPE_FRAMES)];
    let n = views.len();
    let mut out = [0.0; SHAPE_COMPONENTS];
    if n == 0 {
        return out;
    }
    let mut v = [0.0f32; MAX_SHAPE_FRAMES];
    for (c, o) in out.iter_mut().enumerate() {
        for (x, s) in v.iter_mut().zip(views) {
            *x = s[c];
        }
        let v = &mut v[..n];
        v.sort_unstable_by(f32::total_cmp);
        *o = if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        };
    }
    out
}

/// Per-coefficient mean of `views`; all zeros for no views.
pub fn mean_shape(views: &[[f32; SHAPE_COMPONENTS]]) -> [f32; SHAPE_COMPONENTS] {
    let mut sum = [0.0f32; SHAPE_COMPONENTS];
    for s in views {
        for (a, x) in sum.iter_mut().zip(s) {
            *a += x;
        }
    }
    let n = views.len().max(1) as f32;
    sum.map(|s| s / n)
}

impl ShapeCombine {
    /// The combination of `views` by this rule.
    pub fn of(self, views: &[[f32; SHAPE_COMPONENTS]]) -> [f32; SHAPE_COMPONENTS] {
        match self {
            ShapeCombine::Mean => mean_shape(views),
            ShapeCombine::Median => median_shape(views),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(x: f32) -> [f32; SHAPE_COMPONENTS] {
        core::array::from_fn(|c| x + c as f32)
    }

    #[test]
    fn the_median_ignores_one_gross_frame_and_the_mean_does_not() {
        let views = [view(1.0), view(100.0), view(2.0), view(3.0), view(-2.0)];
        let m = median_shape(&views);
        assert_eq!(m, view(2.0));
        assert_eq!(ShapeCombine::Median.of(&views), m);
        let mean = ShapeCombine::Mean.of(&views);
        assert_eq!(mean[0], 104.0 / 5.0);
        assert_eq!(mean[19], 104.0 / 5.0 + 19.0);
    }

    #[test]
    fn an_even_count_takes_the_middle_pair_and_none_gives_zeros() {
        assert_eq!(median_shape(&[view(1.0), view(4.0)]), view(2.5));
        assert_eq!(median_shape(&[view(7.0)]), view(7.0));
        assert_eq!(median_shape(&[]), [0.0; SHAPE_COMPONENTS]);
        assert_eq!(mean_shape(&[]), [0.0; SHAPE_COMPONENTS]);
    }

    #[test]
    fn views_past_the_capacity_are_not_read() {
        let mut views = [view(0.0); MAX_SHAPE_FRAMES + 5];
        for v in &mut views[MAX_SHAPE_FRAMES..] {
            *v = view(1000.0);
        }
        assert_eq!(median_shape(&views), view(0.0));
    }
}
