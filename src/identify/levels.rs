//! Settled levels: the steady state at the end of each step segment.

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
    let t_end = seg.time[n - 1];
    let by_count = n - (n / 4).max(MIN_TAIL);
    let by_time = seg.time.partition_point(|&t| t < t_end - 1.0);
    let start = by_count.max(by_time).min(n - MIN_TAIL);
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
    let half_agree = |x: &[f64]| {
        let (a, b) = x.split_at(x.len() / 2);
        let (ma, mb) = (mean(a), mean(b));
        let m = mean(x);
        let var = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64;
        let stderr = (var * (1.0 / a.len() as f64 + 1.0 / b.len() as f64)).sqrt();
        (ma - mb).abs() <= 0.01 * m.abs() + 4.0 * stderr
    };
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
        settled: half_agree(v) && half_agree(i) && half_agree(w),
    })
}

/// Recognise a coast-down in a segment not marked as one (the contract
/// allows a `dc_step` CSV to hold one): mean armature current magnitude
/// under 5 % of its peak (or 1 mA) while the speed decays to under half
/// its initial value, and the armature voltage holds no level: it follows
/// the falling back-EMF (at the end under half its median over the first
/// quarter) or stays near zero. A step down of a fast motor also has a
/// falling speed and a mean current far below its transient peak, but its
/// voltage holds the new level.
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
    early.sort_by(f64::total_cmp);
    let early = early[early.len() / 2];
    let end = seg.voltage[n - MIN_TAIL..].iter().sum::<f64>().abs() / MIN_TAIL as f64;
    let largest = seg.voltage.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let holds_no_level = end < 0.5 * early || early <= 0.05 * largest;
    mean_abs <= (0.05 * peak).max(1e-3)
        && head.abs() > 0.0
        && tail.abs() < 0.5 * head.abs()
        && holds_no_level
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
    }
}
