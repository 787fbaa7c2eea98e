//! Simulate the full DC model on a recorded segment, with the measured
//! armature voltage as input: the "sim" every dynamic method is validated
//! against.

use crate::model::{DcMotor, DcParams, DcState, ParamError, Terminal};
use crate::record::{DcSegment, SegmentKind};

/// The model's current and speed on `seg`'s time base.
///
/// A step segment starts from its first measured current and speed (the
/// state it begins in, settled or not: a step from a settled level, or
/// the first one from rest while the supply slews — where the model's
/// steady state at the first voltage reading, mid-slew, put the rotor at
/// speed before it had moved); a coast-down from the first measured
/// speed with the armature open. The voltage reading at `t[k]`
/// is taken as the voltage applied over `(t[k−1], t[k]]` (zero-order
/// hold, as the simulated rig reports it); the sample interval is the
/// segment's mean.
pub fn simulate_segment(
    params: &DcParams,
    seg: &DcSegment,
) -> Result<(Vec<f64>, Vec<f64>), ParamError> {
    let n = seg.time.len();
    if n < 2 {
        return Ok((seg.current.clone(), seg.speed.clone()));
    }
    let dt = (seg.time[n - 1] - seg.time[0]) / (n - 1) as f64;
    let motor = DcMotor::new(*params, dt)?;
    let coast = seg.kind == Some(SegmentKind::DcCoastdown);
    let mut x = if coast {
        DcState {
            current: 0.0,
            speed: seg.speed[0],
            angle: 0.0,
        }
    } else {
        DcState {
            current: seg.current[0],
            speed: seg.speed[0],
            angle: 0.0,
        }
    };
    let (mut current, mut speed) = (Vec::with_capacity(n), Vec::with_capacity(n));
    current.push(x.current);
    speed.push(x.speed);
    for k in 1..n {
        let terminal = if coast {
            Terminal::Open
        } else {
            Terminal::Driven(seg.voltage[k])
        };
        x = motor.step(&x, terminal);
        current.push(x.current);
        speed.push(x.speed);
    }
    Ok((current, speed))
}

#[cfg(test)]
mod tests {
    use super::super::recorded::recorded;
    use super::*;

    /// A step segment recorded from the model itself.
    fn step_segment(p: &DcParams, x0: DcState, n: usize, u: impl Fn(usize) -> f64) -> DcSegment {
        let (mut seg, _) = recorded(p, 5e-4, x0, n, u);
        seg.kind = Some(SegmentKind::DcStep);
        seg
    }

    #[test]
    fn reproduces_a_segment_simulated_with_the_same_model() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let seg = step_segment(&p, p.steady_state(60.0), 2000, |k| {
            if k == 0 {
                60.0
            } else {
                248.0
            }
        });
        let (i, w) = simulate_segment(&p, &seg).unwrap();
        assert_eq!(i.len(), 2000);
        for k in 0..2000 {
            assert!((i[k] - seg.current[k]).abs() < 1e-12 && (w[k] - seg.speed[k]).abs() < 1e-9);
        }
    }

    #[test]
    fn a_segment_from_rest_starts_at_rest_even_when_its_first_voltage_is_mid_slew() {
        // The first step of a run: the rotor at rest while the supply
        // slews to 60 V; the first voltage reading is 25 V. The model's
        // steady state at 25 V would start the rotor at about 17 rad/s.
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let seg = step_segment(&p, DcState::default(), 1000, |k| {
            (25.0 + 17.5 * k as f64).min(60.0)
        });
        let (i, w) = simulate_segment(&p, &seg).unwrap();
        assert_eq!((i[0], w[0]), (0.0, 0.0));
        for k in 0..1000 {
            assert!((i[k] - seg.current[k]).abs() < 1e-12 && (w[k] - seg.speed[k]).abs() < 1e-9);
        }
    }
}
