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

/// `v` with `digits` significant digits, plain where that reads well.
pub fn sig(v: f64, digits: usize) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor() as i32;
    if (-3..5).contains(&mag) {
        let decimals = (digits as i32 - 1 - mag).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.prec$e}", prec = digits.saturating_sub(1))
    }
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
                    format!("95 % CI [{}, {}]", sig(lo, 5), sig(hi, 5))
                });
                let value = sig(p.value, 6);
                let _ = write!(out, "  {key:<4} {value:>12} {:<10} {ci}", p.unit);
                if let Some(t) = param_value(truth, key) {
                    let err = 100.0 * (p.value - t) / t;
                    let _ = write!(out, "   simulated {} ({err:+.3} %)", sig(t, 6));
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
    crate::contract::render_warnings(&mut out, r);
    out
}

fn name_of_static(r: &crate::report::IdentificationReport) -> bool {
    r.methods.get("steady_state").is_some_and(|m| m.applies) && r.methods.len() == 1
}

#[cfg(test)]
mod tests {
    use super::sig;

    #[test]
    fn significant_digits_read_naturally() {
        assert_eq!(sig(30.95496, 6), "30.9550");
        assert_eq!(sig(1.322951, 6), "1.32295");
        assert_eq!(sig(0.0005003559, 4), "5.004e-4");
        assert_eq!(sig(0.128, 3), "0.128");
        assert_eq!(sig(123456.0, 3), "1.23e5");
        assert_eq!(sig(-0.0, 3), "-0");
    }
}
