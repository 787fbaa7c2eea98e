//! Gaps in a DC record's time: a data logger that drops samples (a USB
//! DAQ that stalled, a buffer that overflowed) leaves a segment whose
//! samples are not evenly spaced. Every DC model is simulated one sample
//! interval at a time, so across a gap it would take tens of milliseconds
//! of the motor's response for one interval: the fit then bends its
//! parameters to the jump. A segment is cut at each gap instead, and each
//! part is fitted from its own first sample, as a segment that does not
//! continue the one before it is.

use super::split::split_at;
use crate::record::Record;

/// A time step longer than this many times the segment's median step is a
/// gap (a logger's jitter stays well under it).
pub const GAP_STEPS: f64 = 2.5;

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
