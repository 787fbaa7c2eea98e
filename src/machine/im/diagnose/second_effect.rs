//! A core loss beside the verdict. A real machine always has core loss,
//! and a record that shows another effect as well holds two: a
//! single-effect candidate then leaves much of the gap (the verdict says
//! so). When the verdict leaves more than twice the noise floor (only then:
//! a refit from the verdict's own optimum gains a little on every record,
//! which the held-out test calls significant), each other candidate is
//! refitted with a core loss beside it (`Rfe` in parallel with
//! the magnetising branch, [`ImAugmentation::iron`]), held out like every
//! candidate, and the pair that takes the gap furthest, significantly
//! beyond the verdict alone, is named in a warning with its `Rfe`. The
//! verdict itself stays a single effect, as the contract's vocabulary is.

use super::data::SweepSet;
use super::effects::{effect_name, ImAugmentation};
use super::fit::{fit, held_out};
use super::{blocks, held_out_nrmse, Evaluated};
use crate::diagnose::decision::held_out_sign_flip_test;
use crate::model::Effect;

/// A candidate refitted with a core loss beside it.
struct Pair<'a> {
    with: &'a Evaluated,
    validation_nrmse: f64,
    p_value: f64,
    rfe: f64,
}

/// The warning naming the best candidate-with-core-loss pair, where one
/// takes the held-out gap significantly beyond the verdict `w` alone;
/// `candidates` are the reportable ones, `folds` the diagnosis' own.
pub(super) fn core_loss_pair_warning(
    data: &SweepSet,
    folds: &[Vec<usize>],
    w: &Evaluated,
    candidates: &[&Evaluated],
) -> Option<String> {
    let all: Vec<usize> = (0..data.len()).collect();
    // The core loss's start: the iron-loss candidate's own fit, else a
    // typical Rfe of 25 Xm.
    let ln_rfe = candidates
        .iter()
        .find(|e| e.effect == Effect::IronLoss)
        .map_or(w.full.x[1] + 25f64.ln(), |e| e.full.x[4]);
    let others: Vec<&&Evaluated> = candidates
        .iter()
        .filter(|e| e.effect != Effect::IronLoss)
        .collect();
    let tried = others.len();
    let pairs = others.into_iter().filter_map(|e| {
        let model = ImAugmentation {
            iron: true,
            ..e.model
        };
        let mut start = e.full.x.clone();
        start.insert(model.iron_index(), ln_rfe);
        let full = fit(model, data, &all, &[start])?;
        let held = held_out(model, data, folds, &full.x, &[])?;
        let test = held_out_sign_flip_test(&w.blocks, &blocks(&held), tried);
        Some(Pair {
            with: e,
            validation_nrmse: held_out_nrmse(data, &held),
            p_value: test.p_value,
            rfe: full.x[model.iron_index()].exp(),
        })
    });
    // A core loss that is there: `Rfe` below a thousand times `Xm` (beyond,
    // the fit has run off to no core loss at all).
    let visible = |p: &Pair| p.rfe < 1e3 * w.full.x[1].exp();
    let best = pairs
        .filter(|p| visible(p) && p.validation_nrmse < w.validation_nrmse && p.p_value < 0.05)
        .min_by(|a, b| a.validation_nrmse.total_cmp(&b.validation_nrmse))?;
    Some(format!(
        "a second effect: {} with a core loss beside it (Rfe = {:.4e} ohm) takes the held-out \
         gap to {:.4}, beyond the verdict's {:.4} (p = {:.3}): the record likely holds both",
        effect_name(Some(best.with.effect)),
        best.rfe,
        best.validation_nrmse,
        w.validation_nrmse,
        best.p_value
    ))
}
