//! Settled levels: the steady state at the end of each step segment.

use crate::identify::stats::median;
use crate::record::DcSegment;

/// Mean voltage, current and speed over the settled tail of a segment.
#[derive(Debug, Clone, PartialEq)]
pub struct SettledLevel {
    /// Segment index.
    pub segment: u32,
    /// Segment label.
    pub label: String,
    /// Mean armature voltage, V.
    pub voltage: f64,
    /// Mean armature current, A.
    pub current: f64,
    /// Mean speed, rad/s.
    pub speed: f64,
    /// Samples averaged.
    pub samples: usize,
    /// Whether the two halves of the tail agree (the signals had stopped
    /// moving beyond their noise).
    pub settled: bool,
}

/// Exact levels, for tests.
#[cfg(test)]
impl SettledLevel {
    /// The settled level of segment `segment`, unlabelled, at `voltage`:
    /// the steady state of `p` there, as if averaged over `samples`.
    pub(crate) fn exact(
        p: &crate::model::DcParams,
        voltage: f64,
        segment: u32,
        samples: usize,
    ) -> SettledLevel {
        let s = p.steady_state(voltage);
        SettledLevel {
            segment,
            label: String::new(),
            voltage,
            current: s.current,
            speed: s.speed,
            samples,
            settled: true,
        }
    }
}

/// Fewest samples a tail may have.
const MIN_TAIL: usize = 20;

/// The level at the end of `seg`: the mean over its last quarter (at
/// least 20 samples, at most one second). `None` for a segment shorter
/// than 40 samples.
pub fn settled_level(seg: &DcSegment) -> Option<SettledLevel> {
    let n = seg.time.len();
    if n < 2 * MIN_TAIL || seg.voltage.len() != n || seg.current.len() != n || seg.speed.len() != n
    {
        return None;
    }
    let start = tail_start(seg);
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
    let (v, i, w) = (
        &seg.voltage[start..],
        &seg.current[start..],
        &seg.speed[start..],
    );
    Some(SettledLevel {
        segment: seg.index,
        label: seg.label.clone(),
        voltage: mean(v),
        current: mean(i),
        // The slope of the angle over the tail, not the mean of the speed
        // samples: for an encoder-derived speed the mean is the count change
        // between the tail's two end readings only, so the timestamp jitter
        // of a polled bus (a few ms) and the quantisation at those two
        // instants would set its error; the slope averages every reading.
        speed: super::step::counter_speed(&seg.time[start..], w),
        samples: n - start,
        settled: unsettled_channel(seg).is_none(),
    })
}

/// The tail's first index (see [`settled_level`]).
fn tail_start(seg: &DcSegment) -> usize {
    let n = seg.time.len();
    let t_end = seg.time[n - 1];
    let by_count = n - (n / 4).max(MIN_TAIL);
    let by_time = seg.time.partition_point(|&t| t < t_end - 1.0);
    by_count.max(by_time).min(n - MIN_TAIL)
}

/// Why the level at the end of `seg` cannot stand for its steady state
/// (the channel and how far it still moves), `None` when it can.
///
/// Judged from each signal's own fit over the tail, not by comparing its
/// halves: a straight line through the tail gives the drift between the
/// tail's mean and its end. A decaying ringing about the level leaves the
/// line flat, so the mean is the level; an exponential approach still
/// under way tilts it. The level stands when the drift is within 1 % of
/// the level, plus three standard errors of the drift (from batch means
/// of the residual, which stay right for ringing and correlated noise),
/// plus half the reading's resolution (a quantised reading flips between
/// two codes).
pub fn unsettled_channel(seg: &DcSegment) -> Option<String> {
    let n = seg.time.len();
    let start = tail_start(seg);
    let t = &seg.time[start..];
    for (name, y) in [
        ("voltage", &seg.voltage),
        ("current", &seg.current),
        ("speed", &seg.speed),
    ] {
        let y = &y[start..n];
        let m = t.len() as f64;
        let tm = t.iter().sum::<f64>() / m;
        let ym = y.iter().sum::<f64>() / m;
        let sxx: f64 = t.iter().map(|ti| (ti - tm).powi(2)).sum();
        if sxx.is_nan() || sxx <= 0.0 {
            continue;
        }
        let slope = t
            .iter()
            .zip(y)
            .map(|(ti, yi)| (ti - tm) * (yi - ym))
            .sum::<f64>()
            / sxx;
        let half_span = t[t.len() - 1] - tm;
        let drift = slope * half_span;
        // Batch means of the residual about the line: the drift's standard
        // error for correlated residuals (ringing, filtered noise).
        let batches = 10usize.min(y.len() / 2).max(2);
        let size = y.len() / batches;
        let means: Vec<f64> = (0..batches)
            .map(|b| {
                let r = b * size..(b + 1) * size;
                r.clone()
                    .map(|k| y[k] - ym - slope * (t[k] - tm))
                    .sum::<f64>()
                    / size as f64
            })
            .collect();
        let var_b = means.iter().map(|v| v * v).sum::<f64>() / (batches - 1) as f64;
        let bt: Vec<f64> = (0..batches)
            .map(|b| t[b * size..(b + 1) * size].iter().sum::<f64>() / size as f64 - tm)
            .collect();
        let sbt: f64 = bt.iter().map(|v| v * v).sum();
        let se_drift = if sbt > 0.0 {
            (var_b / sbt).sqrt() * half_span
        } else {
            0.0
        };
        let step = super::level_error::resolution(y);
        if name == "voltage" {
            let rms = (y
                .iter()
                .zip(t)
                .map(|(yi, ti)| (yi - ym - slope * (ti - tm)).powi(2))
                .sum::<f64>()
                / m)
                .sqrt();
            if rms > 0.02 * ym.abs() && rms > 4.0 * white_noise(y) && rms > step {
                return Some(format!(
                    "its voltage does not hold a level (scatter {rms:.3e} V about {ym:.3} V)"
                ));
            }
        }
        let tolerance = 0.01 * ym.abs() + 3.0 * se_drift + 0.5 * step;
        if drift.abs() > tolerance {
            return Some(format!(
                "its {name} still moves by {:.3e} over the last half of its tail ({:.2} % of its level; \
                 tolerance {:.3e})",
                drift,
                100.0 * drift.abs() / ym.abs().max(f64::MIN_POSITIVE),
                tolerance
            ));
        }
    }
    None
}

/// Robust white-noise level of a reading: the median absolute second
/// difference, `σ·√6·0.6745` for white noise, blind to slow signals and to
/// rare jumps.
pub(crate) fn white_noise(y: &[f64]) -> f64 {
    let mut d: Vec<f64> = y
        .windows(3)
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
        .collect();
    median(&mut d).map_or(0.0, |m| m / (0.6745 * 6f64.sqrt()))
}

/// Recognise a coast-down in a segment not marked as one (the contract
/// allows a `dc_step` CSV to hold one): mean armature current magnitude
/// under 5 % of its peak (or 1 mA) while the speed decays to under half
/// its initial value, and the armature voltage holds no level: it follows
/// the falling back-EMF (at the end under half its median over the first
/// quarter) or stays near zero. A step down of a fast motor also has a
/// falling speed and a mean current far below its transient peak, but its
/// voltage holds the new level. A 0 V short has no voltage either, and
/// when it brakes the rotor within a few milliseconds its mean current is
/// small too; but an open armature carries no current while the rotor
/// still turns, and a short carries the braking current `−K·ω/Ra` then:
/// over the readings after the first two (the boundary sample and the
/// current sensor's response to the opening) at which the speed is still
/// at least half its first reading, the mean current must be as small.
///
/// And with nothing driving it the rotor never speeds up: a driven
/// segment of a lightly loaded motor (a no-load current a few percent of
/// its step transients' peaks, the voltage near the back-EMF) passes every
/// test above when its last level is its lowest, but its speed rises at
/// every step up ([`speed_rises`]).
pub fn is_coastdown(seg: &DcSegment) -> bool {
    let n = seg.time.len();
    if n < 2 * MIN_TAIL {
        return false;
    }
    let peak = seg.current.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mean_abs = seg.current.iter().map(|v| v.abs()).sum::<f64>() / n as f64;
    let head = seg.speed[..MIN_TAIL].iter().sum::<f64>() / MIN_TAIL as f64;
    let tail = seg.speed[n - MIN_TAIL..].iter().sum::<f64>() / MIN_TAIL as f64;
    let mut early: Vec<f64> = seg.voltage[..n / 4].iter().map(|v| v.abs()).collect();
    let early = median(&mut early).unwrap_or(f64::NAN);
    let end = seg.voltage[n - MIN_TAIL..].iter().sum::<f64>().abs() / MIN_TAIL as f64;
    let largest = seg.voltage.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let holds_no_level = end < 0.5 * early || early <= 0.05 * largest;
    let small = (0.05 * peak).max(1e-3);
    let turning: Vec<f64> = (2..n)
        .filter(|&k| seg.speed[k].abs() >= 0.5 * seg.speed[0].abs())
        .map(|k| seg.current[k].abs())
        .collect();
    let open_while_turning =
        turning.is_empty() || turning.iter().sum::<f64>() / turning.len() as f64 <= small;
    mean_abs <= small
        && open_while_turning
        && head.abs() > 0.0
        && tail.abs() < 0.5 * head.abs()
        && holds_no_level
        && !speed_rises(&seg.speed, head)
}

/// Blocks the speed is averaged over for [`speed_rises`].
const RISE_BLOCKS: usize = 50;

/// Whether `speed` (starting near `head`) rises anywhere by more than
/// noise: the mean of some block of samples above the lowest mean of the
/// blocks before it by more than six standard errors of a block mean and
/// 5 % of `head`.
fn speed_rises(speed: &[f64], head: f64) -> bool {
    let m = (speed.len() / RISE_BLOCKS).max(1);
    let tolerance = (6.0 * white_noise(speed) / (m as f64).sqrt()).max(0.05 * head.abs());
    let mut lowest = f64::INFINITY;
    for block in speed.chunks(m) {
        let mean = block.iter().sum::<f64>() / block.len() as f64;
        if (mean.abs() - lowest) > tolerance {
            return true;
        }
        lowest = lowest.min(mean.abs());
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn segment(f: impl Fn(f64) -> (f64, f64, f64), n: usize) -> DcSegment {
        let time: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let (mut voltage, mut current, mut speed) = (vec![], vec![], vec![]);
        for &t in &time {
            let (v, i, w) = f(t);
            voltage.push(v);
            current.push(i);
            speed.push(w);
        }
        DcSegment {
            index: 3,
            label: "x".into(),
            time,
            voltage,
            current,
            speed,
            ..Default::default()
        }
    }

    #[test]
    fn level_is_the_mean_of_the_settled_tail() {
        let s = segment(
            |t| {
                (
                    60.0,
                    0.113 + 0.1 * (-t / 0.02).exp(),
                    42.0 * (1.0 - (-t / 0.05).exp()),
                )
            },
            2000,
        );
        let l = settled_level(&s).unwrap();
        assert!(l.settled);
        assert_eq!(l.samples, 500, "the last quarter");
        let long = segment(|_| (60.0, 0.113, 42.0), 8000);
        let tail = settled_level(&long).unwrap().samples;
        assert!(
            (1000..=1001).contains(&tail),
            "one second at 1 kHz, ends included: {tail}"
        );
        assert!((l.current - 0.113).abs() < 1e-9 && (l.speed - 42.0).abs() < 1e-9);
    }

    #[test]
    fn a_ramp_is_not_settled() {
        let s = segment(|t| (60.0, 0.1, 10.0 * t), 400);
        assert!(!settled_level(&s).unwrap().settled);
        assert!(settled_level(&segment(|_| (1.0, 1.0, 1.0), 30)).is_none());
    }

    #[test]
    fn coastdown_is_recognised_from_the_data() {
        let coast = segment(
            |t| (1.3 * 100.0 * (-t).exp(), 0.0, 100.0 * (-t).exp()),
            2000,
        );
        assert!(is_coastdown(&coast));
        let step = segment(|t| (60.0, 0.113 + 0.1 * (-t / 0.02).exp(), 42.0), 2000);
        assert!(!is_coastdown(&step));
        // A fast motor stepped down from 69 V to 17 V: a short braking
        // current peak (its mean is under 5 % of it) and a falling speed,
        // but the voltage holds the new level.
        let down = segment(
            |t| {
                let u = if t == 0.0 { 69.0 } else { 17.0 };
                (
                    u,
                    0.3 - 42.0 * (-t / 0.003).exp(),
                    44.0 + 136.0 * (-t / 0.013).exp(),
                )
            },
            1300,
        );
        let peak = down.current.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mean_abs = down.current.iter().map(|v| v.abs()).sum::<f64>() / 1300.0;
        assert!(mean_abs < 0.05 * peak, "the current test alone is fooled");
        assert!(!is_coastdown(&down));
        // A 0 V short that brakes the rotor in 5 ms: no voltage, a mean
        // current under 5 % of the braking peak, a falling speed, but the
        // current flows while the rotor turns.
        let short = segment(
            |t| {
                let w = 160.0 * (-t / 0.005).exp();
                (0.0, if t == 0.0 { 3.0 } else { -1.1 * w }, w)
            },
            1000,
        );
        let peak = short.current.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mean_abs = short.current.iter().map(|v| v.abs()).sum::<f64>() / 1000.0;
        assert!(mean_abs < 0.05 * peak, "the current test alone is fooled");
        assert!(!is_coastdown(&short));
        // A block of a long staircase on a lightly loaded motor, from its
        // highest level to its lowest: a no-load current far under the
        // steps' transient peaks, the voltage near the back-EMF and under
        // half its early median at the end, the speed at the end under
        // half the first; but the speed rises at every step up.
        let levels = [140.0, 90.0, 40.0, 80.0, 120.0, 60.0, 100.0, 20.0];
        let stairs = segment(
            |t| {
                let k = ((t / 0.25) as usize).min(levels.len() - 1);
                let since = t - k as f64 * 0.25;
                let (u, before) = (levels[k], if k == 0 { 140.0 } else { levels[k - 1] });
                let w = (u + (before - u) * (-since / 0.05).exp()) / 0.9;
                let i = 0.1 + 0.002 * u + (u - before) / 1.2 * (-since / 0.003).exp();
                (u, i, w)
            },
            2000,
        );
        let peak = stairs.current.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mean_abs = stairs.current.iter().map(|v| v.abs()).sum::<f64>() / 2000.0;
        assert!(mean_abs < 0.05 * peak, "the current test alone is fooled");
        assert!(!is_coastdown(&stairs));
    }
}
