//! Identifiability of the equivalent circuit from the Jacobian of a fit.
//!
//! With `J` the whitened Jacobian with respect to the logarithms of the
//! free elements and `J = U·Σ·Vᵀ`, the combination `v_kᵀ·log θ` has the
//! standard error `s/σ_k` (`s²` the residual variance). A direction whose
//! relative singular value `σ_k/σ_max` is at round-off level is a family of
//! circuits with the same terminal behaviour (structural); one whose
//! standard error exceeds a limit is merely not pinned by these data
//! (practical). The direction's components name the elements that move
//! together along it.

use nalgebra::{DMatrix, DVector};

use crate::model::ImParam;

/// Relative singular value below which a direction is taken as an exact
/// family (the Jacobian is computed analytically, so a true null direction
/// sits at round-off, ~1e-15).
pub const STRUCTURAL_LIMIT: f64 = 1e-8;

/// Largest standard error of a weak direction (log scale) stated as a
/// number; beyond it the direction is said to be undetermined.
const LARGEST_STATED_STD: f64 = 10.0;

/// One poorly determined direction in log-parameter space.
#[derive(Debug, Clone, PartialEq)]
pub struct WeakDirection {
    /// Unit vector over the free elements (log scale), largest first.
    pub components: Vec<(ImParam, f64)>,
    /// `σ_k/σ_max`.
    pub relative_singular_value: f64,
    /// Standard error of the combination (log scale: 0.1 ≈ 10 %).
    pub relative_std: f64,
    /// Whether it is an exact family (no data of this kind can pin it).
    pub structural: bool,
}

impl WeakDirection {
    /// Whether `param` moves along the direction with at least `share` of
    /// the unit vector.
    pub fn moves(&self, param: ImParam, share: f64) -> bool {
        self.components
            .iter()
            .any(|&(p, v)| p == param && v.abs() >= share)
    }

    /// e.g. `Xs −0.71, Xr +0.52, Xm −0.40 (structural)`.
    pub fn describe(&self) -> String {
        let parts: Vec<String> = self
            .components
            .iter()
            .filter(|(_, v)| v.abs() >= 0.05)
            .map(|(p, v)| format!("{p} {v:+.2}"))
            .collect();
        let kind = if self.structural {
            "a family of equivalent circuits: no terminal data pin it".to_string()
        } else if self.relative_std.is_nan() || self.relative_std > LARGEST_STATED_STD {
            // A log-scale error beyond this is a factor of e¹⁰ either way:
            // its digits say nothing a person can use.
            format!(
                "relative standard error above {:.0} %: the data do not determine it",
                100.0 * LARGEST_STATED_STD
            )
        } else {
            format!("relative standard error {:.0} %", 100.0 * self.relative_std)
        };
        format!("{} ({kind})", parts.join(", "))
    }
}

/// What the data determine.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Identifiability {
    /// Weak directions of the fit with every element free.
    pub weak_before_convention: Vec<WeakDirection>,
    /// The convention imposed, if any.
    pub convention: Option<String>,
    /// Weak directions left in the reported fit.
    pub weak: Vec<WeakDirection>,
    /// Elements the reported fit does not determine (no interval given).
    pub unidentifiable: Vec<ImParam>,
    /// Elements the data drive towards zero (below 10⁻³ of the
    /// locked-rotor impedance): the model has more freedom than the data.
    pub at_bound: Vec<ImParam>,
}

/// Weak directions from the singular values `sv`, right singular vectors
/// `v_t` (rows) and residual variance `s2`, over the elements `free`.
pub fn weak_directions(
    parts: &(DVector<f64>, DMatrix<f64>, f64),
    free: &[ImParam],
    practical_limit: f64,
) -> Vec<WeakDirection> {
    let (sv, v_t, s2) = parts;
    let smax = sv.max();
    let mut out = Vec::new();
    for k in 0..sv.len() {
        let rel = if smax > 0.0 { sv[k] / smax } else { 0.0 };
        let std = if sv[k] > 0.0 {
            s2.sqrt() / sv[k]
        } else {
            f64::INFINITY
        };
        let structural = rel < STRUCTURAL_LIMIT;
        if structural || std > practical_limit {
            let mut components: Vec<(ImParam, f64)> = free
                .iter()
                .enumerate()
                .map(|(j, &p)| (p, v_t[(k, j)]))
                .collect();
            components.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
            // Sign convention: the largest component positive.
            if components.first().is_some_and(|c| c.1 < 0.0) {
                for c in &mut components {
                    c.1 = -c.1;
                }
            }
            out.push(WeakDirection {
                components,
                relative_singular_value: rel,
                relative_std: std,
                structural,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A direction the data do not see at all is said to be undetermined,
    /// not given an error of 90 digits (a record whose input power reads
    /// half of what the machine took did that).
    #[test]
    fn an_unbounded_error_is_not_printed_as_a_number() {
        let weak = |relative_std: f64| WeakDirection {
            components: vec![(ImParam::Rs, 1.0)],
            relative_singular_value: 1e-30,
            relative_std,
            structural: false,
        };
        assert_eq!(
            weak(0.8).describe(),
            "Rs +1.00 (relative standard error 80 %)"
        );
        for huge in [1.4e88, f64::INFINITY, f64::NAN] {
            assert_eq!(
                weak(huge).describe(),
                "Rs +1.00 (relative standard error above 1000 %: the data do not determine it)"
            );
        }
    }
}
