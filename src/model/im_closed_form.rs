//! The seed paper's closed forms of the induction-machine slip curves
//! (Eqs. 1–14) and the analytic derivatives of its appendix.
//!
//! The paper writes the input impedance per phase as a ratio of real terms:
//! `Z = (A + jB)/(C − jD)`, so that `|I| = V·√((C²+D²)/(A²+B²))` (Eq. 1) and
//! `P = 3V²·(AC − BD)/(A²+B²)` (Eq. 2), `V` being the voltage across one
//! winding (see [`super::im`] on "line voltage"). Single cage with iron
//! loss: Eqs. 4–7; double cage without iron loss: Eqs. 9–12 with the
//! slip-dependent rotor resistance and reactance of Eqs. 13–14.
//!
//! These forms exist to check the complex-impedance model
//! ([`super::ImCircuit`]) against the paper and to reproduce the appendix;
//! the estimators use the complex model, which covers every circuit.

/// The paper's four terms at one slip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperTerms {
    /// `A` (Eq. 4 or 9).
    pub a: f64,
    /// `B` (Eq. 5 or 10).
    pub b: f64,
    /// `C` (Eq. 6 or 11).
    pub c: f64,
    /// `D` (Eq. 7 or 12).
    pub d: f64,
}

impl PaperTerms {
    /// Eq. 1: RMS phase current for the phase voltage `v`.
    pub fn current(&self, v: f64) -> f64 {
        v * ((self.c * self.c + self.d * self.d) / (self.a * self.a + self.b * self.b)).sqrt()
    }

    /// Eq. 2: three-phase input power for the phase voltage `v`.
    pub fn power(&self, v: f64) -> f64 {
        3.0 * v * v * (self.a * self.c - self.b * self.d) / (self.a * self.a + self.b * self.b)
    }

    /// The appendix's `∂I/∂A, ∂I/∂B, ∂I/∂C, ∂I/∂D`.
    pub fn current_partials(&self, v: f64) -> [f64; 4] {
        let (a, b, c, d) = (self.a, self.b, self.c, self.d);
        let ab = a * a + b * b;
        let cd = (c * c + d * d).sqrt();
        [
            -v * cd * a / ab.powf(1.5),
            -v * cd * b / ab.powf(1.5),
            v * c / (cd * ab.sqrt()),
            v * d / (cd * ab.sqrt()),
        ]
    }

    /// The appendix's `∂P/∂A, ∂P/∂B, ∂P/∂C, ∂P/∂D`.
    pub fn power_partials(&self, v: f64) -> [f64; 4] {
        let (a, b, c, d) = (self.a, self.b, self.c, self.d);
        let ab = a * a + b * b;
        let v2 = v * v;
        let num = a * c - b * d;
        [
            3.0 * v2 * c / ab - 6.0 * v2 * num * a / (ab * ab),
            -3.0 * v2 * d / ab - 6.0 * v2 * num * b / (ab * ab),
            3.0 * v2 * a / ab,
            -3.0 * v2 * b / ab,
        ]
    }
}

/// Single cage with iron loss, Fig. 1 (values in Ω, slip `s > 0`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SingleCageForms {
    /// Stator resistance.
    pub rs: f64,
    /// Stator leakage reactance.
    pub xs: f64,
    /// Magnetising reactance.
    pub xm: f64,
    /// Iron-loss resistance.
    pub rfe: f64,
    /// Rotor resistance.
    pub rr: f64,
    /// Rotor leakage reactance.
    pub xr: f64,
}

impl SingleCageForms {
    /// Eqs. 4–7.
    pub fn terms(&self, s: f64) -> PaperTerms {
        let SingleCageForms {
            rs,
            xs,
            xm,
            rfe,
            rr,
            xr,
        } = *self;
        let c = rr / s + rfe * (1.0 + xr / xm);
        let d = rfe * rr / (s * xm) - xr;
        PaperTerms {
            a: xs * d + rs * c + rfe * rr / s,
            b: xs * c - rs * d + rfe * xr,
            c,
            d,
        }
    }

    /// Eq. 3: electromagnetic torque for the phase voltage `v`, `p` pole
    /// pairs, `w` the supply angular frequency.
    pub fn torque(&self, v: f64, s: f64, p: f64, w: f64) -> f64 {
        let t = self.terms(s);
        3.0 * v * v * p / w * self.rfe * self.rfe * self.rr / s / (t.a * t.a + t.b * t.b)
    }

    /// The appendix: `∂A, ∂B, ∂C, ∂D` with respect to the paper's θ of
    /// Eq. 17, `[Rr Xr Xs Rs Xm Rfe]`, one row per parameter.
    pub fn term_partials(&self, s: f64) -> [[f64; 4]; 6] {
        let SingleCageForms {
            rs,
            xs,
            xm,
            rfe,
            rr,
            xr,
        } = *self;
        let xm2 = xm * xm;
        [
            // Rr
            [
                xs * rfe / (xm * s) + rs / s + rfe / s,
                xs / s - rs * rfe / (xm * s),
                1.0 / s,
                rfe / (xm * s),
            ],
            // Xr
            [
                -xs + rs * rfe / xm,
                xs * rfe / xm + rs + rfe,
                rfe / xm,
                -1.0,
            ],
            // Xs
            [
                rfe * rr / (xm * s) - xr,
                rr / s + rfe * (1.0 + xr / xm),
                0.0,
                0.0,
            ],
            // Rs
            [
                rr / s + rfe * (1.0 + xr / xm),
                -rfe * rr / (xm * s) + xr,
                0.0,
                0.0,
            ],
            // Xm
            [
                -xs * rfe * rr / (xm2 * s) - rs * rfe * xr / xm2,
                -xs * rfe * xr / xm2 + rs * rfe * rr / (xm2 * s),
                -rfe * xr / xm2,
                -rfe * rr / (xm2 * s),
            ],
            // Rfe
            [
                xs * rr / (xm * s) + rs * (1.0 + xr / xm) + rr / s,
                xs * (1.0 + xr / xm) - rs * rr / (xm * s) + xr,
                1.0 + xr / xm,
                rr / (xm * s),
            ],
        ]
    }

    /// Eqs. 28–33: `∂I/∂θ` for θ = `[Rr Xr Xs Rs Xm Rfe]`.
    pub fn current_gradient(&self, v: f64, s: f64) -> [f64; 6] {
        let t = self.terms(s);
        chain(t.current_partials(v), self.term_partials(s))
    }

    /// Eqs. 34–39: `∂P/∂θ` for θ = `[Rr Xr Xs Rs Xm Rfe]`.
    pub fn power_gradient(&self, v: f64, s: f64) -> [f64; 6] {
        let t = self.terms(s);
        chain(t.power_partials(v), self.term_partials(s))
    }
}

fn chain(outer: [f64; 4], inner: [[f64; 4]; 6]) -> [f64; 6] {
    inner.map(|row| row.iter().zip(outer).map(|(a, b)| a * b).sum())
}

/// Double cage without iron loss, Fig. 2 (values in Ω, slip `s > 0`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DoubleCageForms {
    /// Stator resistance.
    pub rs: f64,
    /// Stator leakage reactance.
    pub xs: f64,
    /// Magnetising reactance.
    pub xm: f64,
    /// Cage 1 resistance.
    pub rr1: f64,
    /// Cage 2 resistance.
    pub rr2: f64,
    /// Cage 1 leakage reactance.
    pub xr1: f64,
    /// Cage 2 leakage reactance.
    pub xr2: f64,
}

impl DoubleCageForms {
    /// Eqs. 13–14: the equivalent rotor resistance `Rr(s)` (the rotor
    /// branch is `Rr(s)/s + jXr(s)`) and reactance `Xr(s)`.
    pub fn rotor(&self, s: f64) -> (f64, f64) {
        let DoubleCageForms {
            rr1, rr2, xr1, xr2, ..
        } = *self;
        let s2 = s * s;
        let den = (rr1 + rr2).powi(2) + (xr1 + xr2).powi(2) * s2;
        let r = (rr1 * rr2 * (rr1 + rr2) + (rr1 * xr2 * xr2 + rr2 * xr1 * xr1) * s2) / den;
        let x = (xr1 * xr2 * (xr1 + xr2) * s2 + rr1 * rr1 * xr2 + rr2 * rr2 * xr1) / den;
        (r, x)
    }

    /// Eqs. 9–12.
    pub fn terms(&self, s: f64) -> PaperTerms {
        let (rr, xr) = self.rotor(s);
        let DoubleCageForms { rs, xs, xm, .. } = *self;
        PaperTerms {
            a: rs * (1.0 + xr / xm) + (1.0 + xs / xm) * rr / s,
            b: xr + xs * (1.0 + xr / xm) - rs * (rr / s / xm),
            c: 1.0 + xr / xm,
            d: rr / s / xm,
        }
    }

    /// Eq. 8: electromagnetic torque.
    pub fn torque(&self, v: f64, s: f64, p: f64, w: f64) -> f64 {
        let t = self.terms(s);
        let (rr, _) = self.rotor(s);
        3.0 * v * v * p / w * (rr / s) / (t.a * t.a + t.b * t.b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::im_fixtures::supply;
    use crate::model::{Connection, ImCircuit, RotorCage};

    const FE: SingleCageForms = SingleCageForms {
        rs: 1.93,
        xs: 1.658,
        xm: 38.7,
        rfe: 310.0,
        rr: 3.84,
        xr: 6.789,
    };

    fn fe_circuit() -> ImCircuit {
        ImCircuit {
            rs: FE.rs,
            xs: FE.xs,
            xm: FE.xm,
            rfe: Some(FE.rfe),
            rotor: RotorCage::Single {
                rr: FE.rr,
                xr: FE.xr,
            },
        }
    }

    const DC: DoubleCageForms = DoubleCageForms {
        rs: 0.00778,
        xs: 0.123,
        xm: 4.3,
        rr1: 0.0693,
        rr2: 0.0132,
        xr1: 0.00843,
        xr2: 0.1162,
    };

    fn dc_circuit() -> ImCircuit {
        ImCircuit {
            rs: DC.rs,
            xs: DC.xs,
            xm: DC.xm,
            rfe: None,
            rotor: RotorCage::Double {
                rr1: DC.rr1,
                rr2: DC.rr2,
                xr1: DC.xr1,
                xr2: DC.xr2,
            },
        }
    }

    #[test]
    fn single_cage_forms_equal_the_complex_circuit() {
        // The paper's experimental machine (θ_N of Sec. V), on 220 V delta.
        let c = fe_circuit();
        let supply = supply(220.0, 60.0, Connection::Delta, 2);
        let w = std::f64::consts::TAU * 60.0;
        for s in [0.001, 0.02, 0.1, 0.5, 1.0] {
            let t = FE.terms(s);
            // Z = (A + jB)/(C − jD).
            let z = crate::model::C64::new(t.a, t.b) / crate::model::C64::new(t.c, -t.d);
            assert!((z - c.impedance(s)).norm() < 1e-9 * z.norm(), "s = {s}");
            let op = c.operating_point(&supply, s);
            assert!((t.current(220.0) - op.phase_current).abs() < 1e-9 * op.phase_current);
            assert!((t.power(220.0) - op.input_power).abs() < 1e-9 * op.input_power.abs());
            assert!((FE.torque(220.0, s, 2.0, w) - op.torque).abs() < 1e-9 * op.torque);
        }
    }

    #[test]
    fn double_cage_forms_equal_the_complex_circuit() {
        let c = dc_circuit();
        let supply = supply(1.0, 50.0, Connection::Delta, 1);
        let w = std::f64::consts::TAU * 50.0;
        for s in [0.002, 0.03, 0.2, 0.7, 1.0] {
            // Eqs. 13–14 against the parallel cages.
            let (rr, xr) = DC.rotor(s);
            let zr = c.rotor_impedance(s);
            assert!(
                (zr.re - rr / s).abs() < 1e-12 * zr.norm()
                    && (zr.im - xr).abs() < 1e-12 * zr.norm()
            );
            let t = DC.terms(s);
            let op = c.operating_point(&supply, s);
            assert!((t.current(1.0) - op.phase_current).abs() < 1e-10 * op.phase_current);
            assert!((t.power(1.0) - op.input_power).abs() < 1e-10 * op.input_power);
            assert!((DC.torque(1.0, s, 1.0, w) - op.torque).abs() < 1e-10 * op.torque);
        }
    }

    #[test]
    fn eqs_4_to_7_tend_to_eqs_9_to_12_without_iron_loss() {
        // Sec. IV simulates the double cage with "Eqs. (1) and (4)–(7)": those
        // are the single-cage iron-loss terms; they reduce to Eqs. 9–12 (all
        // four terms divided by Rfe) when Rfe → ∞ and Rr, Xr follow Eqs. 13–14.
        let s = 0.1;
        let (rr, xr) = DC.rotor(s);
        let rfe = 1e12;
        let f = SingleCageForms {
            rs: DC.rs,
            xs: DC.xs,
            xm: DC.xm,
            rfe,
            rr,
            xr,
        }
        .terms(s);
        let d = DC.terms(s);
        for (x, y) in [(f.a, d.a), (f.b, d.b), (f.c, d.c), (f.d, d.d)] {
            assert!((x / rfe - y).abs() < 1e-9 * y.abs().max(1.0), "{x} vs {y}");
        }
    }

    #[test]
    fn appendix_derivatives_match_finite_differences_and_the_complex_model() {
        let v = 220.0;
        // The appendix's rows are the paper's θ of Eq. 17.
        let order = crate::machine::im::identify::THETA_SINGLE_FE_L6;
        let c = fe_circuit();
        for s in [0.005, 0.05, 0.3, 1.0] {
            let gi = FE.current_gradient(v, s);
            let gp = FE.power_gradient(v, s);
            // Finite differences on Eqs. 1–2.
            let vals = [FE.rr, FE.xr, FE.xs, FE.rs, FE.xm, FE.rfe];
            for k in 0..6 {
                let h = vals[k] * 1e-6;
                let mk = |dv: f64| {
                    let mut x = vals;
                    x[k] += dv;
                    SingleCageForms {
                        rr: x[0],
                        xr: x[1],
                        xs: x[2],
                        rs: x[3],
                        xm: x[4],
                        rfe: x[5],
                    }
                    .terms(s)
                };
                let fdi = (mk(h).current(v) - mk(-h).current(v)) / (2.0 * h);
                let fdp = (mk(h).power(v) - mk(-h).power(v)) / (2.0 * h);
                assert!(
                    (fdi - gi[k]).abs() < 1e-6 * gi[k].abs().max(1e-6),
                    "dI/d{}",
                    order[k]
                );
                assert!(
                    (fdp - gp[k]).abs() < 1e-6 * gp[k].abs().max(1e-3),
                    "dP/d{}",
                    order[k]
                );
            }
            // The complex model's gradient: dI = −V·Re(conj(Z)·dZ)/|Z|³,
            // dP = −3V²·Re(dZ/Z²).
            let (z, dz) = c.impedance_gradient(s, &order);
            for k in 0..6 {
                let di = -v * (z.conj() * dz[k]).re / z.norm().powi(3);
                let dp = -3.0 * v * v * (dz[k] / (z * z)).re;
                assert!((di - gi[k]).abs() < 1e-9 * gi[k].abs().max(1e-9));
                assert!((dp - gp[k]).abs() < 1e-9 * gp[k].abs().max(1e-6));
            }
        }
    }
}
