//! A blind DC case: a random motor (around one of four machine families,
//! not only the seed paper's), a staircase of five voltage steps from rest
//! plus a coast-down at 2 kHz, random noise and quantisation on every
//! reading (ADC-like on voltage and current, encoder counts on the speed),
//! and one withheld effect at a random magnitude.
//!
//! The generator's effect models are deliberately a little richer than the
//! diagnosis' candidates, so the method is not self-fulfilling:
//!
//! | effect | generator | magnitude |
//! |---|---|---|
//! | `coulomb_friction` | Stribeck excess `Tb·exp(−(ω/ωs)²)` over the static torque | Tb 0.5–2 × Tst, ωs 3–10 % of top speed |
//! | `brush_drop` | `Vb·(1 − e^(−|i|/i0))·sign(i)` | Vb 1–3 % of rated voltage, i0 2–10 % of rated current |
//! | `armature_reaction` | `K(i) = K/√(1 + (i/Iar)²)` | K 4–20 % lower at the largest step current |
//! | `inductance_saturation` | `La(i) = La·(ℓ + (1−ℓ)/(1 + (i/Isat)²))`, floor ℓ 0.3–0.5 | La 20–50 % lower at the largest step current |
//! | `thermal_drift` | first-order thermal network, `Ra = Ra0·(1 + α·ϑ)`, τth 30–300 s | Ra 3–12 % higher at the end |
//! | `sensor_lag` | transport delay (0–2 samples) then a first-order lag, on current or speed | current τ 10–40 % of τe; speed τ 5–20 % of τm |
//! | `shaft_compliance` | two masses, friction on the load, a little viscous loss on the motor | fr 10–50 Hz, ζ 0.03–0.1, motor share 0.3–0.7 |
//!
//! Magnitudes run from barely above the noise to strong; below those
//! ranges an effect does not change a 2 kHz staircase by more than its
//! noise and quantisation, so no method could name it.

use std::collections::BTreeMap;
use std::f64::consts::TAU;

use rand::rngs::StdRng;
use rand::RngExt;
use rand_distr::{Distribution, Normal};

use super::blind_plan::{drives, Coast, Controller, DcSetup, Drive, PlanKind, SpeedSensor};
use crate::diagnose::blind::{BlindRecord, CaseTruth};
use crate::identify::nrmse;
use crate::model::{DcParams, Effect};
use crate::record::{DcSegment, Record, SegmentKind};

/// Sample interval of every case, s (2 kHz).
pub const DT: f64 = 5e-4;

/// Integration sub-steps per sample.
const SUBSTEPS: usize = 20;

/// Temperature coefficient of copper, 1/K.
const ALPHA_CU: f64 = 0.003_93;

/// The withheld effect as the generator simulates it.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Truth {
    None,
    Stribeck {
        tb: f64,
        ws: f64,
    },
    Brush {
        vb: f64,
        i0: f64,
    },
    Armature {
        iar: f64,
    },
    Inductance {
        isat: f64,
        floor: f64,
    },
    Thermal {
        cth: f64,
        rth: f64,
    },
    Lag {
        current: bool,
        tau: f64,
        delay: usize,
    },
    Shaft {
        fr: f64,
        r: f64,
        zeta: f64,
    },
}

/// A machine family: nominal values and ratings.
struct Family {
    p: DcParams,
    volts: f64,
    amps: f64,
}

fn families() -> [Family; 4] {
    [
        // The seed paper's 180 W motor.
        Family {
            p: DcParams::SEED_TABLE4_MOMENTS,
            volts: 270.0,
            amps: 1.1,
        },
        // A 1 kW, 220 V industrial motor.
        Family {
            p: DcParams {
                ra: 1.5,
                la: 0.025,
                k: 1.3,
                j: 0.02,
                f: 0.004,
                tst: 0.4,
            },
            volts: 220.0,
            amps: 5.5,
        },
        // A 24 V permanent-magnet motor.
        Family {
            p: DcParams {
                ra: 1.2,
                la: 0.0035,
                k: 0.06,
                j: 5e-5,
                f: 1e-5,
                tst: 0.005,
            },
            volts: 24.0,
            amps: 3.0,
        },
        // A 48 V servo motor.
        Family {
            p: DcParams {
                ra: 0.6,
                la: 0.0018,
                k: 0.12,
                j: 4e-4,
                f: 4e-5,
                tst: 0.02,
            },
            volts: 48.0,
            amps: 10.0,
        },
    ]
}

fn around(rng: &mut StdRng, v: f64, spread: f64) -> f64 {
    v * rng.random_range(-spread..spread).exp()
}

/// Simulate one DC staircase record with `effect` withheld (None: no
/// effect): the classic settled staircase ([`DcSetup::classic`]).
pub fn simulate_dc_case(effect: Option<Effect>, rng: &mut StdRng) -> BlindRecord {
    simulate_dc_case_with(effect, &DcSetup::classic(), rng)
}

/// Simulate one DC record with `effect` withheld under `setup`'s plan and
/// sensors. The draws from `rng` are the same for every setup, so a case
/// differs from its classic twin only by what the setup changes.
pub fn simulate_dc_case_with(
    effect: Option<Effect>,
    setup: &DcSetup,
    rng: &mut StdRng,
) -> BlindRecord {
    let fams = families();
    let fam = &fams[rng.random_range(0..fams.len())];
    let mut p = DcParams {
        ra: around(rng, fam.p.ra, 0.3),
        la: around(rng, fam.p.la, 0.3),
        k: around(rng, fam.p.k, 0.2),
        j: around(rng, fam.p.j, 0.4),
        f: around(rng, fam.p.f, 0.4),
        tst: around(rng, fam.p.tst, 0.4),
    };
    if let Some(zeta) = setup.zeta {
        // ζ = ½·√(τm/τe): the inductance sets it; τe at least one sample.
        p.la = p.ra * (p.tau_m() / (4.0 * zeta * zeta)).clamp(DT, 0.2);
    }
    let volts = fam.volts * (p.k / fam.p.k);
    let amps = fam.amps;

    // Plan: five levels from rest (the first at most half the rated
    // voltage), consecutive levels 15–60 % of the rated voltage apart, at
    // least one step down, the last one high.
    let levels = loop {
        let l: Vec<f64> = (0..5)
            .map(|n| {
                let (lo, hi) = match n {
                    0 => (0.2, 0.5),
                    4 => (0.7, 1.0),
                    _ => (0.2, 1.0),
                };
                volts * rng.random_range(lo..hi)
            })
            .collect();
        let apart = l
            .windows(2)
            .all(|w| (0.15..=0.6).contains(&((w[1] - w[0]).abs() / volts)));
        let down = l.windows(2).any(|w| w[1] < w[0]);
        if apart && down {
            break l;
        }
    };
    // Each level is held until the slowest mode has decayed some twelve
    // times (complex poles decay with 2·τe).
    let tau_slow = slowest_tau(&p);
    let mut hold = setup.hold(tau_slow);
    let slew = volts * rng.random_range(20.0..200.0); // V/s per rated volt: 5–50 ms full swing

    let peak_current = {
        let mut prev = 0.0f64;
        let mut m = 0.0f64;
        for &l in &levels {
            m = m.max((l - prev).abs() / p.ra);
            prev = l;
        }
        m
    };
    let w_top = levels.iter().fold(0.0f64, |m, l| m.max(*l)) / p.k;
    // A closed loop designed from the datasheet: the family's values.
    let controller = Controller::new(
        fam.p.k,
        fam.p.ra,
        fam.p.j,
        fam.p.tau_m(),
        setup.loop_gain,
        1.2 * volts,
    );
    let plan_of = |hold: f64| Plan {
        drives: drives(setup, &levels, p.k, hold, DT),
        hold,
        slew,
        coast: setup.has_coast().then_some(setup.coast),
        q_theta: match setup.speed {
            SpeedSensor::Encoder(Some(lines)) => Some(TAU / (4.0 * lines)),
            _ => None,
        },
        current_tau: setup.current_bw.map(|bw| {
            // A current sensor slower than 3 % of τe would be a sensor lag.
            (1.0 / (TAU * bw)).min(0.03 * p.tau_e())
        }),
        tach_tau: match setup.speed {
            SpeedSensor::Tachometer { tau, .. } => Some(tau.min(0.01 * p.tau_m())),
            _ => None,
        },
        controller: controller.clone(),
    };
    let mut params = BTreeMap::new();
    let mut regions: Vec<&str> = Vec::new();
    let truth = match effect {
        None => Truth::None,
        Some(Effect::CoulombFriction) => {
            let tb = p.tst * rng.random_range(0.5..2.0);
            let ws = w_top * rng.random_range(0.03..0.1);
            params.insert("Tb".into(), tb);
            params.insert("ws".into(), ws);
            regions = vec!["coast_down", "start_up"];
            Truth::Stribeck { tb, ws }
        }
        Some(Effect::BrushDrop) => {
            let vb = fam.volts * rng.random_range(0.01..0.03);
            let i0 = amps * rng.random_range(0.02..0.1);
            params.insert("Vb".into(), vb);
            params.insert("i0".into(), i0);
            regions = vec!["settled", "transient", "start_up"];
            Truth::Brush { vb, i0 }
        }
        Some(Effect::ArmatureReaction) => {
            let drop: f64 = rng.random_range(0.04..0.2);
            let x = (1.0 / (1.0 - drop).powi(2) - 1.0).sqrt();
            let iar = peak_current / x;
            params.insert("Iar".into(), iar);
            params.insert("K_drop_at_peak".into(), drop);
            regions = vec!["transient", "start_up", "settled"];
            Truth::Armature { iar }
        }
        Some(Effect::InductanceSaturation) => {
            let drop: f64 = rng.random_range(0.2..0.5);
            let floor: f64 = rng.random_range(0.3..0.5);
            // (1−ℓ)/(1+x²) = 1 − drop − ℓ
            let x = ((1.0 - floor) / (1.0 - drop - floor) - 1.0).sqrt();
            let isat = peak_current / x;
            params.insert("Isat".into(), isat);
            params.insert("floor".into(), floor);
            params.insert("La_drop_at_peak".into(), drop);
            regions = vec!["start_up", "transient"];
            Truth::Inductance { isat, floor }
        }
        Some(Effect::ThermalDrift) => {
            let rise: f64 = rng.random_range(0.03..0.12);
            let tau_th: f64 = rng.random_range(30.0..300.0);
            params.insert("Ra_rise".into(), rise);
            params.insert("tau_th".into(), tau_th);
            regions = vec!["settled", "transient"];
            // Heat capacity from the nominal record's I²R energy so that
            // the rise at the end is about `rise`.
            let energy = simulate(&p, Truth::None, &plan_of(hold)).energy;
            let cth = ALPHA_CU * energy / rise;
            Truth::Thermal {
                cth,
                rth: tau_th / cth,
            }
        }
        Some(Effect::SensorLag) => {
            let current = rng.random_bool(0.5);
            let (tau, delay) = if current {
                (
                    p.tau_e() * rng.random_range(0.1..0.4),
                    rng.random_range(0..2),
                )
            } else {
                (
                    p.tau_m() * rng.random_range(0.05..0.2),
                    rng.random_range(0..3),
                )
            };
            params.insert(
                if current { "tau_current" } else { "tau_speed" }.into(),
                tau,
            );
            params.insert("delay_s".into(), delay as f64 * DT);
            regions = vec!["transient", "start_up"];
            Truth::Lag {
                current,
                tau,
                delay,
            }
        }
        Some(Effect::ShaftCompliance) => {
            let fr = (rng.random_range(10f64.ln()..50f64.ln())).exp();
            let r = rng.random_range(0.3..0.7);
            let zeta: f64 = rng.random_range(0.03..0.1);
            // The classic bench holds a level until it settles: the ringing too.
            if setup.hold_tau.is_none() {
                hold = hold.max((6.0 / (zeta * TAU * fr)).min(3.0));
            }
            params.insert("fr".into(), fr);
            params.insert("r_motor".into(), r);
            params.insert("zeta".into(), zeta);
            regions = vec!["oscillation", "transient", "start_up"];
            Truth::Shaft { fr, r, zeta }
        }
        Some(other) => panic!("{other:?} is not a DC effect"),
    };

    // Readings.
    let sigma_u = fam.volts * rng.random_range(0.0005..0.003);
    let adc = 2f64.powi(setup.adc_bits.unwrap_or(12) as i32);
    let q_u = 1.5 * fam.volts / adc;
    let sigma_i = amps * rng.random_range(0.002..0.01);
    let q_i = 4.0 * amps / adc * rng.random_range(0.5..2.0);
    let classic_lines = [1000.0, 2048.0, 2500.0, 4096.0][rng.random_range(0..4)];
    let lines = match setup.speed {
        SpeedSensor::Encoder(Some(lines)) => lines,
        _ => classic_lines,
    };
    let q_theta = TAU / (4.0 * lines);
    let tach = match setup.speed {
        SpeedSensor::Tachometer { tau, noise } => Some((tau, noise * w_top, 1.5 * w_top / adc)),
        _ => None,
    };
    let plan = plan_of(hold);
    let clean = simulate(&p, truth, &plan);
    let nw = Normal::new(0.0, tach.map_or(1.0, |t| t.1)).expect("σ > 0");
    let nu = Normal::new(0.0, sigma_u).expect("σ > 0");
    let ni = Normal::new(0.0, sigma_i).expect("σ > 0");
    let quant = |v: f64, q: f64| (v / q).round() * q;

    // The withheld sensor lag acts on one reading: a delay line then a
    // first-order lag, over the record's samples in order.
    let (lag_current, lag_speed) = match truth {
        Truth::Lag {
            current,
            tau,
            delay,
        } => {
            let l = Some(Lag::new((-DT / tau).exp(), delay));
            if current {
                (l, None)
            } else {
                (None, l)
            }
        }
        _ => (None, None),
    };
    let (mut lag_i, mut lag_w, mut lag_wc) = (lag_current.clone(), lag_speed.clone(), lag_speed);
    let mut segments: Vec<DcSegment> = Vec::new();
    let mut floors = Vec::new();
    let mut t0 = 0usize;
    let mut last_count = 0.0f64;
    let mut clean_prev = (0.0, 0.0);
    for (index, s) in clean.segments.iter().enumerate() {
        let n = s.u.len();
        let mut seg = DcSegment {
            index: index as u32,
            kind: Some(if s.coast {
                SegmentKind::DcCoastdown
            } else {
                SegmentKind::DcStep
            }),
            label: s.label.clone(),
            ..Default::default()
        };
        let (mut clean_i, mut clean_w) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for k in 0..n {
            if index > 0 && k == 0 {
                // The previous segment's last sample, repeated.
                let prev = &segments[index - 1];
                let last = prev.time.len() - 1;
                seg.time.push(prev.time[last]);
                seg.voltage.push(prev.voltage[last]);
                seg.current.push(prev.current[last]);
                seg.speed.push(prev.speed[last]);
                clean_i.push(clean_prev.0);
                clean_w.push(clean_prev.1);
                continue;
            }
            let count = (s.theta[k] / q_theta).floor();
            let w_sensor = match tach {
                Some((_, _, q_w)) => quant(s.w_tach[k] + nw.sample(rng), q_w),
                None => (count - last_count) * q_theta / DT,
            };
            last_count = count;
            let i_true = lag_i
                .as_mut()
                .map_or(s.i_sensed[k], |l| l.push(s.i_sensed[k]));
            let w_noise_free = if tach.is_some() { s.w_tach[k] } else { s.w[k] };
            let w_clean = lag_wc
                .as_mut()
                .map_or(w_noise_free, |l| l.push(w_noise_free));
            let w_read = lag_w.as_mut().map_or(w_sensor, |l| l.push(w_sensor));
            let u_read = if s.coast { s.emf[k] } else { s.u[k] };
            seg.time.push((t0 + k) as f64 * DT);
            seg.voltage.push(quant(u_read + nu.sample(rng), q_u));
            seg.current.push(quant(i_true + ni.sample(rng), q_i));
            seg.speed.push(w_read);
            clean_i.push(i_true);
            clean_w.push(w_clean);
        }
        let speed_floor = nrmse(&seg.speed, &clean_w).unwrap_or(0.0);
        floors.push(if s.coast {
            speed_floor
        } else {
            0.5 * (nrmse(&seg.current, &clean_i).unwrap_or(0.0) + speed_floor)
        });
        clean_prev = (
            *clean_i.last().unwrap_or(&0.0),
            *clean_w.last().unwrap_or(&0.0),
        );
        t0 += n - 1;
        segments.push(seg);
    }
    let noise_floor = floors.iter().sum::<f64>() / floors.len() as f64;

    let nominal = BTreeMap::from([
        ("Ra".to_string(), p.ra),
        ("La".to_string(), p.la),
        ("K".to_string(), p.k),
        ("J".to_string(), p.j),
        ("f".to_string(), p.f),
        ("Tst".to_string(), p.tst),
    ]);
    BlindRecord {
        record: Record {
            segments,
            ..Default::default()
        },
        truth: CaseTruth {
            effect: effect.map_or("none".to_string(), |e| {
                serde_json::to_value(e)
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_string))
                    .unwrap_or_default()
            }),
            effect_params: params,
            nominal,
            noise: BTreeMap::from([
                ("armature_voltage".to_string(), sigma_u),
                ("armature_current".to_string(), sigma_i),
                ("speed".to_string(), tach.map_or(0.0, |t| t.1)),
            ]),
            quantisation: BTreeMap::from([
                ("armature_voltage".to_string(), q_u),
                ("armature_current".to_string(), q_i),
                ("speed".to_string(), tach.map_or(q_theta / DT, |t| t.2)),
            ]),
            noise_floor,
            regions: regions.into_iter().map(str::to_string).collect(),
            source: crate::diagnose::blind::OWN_SOURCE.to_string(),
            plan: setup.plan.name().to_string(),
            setup: setup_record(setup, &p, hold, lines, &plan),
        },
    }
}

/// A plan as the simulator runs it.
/// The setup as the truth file lists it.
fn setup_record(
    setup: &DcSetup,
    p: &DcParams,
    hold: f64,
    lines: f64,
    plan: &Plan,
) -> BTreeMap<String, f64> {
    let tau_slow = slowest_tau(p);
    let mut m = BTreeMap::from([
        ("hold_s".to_string(), hold),
        ("hold_tau".to_string(), hold / tau_slow),
        ("zeta".to_string(), 0.5 * (p.tau_m() / p.tau_e()).sqrt()),
        ("adc_bits".to_string(), setup.adc_bits.unwrap_or(12) as f64),
        (
            "coast_short".to_string(),
            f64::from(u8::from(plan.coast == Some(Coast::Short))),
        ),
    ]);
    match plan.tach_tau {
        Some(tau) => m.insert("tach_tau_s".to_string(), tau),
        None => m.insert("encoder_lines".to_string(), lines),
    };
    if let Some(tau) = plan.current_tau {
        m.insert("current_bw_hz".to_string(), 1.0 / (TAU * tau));
    }
    if matches!(setup.plan, PlanKind::SpeedLoop | PlanKind::PositionLoop) {
        m.insert("loop_gain".to_string(), setup.loop_gain);
    }
    m
}

/// The slowest mode's time constant (complex poles decay with 2·τe).
fn slowest_tau(p: &DcParams) -> f64 {
    let (tm, te) = (p.tau_m(), p.tau_e());
    let disc = tm * tm - 4.0 * tm * te;
    if disc < 0.0 {
        2.0 * te
    } else {
        2.0 * tm * te / (tm - disc.sqrt())
    }
}

struct Plan {
    drives: Vec<Drive>,
    hold: f64,
    slew: f64,
    /// How the record ends; None: it ends with the last drive.
    coast: Option<Coast>,
    /// The encoder step a closed loop reads the speed with (None: the
    /// tachometer's filtered speed, or the true speed).
    q_theta: Option<f64>,
    /// Current sensor time constant, s.
    current_tau: Option<f64>,
    /// Tachometer filter time constant, s.
    tach_tau: Option<f64>,
    controller: Controller,
}

/// One simulated segment, noise-free: the applied voltage over each
/// interval, the current, the current sensor's output, the clean speed
/// reading (interval mean), the tachometer filter's output, the motor
/// angle at each sample and the back-EMF.
struct CleanSegment {
    label: String,
    coast: bool,
    u: Vec<f64>,
    i: Vec<f64>,
    i_sensed: Vec<f64>,
    w: Vec<f64>,
    w_tach: Vec<f64>,
    theta: Vec<f64>,
    emf: Vec<f64>,
}

/// What the simulator carries from sample to sample besides the state:
/// the sensors' filter outputs, the last encoder count and the speed the
/// controller reads.
struct Sensing {
    i_f: f64,
    w_f: f64,
    count: f64,
    feedback: f64,
    controller: Controller,
}

/// A delay line of `delay` samples followed by a first-order lag.
#[derive(Debug, Clone)]
struct Lag {
    a: f64,
    delay: usize,
    history: std::collections::VecDeque<f64>,
    y: Option<f64>,
}

impl Lag {
    fn new(a: f64, delay: usize) -> Lag {
        Lag {
            a,
            delay,
            history: std::collections::VecDeque::new(),
            y: None,
        }
    }

    /// The lagged reading after the true value `x`.
    fn push(&mut self, x: f64) -> f64 {
        self.history.push_back(x);
        if self.history.len() > self.delay + 1 {
            self.history.pop_front();
        }
        let src = self.history[0];
        let y = match self.y {
            None => src,
            Some(y) => self.a * y + (1.0 - self.a) * src,
        };
        self.y = Some(y);
        y
    }
}

struct Clean {
    segments: Vec<CleanSegment>,
    energy: f64,
}

/// State: current, motor speed, load speed, shaft twist, motor angle,
/// winding temperature rise.
type State = [f64; 6];

fn simulate(p: &DcParams, truth: Truth, plan: &Plan) -> Clean {
    let h = DT / SUBSTEPS as f64;
    let mut x: State = [0.0; 6];
    let mut applied = 0.0f64;
    let mut segments = Vec::new();
    let mut energy = 0.0;
    let (jm, jl, ks, cs) = match truth {
        Truth::Shaft { fr, r, zeta } => {
            let (jm, jl) = (r * p.j, (1.0 - r) * p.j);
            let w0 = TAU * fr;
            let mu = jm * jl / p.j;
            (jm, jl, w0 * w0 * mu, 2.0 * zeta * w0 * mu)
        }
        _ => (p.j, 0.0, 0.0, 0.0),
    };
    let shaft = matches!(truth, Truth::Shaft { .. });
    let deriv = |x: &State, u: f64, open: bool, dir: Option<f64>| -> State {
        let (i, wm, wl, phi, _th, temp) = (x[0], x[1], x[2], x[3], x[4], x[5]);
        let kf = match truth {
            Truth::Armature { iar } => 1.0 / (1.0 + (i / iar).powi(2)).sqrt(),
            _ => 1.0,
        };
        let lf = match truth {
            Truth::Inductance { isat, floor } => floor + (1.0 - floor) / (1.0 + (i / isat).powi(2)),
            _ => 1.0,
        };
        let ra = match truth {
            Truth::Thermal { .. } => p.ra * (1.0 + ALPHA_CU * temp),
            _ => p.ra,
        };
        let vd = match truth {
            Truth::Brush { vb, i0 } => vb * (1.0 - (-i.abs() / i0).exp()) * i.signum(),
            _ => 0.0,
        };
        let di = if open {
            0.0
        } else {
            (u - ra * i - p.k * kf * wm - vd) / (p.la * lf)
        };
        let dtemp = match truth {
            Truth::Thermal { cth, rth } => (ra * i * i - temp / rth) / cth,
            _ => 0.0,
        };
        let mut d = [di, 0.0, 0.0, 0.0, wm, dtemp];
        if let Some(dir) = dir {
            if shaft {
                let tw = ks * phi + cs * (wm - wl);
                d[1] = (p.k * i - tw - 0.1 * p.f * wm) / jm;
                d[2] = (tw - p.f * wl - p.tst * dir) / jl;
                d[3] = wm - wl;
            } else {
                let extra = match truth {
                    Truth::Stribeck { tb, ws } => tb * (-(wm / ws).powi(2)).exp(),
                    _ => 0.0,
                };
                d[1] = (p.k * kf * i - p.f * wm - (p.tst + extra) * dir) / p.j;
            }
        }
        d
    };
    let breakaway = match truth {
        Truth::Stribeck { tb, .. } => p.tst + tb,
        _ => p.tst,
    };
    let kf_of = |i: f64| match truth {
        Truth::Armature { iar } => 1.0 / (1.0 + (i / iar).powi(2)).sqrt(),
        _ => 1.0,
    };
    let filter = |tau: Option<f64>| tau.map_or(1.0, |t| 1.0 - (-h / t).exp());
    let (ci, cw) = (filter(plan.current_tau), filter(plan.tach_tau));
    let mut run = |drive: &Drive,
                   n: usize,
                   label: String,
                   x: &mut State,
                   applied: &mut f64,
                   sense: &mut Sensing| {
        let open = matches!(drive, Drive::Open);
        let mut seg = CleanSegment {
            label,
            coast: open,
            u: Vec::with_capacity(n),
            i: Vec::with_capacity(n),
            i_sensed: Vec::with_capacity(n),
            w: Vec::with_capacity(n),
            w_tach: Vec::with_capacity(n),
            theta: Vec::with_capacity(n),
            emf: Vec::with_capacity(n),
        };
        let slew_to = |applied: &mut f64, t: f64| {
            *applied += (t - *applied).clamp(-plan.slew * DT, plan.slew * DT);
            *applied
        };
        for step in 0..n {
            let t = (step + 1) as f64 * DT;
            let u = match drive {
                Drive::Level(t) => slew_to(applied, *t),
                Drive::Ramp { from, to, samples } => {
                    *applied = from + (to - from) * ((step + 1) as f64 / *samples as f64).min(1.0);
                    *applied
                }
                Drive::Prbs { lo, hi, bits, bit } => {
                    slew_to(applied, if bits[step / bit] { *hi } else { *lo })
                }
                Drive::Speed(w_ref) => {
                    *applied = sense.controller.speed(*w_ref, sense.feedback, DT);
                    *applied
                }
                Drive::Move { from, to, speed } => {
                    let th_ref = from + (to - from).signum() * (speed * t).min((to - from).abs());
                    *applied = sense.controller.position(th_ref, x[4], sense.feedback, DT);
                    *applied
                }
                Drive::Open | Drive::Short => {
                    *applied = 0.0;
                    0.0
                }
            };
            if open {
                x[0] = 0.0;
                sense.i_f = 0.0;
            }
            let th0 = x[4];
            let moving_speed = if shaft { x[2] } else { x[1] };
            let at_rest = x[1] == 0.0 && x[2] == 0.0;
            let dir = if moving_speed != 0.0 {
                Some(moving_speed.signum())
            } else if !at_rest {
                Some(x[1].signum())
            } else if (p.k * kf_of(x[0]) * x[0]).abs() > breakaway {
                Some((x[0]).signum())
            } else {
                None
            };
            for _ in 0..SUBSTEPS {
                let k1 = deriv(x, u, open, dir);
                let add = |a: &State, k: &State, c: f64| -> State {
                    std::array::from_fn(|n| a[n] + c * k[n])
                };
                let k2 = deriv(&add(x, &k1, h / 2.0), u, open, dir);
                let k3 = deriv(&add(x, &k2, h / 2.0), u, open, dir);
                let k4 = deriv(&add(x, &k3, h), u, open, dir);
                for n in 0..6 {
                    x[n] += h / 6.0 * (k1[n] + 2.0 * k2[n] + 2.0 * k3[n] + k4[n]);
                }
                if !shaft {
                    x[2] = x[1];
                }
                if let Some(d) = dir {
                    let s = if shaft { x[2] } else { x[1] };
                    if s * d < 0.0 {
                        if shaft && moving_speed == 0.0 {
                            // The load is still held by its friction.
                            x[2] = 0.0;
                        } else {
                            x[1] = 0.0;
                            x[2] = 0.0;
                            x[3] = 0.0;
                        }
                    }
                }
                energy += h * x[0] * x[0] * p.ra;
                sense.i_f += ci * (x[0] - sense.i_f);
                sense.w_f += cw * (x[1] - sense.w_f);
            }
            let w_mean = (x[4] - th0) / DT;
            sense.feedback = match plan.q_theta {
                Some(q) => {
                    let count = (x[4] / q).floor();
                    let w = (count - sense.count) * q / DT;
                    sense.count = count;
                    w
                }
                None if plan.tach_tau.is_some() => sense.w_f,
                None => w_mean,
            };
            seg.u.push(u);
            seg.i.push(x[0]);
            seg.i_sensed.push(if plan.current_tau.is_some() {
                sense.i_f
            } else {
                x[0]
            });
            seg.w.push(w_mean);
            seg.w_tach.push(sense.w_f);
            seg.theta.push(x[4]);
            seg.emf.push(p.k * x[1]);
        }
        seg
    };
    let mut sense = Sensing {
        i_f: 0.0,
        w_f: 0.0,
        count: 0.0,
        feedback: 0.0,
        controller: plan.controller.clone(),
    };
    let samples = (plan.hold / DT).round() as usize;
    let mut prev = "0 V".to_string();
    for drive in &plan.drives {
        let this = match drive {
            Drive::Level(l) => format!("{l:.1} V"),
            Drive::Ramp { to, .. } => format!("ramp to {to:.1} V"),
            Drive::Prbs { lo, hi, .. } => format!("PRBS {lo:.1}/{hi:.1} V"),
            Drive::Speed(w) => format!("speed loop to {w:.1} rad/s"),
            Drive::Move { to, .. } => format!("position loop to {to:.1} rad"),
            Drive::Open => "coast-down".to_string(),
            Drive::Short => "0 V short".to_string(),
        };
        let label = format!("{prev} → {this}");
        let mut seg = run(drive, samples, label, &mut x, &mut applied, &mut sense);
        if let Some(prev) = segments.last() {
            // The boundary sample (the previous segment's last) comes first.
            prepend(&mut seg, prev);
        }
        segments.push(seg);
        prev = this;
    }
    if let Some(coast) = plan.coast {
        // Until the rotor stops (plus a little), at most 8 s; a short
        // brakes with the electrical damping K²/Ra too.
        let w0 = x[1];
        let f = match coast {
            Coast::Open => p.f,
            Coast::Short => p.f + p.k * p.k / p.ra,
        };
        let decel = (f * w0 + p.tst) / p.j;
        let t_stop = (p.j / f * (1.0 + w0 * f / p.tst).ln()).min(w0 / decel * 3.0);
        let samples = (((t_stop + 0.2).min(8.0)) / DT).round() as usize;
        let (drive, this) = match coast {
            Coast::Open => (Drive::Open, "coast-down"),
            Coast::Short => (Drive::Short, "0 V short"),
        };
        let mut seg = run(
            &drive,
            samples,
            format!("{prev} → {this}"),
            &mut x,
            &mut applied,
            &mut sense,
        );
        prepend(&mut seg, &segments[segments.len() - 1]);
        segments.push(seg);
    }

    Clean { segments, energy }
}

/// Put `prev`'s last sample in front of `seg`.
fn prepend(seg: &mut CleanSegment, prev: &CleanSegment) {
    let last = prev.u.len() - 1;
    seg.u.insert(0, prev.u[last]);
    seg.i.insert(0, prev.i[last]);
    seg.i_sensed.insert(0, prev.i_sensed[last]);
    seg.w.insert(0, prev.w[last]);
    seg.w_tach.insert(0, prev.w_tach[last]);
    seg.theta.insert(0, prev.theta[last]);
    seg.emf.insert(0, prev.emf[last]);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn a_case_is_a_staircase_with_a_coast_down() {
        let mut rng = StdRng::seed_from_u64(3);
        for effect in [None, Some(Effect::ShaftCompliance), Some(Effect::SensorLag)] {
            let case = simulate_dc_case(effect, &mut rng);
            let segs = &case.record.segments;
            assert_eq!(segs.len(), 6);
            assert_eq!(segs[5].kind, Some(SegmentKind::DcCoastdown));
            for w in segs.windows(2) {
                let last = w[0].time.len() - 1;
                assert_eq!(w[0].time[last], w[1].time[0]);
                assert_eq!(w[0].speed[last], w[1].speed[0]);
                assert_eq!(w[0].current[last], w[1].current[0]);
            }
            // The coast-down ends near rest and carries no current.
            let c = &segs[5];
            let top = c.speed[..20].iter().sum::<f64>() / 20.0;
            let end = c.speed[c.speed.len() - 20..].iter().sum::<f64>() / 20.0;
            assert!(end.abs() < 0.1 * top, "{end} vs {top}");
            assert!(case.truth.noise_floor > 0.0 && case.truth.noise_floor < 0.2);
            assert_eq!(case.truth.effect_params.is_empty(), effect.is_none());
        }
    }

    #[test]
    fn every_wide_plan_makes_a_continuous_record_of_its_kind() {
        for (n, plan) in PlanKind::ALL.into_iter().enumerate() {
            let mut setup = DcSetup::draw(plan, &mut StdRng::seed_from_u64(n as u64));
            setup.coast = Coast::Short;
            let case = simulate_dc_case_with(None, &setup, &mut StdRng::seed_from_u64(11));
            assert_eq!(case.truth.plan, plan.name());
            let segs = &case.record.segments;
            let drives = if matches!(plan, PlanKind::Prbs | PlanKind::PositionLoop) {
                4
            } else {
                5
            };
            let coast = usize::from(setup.has_coast());
            assert_eq!(segs.len(), drives + coast, "{plan:?}");
            for w in segs.windows(2) {
                let last = w[0].time.len() - 1;
                assert_eq!(w[0].time[last], w[1].time[0]);
                assert_eq!(w[0].current[last], w[1].current[0]);
            }
            let hold = case.truth.setup["hold_tau"];
            let hold_s = case.truth.setup["hold_s"];
            assert!(
                (2.0 - 1e-9..=12.0 + 1e-9).contains(&hold) || hold_s == 0.05 || hold_s == 1.5,
                "{hold}"
            );
            // A 0 V short is a step the power stage holds: braking current.
            if setup.has_coast() {
                let short = &segs[segs.len() - 1];
                assert_eq!(short.kind, Some(SegmentKind::DcStep));
                assert!(short.label.ends_with("0 V short"), "{}", short.label);
                let braking = short.current.iter().take(20).fold(0.0f64, |m, i| m.min(*i));
                assert!(braking < 0.0, "{plan:?}: no braking current");
            }
            // A closed loop's voltage is the controller's: it varies while
            // a staircase's is held.
            let seg = &segs[2];
            let tail = &seg.voltage[seg.voltage.len() / 2..];
            let spread = tail.iter().fold(f64::MIN, |m, v| m.max(*v))
                - tail.iter().fold(f64::MAX, |m, v| m.min(*v));
            let top = seg.voltage.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            match plan {
                PlanKind::Staircase => assert!(spread < 0.05 * top, "{spread} of {top}"),
                PlanKind::SpeedLoop => assert!(spread > 0.01 * top, "{spread} of {top}"),
                _ => {}
            }
        }
    }
}
