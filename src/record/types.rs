//! The in-memory shape of a record: what the bench sends to the recorder,
//! and what identification reads back (from the bench, MCAP or CSV).

use serde::{Deserialize, Serialize};

pub use super::im_tests::{
    implausible_temperature, DcResistanceReading, ImStandardTests, StandardTestReading,
    SupplyReading, TEMPERATURE_RANGE_C,
};

/// Contract version written to every record and report.
pub use crate::contract::SCHEMA_VERSION;

/// The test kinds of the data contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "snake_case")]
pub enum SegmentKind {
    /// Armature-voltage step of a separately excited DC motor.
    DcStep,
    /// Armature opened from a steady speed; the speed decays to rest.
    DcCoastdown,
    /// Induction-machine slip sweep (the load test).
    ImSlipSweep,
    /// Induction-machine DC winding-resistance reading (an additive kind).
    ImDcResistance,
    /// Induction-machine no-load test at several voltages (an additive kind).
    ImNoLoad,
    /// Induction-machine locked-rotor test (an additive kind).
    ImLockedRotor,
}

impl SegmentKind {
    /// The contract's name for the kind.
    pub fn as_str(self) -> &'static str {
        match self {
            SegmentKind::DcStep => "dc_step",
            SegmentKind::DcCoastdown => "dc_coastdown",
            SegmentKind::ImSlipSweep => "im_slip_sweep",
            SegmentKind::ImDcResistance => "im_dc_resistance",
            SegmentKind::ImNoLoad => "im_no_load",
            SegmentKind::ImLockedRotor => "im_locked_rotor",
        }
    }

    /// Parse the contract's name; `None` for anything else.
    pub fn parse(s: &str) -> Option<SegmentKind> {
        match s {
            "dc_step" => Some(SegmentKind::DcStep),
            "dc_coastdown" => Some(SegmentKind::DcCoastdown),
            "im_slip_sweep" => Some(SegmentKind::ImSlipSweep),
            "im_dc_resistance" => Some(SegmentKind::ImDcResistance),
            "im_no_load" => Some(SegmentKind::ImNoLoad),
            "im_locked_rotor" => Some(SegmentKind::ImLockedRotor),
            _ => None,
        }
    }

    /// The machine whose test this kind is.
    pub fn machine(self) -> crate::model::Machine {
        use crate::model::Machine;
        match self {
            SegmentKind::DcStep | SegmentKind::DcCoastdown => Machine::Dc,
            SegmentKind::ImSlipSweep
            | SegmentKind::ImDcResistance
            | SegmentKind::ImNoLoad
            | SegmentKind::ImLockedRotor => Machine::Induction,
        }
    }

    /// Whether the kind is one of the induction machine's tests.
    pub fn is_im(self) -> bool {
        self.machine() == crate::model::Machine::Induction
    }
}

impl std::fmt::Display for SegmentKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Severity of a `/bench/event` message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventLevel {
    /// Progress and facts.
    Info,
    /// Something a user should look at; the test went on.
    Warn,
    /// The test was stopped and the rig put in its safe state.
    Abort,
}

/// Phase of a `/bench/segment` marker.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SegmentPhase {
    /// The segment begins at this message's time.
    Start,
    /// The segment ends at this message's time.
    End,
}

/// A `/bench/segment` message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentMarker {
    /// Segment index, from 0.
    pub index: u32,
    /// Test kind of the segment.
    pub kind: SegmentKind,
    /// Start or end.
    pub phase: SegmentPhase,
    /// Free text, e.g. `60 V → 248 V`.
    pub label: String,
}

/// A `/bench/event` message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Event {
    /// Severity.
    pub level: EventLevel,
    /// What happened, for a person.
    pub message: String,
}

/// One recorded channel (`/sensor/*` or `/command/*`) and its metadata.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelSpec {
    /// MCAP topic, e.g. `/sensor/armature_current`.
    pub topic: String,
    /// Contract quantity, e.g. `armature_current`.
    pub quantity: String,
    /// SI unit, e.g. `A`.
    pub unit: String,
    /// Driver id of the device that produced it.
    pub source: String,
}

impl ChannelSpec {
    /// A `/sensor/<quantity>` channel.
    pub fn sensor(quantity: &str, unit: &str, source: &str) -> ChannelSpec {
        ChannelSpec {
            topic: format!("/sensor/{quantity}"),
            quantity: quantity.to_string(),
            unit: unit.to_string(),
            source: source.to_string(),
        }
    }

    /// A `/command/<quantity>` channel.
    pub fn command(quantity: &str, unit: &str, source: &str) -> ChannelSpec {
        ChannelSpec {
            topic: format!("/command/{quantity}"),
            quantity: quantity.to_string(),
            unit: unit.to_string(),
            source: source.to_string(),
        }
    }
}

/// The `motorbench.test` metadata record (all values strings in MCAP).
#[derive(Debug, Clone, PartialEq)]
pub struct TestMeta {
    /// Contract version, [`SCHEMA_VERSION`] for what we write.
    pub schema_version: String,
    /// Test kind of the record as a whole.
    pub kind: SegmentKind,
    /// Free-form id of the motor under test.
    pub motor_id: String,
    /// Wall-clock start, RFC 3339.
    pub started_at: String,
    /// Rated values, a JSON object (contract keys: `power_W`, …).
    pub nameplate: serde_json::Value,
    /// The resolved configuration, TOML text.
    pub config: String,
}

/// What the bench hands the recorder; the MCAP reader yields the same.
///
/// `t_ns` is nanoseconds since the start of the test (MCAP `log_time`
/// in a version 1 record; `log_time − start_time_ns` in version 2).
#[derive(Debug, Clone, PartialEq)]
pub enum Entry {
    /// Readings taken at one instant: `(channel index, value)` pairs, the
    /// index into the channel list given when recording started.
    Samples {
        /// Time of the readings.
        t_ns: u64,
        /// `(channel index, value)`.
        values: Vec<(usize, f64)>,
    },
    /// A segment boundary.
    Segment {
        /// Time of the boundary.
        t_ns: u64,
        /// The marker.
        marker: SegmentMarker,
    },
    /// A bench event.
    Event {
        /// When it happened.
        t_ns: u64,
        /// What happened.
        event: Event,
    },
    /// One averaged steady-state point of an induction-machine slip sweep.
    OperatingPoint {
        /// When the point was taken (the end of its averaging window).
        t_ns: u64,
        /// The point.
        point: OperatingPoint,
    },
    /// A stretch where the supply did not follow its set point.
    SupplyLimit {
        /// When the stretch was reported (at the latest its segment's end).
        t_ns: u64,
        /// The stretch.
        limit: SupplyLimit,
    },
    /// One averaged reading of an induction machine's standard test (DC
    /// resistance, no load, locked rotor).
    StandardTest {
        /// When it was taken (the end of its averaging window).
        t_ns: u64,
        /// The reading.
        reading: StandardTestReading,
    },
    /// The final identification (and diagnosis) report.
    Result {
        /// When it was produced.
        t_ns: u64,
        /// The report, as the CLI's `--json` prints it.
        report: serde_json::Value,
    },
}

/// Test records: a `dc_step` segment boundary.
#[cfg(test)]
impl Entry {
    /// The `phase` boundary of `dc_step` segment `index` labelled `label`
    /// at `t_ns`.
    pub(crate) fn dc_step_marker(t_ns: u64, index: u32, phase: SegmentPhase, label: &str) -> Entry {
        Entry::Segment {
            t_ns,
            marker: SegmentMarker {
                index,
                kind: SegmentKind::DcStep,
                phase,
                label: label.into(),
            },
        }
    }
}

/// A `/bench/operating_point` message: one averaged steady-state point of
/// an induction-machine slip sweep, SI units, slip a fraction.
///
/// `speed` and `frequency` are NaN where the source did not give them (a
/// CSV import without those columns); such a point cannot be written to
/// MCAP, whose JSON has no NaN.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OperatingPoint {
    /// Segment (sweep) index.
    pub segment: u32,
    /// Slip, 0 (synchronous) to 1 (locked rotor).
    pub slip: f64,
    /// RMS line-to-line voltage, V.
    pub line_voltage: f64,
    /// RMS line current, A.
    pub line_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Shaft speed, rad/s.
    pub speed: f64,
    /// Supply frequency, Hz.
    pub frequency: f64,
    /// Shaft torque where a torque sensor exists, N·m.
    pub torque: Option<f64>,
    /// The winding thermometer's mean over the point's averaging window,
    /// °C (as labs read it), where the rig has one. Absent from the
    /// message without one, so that such a record is as before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub winding_temperature: Option<f64>,
}

impl OperatingPoint {
    /// The first field that is not a finite number, if any.
    pub fn non_finite_field(&self) -> Option<(&'static str, f64)> {
        [
            ("slip", self.slip),
            ("line_voltage", self.line_voltage),
            ("line_current", self.line_current),
            ("input_power", self.input_power),
            ("speed", self.speed),
            ("frequency", self.frequency),
            ("torque", self.torque.unwrap_or(0.0)),
            (
                "winding_temperature",
                self.winding_temperature.unwrap_or(0.0),
            ),
        ]
        .into_iter()
        .find(|(_, v)| !v.is_finite())
    }
}

/// How a supply failed to follow its set point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SupplyLimitKind {
    /// It held its current limit (constant-current mode), its voltage
    /// below the command.
    CurrentLimit,
    /// It did not reach the commanded voltage, its current below the limit.
    VoltageCompliance,
}

/// A `/bench/supply_limit` message: a stretch of a segment where the
/// supply did not follow its set point, so the segment's voltage is not
/// the step that was commanded. Times in s since the start of the test.
/// (An additive extension of the contract; unknown keys are ignored.)
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SupplyLimit {
    /// Segment index.
    pub segment: u32,
    /// How the supply limited.
    pub kind: SupplyLimitKind,
    /// First reading of the stretch, s.
    pub from: f64,
    /// Last reading of the stretch, s.
    pub to: f64,
    /// The commanded voltage, V.
    pub commanded_voltage: f64,
    /// The measured voltage furthest from the command in the stretch
    /// (current limit) or settled at the segment's end (compliance), V.
    pub measured_voltage: f64,
    /// The current limit the supply was set to, A, when it has one.
    pub current_limit: Option<f64>,
    /// The largest current magnitude read in the stretch (current limit)
    /// or in the segment (compliance), A.
    pub peak_current: f64,
}

impl SupplyLimit {
    /// One line for a person, e.g. for the record's events and the
    /// report's warnings.
    pub fn describe(&self, label: &str) -> String {
        let what = match (self.kind, self.current_limit) {
            (SupplyLimitKind::CurrentLimit, Some(limit)) => format!(
                "current-limiting (held at its {limit:.3} A limit, peak {:.3} A; measured voltage {:.2} V at its furthest from the {:.2} V commanded)",
                self.peak_current, self.measured_voltage, self.commanded_voltage
            ),
            (SupplyLimitKind::CurrentLimit, None) => format!(
                "current-limiting (peak {:.3} A; measured voltage {:.2} V at its furthest from the {:.2} V commanded)",
                self.peak_current, self.measured_voltage, self.commanded_voltage
            ),
            (SupplyLimitKind::VoltageCompliance, _) => format!(
                "short of its commanded voltage (settled at {:.2} V against {:.2} V commanded)",
                self.measured_voltage, self.commanded_voltage
            ),
        };
        format!(
            "the supply was {what} in segment {} ({label}) from {:.4} s to {:.4} s",
            self.segment, self.from, self.to
        )
    }
}

/// The `t_ns` field of an entry (`&Entry` gives `&u64`, `&mut Entry`
/// gives `&mut u64`).
macro_rules! t_ns_field {
    ($entry:expr) => {
        match $entry {
            Entry::Samples { t_ns, .. }
            | Entry::OperatingPoint { t_ns, .. }
            | Entry::Segment { t_ns, .. }
            | Entry::Event { t_ns, .. }
            | Entry::SupplyLimit { t_ns, .. }
            | Entry::StandardTest { t_ns, .. }
            | Entry::Result { t_ns, .. } => t_ns,
        }
    };
}

impl Entry {
    /// The entry's time, ns since the start of the test.
    pub fn t_ns(&self) -> u64 {
        *t_ns_field!(self)
    }

    /// The entry's time, to change.
    pub fn t_ns_mut(&mut self) -> &mut u64 {
        t_ns_field!(self)
    }
}

/// One DC segment as identification sees it: series on one time base.
///
/// All series have the length of `time`. Channels recorded at other
/// instants are linearly interpolated onto the armature-current instants.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DcSegment {
    /// Segment index.
    pub index: u32,
    /// `DcStep` or `DcCoastdown`.
    pub kind: Option<SegmentKind>,
    /// Free text label.
    pub label: String,
    /// Seconds since the start of the test.
    pub time: Vec<f64>,
    /// Armature voltage, V.
    pub voltage: Vec<f64>,
    /// Armature current, A.
    pub current: Vec<f64>,
    /// Shaft speed, rad/s.
    pub speed: Vec<f64>,
}

impl DcSegment {
    /// A test segment of `n` samples `dt` apart that holds the voltage
    /// `u`, the current `i` and the speed `w` throughout.
    #[cfg(test)]
    pub(crate) fn held(n: usize, dt: f64, u: f64, i: f64, w: f64) -> DcSegment {
        DcSegment {
            time: (0..n).map(|k| k as f64 * dt).collect(),
            voltage: vec![u; n],
            current: vec![i; n],
            speed: vec![w; n],
            ..Default::default()
        }
    }

    /// Append one sample: time `t` (s), voltage (V), current (A) and
    /// speed (rad/s).
    pub fn push_sample(&mut self, t: f64, voltage: f64, current: f64, speed: f64) {
        self.time.push(t);
        self.voltage.push(voltage);
        self.current.push(current);
        self.speed.push(speed);
    }
}

/// How much of a damaged (truncated, bit-flipped) file could be read.
#[derive(Debug, Clone, PartialEq)]
pub struct Recovery {
    /// Messages read before the damage.
    pub messages: u64,
    /// The byte offset in the file of the record (or chunk) found damaged;
    /// nothing from there on was read.
    pub offset: u64,
    /// Where the damage is, how much of the file was read and what the
    /// reader found there, on one line.
    pub reason: String,
}

impl std::fmt::Display for Recovery {
    /// `1234 messages recovered; damaged at byte 5678 of 9000 (63.1 % read): …`
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} messages recovered; {}", self.messages, self.reason)
    }
}

/// A whole record, ready for identification.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Record {
    /// Metadata, when the source had it (MCAP does; CSV does not).
    pub meta: Option<TestMeta>,
    /// The segments, in index order.
    pub segments: Vec<DcSegment>,
    /// Induction-machine operating points in recording order.
    pub operating_points: Vec<OperatingPoint>,
    /// Induction-machine standard tests other than the slip sweep (DC
    /// resistance, no load, locked rotor): from CSV, or as the rig
    /// recorded them on `/bench/standard_test`.
    pub standard_tests: ImStandardTests,
    /// Bench events in time order.
    pub events: Vec<(u64, Event)>,
    /// Where the supply did not follow its set point, in recording order.
    pub supply_limits: Vec<SupplyLimit>,
    /// The `/bench/result` found in the file, if any.
    pub recorded_result: Option<serde_json::Value>,
    /// Set when the file was damaged and only partly read.
    pub recovery: Option<Recovery>,
    /// What was done to the record after reading it (a single segment
    /// split, say), for the report's warnings; not part of the contract.
    pub notes: Vec<String>,
    /// Where the analysis' clock leaves out the middle of a long hold
    /// ([`super::thinning`]), in segment order; not part of the contract.
    pub cuts: Vec<ClockCut>,
}

/// A stretch of a long hold the analysis does not read: its clock jumps
/// over it, so the samples after it read earlier than the file has them.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ClockCut {
    /// The segment it lies in.
    pub segment: u32,
    /// The analysis' time of the last sample before it, s.
    pub at_s: f64,
    /// How long it lasts, s.
    pub left_out_s: f64,
}
