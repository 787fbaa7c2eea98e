//! Random separately excited DC motors scaled from a rated power, with a
//! rig configuration and a staircase plan to test each on the simulated
//! rig. Shared by the identification coverage test and the benchmark
//! (included by `#[path]`).
//!
//! The generator, from the nameplate to the model:
//!
//! - rated power P log-uniform in 100 W – 2 kW; rated speed 1000–4000 r/min;
//!   efficiency η from 0.60 (100 W) to 0.85 (2 kW), ±0.03;
//! - rated voltage log-uniform in 24–400 V, narrowed so the rated current
//!   P/(η·U) stays within 0.5–40 A;
//! - Ra from the copper loss: 50–75 % of the rated losses P·(1/η − 1)
//!   dissipated in Ra at rated current;
//! - K from the rated point: U = Ra·I + K·ω;
//! - no-load torque 3–8 % of rated torque, split 30–70 % static (Tst),
//!   the rest viscous at rated speed (f);
//! - rotor inertia from rated torque, J_motor = 1e-4·T^1.4 kg·m² (T in
//!   N·m; catalogue-like: 2e-5 kg·m² at 0.3 N·m, 3.5e-3 kg·m² at 13 N·m),
//!   times 1.5–4 for the coupled load and dynamometer;
//! - electrical time constant La/Ra log-uniform in 2–20 ms.
//!
//! The rig around it: a supply to 1.2·U that slews 200·U per second and
//! whose current rating and limits clear the largest step's peak current
//! (at most the highest level over Ra, so the current limit never acts);
//! 12-bit voltage (±1.5·U, noise half an LSB) and current (±1.3× that
//! peak bound, noise one LSB) converters; an encoder of 1000, 2500 or
//! 5000 lines; 2 kHz sampling; the embedded default's settling rules. The
//! plan is the default staircase scaled to the rated voltage.
#![allow(dead_code)]

use motorbench::config::{Backend, Config, Plan, Supervision};
use motorbench::model::DcParams;
use rand::rngs::StdRng;
use rand::RngExt;

/// The embedded default's staircase (60, 248, 60, 154, 248, 107, 201,
/// 60 V) as fractions of its motor's rated 270 V.
pub const DEFAULT_STAIRCASE: [f64; 8] = [
    60.0 / 270.0,
    248.0 / 270.0,
    60.0 / 270.0,
    154.0 / 270.0,
    248.0 / 270.0,
    107.0 / 270.0,
    201.0 / 270.0,
    60.0 / 270.0,
];

/// A motor with its nameplate.
#[derive(Debug, Clone, Copy)]
pub struct RatedMotor {
    /// Rated output power, W.
    pub power: f64,
    /// Rated armature voltage, V.
    pub voltage: f64,
    /// Rated armature current, A.
    pub current: f64,
    /// Rated speed, r/min.
    pub speed_rpm: f64,
    /// The model's parameters.
    pub params: DcParams,
}

fn log_uniform(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    rng.random_range(lo.ln()..hi.ln()).exp()
}

/// One random motor (see the module documentation).
pub fn random_motor(rng: &mut StdRng) -> RatedMotor {
    let power = log_uniform(rng, 100.0, 2000.0);
    let size = (power / 100.0).ln() / 20.0f64.ln();
    let efficiency = 0.60 + 0.25 * size + rng.random_range(-0.03..0.03);
    let speed_rpm = rng.random_range(1000.0..4000.0);
    let omega = speed_rpm * std::f64::consts::TAU / 60.0;
    let input = power / efficiency;
    let lo = 24.0f64.max(input / 40.0);
    let hi = 400.0f64.min(input / 0.5);
    let voltage = log_uniform(rng, lo, hi);
    let current = input / voltage;
    let losses = input - power;
    let ra = rng.random_range(0.5..0.75) * losses / (current * current);
    let k = (voltage - ra * current) / omega;
    let torque = power / omega;
    let no_load = rng.random_range(0.03..0.08) * torque;
    let static_share = rng.random_range(0.3..0.7);
    let j_motor = 1e-4 * torque.powf(1.4);
    let params = DcParams {
        ra,
        la: ra * log_uniform(rng, 2e-3, 20e-3),
        k,
        j: j_motor * rng.random_range(1.5..4.0),
        f: (1.0 - static_share) * no_load / omega,
        tst: static_share * no_load,
    };
    RatedMotor {
        power,
        voltage,
        current,
        speed_rpm,
        params,
    }
}

/// The embedded default configuration, edited to test `motor` with the
/// staircase `levels` (fractions of rated voltage); `seed` seeds the
/// sensor noise.
pub fn config_for(motor: &RatedMotor, levels: &[f64], seed: u64, rng: &mut StdRng) -> Config {
    let mut cfg = Config::embedded_default();
    let u = motor.voltage;
    let p = &motor.params;
    let volts: Vec<f64> = levels.iter().map(|f| f * u).collect();
    let top = volts.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let peak_bound = top / p.ra;
    cfg.common.motor_id = format!("random-{:.0}W-{:.0}V", motor.power, u);
    cfg.common.nameplate = serde_json::json!({
        "power_W": motor.power,
        "voltage_V": u,
        "current_A": motor.current,
        "speed_rpm": motor.speed_rpm,
    });
    cfg.plan = Plan::DcStep {
        levels: volts,
        coastdown: false,
    };
    cfg.common.limits.max_voltage = 1.1 * u;
    cfg.common.limits.max_current = 1.25 * peak_bound;
    cfg.common.limits.max_speed = 1.5 * top / p.k;
    // The `[supervisor]` defaults a file with these limits and this
    // nameplate would get (power limit, winding estimate): `run` checks
    // them too.
    cfg.common.supervision = Supervision::defaults(&cfg.common.limits, motor.current);
    let Backend::Simulated(sim) = &mut cfg.backend else {
        unreachable!("the embedded default is the simulated rig")
    };
    sim.motor = *p;
    sim.power_stage.max_voltage = 1.2 * u;
    sim.power_stage.slew = 200.0 * u;
    sim.power_stage.current_limit = 2.0 * cfg.common.limits.max_current;
    let s = &mut sim.sensors;
    s.seed = seed;
    s.voltage_full_scale = 1.5 * u;
    s.voltage_bits = 12;
    s.voltage_noise = 0.5 * 2.0 * s.voltage_full_scale / 4096.0;
    s.current_full_scale = 1.3 * peak_bound;
    s.current_bits = 12;
    s.current_noise = 2.0 * s.current_full_scale / 4096.0;
    s.encoder_lines = [1000, 2500, 5000][rng.random_range(0..3usize)];
    cfg
}
