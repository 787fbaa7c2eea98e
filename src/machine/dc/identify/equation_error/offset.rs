//! The electrical equation's constant: a check for an offset in the
//! current or voltage reading.
//!
//! A current reading offset by `b` (a Hall sensor's zero, an amplifier's
//! drift) turns the electrical equation into
//! `U = Ra·(i_m − b) + La·di/dt + K·ω`: a constant `−Ra·b` the model has
//! no term for, which least squares shares out over Ra and K (a 3 % offset
//! moved K by 1 to 6 % on the blind suites' `none` records, with nothing
//! else to show for it). A voltage reading offset by `c` leaves `+c` the
//! same way, a speed reading offset by `d` leaves `−K·d`, and a brush
//! drop on a current of one sign `+U_b`.
//!
//! The check refits the electrical equation alone with a constant beside
//! La, Ra and K, with the instruments of the final pass, and gives the
//! constant with its block-sandwich standard error and the K and Ra it
//! leaves. A constant many standard errors from zero that moves K says
//! the readings (or the brushes) carry something the model does not.

use nalgebra::{Matrix4, Vector4};

use super::rows::{LowPass, SegmentRows, K, LA, RA};
use crate::identify::SpeedReading;
use crate::model::DcParams;
use crate::record::Record;

/// The electrical equation refitted with a constant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ElectricalConstant {
    /// The constant, V (what the voltage reading holds beyond
    /// `Ra·i + La·di/dt + K·ω`).
    pub volts: f64,
    /// Its standard error, V.
    pub std_error: f64,
    /// K with the constant taken up, V·s/rad.
    pub k: f64,
    /// Ra with the constant taken up, Ω.
    pub ra: f64,
}

/// Standard errors beyond which the constant is told from noise. The
/// block-sandwich error assumes the model's form; a small misfit the
/// model does not have a term for (a sensor lag, a warming winding) makes
/// a constant of a few millivolts stand at 5 to 11 standard errors on the
/// blind suites' records, so the constant must also matter (below).
const OFFSET_T: f64 = 5.0;

/// Share by which taking the constant up must move K or Ra for it to
/// matter: half the 1 % a commissioning wants K to.
const OFFSET_MOVE: f64 = 0.005;

impl ElectricalConstant {
    /// The constant in standard errors.
    pub fn t(&self) -> f64 {
        self.volts / self.std_error
    }

    /// A warning (what it is and what to do) when the constant stands clear of noise and moves K or
    /// Ra of `fitted` (the estimate without it) by more than
    /// [`OFFSET_MOVE`]; `None` otherwise.
    pub fn warning(&self, fitted: &DcParams) -> Option<String> {
        let dk = self.k / fitted.k - 1.0;
        let dra = self.ra / fitted.ra - 1.0;
        let matters = dk.abs() >= OFFSET_MOVE || dra.abs() >= OFFSET_MOVE;
        (self.t().abs() >= OFFSET_T && matters && self.ra > 0.0).then(|| {
            format!(
                "the voltage equation leaves a constant of {:+.3} V ({:.0} \
                 standard errors), and taking it up moves K by {:+.1} % and Ra by {:+.1} %: the \
                 current reading offset by about {:+.3e} A (read the current with the power stage off \
                 and subtract it), the speed reading by about {:+.3e} rad/s, the voltage reading by \
                 about {:+.3} V, or a brush drop of a current of one sign; with the constant, \
                 K = {:.5} V*s/rad and Ra = {:.5} ohm",
                self.volts,
                self.t().abs(),
                100.0 * dk,
                100.0 * dra,
                -self.volts / self.ra,
                -self.volts / self.k,
                self.volts,
                self.k,
                self.ra
            )
        })
    }
}

/// Refit the electrical rows `measured` (one entry per segment, sample
/// interval `dts`) with a constant, instruments `instruments` (the same
/// rows of the model's simulation; `measured` itself for least squares).
/// `None` where the equations are singular or the result not finite.
pub fn electrical_constant(
    measured: &[SegmentRows],
    instruments: &[SegmentRows],
    dts: &[f64],
    filter: &LowPass,
) -> Option<ElectricalConstant> {
    // The constant integrated over each interval, filtered like every
    // other column (from a zero state at each segment's start).
    let constant: Vec<Vec<f64>> = measured
        .iter()
        .zip(dts)
        .map(|(r, dt)| {
            let mut col = vec![[*dt]; r.ye.len()];
            filter.apply(&mut col);
            col.into_iter().map(|[v]| v).collect()
        })
        .collect();
    let row = |r: &SegmentRows, c: &[f64], k: usize| {
        Vector4::new(r.xe[k][LA], r.xe[k][RA], r.xe[k][K], c[k])
    };
    // Column scales keep the normal matrix conditioned whatever the units.
    let mut scale = Vector4::zeros();
    for (r, c) in measured.iter().zip(&constant) {
        for k in 0..r.ye.len() {
            scale += row(r, c, k).map(|v| v * v);
        }
    }
    let scale = scale.map(|s| if s > 0.0 { 1.0 / s.sqrt() } else { 1.0 });
    let block = (10.0 * filter.samples()).ceil().max(32.0) as usize;
    let mut a = Matrix4::zeros();
    let mut g = Vector4::zeros();
    for ((rx, rz), c) in measured.iter().zip(instruments).zip(&constant) {
        for k in 0..rx.ye.len() {
            let x = row(rx, c, k).component_mul(&scale);
            let z = row(rz, c, k).component_mul(&scale);
            a += z * x.transpose();
            g += z * rx.ye[k];
        }
    }
    let inv = a.try_inverse()?;
    let theta = inv * g;
    let mut meat = Matrix4::zeros();
    for ((rx, rz), c) in measured.iter().zip(instruments).zip(&constant) {
        for start in (0..rx.ye.len()).step_by(block) {
            let mut s = Vector4::zeros();
            for k in start..(start + block).min(rx.ye.len()) {
                let x = row(rx, c, k).component_mul(&scale);
                let z = row(rz, c, k).component_mul(&scale);
                s += z * (rx.ye[k] - x.dot(&theta));
            }
            meat += s * s.transpose();
        }
    }
    let cov = inv * meat * inv.transpose();
    let out = ElectricalConstant {
        volts: theta[3] * scale[3],
        std_error: cov[(3, 3)].sqrt() * scale[3],
        k: theta[2] * scale[2],
        ra: theta[1] * scale[1],
    };
    [out.volts, out.std_error, out.k, out.ra]
        .iter()
        .all(|v| v.is_finite())
        .then_some(out)
}

/// The warning of [`ElectricalConstant::warning`] for `record`, from its
/// equation-error fit without validation (for the diagnosis, which fits
/// by output error and would otherwise not say it); `None` where the fit
/// does not apply or finds no constant that matters.
pub fn reading_offset_warning(record: &Record) -> Option<String> {
    let fit = super::fit_record(record, SpeedReading::default(), false).ok()?;
    fit.electrical_constant?.warning(&fit.params)
}
