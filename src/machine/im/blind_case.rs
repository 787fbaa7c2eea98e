//! A blind IM case: a random machine's slip sweeps with one withheld
//! effect (or none), measured by meter-like instruments.
//!
//! - Machine: a random rating (1–50 kW, log-uniform; 2, 4 or 6 poles;
//!   50 Hz at 400 or 230 V, 60 Hz at 460 or 230 V; star or delta) and
//!   per-unit elements in the ranges of industrial cage machines (`rs`
//!   0.015–0.05, `rr` 0.015–0.045, total leakage 0.12–0.22 split 40–60 %
//!   to the stator, `xm` 1.8–3.5 at rated flux). The nameplate, with the
//!   connection, goes to the record's metadata.
//! - Plan: one to three sweeps (rated voltage first, then 55–85 % of it),
//!   20–40 points from near synchronous (slip 0.002–0.01) to locked rotor,
//!   denser near synchronous. Main-flux and leakage saturation show only
//!   across voltages, so their plans always hold a second voltage (what a
//!   careful engineer testing for saturation would run).
//! - A no-load test in 40 % of the plans (plan `sweep_no_load`), after
//!   the sweeps: 6–10 readings from 30–80 % to 105–115 % of rated
//!   voltage, the machine running free against friction and windage of
//!   0.5–2 % of its rating (at the slip where its rotor delivers them,
//!   found by root search), slip not recorded.
//! - Meters: current 0.05–0.4 % of reading, power 0.1–0.8 % of reading,
//!   voltage 0.03–0.15 %, each plus quantisation to a 4½-digit autoranging
//!   display (one or ten counts of the reading's decade range); the supply voltage itself wanders by
//!   0.1 %.
//!
//! `truth.noise_floor` compares the readings with the truth evaluated at
//! the voltage as read (the contract's ŷ takes the measured input), so it
//! holds the voltage meter's share of the noise too.
//!
//! The generator's effect models are deliberately a little richer than the
//! diagnosis' candidates (see `docs/diagnosis-im.md` for the ranges):
//! iron loss with a Steinmetz exponent (Rfe varies with E), deep bar as
//! the exact skin effect of a rectangular bar on part of the rotor
//! resistance and leakage, main-flux saturation with a random exponent,
//! leakage saturation with a knee (flux linear up to a knee current, then a
//! smaller slope, the bend smoothed over 15–40 % of the knee current; the
//! candidate fixes it at 25 %), stray load loss with a random power of the rotor current
//! drawn as extra in-phase current, and thermal drift from a first-order
//! thermal model of stator and rotor over the test's real timing (dwell per
//! point, pauses between sweeps).

use std::collections::BTreeMap;

use rand::rngs::StdRng;
use rand::RngExt;
use rand_distr::{Distribution, Normal};

use super::diagnose::effects::{increasing_root, leakage_factor, skin_effect as skin};
use super::COPPER_ALPHA;
use crate::diagnose::blind::{BlindRecord, CaseTruth};
use crate::model::{Connection, Effect, C64};
use crate::record::{
    ImStandardTests, OperatingPoint, Record, SegmentKind, SupplyReading, TestMeta, SCHEMA_VERSION,
};

/// Share of the plans with a no-load test beside the sweeps.
const NO_LOAD_SHARE: f64 = 0.4;

/// Temperature coefficient of aluminium (cage), 1/K.
const ALPHA_AL: f64 = 0.00403;

/// The withheld effect as the generator models it.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Truth {
    None,
    IronLoss {
        p_fe_rated: f64,
        beta: f64,
        e_rated: f64,
    },
    DeepBar {
        xi1: f64,
        bar_r: f64,
        bar_x: f64,
    },
    MainFlux {
        es: f64,
        n: f64,
    },
    Leakage {
        knee: f64,
        slope: f64,
        width: f64,
    },
    Stray {
        c: f64,
        gamma: f64,
    },
    Thermal,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Machine {
    rs: f64,
    xs: f64,
    xm: f64,
    rr: f64,
    xr: f64,
}

/// Thermal state: resistance factors of stator and rotor.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Heat {
    rs: f64,
    rr: f64,
}

/// True phase current, power, rotor current at slip `s`, phase voltage `v`.
fn terminal(m: &Machine, truth: &Truth, heat: Heat, s: f64, v: f64) -> (f64, f64, f64) {
    let rs = m.rs * heat.rs;
    let rr = m.rr * heat.rr;
    let zs = C64::new(rs, m.xs);
    let y_r = |rr: f64, xr: f64| C64::new(s, 0.0) / C64::new(rr, s * xr);
    // Air-gap solution for a magnetising admittance that depends on E.
    let solve_e = |y_m: &dyn Fn(f64) -> C64, yr: C64| -> (f64, f64, f64) {
        let g = |e: f64| e * (C64::new(1.0, 0.0) + zs * (y_m(e) + yr)).norm() - v;
        let mut hi = v;
        while g(hi) < 0.0 {
            hi *= 2.0;
        }
        let e = increasing_root(g, 1e-9 * v, hi).unwrap_or(v);
        let y = y_m(e) + yr;
        (
            e * y.norm(),
            3.0 * e * e * (y.re + rs * y.norm_sqr()),
            e * yr.norm(),
        )
    };
    let linear = |xs: f64, xr: f64, rr: f64| {
        let yr = y_r(rr, xr);
        let y = C64::new(0.0, -1.0 / m.xm) + yr;
        let z = C64::new(rs, xs) + y.inv();
        let i = C64::new(v, 0.0) / z;
        let e = C64::new(v, 0.0) - i * C64::new(rs, xs);
        (
            i.norm(),
            3.0 * (C64::new(v, 0.0) * i.conj()).re,
            (e * yr).norm(),
        )
    };
    match *truth {
        Truth::None | Truth::Thermal => linear(m.xs, m.xr, rr),
        Truth::IronLoss {
            p_fe_rated,
            beta,
            e_rated,
        } => solve_e(
            &|e: f64| {
                // P_fe = p_fe_rated·(E/E_rated)^β over three phases.
                let p = p_fe_rated * (e / e_rated).powf(beta);
                C64::new(p / (3.0 * e * e).max(1e-300), -1.0 / m.xm)
            },
            y_r(rr, m.xr),
        ),
        Truth::DeepBar { xi1, bar_r, bar_x } => {
            let (kr, kx) = skin(xi1 * s.sqrt());
            linear(
                m.xs,
                m.xr * (1.0 - bar_x + bar_x * kx),
                rr * (1.0 - bar_r + bar_r * kr),
            )
        }
        Truth::MainFlux { es, n } => solve_e(
            &|e: f64| C64::new(0.0, -(1.0 + (e / es).powf(n)) / m.xm),
            y_r(rr, m.xr),
        ),
        Truth::Leakage { knee, slope, width } => {
            // Leakage flux linear up to the knee, then rising with
            // `slope` of its initial slope; the bend spread over `width` of
            // the knee current.
            let f = |i: f64| leakage_factor(i, knee, slope, width);
            let h = |i: f64| {
                let (ii, _, _) = linear(m.xs * f(i), m.xr * f(i), rr);
                // I·|Z(I)| − V with |Z(I)| = V/I(I).
                i * v / ii - v
            };
            let lo = linear(m.xs, m.xr, rr).0;
            let mut hi = 2.0 * lo;
            while h(hi) < 0.0 {
                hi *= 2.0;
            }
            let i = increasing_root(h, lo, hi).unwrap_or(lo);
            linear(m.xs * f(i), m.xr * f(i), rr)
        }
        Truth::Stray { c, gamma } => {
            let yr = y_r(rr, m.xr);
            let y = C64::new(0.0, -1.0 / m.xm) + yr;
            let z = C64::new(rs, m.xs) + y.inv();
            let i = C64::new(v, 0.0) / z;
            let e = C64::new(v, 0.0) - i * C64::new(rs, m.xs);
            let ir = (e * yr).norm();
            // The loss is drawn from the supply as in-phase current.
            let p_sll = c * ir.powf(gamma);
            let i_total = i + C64::new(p_sll / (3.0 * v), 0.0);
            (
                i_total.norm(),
                3.0 * (C64::new(v, 0.0) * i_total.conj()).re,
                ir,
            )
        }
    }
}

fn uniform(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

fn gaussian(rng: &mut StdRng, sigma: f64) -> f64 {
    Normal::new(0.0, sigma.max(0.0)).map_or(0.0, |d| d.sample(rng))
}

/// A meter: σ = `relative`·|reading|, then rounded to the resolution of
/// a 4½-digit (20 000-count) autoranging display: `counts` counts of the
/// decade range the reading falls in.
#[derive(Debug, Clone, Copy)]
struct Meter {
    relative: f64,
    counts: f64,
}

impl Meter {
    fn random(rng: &mut StdRng, rel: (f64, f64)) -> Meter {
        Meter {
            relative: uniform(rng, rel.0, rel.1),
            counts: if rng.random::<f64>() < 0.5 { 1.0 } else { 10.0 },
        }
    }

    fn step(&self, x: f64) -> f64 {
        let range = 10f64.powf(x.abs().max(1e-9).log10().ceil());
        self.counts * range / 20_000.0
    }

    fn read(&self, rng: &mut StdRng, x: f64) -> f64 {
        let noisy = x + gaussian(rng, self.relative * x.abs());
        let step = self.step(noisy);
        (noisy / step).round() * step
    }
}

/// Simulate one IM slip-sweep record with `effect` withheld (None: no effect).
pub fn simulate_im_case(effect: Option<Effect>, rng: &mut StdRng) -> BlindRecord {
    // Rating.
    let power = (1000f64.ln() + (50f64.ln()) * rng.random::<f64>()).exp();
    let poles: u32 = [2, 4, 4, 6][rng.random_range(0..4)];
    let (frequency, line_v) = if rng.random::<f64>() < 0.6 {
        (
            50.0,
            if rng.random::<f64>() < 0.7 {
                400.0
            } else {
                230.0
            },
        )
    } else {
        (
            60.0,
            if rng.random::<f64>() < 0.7 {
                460.0
            } else {
                230.0
            },
        )
    };
    let connection = if rng.random::<f64>() < 0.5 {
        Connection::Star
    } else {
        Connection::Delta
    };
    let size = (power / 1000.0).log10() / 50f64.log10(); // 0 (1 kW) … 1 (50 kW)
    let efficiency = 0.80 + 0.12 * size + uniform(rng, -0.02, 0.02);
    let pf = uniform(rng, 0.78, 0.88);
    let line_i = power / (3f64.sqrt() * line_v * efficiency * pf);
    let v_ph = connection.phase_voltage(line_v);
    let i_ph = connection.phase_current(line_i);
    let z_base = v_ph / i_ph;
    let leak = uniform(rng, 0.12, 0.22);
    let share = uniform(rng, 0.4, 0.6);
    let mut m = Machine {
        rs: uniform(rng, 0.015, 0.05) * z_base,
        xs: share * leak * z_base,
        xm: uniform(rng, 1.8, 3.5) * z_base,
        rr: uniform(rng, 0.015, 0.045) * z_base,
        xr: (1.0 - share) * leak * z_base,
    };

    // Plan.
    let needs_voltages = matches!(
        effect,
        Some(Effect::MainFluxSaturation) | Some(Effect::LeakageSaturation)
    );
    let n_voltages = if needs_voltages {
        rng.random_range(2..=3)
    } else {
        rng.random_range(1..=3)
    };
    let mut voltages = vec![line_v];
    for _ in 1..n_voltages {
        let last = *voltages.last().unwrap_or(&line_v);
        let lo = 0.55 * line_v;
        voltages.push(uniform(rng, lo.max(0.6 * last), 0.85 * last).max(lo));
    }
    let n_points = rng.random_range(20..=40);
    let s_min = uniform(rng, 0.002, 0.01);

    // The withheld effect at a random magnitude.
    let mut effect_params = BTreeMap::new();
    let e_rated = 0.95 * v_ph;
    let truth = match effect {
        None => Truth::None,
        Some(Effect::IronLoss) => {
            let frac = uniform(rng, 0.012, 0.035);
            let beta = uniform(rng, 1.8, 2.2);
            effect_params.insert("iron_loss_at_rated_voltage_fraction_of_rating".into(), frac);
            effect_params.insert("steinmetz_exponent".into(), beta);
            effect_params.insert(
                "Rfe_at_rated_ohm".into(),
                3.0 * e_rated * e_rated / (frac * power),
            );
            Truth::IronLoss {
                p_fe_rated: frac * power,
                beta,
                e_rated,
            }
        }
        Some(Effect::DeepBar) => {
            let xi1 = uniform(rng, 0.9, 2.2);
            let bar_r = uniform(rng, 0.55, 0.8);
            let bar_x = uniform(rng, 0.4, 0.7);
            let (kr, kx) = skin(xi1);
            effect_params.insert("reduced_bar_height_at_locked_rotor".into(), xi1);
            effect_params.insert("bar_share_of_Rr".into(), bar_r);
            effect_params.insert("slot_share_of_Xr".into(), bar_x);
            effect_params.insert("Rr_factor_at_locked_rotor".into(), 1.0 - bar_r + bar_r * kr);
            effect_params.insert("Xr_factor_at_locked_rotor".into(), 1.0 - bar_x + bar_x * kx);
            Truth::DeepBar { xi1, bar_r, bar_x }
        }
        Some(Effect::MainFluxSaturation) => {
            let drop = uniform(rng, 0.08, 0.3);
            let n = uniform(rng, 5.0, 9.0);
            // Xm(E_rated) = (1 − drop)·Xm0; the drawn xm is the rated one.
            m.xm /= 1.0 - drop;
            let u = drop / (1.0 - drop);
            let es = e_rated / u.powf(1.0 / n);
            effect_params.insert("Xm_drop_at_rated_voltage".into(), drop);
            effect_params.insert("saturation_exponent".into(), n);
            effect_params.insert("Es_V".into(), es);
            effect_params.insert("Xm_unsaturated_ohm".into(), m.xm);
            Truth::MainFlux { es, n }
        }
        Some(Effect::LeakageSaturation) => {
            let drop = uniform(rng, 0.1, 0.3);
            let slope = uniform(rng, 0.3, 0.5);
            let i_lr = terminal(&m, &Truth::None, Heat { rs: 1.0, rr: 1.0 }, 1.0, v_ph).0;
            let knee = i_lr * (1.0 - drop / (1.0 - slope));
            effect_params.insert("leakage_drop_at_locked_rotor".into(), drop);
            effect_params.insert("knee_current_A".into(), knee);
            let width = uniform(rng, 0.15, 0.4);
            effect_params.insert("slope_above_knee".into(), slope);
            effect_params.insert("bend_width_of_knee".into(), width);
            Truth::Leakage { knee, slope, width }
        }
        Some(Effect::StrayLoadLoss) => {
            let frac = uniform(rng, 0.008, 0.03);
            let gamma = uniform(rng, 1.9, 2.1);
            let ir_rated = rated_rotor_current(&m, v_ph, frequency, poles, power);
            let c = frac * power / ir_rated.powf(gamma);
            effect_params.insert("stray_loss_at_rated_load_fraction_of_rating".into(), frac);
            effect_params.insert("current_exponent".into(), gamma);
            effect_params.insert(
                "Rsll_equivalent_ohm".into(),
                frac * power / (3.0 * ir_rated * ir_rated),
            );
            Truth::Stray { c, gamma }
        }
        Some(Effect::ThermalDrift) => Truth::Thermal,
        Some(_) => Truth::None,
    };

    // Sweeps in time order with the thermal state.
    let mut slips: Vec<f64> = (0..n_points)
        .map(|k| {
            let x = k as f64 / (n_points - 1) as f64;
            s_min + (1.0 - s_min) * x * x
        })
        .collect();
    for k in 1..n_points - 1 {
        let gap = slips[k + 1] - slips[k - 1];
        slips[k] += uniform(rng, -0.15, 0.15) * gap;
    }
    // Thermal model: losses heat stator and rotor (first order); the gain
    // is scaled so that the stator resistance rises by `rise` at the end.
    let tau = uniform(rng, 300.0, 1500.0);
    let dwell = uniform(rng, 3.0, 8.0);
    let pause = uniform(rng, 30.0, 120.0);
    let mut schedule = Vec::new();
    for (seg, &v) in voltages.iter().enumerate() {
        for (k, &s) in slips.iter().enumerate() {
            let pause_before = if seg > 0 && k == 0 { pause } else { 0.0 };
            schedule.push((seg as u32, v, s, pause_before));
        }
    }
    let heats = if truth == Truth::Thermal {
        let rise = uniform(rng, 0.03, 0.2);
        // A small-signal run (0.01 K per unit loss) sets the gain so that
        // the stator resistance rises by about `rise` at its hottest.
        let path = |gain: f64| thermal_path(&m, v_ph / line_v, &schedule, i_ph, tau, dwell, gain);
        let hottest = |p: &[Heat]| p.iter().map(|h| h.rs).fold(1.0f64, f64::max) - 1.0;
        let unit = hottest(&path(0.01));
        let mut gain = if unit > 0.0 { 0.01 * rise / unit } else { 0.0 };
        // Hotter windings draw less current: correct the gain twice.
        for _ in 0..2 {
            let got = hottest(&path(gain));
            if got > 0.0 {
                gain *= rise / got;
            }
        }
        let heats = path(gain);
        effect_params.insert("Rs_rise_hottest".into(), hottest(&heats));
        effect_params.insert(
            "Rr_rise_hottest".into(),
            heats.iter().map(|h| h.rr).fold(1.0f64, f64::max) - 1.0,
        );
        effect_params.insert("thermal_time_constant_s".into(), tau);
        heats
    } else {
        vec![Heat { rs: 1.0, rr: 1.0 }; schedule.len()]
    };

    // Meters.
    let current_meter = Meter::random(rng, (0.0005, 0.004));
    let power_meter = Meter::random(rng, (0.001, 0.008));
    let voltage_meter = Meter::random(rng, (0.0003, 0.0015));
    let w_sync = std::f64::consts::TAU * frequency / f64::from(poles / 2);

    let mut points = Vec::new();
    let (mut clean_i, mut clean_p, mut meas_i, mut meas_p) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (k, &(seg, v_set, s, _)) in schedule.iter().enumerate() {
        let v_true = v_set * (1.0 + gaussian(rng, 0.001));
        let v_phase = connection.phase_voltage(v_true);
        let (i, p, _) = terminal(&m, &truth, heats[k], s, v_phase);
        let li = current_meter.read(rng, connection.line_current(i));
        let lp = power_meter.read(rng, p);
        let v_read = voltage_meter.read(rng, v_true);
        // What a perfect model gives from the measured input (the
        // contract's ŷ): the truth at the voltage as read.
        let (ci, cp, _) = terminal(&m, &truth, heats[k], s, connection.phase_voltage(v_read));
        clean_i.push(connection.line_current(ci));
        clean_p.push(cp);
        meas_i.push(li);
        meas_p.push(lp);
        points.push(OperatingPoint {
            segment: seg,
            slip: s,
            line_voltage: v_read,
            line_current: li,
            input_power: lp,
            speed: (1.0 - s) * w_sync,
            frequency,
            torque: None,
            winding_temperature: None,
        });
    }
    // A no-load test in some plans, drawn after the sweeps so that they
    // stay what they were: the machine running free at several voltages.
    let mut no_load = Vec::new();
    let mut setup = BTreeMap::new();
    if rng.random::<f64>() < NO_LOAD_SHARE {
        let n = rng.random_range(6..=10);
        let (lo, hi) = (uniform(rng, 0.3, 0.8), uniform(rng, 1.05, 1.15));
        let friction = uniform(rng, 0.005, 0.02) * power;
        setup.insert("no_load_readings".to_string(), n as f64);
        setup.insert("no_load_lowest_voltage_fraction".to_string(), lo);
        setup.insert("friction_and_windage_W".to_string(), friction);
        // After the sweeps, in the windings' last state.
        let heat = heats.last().copied().unwrap_or(Heat { rs: 1.0, rr: 1.0 });
        let segment = voltages.len() as u32;
        let free = |v_line: f64| {
            free_running(&m, &truth, heat, connection.phase_voltage(v_line), friction)
        };
        for k in 0..n {
            let v_set = line_v * (lo + (hi - lo) * k as f64 / (n - 1) as f64);
            let v_true = v_set * (1.0 + gaussian(rng, 0.001));
            let (i, p) = free(v_true);
            let li = current_meter.read(rng, connection.line_current(i));
            let lp = power_meter.read(rng, p);
            let v_read = voltage_meter.read(rng, v_true);
            let (ci, cp) = free(v_read);
            clean_i.push(connection.line_current(ci));
            clean_p.push(cp);
            meas_i.push(li);
            meas_p.push(lp);
            no_load.push(SupplyReading {
                segment,
                line_voltage: v_read,
                line_current: li,
                input_power: lp,
                frequency,
                winding_temperature: None,
            });
        }
    }
    let floor = 0.5
        * (crate::identify::nrmse(&meas_i, &clean_i).unwrap_or(0.0)
            + crate::identify::nrmse(&meas_p, &clean_p).unwrap_or(0.0));
    let rms_sigma = |meter: &Meter, x: &[f64]| {
        (x.iter().map(|v| (meter.relative * v).powi(2)).sum::<f64>() / x.len() as f64).sqrt()
    };
    let mut nominal = BTreeMap::new();
    for (k, v) in [
        ("Rs", m.rs),
        ("Xs", m.xs),
        ("Xm", m.xm),
        ("Rr", m.rr),
        ("Xr", m.xr),
    ] {
        nominal.insert(k.to_string(), v);
    }
    let regions: Vec<String> = match effect {
        None => vec![],
        Some(Effect::IronLoss) | Some(Effect::MainFluxSaturation) if !no_load.is_empty() => {
            vec!["low_slip".into(), "no_load".into()]
        }
        Some(Effect::IronLoss) | Some(Effect::MainFluxSaturation) => vec!["low_slip".into()],
        Some(Effect::StrayLoadLoss) => vec!["breakdown".into(), "high_slip".into()],
        Some(_) => vec!["high_slip".into()],
    };
    let rated_speed_rpm = (1.0 - 0.03) * 60.0 * frequency / f64::from(poles / 2);
    let nameplate = serde_json::json!({
        "power_W": (power / 10.0).round() * 10.0,
        "voltage_V": line_v,
        "current_A": (line_i * 10.0).round() / 10.0,
        "speed_rpm": rated_speed_rpm.round(),
        "poles": poles,
        "frequency_Hz": frequency,
        "connection": connection.as_str(),
        "power_factor": (pf * 100.0).round() / 100.0,
    });
    let record = Record {
        meta: Some(TestMeta {
            schema_version: SCHEMA_VERSION.into(),
            kind: SegmentKind::ImSlipSweep,
            motor_id: "blind-im".into(),
            started_at: "2025-01-01T00:00:00Z".into(),
            nameplate,
            config: String::new(),
        }),
        operating_points: points,
        standard_tests: ImStandardTests {
            no_load,
            ..ImStandardTests::default()
        },
        ..Record::default()
    };
    let truth = CaseTruth {
        effect: super::diagnose::effects::effect_name(effect),
        effect_params,
        nominal,
        noise: BTreeMap::from([
            (
                "line_current".to_string(),
                rms_sigma(&current_meter, &clean_i),
            ),
            ("input_power".to_string(), rms_sigma(&power_meter, &clean_p)),
        ]),
        // Largest resolution step met (autoranging: the step follows the reading).
        quantisation: BTreeMap::from([
            (
                "line_current".to_string(),
                max_step(&current_meter, &meas_i),
            ),
            ("input_power".to_string(), max_step(&power_meter, &meas_p)),
            ("line_voltage".to_string(), voltage_meter.step(line_v)),
        ]),
        noise_floor: floor,
        regions,
        source: crate::diagnose::blind::OWN_SOURCE.to_string(),
        plan: if record.standard_tests.no_load.is_empty() {
            "sweep"
        } else {
            "sweep_no_load"
        }
        .to_string(),
        setup,
    };
    BlindRecord { record, truth }
}

/// Phase current and power of the machine running free at phase voltage
/// `v` against `friction` (W): at the slip where the rotor delivers it.
fn free_running(m: &Machine, truth: &Truth, heat: Heat, v: f64, friction: f64) -> (f64, f64) {
    let rr = m.rr * heat.rr;
    let shaft = |s: f64| {
        let ir = terminal(m, truth, heat, s, v).2;
        3.0 * ir * ir * rr * (1.0 - s) / s - friction
    };
    let s = increasing_root(shaft, 1e-9, 0.05)
        .or_else(|| increasing_root(shaft, 1e-9, 0.2))
        .unwrap_or(0.0);
    let (i, p, _) = terminal(m, truth, heat, s, v);
    (i, p)
}

fn max_step(meter: &Meter, readings: &[f64]) -> f64 {
    readings.iter().map(|x| meter.step(*x)).fold(0.0, f64::max)
}

/// Rotor current at rated output (the slip where the shaft gives `power`).
fn rated_rotor_current(m: &Machine, v_ph: f64, f: f64, poles: u32, power: f64) -> f64 {
    let w_sync = std::f64::consts::TAU * f / f64::from(poles / 2);
    let _ = w_sync;
    let heat = Heat { rs: 1.0, rr: 1.0 };
    let shaft = |s: f64| {
        let (_, _, ir) = terminal(m, &Truth::None, heat, s, v_ph);
        3.0 * ir * ir * m.rr * (1.0 - s) / s - power
    };
    let s = increasing_root(shaft, 1e-5, 0.1).unwrap_or(0.03);
    terminal(m, &Truth::None, heat, s, v_ph).2
}

/// Resistance factors along the schedule from a first-order thermal model:
/// stator and rotor each heated towards `gain`·(their loss per unit of the
/// stator's loss at `i_ref`) kelvin with time constant `tau`, over the
/// point dwell and the pauses between sweeps.
fn thermal_path(
    m: &Machine,
    phase_per_line: f64,
    schedule: &[(u32, f64, f64, f64)],
    i_ref: f64,
    tau: f64,
    dwell: f64,
    gain: f64,
) -> Vec<Heat> {
    let (mut th_s, mut th_r) = (0.0f64, 0.0f64);
    let mut out = Vec::with_capacity(schedule.len());
    let p_ref = 3.0 * i_ref * i_ref * m.rs;
    for &(_, v, s, pause) in schedule {
        let cool = (-pause / tau).exp();
        th_s *= cool;
        th_r *= cool;
        let heat = Heat {
            rs: 1.0 + COPPER_ALPHA * th_s,
            rr: 1.0 + ALPHA_AL * th_r,
        };
        out.push(heat);
        let (i, _, ir) = terminal(m, &Truth::Thermal, heat, s, v * phase_per_line);
        let target_s = gain * 3.0 * i * i * m.rs * heat.rs / p_ref;
        let target_r = gain * 3.0 * ir * ir * m.rr * heat.rr / p_ref;
        let k = 1.0 - (-dwell / tau).exp();
        th_s += (target_s - th_s) * k;
        th_r += (target_r - th_r) * k;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn cases_are_plausible_and_carry_their_truth() {
        let mut rng = StdRng::seed_from_u64(3);
        for effect in [
            None,
            Some(Effect::IronLoss),
            Some(Effect::DeepBar),
            Some(Effect::MainFluxSaturation),
            Some(Effect::LeakageSaturation),
            Some(Effect::StrayLoadLoss),
            Some(Effect::ThermalDrift),
        ] {
            let case = simulate_im_case(effect, &mut rng);
            let pts = &case.record.operating_points;
            assert!(pts.len() >= 20);
            assert!(pts
                .iter()
                .all(|p| p.line_current > 0.0 && p.input_power > 0.0));
            assert!(pts.iter().all(|p| (0.0..=1.0).contains(&p.slip)));
            let plate = &case.record.meta.as_ref().unwrap().nameplate;
            assert!(Connection::parse(plate["connection"].as_str().unwrap()).is_some());
            assert!(case.truth.noise_floor > 0.0 && case.truth.noise_floor < 0.05);
            assert_eq!(case.truth.effect_params.is_empty(), effect.is_none());
            if matches!(effect, Some(Effect::MainFluxSaturation)) {
                let segs: std::collections::BTreeSet<u32> = pts.iter().map(|p| p.segment).collect();
                assert!(segs.len() >= 2);
            }
            // Locked-rotor current is several times the no-load current.
            let first = pts[0].line_current;
            let locked = pts.iter().rfind(|p| p.segment == 0).unwrap().line_current;
            assert!(locked > 2.0 * first, "{first} → {locked}");
        }
    }

    /// A no-load test, where a plan has one, runs after the sweeps over
    /// rising voltages from below to above rated, draws the friction and
    /// windage (more power than the stator copper loss alone), and draws
    /// about the sweep's near-synchronous current at rated voltage.
    #[test]
    fn a_no_load_test_runs_free_after_the_sweeps() {
        let mut rng = StdRng::seed_from_u64(5);
        let mut seen = 0;
        for _ in 0..12 {
            let case = simulate_im_case(None, &mut rng);
            let no_load = &case.record.standard_tests.no_load;
            let plan = case.truth.plan.as_str();
            if no_load.is_empty() {
                assert_eq!(plan, "sweep");
                continue;
            }
            seen += 1;
            assert_eq!(plan, "sweep_no_load");
            let last_sweep = case.record.operating_points.iter().map(|p| p.segment).max();
            assert!(no_load.iter().all(|r| Some(r.segment) > last_sweep));
            assert!(no_load
                .windows(2)
                .all(|w| w[1].line_voltage > w[0].line_voltage));
            let rated = case.record.meta.as_ref().unwrap().nameplate["voltage_V"]
                .as_f64()
                .unwrap();
            assert!(no_load[0].line_voltage < 0.85 * rated);
            assert!(no_load.last().unwrap().line_voltage > rated);
            let friction = case.truth.setup["friction_and_windage_W"];
            assert!(no_load.iter().all(|r| r.input_power > friction));
            let near_sync = case.record.operating_points[0].line_current;
            let at_rated = no_load
                .iter()
                .min_by(|a, b| {
                    (a.line_voltage - rated)
                        .abs()
                        .total_cmp(&(b.line_voltage - rated).abs())
                })
                .unwrap();
            let ratio = at_rated.line_current / near_sync;
            assert!((0.5..1.1).contains(&ratio), "{ratio}");
        }
        assert!((2..=9).contains(&seen), "{seen} of 12");
    }
}
