//! Small symmetric positive-definite solves (normal equations of Eq. 1, Eq. 7 and the ICP step) on the stack.
//!
//! An in-place Cholesky factorisation and two triangular solves, `N³/6 + N²` multiply-adds: about 2 k for the
//! 20x20 systems of the shape code, 100 for the 6x6 ICP system. Written out (rather than nalgebra's generic
//! decomposition) so the per-frame path stays on fixed arrays with a clear failure value and no panics.

// Triangular solves read best with explicit row and column indices.
#[allow(clippy::needless_range_loop)]
/// Solve `a x = b` for symmetric positive-definite `a` (only the lower triangle is read; `a` is overwritten by its
/// Cholesky factor, `b` by `x`). Returns false, leaving `b` unspecified, when `a` is not positive definite.
pub fn solve_spd<const N: usize>(a: &mut [[f32; N]; N], b: &mut [f32; N]) -> bool {
    for j in 0..N {
        let mut d = a[j][j];
        for k in 0..j {
            d -= a[j][k] * a[j][k];
        }
        if d.is_nan() || d <= 0.0 || !d.is_finite() {
            return false;
        }
        let d = libm::sqrtf(d);
        a[j][j] = d;
        for i in j + 1..N {
            let mut s = a[i][j];
            for k in 0..j {
                s -= a[i][k] * a[j][k];
            }
            a[i][j] = s / d;
        }
    }
    for i in 0..N {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i][k] * b[k];
        }
        b[i] = s / a[i][i];
    }
    for i in (0..N).rev() {
        let mut s = b[i];
        for k in i + 1..N {
            s -= a[k][i] * b[k];
        }
        b[i] = s / a[i][i];
    }
    b.iter().all(|x| x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_known_system_and_rejects_an_indefinite_one() {
        let m = [[4.0f32, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];
        let x = [0.3f32, -1.2, 2.0];
        let mut b = [0.0f32; 3];
        for i in 0..3 {
            b[i] = (0..3).map(|j| m[i][j] * x[j]).sum();
        }
        let mut a = m;
        assert!(solve_spd(&mut a, &mut b));
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-5, "{b:?}");
        }
        let mut bad = [[1.0f32, 2.0], [2.0, 1.0]];
        assert!(!solve_spd(&mut bad, &mut [1.0, 1.0]));
    }
}
