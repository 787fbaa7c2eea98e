//! Segments recorded from the DC model's own exact step, for tests.

use crate::model::{DcMotor, DcParams, DcState, Terminal};
use crate::record::DcSegment;

/// A segment of `n` samples `dt` apart recorded from [`DcMotor::step`] of
/// `p`, starting in state `x0` at the first sample: the voltage reading
/// `u(k)` at sample `k` is the voltage applied over the interval before
/// it. Also the mean speed over each interval (from the angle; at the
/// first sample, the speed of `x0`).
pub(crate) fn recorded(
    p: &DcParams,
    dt: f64,
    x0: DcState,
    n: usize,
    u: impl Fn(usize) -> f64,
) -> (DcSegment, Vec<f64>) {
    let motor = DcMotor::new(*p, dt).unwrap();
    let mut x = x0;
    let mut seg = DcSegment::default();
    let mut mean_speed = Vec::with_capacity(n);
    for k in 0..n {
        let uk = u(k);
        let before = x.angle;
        if k > 0 {
            x = motor.step(&x, Terminal::Driven(uk));
        }
        seg.push_sample(k as f64 * dt, uk, x.current, x.speed);
        mean_speed.push(if k == 0 {
            x.speed
        } else {
            (x.angle - before) / dt
        });
    }
    (seg, mean_speed)
}
