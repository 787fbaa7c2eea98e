//! A long record's diagnosis reads windows of it: its time and memory are
//! bounded whatever the record's length.
//!
//! The diagnosis fits every candidate on every sample, and refits them on
//! every fold, so its cost grows with the samples (a little faster: the
//! fits need more evaluations on longer records, BENCHMARKS.md). A step
//! record the bench made is already thinned to the transients and the
//! settled tails (`record::thinning`), but a record read from a file, or
//! one that never holds a level (a PRBS, a closed loop running for
//! minutes), is not: a two-minute 2 kHz PRBS took 43 s and 271 MB.
//!
//! Where a record holds more than [`MAX_SAMPLES`], each segment keeps a
//! share of its samples in proportion to its length, as windows of at most
//! [`WINDOW`] samples spread evenly over it: the first at its start (a
//! step and its transient), the last at its end (where it settled). Each
//! window is a segment of its own that starts from its first readings, as
//! a segment after a gap in time does; the diagnosis estimates the
//! winding's heating over what lies between (see `prepare_runs`). The
//! report says how much was read, and where.

use crate::record::{DcSegment, Record};

/// Most samples the diagnosis reads (32.8 s at 2 kHz; the embedded
/// default's record four times over has 60 402).
pub const MAX_SAMPLES: usize = 65_536;

/// Most samples of one window (4.1 s at 2 kHz: many electrical and
/// mechanical time constants of a motor a bench commissions).
pub const WINDOW: usize = 8192;

/// Fewest samples of a window: a segment cut into windows shorter than
/// this takes fewer of them, and one of up to this many is read whole.
const MIN_WINDOW: usize = 1024;

/// The windows of `record` the diagnosis reads, with a note saying so;
/// `None` where it holds at most [`MAX_SAMPLES`].
pub fn windowed(record: &Record) -> Option<Record> {
    let total: usize = record.segments.iter().map(|s| s.time.len()).sum();
    if total <= MAX_SAMPLES {
        return None;
    }
    // A segment of up to a window's least is read whole; the rest share
    // what is left of the budget in proportion to their length.
    let short: usize = record
        .segments
        .iter()
        .map(|s| s.time.len())
        .filter(|&n| n <= MIN_WINDOW)
        .sum();
    let long = total - short;
    let budget = MAX_SAMPLES.saturating_sub(short);
    let mut segments = Vec::new();
    let mut cut = Vec::new();
    for seg in &record.segments {
        let n = seg.time.len();
        // Its share, rounded down: the whole stays within the budget.
        let keep = if n <= MIN_WINDOW {
            n
        } else {
            n * budget / long
        };
        let ranges = spread(n, keep);
        if ranges.len() == 1 && ranges[0] == (0..n) {
            segments.push(DcSegment {
                index: segments.len() as u32,
                ..seg.clone()
            });
            continue;
        }
        cut.push(format!(
            "segment {} ({}): {} window(s) of {} samples of {n}",
            seg.index,
            seg.label,
            ranges.len(),
            ranges[0].len()
        ));
        for (w, r) in ranges.iter().enumerate() {
            let at = |k: usize| seg.time[k];
            segments.push(DcSegment {
                index: segments.len() as u32,
                kind: seg.kind,
                label: format!(
                    "{} [window {} of {}, {:.3}–{:.3} s]",
                    seg.label,
                    w + 1,
                    ranges.len(),
                    at(r.start),
                    at(r.end - 1)
                ),
                time: seg.time[r.clone()].to_vec(),
                voltage: seg.voltage[r.clone()].to_vec(),
                current: seg.current[r.clone()].to_vec(),
                speed: seg.speed[r.clone()].to_vec(),
            });
        }
    }
    let read: usize = segments.iter().map(|s| s.time.len()).sum();
    let mut out = Record {
        segments,
        ..record.clone()
    };
    out.notes.push(format!(
        "the record holds {total} samples, more than the diagnosis reads ({MAX_SAMPLES}): it \
         read {read}, in windows spread over the long segments, each window a segment of its own \
         (numbered anew in time order) that starts from its first readings; {}. \
         `identify` reads every sample",
        cut.join("; ")
    ));
    Some(out)
}

/// Ranges of `0..n` holding `keep` samples in all: the whole where
/// `keep ≥ n`, else windows of at most [`WINDOW`] (at least
/// [`MIN_WINDOW`], or `keep` where that is less) spread evenly, the first
/// at the start and the last at the end.
fn spread(n: usize, keep: usize) -> Vec<std::ops::Range<usize>> {
    if keep >= n {
        return std::iter::once(0..n).collect();
    }
    let count = keep.div_ceil(WINDOW).min(keep / MIN_WINDOW).max(1);
    let len = keep / count;
    if count == 1 {
        return std::iter::once(0..len).collect();
    }
    (0..count)
        .map(|w| {
            let start = w * (n - len) / (count - 1);
            start..start + len
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::SegmentKind;

    fn segment(index: u32, n: usize) -> DcSegment {
        let t0 = index as f64 * 1000.0;
        DcSegment {
            index,
            kind: Some(SegmentKind::DcStep),
            label: format!("s{index}"),
            time: (0..n).map(|k| t0 + k as f64 * 5e-4).collect(),
            voltage: vec![1.0; n],
            current: (0..n).map(|k| k as f64).collect(),
            speed: vec![2.0; n],
        }
    }

    #[test]
    fn a_record_within_the_bound_is_read_whole() {
        let r = Record {
            segments: vec![segment(0, 40_000), segment(1, MAX_SAMPLES - 40_000)],
            ..Default::default()
        };
        assert_eq!(windowed(&r), None);
    }

    #[test]
    fn a_long_record_is_read_in_windows_spread_over_it() {
        let r = Record {
            segments: vec![
                segment(0, 3000),
                segment(1, 600_000),
                segment(2, 500),
                segment(3, 60_000),
            ],
            ..Default::default()
        };
        let w = windowed(&r).expect("windows");
        let read: usize = w.segments.iter().map(|s| s.time.len()).sum();
        assert!(read <= MAX_SAMPLES, "{read}");
        assert!(read > MAX_SAMPLES - 3 * WINDOW, "{read}");
        // Numbered anew in time order, every window a run of the original
        // samples (the current is the sample's index in its segment).
        for (n, s) in w.segments.iter().enumerate() {
            assert_eq!(s.index, n as u32);
            assert!(s.time.len() <= WINDOW, "{}", s.time.len());
            assert!(s.current.windows(2).all(|c| c[1] == c[0] + 1.0));
            assert!(s.time.windows(2).all(|t| t[1] > t[0]));
        }
        assert!(w.segments.windows(2).all(|p| p[1].time[0] > p[0].time[0]));
        // The long segment: its first window at its start, its last at its
        // end, the rest between; the short one kept a share from its start.
        let long: Vec<&DcSegment> = w
            .segments
            .iter()
            .filter(|s| s.label.starts_with("s1 "))
            .collect();
        assert!(long.len() >= 5, "{}", long.len());
        assert_eq!(long[0].current[0], 0.0);
        assert_eq!(*long.last().unwrap().current.last().unwrap(), 599_999.0);
        assert!(w.segments[0].label.starts_with("s0 [window 1 of 1, 0.000–"));
        // A short segment is read whole.
        let whole = w.segments.iter().find(|s| s.label == "s2").unwrap();
        assert_eq!(whole.time, r.segments[2].time);
        assert!(w.notes[0].contains("segment 1 (s1)"), "{}", w.notes[0]);
    }
}
