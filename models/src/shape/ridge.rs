//! Trainer of the linear shape regression (`LINR`, [`supine_core::shape::linear`]): ridge regression from the 20
//! subspace coefficients to the 20 shape coefficients (σ units), with an unpenalised bias. The penalty is
//! `lambda` times the mean diagonal of the centred inputs' Gram matrix, so one grid of `lambda` serves any input
//! scale. Cost: one pass of 20x20 outer products over the samples and a 20x20 Cholesky solve.

use nalgebra::{DMatrix, DVector};
use supine_core::shape::linear::{LINEAR_BOUND, LINEAR_LEN};

use super::forest::DIM;

/// Ridge weights in the `LINR` layout (input `k`, output `j` at `20 k + j`; bias row last), or `None` when the
/// system is singular (fewer distinct samples than inputs and `lambda` = 0).
pub fn fit(x: &[[f32; DIM]], y: &[[f32; DIM]], lambda: f64) -> Option<Vec<f32>> {
    let n = x.len().min(y.len());
    if n == 0 {
        return None;
    }
    let mean = |v: &[[f32; DIM]]| {
        DVector::<f64>::from_fn(DIM, |k, _| {
            v[..n].iter().map(|r| r[k] as f64).sum::<f64>() / n as f64
        })
    };
    let (mx, my) = (mean(x), mean(y));
    let mut a = DMatrix::<f64>::zeros(DIM, DIM);
    let mut b = DMatrix::<f64>::zeros(DIM, DIM);
    for (xr, yr) in x[..n].iter().zip(&y[..n]) {
        let xc = DVector::<f64>::from_fn(DIM, |k, _| xr[k] as f64 - mx[k]);
        let yc = DVector::<f64>::from_fn(DIM, |k, _| yr[k] as f64 - my[k]);
        a += &xc * xc.transpose();
        b += &xc * yc.transpose();
    }
    // The floor keeps a positive `lambda` meaningful when the inputs do not vary (then only the bias is learnt).
    let pen = lambda * a.diagonal().mean().max(1e-9);
    for k in 0..DIM {
        a[(k, k)] += pen;
    }
    let w = a.cholesky()?.solve(&b);
    let bias = my - w.transpose() * mx;
    let mut out = vec![0.0f32; LINEAR_LEN];
    for k in 0..DIM {
        for j in 0..DIM {
            out[k * DIM + j] = w[(k, j)] as f32;
        }
    }
    for j in 0..DIM {
        out[DIM * DIM + j] = bias[j] as f32;
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// The prediction of weights `w` (the `LINR` layout) for inputs `c`, as core computes it (clamped to
/// ±[`LINEAR_BOUND`]).
pub fn predict(w: &[f32], c: &[f32; DIM]) -> [f32; DIM] {
    std::array::from_fn(|j| {
        (w[DIM * DIM + j] + (0..DIM).map(|k| w[k * DIM + j] * c[k]).sum::<f32>())
            .clamp(-LINEAR_BOUND, LINEAR_BOUND)
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
        let truth: Vec<f32> = (0..LINEAR_LEN).map(|_| rng.gen_range(-1.0..1.0)).collect();
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
        assert!(fit(&[], &[], 1e-2).is_none());
    }
}
