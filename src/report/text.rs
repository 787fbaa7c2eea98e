//! The identification as a text table for people.

use std::fmt::Write;

use crate::identify::Identification;
use crate::model::DcParams;

fn param_value(truth: Option<&DcParams>, key: &str) -> Option<f64> {
    let t = truth?;
    Some(match key {
        "K" => t.k,
        "Ra" => t.ra,
        "La" => t.la,
        "J" => t.j,
        "f" => t.f,
        "Tst" => t.tst,
        _ => return None,
    })
}

/// Render `id` as text. With `truth` (the simulated rig's motor) each
/// parameter also shows the true value and the relative error.
pub fn render_text(id: &Identification, truth: Option<&DcParams>) -> String {
    let mut out = String::new();
    let r = &id.report;
    let _ = writeln!(
        out,
        "identification ({}), contract version {}",
        r.kind, r.schema_version
    );
    if !id.levels.is_empty() {
        let _ = writeln!(out, "\nsettled levels (mean of each step's settled tail):");
        let _ = writeln!(
            out,
            "  {:>3}  {:<24} {:>9} {:>9} {:>10} {:>7}",
            "seg", "step", "U [V]", "i [A]", "ω [rad/s]", "samples"
        );
        for l in &id.levels {
            let _ = writeln!(
                out,
                "  {:>3}  {:<24} {:>9.3} {:>9.5} {:>10.3} {:>7}",
                l.segment, l.label, l.voltage, l.current, l.speed, l.samples
            );
        }
    }
    for (name, m) in &r.methods {
        let _ = writeln!(out, "\nmethod {name}:");
        if !m.applies {
            let _ = writeln!(
                out,
                "  does not apply: {}",
                m.reason.as_deref().unwrap_or("no reason given")
            );
            continue;
        }
        if let Some(params) = &m.params {
            for (key, p) in params {
                let ci = p.ci95.map_or("no interval".to_string(), |[lo, hi]| {
                    format!("95 % CI [{lo:.5e}, {hi:.5e}]")
                });
                let _ = write!(out, "  {key:<4} {:>14.6e} {:<10} {ci}", p.value, p.unit);
                if let Some(t) = param_value(truth, key) {
                    let _ = write!(
                        out,
                        "   simulated {t:.6e} ({:+.3} %)",
                        100.0 * (p.value - t) / t
                    );
                }
                let _ = writeln!(out);
            }
        }
        if name == "output_error" {
            if let Some(fit) = &id.output_error {
                out.push_str(&fit.render_details());
            }
        }
        match m.validation_nrmse {
            Some(v) => {
                let _ = writeln!(out, "  validation NRMSE on held-out segments: {v:.4}");
            }
            None => {
                let _ = writeln!(out, "  validation NRMSE: not computed (too few segments)");
            }
        }
    }
    if name_of_static(r) {
        let _ = writeln!(
            out,
            "  (the steady-state model has no La or J: its NRMSE includes every transient it cannot follow)"
        );
    }
    let _ = writeln!(
        out,
        "\nbest: {}",
        r.best.as_deref().unwrap_or("none (no method applies)")
    );
    if !r.warnings.is_empty() {
        let _ = writeln!(out, "\nwarnings:");
        for w in &r.warnings {
            let _ = writeln!(out, "  - {w}");
        }
    }
    out
}

fn name_of_static(r: &crate::report::IdentificationReport) -> bool {
    r.methods.get("steady_state").is_some_and(|m| m.applies) && r.methods.len() == 1
}
