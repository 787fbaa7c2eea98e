//! A motor lab's record of a small three-phase induction machine, as a
//! test and benchmark fixture: the record shape a lab takes for IEEE 112 /
//! IEC 60034-28 work, imported as three `im_slip_sweep` segments.
//!
//! - **load curve** at rated voltage: the shaft loaded from a light load to
//!   150 % of rated torque, slip from the measured speed (an encoder read
//!   to 0.1 rpm) and the shaft torque measured;
//! - **locked rotor** at reduced voltage: slip 1, a few voltages;
//! - **no-load voltage sweep** from 80 % to 115 % of rated voltage, the
//!   shaft uncoupled: the slip is not measured and is written as 0, as a
//!   user importing the test would write it.
//!
//! The machine is richer than any circuit the fits use: main-flux
//! saturation (magnetising current `E/Xm0·(1 + a·(E/E0)^m)`), a core loss
//! `P_fe ∝ E^β` (Steinmetz at fixed frequency), and friction and windage
//! `∝ ω²` taken from the shaft (so the uncoupled rotor runs at the slip
//! where the air-gap power covers them, not at 0). Meters: relative
//! Gaussian errors on voltage and current, on power a share of the reading
//! plus a share of the apparent power (a power analyser's range error, which
//! dominates at the no-load power factor), on torque a share of full scale.

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use super::im::C64;

/// The lab machine: per-phase circuit (star), Ω at 50 Hz, and its losses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabMachine {
    /// Stator resistance at the test temperature (the DC reading), Ω.
    pub rs: f64,
    /// Stator leakage reactance, Ω.
    pub xs: f64,
    /// Unsaturated magnetising reactance, Ω.
    pub xm0: f64,
    /// Saturation: magnetising current is `E/Xm0·(1 + a·(E/E0)^m)`, this `a`.
    pub sat_a: f64,
    /// Saturation exponent `m`.
    pub sat_m: f64,
    /// Rotor resistance (referred), Ω.
    pub rr: f64,
    /// Rotor leakage reactance (referred), Ω.
    pub xr: f64,
    /// Core loss at rated air-gap voltage `E0`, W (three phases).
    pub core_loss: f64,
    /// Steinmetz exponent of the core loss in `E`.
    pub core_beta: f64,
    /// Friction and windage at synchronous speed, W (`∝ ω²`).
    pub friction_windage: f64,
    /// Rated line voltage, V.
    pub rated_voltage: f64,
    /// Rated output, W.
    pub rated_power: f64,
    /// Rated shaft torque, N·m.
    pub rated_torque: f64,
    /// Supply frequency, Hz.
    pub frequency: f64,
    /// Pole pairs.
    pub pole_pairs: u32,
}

/// Meter errors of the lab, relative (1 σ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabMeters {
    /// Voltage, of reading.
    pub voltage: f64,
    /// Current, of reading.
    pub current: f64,
    /// Power, of reading.
    pub power: f64,
    /// Power, of the apparent power `√3·V·I` (range error).
    pub power_range: f64,
    /// Torque, of full scale (twice rated torque).
    pub torque_fs: f64,
    /// Speed, rpm (1 σ, then read to 0.1 rpm).
    pub speed_rpm: f64,
}

impl Default for LabMeters {
    fn default() -> Self {
        LabMeters {
            voltage: 0.001,
            current: 0.002,
            power: 0.002,
            power_range: 0.0005,
            torque_fs: 0.001,
            speed_rpm: 0.2,
        }
    }
}

/// One reading of the lab record (line values).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabPoint {
    /// Slip as recorded (measured, 1 at locked rotor, 0 where not measured).
    pub slip: f64,
    /// The true slip.
    pub true_slip: f64,
    /// Line voltage, V.
    pub line_voltage: f64,
    /// Line current, A.
    pub line_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Shaft torque, N·m, where measured.
    pub torque: Option<f64>,
}

/// One segment (one CSV file) of the lab record.
#[derive(Debug, Clone, PartialEq)]
pub struct LabSegment {
    /// Label: `load`, `locked_rotor` or `no_load`.
    pub label: &'static str,
    /// The readings in recording order.
    pub points: Vec<LabPoint>,
}

/// Terminal values of the lab machine at one true slip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabTerminal {
    /// Phase current, A.
    pub phase_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Air-gap voltage, V (phase).
    pub air_gap_voltage: f64,
    /// Air-gap power, W.
    pub air_gap_power: f64,
    /// Shaft torque (after friction and windage), N·m.
    pub shaft_torque: f64,
}

/// Root of `f` increasing on `[lo, hi]` by bisection (a fixed number of
/// halvings: bounded and deterministic).
fn bisect(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-15 * hi.abs().max(1e-300) {
            break;
        }
    }
    0.5 * (lo + hi)
}

impl LabMachine {
    /// A 1.5 kW, 400 V star, 4-pole, 50 Hz machine: DC stator resistance
    /// 3.8 Ω, no-load current rising about as `V^2.6` around rated voltage,
    /// no-load losses (core, friction and windage) about 16 % of rated
    /// output.
    pub fn small_motor() -> LabMachine {
        LabMachine {
            rs: 3.8,
            xs: 5.2,
            xm0: 125.0,
            sat_a: 0.5,
            sat_m: 6.0,
            rr: 3.3,
            xr: 7.8,
            core_loss: 70.0,
            core_beta: 2.0,
            friction_windage: 170.0,
            rated_voltage: 400.0,
            rated_power: 1500.0,
            rated_torque: 10.0,
            frequency: 50.0,
            pole_pairs: 2,
        }
    }

    /// Rated phase voltage (star), V.
    pub fn rated_phase_voltage(&self) -> f64 {
        self.rated_voltage / 3f64.sqrt()
    }

    /// Synchronous speed, rad/s.
    pub fn synchronous_speed(&self) -> f64 {
        2.0 * std::f64::consts::PI * self.frequency / self.pole_pairs as f64
    }

    /// Magnetising and core-loss admittance at air-gap voltage `e`.
    fn magnetising(&self, e: f64) -> C64 {
        let e0 = 0.93 * self.rated_phase_voltage();
        let u = (e / e0).max(0.0);
        let b = (1.0 + self.sat_a * u.powf(self.sat_m)) / self.xm0;
        let g = self.core_loss / 3.0 * u.powf(self.core_beta) / (e * e).max(1e-300);
        C64::new(g, -b)
    }

    /// Terminal values at true slip `s` and phase voltage `v`.
    pub fn terminal(&self, s: f64, v: f64) -> LabTerminal {
        let zs = C64::new(self.rs, self.xs);
        let y_r = C64::new(s, 0.0) / C64::new(self.rr, s * self.xr);
        let y_ag = |e: f64| self.magnetising(e) + y_r;
        // V = E·|1 + Zs·Y_ag(E)|, increasing in E.
        let e = bisect(
            |e| e * (C64::new(1.0, 0.0) + zs * y_ag(e)).norm() - v,
            0.0,
            v,
        );
        let i = y_ag(e) * e;
        let p_ag = 3.0 * e * e * y_r.re;
        let ws = self.synchronous_speed();
        let w = (1.0 - s) * ws;
        // Friction and windage ∝ ω²: torque ∝ ω.
        let t_fw = self.friction_windage / ws * (w / ws);
        LabTerminal {
            phase_current: i.norm(),
            input_power: 3.0 * e * e * y_ag(e).re + 3.0 * i.norm_sqr() * self.rs,
            air_gap_voltage: e,
            air_gap_power: p_ag,
            shaft_torque: p_ag / ws - t_fw,
        }
    }

    /// The true slip at which the shaft delivers `torque` (0: uncoupled).
    pub fn slip_at_torque(&self, torque: f64, v: f64) -> f64 {
        bisect(|s| self.terminal(s, v).shaft_torque - torque, 0.0, 0.5)
    }

    /// The lab record in the order the lab took it: the no-load sweep
    /// (`no_load_points` readings from 115 % down to 80 % of rated
    /// voltage), the load curve (`load_points` readings at
    /// rated voltage, from 150 % down to 10 % of rated torque, as IEEE 112
    /// takes it), then `locked_points` locked-rotor readings at 10–25 % of
    /// rated voltage; meter noise from `seed`.
    pub fn lab_record(
        &self,
        load_points: usize,
        locked_points: usize,
        no_load_points: usize,
        meters: &LabMeters,
        seed: u64,
    ) -> Vec<LabSegment> {
        let mut rng = StdRng::seed_from_u64(seed);
        let v_rated = self.rated_phase_voltage();
        let ns_rpm = 60.0 * self.frequency / self.pole_pairs as f64;
        let spread = |n: usize, lo: f64, hi: f64| -> Vec<f64> {
            (0..n)
                .map(|k| {
                    let u = if n > 1 {
                        k as f64 / (n - 1) as f64
                    } else {
                        0.0
                    };
                    hi - (hi - lo) * u
                })
                .collect()
        };
        let read = |x: f64, sigma: f64, rng: &mut StdRng| x + sigma * gaussian(rng);
        let segment = |label: &'static str,
                       settings: Vec<(f64, f64)>,
                       slip_read: &dyn Fn(f64, &mut StdRng) -> f64,
                       torque_read: bool,
                       rng: &mut StdRng| {
            let points = settings
                .into_iter()
                .map(|(s, v)| {
                    let t = self.terminal(s, v);
                    let line_v = v * 3f64.sqrt();
                    let line_i = t.phase_current;
                    let apparent = 3f64.sqrt() * line_v * line_i;
                    LabPoint {
                        slip: slip_read(s, rng),
                        true_slip: s,
                        line_voltage: read(line_v, meters.voltage * line_v, rng),
                        line_current: read(line_i, meters.current * line_i, rng),
                        input_power: read(
                            t.input_power,
                            meters.power * t.input_power.abs() + meters.power_range * apparent,
                            rng,
                        ),
                        torque: torque_read.then(|| {
                            read(
                                t.shaft_torque,
                                meters.torque_fs * 2.0 * self.rated_torque,
                                rng,
                            )
                        }),
                    }
                })
                .collect();
            LabSegment { label, points }
        };
        let measured_slip = |s: f64, rng: &mut StdRng| {
            let n = (1.0 - s) * ns_rpm + meters.speed_rpm * gaussian(rng);
            let n = (n * 10.0).round() / 10.0;
            ((ns_rpm - n) / ns_rpm).clamp(0.0, 1.0)
        };
        let load: Vec<(f64, f64)> = spread(load_points, 0.1, 1.5)
            .into_iter()
            .map(|k| (self.slip_at_torque(k * self.rated_torque, v_rated), v_rated))
            .collect();
        let locked: Vec<(f64, f64)> = spread(locked_points, 0.10, 0.25)
            .into_iter()
            .rev()
            .map(|k| (1.0, k * v_rated))
            .collect();
        let no_load: Vec<(f64, f64)> = spread(no_load_points, 0.8, 1.15)
            .into_iter()
            .map(|k| (self.slip_at_torque(0.0, k * v_rated), k * v_rated))
            .collect();
        vec![
            segment("no_load", no_load, &|_, _| 0.0, false, &mut rng),
            segment("load", load, &measured_slip, true, &mut rng),
            segment("locked_rotor", locked, &|_, _| 1.0, true, &mut rng),
        ]
    }
}

impl LabSegment {
    /// The segment as an `im_slip_sweep` CSV file (segment `index`).
    pub fn to_csv(&self, index: u32, frequency: f64) -> String {
        let torque = self.points.iter().all(|p| p.torque.is_some());
        let mut out = format!(
            "# motorbench segment {index} kind=im_slip_sweep label={}\n",
            self.label
        );
        out.push_str("slip,line_voltage_V,line_current_A,input_power_W,frequency_Hz");
        out.push_str(if torque { ",torque_Nm\n" } else { "\n" });
        for p in &self.points {
            out.push_str(&format!(
                "{:.6},{:.3},{:.5},{:.3},{frequency}",
                p.slip, p.line_voltage, p.line_current, p.input_power
            ));
            if let (true, Some(t)) = (torque, p.torque) {
                out.push_str(&format!(",{t:.4}"));
            }
            out.push('\n');
        }
        out
    }
}

/// A standard normal draw (Box–Muller; `rand` alone, no distribution crate).
fn gaussian(rng: &mut StdRng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_machine_has_the_lab_record_features() {
        let m = LabMachine::small_motor();
        let v = m.rated_phase_voltage();
        // No-load current against voltage: the log-log slope over 80–115 %.
        let i_at = |k: f64| {
            m.terminal(m.slip_at_torque(0.0, k * v), k * v)
                .phase_current
        };
        let slope = (i_at(1.15) / i_at(0.8)).ln() / (1.15f64 / 0.8).ln();
        assert!(
            (2.3..2.9).contains(&slope),
            "no-load current ∝ V^{slope:.2}"
        );
        // No-load input power: core, friction and windage and copper.
        let s0 = m.slip_at_torque(0.0, v);
        let nl = m.terminal(s0, v);
        let share = nl.input_power / m.rated_power;
        assert!(
            (0.14..0.22).contains(&share),
            "no-load power {share:.3} of rated"
        );
        // The uncoupled rotor runs at a small slip that covers the friction.
        assert!(s0 > 1e-4 && s0 < 0.01, "no-load slip {s0}");
        // Rated torque at a plausible rated slip.
        let sr = m.slip_at_torque(m.rated_torque, v);
        assert!((0.02..0.08).contains(&sr), "rated slip {sr}");
    }

    #[test]
    fn the_record_has_three_segments_of_the_asked_sizes_in_lab_order() {
        let m = LabMachine::small_motor();
        let segs = m.lab_record(125, 6, 10, &LabMeters::default(), 1);
        let sizes: Vec<usize> = segs.iter().map(|s| s.points.len()).collect();
        assert_eq!(sizes, vec![10, 125, 6]);
        assert!(segs[2].points.iter().all(|p| p.slip == 1.0));
        assert!(segs[0]
            .points
            .iter()
            .all(|p| p.slip == 0.0 && p.true_slip > 0.0));
        let csv = segs[0].to_csv(0, 50.0);
        assert!(csv.starts_with("# motorbench segment 0 kind=im_slip_sweep label=no_load\n"));
        assert_eq!(csv.lines().count(), 12);
    }
}
