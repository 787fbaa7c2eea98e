//! The no-load test reduced: friction and windage as the intercept at
//! V = 0 of the constant losses (input power less stator copper loss)
//! regressed on V² over the lower voltages; per voltage the core loss, the
//! air-gap voltage behind the stator impedance, `Xm = E²/(Q − I²·Xs)` and
//! `Rfe = E²/P_fe` (per phase); the fitted `Xm(V)` curve; and `Xm`, `Rfe`
//! and the core loss at rated voltage.

use super::error::StandardTestsError;
use super::phase::PhaseReading;
use super::regression::{line, polynomial, powers, through_origin};
use crate::contract::{NoLoadRow, XmCurve};
use crate::model::{Connection, C64};
use crate::record::SupplyReading;

/// The friction regression uses the readings at or below this share of
/// rated voltage, where core loss is close to proportional to V² (when
/// there are at least [`MIN_LOW_POINTS`] of them).
pub const FRICTION_VOLTAGE_SHARE: f64 = 0.6;

/// Fewest low-voltage readings for the friction regression; with fewer,
/// it uses every reading and says so.
pub(super) const MIN_LOW_POINTS: usize = 3;

/// Highest degree of the `Xm(V)` polynomial.
const XM_CURVE_DEGREE: usize = 2;

/// Friction and windage from the constant losses.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Friction {
    /// Intercept at V = 0, W (may be < 0 on bad data: the caller decides).
    pub pfw: f64,
    /// Half-width of its 95 % interval.
    pub half_width: Option<f64>,
    /// Which readings the regression used (in `readings` order).
    pub used: Vec<bool>,
    /// Why it used every reading, when it did.
    pub note: Option<String>,
}

/// The constant losses of each reading with the stator resistance `rs`
/// per phase: `P − 3·I_ph²·Rs`, W.
fn constant_losses(readings: &[SupplyReading], connection: Connection, rs: f64) -> Vec<f64> {
    readings
        .iter()
        .map(|r| r.input_power - 3.0 * connection.phase_current(r.line_current).powi(2) * rs)
        .collect()
}

/// Friction and windage with the stator resistance `rs` (per phase, at
/// the no-load test's temperature) and rated line voltage `rated`.
pub(super) fn friction(
    readings: &[SupplyReading],
    connection: Connection,
    rs: f64,
    rated: f64,
) -> Result<Friction, StandardTestsError> {
    let pk = constant_losses(readings, connection, rs);
    let low: Vec<bool> = readings
        .iter()
        .map(|r| r.line_voltage <= FRICTION_VOLTAGE_SHARE * rated)
        .collect();
    let n_low = low.iter().filter(|u| **u).count();
    let (used, note) = if n_low >= MIN_LOW_POINTS {
        (low, None)
    } else {
        (
            vec![true; readings.len()],
            Some(format!(
                "{n_low} no-load reading(s) at or below {:.0} % of rated voltage ({:.1} V), fewer \
                 than {MIN_LOW_POINTS}: friction and windage extrapolated from all {} readings \
                 (saturation at the higher voltages bends the line and biases the intercept)",
                100.0 * FRICTION_VOLTAGE_SHARE,
                FRICTION_VOLTAGE_SHARE * rated,
                readings.len()
            )),
        )
    };
    let (x, y): (Vec<f64>, Vec<f64>) = readings
        .iter()
        .zip(&pk)
        .zip(&used)
        .filter(|(_, u)| **u)
        .map(|((r, p), _)| (r.line_voltage.powi(2), *p))
        .unzip();
    let fit = line(&x, &y).ok_or(StandardTestsError::FrictionVoltages)?;
    Ok(Friction {
        pfw: fit.beta[0],
        half_width: fit.half_width(0),
        used,
        note,
    })
}

/// Friction and windage as the IM diagnosis takes them for its
/// free-running points.
#[derive(Debug, Clone, PartialEq)]
pub struct NoLoadFriction {
    /// Friction and windage, W (the intercept, held at ≥ 0).
    pub pfw: f64,
    /// The stator resistance per phase the copper loss was taken with, Ω.
    pub rs: f64,
    /// Whether `rs` is the DC reading's (else the caller's fallback).
    pub rs_from_dc: bool,
    /// What a user should know: the intercept held at 0, every reading used.
    pub notes: Vec<String>,
}

/// Friction and windage from no-load readings: the intercept at V = 0 of
/// the constant losses regressed on V², with the stator resistance of the
/// DC readings (at the no-load test's temperature) where there are any,
/// else `rs_fallback` (per phase); `rated` the rated line voltage, else
/// the highest no-load voltage.
pub fn no_load_friction(
    readings: &[SupplyReading],
    dc: &[crate::record::DcResistanceReading],
    connection: Connection,
    rs_fallback: f64,
    rated: Option<f64>,
) -> Result<NoLoadFriction, StandardTestsError> {
    use super::dc_resistance::{dc_resistance, mean_temperature, temperature_factor};
    let (rs, rs_from_dc) = match dc_resistance(dc, connection) {
        Ok(d) if !dc.is_empty() => {
            let t_nl = mean_temperature(readings.iter().map(|r| r.winding_temperature));
            (d.rs * temperature_factor(d.temperature, t_nl), true)
        }
        _ => (rs_fallback, false),
    };
    let rated = rated
        .filter(|v| *v > 0.0)
        .unwrap_or_else(|| readings.iter().map(|r| r.line_voltage).fold(0.0, f64::max));
    let fr = friction(readings, connection, rs, rated)?;
    let mut notes: Vec<String> = fr.note.into_iter().collect();
    if fr.pfw < 0.0 {
        notes.push(format!(
            "the no-load losses extrapolate to {:.3e} W at zero voltage: friction and windage \
             held at 0",
            fr.pfw
        ));
    }
    Ok(NoLoadFriction {
        pfw: fr.pfw.max(0.0),
        rs,
        rs_from_dc,
        notes,
    })
}

/// One row per reading, by rising voltage, with `rs` and `xs` (per phase,
/// at the no-load test's temperature and frequency) and friction `pfw`.
pub(super) fn rows(
    readings: &[SupplyReading],
    connection: Connection,
    rs: f64,
    xs: f64,
    pfw: f64,
    used: &[bool],
) -> Result<Vec<NoLoadRow>, StandardTestsError> {
    let pk = constant_losses(readings, connection, rs);
    let mut rows = Vec::new();
    for (k, r) in readings.iter().enumerate() {
        let PhaseReading {
            v,
            i,
            p: pph,
            q: qph,
        } = PhaseReading::of(r, k, "no-load", connection)?;
        // The phase current lags the voltage by φ.
        let current = C64::new(pph / v, -qph / v);
        let e2 = (C64::new(v, 0.0) - current * C64::new(rs, xs)).norm_sqr();
        let qm = qph - i * i * xs;
        let core = pk[k] - pfw;
        rows.push(NoLoadRow {
            segment: r.segment,
            line_voltage: r.line_voltage,
            line_current: r.line_current,
            input_power: r.input_power,
            constant_losses: pk[k],
            core_loss: (core > 0.0).then_some(core),
            air_gap_voltage: e2.sqrt(),
            xm: (qm > 0.0).then(|| e2 / qm),
            rfe: (core > 0.0).then(|| 3.0 * e2 / core),
            in_friction_fit: used[k],
        });
    }
    rows.sort_by(|a, b| a.line_voltage.total_cmp(&b.line_voltage));
    Ok(rows)
}

/// `Xm(V)` fitted to the rows that have an `Xm`: the curve, and `Xm` at
/// line voltage `v` (clamped to the fitted range) with the half-width of
/// its 95 % interval.
pub(super) fn xm_curve(rows: &[NoLoadRow], v: f64) -> Option<(XmCurve, f64, Option<f64>)> {
    let (x, y): (Vec<f64>, Vec<f64>) = rows
        .iter()
        .filter_map(|r| Some((r.line_voltage, r.xm?)))
        .unzip();
    let (lo, hi) = x
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let degree = XM_CURVE_DEGREE.min(x.len().checked_sub(1)?);
    // Fit in units of the highest voltage: the powers stay near 1.
    let xs: Vec<f64> = x.iter().map(|v| v / hi).collect();
    let fit = polynomial(&xs, &y, degree)?;
    let (xm, hw) = fit.predict(&powers(v.clamp(lo, hi) / hi, degree));
    let coefficients = (0..=degree)
        .map(|k| fit.beta[k] / hi.powi(k as i32))
        .collect();
    let curve = XmCurve {
        coefficients,
        from_v: lo,
        to_v: hi,
        rms_residual: fit.rms,
    };
    Some((curve, xm, hw))
}

/// Readings within this share of rated voltage either side give `Rfe` at
/// rated voltage.
const NEAR_RATED: f64 = 0.25;

/// `Rfe` at rated line voltage `v`: the inverse of the slope of core loss
/// against `3·E²` through the origin over the readings within
/// [`NEAR_RATED`] of it (with the half-width of its 95 % interval), or,
/// with a single such reading, interpolated without an interval of its own.
pub(super) fn rfe_at_rated(rows: &[NoLoadRow], v: f64) -> Option<(f64, Option<f64>)> {
    let (x, y): (Vec<f64>, Vec<f64>) = rows
        .iter()
        .filter(|r| (r.line_voltage - v).abs() <= NEAR_RATED * v)
        .filter_map(|r| Some((3.0 * r.air_gap_voltage.powi(2), r.core_loss?)))
        .unzip();
    if x.len() < 2 {
        return Some((interpolate(rows, v, |r| r.rfe)?, None));
    }
    let (g, hw) = through_origin(&x, &y).filter(|(g, _)| *g > 0.0)?;
    Some((1.0 / g, hw.map(|h| h / (g * g))))
}

/// `field` of the rows that have it, linearly interpolated in line
/// voltage at `v` (the nearest end outside their range).
pub(super) fn interpolate(
    rows: &[NoLoadRow],
    v: f64,
    field: impl Fn(&NoLoadRow) -> Option<f64>,
) -> Option<f64> {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((r.line_voltage, field(r)?)))
        .collect();
    let (first, last) = (pts.first()?, pts.last()?);
    if v <= first.0 {
        return Some(first.1);
    }
    if v >= last.0 {
        return Some(last.1);
    }
    pts.windows(2).find(|w| v <= w[1].0).map(|w| {
        let span = w[1].0 - w[0].0;
        if span <= 0.0 {
            return w[1].1;
        }
        w[0].1 + (v - w[0].0) / span * (w[1].1 - w[0].1)
    })
}
