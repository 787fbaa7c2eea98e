//! The text report of an induction-machine identification: each method's
//! parameters in Ω and per unit with their intervals, what the data do not
//! determine, the standard tests' tables (no-load per voltage, locked
//! rotor per point, the fitted `Xm(V)`), the warnings.

use std::fmt::Write;

use crate::contract::StandardTestTables;
use crate::identify::{ImIdentification, ParamSource};

/// The head of the columns both tables open with: the supply's line
/// voltage, line current and input power ([`supply_cells`]).
const SUPPLY_HEADER: &str = "   V line    I line     P in W";

/// A reading's line voltage, line current and input power, under
/// [`SUPPLY_HEADER`].
fn supply_cells(line_voltage: f64, line_current: f64, input_power: f64) -> String {
    format!("{line_voltage:>9.2} {line_current:>9.4} {input_power:>10.2}")
}

/// The standard tests' tables, for a person.
fn render_tables(out: &mut String, t: &StandardTestTables) {
    let opt = |v: Option<f64>, w: usize, p: usize| {
        v.map_or(format!("{:>w$}", "-"), |v| format!("{v:>w$.p$}"))
    };
    let _ = writeln!(
        out,
        "\nno load (per phase){}",
        if t.no_load.iter().any(|r| r.in_friction_fit) {
            "; * = in the friction-and-windage fit"
        } else {
            ""
        }
    );
    let _ = writeln!(
        out,
        "  {SUPPLY_HEADER} {:>11} {:>10} {:>9} {:>10} {:>11}",
        "P-Pcu W", "Pfe W", "E V", "Xm ohm", "Rfe ohm"
    );
    for r in &t.no_load {
        let _ = writeln!(
            out,
            "  {} {:>11.2} {} {:>9.2} {} {}{}",
            supply_cells(r.line_voltage, r.line_current, r.input_power),
            r.constant_losses,
            opt(r.core_loss, 10, 2),
            r.air_gap_voltage,
            opt(r.xm, 10, 3),
            opt(r.rfe, 11, 1),
            if r.in_friction_fit { " *" } else { "" }
        );
    }
    if let Some(c) = &t.xm_curve {
        let terms: Vec<String> = c
            .coefficients
            .iter()
            .enumerate()
            .map(|(k, a)| match k {
                0 => format!("{a:.5}"),
                1 => format!("{a:+.5e}*V"),
                _ => format!("{a:+.5e}*V^{k}"),
            })
            .collect();
        let _ = writeln!(
            out,
            "  Xm(V) = {} ohm, {:.1} to {:.1} V, rms residual {:.4} ohm",
            terms.join(" "),
            c.from_v,
            c.to_v,
            c.rms_residual
        );
    }
    let _ = writeln!(out, "\nlocked rotor (per phase)");
    let _ = writeln!(
        out,
        "  {SUPPLY_HEADER} {:>8} {:>10} {:>10} {:>10}",
        "f Hz", "Zlr ohm", "Rlr ohm", "Xlr ohm"
    );
    for r in &t.locked_rotor {
        let _ = writeln!(
            out,
            "  {} {} {:>10.4} {:>10.4} {:>10.4}",
            supply_cells(r.line_voltage, r.line_current, r.input_power),
            opt(r.frequency, 8, 2),
            r.zlr,
            r.rlr,
            r.xlr
        );
    }
}

/// The report as text for a person.
pub fn render_im_text(id: &ImIdentification) -> String {
    let mut out = String::new();
    let n = id.sweep.points.len();
    let mut segs: Vec<u32> = id.sweep.points.iter().map(|p| p.segment).collect();
    segs.sort_unstable();
    segs.dedup();
    let _ = writeln!(
        out,
        "induction machine, {n} operating points in {} segment(s), {} connection",
        segs.len(),
        id.sweep.connection
    );
    let zb = id.base.map(|b| b.impedance());
    if let Some(b) = &id.base {
        let _ = writeln!(
            out,
            "per-unit base: {:.2} V, {:.3} A per phase, Z_base = {:.4} ohm",
            b.phase_voltage,
            b.phase_current,
            b.impedance()
        );
    }
    let pu = |v: f64| zb.map_or(String::new(), |z| format!("{:>10.5} p.u.", v / z));
    for (key, method) in &id.report.methods {
        let best = if id.report.best.as_deref() == Some(key) {
            "  (best)"
        } else {
            ""
        };
        let _ = writeln!(out, "\n{key}{best}");
        match &method.params {
            Some(params) if method.applies => {
                // The names' column as wide as the longest.
                let width = params.keys().map(|k| k.chars().count()).fold(4, usize::max);
                for (name, p) in params {
                    let ci = p.ci95.map_or("no interval".to_string(), |[lo, hi]| {
                        format!("95 % [{lo:.4}, {hi:.4}]")
                    });
                    let source = id
                        .lm
                        .as_ref()
                        .filter(|_| key == "lm")
                        .and_then(|f| f.params.iter().find(|q| q.param.key() == name))
                        .map_or("", |q| {
                            if q.source == ParamSource::Convention {
                                "  by convention"
                            } else {
                                ""
                            }
                        });
                    let (unit, per_unit) = if p.unit == "ohm" {
                        ("ohm", pu(p.value))
                    } else {
                        (p.unit.as_str(), String::new())
                    };
                    let _ = writeln!(
                        out,
                        "  {name:<width$} {:>12.5} {unit:<3} {per_unit} {ci}{source}",
                        p.value
                    );
                }
                if let Some(v) = method.validation_nrmse {
                    let _ = writeln!(out, "  held-out NRMSE {v:.4}");
                }
            }
            _ => {
                let _ = writeln!(
                    out,
                    "  does not apply: {}",
                    method.reason.as_deref().unwrap_or("no reason given")
                );
            }
        }
    }
    if let Some(f) = &id.lm {
        let _ = writeln!(
            out,
            "\nlm fit: rms relative residual {:.3} % (current){}; {} of {} starts reached the best cost",
            100.0 * f.current_rms_relative,
            f.power_rms_relative.map_or(String::new(), |p| format!(", {:.3} % (power)", 100.0 * p)),
            f.starts.1,
            f.starts.0
        );
        if !f.free.is_empty() {
            let names: Vec<&str> = f.free.iter().map(|p| p.key()).collect();
            let _ = writeln!(out, "correlation ({}):", names.join(", "));
            for (i, name) in names.iter().enumerate() {
                let row: Vec<String> = (0..f.free.len())
                    .map(|j| format!("{:+.2}", f.correlation[(i, j)]))
                    .collect();
                let _ = writeln!(out, "  {name:<4} {}", row.join(" "));
            }
        }
    }
    if let Some(t) = &id.report.standard_tests {
        render_tables(&mut out, t);
    }
    crate::contract::render_warnings(&mut out, &id.report);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The supply's columns stand under their heads, as wide as them.
    #[test]
    fn supply_cells_stand_under_their_heads() {
        assert_eq!(
            SUPPLY_HEADER,
            format!("{:>9} {:>9} {:>10}", "V line", "I line", "P in W")
        );
        assert_eq!(
            supply_cells(400.0, 12.3456, 1234.5),
            "   400.00   12.3456    1234.50"
        );
        assert_eq!(supply_cells(400.0, 1.0, 1.0).len(), SUPPLY_HEADER.len());
    }
}
