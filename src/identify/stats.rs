//! Small statistics helpers: linear least squares with covariance,
//! Student-t quantiles for confidence intervals, and the median.

use nalgebra::{DMatrix, DVector};

/// The 97.5 % quantile of Student's t with `dof` degrees of freedom: the
/// factor of a two-sided 95 % interval. Exact at every `dof` (a table that
/// switches to the normal 1.96 above 30 made intervals 3.9 % too narrow at
/// 31 degrees of freedom); infinite without a spare degree of freedom.
pub fn t975(dof: usize) -> f64 {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    if dof == 0 {
        return f64::INFINITY;
    }
    StudentsT::new(0.0, 1.0, dof as f64).map_or(f64::INFINITY, |d| d.inverse_cdf(0.975))
}

/// The median of `values` (the upper one of an even count), reordering
/// them (a selection, not a sort: linear time); `None` when there are
/// none. The value a sort by `total_cmp` puts at `len/2`, bit for bit.
pub fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mid = values.len() / 2;
    Some(*values.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// A least-squares solution of `A·x ≈ b`.
#[derive(Debug, Clone, PartialEq)]
pub struct LeastSquares {
    /// The solution.
    pub x: DVector<f64>,
    /// Half-widths of the 95 % intervals (`None` without spare rows).
    pub half_width: Option<DVector<f64>>,
}

/// Solve `A·x ≈ b` (rows ≥ columns, full column rank) by SVD; intervals
/// from the residual variance when there are more rows than columns;
/// `None` for a rank-deficient or non-finite system.
pub fn least_squares(a: &DMatrix<f64>, b: &DVector<f64>) -> Option<LeastSquares> {
    let (rows, cols) = a.shape();
    // The SVD panics on a NaN ("Singular value was NaN"): data that made
    // the system non-finite has no solution.
    if rows < cols || !a.iter().chain(b.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let svd = a.clone().svd(true, true);
    let smax = svd.singular_values.max();
    if svd.singular_values.min() <= smax * 1e-12 {
        return None;
    }
    let x = svd.solve(b, 0.0).ok()?;
    let dof = rows - cols;
    let half_width = (dof > 0).then(|| {
        let r = a * &x - b;
        let s2 = r.norm_squared() / dof as f64;
        let ata_inv = (a.transpose() * a)
            .try_inverse()
            .unwrap_or_else(|| DMatrix::from_element(cols, cols, f64::NAN));
        DVector::from_fn(cols, |i, _| t975(dof) * (s2 * ata_inv[(i, i)]).sqrt())
    });
    Some(LeastSquares { x, half_width })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_system_has_no_interval_and_noisy_one_covers_truth() {
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 3.0, 4.0]);
        let b = DVector::from_vec(vec![5.0, 11.0]);
        let ls = least_squares(&a, &b).unwrap();
        assert!((ls.x[0] - 1.0).abs() < 1e-12 && (ls.x[1] - 2.0).abs() < 1e-12);
        assert!(ls.half_width.is_none());
        // y = 2 + 0.5·x with small alternating errors.
        let xs: Vec<f64> = (0..10).map(f64::from).collect();
        let a = DMatrix::from_fn(10, 2, |r, c| if c == 0 { 1.0 } else { xs[r] });
        let b = DVector::from_fn(10, |r, _| {
            2.0 + 0.5 * xs[r] + if r % 2 == 0 { 0.01 } else { -0.01 }
        });
        let ls = least_squares(&a, &b).unwrap();
        let hw = ls.half_width.unwrap();
        assert!((ls.x[1] - 0.5).abs() < hw[1] && hw[1] < 0.01);
    }

    #[test]
    fn a_non_finite_system_is_refused_not_a_panic() {
        let a = DMatrix::from_row_slice(3, 2, &[1.0, 2.0, f64::NAN, 4.0, 3.0, 7.0]);
        assert!(least_squares(&a, &DVector::from_vec(vec![1.0, 2.0, 3.0])).is_none());
        let a = DMatrix::from_row_slice(3, 2, &[1.0, 2.0, 2.0, 4.0, 3.0, 7.0]);
        let b = DVector::from_vec(vec![1.0, f64::INFINITY, 3.0]);
        assert!(least_squares(&a, &b).is_none());
    }

    #[test]
    fn t_quantiles_are_exact_at_every_degree_of_freedom() {
        // Reference values of the 97.5 % quantile (published tables and
        // R's qt(0.975, dof)), not computed with the code under test.
        for (dof, exact) in [
            (1, 12.706_205),
            (10, 2.228_139),
            (31, 2.039_513),
            (54, 2.004_879),
            (1000, 1.962_339),
        ] {
            let t = t975(dof);
            assert!((t - exact).abs() < 1e-5, "t975({dof}) = {t}, exact {exact}");
        }
        assert!(t975(0).is_infinite());
    }

    #[test]
    fn rank_deficient_is_refused() {
        let a = DMatrix::from_row_slice(3, 2, &[1.0, 2.0, 2.0, 4.0, 3.0, 6.0]);
        assert!(least_squares(&a, &DVector::from_vec(vec![1.0, 2.0, 3.0])).is_none());
    }
}
