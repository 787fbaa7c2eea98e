//! The locked-rotor test reduced per point (`Z_lr = V/I`, `R_lr = P/I²`,
//! `X_lr = √(Z_lr² − R_lr²)`, per phase) and over all points (`R_lr` and
//! `X_lr` as the slopes of per-phase active and reactive power against the
//! phase current squared, through the origin, with their 95 % intervals),
//! and the rotor branch behind it once `Rs`, `Xs` and the magnetising
//! branch are known (IEEE 112's correction for the current `Xm` takes).

use super::error::StandardTestsError;
use super::phase::PhaseReading;
use super::regression::through_origin;
use crate::contract::LockedRotorRow;
use crate::model::{Connection, C64};
use crate::record::SupplyReading;

/// The locked-rotor test reduced, Ω per phase at its frequency.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct LockedRotor {
    /// One row per reading, by rising current.
    pub rows: Vec<LockedRotorRow>,
    /// `R_lr` and the half-width of its 95 % interval.
    pub rlr: (f64, Option<f64>),
    /// `X_lr` and the half-width of its 95 % interval.
    pub xlr: (f64, Option<f64>),
}

/// Frequencies that differ by less than this share are one frequency.
const SAME_FREQUENCY: f64 = 0.01;

/// The common frequency of `readings` (NaN when none gives one), or why
/// there is none.
pub(super) fn common_frequency(
    readings: &[SupplyReading],
    test: &'static str,
) -> Result<f64, StandardTestsError> {
    let known: Vec<f64> = readings
        .iter()
        .map(|r| r.frequency)
        .filter(|f| f.is_finite())
        .collect();
    let Some(&first) = known.first() else {
        return Ok(f64::NAN);
    };
    if let Some(other) = known
        .iter()
        .find(|f| ((*f - first) / first).abs() > SAME_FREQUENCY)
    {
        return Err(StandardTestsError::Frequencies {
            test,
            first,
            other: *other,
        });
    }
    Ok(known.iter().sum::<f64>() / known.len() as f64)
}

/// The readings grouped by frequency, lowest first, when every reading
/// gives one and they fall into two groups or more; `None` otherwise (one
/// frequency, or a reading without one: [`common_frequency`] decides).
pub(super) fn frequency_groups(readings: &[SupplyReading]) -> Option<Vec<Vec<SupplyReading>>> {
    if readings.iter().any(|r| !r.frequency.is_finite()) {
        return None;
    }
    let mut sorted = readings.to_vec();
    sorted.sort_by(|a, b| a.frequency.total_cmp(&b.frequency));
    let mut groups: Vec<Vec<SupplyReading>> = Vec::new();
    for r in sorted {
        match groups.last_mut() {
            Some(g)
                if ((r.frequency - g[0].frequency) / g[0].frequency).abs() <= SAME_FREQUENCY =>
            {
                g.push(r)
            }
            _ => groups.push(vec![r]),
        }
    }
    (groups.len() > 1).then_some(groups)
}

/// Reduce the locked-rotor readings of a winding connected as `connection`.
pub(super) fn locked_rotor(
    readings: &[SupplyReading],
    connection: Connection,
) -> Result<LockedRotor, StandardTestsError> {
    let mut rows = Vec::new();
    let (mut i2, mut p, mut q) = (Vec::new(), Vec::new(), Vec::new());
    for (k, r) in readings.iter().enumerate() {
        let PhaseReading {
            v,
            i,
            p: pph,
            q: qph,
        } = PhaseReading::of(r, k, "locked-rotor", connection)?;
        rows.push(LockedRotorRow {
            segment: r.segment,
            line_voltage: r.line_voltage,
            line_current: r.line_current,
            input_power: r.input_power,
            frequency: r.frequency.is_finite().then_some(r.frequency),
            zlr: v / i,
            rlr: pph / (i * i),
            xlr: qph / (i * i),
        });
        i2.push(i * i);
        p.push(pph);
        q.push(qph);
    }
    rows.sort_by(|a, b| a.line_current.total_cmp(&b.line_current));
    let rlr = through_origin(&i2, &p).ok_or(StandardTestsError::LockedRotorImpedance("R_lr"))?;
    let xlr = through_origin(&i2, &q).ok_or(StandardTestsError::LockedRotorImpedance("X_lr"))?;
    Ok(LockedRotor { rows, rlr, xlr })
}

/// The rotor branch `Rr + jXr` behind the locked-rotor impedance
/// `rlr + j·xlr` once the stator's `rs + j·xs` and the magnetising
/// branch's admittance `ym` (all at the test's frequency) are taken off;
/// `None` when nothing physical is left (a resistance or reactance ≤ 0).
pub(super) fn rotor_branch(rlr: f64, xlr: f64, rs: f64, xs: f64, ym: C64) -> Option<C64> {
    let z2 = C64::new(rlr - rs, xlr - xs);
    if z2.re <= 0.0 || z2.im <= 0.0 {
        return None;
    }
    let zr = (z2.inv() - ym).inv();
    (zr.re > 0.0 && zr.im > 0.0 && zr.re.is_finite() && zr.im.is_finite()).then_some(zr)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(v: f64, i: f64, p: f64, f: f64) -> SupplyReading {
        SupplyReading {
            segment: 1,
            line_voltage: v,
            line_current: i,
            input_power: p,
            frequency: f,
            winding_temperature: None,
        }
    }

    #[test]
    fn per_point_and_regressed_impedances_of_a_star_winding() {
        // Per phase 3 + j4 Ω: |Z| = 5 Ω; at 10 A per phase 50 V, 300 W.
        let v = 50.0 * 3f64.sqrt();
        let r = [
            reading(v, 10.0, 900.0, 50.0),
            reading(v / 2.0, 5.0, 225.0, 50.0),
        ];
        let lr = locked_rotor(&r, Connection::Star).unwrap();
        assert_eq!(lr.rows[0].line_current, 5.0);
        assert!((lr.rows[1].zlr - 5.0).abs() < 1e-9);
        assert!((lr.rlr.0 - 3.0).abs() < 1e-9 && (lr.xlr.0 - 4.0).abs() < 1e-9);
        let e = locked_rotor(&[reading(v, 10.0, 2000.0, 50.0)], Connection::Star).unwrap_err();
        assert!(e.to_string().contains("not below"), "{e}");
        assert!(common_frequency(
            &[reading(v, 1.0, 1.0, 50.0), reading(v, 1.0, 1.0, 25.0)],
            "x"
        )
        .unwrap_err()
        .to_string()
        .contains("more than one frequency"));
    }

    #[test]
    fn a_textbook_locked_rotor_test_at_quarter_frequency() {
        // A textbook worked example: 7.5 hp, 208 V, 60 Hz, star; locked
        // rotor at 15 Hz, 25 V, 27.9 A (mean of the three lines), 920 W.
        // The book's numbers: Z_lr = 0.517 Ω, R_lr = 0.394 Ω,
        // X_lr = 0.335 Ω at 15 Hz, so 1.34 Ω at 60 Hz.
        let lr = locked_rotor(&[reading(25.0, 27.9, 920.0, 15.0)], Connection::Star).unwrap();
        let row = &lr.rows[0];
        assert!((row.zlr - 0.517).abs() < 5e-4, "{row:?}");
        assert!((lr.rlr.0 - 0.394).abs() < 5e-4 && (lr.xlr.0 - 0.335).abs() < 5e-4);
        assert!((4.0 * lr.xlr.0 - 1.34).abs() < 5e-3);
        assert_eq!(
            (lr.rlr.1, lr.xlr.1),
            (None, None),
            "one reading, no interval"
        );
    }

    #[test]
    fn the_rotor_branch_is_what_the_magnetising_branch_leaves() {
        let zr = C64::new(1.2, 2.5);
        let ym = C64::new(1.0 / 800.0, -1.0 / 60.0);
        let z = C64::new(0.9, 2.0) + (ym + zr.inv()).inv();
        let back = rotor_branch(z.re, z.im, 0.9, 2.0, ym).unwrap();
        assert!((back - zr).norm() < 1e-12, "{back}");
        assert!(rotor_branch(z.re, z.im, z.re + 0.1, 2.0, ym).is_none());
    }
}
