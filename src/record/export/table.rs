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
//!
//! [`TableRows`] builds the table as the entries come, so the export
//! writes a long record in row groups without holding it whole.

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
        let mut rows = TableRows::new(channels, segment_spans(entries));
        for e in entries {
            rows.push(e);
        }
        rows.finish()
    }

    /// An empty table with the columns of `channels`.
    pub fn empty(channels: &[ChannelSpec]) -> SampleTable {
        SampleTable {
            channels: channels
                .iter()
                .map(|c| ChannelColumn {
                    name: column_name(c),
                    topic: c.topic.clone(),
                    unit: c.unit.clone(),
                    cells: Vec::new(),
                })
                .collect(),
            ..SampleTable::default()
        }
    }
}

/// Builds a [`SampleTable`] from entries as they come, a row per instant
/// and segment, so that a long record's table can be written in pieces
/// ([`TableRows::take`]) rather than held whole.
#[derive(Debug, Clone)]
pub struct TableRows {
    /// The columns' channels.
    channels: Vec<ChannelSpec>,
    /// Each segment's `start..=end`, ns (see [`segment_spans`]).
    spans: BTreeMap<u32, (u64, u64)>,
    /// The instant being read and its cells, one per channel.
    open: Option<(u64, Vec<Option<f64>>)>,
    /// The rows of the instants read before it.
    table: SampleTable,
}

impl TableRows {
    /// Rows of `channels` in the segments of `spans`
    /// ([`segment_spans`] of the record's markers).
    pub fn new(channels: &[ChannelSpec], spans: BTreeMap<u32, (u64, u64)>) -> TableRows {
        TableRows {
            channels: channels.to_vec(),
            spans,
            open: None,
            table: SampleTable::empty(channels),
        }
    }

    /// Takes one entry (only samples make rows). Readings of one instant
    /// may come in several entries (an event between them): they make one
    /// row.
    pub fn push(&mut self, entry: &Entry) {
        let Entry::Samples { t_ns, values } = entry else {
            return;
        };
        if self.open.as_ref().is_none_or(|(t, _)| t != t_ns) {
            self.close();
            self.open = Some((*t_ns, vec![None; self.table.channels.len()]));
        }
        let (_, cells) = self.open.as_mut().expect("an instant is open");
        for &(index, value) in values {
            if let Some(cell) = cells.get_mut(index) {
                if value.is_finite() {
                    *cell = Some(value);
                }
            }
        }
    }

    /// The rows of the instants read before the one being read.
    pub fn rows(&self) -> usize {
        self.table.rows()
    }

    /// Hands over the rows so far (the instant being read stays).
    pub fn take(&mut self) -> SampleTable {
        std::mem::replace(&mut self.table, SampleTable::empty(&self.channels))
    }

    /// The rows not taken yet, the last instant's included.
    pub fn finish(mut self) -> SampleTable {
        self.close();
        self.table
    }

    /// Makes the open instant its rows: one per segment it lies in, one
    /// with no segment when it lies in none.
    fn close(&mut self) {
        let Some((t, cells)) = self.open.take() else {
            return;
        };
        let mut inside = self
            .spans
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
            self.table.t_ns.push(t);
            self.table.segment.push(segment);
            for (column, &cell) in self.table.channels.iter_mut().zip(&cells) {
                column.cells.push(cell);
            }
        }
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
pub fn segment_spans(entries: &[Entry]) -> BTreeMap<u32, (u64, u64)> {
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

        // Taken in pieces as the entries come, the rows are the same: an
        // instant read across a take stays one row.
        for cut in 0..entries.len() {
            let mut rows = TableRows::new(&channels, segment_spans(&entries));
            for e in &entries[..cut] {
                rows.push(e);
            }
            let mut first = rows.take();
            for e in &entries[cut..] {
                rows.push(e);
            }
            let rest = rows.finish();
            first.t_ns.extend(rest.t_ns);
            first.segment.extend(rest.segment);
            for (a, b) in first.channels.iter_mut().zip(rest.channels) {
                a.cells.extend(b.cells);
            }
            assert_eq!(first, t, "taken after {cut} entries");
        }
    }
}
