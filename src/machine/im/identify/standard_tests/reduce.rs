//! The classical reduction as one function of its four measured inputs
//! (the DC resistance, `R_lr`, `X_lr` and an offset of the friction
//! intercept), so their 95 % intervals carry to every element by first
//! derivatives: `Xs` and `Xr` in the design class's ratio with the rotor
//! branch behind the locked-rotor impedance once `Rs`, `Xs` and the
//! magnetising branch at rated voltage (from the no-load test, which
//! itself needs `Xs`) are taken off; solved for `Xs` by bisection.

use super::error::StandardTestsError;
use super::locked_rotor::rotor_branch;
use super::no_load::{friction, interpolate, rfe_at_rated, rows, xm_curve};
use crate::contract::{NoLoadRow, XmCurve};
use crate::model::{Connection, LeakageSplit, C64};
use crate::record::SupplyReading;

/// Bisection steps for `Xs` (the interval halves each step: 2⁻⁶⁰ of `X_lr`).
const BISECTION_STEPS: usize = 60;

/// The measured inputs the intervals come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Inputs {
    /// Stator resistance per phase at the DC test's temperature, Ω.
    pub rs_dc: f64,
    /// Locked-rotor resistance per phase, Ω.
    pub rlr: f64,
    /// Locked-rotor reactance per phase at the test frequency, Ω.
    pub xlr: f64,
    /// An offset added to the friction regression's intercept, W (0 for
    /// the estimate; its interval's half-width for the propagation).
    pub pfw_offset: f64,
}

impl Inputs {
    /// The inputs as an array, in declaration order.
    pub fn to_array(self) -> [f64; 4] {
        [self.rs_dc, self.rlr, self.xlr, self.pfw_offset]
    }

    /// The inputs from an array in declaration order.
    pub fn from_array(a: [f64; 4]) -> Inputs {
        Inputs {
            rs_dc: a[0],
            rlr: a[1],
            xlr: a[2],
            pfw_offset: a[3],
        }
    }
}

/// What the reduction needs beside its inputs.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Context<'a> {
    /// The no-load readings.
    pub no_load: &'a [SupplyReading],
    /// The winding's connection.
    pub connection: Connection,
    /// `Rs(no-load temperature)/Rs(DC temperature)`.
    pub k_no_load: f64,
    /// `Rs(locked-rotor temperature)/Rs(DC temperature)`.
    pub k_locked: f64,
    /// No-load frequency over locked-rotor frequency.
    pub f_ratio: f64,
    /// Rated line voltage, V.
    pub rated_voltage: f64,
    /// The leakage split's convention.
    pub split: LeakageSplit,
}

/// The reduction's elements, Ω per phase; reactances at the no-load
/// frequency.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Solved {
    /// `Rs` at the locked-rotor test's temperature.
    pub rs: f64,
    /// Stator leakage reactance.
    pub xs: f64,
    /// Rotor leakage reactance.
    pub xr: f64,
    /// Rotor resistance (at the locked-rotor frequency).
    pub rr: f64,
    /// Magnetising reactance at rated voltage.
    pub xm: f64,
    /// Half-width of the `Xm(V)` curve's interval at rated voltage.
    pub xm_curve_half_width: Option<f64>,
    /// Core-loss resistance at rated voltage, when the core loss is > 0.
    pub rfe: Option<f64>,
    /// Half-width of the interval of the `Rfe` regression near rated
    /// voltage (two readings there or more).
    pub rfe_fit_half_width: Option<f64>,
    /// Core loss at rated voltage, W.
    pub pfe: Option<f64>,
    /// Friction and windage used (the intercept plus the offset, ≥ 0), W.
    pub pfw: f64,
    /// The friction intercept before it was held at ≥ 0, W.
    pub pfw_raw: f64,
    /// Half-width of the friction intercept's 95 % interval.
    pub pfw_half_width: Option<f64>,
    /// Why the friction regression used every reading, when it did.
    pub friction_note: Option<String>,
    /// The no-load table.
    pub rows: Vec<NoLoadRow>,
    /// The fitted `Xm(V)`.
    pub curve: Option<XmCurve>,
}

/// The magnetising branch at rated voltage, Ω at the no-load frequency.
struct Magnetising {
    /// The no-load table.
    table: Vec<NoLoadRow>,
    /// The fitted `Xm(V)`.
    curve: XmCurve,
    /// `Xm` and the half-width of the curve's interval.
    xm: (f64, Option<f64>),
    /// `Rfe` and the half-width of its regression's interval.
    rfe: Option<(f64, Option<f64>)>,
    /// Core loss `3·E²/Rfe`, W.
    pfe: Option<f64>,
}

fn magnetising(
    ctx: &Context,
    rs_nl: f64,
    xs_nl: f64,
    pfw: f64,
    used: &[bool],
) -> Result<Magnetising, StandardTestsError> {
    let table = rows(ctx.no_load, ctx.connection, rs_nl, xs_nl, pfw, used)?;
    let (curve, xm, hw) = xm_curve(&table, ctx.rated_voltage)
        .ok_or(StandardTestsError::NoMagnetising { xs: xs_nl })?;
    if xm.is_nan() || xm <= 0.0 {
        return Err(StandardTestsError::XmNotPositive { xm });
    }
    let rfe = rfe_at_rated(&table, ctx.rated_voltage);
    let e = interpolate(&table, ctx.rated_voltage, |r| Some(r.air_gap_voltage));
    let pfe = rfe.zip(e).map(|((r, _), e)| 3.0 * e * e / r);
    Ok(Magnetising {
        table,
        curve,
        xm: (xm, hw),
        rfe,
        pfe,
    })
}

/// The reduction at `inputs`.
pub(super) fn solve(ctx: &Context, inputs: Inputs) -> Result<Solved, StandardTestsError> {
    let rs_nl = inputs.rs_dc * ctx.k_no_load;
    let rs_lr = inputs.rs_dc * ctx.k_locked;
    let fr = friction(ctx.no_load, ctx.connection, rs_nl, ctx.rated_voltage)?;
    let pfw_raw = fr.pfw + inputs.pfw_offset;
    let pfw = pfw_raw.max(0.0);
    // The rotor branch with `xs` (Ω at the locked-rotor frequency).
    let branch = |xs: f64| -> Result<(C64, Magnetising), StandardTestsError> {
        let m = magnetising(ctx, rs_nl, xs * ctx.f_ratio, pfw, &fr.used)?;
        let xm = m.xm.0 / ctx.f_ratio;
        let ym = C64::new(m.rfe.map_or(0.0, |r| 1.0 / r.0), -1.0 / xm);
        let zr = rotor_branch(inputs.rlr, inputs.xlr, rs_lr, xs, ym).ok_or(
            StandardTestsError::NoRotorBranch {
                rlr: inputs.rlr,
                xlr: inputs.xlr,
                rs: rs_lr,
                xs,
                xm,
            },
        )?;
        Ok((zr, m))
    };
    let ratio = ctx.split.ratio();
    let (mut lo, mut hi) = (0.0, inputs.xlr);
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (lo + hi);
        match branch(mid) {
            Ok((zr, _)) if mid < ratio * zr.im => lo = mid,
            _ => hi = mid,
        }
    }
    let xs = lo;
    let (zr, m) = branch(xs)?;
    Ok(Solved {
        rs: rs_lr,
        xs: xs * ctx.f_ratio,
        xr: zr.im * ctx.f_ratio,
        rr: zr.re,
        xm: m.xm.0,
        xm_curve_half_width: m.xm.1,
        rfe: m.rfe.map(|r| r.0),
        rfe_fit_half_width: m.rfe.and_then(|r| r.1),
        pfe: m.pfe,
        pfw,
        pfw_raw,
        pfw_half_width: fr.half_width,
        friction_note: fr.note,
        rows: m.table,
        curve: Some(m.curve),
    })
}

/// The elements whose intervals [`propagate`] gives, in this order.
pub(super) fn elements(s: &Solved) -> [f64; 8] {
    [
        s.rs,
        s.xs,
        s.xr,
        s.rr,
        s.xm,
        s.rfe.unwrap_or(f64::NAN),
        s.pfe.unwrap_or(f64::NAN),
        s.pfw,
    ]
}

/// Half-widths of the 95 % intervals of [`elements`], from the inputs'
/// half-widths `hw` (0 where an input has none) by first derivatives
/// (central differences), summed in quadrature; `None` for an element
/// whose derivative could not be taken.
pub(super) fn propagate(ctx: &Context, at: Inputs, hw: [f64; 4]) -> [Option<f64>; 8] {
    let mut sum = [0.0f64; 8];
    let mut ok = [true; 8];
    for (k, &h) in hw.iter().enumerate() {
        if h <= 0.0 {
            continue;
        }
        let shifted = |sign: f64| {
            let mut a = at.to_array();
            a[k] += sign * h;
            solve(ctx, Inputs::from_array(a)).ok().map(|s| elements(&s))
        };
        match (shifted(1.0), shifted(-1.0)) {
            (Some(up), Some(down)) => {
                for j in 0..8 {
                    let d = 0.5 * (up[j] - down[j]);
                    if d.is_finite() {
                        sum[j] += d * d;
                    } else {
                        ok[j] = false;
                    }
                }
            }
            _ => ok = [false; 8],
        }
    }
    std::array::from_fn(|j| ok[j].then(|| sum[j].sqrt()))
}
