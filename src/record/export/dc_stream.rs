//! The DC segments' contract CSV files written as the record is read, so
//! that exporting an hour of 2 kHz samples holds seconds of them, not the
//! hour (a whole-record read at full resolution held about 600 MB).
//!
//! The rows are those of [`super::csv`] on a full-resolution
//! [`crate::record::Record`], to the byte: one per armature-current
//! reading in a segment's `start..=end`, with the voltage and the speed
//! linearly interpolated at its instant from their own readings (the
//! first reading at that instant where there is one, the edge value
//! outside their range; [`crate::record::RecordBuilder`] has the rules).
//! A row waits until both series have a reading at or after its instant;
//! readings no row can need any more are let go.
//!
//! That needs each series' readings in time order, which a recorder
//! writes. A file whose readings of one series go back in time is not
//! streamed: [`DcStream::finish`] says so, and the export reads the
//! record whole instead.

use std::collections::{BTreeMap, VecDeque};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::table::segment_spans;
use super::ExportError;
use crate::record::builder::{dc_slot, interpolate};
use crate::record::csv::{COL_CURRENT, COL_SPEED, COL_TIME, COL_VOLTAGE};
use crate::record::{ChannelSpec, DcSegment, Entry, SegmentKind};

/// The series' slots: voltage, current (the time base), speed.
const VOLTAGE: usize = 0;
const CURRENT: usize = 1;
const SPEED: usize = 2;

/// One segment as its markers describe it.
#[derive(Debug, Clone)]
struct Span {
    start: u64,
    end: u64,
    kind: SegmentKind,
    label: String,
}

/// A current reading waiting for its voltage and speed.
#[derive(Debug, Clone, Copy)]
struct Row {
    t_ns: u64,
    current: f64,
}

/// What a stream ended with.
#[derive(Debug)]
pub(super) enum Streamed {
    /// The files written, by segment index.
    Files(Vec<(u32, PathBuf)>),
    /// A series went back in time: nothing is kept, read the record whole.
    OutOfOrder,
}

/// The files written so far, and where and how to name them.
struct Files<'a> {
    out_dir: &'a Path,
    stem: &'a str,
    source: &'a str,
    open: BTreeMap<u32, (PathBuf, BufWriter<File>)>,
}

/// Writes the DC segments' CSV files of one record from its entries.
pub(super) struct DcStream<'a> {
    files: Files<'a>,
    /// The series each channel feeds (the first channel of a quantity).
    slots: Vec<Option<usize>>,
    spans: BTreeMap<u32, Span>,
    /// Voltage and speed readings a waiting or later row may need.
    series: [VecDeque<(u64, f64)>; 3],
    /// The latest instant read per series.
    latest: [Option<u64>; 3],
    rows: VecDeque<Row>,
    out_of_order: bool,
    failed: Option<ExportError>,
}

impl<'a> DcStream<'a> {
    /// A stream for a record with these channels and (non-sample)
    /// entries, writing `<stem>.segment-<index>.csv` into `out_dir`;
    /// `segments` are the record built from those entries alone (each
    /// segment's kind and label as the reader takes them from its markers).
    pub(super) fn new(
        channels: &[ChannelSpec],
        entries: &[Entry],
        segments: &[DcSegment],
        out_dir: &'a Path,
        stem: &'a str,
        source: &'a str,
    ) -> DcStream<'a> {
        let mut slots: Vec<Option<usize>> = Vec::with_capacity(channels.len());
        for c in channels {
            let slot = dc_slot(c).filter(|s| !slots.contains(&Some(*s)));
            slots.push(slot);
        }
        DcStream {
            files: Files {
                out_dir,
                stem,
                source,
                open: BTreeMap::new(),
            },
            slots,
            spans: spans(entries, segments),
            series: Default::default(),
            latest: [None; 3],
            rows: VecDeque::new(),
            out_of_order: false,
            failed: None,
        }
    }

    /// Takes the next entry of the file.
    pub(super) fn push(&mut self, entry: &Entry) {
        let Entry::Samples { t_ns, values } = entry else {
            return;
        };
        if self.out_of_order || self.failed.is_some() {
            return;
        }
        for &(index, value) in values {
            let Some(Some(slot)) = self.slots.get(index).copied() else {
                continue;
            };
            if !value.is_finite() {
                continue;
            }
            if self.latest[slot].is_some_and(|t| *t_ns < t) {
                self.out_of_order = true;
                return;
            }
            self.latest[slot] = Some(*t_ns);
            if slot == CURRENT {
                self.rows.push_back(Row {
                    t_ns: *t_ns,
                    current: value,
                });
            } else {
                self.series[slot].push_back((*t_ns, value));
            }
        }
        self.write_ready(false);
        self.let_go();
    }

    /// Writes the rows still waiting (at the edge values) and closes the
    /// files.
    pub(super) fn finish(mut self) -> Result<Streamed, ExportError> {
        if !self.out_of_order {
            // A record without one of the three series has no DC rows
            // (identification says which is missing).
            if self.latest.iter().all(Option::is_some) {
                self.write_ready(true);
            }
            if let Some(e) = self.failed.take() {
                return Err(e);
            }
        }
        let mut written = Vec::new();
        for (index, (path, mut file)) in std::mem::take(&mut self.files.open) {
            if self.out_of_order {
                drop(file);
                let _ = std::fs::remove_file(&path);
                continue;
            }
            file.flush().map_err(|source| ExportError::Io {
                path: path.clone(),
                source,
            })?;
            written.push((index, path));
        }
        Ok(if self.out_of_order {
            Streamed::OutOfOrder
        } else {
            Streamed::Files(written)
        })
    }

    /// Writes the waiting rows whose voltage and speed are known (all of
    /// them at the end of the file).
    fn write_ready(&mut self, at_end: bool) {
        while let Some(&row) = self.rows.front() {
            let [voltage, _, speed] = &mut self.series;
            let (Some(v), Some(w)) = (
                value_at(voltage, row.t_ns, at_end),
                value_at(speed, row.t_ns, at_end),
            ) else {
                return;
            };
            self.rows.pop_front();
            for (&index, span) in &self.spans {
                if !(span.start <= row.t_ns && row.t_ns <= span.end) {
                    continue;
                }
                if let Err(e) = self.files.write_row(index, span, row, v, w) {
                    self.failed = Some(e);
                    return;
                }
            }
        }
    }

    /// Lets go of the voltage and speed readings no row can need: all but
    /// the last one before the next row's instant (rows come in time
    /// order, so no later row is earlier).
    fn let_go(&mut self) {
        let Some(next) = self.rows.front().map(|r| r.t_ns).or(self.latest[CURRENT]) else {
            return;
        };
        for s in [VOLTAGE, SPEED] {
            let series = &mut self.series[s];
            while series.len() >= 2 && series[1].0 < next {
                series.pop_front();
            }
        }
    }
}

impl Files<'_> {
    /// Appends `row` to segment `index`'s file, opened with its header
    /// by the first row.
    fn write_row(
        &mut self,
        index: u32,
        span: &Span,
        row: Row,
        v: f64,
        w: f64,
    ) -> Result<(), ExportError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| ExportError::Io { path, source }
        };
        if !self.open.contains_key(&index) {
            let path = self
                .out_dir
                .join(format!("{}.segment-{index}.csv", self.stem));
            let mut file = BufWriter::new(File::create(&path).map_err(io(&path))?);
            let head = super::csv::preamble(index, span.kind, &span.label, self.source);
            writeln!(
                file,
                "{head}{COL_TIME},{COL_VOLTAGE},{COL_CURRENT},{COL_SPEED}"
            )
            .map_err(io(&path))?;
            self.open.insert(index, (path, file));
        }
        let (path, file) = self.open.get_mut(&index).expect("opened above");
        let t = row.t_ns as f64 * 1e-9;
        writeln!(file, "{t:?},{v:?},{:?},{w:?}", row.current).map_err(io(path))
    }
}

/// The value of the readings `s` (in time order) at `t`, as
/// [`crate::record::RecordBuilder`] interpolates it; `None` while no
/// reading at or after `t` has come (unless `at_end`: then the last
/// reading's value).
fn value_at(s: &mut VecDeque<(u64, f64)>, t: u64, at_end: bool) -> Option<f64> {
    let s = s.make_contiguous();
    let last = s.last()?.0;
    (at_end || t <= last).then(|| interpolate(s, t))
}

/// Each segment's span by the reader's rule ([`segment_spans`]), with
/// its kind and label from `segments`.
fn spans(entries: &[Entry], segments: &[DcSegment]) -> BTreeMap<u32, Span> {
    segment_spans(entries)
        .into_iter()
        .filter_map(|(index, (start, end))| {
            let segment = segments.iter().find(|s| s.index == index)?;
            let span = Span {
                start,
                end,
                kind: segment.kind.unwrap_or(SegmentKind::DcStep),
                label: segment.label.clone(),
            };
            Some((index, span))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{RecordBuilder, Resolution, SegmentPhase};

    /// The builder tests' channels and a second current channel (the
    /// first one counts).
    fn channels() -> Vec<ChannelSpec> {
        let mut channels = crate::record::builder::tests::channels();
        channels.push(ChannelSpec::sensor("armature_current", "A", "aux"));
        channels
    }

    /// Current every 100 ns from 0 to 6 µs; voltage at every third of its
    /// instants, twice at 3 µs; speed every 700 ns from 1 µs (so
    /// the first rows take its edge value) to 4 µs (so the last ones do
    /// too); a NaN and the command channel beside; segment 0 from 1 µs to
    /// 3 µs, segment 1 from 3 µs (the boundary reading is in both) with no
    /// end, segment 2 with an end and no start (ignored).
    fn entries() -> Vec<Entry> {
        let mut e = vec![
            Entry::dc_step_marker(1_000, 0, SegmentPhase::Start, "first"),
            Entry::dc_step_marker(2_500, 2, SegmentPhase::End, "stray"),
        ];
        for k in 0..=60u64 {
            let t = 100 * k;
            let mut values = vec![(0, 999.0), (2, (k as f64).sin()), (4, -1.0)];
            if k == 7 {
                values.push((2, f64::NAN));
            }
            e.push(Entry::Samples { t_ns: t, values });
            if k % 3 == 0 {
                let v = 10.0 * (k as f64 * 0.37).cos();
                e.push(Entry::Samples {
                    t_ns: t,
                    values: vec![(1, v)],
                });
                if k == 30 {
                    e.push(Entry::Samples {
                        t_ns: t,
                        values: vec![(1, v + 7.0)],
                    });
                }
            }
            if k % 7 == 3 && (10..=40).contains(&k) {
                e.push(Entry::Samples {
                    t_ns: t,
                    values: vec![(3, 100.0 + k as f64)],
                });
            }
            if k == 30 {
                e.push(Entry::dc_step_marker(t, 0, SegmentPhase::End, "first"));
                e.push(Entry::dc_step_marker(t, 1, SegmentPhase::Start, "second"));
            }
        }
        e
    }

    /// The segments of the record of `markers` alone, as the export
    /// builds them.
    fn marker_segments(markers: &[Entry]) -> Vec<DcSegment> {
        let mut b = RecordBuilder::new(None, channels());
        for e in markers {
            b.push(e);
        }
        b.finish().segments
    }

    /// The files of the whole-record export, by name.
    fn whole(entries: &[Entry], source: &str) -> Vec<(String, String)> {
        let mut b = RecordBuilder::new(None, channels()).resolution(Resolution::Full);
        for e in entries {
            b.push(e);
        }
        let record = b.finish();
        super::super::csv::segment_files(&record, source)
            .filter(|f| !f.text.is_empty())
            .map(|f| (format!("rec.segment-{}.csv", f.segment), f.text))
            .collect()
    }

    fn streamed(entries: &[Entry], dir: &Path, source: &str) -> Streamed {
        let markers: Vec<Entry> = entries
            .iter()
            .filter(|e| !matches!(e, Entry::Samples { .. }))
            .cloned()
            .collect();
        let segments = marker_segments(&markers);
        let mut stream = DcStream::new(&channels(), &markers, &segments, dir, "rec", source);
        for e in entries {
            stream.push(e);
        }
        stream.finish().unwrap()
    }

    #[test]
    fn the_stream_writes_the_whole_records_files_to_the_byte() {
        let dir = tempfile::tempdir().unwrap();
        let entries = entries();
        let Streamed::Files(files) = streamed(&entries, dir.path(), "rec.mcap") else {
            panic!("in order");
        };
        let got: Vec<(String, String)> = files
            .iter()
            .map(|(_, p)| {
                let name = p.file_name().unwrap().to_string_lossy().into_owned();
                (name, std::fs::read_to_string(p).unwrap())
            })
            .collect();
        let want = whole(&entries, "rec.mcap");
        assert_eq!(got.len(), 2, "segments 0 and 1");
        assert_eq!(got, want);
        assert!(want[1].1.contains("second (incomplete)"), "{}", want[1].1);
    }

    #[test]
    fn readings_that_go_back_in_time_are_not_streamed() {
        let dir = tempfile::tempdir().unwrap();
        let mut entries = entries();
        // A speed reading far behind the others, after them in the file.
        entries.push(Entry::Samples {
            t_ns: 1_200,
            values: vec![(3, 5.0)],
        });
        assert!(matches!(
            streamed(&entries, dir.path(), "rec.mcap"),
            Streamed::OutOfOrder
        ));
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            0,
            "what was written is removed"
        );
    }

    #[test]
    fn a_record_without_speed_has_no_dc_files() {
        let dir = tempfile::tempdir().unwrap();
        let entries: Vec<Entry> = entries()
            .into_iter()
            .map(|e| match e {
                Entry::Samples { t_ns, values } => Entry::Samples {
                    t_ns,
                    values: values.into_iter().filter(|v| v.0 != 3).collect(),
                },
                e => e,
            })
            .collect();
        let Streamed::Files(files) = streamed(&entries, dir.path(), "rec.mcap") else {
            panic!("in order");
        };
        assert!(files.is_empty() && whole(&entries, "rec.mcap").is_empty());
    }

    #[test]
    fn readings_no_row_needs_are_let_go() {
        // A long record holds a few readings at any time.
        let dir = tempfile::tempdir().unwrap();
        let markers = vec![Entry::dc_step_marker(0, 0, SegmentPhase::Start, "long")];
        let segments = marker_segments(&markers);
        let mut stream = DcStream::new(
            &channels(),
            &markers,
            &segments,
            dir.path(),
            "rec",
            "rec.mcap",
        );
        let mut most = 0;
        for k in 0..100_000u64 {
            stream.push(&Entry::Samples {
                t_ns: 500 * k,
                values: vec![(1, 1.0), (2, 2.0), (3, 3.0)],
            });
            most = most
                .max(stream.rows.len() + stream.series.iter().map(VecDeque::len).sum::<usize>());
        }
        assert!(most <= 4, "{most} readings held");
        let Streamed::Files(files) = stream.finish().unwrap() else {
            panic!("in order");
        };
        let text = std::fs::read_to_string(&files[0].1).unwrap();
        assert_eq!(
            text.lines().filter(|l| !l.starts_with('#')).count(),
            100_001
        );
    }
}
