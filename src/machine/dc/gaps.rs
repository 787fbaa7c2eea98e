//! Gaps in a DC record's time: a data logger that drops samples (a USB
//! DAQ that stalled, a buffer that overflowed) leaves a segment whose
//! samples are not evenly spaced. Every DC model is simulated one sample
//! interval at a time, so across a gap it would take tens of milliseconds
//! of the motor's response for one interval: the fit then bends its
//! parameters to the jump. A segment is cut at each gap instead, and each
//! part is fitted from its own first sample, as a segment that does not
//! continue the one before it is.
//!
//! A sample or two missing (a step of two or three intervals, the
//! commonest drop of a streaming logger) is no reason to cut: a record
//! that drops one sample in fifty would fall into parts too short to
//! fit, and each part would start from a noisy reading of its state (a
//! coarse encoder's speed is wrong by a count for a mechanical time
//! constant). Left as it is, though, the model would take the longer step
//! for one interval, and every later sample of the segment would stand an
//! interval or two early against it. So such samples are put back
//! ([`fill_missing_samples`]): their voltage is the next reading's (the
//! reading at `t[k]` is the voltage applied over the interval that ends
//! there, so the next reading was applied over the missing intervals
//! too), their current and speed on the straight line between their
//! neighbours; the report says how many in which segment.

use super::split::split_at;
use crate::record::{DcSegment, Record};

/// A time step longer than this many times the segment's median step is a
/// gap (a logger's jitter stays well under it).
pub const GAP_STEPS: f64 = 2.5;

/// Most samples missing in a row that are put back; a longer drop is a
/// gap, cut.
const MOST_FILLED: usize = 2;

/// A step, in sample intervals, is taken for `m` missing samples when it
/// rounds to `m + 1` from the half-way point between one interval and
/// two: a logger's jitter of less than a quarter of an interval either
/// way is never a missing sample.
const ONE_MISSING_FROM: f64 = 1.5;

/// The record with each run of up to [`MOST_FILLED`] missing samples put
/// back (a step of about two or three intervals), and a note for the
/// report's warnings on each segment that had one.
pub fn fill_missing_samples(mut record: Record) -> Record {
    for seg in &mut record.segments {
        let Some(interval) = nominal_step(&seg.time) else {
            continue;
        };
        // (index of the sample after the drop, samples missing before it)
        let drops: Vec<(usize, usize)> = (1..seg.time.len())
            .filter_map(|k| {
                let step = (seg.time[k] - seg.time[k - 1]) / interval;
                (step > ONE_MISSING_FROM && step < MOST_FILLED as f64 + 1.5)
                    .then(|| (k, (step.round() as usize).clamp(2, MOST_FILLED + 1) - 1))
            })
            .collect();
        if drops.is_empty() {
            continue;
        }
        let at: Vec<String> = drops
            .iter()
            .take(3)
            .map(|&(k, _)| format!("{:.4} s", seg.time[k - 1]))
            .collect();
        let missing: usize = drops.iter().map(|d| d.1).sum();
        let n = seg.time.len() + missing;
        let mut filled = DcSegment {
            time: Vec::with_capacity(n),
            voltage: Vec::with_capacity(n),
            current: Vec::with_capacity(n),
            speed: Vec::with_capacity(n),
            index: seg.index,
            kind: seg.kind,
            label: std::mem::take(&mut seg.label),
        };
        let mut next = drops.iter().peekable();
        for k in 0..seg.time.len() {
            if let Some(&(_, m)) = next.next_if(|d| d.0 == k) {
                for j in 1..=m {
                    let a = j as f64 / (m + 1) as f64;
                    let line = |v: &[f64]| v[k - 1] + a * (v[k] - v[k - 1]);
                    filled.time.push(line(&seg.time));
                    filled.current.push(line(&seg.current));
                    filled.speed.push(line(&seg.speed));
                    filled.voltage.push(seg.voltage[k]);
                }
            }
            filled.time.push(seg.time[k]);
            filled.current.push(seg.current[k]);
            filled.speed.push(seg.speed[k]);
            filled.voltage.push(seg.voltage[k]);
        }
        *seg = filled;
        record.notes.push(format!(
            "{} misses {missing} sample(s) in {} drop(s) of one or two (a step of two or three \
             sample intervals, after {}{}): each put back, its voltage the next reading's, its \
             current and speed on the line between their neighbours, so that the model's time \
             stays the record's",
            seg.label,
            drops.len(),
            at.join(", "),
            if drops.len() > 3 { ", …" } else { "" }
        ));
    }
    record
}

/// The record with every segment cut at its gaps (segments renumbered in
/// order when one is cut), and a note for the report's warnings on each.
pub fn cut_at_time_gaps(mut record: Record) -> Record {
    let mut out = Vec::with_capacity(record.segments.len());
    let mut notes = Vec::new();
    for seg in std::mem::take(&mut record.segments) {
        let cuts = gaps(&seg.time);
        if cuts.is_empty() {
            out.push(seg);
            continue;
        }
        let median = median_step(&seg.time);
        let described: Vec<String> = cuts
            .iter()
            .map(|&k| {
                let jump = seg.time[k] - seg.time[k - 1];
                format!(
                    "{:.1} ms at {:.3} s ({:.0} sample periods)",
                    jump * 1e3,
                    seg.time[k - 1],
                    jump / median
                )
            })
            .collect();
        notes.push(format!(
            "{} has {} gap(s) in its time: {}; cut there into {} parts, each fitted from its own \
             first sample (a model is not simulated across missing samples)",
            seg.label,
            cuts.len(),
            crate::excerpt::listed(&described),
            cuts.len() + 1
        ));
        out.extend(split_at(&seg, &cuts));
    }
    if !notes.is_empty() {
        for (k, s) in out.iter_mut().enumerate() {
            s.index = k as u32;
        }
        record.notes.extend(notes);
    }
    record.segments = out;
    record
}

/// The median of the time steps of `time` (0 with fewer than 2 samples).
fn median_step(time: &[f64]) -> f64 {
    let mut steps: Vec<f64> = time.windows(2).map(|w| w[1] - w[0]).collect();
    crate::identify::stats::median(&mut steps).unwrap_or(0.0)
}

/// The sample interval of `time`: the mean of its steps under 1.75 times
/// their median (a logger whose stamps alternate early and late has a
/// median step shorter or longer than its interval; the mean of the
/// steps that are no drop is the interval). `None` without two samples
/// evenly ordered in time.
fn nominal_step(time: &[f64]) -> Option<f64> {
    let median = median_step(time);
    if median.is_nan() || median <= 0.0 {
        return None;
    }
    let (sum, n) = time
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|&d| d > 0.0 && d < 1.75 * median)
        .fold((0.0, 0usize), |(s, n), d| (s + d, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// Indices `k` where the step `time[k] − time[k−1]` is a gap.
fn gaps(time: &[f64]) -> Vec<usize> {
    let median = median_step(time);
    if median.is_nan() || median <= 0.0 {
        return Vec::new();
    }
    (1..time.len())
        .filter(|&k| time[k] - time[k - 1] > GAP_STEPS * median)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{DcSegment, SegmentKind};

    fn record(time: Vec<f64>) -> Record {
        let n = time.len();
        Record {
            segments: vec![DcSegment {
                index: 0,
                kind: Some(SegmentKind::DcStep),
                label: "lab.csv".into(),
                // The sample's number at 2 kHz, to tell which samples a part holds.
                voltage: time.iter().map(|t| (t / 5e-4).round()).collect(),
                current: vec![1.0; n],
                speed: vec![2.0; n],
                time,
            }],
            ..Record::default()
        }
    }

    #[test]
    fn one_or_two_missing_samples_are_put_back_and_a_longer_drop_is_not() {
        // 2 kHz with jitter of a tenth of a period; sample 51 missing
        // alone, 200 and 201 together, 300..303 together.
        let time: Vec<f64> = (0..400)
            .filter(|k| ![51, 200, 201, 300, 301, 302].contains(k))
            .map(|k| k as f64 * 5e-4 + if k % 2 == 0 { 5e-5 } else { -5e-5 })
            .collect();
        let filled = fill_missing_samples(record(time));
        let seg = &filled.segments[0];
        assert_eq!(
            seg.time.len(),
            397,
            "three samples put back, three left out"
        );
        // Each sample put back: where it was missing, its time and current
        // on the line between its neighbours', its voltage the next
        // reading's.
        let k = seg
            .voltage
            .iter()
            .position(|&v| v == 52.0)
            .expect("sample 52");
        assert_eq!(k, 51, "put back where it was missing");
        assert_eq!(seg.voltage[k + 1], 52.0, "its voltage the next reading's");
        assert_eq!(seg.voltage[k - 1], 50.0);
        assert!((seg.time[k] - 0.5 * (seg.time[k - 1] + seg.time[k + 1])).abs() < 1e-12);
        assert!((seg.time[k] - 51.0 * 5e-4).abs() < 1e-4);
        assert_eq!(seg.current[k], 1.0);
        let k = seg
            .voltage
            .iter()
            .position(|&v| v == 202.0)
            .expect("sample 202");
        assert_eq!(k, 200, "two put back where they were missing");
        assert_eq!(&seg.voltage[199..203], [199.0, 202.0, 202.0, 202.0]);
        let third = (seg.time[202] - seg.time[199]) / 3.0;
        assert!((seg.time[200] - seg.time[199] - third).abs() < 1e-12);
        assert!((seg.time[201] - seg.time[199] - 2.0 * third).abs() < 1e-12);
        // Three missing together stay a gap, which the cut then finds.
        assert!(!seg.voltage.contains(&301.0) && seg.voltage.contains(&303.0));
        assert!(
            filled.notes.len() == 1 && filled.notes[0].contains("misses 3 sample(s) in 2 drop(s)"),
            "{:?}",
            filled.notes
        );
        assert_eq!(cut_at_time_gaps(filled).segments.len(), 2);

        // Jitter alone: nothing put back.
        let jittered: Vec<f64> = (0..100)
            .map(|k| k as f64 * 5e-4 + if k % 2 == 0 { 5e-5 } else { -5e-5 })
            .collect();
        let kept = fill_missing_samples(record(jittered.clone()));
        assert_eq!(kept.segments[0].time, jittered);
        assert!(kept.notes.is_empty());
    }

    #[test]
    fn a_segment_is_cut_at_each_gap_and_jitter_is_left_alone() {
        // 2 kHz, with samples 100..140 and 300..310 missing.
        let time: Vec<f64> = (0..500)
            .filter(|k| !(100..140).contains(k) && !(300..310).contains(k))
            .map(|k| k as f64 * 5e-4)
            .collect();
        let cut = cut_at_time_gaps(record(time));
        assert_eq!(cut.segments.len(), 3);
        let lens: Vec<usize> = cut.segments.iter().map(|s| s.time.len()).collect();
        assert_eq!(lens, [100, 160, 190]);
        assert_eq!(cut.segments[1].voltage[0], 140.0, "the part after the gap");
        assert_eq!(
            cut.segments.iter().map(|s| s.index).collect::<Vec<_>>(),
            [0, 1, 2]
        );
        assert!(
            cut.notes[0].contains("2 gap(s)") && cut.notes[0].contains("20.5 ms at 0.050 s (41"),
            "{}",
            cut.notes[0]
        );

        // Jitter of a tenth of a period everywhere: no gap.
        let jittered: Vec<f64> = (0..500)
            .map(|k| k as f64 * 5e-4 + if k % 2 == 0 { 5e-5 } else { -5e-5 })
            .collect();
        let kept = cut_at_time_gaps(record(jittered.clone()));
        assert_eq!(kept.segments.len(), 1);
        assert_eq!(kept.segments[0].time, jittered);
        assert!(kept.notes.is_empty());
    }
}
