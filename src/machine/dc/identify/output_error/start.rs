//! Start values for the output-error fit when no other method offers
//! them: K, Ra, f, Tst from the steady-state fit, La and J from the
//! integrated model equations over each step's transient.
//!
//! Integrated from the segment start (a settled state) the model's
//! equations are exact, whatever the time constants:
//!
//! ```text
//! La·(i(t) − i(0)) = ∫ (U − Ra·i − K·ω) dt     up to the current peak
//! J·(ω(t) − ω(0))  = ∫ (K·i − f·ω − Tst) dt    up to 90 % of the speed change
//! ```
//!
//! With K, Ra, f and Tst known, each step gives La and J as a ratio; the
//! steps are combined by least squares. Stopping the integrals early keeps
//! the static error of K, Ra, f, Tst from accumulating over the settled
//! tail. The results are starts, not estimates: the fit refines them.

use super::simulation::{SegmentInput, SegmentStart, SpeedReading};
use crate::model::DcParams;

/// Fallback electrical time constant, in sample intervals.
const FALLBACK_TAU_E_SAMPLES: f64 = 10.0;

/// Fallback mechanical time constant, s.
const FALLBACK_TAU_M: f64 = 0.1;

/// La and J estimated from `segments` given K, Ra, f, Tst in `statics`
/// (whose La and J are ignored); fallbacks where a step gives nothing
/// usable (a change smaller than `min_change` noise levels). Returns the
/// parameters and whether each of La, J came from the data.
pub fn crude_start(
    statics: &DcParams,
    segments: &[SegmentInput],
    sigma: [f64; 2],
    reading: SpeedReading,
) -> (DcParams, [bool; 2]) {
    let p = statics;
    let (mut la_num, mut la_den, mut j_num, mut j_den) = (0.0, 0.0, 0.0, 0.0);
    for input in segments {
        if !matches!(input.start, SegmentStart::Settled(_)) {
            continue;
        }
        let s = input.seg;
        let n = s.time.len();
        let dt = input.dt;
        // Speed over (t[k−1], t[k]]: the reading itself when it is the
        // interval mean, else the trapezoid.
        let w_interval = |k: usize| match reading {
            SpeedReading::IntervalMean => s.speed[k],
            SpeedReading::Instantaneous => 0.5 * (s.speed[k] + s.speed[k - 1]),
        };
        let i_interval = |k: usize| 0.5 * (s.current[k] + s.current[k - 1]);

        // Electrical: up to the largest current excursion in the first half.
        let peak = (1..n / 2).max_by(|&a, &b| {
            (s.current[a] - s.current[0])
                .abs()
                .total_cmp(&(s.current[b] - s.current[0]).abs())
        });
        if let Some(kp) = peak {
            let di = s.current[kp] - s.current[0];
            if di.abs() > 10.0 * sigma[0] {
                let integral: f64 = (1..=kp)
                    .map(|k| (s.voltage[k] - p.ra * i_interval(k) - p.k * w_interval(k)) * dt)
                    .sum();
                la_num += integral * di;
                la_den += di * di;
            }
        }

        // Mechanical: up to 90 % of the speed change to the segment's end.
        let tail = (n / 10).max(1);
        let w_end = s.speed[n - tail..].iter().sum::<f64>() / tail as f64;
        let change = w_end - s.speed[0];
        if change.abs() > 10.0 * sigma[1] {
            if let Some(k90) = (1..n).find(|&k| (s.speed[k] - s.speed[0]) / change >= 0.9) {
                let dw = s.speed[k90] - s.speed[0];
                let integral: f64 = (1..=k90)
                    .map(|k| {
                        let w = w_interval(k);
                        (p.k * i_interval(k) - p.f * w - p.tst * w.signum()) * dt
                    })
                    .sum();
                j_num += integral * dw;
                j_den += dw * dw;
            }
        }
    }
    let dt = segments.first().map_or(1e-3, |s| s.dt);
    let la = (la_den > 0.0)
        .then(|| la_num / la_den)
        .filter(|v| v.is_finite() && *v > 0.0);
    let j = (j_den > 0.0)
        .then(|| j_num / j_den)
        .filter(|v| v.is_finite() && *v > 0.0);
    let start = DcParams {
        la: la.unwrap_or(p.ra * FALLBACK_TAU_E_SAMPLES * dt),
        j: j.unwrap_or(FALLBACK_TAU_M * p.k * p.k / p.ra),
        ..*p
    };
    (start, [la.is_some(), j.is_some()])
}

#[cfg(test)]
mod tests {
    use super::super::simulation::simulate_series;
    use super::*;
    use crate::record::DcSegment;

    #[test]
    fn recovers_la_and_j_from_exact_steps() {
        let truth = DcParams::SEED_TABLE4_MOMENTS;
        let dt = 5e-4;
        let mut segs = Vec::new();
        for (from, to) in [(60.0, 248.0), (248.0, 107.0), (107.0, 201.0)] {
            let mut seg = DcSegment {
                time: (0..3000).map(|k| k as f64 * dt).collect(),
                voltage: (0..3000).map(|k| if k == 0 { from } else { to }).collect(),
                ..Default::default()
            };
            let input = SegmentInput::new(&seg, SegmentStart::Settled(from));
            (seg.current, seg.speed) =
                simulate_series(&truth, &input, SpeedReading::IntervalMean).unwrap();
            segs.push(seg);
        }
        let inputs: Vec<SegmentInput> = segs
            .iter()
            .map(|s| SegmentInput::new(s, SegmentStart::Settled(s.voltage[0])))
            .collect();
        let statics = DcParams {
            la: 1.0,
            j: 1.0,
            ..truth
        };
        let (start, from_data) =
            crude_start(&statics, &inputs, [0.002, 0.5], SpeedReading::IntervalMean);
        assert_eq!(from_data, [true, true]);
        // Exact data: only the trapezoid on the current limits the result.
        assert!(
            ((start.la - truth.la) / truth.la).abs() < 0.02,
            "La {}",
            start.la
        );
        assert!(
            ((start.j - truth.j) / truth.j).abs() < 0.02,
            "J {}",
            start.j
        );
    }

    #[test]
    fn flat_data_falls_back() {
        let seg = DcSegment::held(100, 1e-3, 10.0, 0.1, 7.0);
        let inputs = [SegmentInput::new(&seg, SegmentStart::Settled(10.0))];
        let p = DcParams::SEED_TABLE4_MOMENTS;
        let (start, from_data) = crude_start(&p, &inputs, [0.002, 0.5], SpeedReading::IntervalMean);
        assert_eq!(from_data, [false, false]);
        assert!((start.la - p.ra * 10.0 * 1e-3).abs() < 1e-12);
        assert!((start.j - 0.1 * p.k * p.k / p.ra).abs() < 1e-12);
    }
}
