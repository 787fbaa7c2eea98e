//! The machine plug-in: what differs between a DC machine's test and an
//! induction machine's, behind one trait, so that everything else — the
//! session that opens the rig, records, runs the plan and analyses
//! ([`crate::session`]), the CLI's `run`, the daemon's jobs, the tests —
//! is written once.
//!
//! A [`Machine`] is a validated test configuration that knows its plan: it
//! opens its rig (any number of power stages, the stage that feeds the
//! machine first, and one sensor stream), names the channels its record
//! holds, runs its plan through the bench's one sequencer core, and
//! analyses the record it made ([`Analysis`]: the contract's report with
//! the diagnosis attached, the text, the plot).
//! [`crate::config::TestConfig::into_machine`] is the one place a plan is
//! mapped to its machine.
//!
//! A third machine would be a folder beside `dc/` and `im/` holding what
//! those hold (its configuration file format, plan, rig builder,
//! simulated and protocol-served rigs, `identify/`, `diagnose/`, text,
//! plot, blind-case simulator) and implementing this trait, plus a
//! [`crate::config::TestConfig`] variant (with its
//! [`crate::config::PlanKind`]s), the record's [`SegmentKind`]s (the
//! compiler then lists the exhaustive matches on them) and a branch in
//! each function of `records.rs` ([`analyse`], [`diagnose`],
//! [`check_record`], [`ready_record`]: the one place a record is mapped
//! to its machine, as `into_machine` is for a plan).

pub mod dc;
pub mod im;
mod records;
mod sim_parts;

pub use dc::analyse_dc;
pub use im::analyse_im;
pub use records::{
    analyse, analyse_record, check_record, diagnose, ready_record, record_analysis_kind,
    AnalyseOptions, ImplausibleRecord,
};

use std::any::Any;
use std::path::Path;

use async_trait::async_trait;
use motorbench_drivers::{ChannelInfo, LinkHealth, PowerStage, SensorStream};

use crate::bench::{BenchError, Outcome, Progress, RecordSink, SafetyRules, StopPath};
use crate::config::CommonConfig;
use crate::diagnose::{attach_diagnosis, ResidualPlot};
use crate::record::{ChannelSpec, Event, EventLevel, Record, SegmentKind};
use crate::report::IdentificationReport;
use crate::rig::ModbusProbe;
use crate::rig::RigError;

/// A simulated rig's true machine (its parameters, of the machine's own
/// type), for the text report's "true value" column.
pub type Truth = Box<dyn Any + Send + Sync>;

/// One power stage of a rig.
pub struct RigStage {
    /// Its role, for a person (`power stage`, `supply`, `dynamometer`).
    pub name: &'static str,
    /// The stage.
    pub stage: Box<dyn PowerStage>,
    /// The bound of its set points (the configured limit).
    pub max_setpoint: f64,
}

/// A rig opened for a test.
pub struct OpenedRig {
    /// The power stages, the stage that feeds the machine first (it is
    /// made safe first).
    pub stages: Vec<RigStage>,
    /// What measures the machine.
    pub sensors: Box<dyn SensorStream>,
    /// Encoder counts per revolution.
    pub counts_per_rev: f64,
    /// The simulated machine, on a simulated rig.
    pub truth: Option<Truth>,
    /// What must live as long as the test: the protocol servers of a
    /// simulated rig served behind Modbus or CAN.
    pub keep_alive: Option<Box<dyn Any + Send>>,
    /// The sensors again, for a one-shot read of each channel (`probe`),
    /// where the rig polls them over Modbus.
    pub modbus_probe: Option<ModbusProbe>,
    /// The health of the buses the rig owns (its Modbus links, one per
    /// link); a rig with none (the in-process simulation) leaves it
    /// empty. The sensors' own links ([`SensorStream::link_health`]) are
    /// not in it.
    pub links: Vec<LinkHealth>,
}

impl OpenedRig {
    /// A rig of `stages` measured by `sensors`, as a rig builder gives it:
    /// `truth` the simulated machine, `served` the protocol servers to
    /// keep alive, `links` the health of its buses; no Modbus probe.
    pub fn new<T: Any + Send + Sync, S: Any + Send>(
        stages: Vec<RigStage>,
        sensors: Box<dyn SensorStream>,
        counts_per_rev: f64,
        truth: Option<T>,
        served: Option<S>,
        links: Vec<LinkHealth>,
    ) -> OpenedRig {
        OpenedRig {
            stages,
            sensors,
            counts_per_rev,
            truth: truth.map(|t| Box::new(t) as Truth),
            keep_alive: served.map(|s| Box::new(s) as Box<dyn Any + Send>),
            modbus_probe: None,
            links,
        }
    }
}

/// The rig as a plan drives it: its stages in the order
/// [`OpenedRig::stages`] gave them, and its sensors.
pub struct PlanRig<'a> {
    /// The power stages.
    pub stages: &'a mut [Box<dyn PowerStage>],
    /// The sensors.
    pub sensors: &'a mut dyn SensorStream,
    /// Encoder counts per revolution.
    pub counts_per_rev: f64,
}

/// How long a plan's segments take, for a progress estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanDurations {
    /// A segment's expected duration before one has finished, s.
    pub guess_s: f64,
    /// Each segment's longest duration (its timeout), s.
    pub timeouts_s: Vec<f64>,
    /// Each segment's kind.
    pub kinds: Vec<SegmentKind>,
}

/// Why a machine's plot could not be written: the machine's own plot
/// error (each machine draws its own kind of plot).
pub type PlotFailure = Box<dyn std::error::Error + Send + Sync>;

/// A machine's analysis of a record: identification with its diagnosis.
pub trait Analysis: Send {
    /// The report per the data contract.
    fn report(&self) -> &IdentificationReport;
    /// The report, to attach a diagnosis to.
    fn report_mut(&mut self) -> &mut IdentificationReport;
    /// The identification as text for a person (without the diagnosis).
    fn text(&self) -> String;
    /// Draw the record against the identified model to `path` (SVG).
    fn write_plot(&self, record: &Record, path: &Path) -> Result<(), PlotFailure>;
    /// Why nothing could be identified, for exit code 4; `None` when a
    /// method applied.
    fn refusal(&self) -> Option<String>;
}

/// What differs between machines; see the module docs.
#[async_trait]
pub trait Machine: Send + Sync {
    /// The record's kind (the contract's `kind`).
    fn kind(&self) -> SegmentKind;
    /// What every test configuration holds: the file and its text
    /// (recorded in the record's metadata), the motor's id and nameplate,
    /// the sample rate, limits, supervision, retention, the faults it
    /// injects.
    fn common(&self) -> &CommonConfig;
    /// The test and its rig for a person: "`motor` on `rig` (`file`)".
    fn describe(&self) -> String;
    /// The plan for a person, one line.
    fn plan_summary(&self) -> String;
    /// The checks every batch of this test must pass.
    fn safety_rules(&self) -> SafetyRules;
    /// How long the plan's segments take.
    fn durations(&self) -> PlanDurations;
    /// The record's channels: the sensors', the derived speed, and one
    /// command channel per stage (`stage_ids` in [`OpenedRig::stages`]'
    /// order).
    fn record_channels(&self, sensors: &[ChannelInfo], stage_ids: &[&str]) -> Vec<ChannelSpec>;
    /// Open the rig; `realtime` paces a simulated rig at the wall clock.
    async fn open_rig(&self, realtime: bool) -> Result<OpenedRig, RigError>;
    /// Run the plan to its end, recording into `sink`; every stop comes
    /// through `stops`, and the rig is safe when this returns.
    async fn run_plan(
        &self,
        rig: PlanRig<'_>,
        sink: &mut RecordSink,
        progress: &dyn Progress,
        stops: StopPath<'_>,
    ) -> Result<Outcome, BenchError>;
    /// The analysis of a record this test made (CPU work: call it off the
    /// reactor); `truth` is the simulated machine.
    fn analyser(&self, truth: Option<Truth>) -> Analyser;
}

/// Analyses a record: identification and, when the flag says so, the
/// diagnosis.
pub type Analyser = Box<dyn FnOnce(&Record, bool) -> Analysed + Send>;

/// A record analysed.
pub struct Analysed {
    /// Identification, with the diagnosis in its report when asked for.
    pub analysis: Box<dyn Analysis>,
    /// The diagnosis' residuals before and after its effect, when diagnosed.
    pub residuals: Option<ResidualPlot>,
}

impl Analysed {
    /// Identify `record` as `identify` does and, when `diagnose`, attach
    /// the diagnosis of a test of `kind` to the report.
    pub fn of<A: Analysis + 'static>(
        record: &Record,
        kind: SegmentKind,
        diagnose: bool,
        identify: impl FnOnce(&Record) -> A,
    ) -> Analysed {
        let mut analysed = Analysed {
            analysis: Box::new(identify(record)),
            residuals: None,
        };
        analysed.analysis.report_mut().test_warnings =
            test_warnings(record.events.iter().map(|(t, e)| (*t, e)));
        if diagnose {
            analysed.diagnose(record, kind);
        }
        analysed
    }

    /// Attach the diagnosis of `record`, a test of `kind`, to this
    /// identification's report (and keep its residuals): what
    /// [`Analysed::of`] does when asked to diagnose, as a step of its own,
    /// so that a test can record its identification before the diagnosis
    /// runs.
    pub fn diagnose(&mut self, record: &Record, kind: SegmentKind) {
        self.residuals = attach_diagnosis(self.analysis.report_mut(), record, kind);
    }
}

/// Most of a test's warning events a report lists; the rest are counted.
const MAX_TEST_WARNINGS: usize = 20;

/// The report's `test_warnings` of a record's events: each warning as
/// "at test time T s: message", at most [`MAX_TEST_WARNINGS`] of them in
/// time order, then how many more the record holds. Where there are more,
/// the first of each kind (the message with its numbers left out) is
/// listed before any repeat, so that a flood of one kind (a late bus's
/// batches, one a millisecond) cannot hide a warning of another.
fn test_warnings<'a>(events: impl IntoIterator<Item = (u64, &'a Event)>) -> Vec<String> {
    let warned: Vec<(u64, &Event)> = events
        .into_iter()
        .filter(|(_, e)| e.level == EventLevel::Warn)
        .collect();
    let kind = |e: &Event| -> String {
        e.message
            .chars()
            .filter(|c| !c.is_ascii_digit() && *c != '.')
            .collect()
    };
    let mut seen = std::collections::HashSet::new();
    let (first, repeats): (Vec<usize>, Vec<usize>) =
        (0..warned.len()).partition(|&k| seen.insert(kind(warned[k].1)));
    let mut listed: Vec<usize> = first
        .into_iter()
        .chain(repeats)
        .take(MAX_TEST_WARNINGS)
        .collect();
    listed.sort_unstable();
    let mut out: Vec<String> = listed
        .iter()
        .map(|&k| {
            let (t, e) = warned[k];
            format!("at test time {:.3} s: {}", t as f64 * 1e-9, e.message)
        })
        .collect();
    if warned.len() > MAX_TEST_WARNINGS {
        out.push(format!(
            "{} more warnings during the test (the record's /bench/events holds them all)",
            warned.len() - MAX_TEST_WARNINGS
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn event(level: EventLevel, message: &str) -> Event {
        Event {
            level,
            message: message.into(),
        }
    }

    #[test]
    fn a_report_lists_the_tests_warnings_with_their_time_and_counts_the_rest() {
        let events = [
            (1_500_000_000, event(EventLevel::Info, "segment 1: 60 V")),
            (
                2_250_000_000,
                event(EventLevel::Warn, "level 60 V did not settle"),
            ),
            (3_000_000_000, event(EventLevel::Abort, "stopped")),
        ];
        let listed = test_warnings(events.iter().map(|(t, e)| (*t, e)));
        assert_eq!(listed, ["at test time 2.250 s: level 60 V did not settle"]);

        let many: Vec<(u64, Event)> = (0..25)
            .map(|n| {
                (
                    n * 1_000_000_000,
                    event(EventLevel::Warn, &format!("point {n} skipped")),
                )
            })
            .collect();
        let listed = test_warnings(many.iter().map(|(t, e)| (*t, e)));
        assert_eq!(listed.len(), MAX_TEST_WARNINGS + 1);
        assert_eq!(listed[19], "at test time 19.000 s: point 19 skipped");
        assert!(
            listed[20].starts_with("5 more warnings during the test"),
            "{}",
            listed[20]
        );
        assert!(test_warnings(std::iter::empty()).is_empty());
    }

    /// A flood of one kind of warning (a late bus's batches) leaves room
    /// for the one warning of another kind that came after it.
    #[test]
    fn a_flood_of_one_warning_does_not_hide_another() {
        let mut events: Vec<(u64, Event)> = (0..30)
            .map(|n| {
                (
                    n * 1_000_000,
                    event(
                        EventLevel::Warn,
                        &format!(
                            "merged: a batch of encoder_count arrived {}.0 ms late",
                            50 - n
                        ),
                    ),
                )
            })
            .collect();
        events.push((40_000_000, event(EventLevel::Warn, "garbage on the line")));
        let listed = test_warnings(events.iter().map(|(t, e)| (*t, e)));
        assert_eq!(listed.len(), MAX_TEST_WARNINGS + 1);
        assert_eq!(listed[19], "at test time 0.040 s: garbage on the line");
        assert_eq!(
            listed[0],
            "at test time 0.000 s: merged: a batch of encoder_count arrived 50.0 ms late"
        );
        assert!(listed[20].starts_with("11 more warnings"), "{}", listed[20]);
    }
}
