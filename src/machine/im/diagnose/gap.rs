//! Where the IM gap lies: the nominal model's held-out residual split by
//! channel, supply voltage and region along slip (`low_slip`,
//! `breakdown`, `high_slip`), a no-load test's points by themselves
//! (`no_load`, along line voltage), and residual statistics as evidence.
//!
//! Regions follow from the nominal fit's slip of maximum torque `s_bd`
//! (Thevenin form, `Rr/√(Rth² + (Xth + Xr)²)`): `low_slip` below `s_bd/2`
//! (near synchronous, up to about rated slip, where the magnetising branch
//! and iron dominate), `breakdown` from `s_bd/2` to `2·s_bd`, `high_slip`
//! above (towards locked rotor, where rotor impedance and leakage
//! dominate).

use std::collections::BTreeMap;

use statrs::distribution::{ContinuousCDF, Normal, StudentsT};

use super::data::SweepSet;
use super::fit::HeldOut;
use crate::contract::{GapRegion, RegionAxis, ResidualEvidence};
use crate::model::C64;

/// Channels of the IM contract, in order (current, power).
pub const CHANNELS: [&str; 2] = ["line_current", "input_power"];

/// The shaft torque's channel, where a record has a torque column (an
/// additive extension of the contract's channels).
pub const TORQUE_CHANNEL: &str = "shaft_torque";

/// The slip ranges of the three regions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlipRegions {
    /// Slip of maximum torque of the nominal fit.
    pub breakdown_slip: f64,
}

impl SlipRegions {
    /// Regions of a single-cage circuit (Ω).
    pub fn of(rs: f64, xs: f64, xm: f64, rr: f64, xr: f64) -> SlipRegions {
        let zs = C64::new(rs, xs);
        let zm = C64::new(0.0, xm);
        let zth = zs * zm / (zs + zm);
        let s = rr / (zth.re * zth.re + (zth.im + xr).powi(2)).sqrt();
        SlipRegions {
            breakdown_slip: s.clamp(1e-3, 1.0),
        }
    }

    /// `(label, from, to)` of the three regions (an empty one left out).
    pub fn bounds(&self) -> Vec<(&'static str, f64, f64)> {
        let a = 0.5 * self.breakdown_slip;
        let b = (2.0 * self.breakdown_slip).min(1.0);
        let mut v = vec![("low_slip", 0.0, a), ("breakdown", a, b)];
        if b < 1.0 {
            v.push(("high_slip", b, 1.0));
        }
        v
    }

    /// Whether point `k` of `data` is one of known slip (not a no-load
    /// reading) in voltage group `group` and the region `label`.
    pub fn holds(&self, data: &SweepSet, k: usize, group: usize, label: &str) -> bool {
        data.group[k] == group && !data.free_running[k] && self.label(data.inputs[k].slip) == label
    }

    /// Label of the region a slip falls in.
    pub fn label(&self, s: f64) -> &'static str {
        let bounds = self.bounds();
        bounds
            .iter()
            .find(|(_, a, b)| s >= *a && s < *b)
            .or(bounds.last())
            .map_or("high_slip", |r| r.0)
    }
}

/// The segments of a no-load test (free-running points), in order.
fn no_load_segments(data: &SweepSet) -> Vec<u32> {
    let mut segs: Vec<u32> = (0..data.len())
        .filter(|&k| data.free_running[k])
        .map(|k| data.segment[k])
        .collect();
    segs.dedup();
    segs
}

/// Shares of the squared weighted residual: regions (largest first), per
/// channel, per supply voltage.
pub fn shares(
    data: &SweepSet,
    held: &HeldOut,
    regions: &SlipRegions,
) -> (Vec<GapRegion>, BTreeMap<String, f64>, BTreeMap<String, f64>) {
    let weighted = &held.weighted;
    // The channel `c` (current, power, torque) of point `k`, squared.
    let sq = |c: usize, k: usize| match c {
        0 => weighted[k].0.powi(2),
        1 => weighted[k].1.powi(2),
        _ => held.weighted_torque[k].powi(2),
    };
    let channels: Vec<&str> = CHANNELS
        .iter()
        .copied()
        .chain(data.has_torque().then_some(TORQUE_CHANNEL))
        .collect();
    let total: f64 = (0..data.len())
        .map(|k| (0..channels.len()).map(|c| sq(c, k)).sum::<f64>())
        .sum();
    let total = if total > 0.0 { total } else { 1.0 };
    let mut out = Vec::new();
    let mut by_channel = BTreeMap::new();
    let mut by_voltage = BTreeMap::new();
    for (c, name) in channels.iter().enumerate() {
        let sq = |k: usize| sq(c, k);
        by_channel.insert(
            name.to_string(),
            (0..data.len()).map(sq).sum::<f64>() / total,
        );
        for (g, &v) in data.group_voltage.iter().enumerate() {
            for (label, from, to) in regions.bounds() {
                let idx: Vec<usize> = (0..data.len())
                    .filter(|&k| regions.holds(data, k, g, label))
                    .collect();
                if idx.is_empty() {
                    continue;
                }
                out.push(GapRegion {
                    channel: name.to_string(),
                    axis: RegionAxis::Slip,
                    from,
                    to,
                    label: label.into(),
                    share: idx.iter().map(|&k| sq(k)).sum::<f64>() / total,
                    segment: None,
                    voltage: Some(v),
                });
            }
        }
    }
    for seg in no_load_segments(data) {
        let idx: Vec<usize> = (0..data.len())
            .filter(|&k| data.free_running[k] && data.segment[k] == seg)
            .collect();
        let line = |k: &usize| data.connection.line_voltage(data.inputs[*k].voltage);
        let from = idx.iter().map(line).fold(f64::INFINITY, f64::min);
        let to = idx.iter().map(line).fold(0.0, f64::max);
        // A no-load reading has no torque: its channels are two.
        for (c, name) in CHANNELS.iter().enumerate() {
            let sq = |k: &usize| sq(c, *k);
            out.push(GapRegion {
                channel: name.to_string(),
                axis: RegionAxis::Voltage,
                from,
                to,
                label: "no_load".into(),
                share: idx.iter().map(sq).sum::<f64>() / total,
                segment: Some(seg),
                voltage: None,
            });
        }
    }
    for (g, &v) in data.group_voltage.iter().enumerate() {
        let s: f64 = (0..data.len())
            .filter(|&k| data.group[k] == g)
            .map(|k| (0..channels.len()).map(|c| sq(c, k)).sum::<f64>())
            .sum();
        by_voltage.insert(format!("{v:.0}"), s / total);
    }
    out.sort_by(|a, b| b.share.total_cmp(&a.share));
    (out, by_channel, by_voltage)
}

/// Pearson correlation and its two-sided p-value under independence.
fn correlation(x: &[f64], y: &[f64]) -> (f64, Option<f64>) {
    let n = x.len().min(y.len());
    if n < 4 {
        return (0.0, None);
    }
    let mx = x.iter().sum::<f64>() / n as f64;
    let my = y.iter().sum::<f64>() / n as f64;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for k in 0..n {
        sxy += (x[k] - mx) * (y[k] - my);
        sxx += (x[k] - mx).powi(2);
        syy += (y[k] - my).powi(2);
    }
    if sxx <= 0.0 || syy <= 0.0 {
        return (0.0, None);
    }
    let r = (sxy / (sxx * syy).sqrt()).clamp(-1.0, 1.0);
    let dof = (n - 2) as f64;
    let t = r * (dof / (1.0 - r * r).max(1e-300)).sqrt();
    let p = StudentsT::new(0.0, 1.0, dof)
        .ok()
        .map(|d| (2.0 * (1.0 - d.cdf(t.abs()))).min(1.0));
    (r, p)
}

/// Wald–Wolfowitz runs test on the signs of `r` (in the given order):
/// the z statistic and the one-sided p-value of "too few runs" (a smooth,
/// systematic residual).
fn runs_test(r: &[f64]) -> (f64, Option<f64>) {
    let signs: Vec<bool> = r.iter().filter(|v| **v != 0.0).map(|v| *v > 0.0).collect();
    let n1 = signs.iter().filter(|s| **s).count() as f64;
    let n2 = signs.len() as f64 - n1;
    if n1 < 2.0 || n2 < 2.0 {
        return (0.0, None);
    }
    let runs = 1 + signs.windows(2).filter(|w| w[0] != w[1]).count();
    let n = n1 + n2;
    let mean = 2.0 * n1 * n2 / n + 1.0;
    let var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n * n * (n - 1.0));
    if var <= 0.0 {
        return (0.0, None);
    }
    let z = (runs as f64 - mean) / var.sqrt();
    let p = Normal::new(0.0, 1.0).ok().map(|d| d.cdf(z));
    (z, p)
}

/// Residual statistics of the nominal held-out residual, per channel:
/// correlation with slip, with |I|, with the air-gap voltage `e`, with
/// the recording order (time), and a runs test along slip.
pub fn evidence(data: &SweepSet, weighted: &[(f64, f64)], e: &[f64]) -> Vec<ResidualEvidence> {
    let n = data.len();
    let slip: Vec<f64> = data.inputs.iter().map(|p| p.slip).collect();
    let order: Vec<f64> = (0..n).map(|k| k as f64).collect();
    // Points ordered by segment, then slip.
    let mut by_slip: Vec<usize> = (0..n).collect();
    by_slip.sort_by(|&a, &b| {
        data.segment[a]
            .cmp(&data.segment[b])
            .then(slip[a].total_cmp(&slip[b]))
    });
    let mut out = Vec::new();
    for (c, name) in CHANNELS.iter().enumerate() {
        let r: Vec<f64> = weighted
            .iter()
            .map(|&(a, b)| if c == 0 { a } else { b })
            .collect();
        let mut push = |statistic: &str, (value, p_value): (f64, Option<f64>)| {
            out.push(ResidualEvidence {
                channel: name.to_string(),
                statistic: statistic.into(),
                value,
                p_value,
            })
        };
        push("corr_slip", correlation(&r, &slip));
        push("corr_abs_current", correlation(&r, &data.current));
        push("corr_air_gap_voltage", correlation(&r, e));
        push("corr_time", correlation(&r, &order));
        let sorted: Vec<f64> = by_slip.iter().map(|&k| r[k]).collect();
        push("runs_along_slip", runs_test(&sorted));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_cover_the_sweep_in_order() {
        let r = SlipRegions::of(1.0, 2.0, 60.0, 1.2, 2.0);
        assert!(r.breakdown_slip > 0.1 && r.breakdown_slip < 0.5);
        assert_eq!(r.label(0.0), "low_slip");
        assert_eq!(r.label(r.breakdown_slip), "breakdown");
        assert_eq!(r.label(1.0), "high_slip");
    }

    #[test]
    fn runs_test_sees_a_smooth_residual() {
        let smooth: Vec<f64> = (0..30).map(|k| (k as f64 / 5.0).sin()).collect();
        let (z, p) = runs_test(&smooth);
        assert!(z < -3.0 && p.unwrap() < 0.01, "z {z}");
        let alternating: Vec<f64> = (0..30)
            .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        assert!(runs_test(&alternating).1.unwrap() > 0.99);
        let (r, p) = correlation(&[1.0, 2.0, 3.0, 4.0, 5.0], &[2.0, 4.0, 6.1, 8.0, 10.0]);
        assert!(r > 0.99 && p.unwrap() < 0.01);
    }
}
