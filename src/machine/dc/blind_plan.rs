//! The test plan and the sensors of a blind DC case: what drives the
//! armature in each segment and how the readings are taken.
//!
//! The classic plan ([`DcSetup::classic`]) is the settled staircase the
//! blind suite started with: five levels, each held twelve slowest time
//! constants, an open-armature coast-down, a 1000–4096-line encoder and
//! 12-bit ADCs. A wide setup ([`DcSetup::draw`]) varies what a rig
//! engineer's records vary:
//!
//! - the plan: a staircase, ramps, a PRBS between two levels, a PI speed
//!   loop or a position loop driving the armature (the voltage channel is
//!   the controller's command);
//! - holds from 2 to 12 slowest time constants;
//! - the motor's damping (ζ from 0.25 to 4, by its inductance);
//! - the end: an open-armature coast-down or a 0 V short (a braking step);
//! - the speed sensor: an encoder of 100–10 000 lines or a filtered
//!   tachometer; a current sensor of 1–20 kHz bandwidth; 10–16-bit ADCs.

use rand::rngs::StdRng;
use rand::RngExt;

/// What drives the armature over a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanKind {
    /// Voltage levels, each slewed to and held.
    Staircase,
    /// Voltage ramps between levels, then held.
    Ramp,
    /// A pseudo-random binary sequence between two levels per segment.
    Prbs,
    /// A PI speed controller's command follows speed setpoint steps.
    SpeedLoop,
    /// A position controller (P position, PI speed) follows moves.
    PositionLoop,
}

impl PlanKind {
    /// Every plan a wide suite draws from.
    pub const ALL: [PlanKind; 5] = [
        PlanKind::Staircase,
        PlanKind::Ramp,
        PlanKind::Prbs,
        PlanKind::SpeedLoop,
        PlanKind::PositionLoop,
    ];

    /// The plan's name in the truth file and the score table.
    pub fn name(self) -> &'static str {
        match self {
            PlanKind::Staircase => "staircase",
            PlanKind::Ramp => "ramp",
            PlanKind::Prbs => "prbs",
            PlanKind::SpeedLoop => "speed_loop",
            PlanKind::PositionLoop => "position_loop",
        }
    }
}

/// How the record ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coast {
    /// The armature opened: no current, the voltage reading is the EMF.
    Open,
    /// The armature shorted by the power stage: a step to 0 V.
    Short,
}

/// The speed reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SpeedSensor {
    /// Counts of an encoder; `None`: the classic 1000–4096 lines.
    Encoder(Option<f64>),
    /// A tachometer through a first-order filter of `tau` s, with white
    /// noise of `noise` times the top speed, on the ADC.
    Tachometer {
        /// Filter time constant, s.
        tau: f64,
        /// Noise, a fraction of the top speed.
        noise: f64,
    },
}

/// The plan and sensors of one case.
#[derive(Debug, Clone, PartialEq)]
pub struct DcSetup {
    /// What drives the armature.
    pub plan: PlanKind,
    /// Hold per segment in slowest time constants; `None`: twelve,
    /// clamped to 0.3–1.5 s (the classic staircase).
    pub hold_tau: Option<f64>,
    /// Damping ratio the motor's inductance is set to; `None`: the family's.
    pub zeta: Option<f64>,
    /// How the record ends (a position loop ends at rest, without one).
    pub coast: Coast,
    /// The speed reading.
    pub speed: SpeedSensor,
    /// ADC resolution; `None`: 12 bits.
    pub adc_bits: Option<u32>,
    /// Current sensor bandwidth, Hz; `None`: ideal.
    pub current_bw: Option<f64>,
    /// Fraction of a ramp segment spent ramping.
    pub ramp_share: f64,
    /// A closed loop's speed bandwidth, in units of 1/τm.
    pub loop_gain: f64,
    /// Seed of the PRBS bits.
    pub prbs_seed: u64,
}

impl DcSetup {
    /// The classic settled staircase.
    pub fn classic() -> DcSetup {
        DcSetup {
            plan: PlanKind::Staircase,
            hold_tau: None,
            zeta: None,
            coast: Coast::Open,
            speed: SpeedSensor::Encoder(None),
            adc_bits: None,
            current_bw: None,
            ramp_share: 1.0,
            loop_gain: 3.0,
            prbs_seed: 0,
        }
    }

    /// A wide setup of `plan`, every other choice drawn from `rng`.
    pub fn draw(plan: PlanKind, rng: &mut StdRng) -> DcSetup {
        let log_uniform = |rng: &mut StdRng, lo: f64, hi: f64| -> f64 {
            rng.random_range(lo.ln()..hi.ln()).exp()
        };
        let zeta = if rng.random_bool(0.5) {
            rng.random_range(0.25..0.9)
        } else {
            log_uniform(rng, 1.2, 4.0)
        };
        let speed = if rng.random_bool(0.7) {
            SpeedSensor::Encoder(Some(log_uniform(rng, 100.0, 10_000.0).round()))
        } else {
            SpeedSensor::Tachometer {
                tau: log_uniform(rng, 1e-4, 1e-3),
                noise: rng.random_range(0.001..0.005),
            }
        };
        DcSetup {
            plan,
            hold_tau: Some(log_uniform(rng, 2.0, 12.0)),
            zeta: Some(zeta),
            coast: if rng.random_bool(0.5) {
                Coast::Open
            } else {
                Coast::Short
            },
            speed,
            adc_bits: Some(rng.random_range(10..=16)),
            current_bw: Some(log_uniform(rng, 1e3, 2e4)),
            ramp_share: rng.random_range(0.5..1.0),
            loop_gain: rng.random_range(1.5..4.0),
            prbs_seed: rng.random(),
        }
    }

    /// Hold per segment, s, for a motor whose slowest mode decays with `tau_slow`.
    pub fn hold(&self, tau_slow: f64) -> f64 {
        match self.hold_tau {
            None => (12.0 * tau_slow).clamp(0.3, 1.5),
            Some(h) => (h * tau_slow).clamp(0.05, 1.5),
        }
    }

    /// Whether the record ends with a coast (open or short).
    pub fn has_coast(&self) -> bool {
        self.plan != PlanKind::PositionLoop
    }
}

/// What drives the armature during one segment.
#[derive(Debug, Clone, PartialEq)]
pub enum Drive {
    /// Slew to the level and hold it.
    Level(f64),
    /// Ramp linearly from `from` to `to` over `samples`, then hold.
    Ramp {
        /// Start, V.
        from: f64,
        /// End, V.
        to: f64,
        /// Ramp length, samples.
        samples: usize,
    },
    /// Switch between `lo` and `hi` per `bits`, each `bit` samples long.
    Prbs {
        /// Low level, V.
        lo: f64,
        /// High level, V.
        hi: f64,
        /// The sequence.
        bits: Vec<bool>,
        /// Samples per bit.
        bit: usize,
    },
    /// The speed loop tracks `target` rad/s.
    Speed(f64),
    /// The position loop moves from `from` to `to` rad at `speed` rad/s, then holds.
    Move {
        /// Start, rad.
        from: f64,
        /// End, rad.
        to: f64,
        /// Reference speed, rad/s.
        speed: f64,
    },
    /// The armature open.
    Open,
    /// The armature shorted (0 V).
    Short,
}

/// A PI speed controller (and a P position loop around it) designed
/// from the datasheet values, with anti-windup by conditional
/// integration, updated once per sample.
#[derive(Debug, Clone)]
pub struct Controller {
    kp: f64,
    ki: f64,
    k_pos: f64,
    limit: f64,
    w_max: f64,
    integral: f64,
}

impl Controller {
    /// Design for a motor of EMF constant `k`, resistance `ra`, mechanical
    /// time constant `tau_m`, speed bandwidth `gain/τm`, voltage `limit`.
    pub fn new(k: f64, ra: f64, j: f64, tau_m: f64, gain: f64, limit: f64) -> Controller {
        let wc = gain / tau_m;
        let kp = wc * ra * j / k;
        Controller {
            kp,
            ki: kp / tau_m,
            k_pos: wc / 4.0,
            limit,
            w_max: limit / k,
            integral: 0.0,
        }
    }

    /// The voltage command for speed reference `w_ref` at speed reading `w`.
    pub fn speed(&mut self, w_ref: f64, w: f64, dt: f64) -> f64 {
        let e = w_ref - w;
        let free = self.kp * e + self.ki * self.integral;
        if free.abs() < self.limit || free.signum() != e.signum() {
            self.integral += e * dt;
        }
        (self.kp * e + self.ki * self.integral).clamp(-self.limit, self.limit)
    }

    /// The voltage command for position reference `th_ref` at position
    /// `th` and speed reading `w`.
    pub fn position(&mut self, th_ref: f64, th: f64, w: f64, dt: f64) -> f64 {
        let w_ref = (self.k_pos * (th_ref - th)).clamp(-self.w_max, self.w_max);
        self.speed(w_ref, w, dt)
    }
}

/// The drives of a plan's segments (the coast excluded), for `levels`
/// (V) of a motor with EMF constant `k`, each segment `hold` s long.
pub fn drives(setup: &DcSetup, levels: &[f64], k: f64, hold: f64, dt: f64) -> Vec<Drive> {
    let samples = (hold / dt).round() as usize;
    let mut prev = 0.0;
    match setup.plan {
        PlanKind::Staircase => levels.iter().map(|l| Drive::Level(*l)).collect(),
        PlanKind::Ramp => levels
            .iter()
            .map(|&l| {
                let d = Drive::Ramp {
                    from: prev,
                    to: l,
                    samples: ((samples as f64 * setup.ramp_share) as usize).max(1),
                };
                prev = l;
                d
            })
            .collect(),
        PlanKind::Prbs => {
            let mut bits_rng = <StdRng as rand::SeedableRng>::seed_from_u64(setup.prbs_seed);
            let top = levels.iter().fold(0.0f64, |m, l| m.max(*l));
            // Bits of a fifth of a hold: a 2-τ hold still switches ten times.
            let bit = (samples / 5).max(2);
            levels[1..]
                .iter()
                .map(|&l| {
                    let hi = l.max(0.3 * top);
                    let lo = hi - 0.25 * top;
                    Drive::Prbs {
                        lo,
                        hi,
                        bits: (0..samples.div_ceil(bit))
                            .map(|_| bits_rng.random_bool(0.5))
                            .collect(),
                        bit,
                    }
                })
                .collect()
        }
        PlanKind::SpeedLoop => levels.iter().map(|l| Drive::Speed(0.9 * l / k)).collect(),
        PlanKind::PositionLoop => {
            // Moves out and back so that the speed reverses, at speeds of
            // the levels' no-load speeds (60 % of the segment moving).
            let mut at = 0.0;
            levels[1..]
                .iter()
                .enumerate()
                .map(|(n, &l)| {
                    let speed = 0.8 * l / k;
                    let dir = if n % 2 == 0 { 1.0 } else { -1.0 };
                    let to = at + dir * speed * 0.6 * hold * if n == 0 { 1.0 } else { 1.5 };
                    let d = Drive::Move {
                        from: at,
                        to,
                        speed,
                    };
                    at = to;
                    d
                })
                .collect()
        }
    }
}
