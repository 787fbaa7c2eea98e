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

use std::collections::BTreeMap;

use super::schema::SENSOR_PREFIX;
use super::types::{
    ChannelSpec, DcSegment, Entry, Event, ImStandardTests, OperatingPoint, Record, SegmentKind,
    SegmentPhase, SupplyLimit, TestMeta,
};

/// Appended to the label of a segment that has no end marker.
pub const INCOMPLETE_SUFFIX: &str = " (incomplete)";

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
    /// `(t_ns, value)` per series: voltage, current, speed.
    samples: [Vec<(u64, f64)>; 3],
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
            Series::Current => 1,
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

impl RecordBuilder {
    /// A builder for a record with this metadata and channel list (the
    /// list whose indices [`Entry::Samples`] refers to).
    pub fn new(meta: Option<TestMeta>, channels: Vec<ChannelSpec>) -> Self {
        let mut taken = [false; 3];
        let roles = channels
            .iter()
            .map(|c| {
                let s = Series::of(c)?;
                if taken[s.slot()] {
                    return None;
                }
                taken[s.slot()] = true;
                Some(s)
            })
            .collect();
        RecordBuilder {
            meta,
            roles,
            samples: Default::default(),
            spans: BTreeMap::new(),
            events: Vec::new(),
            result: None,
            points: Vec::new(),
            standard_tests: ImStandardTests::default(),
            supply_limits: Vec::new(),
        }
    }

    /// Takes one entry. Samples on channels outside the list given to
    /// [`RecordBuilder::new`] are ignored.
    pub fn push(&mut self, entry: &Entry) {
        match entry {
            Entry::Samples { t_ns, values } => {
                for &(index, value) in values {
                    if !value.is_finite() {
                        continue;
                    }
                    if let Some(Some(series)) = self.roles.get(index) {
                        self.samples[series.slot()].push((*t_ns, value));
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

    /// Builds the record.
    pub fn finish(self) -> Record {
        let RecordBuilder {
            meta,
            mut samples,
            spans,
            mut events,
            result,
            points,
            standard_tests,
            supply_limits,
            ..
        } = self;
        for s in &mut samples {
            // Stable: samples at one instant keep their arrival order.
            s.sort_by_key(|&(t, _)| t);
        }
        let complete = samples.iter().all(|s| !s.is_empty());
        let [voltage, current, speed] = &samples;
        let segments = spans
            .into_iter()
            .map(|(index, span)| {
                let mut seg = DcSegment {
                    index,
                    kind: Some(span.kind),
                    label: match span.end {
                        Some(_) => span.label,
                        None => span.label + INCOMPLETE_SUFFIX,
                    },
                    ..DcSegment::default()
                };
                if complete {
                    let end = span.end.unwrap_or(u64::MAX);
                    let base: Vec<(u64, f64)> = current
                        .iter()
                        .copied()
                        .filter(|&(t, _)| span.start <= t && t <= end)
                        .collect();
                    seg.time = base.iter().map(|&(t, _)| t as f64 * 1e-9).collect();
                    seg.current = base.iter().map(|&(_, v)| v).collect();
                    seg.voltage = base.iter().map(|&(t, _)| interpolate(voltage, t)).collect();
                    seg.speed = base.iter().map(|&(t, _)| interpolate(speed, t)).collect();
                }
                seg
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
            notes: Vec::new(),
        }
    }
}

/// The value of the series `s` (sorted by time, not empty) at `t`: linear
/// between neighbours, exact where a sample lies at `t` (the first such),
/// the edge value outside the series' range.
fn interpolate(s: &[(u64, f64)], t: u64) -> f64 {
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
mod tests {
    use super::*;
    use crate::record::types::EventLevel;

    fn channels() -> Vec<ChannelSpec> {
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
