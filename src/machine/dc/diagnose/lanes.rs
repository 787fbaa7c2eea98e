//! The rigid DC models (nominal, or with an effect that enters as `ΔV`,
//! `ΔT`, or read through a sensor's lag) simulated in lockstep: several
//! parameter sets of one model form on the same segment, sample by
//! sample, each "lane" with its own state.
//!
//! Why: one simulation is a serial recursion (the state at `k + 1` needs
//! the state at `k`, through an `exp` or a `tanh` for some effects), so a
//! core spends most of a lone simulation waiting for the previous sample.
//! A finite-difference Jacobian simulates the same segments once per
//! parameter, and those simulations do not depend on one another: stepped
//! together, the core overlaps them. Every lane does exactly the
//! arithmetic the lone simulation does, in the same order, so a lane's
//! readings are the lone simulation's to the last bit (a test holds it).
//! [`AugModel::simulate_runs`] is the one-lane case of the same code.

use super::model::{
    AugModel, CoastStep, Continuation, EndState, LagFilter, Rigid, SegmentRun, Start,
};

/// Simulate the models of `models` whose `live` is set on `runs` in order,
/// each run that continues the one before it from the lane's state at that
/// run's end, as [`AugModel::simulate_runs`] does for one model;
/// `out(l, n, readings)` with the `(current, speed reading)` of every
/// sample of run `n` in lane `l`, once per run and lane that emitted any.
/// Rigid models and sensor lags (a rigid motor read through a lag) go in
/// lockstep, shaft compliance one lane after another. Whether each lane's
/// simulation went through.
///
/// The readings are handed over a run at a time, not a sample at a time:
/// the caller's loop over them is then a tight one, where a call per
/// sample and lane cost about a tenth of a diagnosis.
pub(super) fn simulate_runs(
    models: &[AugModel],
    live: &[bool],
    runs: &[SegmentRun],
    mut out: impl FnMut(usize, usize, &[(f64, f64)]),
) -> Vec<bool> {
    let most = runs.iter().map(SegmentRun::len).max().unwrap_or(0) + 1;
    if !models.iter().all(AugModel::in_lockstep) {
        let mut readings = Vec::with_capacity(most);
        return models
            .iter()
            .zip(live)
            .enumerate()
            .map(|(l, (m, &live))| {
                if !live {
                    return false;
                }
                let mut run = None;
                readings.clear();
                let ok = m.simulate_runs(runs, &mut |n, i, w| {
                    if run != Some(n) {
                        if let Some(done) = run {
                            out(l, done, &readings);
                        }
                        readings.clear();
                        run = Some(n);
                    }
                    readings.push((i, w));
                });
                if let Some(done) = run {
                    out(l, done, &readings);
                }
                ok
            })
            .collect();
    }
    // The motors stepped in lockstep: a sensor lag's is the nominal one,
    // its readings passed through the lag (`LagFilter`) as they come.
    let motors: Vec<AugModel> = models.iter().map(AugModel::motor).collect();
    let mut readings: Vec<Vec<(f64, f64)>> = vec![Vec::with_capacity(most); models.len()];
    let mut alive: Vec<bool> = live
        .iter()
        .zip(models)
        .map(|(&l, m)| l && m.valid())
        .collect();
    let mut ends: Vec<Option<EndState>> = vec![None; models.len()];
    let mut prev_index: Option<u32> = None;
    for (n, run) in runs.iter().enumerate() {
        let continues =
            run.continues.is_some() && prev_index.is_some_and(|i| i + 1 == run.seg.index);
        let from: Vec<Option<EndState>> = ends.iter().map(|e| e.filter(|_| continues)).collect();
        let mut filters: Vec<Option<LagFilter>> = models
            .iter()
            .zip(&from)
            .map(|(m, from)| m.lag_filter(run, from.as_ref()))
            .collect();
        let motor_from: Vec<Option<EndState>> = from
            .iter()
            .zip(&filters)
            .map(|(from, lag)| match lag {
                Some(_) => LagFilter::motor_from(from.as_ref()),
                None => *from,
            })
            .collect();
        ends = simulate_rigid(&motors, &alive, run, &motor_from, |l, i, w| {
            readings[l].push(match &mut filters[l] {
                Some(lag) => lag.reading(i, w),
                None => (i, w),
            })
        });
        for (l, lane) in readings.iter_mut().enumerate() {
            if !lane.is_empty() {
                out(l, n, lane);
                lane.clear();
            }
        }
        for ((a, e), lag) in alive.iter_mut().zip(ends.iter_mut()).zip(filters) {
            if let (Some(end), Some(lag)) = (e.as_mut(), lag) {
                *end = lag.end(*end);
            }
            *a = e.is_some();
        }
        prev_index = Some(run.seg.index);
    }
    alive
}

/// A lane's sample after [`Lane::predict`].
#[derive(Clone, Copy)]
enum Half {
    /// The step is done: `(i, ω, Δθ)` and the friction's direction.
    Done((f64, f64, f64), Option<f64>),
    /// The effect is to be evaluated again at the predicted state.
    Predicted {
        /// The friction's direction.
        d: f64,
        /// The static torque, signed.
        t: f64,
        /// `(ΔV, ΔT)` at the sample's start.
        first: (f64, f64),
        /// The predicted `(i, ω)` and the heat there.
        at: (f64, f64, f64),
    },
}

/// One parameter set's state in a lockstep simulation of one segment.
struct Lane<'m> {
    model: &'m AugModel,
    i: f64,
    w: f64,
    heat: f64,
    /// The last readings emitted (the end state keeps them).
    last: (f64, f64),
    /// False once the model refused its parameters or diverged: a dead
    /// lane emits nothing more.
    alive: bool,
}

impl Lane<'_> {
    #[inline(always)]
    fn emit(&mut self, l: usize, i: f64, w: f64, out: &mut impl FnMut(usize, f64, f64)) {
        self.last = (i, w);
        out(l, i, w);
    }

    /// Set the state where `run` starts (from the end of the previous run
    /// when `from` is given), emitting the first reading where the start
    /// gives one; the index of the first sample left to simulate.
    fn begin(
        &mut self,
        l: usize,
        run: &SegmentRun,
        from: Option<&EndState>,
        out: &mut impl FnMut(usize, f64, f64),
    ) -> usize {
        self.heat = run.heat_before;
        self.last = (0.0, 0.0);
        if let Some(e) = from {
            let [i, w, ..] = e.x;
            self.i = if run.coast { 0.0 } else { i };
            self.w = w;
            if run.continues == Some(Continuation::Shared) {
                let (ri, rw) = e.reading;
                self.emit(l, if run.coast { 0.0 } else { ri }, rw, out);
                return 1;
            }
            return 0;
        }
        let (i, w) = match run.start {
            Start::Rest => (0.0, 0.0),
            Start::Settled(u0) => {
                let s = self.model.steady_state(u0, self.heat);
                self.emit(l, if run.coast { 0.0 } else { s.0 }, s.1, out);
                s
            }
            Start::State(i0, w0) => {
                let i0 = if run.coast { 0.0 } else { i0 };
                self.emit(l, i0, w0, out);
                (i0, w0)
            }
        };
        // An open armature carries no current, whatever the start's.
        (self.i, self.w) = (if run.coast { 0.0 } else { i }, w);
        match run.start {
            Start::Rest => 0,
            Start::Settled(_) | Start::State(..) => 1,
        }
    }

    /// One sample of the open armature: `(0, speed reading)`.
    #[inline]
    fn coast(&mut self, coast: &CoastStep, inv_dt: f64) -> (f64, f64) {
        let (p, w, heat) = (&self.model.p, self.w, self.heat);
        let (nw, dth) = if w == 0.0 {
            (0.0, 0.0)
        } else {
            let dir = w.signum();
            let t0 = p.tst * dir + self.model.perturb(0.0, w, 0.0, heat, dir).1;
            let (pw, _) = coast.step(w, t0);
            let t = if self.model.is_nominal() {
                t0
            } else {
                let t1 = p.tst * dir + self.model.perturb(0.0, pw, 0.0, heat, dir).1;
                0.5 * (t0 + t1)
            };
            let (nw, dth) = coast.step(w, t);
            (if nw * dir < 0.0 { 0.0 } else { nw }, dth)
        };
        self.w = nw;
        (0.0, dth * inv_dt)
    }

    /// The first half of one sample of the driven motor under the
    /// voltage `uk`: the direction of the friction and, for a model with
    /// an effect, the effect at the sample's start and the state it
    /// predicts; a step without an effect to evaluate again is done here.
    #[inline(always)]
    fn predict(&self, step: &Rigid, uk: f64, dt: f64) -> Half {
        let m = self.model;
        let p = &m.p;
        let (i, w, heat) = (self.i, self.w, self.heat);
        let friction = m.breakaway();
        let dir = if w != 0.0 {
            Some(w.signum())
        } else if friction == 0.0 {
            Some(1.0)
        } else if (m.k_eff(i) * i).abs() > friction {
            Some((m.k_eff(i) * i).signum())
        } else {
            None
        };
        match dir {
            None => {
                let (dv, _) = m.perturb(i, 0.0, uk, heat, 1.0);
                let i_ss = (uk - dv) / p.ra;
                Half::Done((i_ss + (i - i_ss) * step.decay, 0.0, 0.0), None)
            }
            Some(d) => {
                let t = p.tst * d;
                if m.is_nominal() {
                    Half::Done(step.step(i, w, uk, t), dir)
                } else {
                    let (dv0, dt0) = m.perturb(i, w, uk, heat, d);
                    let (pi, pw, _) = step.step(i, w, uk - dv0, t + dt0);
                    Half::Predicted {
                        d,
                        t,
                        first: (dv0, dt0),
                        at: (pi, pw, heat + dt * i * i),
                    }
                }
            }
        }
    }

    /// The second half: the effect at the predicted state, the step with
    /// the mean of the two, and the new state; the readings, or `None`
    /// when the state is no longer finite.
    #[inline(always)]
    fn finish(
        &mut self,
        half: Half,
        step: &Rigid,
        uk: f64,
        dt: f64,
        inv_dt: f64,
    ) -> Option<(f64, f64)> {
        let (i, w, heat) = (self.i, self.w, self.heat);
        let ((ni, nw, dth), dir) = match half {
            Half::Done(next, dir) => (next, dir),
            Half::Predicted {
                d,
                t,
                first: (dv0, dt0),
                at: (pi, pw, ph),
            } => {
                let (dv1, dt1) = self.model.perturb(pi, pw, uk, ph, d);
                let next = step.step(i, w, uk - 0.5 * (dv0 + dv1), t + 0.5 * (dt0 + dt1));
                (next, Some(d))
            }
        };
        self.heat = heat + 0.5 * dt * (i * i + ni * ni);
        let nw = match dir {
            Some(d) if nw * d < 0.0 => 0.0,
            _ => nw,
        };
        (self.i, self.w) = (ni, nw);
        if !(ni.is_finite() && nw.is_finite()) {
            return None;
        }
        Some((ni, dth * inv_dt))
    }

    fn end(&self) -> EndState {
        EndState {
            x: [self.i, self.w, self.w, 0.0],
            reading: self.last,
            ..EndState::default()
        }
    }
}

/// Simulate every model of `models` whose `live` is set (all rigid: not a
/// sensor lag, not shaft compliance) on `run`, lane `l` from `from[l]`
/// when given (the end of the previous run); `out(l, current, speed
/// reading)` for every sample of lane `l`, the lanes interleaved sample by
/// sample. The end state of each lane, `None` where it was not live, the
/// model refuses its parameters or it diverged (that lane stops emitting
/// there).
pub(super) fn simulate_rigid(
    models: &[AugModel],
    live: &[bool],
    run: &SegmentRun,
    from: &[Option<EndState>],
    mut out: impl FnMut(usize, f64, f64),
) -> Vec<Option<EndState>> {
    let mut lanes: Vec<Lane> = models
        .iter()
        .zip(live)
        .map(|(model, &live)| Lane {
            model,
            i: 0.0,
            w: 0.0,
            heat: 0.0,
            last: (0.0, 0.0),
            alive: live && model.valid(),
        })
        .collect();
    let dt = run.dt;
    let inv_dt = 1.0 / dt;
    let u = &run.seg.voltage;
    // Every lane starts at the same sample: whether a start emits a
    // reading depends on the run and on whether `from` is given, which
    // the caller decides for all lanes alike.
    let mut first = 0;
    for (l, lane) in lanes.iter_mut().enumerate() {
        if lane.alive {
            first = lane.begin(l, run, from[l].as_ref(), &mut out);
        }
    }
    if run.coast {
        let coasts: Vec<CoastStep> = models.iter().map(|m| CoastStep::new(&m.p, dt)).collect();
        for _ in first..u.len() {
            for (l, lane) in lanes.iter_mut().enumerate() {
                if lane.alive {
                    let (i, w) = lane.coast(&coasts[l], inv_dt);
                    lane.emit(l, i, w, &mut out);
                }
            }
        }
        return lanes
            .iter()
            .map(|lane| (lane.alive && lane.w.is_finite()).then(|| lane.end()))
            .collect();
    }
    let steps: Vec<Option<Rigid>> = lanes
        .iter_mut()
        .map(|lane| {
            let step = if lane.alive {
                Rigid::new(&lane.model.p, dt)
            } else {
                None
            };
            lane.alive = step.is_some();
            step
        })
        .collect();
    // Each sample in two passes over the lanes: the effect at every
    // lane's state, then at every lane's predicted state. Within a lane
    // the two depend on each other (through an `exp` or a `tanh` for
    // some effects), across lanes they do not: a pass lets the core
    // overlap the lanes' evaluations, where one lane's whole sample
    // after another's waited for each in turn.
    let mut halves = vec![Half::Done((0.0, 0.0, 0.0), None); lanes.len()];
    for &uk in &u[first..] {
        for ((lane, step), half) in lanes.iter().zip(&steps).zip(halves.iter_mut()) {
            if let Some(step) = step.as_ref().filter(|_| lane.alive) {
                *half = lane.predict(step, uk, dt);
            }
        }
        for (l, ((lane, step), half)) in lanes.iter_mut().zip(&steps).zip(&halves).enumerate() {
            let Some(step) = step.as_ref().filter(|_| lane.alive) else {
                continue;
            };
            match lane.finish(*half, step, uk, dt, inv_dt) {
                Some((i, w)) => lane.emit(l, i, w, &mut out),
                None => lane.alive = false,
            }
        }
    }
    lanes
        .iter()
        .map(|lane| lane.alive.then(|| lane.end()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::dc::diagnose::model::{Augment, LagChannel};
    use crate::model::DcParams;
    use crate::record::DcSegment;

    /// A segment of `n` samples at 1 kHz under `volts(k)`; the readings
    /// do not matter to a simulation.
    fn segment(index: u32, n: usize, volts: impl Fn(usize) -> f64) -> DcSegment {
        let mut seg = DcSegment {
            index,
            ..Default::default()
        };
        for k in 0..n {
            seg.push_sample(k as f64 * 1e-3, volts(k), 0.0, 0.0);
        }
        seg
    }

    /// Each lane of a lockstep simulation emits what its model alone
    /// emits, bit for bit, over a start from rest, a continued segment, a
    /// coast-down and a segment after a gap, sensor lags among them; a
    /// refused model's lane emits nothing and fails without disturbing the
    /// others.
    #[test]
    fn every_lane_is_its_model_alone() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let segs = [
            segment(0, 300, |k| if k < 100 { 60.0 } else { 248.0 }),
            segment(1, 200, |k| 120.0 + (k % 7) as f64),
            segment(2, 400, |_| 0.0),
            segment(4, 150, |k| -30.0 * (k as f64 / 50.0).sin()),
        ];
        let start = [
            Start::Rest,
            Start::Settled(248.0),
            Start::Settled(120.0),
            Start::State(1.0, 3.0),
        ];
        let runs: Vec<SegmentRun> = segs
            .iter()
            .zip(start)
            .enumerate()
            .map(|(n, (seg, start))| SegmentRun {
                seg,
                dt: 1e-3,
                start,
                coast: n == 2,
                heat_before: 10.0 * n as f64,
                // The second run shares its first sample with the first's
                // last (a boundary sample both segments hold).
                continues: match n {
                    0 => None,
                    1 => Some(Continuation::Shared),
                    _ => Some(Continuation::Next),
                },
            })
            .collect();
        let with = |aug, e: [f64; 3]| AugModel { p, aug, e };
        let models = [
            AugModel::nominal(p),
            with(Augment::CoulombFriction, [0.05, 20.0, 0.0]),
            with(Augment::BrushDrop, [1.5, 0.8, 0.0]),
            with(Augment::ArmatureReaction, [2e-4, 0.0, 0.0]),
            // Refused: a negative friction speed.
            with(Augment::CoulombFriction, [0.05, -1.0, 0.0]),
            with(Augment::InductanceSaturation, [5e-3, 0.0, 0.0]),
            with(Augment::ThermalDrift, [1e-3, 0.0, 0.0]),
            // A rigid motor read through a lag, with and without a dead
            // time, on either channel.
            with(Augment::SensorLag(LagChannel::Current), [2e-3, 0.0, 0.0]),
            with(Augment::SensorLag(LagChannel::Speed), [5e-3, 2e-3, 0.0]),
            with(Augment::SensorLag(LagChannel::Current), [0.0, 1e-3, 0.0]),
            // Refused: a lag that is not a number.
            with(Augment::SensorLag(LagChannel::Speed), [f64::NAN, 0.0, 0.0]),
        ];
        let mut lanes: Vec<Vec<(usize, u64, u64)>> = vec![Vec::new(); models.len()];
        let ok = simulate_runs(&models, &[true; 11], &runs, |l, n, readings| {
            lanes[l].extend(readings.iter().map(|(i, w)| (n, i.to_bits(), w.to_bits())))
        });
        for (l, m) in models.iter().enumerate() {
            let mut alone = Vec::new();
            let alone_ok = m.simulate_runs(&runs, &mut |n, i, w| {
                alone.push((n, i.to_bits(), w.to_bits()))
            });
            assert_eq!(ok[l], alone_ok, "lane {l}");
            assert_eq!(lanes[l], alone, "lane {l}");
        }
        assert_eq!(
            ok,
            [true, true, true, true, false, true, true, true, true, true, false]
        );
        assert!(lanes[4].is_empty() && lanes[10].is_empty());
        // The lags lag: their readings are not the nominal motor's.
        assert_ne!(lanes[7], lanes[0]);
        assert_ne!(lanes[8], lanes[0]);
        assert_eq!(lanes[0].len(), 300 + 200 + 400 + 150);
    }
}
