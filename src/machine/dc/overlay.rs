//! Measured-against-model plot data for every segment of a record.

use crate::identify::Identification;
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
                current.push(Trace {
                    name: sim.model.clone(),
                    values: sim.current.clone(),
                });
                speed.push(Trace {
                    name: sim.model.clone(),
                    values: sim.speed.clone(),
                });
            }
            SegmentPlot {
                title: format!("segment {}: {}", seg.index, seg.label),
                time: seg.time.clone(),
                current,
                speed,
            }
        })
        .collect()
}
