//! The square-root form of a least-squares problem's linearisation.
//!
//! A Levenberg–Marquardt step only sees `JᵀJ` and `Jᵀr`, so a problem with
//! thousands of residuals can hand the solver an equivalent one with
//! `P + 1` rows: `R = Λ^½·Vᵀ` from `JᵀJ = V·Λ·Vᵀ`, `r' = [R⁻ᵀ·Jᵀr;
//! ‖r − projection‖]`. Both the DC output-error fit (fixed size) and the
//! DC diagnosis's augmented fits (any size) use it; the fixed-size caller
//! converts its 6×6 normal matrix, which keeps the arithmetic the same.

use nalgebra::{DMatrix, DVector};

/// The `P+1`-row problem equivalent to the normal equations `(jtj, g)` of
/// a residual vector with squared norm `r_norm_sq`. Directions with no
/// weight in `JᵀJ` (eigenvalue ≤ 1e-14 of the largest) get zero rows.
/// Returns `None` when any input is not finite (the eigen-decomposition
/// need not converge on a NaN): the caller refuses that point.
pub(crate) fn square_root_problem(
    jtj: DMatrix<f64>,
    g: &DVector<f64>,
    r_norm_sq: f64,
) -> Option<(DVector<f64>, DMatrix<f64>)> {
    if !jtj.iter().chain(g.iter()).all(|v| v.is_finite()) || !r_norm_sq.is_finite() {
        return None;
    }
    let np = jtj.ncols();
    let eig = jtj.symmetric_eigen();
    let largest = eig.eigenvalues.max();
    let mut rr = DVector::zeros(np + 1);
    let mut rj = DMatrix::zeros(np + 1, np);
    let mut explained = 0.0;
    for i in 0..np {
        let l = eig.eigenvalues[i];
        if l > 1e-14 * largest && l > 0.0 {
            let v = eig.eigenvectors.column(i);
            let root = l.sqrt();
            rj.row_mut(i).copy_from(&(v.transpose() * root));
            rr[i] = v.dot(g) / root;
            explained += rr[i] * rr[i];
        }
    }
    rr[np] = (r_norm_sq - explained).max(0.0).sqrt();
    Some((rr, rj))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reduced_problem_has_the_same_normal_equations_and_cost() {
        let jac =
            DMatrix::from_row_slice(5, 2, &[1.0, 0.5, 2.0, -1.0, 0.3, 0.7, -1.2, 0.1, 0.4, 2.2]);
        let r = DVector::from_row_slice(&[0.3, -0.2, 1.1, 0.05, -0.7]);
        let (rr, rj) =
            square_root_problem(jac.tr_mul(&jac), &jac.tr_mul(&r), r.norm_squared()).unwrap();
        assert_eq!((rr.len(), rj.nrows()), (3, 3));
        assert!((rj.tr_mul(&rj) - jac.tr_mul(&jac)).abs().max() < 1e-12);
        assert!((rj.tr_mul(&rr) - jac.tr_mul(&r)).abs().max() < 1e-12);
        assert!((rr.norm_squared() - r.norm_squared()).abs() < 1e-12);
    }

    #[test]
    fn a_non_finite_linearisation_is_refused() {
        let jtj = DMatrix::from_row_slice(1, 1, &[f64::NAN]);
        assert!(square_root_problem(jtj, &DVector::zeros(1), 1.0).is_none());
        let jtj = DMatrix::identity(1, 1);
        assert!(square_root_problem(jtj, &DVector::zeros(1), f64::INFINITY).is_none());
    }
}
