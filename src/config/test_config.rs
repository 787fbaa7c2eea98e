//! The configuration of one test, whatever the machine: the `[test]`
//! table's `plan` (a tagged enum, [`PlanKind`]) names the test, and the
//! test its machine. This is the one place that maps a plan to its
//! machine; the CLI (`run`, `probe`), the daemon and the tests load every
//! configuration through [`TestConfig`] and never look into the TOML.
//!
//! Each machine validates its own schema: a DC machine's ([`Config`],
//! `dc_step` / `dc_coastdown`) or an induction machine's ([`ImRunConfig`],
//! `im_slip_sweep` / `im_standard_tests`). Errors are [`ConfigError`]s for both, naming the
//! file, the line and the key.
//!
//! A third machine would add a [`PlanKind`] variant per plan, a
//! [`TestConfig`] variant holding its validated configuration, and its
//! schema's parser; the compiler then lists every place that must say
//! what the new machine does.

use std::path::Path;

use serde::Deserialize;

use super::{invalid, merged_test, syntax_error, CommonConfig, Config, ConfigError};
use crate::excerpt::quoted;
use crate::machine::im::ImRunConfig;
use crate::machine::Machine;
use crate::model::ImModel;

/// The test a configuration asks for (`test.plan`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlanKind {
    /// DC machine: armature-voltage staircase (optionally ending in a
    /// coast-down).
    DcStep,
    /// DC machine: run up, open the armature, let it coast.
    DcCoastdown,
    /// Induction machine: slip sweep at several supply voltages.
    ImSlipSweep,
    /// Induction machine: the standard test set (DC resistance, no load,
    /// locked rotor), then the slip sweep as the load test.
    ImStandardTests,
}

impl PlanKind {
    /// Every plan this version runs.
    pub const ALL: [PlanKind; 4] = [
        PlanKind::DcStep,
        PlanKind::DcCoastdown,
        PlanKind::ImSlipSweep,
        PlanKind::ImStandardTests,
    ];

    /// The name in `test.plan`.
    pub fn name(self) -> &'static str {
        match self {
            PlanKind::DcStep => "dc_step",
            PlanKind::DcCoastdown => "dc_coastdown",
            PlanKind::ImSlipSweep => "im_slip_sweep",
            PlanKind::ImStandardTests => "im_standard_tests",
        }
    }

    /// The machine the plan tests: `dc` or `induction`.
    pub fn machine(self) -> &'static str {
        match self {
            PlanKind::DcStep | PlanKind::DcCoastdown => "dc",
            PlanKind::ImSlipSweep | PlanKind::ImStandardTests => "induction",
        }
    }

    /// The plan `text` names; `None` when it names none (the machine's
    /// schema then says what is missing).
    fn of(source: &str, text: &str) -> Result<Option<PlanKind>, ConfigError> {
        let doc: toml::Table = toml::from_str(text).map_err(|e| syntax_error(source, text, &e))?;
        let Some(plan) = doc.get("test").and_then(|t| t.get("plan")) else {
            return Ok(None);
        };
        let Some(name) = plan.as_str() else {
            return Ok(None);
        };
        match plan.clone().try_into::<PlanKind>() {
            Ok(kind) => Ok(Some(kind)),
            Err(_) => Err(invalid(
                source,
                "test.plan",
                format!(
                    "unknown plan {} (this version has: {})",
                    quoted(name),
                    PlanKind::ALL
                        .map(|p| format!("\"{}\"", p.name()))
                        .join(", ")
                ),
            )),
        }
    }
}

/// A validated configuration of one test; see the module docs.
#[derive(Debug, Clone)]
pub enum TestConfig {
    /// A DC machine on one power stage.
    Dc(Box<Config>),
    /// An induction machine on a supply VFD and a dynamometer.
    Im(Box<ImRunConfig>),
}

impl TestConfig {
    /// Read and validate `path`.
    pub fn load(path: &Path) -> Result<TestConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        TestConfig::parse(&path.display().to_string(), &text)
    }

    /// `path`, or the embedded default (a DC step test on the simulated
    /// rig) when none.
    pub fn load_or_default(path: Option<&Path>) -> Result<TestConfig, ConfigError> {
        match path {
            Some(p) => TestConfig::load(p),
            None => Ok(TestConfig::Dc(Box::new(Config::embedded_default()))),
        }
    }

    /// Parse and validate `text`; `source` names it in errors (and its
    /// directory resolves relative device-profile paths).
    pub fn parse(source: &str, text: &str) -> Result<TestConfig, ConfigError> {
        let dir = Path::new(source).parent().unwrap_or(Path::new("."));
        TestConfig::parse_composed(source, dir, text).map_err(|e| e.located(Some(text)))
    }

    /// Parse and validate `text` the program composed: errors name the
    /// key, not a line of the composed text; relative profile paths are
    /// resolved in `dir`.
    fn parse_composed(source: &str, dir: &Path, text: &str) -> Result<TestConfig, ConfigError> {
        match PlanKind::of(source, text)? {
            Some(PlanKind::ImSlipSweep | PlanKind::ImStandardTests) => Ok(TestConfig::Im(
                Box::new(ImRunConfig::parse_composed(source, dir, text)?),
            )),
            Some(PlanKind::DcStep | PlanKind::DcCoastdown) | None => Ok(TestConfig::Dc(Box::new(
                Config::parse_composed(source, dir, text)?,
            ))),
        }
    }

    /// This configuration with `test` (the keys of a `[test]` table, from
    /// the daemon's start request) applied over its own `[test]`: the
    /// text is composed again and validated like any configuration file,
    /// so a bad key is refused by name, and the configuration text of the
    /// result (recorded in the MCAP) is the resolved TOML. Device-profile
    /// paths stay relative to the configuration's own directory; a plan
    /// of another machine is refused.
    pub fn with_test(
        &self,
        test: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<TestConfig, ConfigError> {
        let common = self.common();
        let source = format!("{} with the request's [test]", common.source);
        let text = merged_test(&common.text, test, &source)?;
        let machine = self.machine();
        if let Some(plan) = PlanKind::of(&source, &text)?.filter(|p| p.machine() != machine) {
            let own: Vec<String> = PlanKind::ALL
                .iter()
                .filter(|p| p.machine() == machine)
                .map(|p| format!("\"{}\"", p.name()))
                .collect();
            return Err(invalid(
                &source,
                "test.plan",
                format!(
                    "\"{}\" is a plan for a {} machine; this rig's machine is {} (its plans: {})",
                    plan.name(),
                    plan.machine(),
                    machine,
                    own.join(", ")
                ),
            ));
        }
        let dir = Path::new(&common.source).parent().unwrap_or(Path::new("."));
        TestConfig::parse_composed(&source, dir, &text)
    }

    /// The test as its machine runs it: the one place a plan is mapped
    /// to its [`Machine`].
    pub fn into_machine(self) -> Box<dyn Machine> {
        match self {
            TestConfig::Dc(c) => c,
            TestConfig::Im(c) => c,
        }
    }

    /// The plan.
    pub fn plan(&self) -> PlanKind {
        match self {
            TestConfig::Dc(c) => match c.plan {
                super::Plan::DcStep { .. } => PlanKind::DcStep,
                super::Plan::DcCoastdown { .. } => PlanKind::DcCoastdown,
            },
            TestConfig::Im(c) if c.standard.is_some() => PlanKind::ImStandardTests,
            TestConfig::Im(_) => PlanKind::ImSlipSweep,
        }
    }

    /// The machine kind: `dc` or `induction`.
    pub fn machine(&self) -> &'static str {
        self.plan().machine()
    }

    /// What every test configuration holds: the file, the motor, the
    /// sample rate, limits, supervision, retention, faults.
    pub fn common(&self) -> &CommonConfig {
        match self {
            TestConfig::Dc(c) => &c.common,
            TestConfig::Im(c) => &c.common,
        }
    }

    /// The rig's hardware, for a person.
    pub fn describe(&self) -> String {
        match self {
            TestConfig::Dc(c) => c.backend.describe(),
            TestConfig::Im(c) => c.describe_rig(),
        }
    }

    /// The names of the rig's stages, in the order the supervisor commands
    /// them safe.
    pub fn stages(&self) -> Vec<&'static str> {
        match self {
            TestConfig::Dc(_) => vec!["power_stage"],
            TestConfig::Im(c) if c.standard.is_some() => {
                vec!["supply", "dynamometer", "dc_source"]
            }
            TestConfig::Im(_) => vec!["supply", "dynamometer"],
        }
    }
}

/// The induction-machine circuit a record's configuration text asks to
/// identify (`test.model`). Only that key is read: the whole text need not
/// validate where the record is replayed (its device profiles may live on
/// the rig's computer).
pub fn recorded_im_model(text: &str) -> Option<ImModel> {
    let t = toml::from_str::<toml::Table>(text).ok()?;
    ImModel::parse(t.get("test")?.get("model")?.as_str()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIM_IM: &str = include_str!("../../config/sim-im.toml");
    const SIM_IM_STANDARD: &str = include_str!("../../config/sim-im-standard.toml");

    #[test]
    fn the_plan_picks_the_machine() {
        let dc = TestConfig::parse("dc.toml", super::super::DEFAULT_CONFIG).unwrap();
        assert_eq!((dc.plan(), dc.machine()), (PlanKind::DcStep, "dc"));
        let im = TestConfig::parse("im.toml", SIM_IM).unwrap();
        assert_eq!(
            (im.plan(), im.machine()),
            (PlanKind::ImSlipSweep, "induction")
        );
        assert_eq!(im.stages(), ["supply", "dynamometer"]);
        let standard = TestConfig::parse("std.toml", SIM_IM_STANDARD).unwrap();
        assert_eq!(
            (standard.plan(), standard.machine()),
            (PlanKind::ImStandardTests, "induction")
        );
        assert_eq!(standard.stages(), ["supply", "dynamometer", "dc_source"]);
        assert_eq!(recorded_im_model(SIM_IM), Some(ImModel::Double));
        assert_eq!(recorded_im_model(super::super::DEFAULT_CONFIG), None);
    }

    #[test]
    fn an_unknown_plan_names_file_line_and_key() {
        let text = SIM_IM.replace("plan = \"im_slip_sweep\"", "plan = \"im_locked_rotor\"");
        let line = text.lines().position(|l| l.starts_with("plan = ")).unwrap() + 1;
        let e = TestConfig::parse("im.toml", &text).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("im.toml:{line}: test.plan: unknown plan")),
            "{e}"
        );
        assert!(e.contains("\"im_slip_sweep\""), "{e}");
    }

    #[test]
    fn induction_machine_errors_are_typed_with_file_line_and_key() {
        let text = SIM_IM.replace("poles = 4", "poles = 3");
        let line = text
            .lines()
            .position(|l| l.starts_with("poles = 3"))
            .unwrap()
            + 1;
        match TestConfig::parse("im.toml", &text).unwrap_err() {
            ConfigError::Invalid {
                path,
                line: at,
                key,
                ..
            } => assert_eq!(
                (path.as_str(), at, key.as_str()),
                ("im.toml", Some(line), "motor.nameplate.poles")
            ),
            other => panic!("not an invalid value: {other}"),
        }
        let e = TestConfig::parse("im.toml", &format!("{SIM_IM}\n[limits.extra]\n")).unwrap_err();
        assert!(matches!(e, ConfigError::Parse { .. }), "{e}");
    }
}
