//! Turns a stream of [`Entry`] into a [`Record`].
//!
//! The bench feeds it live (in memory) and the MCAP reader feeds it from a
//! file; both go through the same code, so a replay yields bit-identical
//! data.
//!
//! Rules:
//!
//! - A segment's samples are those whose `t_ns` lies in its
//!   `start..=end` markers. A segment with a start but no end (an aborted
//!   test, a truncated file) takes every sample after its start, and its
//!   label gets [`INCOMPLETE_SUFFIX`]. An end marker without a start is
//!   ignored; repeated markers keep the first start and the last end.
//! - The DC series come from `/sensor/` channels only (`/command/` channels
//!   are not measurements): quantity `armature_voltage` → voltage,
//!   `armature_current` → current, `speed` → speed. Where several sensor
//!   channels carry one quantity, the first in the channel list is used.
//! - The time base is the armature-current instants; voltage and speed are
//!   linearly interpolated onto them from all their samples (inside or
//!   outside the segment): an exact copy where timestamps coincide, the
//!   edge value outside their range.
//! - If one of the three quantities has no samples at all, every segment
//!   keeps empty series; identification reports it.
//! - Non-finite values (NaN, ±infinity) are skipped: JSON cannot carry
//!   them, so the recorder writes a `/bench/event` warning instead, and the
//!   live record must match the replayed one.
//! - Time in seconds is `t_ns as f64 * 1e-9`.
//! - Events go to [`Record::events`] in time order; the last result
//!   becomes [`Record::recorded_result`]. Segments are sorted by index.
//! - At [`Resolution::Analysis`] (the default) a long step segment keeps
//!   its first and last samples of each series, and a note says what was
//!   left out: [`super::thinning`] has the rule.
//!   [`Resolution::Full`] keeps every sample.

use std::collections::BTreeMap;

use super::schema::SENSOR_PREFIX;
use super::thinning::{splices, Head, Resolution, SpanSeries, PENDING};
use super::types::{
    ChannelSpec, ClockCut, DcSegment, Entry, Event, ImStandardTests, OperatingPoint, Record,
    SegmentKind, SegmentPhase, SupplyLimit, TestMeta,
};

/// Appended to the label of a segment that has no end marker.
pub const INCOMPLETE_SUFFIX: &str = " (incomplete)";

/// The current's slot: the time base, and the series whose head and
/// tail decide a segment's cut.
const CURRENT: usize = 1;

/// Which DC series a channel feeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Series {
    Voltage,
    Current,
    Speed,
}

/// A segment as its markers describe it.
#[derive(Debug, Clone)]
struct SegmentSpan {
    kind: SegmentKind,
    label: String,
    start: u64,
    end: Option<u64>,
}

/// Collects entries and builds a [`Record`] from them.
#[derive(Debug, Clone)]
pub struct RecordBuilder {
    meta: Option<TestMeta>,
    /// For each channel index, the series it feeds (if any).
    roles: Vec<Option<Series>>,
    /// `(t_ns, value)` per series (voltage, current, speed) not yet
    /// assigned to a segment.
    pending: [Vec<(u64, f64)>; 3],
    /// Per series, the samples assigned and kept: a segment's head, and
    /// whatever lies outside every segment.
    kept: [Vec<(u64, f64)>; 3],
    /// Per segment index and series, its samples counted and its tail.
    spans_series: BTreeMap<u32, [SpanSeries; 3]>,
    /// Per segment index, where its head ends.
    heads: BTreeMap<u32, Head>,
    /// What the record keeps of its samples.
    resolution: Resolution,
    spans: BTreeMap<u32, SegmentSpan>,
    events: Vec<(u64, Event)>,
    result: Option<serde_json::Value>,
    points: Vec<OperatingPoint>,
    standard_tests: ImStandardTests,
    supply_limits: Vec<SupplyLimit>,
}

impl Series {
    fn slot(self) -> usize {
        match self {
            Series::Voltage => 0,
            Series::Current => CURRENT,
            Series::Speed => 2,
        }
    }

    fn of(spec: &ChannelSpec) -> Option<Series> {
        if !spec.topic.starts_with(SENSOR_PREFIX) {
            return None;
        }
        match spec.quantity.as_str() {
            "armature_voltage" => Some(Series::Voltage),
            "armature_current" => Some(Series::Current),
            "speed" => Some(Series::Speed),
            _ => None,
        }
    }
}

/// The DC series slot a channel feeds, if any (0 voltage, 1 current, 2
/// speed): a `/sensor/` channel of armature voltage, armature current or
/// speed. Where several channels carry one quantity, the first is used.
pub(crate) fn dc_slot(spec: &ChannelSpec) -> Option<usize> {
    Series::of(spec).map(Series::slot)
}

impl RecordBuilder {
    /// A builder for a record with this metadata and channel list (the
    /// list whose indices [`Entry::Samples`] refers to).
    pub fn new(meta: Option<TestMeta>, channels: Vec<ChannelSpec>) -> Self {
        let mut builder = RecordBuilder {
            meta,
            roles: Vec::with_capacity(channels.len()),
            pending: Default::default(),
            kept: Default::default(),
            spans_series: BTreeMap::new(),
            heads: BTreeMap::new(),
            resolution: Resolution::Analysis,
            spans: BTreeMap::new(),
            events: Vec::new(),
            result: None,
            points: Vec::new(),
            standard_tests: ImStandardTests::default(),
            supply_limits: Vec::new(),
        };
        for c in &channels {
            builder.add_channel(c);
        }
        builder
    }

    /// Appends a channel to the list [`Entry::Samples`] indexes into (a
    /// file declares its channels as it goes).
    pub fn add_channel(&mut self, spec: &ChannelSpec) {
        let role = Series::of(spec).filter(|s| !self.roles.contains(&Some(*s)));
        self.roles.push(role);
    }

    /// Sets the record's metadata (a file may carry it anywhere).
    pub fn set_meta(&mut self, meta: TestMeta) {
        self.meta = Some(meta);
    }

    /// Takes one entry. Samples on channels outside the list given to
    /// [`RecordBuilder::new`] and [`RecordBuilder::add_channel`] are
    /// ignored.
    pub fn push(&mut self, entry: &Entry) {
        match entry {
            Entry::Samples { t_ns, values } => {
                for &(index, value) in values {
                    if !value.is_finite() {
                        continue;
                    }
                    if let Some(Some(series)) = self.roles.get(index) {
                        let slot = series.slot();
                        self.pending[slot].push((*t_ns, value));
                        if self.pending[slot].len() >= 2 * PENDING {
                            self.assign(slot, PENDING);
                        }
                    }
                }
            }
            Entry::Segment { t_ns, marker } => match marker.phase {
                SegmentPhase::Start => {
                    self.spans.entry(marker.index).or_insert(SegmentSpan {
                        kind: marker.kind,
                        label: marker.label.clone(),
                        start: *t_ns,
                        end: None,
                    });
                }
                SegmentPhase::End => {
                    if let Some(span) = self.spans.get_mut(&marker.index) {
                        span.end = Some(*t_ns);
                    }
                }
            },
            Entry::Event { t_ns, event } => self.events.push((*t_ns, event.clone())),
            Entry::Result { report, .. } => self.result = Some(report.clone()),
            Entry::OperatingPoint { point, .. } => self.points.push(*point),
            Entry::SupplyLimit { limit, .. } => self.supply_limits.push(*limit),
            Entry::StandardTest { reading, .. } => self.standard_tests.push(*reading),
        }
    }

    /// What the record keeps of its samples (default
    /// [`Resolution::Analysis`]).
    pub fn resolution(mut self, resolution: Resolution) -> Self {
        self.resolution = resolution;
        self
    }

    /// Assigns the `count` oldest pending samples of series `slot` to the
    /// segments known now: a sample is kept when it lies outside every
    /// segment or in the head of one that contains it (a boundary sample
    /// belongs to both segments), and goes to the tails of the segments
    /// that contain it otherwise.
    fn assign(&mut self, slot: usize, count: usize) {
        let pending = &mut self.pending[slot];
        // Stable: samples at one instant keep their arrival order.
        pending.sort_by_key(|&(t, _)| t);
        let count = count.min(pending.len());
        let whole = self.resolution == Resolution::Full;
        for (t, v) in pending.drain(..count) {
            let contains = |span: &&SegmentSpan| t >= span.start && span.end.is_none_or(|e| t <= e);
            let (mut inside, mut in_head) = (false, false);
            for (index, span) in self.spans.iter().filter(|(_, s)| contains(s)) {
                inside = true;
                let end = self.heads.get(index).and_then(|h| h.end);
                in_head |= whole
                    || span.kind == SegmentKind::DcCoastdown
                    || end.is_none_or(|end| t <= end);
            }
            for (index, span) in self.spans.iter().filter(|(_, s)| contains(s)) {
                let series = &mut self.spans_series.entry(*index).or_default()[slot];
                if !in_head {
                    series.tail(t, v);
                    continue;
                }
                series.head();
                let head = self.heads.entry(*index).or_default();
                if slot == CURRENT
                    && !whole
                    && span.kind != SegmentKind::DcCoastdown
                    && head.end.is_none()
                {
                    head.reading(t, v);
                }
            }
            if in_head || !inside {
                self.kept[slot].push((t, v));
            }
        }
    }

    /// Builds the record.
    pub fn finish(mut self) -> Record {
        for slot in 0..3 {
            let n = self.pending[slot].len();
            self.assign(slot, n);
        }
        let RecordBuilder {
            meta,
            mut kept,
            mut spans_series,
            heads,
            spans,
            mut events,
            result,
            points,
            standard_tests,
            supply_limits,
            ..
        } = self;
        // A segment's tail that follows its head without a cut holds
        // samples as read. A cut segment's current tail is read with its
        // segment below; its voltage and speed are read at its instants
        // with the rest.
        let mut cut_tail = Vec::new();
        for series in spans_series.values_mut() {
            let cut = series[CURRENT].is_cut();
            for (slot, s) in series.iter_mut().enumerate() {
                match (cut, slot == CURRENT) {
                    (true, true) => cut_tail.extend(s.last()),
                    (true, false) => kept[slot].extend(s.last()),
                    (false, _) => kept[slot].extend(s.tail.drain(..)),
                }
            }
        }
        for s in kept.iter_mut() {
            s.sort_by_key(|&(t, _)| t);
        }
        cut_tail.sort_by_key(|&(t, _)| t);
        // A cut segment's head is kept: a series with samples keeps some.
        let complete = kept.iter().all(|s| !s.is_empty());
        let [voltage, current, speed] = &kept;
        let read_at = |seg: &mut DcSegment, at: &mut dyn Iterator<Item = (u64, f64)>| {
            for (t, i) in at {
                seg.time.push(t as f64 * 1e-9);
                seg.current.push(i);
                seg.voltage.push(interpolate(voltage, t));
                seg.speed.push(interpolate(speed, t));
            }
        };
        let mut notes = Vec::new();
        // Each spliced segment's cut, its time still the record's.
        let mut cuts: Vec<ClockCut> = Vec::new();
        let mut segments = Vec::with_capacity(spans.len());
        for (index, span) in spans {
            let mut seg = DcSegment {
                index,
                kind: Some(span.kind),
                label: match span.end {
                    Some(_) => span.label,
                    None => span.label + INCOMPLETE_SUFFIX,
                },
                ..DcSegment::default()
            };
            let end = span.end.unwrap_or(u64::MAX);
            let within = |&(t, _): &(u64, f64)| span.start <= t && t <= end;
            let cut = spans_series
                .get(&index)
                .filter(|s| s[CURRENT].is_cut())
                .map(|s| s[CURRENT].seen);
            if !complete {
                segments.push(seg);
                continue;
            }
            let Some(seen) = cut else {
                read_at(&mut seg, &mut current.iter().copied().filter(within));
                segments.push(seg);
                continue;
            };
            let head_end = heads.get(&index).and_then(|h| h.end).unwrap_or(end);
            read_at(
                &mut seg,
                &mut current
                    .iter()
                    .copied()
                    .filter(|&(t, _)| span.start <= t && t <= head_end),
            );
            let mut tail = DcSegment::default();
            read_at(&mut tail, &mut cut_tail.iter().copied().filter(within));
            let (note, left_out) = splice(&mut seg, tail, seen, span.start, end);
            notes.push(note);
            cuts.extend(left_out.map(|(at_s, left_out_s)| ClockCut {
                segment: index,
                at_s,
                left_out_s,
            }));
            segments.push(seg);
        }
        // The analysis' clock leaves out what a splice left out: a segment
        // that followed a spliced one still follows it.
        let earlier = |cuts: &[ClockCut], t: f64| {
            cuts.iter()
                .filter(|c| c.at_s < t)
                .map(|c| c.left_out_s)
                .sum::<f64>()
        };
        if !cuts.is_empty() {
            for seg in &mut segments {
                for t in &mut seg.time {
                    *t -= earlier(&cuts, *t);
                }
            }
        }
        let cuts = cuts
            .iter()
            .map(|c| ClockCut {
                at_s: c.at_s - earlier(&cuts, c.at_s),
                ..*c
            })
            .collect();
        events.sort_by_key(|&(t, _)| t);
        Record {
            meta,
            segments,
            events,
            operating_points: points,
            standard_tests,
            supply_limits,
            recorded_result: result,
            recovery: None,
            notes,
            cuts,
        }
    }
}

/// Joins `tail` to `seg` (its head) where the head ends on the tail's
/// level ([`splices`]), and returns the note for the report and the cut:
/// the head's last time and the time between it and the tail, less one
/// sample interval, which the analysis' clock leaves out. Otherwise `seg`
/// keeps its head alone. `seg` has `seen` current readings from `start` to
/// `end`, ns.
fn splice(
    seg: &mut DcSegment,
    tail: DcSegment,
    seen: usize,
    start: u64,
    end: u64,
) -> (String, Option<(f64, f64)>) {
    let n = seg.time.len();
    let length = match end {
        u64::MAX => String::new(),
        end => format!(" over {:.1} s", (end - start) as f64 * 1e-9),
    };
    let settled = n >= 2
        && !tail.time.is_empty()
        && [
            (&seg.voltage, &tail.voltage),
            (&seg.current, &tail.current),
            (&seg.speed, &tail.speed),
        ]
        .iter()
        .all(|(h, t)| splices(h, t));
    let head_s = match (seg.time.first(), seg.time.last()) {
        (Some(first), Some(last)) => last - first,
        _ => 0.0,
    };
    let kept =
        "the record file keeps them all (`motorbench export` writes them, and a CSV file is \
                read whole)";
    if !settled {
        let note = format!(
            "{} holds {seen} current readings{length}; its first {n} ({head_s:.2} s) do not end on \
             the level its last {} hold: the analysis reads the first {n} alone; {kept}",
            seg.label,
            tail.time.len(),
        );
        return (note, None);
    }
    let at = seg.time[n - 1];
    let left_out = tail.time[0] - at - head_s / (n - 1) as f64;
    seg.time.extend(tail.time);
    seg.voltage.extend(tail.voltage);
    seg.current.extend(tail.current);
    seg.speed.extend(tail.speed);
    let note = format!(
        "{} holds {seen} current readings{length}: the analysis reads its first {n} ({head_s:.2} s, \
         the step) and its last {} (the settled level), and its clock leaves out the {left_out:.1} \
         s between them (times after {:.3} s read that much earlier); {kept}",
        seg.label,
        seg.time.len() - n,
        at,
    );
    (note, Some((at, left_out)))
}

/// The value of the series `s` (sorted by time, not empty) at `t`: linear
/// between neighbours, exact where a sample lies at `t` (the first such),
/// the edge value outside the series' range.
pub(crate) fn interpolate(s: &[(u64, f64)], t: u64) -> f64 {
    let i = s.partition_point(|&(ts, _)| ts < t);
    if i == s.len() {
        return s[s.len() - 1].1;
    }
    let (t1, v1) = s[i];
    if t1 == t || i == 0 {
        return v1;
    }
    let (t0, v0) = s[i - 1];
    let w = (t - t0) as f64 / (t1 - t0) as f64;
    v0 + (v1 - v0) * w
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::record::thinning::{HEAD_MAX, HEAD_SAMPLES, PAST_HEAD, TAIL_SAMPLES};
    use crate::record::types::{EventLevel, SegmentMarker};
    use crate::record::Record;

    /// A DC record's channels: a voltage command, then the voltage,
    /// current and speed sensors.
    pub(crate) fn channels() -> Vec<ChannelSpec> {
        vec![
            ChannelSpec::command("armature_voltage", "V", "psu"),
            ChannelSpec::sensor("armature_voltage", "V", "daq"),
            ChannelSpec::sensor("armature_current", "A", "daq"),
            ChannelSpec::sensor("speed", "rad/s", "enc"),
        ]
    }

    fn samples(t_ns: u64, values: &[(usize, f64)]) -> Entry {
        Entry::Samples {
            t_ns,
            values: values.to_vec(),
        }
    }

    #[test]
    fn assigns_samples_to_segments_inclusively() {
        let mut b = RecordBuilder::new(None, channels());
        for k in 0..10u64 {
            let t = k * 100;
            b.push(&samples(
                t,
                &[(0, 999.0), (1, k as f64), (2, 10.0 + k as f64), (3, 20.0)],
            ));
        }
        // Pushed out of index order on purpose.
        b.push(&Entry::dc_step_marker(
            500,
            1,
            SegmentPhase::Start,
            "second",
        ));
        b.push(&Entry::dc_step_marker(200, 0, SegmentPhase::Start, "first"));
        b.push(&Entry::dc_step_marker(400, 0, SegmentPhase::End, "first"));
        b.push(&Entry::dc_step_marker(700, 1, SegmentPhase::End, "second"));
        let r = b.finish();
        assert_eq!(r.segments.len(), 2);
        let s0 = &r.segments[0];
        assert_eq!(s0.index, 0);
        assert_eq!(s0.label, "first");
        assert_eq!(s0.kind, Some(SegmentKind::DcStep));
        assert_eq!(s0.time, vec![200.0 * 1e-9, 300.0 * 1e-9, 400.0 * 1e-9]);
        assert_eq!(s0.current, vec![12.0, 13.0, 14.0]);
        // The sensor, not the command channel.
        assert_eq!(s0.voltage, vec![2.0, 3.0, 4.0]);
        assert_eq!(s0.speed, vec![20.0; 3]);
        assert_eq!(r.segments[1].current, vec![15.0, 16.0, 17.0]);
    }

    #[test]
    fn open_segment_takes_the_rest_and_is_marked() {
        let mut b = RecordBuilder::new(None, channels());
        b.push(&Entry::dc_step_marker(250, 0, SegmentPhase::Start, "step"));
        for k in 0..6u64 {
            b.push(&samples(k * 100, &[(1, 1.0), (2, k as f64), (3, 2.0)]));
        }
        let r = b.finish();
        assert_eq!(r.segments[0].label, "step (incomplete)");
        assert_eq!(r.segments[0].current, vec![3.0, 4.0, 5.0]);
    }

    #[test]
    fn interpolates_onto_current_instants() {
        let mut b = RecordBuilder::new(None, channels());
        b.push(&Entry::dc_step_marker(0, 0, SegmentPhase::Start, "s"));
        // Voltage at 100 and 300; speed at 0, 200 and 400; current every 50.
        b.push(&samples(100, &[(1, 10.0)]));
        b.push(&samples(300, &[(1, 30.0)]));
        for (t, w) in [(0, 0.0), (200, 2.0), (400, 4.0)] {
            b.push(&samples(t, &[(3, w)]));
        }
        for t in [0u64, 50, 100, 150, 200, 250, 300, 350, 400, 450] {
            b.push(&samples(t, &[(2, t as f64)]));
        }
        b.push(&Entry::dc_step_marker(450, 0, SegmentPhase::End, "s"));
        let r = b.finish();
        let s = &r.segments[0];
        assert_eq!(s.time.len(), 10);
        // Held before 100 and after 300; linear between; exact at 100/300.
        assert_eq!(
            s.voltage,
            vec![10.0, 10.0, 10.0, 15.0, 20.0, 25.0, 30.0, 30.0, 30.0, 30.0]
        );
        assert_eq!(
            s.speed,
            vec![0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.0]
        );
    }

    /// A record of one segment of `kind` and `n` samples 500 µs apart
    /// (voltage, current and speed each `x(k)`), then a short second
    /// segment.
    fn long_record(
        n: u64,
        kind: SegmentKind,
        resolution: Resolution,
        x: impl Fn(u64) -> f64,
    ) -> Record {
        let mut b = RecordBuilder::new(None, channels()).resolution(resolution);
        let dt = 500_000;
        let marker = |t, phase, label: &str| Entry::Segment {
            t_ns: t,
            marker: SegmentMarker {
                index: 4,
                kind,
                phase,
                label: label.into(),
            },
        };
        b.push(&marker(0, SegmentPhase::Start, "long"));
        for k in 0..n + 100 {
            let x = x(k);
            b.push(&samples(k * dt, &[(1, x), (2, x), (3, x)]));
            if k == n - 1 {
                b.push(&marker(k * dt, SegmentPhase::End, "long"));
                b.push(&Entry::dc_step_marker(
                    k * dt,
                    7,
                    SegmentPhase::Start,
                    "next",
                ));
            }
        }
        b.push(&Entry::dc_step_marker(
            (n + 99) * dt,
            7,
            SegmentPhase::End,
            "next",
        ));
        b.finish()
    }

    /// A step from 0 to 2 with 500 µs samples settling in about 20 ms,
    /// then held, with ±0.01 alternating noise.
    fn settling(k: u64) -> f64 {
        2.0 * (1.0 - (-(k as f64) / 40.0).exp()) + if k % 2 == 0 { 0.01 } else { -0.01 }
    }

    #[test]
    fn a_long_settled_hold_is_read_as_its_head_and_its_tail() {
        let n = 200_000;
        let r = long_record(n, SegmentKind::DcStep, Resolution::Analysis, settling);
        assert_eq!(r.segments.len(), 2);
        let (long, next) = (&r.segments[0], &r.segments[1]);
        assert_eq!(long.index, 4);
        let (h, t) = (HEAD_SAMPLES, TAIL_SAMPLES);
        assert_eq!(long.time.len(), h + t);
        // The head as read, then the hold's last samples (the boundary
        // sample, the next segment's first, left out).
        let want: Vec<f64> = (0..h as u64)
            .chain(n - 1 - t as u64..n - 1)
            .map(settling)
            .collect();
        for series in [&long.current, &long.voltage, &long.speed] {
            let differs: Vec<(usize, f64, f64)> = series
                .iter()
                .zip(&want)
                .enumerate()
                .filter(|(_, (a, b))| a != b)
                .map(|(k, (a, b))| (k, *a, *b))
                .take(3)
                .collect();
            assert!(differs.is_empty(), "the head and the tail: {differs:?}");
        }
        // Evenly sampled: the tail follows the head one interval later.
        for w in long.time.windows(2) {
            assert!((w[1] - w[0] - 5e-4).abs() < 1e-9, "{w:?}");
        }
        // The next segment starts at the shared boundary sample, whole,
        // one sample interval after the last, on the analysis' clock.
        assert_eq!(next.current[0], settling(n - 1));
        let gap = next.time[0] - long.time[long.time.len() - 1];
        assert!((gap - 5e-4).abs() < 1e-9, "{gap}");
        assert_eq!(next.time.len(), 101);
        // The cut, on the analysis' clock: after the head's last sample,
        // as long as the note says.
        assert_eq!(r.cuts.len(), 1);
        let cut = r.cuts[0];
        assert_eq!((cut.segment, cut.at_s), (4, long.time[h - 1]));
        let left_out = ((n - 1 - t as u64) - h as u64) as f64 * 5e-4;
        assert!((cut.left_out_s - left_out).abs() < 1e-9, "{cut:?}");
        assert_eq!(r.notes.len(), 1);
        assert_eq!(
            r.notes[0],
            "long holds 200000 current readings over 100.0 s: the analysis reads its first 2048 \
             (1.02 s, the step) and its last 2048 (the settled level), and its clock leaves out \
             the 98.0 s between them (times after 1.024 s read that much earlier); the record \
             file keeps them all (`motorbench export` writes them, and a CSV file is read whole)"
        );
    }

    #[test]
    fn a_segment_that_never_settles_is_read_as_its_longest_head() {
        let n = 30_000;
        let r = long_record(n, SegmentKind::DcStep, Resolution::Analysis, |k| k as f64);
        let long = &r.segments[0];
        let first: Vec<f64> = (0..HEAD_MAX).map(|k| k as f64).collect();
        assert!(long.current == first && long.speed == first);
        assert!(
            r.notes[0].contains("do not end on the level"),
            "{}",
            r.notes[0]
        );
        // Its head alone: the clock leaves nothing out.
        assert!(r.cuts.is_empty());
    }

    #[test]
    fn a_coast_down_and_a_full_resolution_record_are_read_whole() {
        let n = 100_000;
        for (kind, resolution) in [
            (SegmentKind::DcCoastdown, Resolution::Analysis),
            (SegmentKind::DcStep, Resolution::Full),
        ] {
            let r = long_record(n, kind, resolution, |k| k as f64);
            assert_eq!(r.segments[0].current.len(), n as usize, "{kind:?}");
            assert!(r.segments[0]
                .current
                .iter()
                .enumerate()
                .all(|(k, &i)| i == k as f64));
            assert!(r.notes.is_empty() && r.cuts.is_empty());
        }
    }

    #[test]
    fn a_segment_within_its_head_and_what_follows_is_read_whole() {
        let n = (HEAD_SAMPLES + PAST_HEAD) as u64;
        let thin = long_record(n, SegmentKind::DcStep, Resolution::Analysis, settling);
        let full = long_record(n, SegmentKind::DcStep, Resolution::Full, settling);
        assert!(thin.segments == full.segments, "the same segments");
        assert!(thin.notes.is_empty());
        assert_eq!(thin.segments[0].time.len(), n as usize);
    }

    #[test]
    fn interpolate_edges_and_exact() {
        let s = [(10u64, 1.0), (20, 3.0), (20, 5.0), (40, 7.0)];
        assert_eq!(interpolate(&s, 0), 1.0);
        assert_eq!(interpolate(&s, 10), 1.0);
        assert_eq!(interpolate(&s, 15), 2.0);
        assert_eq!(interpolate(&s, 20), 3.0);
        assert_eq!(interpolate(&s, 30), 6.0);
        assert_eq!(interpolate(&s, 50), 7.0);
        assert_eq!(interpolate(&[(5, 0.1 + 0.2)], 5), 0.1 + 0.2);
    }

    #[test]
    fn missing_channel_leaves_series_empty() {
        let chans = vec![
            ChannelSpec::sensor("armature_voltage", "V", "daq"),
            ChannelSpec::sensor("armature_current", "A", "daq"),
            ChannelSpec::command("speed", "rad/s", "dyno"),
        ];
        let mut b = RecordBuilder::new(None, chans);
        b.push(&Entry::dc_step_marker(0, 0, SegmentPhase::Start, "s"));
        b.push(&samples(10, &[(0, 1.0), (1, 2.0), (2, 3.0)]));
        b.push(&Entry::dc_step_marker(20, 0, SegmentPhase::End, "s"));
        let r = b.finish();
        assert_eq!(r.segments.len(), 1);
        let s = &r.segments[0];
        assert!(s.time.is_empty() && s.voltage.is_empty());
        assert!(s.current.is_empty() && s.speed.is_empty());
    }

    #[test]
    fn skips_non_finite_and_unknown_channels() {
        let mut b = RecordBuilder::new(None, channels());
        b.push(&Entry::dc_step_marker(0, 0, SegmentPhase::Start, "s"));
        b.push(&samples(
            10,
            &[(1, 1.0), (2, f64::NAN), (3, 2.0), (17, 5.0)],
        ));
        b.push(&samples(20, &[(1, 1.0), (2, 4.0), (3, f64::INFINITY)]));
        b.push(&Entry::dc_step_marker(30, 0, SegmentPhase::End, "s"));
        let r = b.finish();
        let s = &r.segments[0];
        assert_eq!(s.current, vec![4.0]);
        assert_eq!(s.speed, vec![2.0]);
    }

    #[test]
    fn events_result_and_meta() {
        let meta = TestMeta {
            schema_version: "1".into(),
            kind: SegmentKind::DcStep,
            motor_id: "m1".into(),
            started_at: "2026-01-01T00:00:00Z".into(),
            nameplate: serde_json::json!({"power_W": 100.0}),
            config: String::new(),
        };
        let mut b = RecordBuilder::new(Some(meta.clone()), channels());
        let ev = |t, m: &str| Entry::Event {
            t_ns: t,
            event: Event {
                level: EventLevel::Info,
                message: m.into(),
            },
        };
        b.push(&ev(20, "b"));
        b.push(&ev(10, "a"));
        b.push(&Entry::Result {
            t_ns: 30,
            report: serde_json::json!({"n": 1}),
        });
        b.push(&Entry::Result {
            t_ns: 40,
            report: serde_json::json!({"n": 2}),
        });
        let r = b.finish();
        assert_eq!(r.meta, Some(meta));
        assert_eq!(
            r.events.iter().map(|(t, _)| *t).collect::<Vec<_>>(),
            vec![10, 20]
        );
        assert_eq!(r.recorded_result, Some(serde_json::json!({"n": 2})));
        assert!(r.segments.is_empty());
        assert!(r.recovery.is_none());
    }
}
