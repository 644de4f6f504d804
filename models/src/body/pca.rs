//! Principal component analysis of many meshes with the Gram-matrix trick.
//!
//! With N bodies of D = 3·rows coordinates (N ≈ 10³ ≪ D ≈ 4·10⁴), the D×D covariance is out of reach but the N×N
//! Gram matrix G = X Xᵀ of the centred data is cheap (one sgemm, N²·D flops): if G u = λ u then Xᵀ u / √λ is a
//! unit principal direction with variance λ/(N−1). The single-threaded, fixed-order matrix products keep the result
//! bit-identical for identical input.

use nalgebra::{DMatrix, SymmetricEigen};

/// A fitted PCA model.
#[derive(Clone, Debug)]
pub struct Pca {
    /// Mean of the data, length D.
    pub mean: Vec<f64>,
    /// Unit-norm, mutually orthogonal principal directions, `components[k]` of length D.
    pub components: Vec<Vec<f64>>,
    /// Standard deviation of each kept component's coefficient (√(λ/(N−1))).
    pub sigma: Vec<f64>,
    /// Every eigenvalue of the Gram matrix divided by N−1 (variances), descending.
    pub variances: Vec<f64>,
}

impl Pca {
    /// Fit `k` components to `rows` (each of the same length D, at least two rows).
    pub fn fit(rows: &[Vec<f32>], k: usize) -> Pca {
        let n = rows.len();
        let d = rows[0].len();
        assert!(n >= 2 && k < n, "PCA needs at least k+1 rows");
        let mut mean = vec![0.0f64; d];
        for r in rows {
            for (m, &x) in mean.iter_mut().zip(r) {
                *m += x as f64;
            }
        }
        mean.iter_mut().for_each(|m| *m /= n as f64);
        // Centred data, N × D, f32 for the big product (relative error ~1e-6, far below the 0.1 mm we care about).
        let x = DMatrix::<f32>::from_fn(n, d, |i, j| (rows[i][j] as f64 - mean[j]) as f32);
        let g32 = &x * x.transpose();
        let g = g32.map(|v| v as f64);
        let eig = SymmetricEigen::new(g);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]).then(a.cmp(&b)));
        let variances: Vec<f64> = order
            .iter()
            .map(|&i| eig.eigenvalues[i].max(0.0) / (n - 1) as f64)
            .collect();
        let mut u = DMatrix::<f32>::zeros(n, k);
        for (c, &i) in order.iter().take(k).enumerate() {
            let l = eig.eigenvalues[i].max(1e-30).sqrt();
            for r in 0..n {
                u[(r, c)] = (eig.eigenvectors[(r, i)] / l) as f32;
            }
        }
        let v = x.transpose() * u; // D × k
        let mut components = Vec::with_capacity(k);
        for c in 0..k {
            let mut col: Vec<f64> = v.column(c).iter().map(|&x| x as f64).collect();
            // Re-normalise in f64 (the f32 product leaves ~1e-6 norm error).
            let norm = col.iter().map(|x| x * x).sum::<f64>().sqrt();
            col.iter_mut().for_each(|x| *x /= norm);
            components.push(col);
        }
        // Gram–Schmidt once in f64 so the stored basis is orthonormal to ~1e-12.
        for c in 0..k {
            for p in 0..c {
                let dot: f64 = components[c].iter().zip(&components[p]).map(|(a, b)| a * b).sum();
                let prev = components[p].clone();
                components[c]
                    .iter_mut()
                    .zip(&prev)
                    .for_each(|(a, b)| *a -= dot * b);
            }
            let norm = components[c].iter().map(|x| x * x).sum::<f64>().sqrt();
            components[c].iter_mut().for_each(|x| *x /= norm);
        }
        let sigma = variances.iter().take(k).map(|v| v.sqrt()).collect();
        Pca {
            mean,
            components,
            sigma,
            variances,
        }
    }

    /// Fraction of the total variance in the first `k` components.
    pub fn explained(&self, k: usize) -> f64 {
        let total: f64 = self.variances.iter().sum();
        self.variances.iter().take(k).sum::<f64>() / total
    }

    /// Coefficients of `row` (projection of `row − mean` on the components).
    pub fn project(&self, row: &[f32]) -> Vec<f64> {
        self.components
            .iter()
            .map(|c| {
                c.iter()
                    .zip(row)
                    .zip(&self.mean)
                    .map(|((a, &x), m)| a * (x as f64 - m))
                    .sum()
            })
            .collect()
    }

    /// `mean + Σ s_k · component_k`.
    pub fn reconstruct(&self, s: &[f64]) -> Vec<f64> {
        let mut out = self.mean.clone();
        for (c, &sk) in self.components.iter().zip(s) {
            out.iter_mut().zip(c).for_each(|(o, a)| *o += sk * a);
        }
        out
    }

    /// Flip the sign of component `k` (and nothing else: coefficients flip with it).
    pub fn flip(&mut self, k: usize) {
        self.components[k].iter_mut().for_each(|x| *x = -*x);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;
    use rand_chacha::ChaCha8Rng;
    use rand_chacha::rand_core::SeedableRng;

    #[test]
    fn recovers_a_low_rank_model_exactly() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let d = 60;
        let dirs: Vec<Vec<f64>> = (0..3)
            .map(|_| (0..d).map(|_| rng.gen_range(-1.0..1.0)).collect())
            .collect();
        let rows: Vec<Vec<f32>> = (0..40)
            .map(|_| {
                let s: Vec<f64> = (0..3)
                    .map(|i| rng.gen_range(-1.0..1.0) * (3 - i) as f64)
                    .collect();
                (0..d)
                    .map(|j| (1.0 + (0..3).map(|i| s[i] * dirs[i][j]).sum::<f64>()) as f32)
                    .collect()
            })
            .collect();
        let pca = Pca::fit(&rows, 5);
        assert!(pca.explained(3) > 0.999_999, "{}", pca.explained(3));
        for c in 0..5 {
            for p in 0..5 {
                let dot: f64 = pca.components[c]
                    .iter()
                    .zip(&pca.components[p])
                    .map(|(a, b)| a * b)
                    .sum();
                assert!(
                    (dot - if c == p { 1.0 } else { 0.0 }).abs() < 1e-9,
                    "({c},{p}) {dot}"
                );
            }
        }
        for r in &rows {
            let rec = pca.reconstruct(&pca.project(r)[..3]);
            let err = rec
                .iter()
                .zip(r)
                .map(|(a, &b)| (a - b as f64).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-4, "{err}");
        }
        assert!(pca.sigma[0] >= pca.sigma[1] && pca.sigma[1] >= pca.sigma[2]);
    }
}
