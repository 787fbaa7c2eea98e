//! Voltage steps between two settled levels at which the rotor turns: the
//! data Pasek's method and the method of moments read.
//!
//! Both methods assume the linear model of Eqs. 3–4 around the pre-step
//! level, which holds while the rotor keeps turning one way (the static
//! torque is then a constant load). A step from rest (breakaway) or across
//! zero speed is not used.

use super::error::NotApplicable;
use super::SettledLevel;
use crate::record::{DcSegment, Record, SegmentKind};

/// One step, in absolute time, with the levels before and after it.
#[derive(Debug, Clone, PartialEq)]
pub struct VoltageStep {
    /// Segment index.
    pub segment: u32,
    /// Segment label.
    pub label: String,
    /// Settled level before the step (the previous segment's).
    pub before: SettledLevel,
    /// Settled level after the step (this segment's).
    pub after: SettledLevel,
    /// The equivalent ideal step instant, s: the instant an ideal step of
    /// the same size would have to occur at to give the same voltage–time
    /// area (the midpoint of a slewed ramp).
    pub t_step: f64,
    /// Index of the first sample after the voltage transition.
    pub transition_end: usize,
    /// Index where the settled tail (the level's averaging window) starts.
    pub tail_start: usize,
    /// Standard deviation of the current samples in the settled tail, A.
    pub current_noise: f64,
    /// Speed before the step, rad/s: the level's, refined by
    /// [`counter_speed`] where the previous segment is at hand.
    pub w0: f64,
    /// Speed after the step, rad/s, likewise.
    pub w1: f64,
}

impl VoltageStep {
    /// ΔU = U1 − U0, V.
    pub fn du(&self) -> f64 {
        self.after.voltage - self.before.voltage
    }

    /// Δi(∞), A.
    pub fn di_final(&self) -> f64 {
        self.after.current - self.before.current
    }

    /// Δω(∞), rad/s.
    pub fn dw_final(&self) -> f64 {
        self.w1 - self.w0
    }
}

fn mean_sd(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (m, v.sqrt())
}

/// The step on `seg` from `before` to `after`, or why it cannot be used.
pub fn voltage_step(
    seg: &DcSegment,
    before: &SettledLevel,
    after: &SettledLevel,
) -> Result<VoltageStep, NotApplicable> {
    let n = seg.time.len();
    let du = after.voltage - before.voltage;
    if du.abs() < 1e-9 * after.voltage.abs().max(1.0) {
        return Err(NotApplicable::Missing("no voltage step".into()));
    }
    if before.speed == 0.0 || after.speed == 0.0 || before.speed.signum() != after.speed.signum() {
        return Err(NotApplicable::Missing(
            "the rotor is at rest or reverses across the step".into(),
        ));
    }
    let tail_start = n - after.samples.min(n);
    let (_, u_noise) = mean_sd(&seg.voltage[tail_start..]);
    let (_, current_noise) = mean_sd(&seg.current[tail_start..]);
    let tol = (0.02 * du.abs()).max(4.0 * u_noise);
    // The transition ends where the voltage stays within `tol` of its new
    // level for 3 samples.
    let transition_end = (1..n)
        .find(|&k| (k..(k + 3).min(n)).all(|j| (seg.voltage[j] - after.voltage).abs() <= tol))
        .ok_or_else(|| NotApplicable::Missing("the voltage never reaches its new level".into()))?;
    if transition_end >= tail_start {
        return Err(NotApplicable::Missing(
            "the voltage transition lasts into the settled tail".into(),
        ));
    }
    // The reading at t[k] is the voltage held over (t[k−1], t[k]].
    let t_step = seg.time[0]
        + (1..transition_end)
            .map(|k| (after.voltage - seg.voltage[k]) / du * (seg.time[k] - seg.time[k - 1]))
            .sum::<f64>();
    Ok(VoltageStep {
        segment: seg.index,
        label: seg.label.clone(),
        before: before.clone(),
        after: after.clone(),
        t_step,
        transition_end,
        tail_start,
        current_noise,
        w0: before.speed,
        w1: counter_speed(&seg.time[tail_start..], &seg.speed[tail_start..]),
    })
}

/// The angle the speed readings integrate to (each reading over the
/// interval before it), starting at 0: for a speed derived from encoder
/// counts, the count itself in radians.
pub(crate) fn running_angle(time: &[f64], speed: &[f64]) -> Vec<f64> {
    let mut acc = 0.0;
    (0..time.len().min(speed.len()))
        .map(|k| {
            if k > 0 {
                acc += speed[k] * (time[k] - time[k - 1]);
            }
            acc
        })
        .collect()
}

/// The mean speed over a window, as the least-squares slope of the angle
/// (the running sum of speed × interval) against time.
///
/// For a speed derived from encoder counts the running sum is the count
/// itself, each reading off by its own quantisation (±1/2 count, nearly
/// independent), so the slope averages them; the plain mean of the speed
/// samples is the count change between the window's two ends only, off
/// by up to a count over the window. The moments method integrates its
/// final-value error with weights up to t³/6, so the difference shows.
pub fn counter_speed(time: &[f64], speed: &[f64]) -> f64 {
    let n = time.len().min(speed.len());
    if n < 3 {
        return speed[..n].iter().sum::<f64>() / n.max(1) as f64;
    }
    let angle = running_angle(&time[..n], &speed[..n]);
    let tm = time[..n].iter().sum::<f64>() / n as f64;
    let am = angle.iter().sum::<f64>() / n as f64;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for k in 0..n {
        sxy += (time[k] - tm) * (angle[k] - am);
        sxx += (time[k] - tm).powi(2);
    }
    sxy / sxx
}

/// Every usable step of `record`: a step segment whose level and whose
/// predecessor's level are settled and turning the same way, the
/// segments contiguous in time.
pub fn voltage_steps(record: &Record, levels: &[SettledLevel]) -> Vec<VoltageStep> {
    let level = |index: u32| levels.iter().find(|l| l.segment == index && l.settled);
    let mut out = Vec::new();
    for pair in record.segments.windows(2) {
        let (prev, seg) = (&pair[0], &pair[1]);
        if seg.kind == Some(SegmentKind::DcCoastdown) || seg.time.len() < 2 || prev.time.is_empty()
        {
            continue;
        }
        let dt = (seg.time[seg.time.len() - 1] - seg.time[0]) / (seg.time.len() - 1) as f64;
        if seg.time[0] - prev.time[prev.time.len() - 1] > 2.0 * dt {
            continue;
        }
        let (Some(before), Some(after)) = (level(prev.index), level(seg.index)) else {
            continue;
        };
        if let Ok(mut step) = voltage_step(seg, before, after) {
            let m = prev.time.len();
            let start = m - before.samples.min(m);
            step.w0 = counter_speed(&prev.time[start..], &prev.speed[start..]);
            out.push(step);
        }
    }
    out
}

/// The step to fit on: the largest voltage rise, else the largest step.
pub fn fit_step(steps: &[VoltageStep]) -> Option<usize> {
    let rise = |s: &VoltageStep| s.du() * s.after.voltage.signum();
    let best_by = |f: &dyn Fn(&VoltageStep) -> f64| {
        steps
            .iter()
            .enumerate()
            .filter(|(_, s)| f(s) > 0.0)
            .max_by(|a, b| f(a.1).total_cmp(&f(b.1)))
            .map(|(n, _)| n)
    };
    best_by(&rise).or_else(|| best_by(&|s: &VoltageStep| s.du().abs()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level(segment: u32, voltage: f64, speed: f64, samples: usize) -> SettledLevel {
        SettledLevel {
            segment,
            label: String::new(),
            voltage,
            current: 0.1,
            speed,
            samples,
            settled: true,
        }
    }

    #[test]
    fn equivalent_step_instant_is_the_ramp_midpoint() {
        // 1 ms sampling; the voltage ramps 60 → 248 V over samples 1..=4
        // (each reading held over the interval before it).
        let time: Vec<f64> = (0..200).map(|k| 1.0 + k as f64 * 1e-3).collect();
        let voltage: Vec<f64> = (0..200)
            .map(|k| match k {
                0 => 60.0,
                1..=4 => 60.0 + 188.0 * k as f64 / 4.0,
                _ => 248.0,
            })
            .collect();
        let seg = DcSegment {
            index: 1,
            time,
            current: vec![0.1; 200],
            speed: vec![10.0; 200],
            voltage,
            ..Default::default()
        };
        let s = voltage_step(&seg, &level(0, 60.0, 10.0, 50), &level(1, 248.0, 20.0, 50)).unwrap();
        // Held values 107, 154, 201 over the first three intervals: the
        // area missing is (0.75 + 0.5 + 0.25)·1 ms = 1.5 ms.
        assert!((s.t_step - 1.0015).abs() < 1e-12, "{}", s.t_step);
        assert_eq!(s.transition_end, 4);
        assert_eq!(s.tail_start, 150);
        let rest = voltage_step(&seg, &level(0, 60.0, 0.0, 50), &level(1, 248.0, 20.0, 50));
        assert!(rest.unwrap_err().to_string().contains("rest"));
    }
}
