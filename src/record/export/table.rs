//! A record's samples as one wide table: a row per sampled instant and
//! segment, a column per recorded channel, what `export` writes to
//! Parquet.
//!
//! - Columns: `time_s` (s since the start of the test, as identification
//!   and the CSV export count it), `segment` (the segment the row belongs
//!   to, none outside every segment), then one column per `/sensor/` and
//!   `/command/` channel in the record's order, named after its quantity
//!   (`armature_current`); a command is `<quantity>_command`.
//! - A cell is empty where its channel has no reading at that instant (a
//!   command is written when it changes; a channel may start later).
//! - Segments follow the reader's rule ([`super::super::RecordBuilder`]): a
//!   segment holds the instants in `start..=end` of its markers, to the
//!   end of the record when it has no end. An instant on the boundary of
//!   two segments is in both, so it has a row in each: filtering the
//!   table on one segment gives exactly the instants identification sees
//!   in it.

use std::collections::BTreeMap;

use crate::record::schema::COMMAND_PREFIX;
use crate::record::{ChannelSpec, Entry, SegmentPhase};

/// Appended to a command channel's quantity to name its column.
pub const COMMAND_SUFFIX: &str = "_command";

/// One channel's column.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelColumn {
    /// Column name: the quantity, `<quantity>_command` for a command.
    pub name: String,
    /// The channel's topic.
    pub topic: String,
    /// SI unit.
    pub unit: String,
    /// One cell per row; `None` where the channel has no reading.
    pub cells: Vec<Option<f64>>,
}

/// The table. Every column has [`SampleTable::rows`] cells.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SampleTable {
    /// Time of each row, ns since the start of the test.
    pub t_ns: Vec<u64>,
    /// Segment of each row.
    pub segment: Vec<Option<u32>>,
    /// The channels' columns.
    pub channels: Vec<ChannelColumn>,
}

impl SampleTable {
    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.t_ns.len()
    }

    /// The table of `entries` recorded on `channels`.
    pub fn build(channels: &[ChannelSpec], entries: &[Entry]) -> SampleTable {
        // One row per instant first: readings of one instant may come in
        // several entries (an event between them).
        let mut instants: Vec<u64> = Vec::new();
        let mut cells: Vec<Vec<Option<f64>>> = vec![Vec::new(); channels.len()];
        for e in entries {
            let Entry::Samples { t_ns, values } = e else {
                continue;
            };
            if instants.last() != Some(t_ns) {
                instants.push(*t_ns);
                for c in &mut cells {
                    c.push(None);
                }
            }
            for &(index, value) in values {
                if let Some(column) = cells.get_mut(index) {
                    if value.is_finite() {
                        *column.last_mut().expect("a row was pushed") = Some(value);
                    }
                }
            }
        }
        let spans = spans(entries);
        let mut table = SampleTable {
            channels: channels
                .iter()
                .map(|c| ChannelColumn {
                    name: column_name(c),
                    topic: c.topic.clone(),
                    unit: c.unit.clone(),
                    cells: Vec::with_capacity(instants.len()),
                })
                .collect(),
            ..SampleTable::default()
        };
        for (row, &t) in instants.iter().enumerate() {
            let mut inside = spans
                .iter()
                .filter(|(_, &(start, end))| start <= t && t <= end)
                .map(|(&index, _)| Some(index))
                .peekable();
            let none = [None];
            let segments: Vec<Option<u32>> = if inside.peek().is_some() {
                inside.collect()
            } else {
                none.to_vec()
            };
            for segment in segments {
                table.t_ns.push(t);
                table.segment.push(segment);
                for (column, values) in table.channels.iter_mut().zip(&cells) {
                    column.cells.push(values[row]);
                }
            }
        }
        table
    }
}

/// The column name of channel `c`.
pub fn column_name(c: &ChannelSpec) -> String {
    if c.topic.starts_with(COMMAND_PREFIX) {
        format!("{}{COMMAND_SUFFIX}", c.quantity)
    } else {
        c.quantity.clone()
    }
}

/// Each segment's `start..=end` in ns, by index: the first start, the last
/// end, open to the end of the record without one (the reader's rule).
fn spans(entries: &[Entry]) -> BTreeMap<u32, (u64, u64)> {
    let mut spans: BTreeMap<u32, (u64, Option<u64>)> = BTreeMap::new();
    for e in entries {
        let Entry::Segment { t_ns, marker } = e else {
            continue;
        };
        match marker.phase {
            SegmentPhase::Start => {
                spans.entry(marker.index).or_insert((*t_ns, None));
            }
            SegmentPhase::End => {
                if let Some(span) = spans.get_mut(&marker.index) {
                    span.1 = Some(*t_ns);
                }
            }
        }
    }
    spans
        .into_iter()
        .map(|(i, (start, end))| (i, (start, end.unwrap_or(u64::MAX))))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples(t_ns: u64, values: &[(usize, f64)]) -> Entry {
        Entry::Samples {
            t_ns,
            values: values.to_vec(),
        }
    }

    #[test]
    fn a_row_per_instant_and_segment_a_column_per_channel() {
        let channels = [
            ChannelSpec::sensor("armature_current", "A", "daq"),
            ChannelSpec::command("armature_voltage", "V", "psu"),
        ];
        let entries = vec![
            samples(0, &[(1, 12.0)]),
            Entry::dc_step_marker(10, 0, SegmentPhase::Start, "a"),
            samples(10, &[(0, 1.0)]),
            samples(20, &[(0, 2.0)]),
            Entry::dc_step_marker(20, 0, SegmentPhase::End, "a"),
            Entry::dc_step_marker(20, 1, SegmentPhase::Start, "b"),
            samples(20, &[(1, 6.0)]),
            samples(30, &[(0, f64::NAN)]),
        ];
        let t = SampleTable::build(&channels, &entries);
        assert_eq!(t.t_ns, vec![0, 10, 20, 20, 30]);
        assert_eq!(t.segment, vec![None, Some(0), Some(0), Some(1), Some(1)]);
        assert_eq!(t.channels[0].name, "armature_current");
        assert_eq!(t.channels[1].name, "armature_voltage_command");
        assert_eq!(
            t.channels[0].cells,
            vec![None, Some(1.0), Some(2.0), Some(2.0), None]
        );
        assert_eq!(
            t.channels[1].cells,
            vec![Some(12.0), None, Some(6.0), Some(6.0), None]
        );
    }
}
