//! Trainer of the linear shape regression (`LINP`/`LINR`, [`supine_core::shape::linear`]): ridge regression from
//! the regression inputs (the 20 subspace coefficients, and for `LINP` the salient points' distances) to the 20
//! shape coefficients (σ units), with an unpenalised bias. The penalty is `lambda` times the mean diagonal of the
//! centred inputs' Gram matrix, so one grid of `lambda` serves any common input scale; inputs of mixed scales (the
//! coefficients and the distances of `LINP`) need smaller `lambda` for the small ones, hence the trainer's grid
//! down to 1e-6. Cost: one pass of N x N outer products over the samples and an N x N Cholesky solve.

use nalgebra::{DMatrix, DVector};
use supine_core::shape::linear::LINEAR_BOUND;

use super::forest::DIM;

/// Ridge weights for `N` inputs in the core layout (input `k`, output `j` at `20 k + j`; bias row last:
/// `(N + 1) · 20` values), or `None` when the system is singular (fewer distinct samples than inputs and `lambda`
/// = 0).
pub fn fit<const N: usize>(x: &[[f32; N]], y: &[[f32; DIM]], lambda: f64) -> Option<Vec<f32>> {
    let n = x.len().min(y.len());
    if n == 0 {
        return None;
    }
    let avg = |v: &dyn Fn(usize) -> f64| (0..n).map(v).sum::<f64>() / n as f64;
    let mx = DVector::<f64>::from_fn(N, |k, _| avg(&|r| x[r][k] as f64));
    let my = DVector::<f64>::from_fn(DIM, |k, _| avg(&|r| y[r][k] as f64));
    let mut a = DMatrix::<f64>::zeros(N, N);
    let mut b = DMatrix::<f64>::zeros(N, DIM);
    for (xr, yr) in x[..n].iter().zip(&y[..n]) {
        let xc = DVector::<f64>::from_fn(N, |k, _| xr[k] as f64 - mx[k]);
        let yc = DVector::<f64>::from_fn(DIM, |k, _| yr[k] as f64 - my[k]);
        a += &xc * xc.transpose();
        b += &xc * yc.transpose();
    }
    // The floor keeps a positive `lambda` meaningful when the inputs do not vary (then only the bias is learnt).
    let pen = lambda * a.diagonal().mean().max(1e-9);
    for k in 0..N {
        a[(k, k)] += pen;
    }
    let w = a.cholesky()?.solve(&b);
    let bias = my - w.transpose() * mx;
    let mut out = vec![0.0f32; (N + 1) * DIM];
    for k in 0..N {
        for j in 0..DIM {
            out[k * DIM + j] = w[(k, j)] as f32;
        }
    }
    for j in 0..DIM {
        out[N * DIM + j] = bias[j] as f32;
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// The prediction of weights `w` (the layout of [`fit`]) for inputs `x`, as core computes it (clamped to
/// ±[`LINEAR_BOUND`]).
pub fn predict<const N: usize>(w: &[f32], x: &[f32; N]) -> [f32; DIM] {
    std::array::from_fn(|j| {
        let mut o = w[N * DIM + j];
        for (k, xk) in x.iter().enumerate() {
            o += w[k * DIM + j] * xk;
        }
        o.clamp(-LINEAR_BOUND, LINEAR_BOUND)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn recovers_a_known_affine_map() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let truth: Vec<f32> = (0..(DIM + 1) * DIM).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let x: Vec<[f32; DIM]> = (0..200)
            .map(|_| std::array::from_fn(|_| rng.gen_range(-0.05..0.05)))
            .collect();
        let y: Vec<[f32; DIM]> = x.iter().map(|c| predict(&truth, c)).collect();
        let w = fit(&x, &y, 0.0).unwrap();
        for (a, b) in w.iter().zip(&truth) {
            assert!((a - b).abs() < 1e-3, "{a} vs {b}");
        }
    }

    #[test]
    fn too_few_samples_without_penalty_is_refused() {
        let x = vec![[1.0f32; DIM]; 3];
        let y = vec![[0.5f32; DIM]; 3];
        assert!(fit(&x, &y, 0.0).is_none());
        assert!(fit(&x, &y, 1e-2).is_some());
        assert!(fit::<DIM>(&[], &[], 1e-2).is_none());
    }
}
