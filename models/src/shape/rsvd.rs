//! Randomised SVD (Halko, Martinsson and Tropp 2011, the scheme RedSVD implements) of a centred image matrix: the
//! leading right singular vectors are the eigen-images of paper §3.2.
//!
//! `X` is n images × P pixels. A Gaussian test matrix `Ω` (P × (k + p)) gives `Y = X Ω`, refined by `q` power
//! iterations `Y ← X (Xᵀ Y)` with re-orthonormalisation; `Q = orth(Y)`, `B = Qᵀ X` ((k + p) × P) and the small
//! eigen-decomposition of `B Bᵀ` gives the right singular vectors `V = Bᵀ U Σ⁻¹`. Cost: `(2q + 2) · n · P · (k + p)`
//! multiply-adds (a few seconds for 2 k images of 9 k pixels).

use nalgebra::{DMatrix, SymmetricEigen};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// The leading `k` right singular vectors (columns of a P × k matrix) and singular values of `x`.
pub fn randomized_svd(
    x: &DMatrix<f32>,
    k: usize,
    oversample: usize,
    power_iters: usize,
    seed: u64,
) -> (DMatrix<f32>, Vec<f32>) {
    let l = (k + oversample).min(x.nrows()).min(x.ncols());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let omega = DMatrix::<f32>::from_fn(x.ncols(), l, |_, _| StandardNormal.sample(&mut rng));
    let mut y = x * omega;
    for _ in 0..power_iters {
        y = y.qr().q();
        let z = (x.transpose() * &y).qr().q();
        y = x * z;
    }
    let q = y.qr().q();
    let b = q.transpose() * x; // l × P
    let bbt = (&b * b.transpose()).map(|v| v as f64);
    let eig = SymmetricEigen::new(bbt);
    let mut order: Vec<usize> = (0..l).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
    let mut v = DMatrix::<f32>::zeros(x.ncols(), k.min(l));
    let mut s = Vec::new();
    for (c, &i) in order.iter().take(k.min(l)).enumerate() {
        let sv = eig.eigenvalues[i].max(0.0).sqrt();
        s.push(sv as f32);
        let u = eig.eigenvectors.column(i).map(|x| x as f32);
        let col = b.transpose() * u / (sv.max(1e-12) as f32);
        v.set_column(c, &col);
    }
    (v, s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_the_leading_directions_of_a_low_rank_matrix() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (n, p, r) = (120, 300, 5);
        let a = DMatrix::<f32>::from_fn(n, r, |_, _| StandardNormal.sample(&mut rng));
        let b = DMatrix::<f32>::from_fn(r, p, |_, _| StandardNormal.sample(&mut rng));
        let scales =
            DMatrix::<f32>::from_diagonal(&nalgebra::DVector::from_vec(vec![50.0, 20.0, 10.0, 5.0, 2.0]));
        let x = &a * scales * &b;
        let (v, s) = randomized_svd(&x, 5, 10, 2, 1);
        let exact = x.clone().svd(false, true);
        let mut sv: Vec<f32> = exact.singular_values.iter().copied().collect();
        sv.sort_by(|a, b| b.total_cmp(a));
        for i in 0..5 {
            assert!(
                (s[i] - sv[i]).abs() / sv[i] < 1e-3,
                "singular value {i}: {} vs {}",
                s[i],
                sv[i]
            );
        }
        // Orthonormal columns spanning X's row space: X V Vᵀ = X.
        let recon = &x * &v * v.transpose();
        assert!((recon - &x).norm() / x.norm() < 1e-3);
    }
}
