//! Measured-against-model plot data for every segment of a record.
//!
//! The steady-state method predicts settled levels, not a response in
//! time: its trace is drawn only over the tail of the segment it averaged
//! (the settled level), not as a jump at the step.

use crate::identify::{Identification, SimulatedSegment};
use crate::record::Record;
use crate::report::{SegmentPlot, Trace};

/// One [`SegmentPlot`] per segment: the measurement first, then every
/// model response identification produced for that segment.
pub fn segment_plots(record: &Record, id: &Identification) -> Vec<SegmentPlot> {
    record
        .segments
        .iter()
        .filter(|s| !s.time.is_empty())
        .map(|seg| {
            let mut current = vec![Trace {
                name: "measured".into(),
                values: seg.current.clone(),
            }];
            let mut speed = vec![Trace {
                name: "measured".into(),
                values: seg.speed.clone(),
            }];
            for sim in id.simulated.iter().filter(|s| s.index == seg.index) {
                let shown = |values: &[f64]| match settled_tail(id, sim, seg.index) {
                    Some(tail) => only_tail(values, tail),
                    None => values.to_vec(),
                };
                current.push(Trace {
                    name: sim.model.clone(),
                    values: shown(&sim.current),
                });
                speed.push(Trace {
                    name: sim.model.clone(),
                    values: shown(&sim.speed),
                });
            }
            SegmentPlot {
                title: format!("segment {}: {}", seg.index, seg.label),
                time: seg.time.clone(),
                current,
                speed,
                cuts: record
                    .cuts
                    .iter()
                    .filter(|c| seg.time.last().is_some_and(|&end| c.at_s <= end))
                    .copied()
                    .collect(),
            }
        })
        .collect()
}

/// The number of samples at the end of segment `index` that the
/// steady-state method averaged, when `sim` is its trace.
fn settled_tail(id: &Identification, sim: &SimulatedSegment, index: u32) -> Option<usize> {
    if sim.model != "steady_state" {
        return None;
    }
    id.levels
        .iter()
        .find(|l| l.segment == index)
        .map(|l| l.samples)
}

/// `values` with all but the last `tail` set to NaN (not drawn).
fn only_tail(values: &[f64], tail: usize) -> Vec<f64> {
    let from = values.len().saturating_sub(tail);
    values
        .iter()
        .enumerate()
        .map(|(k, &v)| if k >= from { v } else { f64::NAN })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_tail_is_kept() {
        let v = only_tail(&[1.0, 2.0, 3.0, 4.0], 2);
        assert!(v[0].is_nan() && v[1].is_nan());
        assert_eq!(v[2..], [3.0, 4.0]);
        assert_eq!(only_tail(&[1.0], 5), vec![1.0]);
    }
}
