//! Short segments that continue one another, joined into one driven
//! segment.
//!
//! The diagnosis holds out blocks of samples within segments and needs
//! segments of at least [`MIN_SAMPLES`] samples; equation error and
//! output error need a segment's first readings to start it from, and
//! the segment before it long enough to give them. A slow logger (100 or
//! 200 Hz) or short holds give a staircase whose steps are each under
//! that, yet the record is one continuous test: each segment starts where
//! the one before it ended (on its last sample, as the bench writes a
//! staircase, or one interval later). Such a run of segments is one
//! driven segment to the model, whose simulation takes any voltage; so
//! they are joined into one, where any of them is too short to take part
//! alone, and the report says which. The level methods (steady state,
//! Pasek, moments, coast-down) keep the segments as they are: they need
//! one level a segment.

use crate::identify::SimulatedSegment;
use crate::machine::dc::identify::is_coastdown;
use crate::record::{DcSegment, Record, SegmentKind};

/// Fewest samples a segment needs to take part alone.
pub const MIN_SAMPLES: usize = 40;

/// A record with its short continuing segments joined, and where each
/// joined segment's samples came from.
#[derive(Debug, Clone)]
pub struct Joined {
    /// The record with the segments joined (numbered anew); its last note
    /// says which were joined, for `reader` (the methods that read it).
    pub record: Record,
    /// Per segment of `record`, its parts: the original segment's index,
    /// how many of its first samples were the part before's last (0 or 1:
    /// one instant written in both), and its sample count.
    parts: Vec<Vec<(u32, usize, usize)>>,
}

impl Joined {
    /// Model responses to the joined segments as responses to the
    /// original segments: each joined response cut at its parts' bounds
    /// (a sample two parts share goes to both). Responses to a segment
    /// that was not joined keep their segment's original index.
    pub fn split_back(&self, joined: Vec<SimulatedSegment>) -> Vec<SimulatedSegment> {
        let mut out = Vec::with_capacity(joined.len());
        for sim in joined {
            let Some(parts) = self.parts.get(sim.index as usize) else {
                continue;
            };
            let mut at = 0usize;
            for &(index, skip, n) in parts {
                let from = at.saturating_sub(skip);
                let to = (from + n).min(sim.current.len());
                if from < to {
                    out.push(SimulatedSegment {
                        index,
                        model: sim.model.clone(),
                        current: sim.current[from..to].to_vec(),
                        speed: sim.speed[from..to].to_vec(),
                    });
                }
                at = from + n;
            }
        }
        out
    }
}

/// The record with each run of segments that continue one another, and
/// of which one is shorter than [`MIN_SAMPLES`], joined into one; `None`
/// where nothing is joined. `reader` names what reads the joined record
/// in its note ("the diagnosis").
pub fn join_short_continuations(record: &Record, reader: &str) -> Option<Joined> {
    let segs = &record.segments;
    if !segs.iter().any(|s| s.time.len() < MIN_SAMPLES) {
        return None;
    }
    let mut out: Vec<DcSegment> = Vec::with_capacity(segs.len());
    // Per joined segment of `out`, the labels of the segments it holds.
    let mut held: Vec<Vec<String>> = Vec::new();
    let mut parts: Vec<Vec<(u32, usize, usize)>> = Vec::new();
    for seg in segs {
        let short = |s: &DcSegment| s.time.len() < MIN_SAMPLES;
        match out.last_mut() {
            Some(last) if (short(last) || short(seg)) && continues(last, seg) => {
                let skip = usize::from(seg.time.first() == last.time.last());
                last.time.extend_from_slice(&seg.time[skip..]);
                last.voltage.extend_from_slice(&seg.voltage[skip..]);
                last.current.extend_from_slice(&seg.current[skip..]);
                last.speed.extend_from_slice(&seg.speed[skip..]);
                held.last_mut()
                    .expect("one per segment")
                    .push(seg.label.clone());
                parts
                    .last_mut()
                    .expect("one per segment")
                    .push((seg.index, skip, seg.time.len()));
            }
            _ => {
                out.push(seg.clone());
                held.push(vec![seg.label.clone()]);
                parts.push(vec![(seg.index, 0, seg.time.len())]);
            }
        }
    }
    let joined: Vec<String> = held
        .iter()
        .zip(&out)
        .filter(|(h, _)| h.len() > 1)
        .map(|(h, s)| {
            format!(
                "{} ({} samples) from {}",
                h[0],
                s.time.len(),
                crate::excerpt::listed(h)
            )
        })
        .collect();
    if joined.is_empty() {
        return None;
    }
    let mut joined_record = record.clone();
    for (k, s) in out.iter_mut().enumerate() {
        s.index = k as u32;
    }
    joined_record.segments = out;
    joined_record.notes.push(format!(
        "segments under {MIN_SAMPLES} samples that continue one another are joined for {reader} \
         (one driven segment to the model): {}",
        joined.join("; ")
    ));
    Some(Joined {
        record: joined_record,
        parts,
    })
}

/// Whether `next` continues `seg` in time: a driven segment each, `next`
/// starting on `seg`'s last sample or within one and a half of its sample
/// intervals after it.
fn continues(seg: &DcSegment, next: &DcSegment) -> bool {
    let driven = |s: &DcSegment| s.kind != Some(SegmentKind::DcCoastdown) && !is_coastdown(s);
    let (Some(&end), Some(&start)) = (seg.time.last(), next.time.first()) else {
        return false;
    };
    let n = seg.time.len();
    let interval = if n > 1 {
        (end - seg.time[0]) / (n - 1) as f64
    } else {
        next.time.get(1).map_or(0.0, |t| t - start)
    };
    driven(seg) && driven(next) && interval > 0.0 && start >= end && start - end <= 1.5 * interval
}

#[cfg(test)]
mod tests {
    use super::*;

    fn staircase(lens: &[usize]) -> Record {
        let mut t0 = 0.0;
        let segments = lens
            .iter()
            .enumerate()
            .map(|(k, &n)| {
                // Each segment starts on the last sample of the one before.
                let time: Vec<f64> = (0..n).map(|j| t0 + j as f64 * 2e-3).collect();
                t0 = *time.last().unwrap();
                DcSegment {
                    index: k as u32,
                    kind: Some(SegmentKind::DcStep),
                    label: format!("s{k}.csv"),
                    voltage: vec![10.0 * (k + 1) as f64; n],
                    current: vec![1.0; n],
                    speed: vec![5.0 * (k + 1) as f64; n],
                    time,
                }
            })
            .collect();
        Record {
            segments,
            ..Record::default()
        }
    }

    #[test]
    fn short_segments_that_continue_one_another_are_joined() {
        let joined = join_short_continuations(&staircase(&[25, 26, 26, 60, 26]), "the diagnosis")
            .unwrap()
            .record;
        let lens: Vec<usize> = joined.segments.iter().map(|s| s.time.len()).collect();
        // 25 + 25 + 25 (the shared first samples once), then 60 alone
        // would do, but the 26 after it is short: joined to it.
        assert_eq!(lens, [75, 85]);
        let first = &joined.segments[0];
        assert!(first.time.windows(2).all(|w| w[1] > w[0]), "time increases");
        assert_eq!(first.voltage[24], 10.0);
        assert_eq!(
            first.voltage[25], 20.0,
            "the next segment's first new sample"
        );
        assert_eq!(joined.segments[1].index, 1);
        let note = joined.notes.last().unwrap();
        assert!(
            note.contains("s0.csv (75 samples) from s0.csv, s1.csv, s2.csv"),
            "{note}"
        );

        // Long enough alone: nothing joined.
        assert!(join_short_continuations(&staircase(&[60, 60]), "x").is_none());
        // Short but not continuing (a second's pause between them): apart.
        let mut apart = staircase(&[25, 25]);
        for t in &mut apart.segments[1].time {
            *t += 1.0;
        }
        assert!(join_short_continuations(&apart, "x").is_none());
    }

    #[test]
    fn responses_to_joined_segments_are_cut_back_at_the_parts() {
        let record = staircase(&[25, 26, 60, 10]);
        let joined = join_short_continuations(&record, "x").unwrap();
        let lens: Vec<usize> = joined
            .record
            .segments
            .iter()
            .map(|s| s.time.len())
            .collect();
        // 25 + 25; 60 + 9 (each later part's first sample is the one before's last).
        assert_eq!(lens, [50, 69]);
        // A response that counts its samples: each original segment gets
        // its own stretch, the shared instant in both.
        let response = |index: u32, n: usize| SimulatedSegment {
            index,
            model: "m".into(),
            current: (0..n).map(|k| k as f64).collect(),
            speed: (0..n).map(|k| -(k as f64)).collect(),
        };
        let back = joined.split_back(vec![response(0, 50), response(1, 69)]);
        let got: Vec<(u32, usize, f64, f64)> = back
            .iter()
            .map(|s| {
                (
                    s.index,
                    s.current.len(),
                    s.current[0],
                    *s.speed.last().unwrap(),
                )
            })
            .collect();
        assert_eq!(
            got,
            [
                (0, 25, 0.0, -24.0),
                (1, 26, 24.0, -49.0),
                (2, 60, 0.0, -59.0),
                (3, 10, 59.0, -68.0),
            ]
        );
        assert!(back.iter().all(|s| s.model == "m"));
    }
}
