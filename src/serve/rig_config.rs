//! A rig's configuration as the daemon holds it: a DC rig ([`Config`],
//! `dc_step` / `dc_coastdown` plans) or an induction-machine rig
//! ([`ImRunConfig`], the `im_slip_sweep` plan, with its two stages), told
//! apart by the file's `test.plan`.

use std::path::Path;

use crate::bench::{is_im_sweep_config, ImRunConfig};
use crate::config::{Config, ConfigError, Retention, Supervision};

use super::test_override::{with_im_test_override, with_test_override};

/// A rig's configuration; see the module docs.
#[derive(Debug, Clone)]
pub enum RigConfig {
    /// A DC machine on one power stage.
    Dc(Box<Config>),
    /// An induction machine on a supply VFD and a dynamometer.
    Im(Box<ImRunConfig>),
}

/// Why a rig configuration could not be used.
#[derive(Debug, thiserror::Error)]
pub enum RigConfigError {
    /// A DC configuration's error.
    #[error(transparent)]
    Dc(#[from] ConfigError),
    /// An induction-machine configuration's error (names the file and the
    /// line or key).
    #[error("{0}")]
    Im(String),
}

impl RigConfig {
    /// Read and validate `path`.
    pub fn load(path: &Path) -> Result<RigConfig, RigConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        if is_im_sweep_config(&text) {
            Ok(RigConfig::Im(Box::new(
                ImRunConfig::parse(&path.display().to_string(), &text)
                    .map_err(RigConfigError::Im)?,
            )))
        } else {
            Ok(RigConfig::Dc(Box::new(Config::load(path)?)))
        }
    }

    /// The motor under test.
    pub fn motor_id(&self) -> &str {
        match self {
            RigConfig::Dc(c) => &c.motor_id,
            RigConfig::Im(c) => &c.motor_id,
        }
    }

    /// Where the configuration came from.
    pub fn source(&self) -> &str {
        match self {
            RigConfig::Dc(c) => &c.source,
            RigConfig::Im(c) => &c.source,
        }
    }

    /// The rig's hardware, for a person.
    pub fn describe(&self) -> String {
        match self {
            RigConfig::Dc(c) => c.backend.describe(),
            RigConfig::Im(c) => c.describe_rig(),
        }
    }

    /// The machine kind: `dc` or `induction`.
    pub fn machine(&self) -> &'static str {
        match self {
            RigConfig::Dc(_) => "dc",
            RigConfig::Im(_) => "induction",
        }
    }

    /// The names of the rig's stages, in the order the supervisor commands
    /// them safe.
    pub fn stages(&self) -> Vec<&'static str> {
        match self {
            RigConfig::Dc(_) => vec!["power_stage"],
            RigConfig::Im(_) => vec!["supply", "dynamometer"],
        }
    }

    /// What the safety supervisor enforces beyond the limits.
    pub fn supervision(&self) -> &Supervision {
        match self {
            RigConfig::Dc(c) => &c.supervision,
            RigConfig::Im(c) => &c.supervision,
        }
    }

    /// How long the rig's records are kept.
    pub fn retention(&self) -> Retention {
        match self {
            RigConfig::Dc(c) => c.retention,
            RigConfig::Im(c) => c.retention,
        }
    }

    /// This configuration with `test` (keys of `[test]`) applied over it.
    pub fn with_test(
        &self,
        test: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<RigConfig, String> {
        match self {
            RigConfig::Dc(c) => with_test_override(c, test)
                .map(|c| RigConfig::Dc(Box::new(c)))
                .map_err(|e| e.to_string()),
            RigConfig::Im(c) => with_im_test_override(c, test).map(|c| RigConfig::Im(Box::new(c))),
        }
    }
}
