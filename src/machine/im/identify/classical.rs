//! Classical IEEE-112-style estimates from the sweep's own no-load and
//! locked-rotor points: the starting points of the fits when the user
//! gives none.
//!
//! - The point of smallest slip stands for the no-load test: its reactance
//!   is `Xs + Xm`, its power less the stator copper loss is the iron loss,
//!   `Rfe = 3·E²/P_fe` with `E` the voltage behind the stator impedance
//!   (less the rotor's `3·E²·s/Rr`, since the sweep's point is not uncoupled).
//! - The point of largest slip stands for the locked-rotor test:
//!   `Z_lr = R_lr + jX_lr`, the leakage split by design class
//!   (`Xs = share·X_lr`), `Rr = (R_lr − Rs)·((Xr + Xm)/Xm)²`.
//! - Without a DC measurement `Rs` is taken as half of `R_lr` (a start,
//!   not an estimate: the fit refines it).
//! - For the double cage the rotor impedance seen at a low slip and at
//!   locked rotor give the running (inner) and starting (outer) cage; a
//!   few ratios of the two cages' resistances make several starts.

use super::error::ImFitError;
use super::sweep::PhaseData;
use crate::model::{ImCircuit, ImModel, LeakageSplit, RotorCage, C64};

/// The per-phase impedance a point shows: `|Z| = V/I`, `cos φ = P/(3VI)`.
fn point_impedance(data: &PhaseData, k: usize) -> C64 {
    let (v, i, p) = (data.voltage[k], data.current[k], data.power[k]);
    let zn = v / i;
    let cos = (p / (3.0 * v * i)).clamp(-1.0, 1.0);
    let sin = (1.0 - cos * cos).sqrt();
    C64::new(zn * cos, zn * sin)
}

fn extreme(data: &PhaseData, largest: bool) -> Option<usize> {
    (0..data.len()).reduce(|a, b| {
        let better = if largest {
            data.slip[b] > data.slip[a]
        } else {
            data.slip[b] < data.slip[a]
        };
        if better {
            b
        } else {
            a
        }
    })
}

/// Classical estimate of a single cage (with iron loss when `iron_loss`).
/// `rs` is the stator resistance when known (e.g. from a DC test).
pub fn classical_single(
    data: &PhaseData,
    split: LeakageSplit,
    iron_loss: bool,
    rs: Option<f64>,
) -> Result<ImCircuit, ImFitError> {
    let nl = extreme(data, false)
        .ok_or_else(|| ImFitError::Missing("the sweep has no points".into()))?;
    let lr =
        extreme(data, true).ok_or_else(|| ImFitError::Missing("the sweep has no points".into()))?;
    if data.slip.iter().all(|&s| s == 0.0) {
        return Err(ImFitError::Missing(
            "every point's slip is 0: the slip was not measured (a no-load voltage sweep, say); \
             a slip sweep needs each point's speed, and a no-load test without it is read as \
             --kind im_no_load, reduced with locked-rotor and DC-resistance files (the standard \
             tests)"
                .into(),
        ));
    }
    if data.slip[lr] - data.slip[nl] < 0.2 {
        return Err(ImFitError::Missing(format!(
            "the sweep spans slip {:.3} to {:.3} only: it needs a point near no load and one near locked rotor",
            data.slip[nl], data.slip[lr]
        )));
    }
    let z_nl = point_impedance(data, nl);
    let z_lr = point_impedance(data, lr);
    let r_lr = z_lr.re.max(1e-6 * z_lr.norm());
    let x_lr = z_lr.im.max(1e-3 * z_lr.norm());
    let rs = rs.unwrap_or(0.5 * r_lr);
    let xs = split.stator_share * x_lr;
    let xr = (1.0 - split.stator_share) * x_lr;
    let xm = (z_nl.im - xs).max(5.0 * x_lr);
    let rr = ((r_lr - rs) * ((xr + xm) / xm).powi(2)).max(0.2 * r_lr);
    let rfe = iron_loss.then(|| {
        let (v, i, p) = (data.voltage[nl], data.current[nl], data.power[nl]);
        let e = (C64::new(v, 0.0) - C64::new(i, 0.0) * C64::new(rs, xs)).norm();
        // Near synchronism the rotor branch is about Rr/s: take its power off
        // too (IEEE 112's no-load point is uncoupled; a sweep's is not quite).
        let s_nl = data.slip[nl];
        let p_fe = p - 3.0 * i * i * rs - 3.0 * e * e * s_nl / rr;
        if p_fe > 0.0 {
            (3.0 * e * e / p_fe).max(2.0 * xm)
        } else {
            50.0 * xm
        }
    });
    let c = ImCircuit {
        rs,
        xs,
        xm,
        rfe,
        rotor: RotorCage::Single { rr, xr },
    };
    c.validate()
        .map_err(|e| ImFitError::Unidentifiable(format!("classical estimate: {e}")))?;
    Ok(c)
}

/// Rotor impedance a point shows behind the stator and magnetising branch
/// of `c`.
fn rotor_seen(data: &PhaseData, k: usize, c: &ImCircuit) -> Option<C64> {
    let z_ag = point_impedance(data, k) - C64::new(c.rs, c.xs);
    let y_r = z_ag.inv() - c.magnetising_admittance();
    (y_r.re > 0.0).then(|| y_r.inv())
}

/// Starting points for `model`: the classical estimate, and for the double
/// cage a few splits into a starting and a running cage.
pub fn classical_starts(
    data: &PhaseData,
    model: ImModel,
    split: LeakageSplit,
    rs: Option<f64>,
) -> Result<Vec<ImCircuit>, ImFitError> {
    let single = classical_single(data, split, model.has_iron_loss(), rs)?;
    if !model.is_double() {
        return Ok(vec![single]);
    }
    let RotorCage::Single { rr, xr } = single.rotor else {
        unreachable!("classical_single gives a single cage")
    };
    // Running cage from a low-slip point with real load current.
    let lr =
        extreme(data, true).ok_or_else(|| ImFitError::Missing("the sweep has no points".into()))?;
    let mut low: Option<(f64, f64)> = None;
    let mut order: Vec<usize> = (0..data.len()).collect();
    order.sort_by(|a, b| data.slip[*a].total_cmp(&data.slip[*b]));
    for &k in &order {
        if data.slip[k] < 0.01 {
            continue;
        }
        if let Some(z) = rotor_seen(data, k, &single) {
            low = Some((z.re * data.slip[k], z.im.max(0.0)));
            break;
        }
    }
    let (r_low, x_low) = low.unwrap_or((0.5 * rr, xr));
    let (r_high, x_high) = rotor_seen(data, lr, &single)
        .map(|z| (z.re * data.slip[lr], z.im.max(1e-3 * xr)))
        .unwrap_or((rr, xr));
    let mut starts = Vec::new();
    for rho in [2.0, 5.0, 15.0] {
        for x1_share in [0.1, 0.5] {
            let rr2 = r_low.max(1e-6) * (1.0 + rho) / rho;
            let rr1 = (rho * rr2).max(r_high);
            let xr1 = x1_share * x_high;
            let xr2 = ((x_low * (1.0 + rho).powi(2) - xr1) / (rho * rho)).max(x_high);
            let c = ImCircuit {
                rotor: RotorCage::Double { rr1, rr2, xr1, xr2 },
                ..single
            };
            if c.validate().is_ok() {
                starts.push(c);
            }
        }
    }
    if starts.is_empty() {
        return Err(ImFitError::Unidentifiable(
            "classical estimate: no valid double-cage start".into(),
        ));
    }
    Ok(starts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{slip_grid, SlipSweep, SweepNoise};
    use crate::model::im_fixtures::{single_cage, STAR_400V_50HZ};

    #[test]
    fn a_sweep_whose_slip_was_not_measured_says_so() {
        let c = single_cage(0.5, 1.2, 40.0, Some(600.0), 0.6, 1.2);
        let mut d = SlipSweep::simulate_seeded(
            &c,
            &STAR_400V_50HZ,
            &slip_grid(10, 0.001),
            &SweepNoise::default(),
            5,
        )
        .phase_data();
        d.slip.iter_mut().for_each(|s| *s = 0.0);
        let e = classical_single(&d, LeakageSplit::DESIGN_A, true, None).unwrap_err();
        assert!(e.to_string().contains("the slip was not measured"), "{e}");
        assert!(e.to_string().contains("--kind im_no_load"), "{e}");
    }

    #[test]
    fn classical_estimate_is_near_a_single_cage_machine() {
        let c = single_cage(0.5, 1.2, 40.0, Some(600.0), 0.6, 1.2);
        let d = SlipSweep::simulate_seeded(
            &c,
            &STAR_400V_50HZ,
            &slip_grid(30, 0.001),
            &SweepNoise::default(),
            5,
        )
        .phase_data();
        let e = classical_single(&d, LeakageSplit::DESIGN_A, true, Some(0.5)).unwrap();
        // Locked-rotor leakage and resistance split as IEEE 112 does.
        assert!((e.xs - 1.2).abs() < 0.05, "{e:?}");
        assert!((e.xm - 40.0).abs() < 2.0, "{e:?}");
        let RotorCage::Single { rr, .. } = e.rotor else {
            panic!()
        };
        assert!((rr - 0.6).abs() < 0.05, "{e:?}");
        assert!((e.rfe.unwrap() - 600.0).abs() < 120.0, "{e:?}");
    }

    #[test]
    fn a_sweep_without_locked_rotor_is_refused() {
        let c = single_cage(0.5, 1.2, 40.0, None, 0.6, 1.2);
        let d = SlipSweep::simulate_seeded(
            &c,
            &STAR_400V_50HZ,
            &[0.01, 0.03, 0.1],
            &SweepNoise::default(),
            5,
        )
        .phase_data();
        assert!(classical_single(&d, LeakageSplit::DESIGN_A, false, None)
            .unwrap_err()
            .to_string()
            .contains("locked rotor"));
    }
}
