//! The DC model's two equations, integrated over each sample interval and
//! low-pass filtered, as rows of a linear regression in (La, Ra, K, J, f,
//! Tst).
//!
//! Over the interval `(t[k−1], t[k]]` the model integrates exactly to
//!
//! ```text
//! ∫U dt          = La·Δi + Ra·∫i dt + K·∫ω dt
//! 0              = −K·∫i dt + J·Δω + f·∫ω dt + Tst·∫sign(ω) dt
//! ```
//!
//! (the voltage reading at `t[k]` is the voltage held over the interval;
//! for an interval-mean speed reading, the speed integral over the
//! interval is the reading itself, and the mechanical equation is taken
//! over `(t[k−½], t[k+½]]`, between two readings, so that the current
//! enters at its sampling instant). Every row is an exact relation between
//! samples up to the quadrature of the current, whatever the state the
//! segment starts in, so no start values or settled levels are needed.
//!
//! The differences `Δi`, `Δω` of noisy samples are mostly noise; the same
//! linear low-pass filter (two first-order sections, zero initial state)
//! is applied to every column, which keeps each relation exact (a filter
//! of a sum of exact relations) while removing the noise above the
//! filter's corner. Rows where the rotor is near rest or reverses are
//! zeroed before filtering: there the static friction is not `Tst·sign(ω)`.

use crate::identify::SpeedReading;
use crate::record::DcSegment;

/// Number of unknowns: La, Ra, K, J, f, Tst (this order).
pub const NU: usize = 6;

/// Index of each unknown in a row.
pub const LA: usize = 0;
/// Armature resistance.
pub const RA: usize = 1;
/// Motor constant.
pub const K: usize = 2;
/// Inertia.
pub const J: usize = 3;
/// Viscous friction.
pub const F: usize = 4;
/// Static torque.
pub const TST: usize = 5;

/// The filtered rows of one segment: electrical and mechanical equation at
/// each sample (`x · θ = y`).
#[derive(Debug, Clone, Default)]
pub struct SegmentRows {
    /// Electrical regressors per sample.
    pub xe: Vec<[f64; NU]>,
    /// Electrical regressand (filtered `∫U dt`).
    pub ye: Vec<f64>,
    /// Mechanical regressors per sample (regressand zero).
    pub xm: Vec<[f64; NU]>,
}

/// A first-order low-pass section applied twice, with pole `a` (0 < a < 1).
#[derive(Debug, Clone, Copy)]
pub struct LowPass {
    a: f64,
}

impl LowPass {
    /// A filter with corner frequency `corner_hz` at sample interval `dt`.
    pub fn new(corner_hz: f64, dt: f64) -> LowPass {
        LowPass {
            a: (-2.0 * std::f64::consts::PI * corner_hz * dt).exp(),
        }
    }

    /// The filter's time constant in samples (of one section).
    pub fn samples(&self) -> f64 {
        1.0 / (1.0 - self.a)
    }

    /// Filter every column of `rows` in place (two passes of one section,
    /// from a zero state).
    pub fn apply<const N: usize>(&self, rows: &mut [[f64; N]]) {
        for _ in 0..2 {
            let mut s = [0.0; N];
            for r in rows.iter_mut() {
                for c in 0..N {
                    s[c] = self.a * s[c] + (1.0 - self.a) * r[c];
                    r[c] = s[c];
                }
            }
        }
    }
}

/// The rows of `seg` with measured current and speed `i`, `w` (the
/// record's, or a simulation's for instruments), filtered by `filter`.
/// `moving[k]` says whether the mechanical row at `k` is used.
pub fn rows(
    seg: &DcSegment,
    i: &[f64],
    w: &[f64],
    moving: &[bool],
    reading: SpeedReading,
    filter: &LowPass,
) -> SegmentRows {
    let n = seg.time.len();
    let dt = (seg.time[n - 1] - seg.time[0]) / (n - 1) as f64;
    let u = &seg.voltage;
    // Electrical rows, one per interval (t[k−1], t[k]]; column NU holds
    // the regressand while filtering.
    let mut e: Vec<[f64; NU + 1]> = (1..n)
        .map(|k| {
            let int_w = match reading {
                SpeedReading::IntervalMean => w[k] * dt,
                SpeedReading::Instantaneous => 0.5 * (w[k] + w[k - 1]) * dt,
            };
            let mut r = [0.0; NU + 1];
            r[LA] = i[k] - i[k - 1];
            r[RA] = 0.5 * (i[k] + i[k - 1]) * dt;
            r[K] = int_w;
            r[NU] = u[k] * dt;
            r
        })
        .collect();
    let mut m: Vec<[f64; NU]> = (1..n)
        .map(|k| {
            let mut r = [0.0; NU];
            if !moving[k] {
                return r;
            }
            let (dw, int_i, int_w) = match reading {
                SpeedReading::IntervalMean if k + 1 < n => {
                    (w[k + 1] - w[k], i[k] * dt, 0.5 * (w[k] + w[k + 1]) * dt)
                }
                SpeedReading::IntervalMean => return r,
                SpeedReading::Instantaneous => (
                    w[k] - w[k - 1],
                    0.5 * (i[k] + i[k - 1]) * dt,
                    0.5 * (w[k] + w[k - 1]) * dt,
                ),
            };
            r[K] = -int_i;
            r[J] = dw;
            r[F] = int_w;
            r[TST] = int_w.signum() * dt;
            r
        })
        .collect();
    filter.apply(&mut e);
    filter.apply(&mut m);
    SegmentRows {
        xe: e.iter().map(|r| std::array::from_fn(|c| r[c])).collect(),
        ye: e.iter().map(|r| r[NU]).collect(),
        xm: m,
    }
}

/// Which mechanical rows of `seg` to use: the speed readings around the
/// interval all clear of zero by `threshold` and of one sign.
pub fn moving(w: &[f64], threshold: f64, reading: SpeedReading) -> Vec<bool> {
    let n = w.len();
    (0..n)
        .map(|k| {
            if k == 0 {
                return false;
            }
            let hi = match reading {
                SpeedReading::IntervalMean => (k + 1).min(n - 1),
                SpeedReading::Instantaneous => k,
            };
            let s = w[k].signum();
            (k - 1..=hi).all(|m| w[m].abs() > threshold && w[m].signum() == s)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::dc::identify::recorded::recorded;
    use crate::model::{DcParams, DcState};

    #[test]
    fn exact_data_satisfies_the_filtered_rows() {
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let dt = 5e-4;
        let x0 = DcState {
            current: 0.1,
            speed: 40.0,
            angle: 0.0,
        };
        let (seg, w_mean) = recorded(&p, dt, x0, 2000, |k| 100.0 + 80.0 * ((k / 150) % 2) as f64);
        let theta = [p.la, p.ra, p.k, p.j, p.f, p.tst];
        let filter = LowPass::new(50.0, dt);
        let mov = moving(&w_mean, 1.0, SpeedReading::IntervalMean);
        let r = rows(
            &seg,
            &seg.current,
            &w_mean,
            &mov,
            SpeedReading::IntervalMean,
            &filter,
        );
        let dot = |x: &[f64; NU]| x.iter().zip(theta).map(|(a, b)| a * b).sum::<f64>();
        let scale_e = r.ye.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst_e =
            r.xe.iter()
                .zip(&r.ye)
                .map(|(x, y)| (dot(x) - y).abs())
                .fold(0.0, f64::max);
        // Only the trapezoid on the current is approximate.
        assert!(worst_e < 1e-3 * scale_e, "{worst_e} vs {scale_e}");
        let scale_m = r.xm.iter().map(|x| (x[K] * p.k).abs()).fold(0.0, f64::max);
        let worst_m = r.xm.iter().map(|x| dot(x).abs()).fold(0.0, f64::max);
        assert!(worst_m < 2e-3 * scale_m, "{worst_m} vs {scale_m}");
    }
}
