//! The output-error fit's inner loop: the DC model simulated exactly (zero-
//! order hold) on one recorded step segment, with the measured voltage as
//! input, as fast as the fit needs.
//!
//! [`DcMotor::step`] handles effects, open terminals and RK4; the fit calls
//! the simulation some hundred times per record, so this loop takes the
//! motor's own discretisation ([`DcMotor::driven_zoh`]) and repeats only
//! the driven branch of its exact step in scalars (friction direction,
//! stiction, stop on a sign change). A unit test holds the two equal.
//!
//! A forward-difference Jacobian simulates seven parameter sets at once
//! ([`simulate_lanes`]): their steps go as vector operations while every
//! rotor turns, each lane's arithmetic still the lone simulation's, so
//! its readings are the same to the bit.

use crate::identify::vector::with_avx;
use crate::model::{DcMotor, DcParams, ParamError};
use crate::record::DcSegment;

/// What the speed channel of a record reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SpeedReading {
    /// The mean speed over the preceding sample interval: differentiated
    /// encoder counts, which is what the bench records.
    #[default]
    IntervalMean,
    /// The speed at the sampling instant (a tachometer, an observer).
    Instantaneous,
}

/// The state a step segment starts from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SegmentStart {
    /// Settled at the given voltage, V: the level before the segment
    /// (whose last sample is the segment's first), which had settled. The
    /// mean over that level's settled tail is far less noisy than the one
    /// boundary reading, and the whole step response scales with it.
    Settled(f64),
    /// At rest without current before the first sample; the first voltage
    /// reading is the first voltage applied (a start from a disabled
    /// supply or after a coast-down).
    FromRest,
    /// In a measured state at the first sample: current, A, and speed,
    /// rad/s (a segment after a level that had not settled, or a record
    /// that starts in motion away from any steady state).
    State {
        /// Armature current, A.
        current: f64,
        /// Speed, rad/s.
        speed: f64,
    },
}

/// A step segment ready to simulate.
#[derive(Debug, Clone, Copy)]
pub struct SegmentInput<'a> {
    /// The recorded segment.
    pub seg: &'a DcSegment,
    /// Sample interval, s (the segment's mean).
    pub dt: f64,
    /// How it starts.
    pub start: SegmentStart,
    /// For a settled start at the mean voltage over the settled tail of
    /// the record's previous segment: that segment's index and the number
    /// of its last samples averaged. The noise of those readings reaches
    /// this segment through its start.
    pub level_before: Option<(u32, usize)>,
}

impl<'a> SegmentInput<'a> {
    /// Prepare `seg` (at least 2 samples) starting as `start` says.
    pub fn new(seg: &'a DcSegment, start: SegmentStart) -> SegmentInput<'a> {
        let n = seg.time.len();
        let dt = (seg.time[n - 1] - seg.time[0]) / (n - 1).max(1) as f64;
        SegmentInput {
            seg,
            dt,
            start,
            level_before: None,
        }
    }

    /// Samples in the segment.
    pub fn len(&self) -> usize {
        self.seg.time.len()
    }
}

/// One exact step of the driven motor in scalars: the coefficients of
/// [`DcMotor::driven_zoh`] and what the stiction branch needs.
pub struct DrivenStep {
    /// Columns `i`, `ω` of the state transition, rows `i`, `ω`, `θ`.
    pub a: [[f64; 2]; 3],
    /// Input matrix: columns `U`, `Tst·dir`; rows `i`, `ω`, `θ`.
    pub b: [[f64; 2]; 3],
    k: f64,
    ra: f64,
    tst: f64,
    decay: f64,
}

impl DrivenStep {
    /// The step of `params` over `dt`.
    pub fn new(params: &DcParams, dt: f64) -> Result<DrivenStep, ParamError> {
        let motor = DcMotor::new(*params, dt)?;
        let z = motor.driven_zoh();
        Ok(DrivenStep {
            a: std::array::from_fn(|r| [z.ad[(r, 0)], z.ad[(r, 1)]]),
            b: std::array::from_fn(|r| [z.bd[(r, 0)], z.bd[(r, 1)]]),
            k: params.k,
            ra: params.ra,
            tst: params.tst,
            decay: (-dt / params.tau_e()).exp(),
        })
    }

    /// `(i, ω, Δθ)` after one step from `(i, ω)` under voltage `u`.
    #[inline]
    fn step(&self, i: f64, w: f64, u: f64) -> (f64, f64, f64) {
        let dir = if w != 0.0 {
            w.signum()
        } else if self.tst == 0.0 {
            1.0
        } else if (self.k * i).abs() > self.tst {
            (self.k * i).signum()
        } else {
            // Held by the static torque: only the circuit moves.
            let i_ss = u / self.ra;
            return (i_ss + (i - i_ss) * self.decay, 0.0, 0.0);
        };
        let t = self.tst * dir;
        let (a, b) = (&self.a, &self.b);
        let ni = a[0][0] * i + a[0][1] * w + b[0][0] * u + b[0][1] * t;
        let nw = a[1][0] * i + a[1][1] * w + b[1][0] * u + b[1][1] * t;
        let dth = a[2][0] * i + a[2][1] * w + b[2][0] * u + b[2][1] * t;
        (ni, if nw * dir < 0.0 { 0.0 } else { nw }, dth)
    }
}

/// Simulate `params` on `input`; `out(current, speed reading)` for every
/// sample of the segment, in order.
///
/// The voltage reading at `t[k]` is the voltage applied over
/// `(t[k−1], t[k]]`, as the bench records it.
pub fn simulate(
    params: &DcParams,
    input: &SegmentInput,
    reading: SpeedReading,
    mut out: impl FnMut(f64, f64),
) -> Result<(), ParamError> {
    let step = DrivenStep::new(params, input.dt)?;
    let u = &input.seg.voltage;
    let inv_dt = 1.0 / input.dt;
    let interval = reading == SpeedReading::IntervalMean;
    let (mut i, mut w) = first_sample(params, &step, input, interval, &mut out);
    for &uk in u.iter().skip(1) {
        let (ni, nw, dth) = step.step(i, w, uk);
        (i, w) = (ni, nw);
        out(ni, if interval { dth * inv_dt } else { nw });
    }
    Ok(())
}

/// The state at a segment's first sample, as `input.start` says, and its
/// reading handed to `out`.
fn first_sample(
    params: &DcParams,
    step: &DrivenStep,
    input: &SegmentInput,
    interval: bool,
    out: &mut impl FnMut(f64, f64),
) -> (f64, f64) {
    match input.start {
        SegmentStart::Settled(u0) => {
            let s = params.steady_state(u0);
            out(s.current, s.speed);
            (s.current, s.speed)
        }
        SegmentStart::FromRest => {
            let (i, w, dth) = step.step(0.0, 0.0, input.seg.voltage[0]);
            // As the steps after it: times the inverse of the interval.
            out(i, if interval { dth * (1.0 / input.dt) } else { w });
            (i, w)
        }
        SegmentStart::State { current, speed } => {
            out(current, speed);
            (current, speed)
        }
    }
}

/// Most parameter sets [`simulate_lanes`] steps at once: the point of a
/// forward-difference Jacobian and its six steps, and one spare.
pub const LANES: usize = 8;

/// The coefficients of up to [`LANES`] [`DrivenStep`]s, one array per
/// coefficient (lane `l` at index `l`), so that one sample's step of every
/// lane is a handful of vector operations.
struct LaneSteps {
    a: [[[f64; LANES]; 2]; 3],
    b: [[[f64; LANES]; 2]; 3],
    tst: [f64; LANES],
}

impl LaneSteps {
    /// `steps`, padded with copies of the first.
    fn new(steps: &[&DrivenStep]) -> LaneSteps {
        let at = |l: usize| steps[if l < steps.len() { l } else { 0 }];
        LaneSteps {
            a: std::array::from_fn(|r| {
                std::array::from_fn(|c| std::array::from_fn(|l| at(l).a[r][c]))
            }),
            b: std::array::from_fn(|r| {
                std::array::from_fn(|c| std::array::from_fn(|l| at(l).b[r][c]))
            }),
            tst: std::array::from_fn(|l| at(l).tst),
        }
    }

    /// One step of every lane whose rotor turns (`w[l] ≠ 0` for every
    /// `l`): [`DrivenStep::step`]'s turning branch, operation for
    /// operation, so each lane gets the lone step's bits. Returns `Δθ`.
    #[inline(always)]
    fn step_turning(&self, i: &mut [f64; LANES], w: &mut [f64; LANES], u: f64) -> [f64; LANES] {
        let (a, b) = (&self.a, &self.b);
        let mut dth = [0.0; LANES];
        for l in 0..LANES {
            // w ≠ 0, so its sign is what `signum` gives.
            let dir = 1.0f64.copysign(w[l]);
            let t = self.tst[l] * dir;
            let (il, wl) = (i[l], w[l]);
            let ni = a[0][0][l] * il + a[0][1][l] * wl + b[0][0][l] * u + b[0][1][l] * t;
            let nw = a[1][0][l] * il + a[1][1][l] * wl + b[1][0][l] * u + b[1][1][l] * t;
            dth[l] = a[2][0][l] * il + a[2][1][l] * wl + b[2][0][l] * u + b[2][1][l] * t;
            i[l] = ni;
            w[l] = if nw * dir < 0.0 { 0.0 } else { nw };
        }
        dth
    }
}

/// What [`simulate_lanes`] hands each sample's readings to: a closure
/// `FnMut(sample, currents, speed readings)`, or a type of its own whose
/// method is `#[inline(always)]`, so that it runs inside the simulation's
/// vector loop instead of as a call per sample.
pub trait LaneReadings {
    /// The readings of every lane at `sample`; entries at and beyond the
    /// number of lanes are padding, to be ignored.
    fn readings(&mut self, sample: usize, current: &[f64; LANES], speed: &[f64; LANES]);
}

impl<F: FnMut(usize, &[f64; LANES], &[f64; LANES])> LaneReadings for F {
    fn readings(&mut self, sample: usize, current: &[f64; LANES], speed: &[f64; LANES]) {
        self(sample, current, speed)
    }
}

/// [`simulate`] for up to [`LANES`] parameter sets at once, in lockstep:
/// one pass over the samples steps every lane (a forward-difference
/// Jacobian's simulations do not depend on one another). While every
/// rotor turns, a sample's step of all lanes is one set of vector
/// operations (AVX where the processor has it, checked at run time);
/// otherwise each lane takes the lone simulation's step. Each lane does
/// the lone simulation's arithmetic in its order, so its readings are the
/// lone simulation's to the last bit ([`with_avx`]).
///
/// `out` gets every sample's readings, in order (see [`LaneReadings`]).
///
/// # Panics
///
/// With no lane or more than [`LANES`].
pub fn simulate_lanes(
    lanes: &[(&DcParams, DrivenStep)],
    input: &SegmentInput,
    reading: SpeedReading,
    out: &mut impl LaneReadings,
) {
    assert!(
        !lanes.is_empty() && lanes.len() <= LANES,
        "1 to {LANES} lanes, not {}",
        lanes.len()
    );
    with_avx(
        #[inline(always)]
        || lanes_kernel(lanes, input, reading, out),
    );
}

/// The body of [`simulate_lanes`].
#[inline(always)]
fn lanes_kernel(
    lanes: &[(&DcParams, DrivenStep)],
    input: &SegmentInput,
    reading: SpeedReading,
    out: &mut impl LaneReadings,
) {
    let u = &input.seg.voltage;
    let inv_dt = 1.0 / input.dt;
    let interval = reading == SpeedReading::IntervalMean;
    let steps: Vec<&DrivenStep> = lanes.iter().map(|(_, s)| s).collect();
    let block = LaneSteps::new(&steps);
    let (mut i, mut w) = ([0.0; LANES], [0.0; LANES]);
    let (mut ci, mut cw) = ([0.0; LANES], [0.0; LANES]);
    for l in 0..LANES {
        let (params, step) = &lanes[if l < lanes.len() { l } else { 0 }];
        (i[l], w[l]) = first_sample(params, step, input, interval, &mut |a, b| {
            (ci[l], cw[l]) = (a, b);
        });
    }
    out.readings(0, &ci, &cw);
    for (k, &uk) in u.iter().enumerate().skip(1) {
        let dth = if w.iter().all(|w| *w != 0.0) {
            block.step_turning(&mut i, &mut w, uk)
        } else {
            let mut dth = [0.0; LANES];
            for l in 0..LANES {
                let (ni, nw, d) = steps[if l < steps.len() { l } else { 0 }].step(i[l], w[l], uk);
                (i[l], w[l], dth[l]) = (ni, nw, d);
            }
            dth
        };
        let speed = if interval { dth.map(|d| d * inv_dt) } else { w };
        out.readings(k, &i, &speed);
    }
}

/// Output variance per unit variance of a white error in the voltage
/// reading: the sums of squares of the impulse responses from the voltage
/// to the current and to the speed reading, in A²/V² and (rad/s)²/V².
/// For the turning motor (friction direction fixed), which is linear.
pub fn voltage_noise_gain(
    params: &DcParams,
    dt: f64,
    reading: SpeedReading,
) -> Result<[f64; 2], ParamError> {
    let step = DrivenStep::new(params, dt)?;
    let (a, b) = (&step.a, &step.b);
    // The sum below runs until the impulse response has decayed, which
    // takes about 12/(1 − ρ) samples for a spectral radius ρ: a model
    // whose slowest mode outlasts 10⁵ samples (J driven towards infinity
    // by a fit gone astray) would take seconds per call, so it gets no
    // gain (the caller then leaves the noise-bias correction out).
    if spectral_radius(a) >= 1.0 - MIN_DECAY_PER_SAMPLE {
        return Err(ParamError {
            name: "J",
            value: params.j,
            reason:
                "gives a mode slower than 10⁵ samples, whose voltage-noise gain is not computed",
        });
    }
    // The response at sample 0 to a unit voltage error over that sample.
    let mut s = [b[0][0], b[1][0]];
    let mut sum = [s[0] * s[0], speed_of(reading, s[1], b[2][0], dt).powi(2)];
    // Until a block of samples adds a negligible fraction.
    let mut block = 0.0;
    for k in 1..100_000_000usize {
        let dth = a[2][0] * s[0] + a[2][1] * s[1];
        s = [
            a[0][0] * s[0] + a[0][1] * s[1],
            a[1][0] * s[0] + a[1][1] * s[1],
        ];
        let add = [s[0] * s[0], speed_of(reading, s[1], dth, dt).powi(2)];
        for c in 0..2 {
            sum[c] += add[c];
            block += add[c] / sum[c].max(f64::MIN_POSITIVE);
        }
        if k % 256 == 0 {
            if block < 1e-13 {
                break;
            }
            block = 0.0;
        }
    }
    Ok(sum)
}

/// Smallest per-sample decay `1 − ρ` of the slowest mode for which
/// [`voltage_noise_gain`] sums the impulse response.
const MIN_DECAY_PER_SAMPLE: f64 = 1e-5;

/// The spectral radius of the (current, speed) block of a state
/// transition: the larger modulus of its two eigenvalues.
fn spectral_radius(a: &[[f64; 2]; 3]) -> f64 {
    let (tr, det) = (a[0][0] + a[1][1], a[0][0] * a[1][1] - a[0][1] * a[1][0]);
    let disc = 0.25 * tr * tr - det;
    if disc >= 0.0 {
        0.5 * tr.abs() + disc.sqrt()
    } else {
        det.abs().sqrt()
    }
}

#[inline]
fn speed_of(reading: SpeedReading, w: f64, dth: f64, dt: f64) -> f64 {
    match reading {
        SpeedReading::IntervalMean => dth / dt,
        SpeedReading::Instantaneous => w,
    }
}

/// [`simulate`] collected into current and speed series.
pub fn simulate_series(
    params: &DcParams,
    input: &SegmentInput,
    reading: SpeedReading,
) -> Result<(Vec<f64>, Vec<f64>), ParamError> {
    let n = input.len();
    let (mut current, mut speed) = (Vec::with_capacity(n), Vec::with_capacity(n));
    simulate(params, input, reading, |i, w| {
        current.push(i);
        speed.push(w);
    })?;
    Ok((current, speed))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{DcState, Terminal};
    use crate::record::SegmentKind;

    #[test]
    fn a_mode_slower_than_the_bound_gets_no_noise_gain() {
        // The seed motor at 2 kHz: τm = 85 ms, 170 samples; a gain.
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let [gi, gw] = voltage_noise_gain(&p, 5e-4, SpeedReading::IntervalMean).unwrap();
        assert!(gi > 0.0 && gw > 0.0 && gi.is_finite() && gw.is_finite());
        // A fit gone astray to J = 10¹² kg·m² (a current read in mA): its
        // mechanical mode would take some 10¹⁴ samples to sum.
        let astray = DcParams { j: 1e12, ..p };
        let e = voltage_noise_gain(&astray, 5e-4, SpeedReading::IntervalMean).unwrap_err();
        assert_eq!(e.name, "J");
    }

    /// A segment recorded from `DcMotor::step` itself, and the mean speed
    /// over each step (from the angle), for voltages `u`: settled at
    /// `u[0]`, or from rest with `u[0]` the first voltage applied.
    fn reference(p: &DcParams, from_rest: bool, u: &[f64], dt: f64) -> (DcSegment, Vec<f64>) {
        let motor = DcMotor::new(*p, dt).unwrap();
        let mut seg = DcSegment {
            kind: Some(SegmentKind::DcStep),
            ..Default::default()
        };
        let mut mean_speed = Vec::new();
        let mut x = if from_rest {
            DcState::default()
        } else {
            p.steady_state(u[0])
        };
        for (k, &uk) in u.iter().enumerate() {
            if k == 0 && !from_rest {
                mean_speed.push(x.speed);
            } else {
                let before = x.angle;
                x = motor.step(&x, Terminal::Driven(uk));
                mean_speed.push((x.angle - before) / dt);
            }
            seg.push_sample(k as f64 * dt, uk, x.current, x.speed);
        }
        (seg, mean_speed)
    }

    #[test]
    fn matches_the_motor_step_from_a_settled_level() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let dt = 5e-4;
        let u: Vec<f64> = (0..3000)
            .map(|k| if k == 0 { 248.0 } else { 60.0 })
            .collect();
        let (seg, mean_speed) = reference(&p, false, &u, dt);
        let input = SegmentInput::new(&seg, SegmentStart::Settled(248.0));
        let (i, w) = simulate_series(&p, &input, SpeedReading::Instantaneous).unwrap();
        let (_, wm) = simulate_series(&p, &input, SpeedReading::IntervalMean).unwrap();
        for k in 0..u.len() {
            assert!((i[k] - seg.current[k]).abs() < 1e-12, "current at {k}");
            assert!((w[k] - seg.speed[k]).abs() < 1e-9, "speed at {k}");
            assert!((wm[k] - mean_speed[k]).abs() < 1e-6, "mean speed at {k}");
        }
        // The interval mean lags the instantaneous speed while it falls.
        assert!(wm[10] > w[10] && w[10] > w[11]);
    }

    #[test]
    fn matches_the_motor_step_from_rest_through_breakaway() {
        // A slow voltage ramp from rest: the rotor is held by Tst until
        // K·i exceeds it, then turns.
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let dt = 5e-4;
        let u: Vec<f64> = (0..4000).map(|k| (k as f64 * 0.01).min(20.0)).collect();
        let (seg, mean_speed) = reference(&p, true, &u, dt);
        let input = SegmentInput::new(&seg, SegmentStart::FromRest);
        let (i, wm) = simulate_series(&p, &input, SpeedReading::IntervalMean).unwrap();
        let held = seg.speed.iter().take_while(|w| **w == 0.0).count();
        assert!(held > 100 && held < 3000, "breakaway at sample {held}");
        for k in 0..u.len() {
            assert!((i[k] - seg.current[k]).abs() < 1e-12, "current at {k}");
            assert!((wm[k] - mean_speed[k]).abs() < 1e-6, "mean speed at {k}");
        }
    }

    /// Every lane of a lockstep simulation is its parameter set alone,
    /// bit for bit, from each kind of start.
    #[test]
    fn every_lane_is_its_parameter_set_alone() {
        let base = DcParams::SEED_TABLE4_MOMENTS;
        let dt = 5e-4;
        // Up, further up, then reversed: the rotor breaks away, turns,
        // stops (the speed clamped at zero, held by Tst) and reverses.
        let u: Vec<f64> = (0..2400)
            .map(|k| match k {
                0..700 => 60.0,
                700..1400 => 248.0,
                _ => -150.0,
            })
            .collect();
        let (seg, _) = reference(&base, true, &u, dt);
        // As many sets as a forward-difference Jacobian's lanes.
        let sets: Vec<DcParams> = [1.0, 1.1, 0.9, 1.3, 0.7, 1.05, 1.6]
            .iter()
            .enumerate()
            .map(|(n, f)| DcParams {
                ra: base.ra * f,
                k: base.k * (1.0 + 0.05 * n as f64),
                tst: base.tst / f,
                ..base
            })
            .collect();
        for start in [
            SegmentStart::FromRest,
            SegmentStart::Settled(60.0),
            SegmentStart::State {
                current: 2.0,
                speed: 40.0,
            },
        ] {
            let input = SegmentInput::new(&seg, start);
            let lanes: Vec<(&DcParams, DrivenStep)> = sets
                .iter()
                .map(|p| (p, DrivenStep::new(p, input.dt).unwrap()))
                .collect();
            // The dispatched kernel (AVX where the processor has it) and
            // the kernel as the baseline build compiles it.
            for baseline in [false, true] {
                let mut got = vec![Vec::new(); sets.len()];
                let mut readings = |k, i: &[f64; LANES], w: &[f64; LANES]| {
                    for (l, got) in got.iter_mut().enumerate() {
                        got.push((k, i[l].to_bits(), w[l].to_bits()));
                    }
                };
                let reading = SpeedReading::IntervalMean;
                if baseline {
                    lanes_kernel(&lanes, &input, reading, &mut readings);
                } else {
                    simulate_lanes(&lanes, &input, reading, &mut readings);
                }
                for (l, p) in sets.iter().enumerate() {
                    let (i, w) = simulate_series(p, &input, reading).unwrap();
                    let alone: Vec<(usize, u64, u64)> = (0..i.len())
                        .map(|k| (k, i[k].to_bits(), w[k].to_bits()))
                        .collect();
                    assert_eq!(
                        got[l], alone,
                        "lane {l} from {start:?}, baseline {baseline}"
                    );
                }
            }
        }
    }

    #[test]
    fn invalid_parameters_are_an_error() {
        let seg = DcSegment {
            time: vec![0.0, 1e-3],
            voltage: vec![1.0, 1.0],
            current: vec![0.0, 0.0],
            speed: vec![0.0, 0.0],
            ..Default::default()
        };
        let p = DcParams {
            j: 0.0,
            ..DcParams::SEED_TABLE4_MOMENTS
        };
        let input = SegmentInput::new(&seg, SegmentStart::Settled(248.0));
        let err = simulate_series(&p, &input, SpeedReading::IntervalMean).unwrap_err();
        assert_eq!(err.name, "J");
    }
}
