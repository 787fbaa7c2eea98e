//! Which candidate is the verdict, from the candidates in score order and
//! what the tests and the refusal rules said of each.
//!
//! The first candidate that passes the held-out tests and is not refused
//! is the verdict, with one exception. A candidate refused for explaining
//! only part of the gap still outranks the ones below it: a lower-ranked
//! one is the verdict only where it beats it on the held-out blocks. Else
//! the record shows two effects (a plant's and its sensors', say) that
//! each take part of the gap, and naming the lower-ranked one would be a
//! guess between them: the verdict is `none`, with a warning naming both
//! and the test plan that separates them.

use super::candidates::separating_plan;
use super::effect_name;
use crate::diagnose::decision::held_out_test;
use crate::model::Effect;

/// Why a candidate that passes the tests is not the verdict.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Refusal {
    /// The reason, to follow "shrinks the held-out gap".
    pub why: String,
    /// Refused for explaining only part of the gap (its parameters are
    /// physical and determined): it then outranks the candidates below.
    pub partial: bool,
}

/// One candidate, in score order, as the decision sees it.
pub(super) struct Ranked<'a> {
    /// The candidate's effect.
    pub effect: Effect,
    /// Its squared held-out residual per block (the nominal's blocks).
    pub blocks: &'a [f64],
    /// It passes the held-out and in-sample tests with a positive score.
    pub passes: bool,
    /// Why it is not the verdict, where a rule refuses it.
    pub refusal: Option<Refusal>,
}

/// The index of the verdict in `ranked`, if any; a warning for every
/// candidate that passes the tests and is not the verdict, and for a
/// verdict left out for a higher-ranked partial one.
pub(super) fn choose(ranked: &[Ranked], warnings: &mut Vec<String>) -> Option<usize> {
    let mut winner = None;
    let mut decided = false;
    let mut outranking: Option<&Ranked> = None;
    for (n, c) in ranked.iter().enumerate().filter(|(_, c)| c.passes) {
        match &c.refusal {
            None if !decided => {
                decided = true;
                let tie =
                    outranking.filter(|o| !held_out_test(o.blocks, c.blocks, 1).significant());
                match tie {
                    Some(o) => warnings.push(format!(
                        "{}: explains the gap, but no better on the held-out blocks than {}, \
                         which scores higher and explains part of it: the record likely holds \
                         both, and neither is taken as the verdict; to separate them: {}",
                        effect_name(c.effect),
                        effect_name(o.effect),
                        separating_plan(c.effect, o.effect)
                    )),
                    None => winner = Some(n),
                }
            }
            None => {}
            Some(r) => {
                if !decided && outranking.is_none() && r.partial {
                    outranking = Some(c);
                }
                warnings.push(format!(
                    "{}: shrinks the held-out gap {}; not taken as the verdict",
                    effect_name(c.effect),
                    r.why
                ));
            }
        }
    }
    winner
}

#[cfg(test)]
mod tests {
    use super::*;

    fn partial() -> Option<Refusal> {
        Some(Refusal {
            why: "by 49 % only of its excess over the noise floor".into(),
            partial: true,
        })
    }

    fn ranked(effect: Effect, blocks: &[f64], refusal: Option<Refusal>) -> Ranked<'_> {
        Ranked {
            effect,
            blocks,
            passes: true,
            refusal,
        }
    }

    /// Squared held-out residuals of 40 blocks: `level` plus a spread
    /// every candidate shares, plus `jitter` times a spread of its own
    /// (mean zero), so that a paired test sees a difference of levels
    /// against a known scatter.
    fn blocks(level: f64, jitter: f64) -> Vec<f64> {
        (0..40)
            .map(|b| {
                let shared = 0.2 * ((b * 7 % 11) as f64 - 5.0) / 5.0;
                let own = jitter * (b as f64 * 1.3).sin();
                level + shared + own
            })
            .collect()
    }

    #[test]
    fn the_first_candidate_that_passes_and_is_not_refused_is_the_verdict() {
        let (a, b) = (blocks(1.0, 0.0), blocks(0.9, 0.05));
        let mut not_passing = ranked(Effect::BrushDrop, &a, None);
        not_passing.passes = false;
        let unphysical = Some(Refusal {
            why: "only with an unphysical sign of its parameter".into(),
            partial: false,
        });
        let list = [
            not_passing,
            ranked(Effect::ThermalDrift, &a, unphysical),
            ranked(Effect::SensorLag, &b, None),
            ranked(Effect::ShaftCompliance, &b, partial()),
        ];
        let mut warnings = Vec::new();
        assert_eq!(choose(&list, &mut warnings), Some(2));
        assert_eq!(warnings.len(), 2, "{warnings:?}");
        assert!(warnings[0].starts_with("thermal_drift: shrinks the held-out gap only with"));
    }

    /// The verdict and warnings of a Coulomb candidate refused as
    /// partial, ranked above a sensor lag that explains the gap with
    /// held-out blocks at `lag_level` (the Coulomb's at 1).
    fn coulomb_above_a_lag(lag_level: f64) -> (Option<usize>, Vec<String>) {
        let (coulomb, lag) = (blocks(1.0, 0.0), blocks(lag_level, 0.05));
        let list = [
            ranked(Effect::CoulombFriction, &coulomb, partial()),
            ranked(Effect::SensorLag, &lag, None),
        ];
        let mut warnings = Vec::new();
        (choose(&list, &mut warnings), warnings)
    }

    #[test]
    fn a_verdict_no_better_than_a_higher_ranked_partial_candidate_is_none_naming_both() {
        // The lag explains a little more of the gap than the Coulomb
        // candidate, no better block by block.
        let (verdict, warnings) = coulomb_above_a_lag(0.99);
        assert_eq!(verdict, None);
        let w = warnings.last().expect("a warning");
        assert!(
            w.starts_with("sensor_lag: explains the gap, but no better")
                && w.contains("than coulomb_friction"),
            "{w}"
        );
    }

    #[test]
    fn a_verdict_that_beats_the_partial_candidate_on_the_blocks_stands() {
        assert_eq!(coulomb_above_a_lag(0.9).0, Some(1));
    }

    #[test]
    fn a_candidate_refused_for_another_reason_outranks_nothing() {
        let (a, b) = (blocks(1.0, 0.0), blocks(0.99, 0.05));
        let undetermined = Some(Refusal {
            why: "with a parameter the record does not determine".into(),
            partial: false,
        });
        let list = [
            ranked(Effect::CoulombFriction, &a, undetermined),
            ranked(Effect::SensorLag, &b, None),
        ];
        assert_eq!(choose(&list, &mut Vec::new()), Some(1));
    }
}
