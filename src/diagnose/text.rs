//! The diagnosis as text for people at a shell.

use std::fmt::Write as _;

use super::{Diagnosis, RegionAxis};
use crate::diagnose::decision::FALSE_ALARM_RATE;

/// Render `d` as a short text report: where the gap lies, the verdict and
/// how far it shrinks, the candidates, corrected parameters, look-alikes.
pub fn render_diagnosis_text(d: &Diagnosis) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "sim-to-real diagnosis ({}; {})", d.kind, d.validation);
    let _ = writeln!(
        s,
        "  nominal model {}: fit NRMSE {:.4}, held-out NRMSE {:.4} (noise floor {:.4})",
        d.nominal.model, d.nominal.fit_nrmse, d.nominal.validation_nrmse, d.gap.noise_floor
    );
    if !d.gap.regions.is_empty() {
        let _ = writeln!(
            s,
            "  where the gap lies (share of the squared held-out residual):"
        );
        for r in d.gap.regions.iter().take(6) {
            let place = match (r.segment, r.voltage) {
                (Some(seg), _) => format!(" segment {seg}"),
                (None, Some(v)) => format!(" at {v:.0} V"),
                _ => String::new(),
            };
            let span = match r.axis {
                RegionAxis::Voltage => format!("{:.0}–{:.0} V", r.from, r.to),
                _ => format!("{:?} {:.4}–{:.4}", r.axis, r.from, r.to),
            };
            let _ = writeln!(
                s,
                "    {:>5.1} %  {:<18} {:<12}{place}, {span}",
                100.0 * r.share,
                r.channel,
                r.label,
            );
        }
    }
    let v = &d.verdict;
    if v.effect == "none" {
        // `confidence` of `none` is the smallest candidate p-value.
        let why = if v.confidence < FALSE_ALARM_RATE {
            "candidates shrink the held-out gap beyond what noise gives, but none explains it \
             (the warnings say why)"
        } else {
            "no candidate shrinks the held-out gap beyond what noise gives"
        };
        let _ = writeln!(
            s,
            "  verdict: none — {why} (confidence {:.3})",
            v.confidence
        );
    } else {
        let _ = writeln!(
            s,
            "  verdict: {} — held-out gap {:.4} → {:.4} (shrink {:.1} %, confidence {:.3})",
            v.effect,
            v.gap_before,
            v.gap_after,
            100.0 * v.shrink,
            v.confidence
        );
    }
    if let Some(best) = d.candidates.iter().find(|c| c.effect == v.effect) {
        for (key, p) in &best.params {
            let ci = p
                .ci95
                .map(|[a, b]| format!(" [{a:.4e}, {b:.4e}]"))
                .unwrap_or_default();
            let _ = writeln!(s, "    {key} = {:.4e} {}{ci}", p.value, p.unit);
        }
    }
    if !v.corrected_params.is_empty() {
        let _ = writeln!(s, "  nominal parameters once the effect is modelled:");
        for (key, c) in &v.corrected_params {
            let _ = writeln!(
                s,
                "    {key:<4} {:.5e} → {:.5e} {} (nominal fit biased {:+.2} %)",
                c.nominal,
                c.corrected,
                c.unit,
                100.0 * c.bias
            );
        }
    }
    for l in &v.look_alikes {
        let _ = writeln!(
            s,
            "  cannot tell apart from {} (held-out NRMSE {:.4}): {}",
            l.effect, l.validation_nrmse, l.plan
        );
    }
    let _ = writeln!(s, "  candidates (held-out NRMSE, shrink, score, p):");
    for c in &d.candidates {
        let _ = writeln!(
            s,
            "    {:<24} {:.4}  {:>6.1} %  {:>10.1}  {:.2e}",
            c.effect,
            c.validation_nrmse,
            100.0 * c.shrink,
            c.score,
            c.p_value
        );
    }
    for w in &d.warnings {
        let _ = writeln!(s, "  warning: {w}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn none_with_smallest_p(p: f64) -> Diagnosis {
        serde_json::from_value(serde_json::json!({
            "schema_version": "1.0",
            "kind": "dc_step",
            "nominal": {"model": "dc_nominal", "params": {}, "fit_nrmse": 0.0126,
                        "validation_nrmse": 0.013},
            "gap": {"regions": [], "noise_floor": 0.0092},
            "candidates": [],
            "verdict": {"effect": "none", "gap_before": 0.013, "gap_after": 0.013,
                        "shrink": 0.0, "confidence": p},
            "validation": "interleaved blocks",
            "warnings": []
        }))
        .expect("a diagnosis")
    }

    #[test]
    fn a_none_verdict_says_whether_candidates_were_significant_but_refused() {
        let refused = render_diagnosis_text(&none_with_smallest_p(7e-4));
        assert!(
            refused.contains(
                "verdict: none — candidates shrink the held-out gap beyond what \
                              noise gives, but none explains it (the warnings say why)"
            ),
            "{refused}"
        );
        let noise = render_diagnosis_text(&none_with_smallest_p(0.3));
        assert!(
            noise.contains(
                "verdict: none — no candidate shrinks the held-out gap beyond what \
                            noise gives (confidence 0.300)"
            ),
            "{noise}"
        );
    }
}
