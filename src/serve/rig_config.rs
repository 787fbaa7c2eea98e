//! A rig's configuration as the daemon holds it: the one
//! [`TestConfig`](crate::config::TestConfig) (a DC rig, `dc_step` /
//! `dc_coastdown`; an induction-machine rig, `im_slip_sweep`, with its two
//! stages), and the start request's `[test]` applied over it.

use crate::config::ConfigError;
pub use crate::config::TestConfig as RigConfig;

use super::test_override::{with_im_test_override, with_test_override};

impl RigConfig {
    /// This configuration with `test` (keys of `[test]`) applied over it.
    pub fn with_test(
        &self,
        test: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<RigConfig, ConfigError> {
        match self {
            RigConfig::Dc(c) => with_test_override(c, test).map(|c| RigConfig::Dc(Box::new(c))),
            RigConfig::Im(c) => with_im_test_override(c, test).map(|c| RigConfig::Im(Box::new(c))),
        }
    }
}
